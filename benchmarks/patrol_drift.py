"""How far an open-loop corridor patrol drifts per loop on the simulator (the figures in docs/mission-language.md).

Not a test: prints figures. For each seed it runs ``missions/patrol.yaml``
(drive 3 m, turn 180 deg, drive 3 m, turn 180 deg, on ``worlds/corridor.yaml``)
with ``times: forever`` and ``--max-time 10 min``, and reads the simulator's
truth from the run's recording at the end of every loop (1 s after the
second turn, the robot settled, back at the start end facing east):

1. the heading error per loop (deg, negative = clockwise), from the last loop;
2. the sideways offset per loop (cm, positive = north), from the last loop;
3. when the run ended and how (``failure`` = the drive was blocked by the wall).

It does so for the sim profile as shipped (turn tolerance 3 deg) and with
``control.turn_tolerance_rad`` at 1 deg, measured in the same run.

Run: python benchmarks/patrol_drift.py [--seeds 3] [--minutes 10]
"""

from __future__ import annotations

import argparse
import bisect
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

from beastbt.recording.reader import read_recording

REPO = Path(__file__).resolve().parent.parent
ONE_DEG_RAD = math.radians(1.0)


def forever_mission(folder: Path) -> Path:
    """missions/patrol.yaml with ``times: forever`` (and its world by absolute path), written in ``folder``."""
    text = (REPO / "missions" / "patrol.yaml").read_text()
    text = text.replace("world: ../worlds/corridor.yaml", f"world: {REPO / 'worlds' / 'corridor.yaml'}")
    text = text.replace("times: 3", "times: forever")
    path = folder / "patrol_forever.yaml"
    path.write_text(text)
    return path


def tight_profile(folder: Path) -> Path:
    """robots/sim.yaml with ``control: {turn_tolerance_rad: 1 deg}``, written in ``folder``."""
    text = (REPO / "robots" / "sim.yaml").read_text()
    text = text.replace("\nsafety:", f"\ncontrol:\n  turn_tolerance_rad: {ONE_DEG_RAD:.6f}\n\nsafety:", 1)
    path = folder / "sim_turn_1deg.yaml"
    path.write_text(text)
    return path


def run_once(mission: Path, folder: Path, seed: int, minutes: float, profile: list[str]) -> dict:
    """Run the patrol; the per-loop truth (heading deg, y m) and how the run ended."""
    runs, summary = folder / f"runs_{seed}", folder / f"summary_{seed}.json"
    subprocess.run([sys.executable, "-m", "beastbt", "run", str(mission), "--seed", str(seed),
                    "--max-time", f"{minutes:g} min", "--summary", str(summary), "--runs-dir", str(runs), *profile],
                   capture_output=True, text=True, check=False)
    result = json.loads(summary.read_text())
    (mcap,) = runs.glob("*/run.mcap")
    recording = read_recording(mcap)
    turn_ends = [m["now_s"] for _, m in recording.messages["/tree"] for c in m["changes"]
                 if c["name"].startswith("turn") and c["status"] == "SUCCESS"]
    truth = [m for _, m in recording.messages["/truth"]]
    times = [m["t_s"] for m in truth]
    loops = [truth[min(bisect.bisect_left(times, t + 1.0), len(truth) - 1)] for t in turn_ends[1::2]]
    return {"status": result["status"], "time_s": result["sim_time_s"],
            "headings_deg": [math.degrees(math.remainder(m["yaw"], 2 * math.pi)) for m in loops],
            "offsets_m": [m["y"] for m in loops]}


def main() -> None:
    """Print the drift per loop for each seed, with the shipped and the tightened turn tolerance."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--minutes", type=float, default=10.0)
    args = parser.parse_args()
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("patrol_drift")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        mission = forever_mission(folder)
        for label, profile in (("turn tolerance 3 deg (shipped)", []),
                               ("turn tolerance 1 deg", ["--robot", str(tight_profile(folder)), "--sim"])):
            print(label)
            rows: list[dict] = []
            for seed in range(1, args.seeds + 1):
                sub = folder / f"{len(profile)}_{seed}"
                sub.mkdir()
                r = run_once(mission, sub, seed, args.minutes, profile)
                n = len(r["headings_deg"])
                per_loop = (f"{r['headings_deg'][-1] / n:+.2f} deg and {100 * r['offsets_m'][-1] / n:+.1f} cm per loop"
                            if n else "no loop completed")
                print(f"  seed {seed}: {n} loops, {per_loop}; ended {r['status']} at {r['time_s']:.0f} s", flush=True)
                if n:
                    rows.append({"deg": abs(r["headings_deg"][-1] / n), "cm": abs(100 * r["offsets_m"][-1] / n),
                                 "loops": n, "end_s": r["time_s"], "blocked": r["status"] == "failure"})
            key = "shipped" if not profile else "tight"
            for name in ("deg", "cm", "loops", "end_s"):
                values = [row[name] for row in rows]
                if values:
                    figures.put(f"{key}.{name}_per_loop.min" if name in ("deg", "cm") else f"{key}.{name}.min",
                                min(values))
                    figures.put(f"{key}.{name}_per_loop.max" if name in ("deg", "cm") else f"{key}.{name}.max",
                                max(values))
            figures.put(f"{key}.blocked_runs", sum(row["blocked"] for row in rows))
    figures.save()


if __name__ == "__main__":
    main()
