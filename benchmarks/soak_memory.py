"""Soak: does a ``forever`` mission's memory stay flat? (issue 25, point 4)

A robot on ``repeat: forever`` runs for days; whatever a run keeps per tick,
step or command grows without bound. This runs missions on the simulator at
full speed through the same session loop as ``beastbt run`` (no run folder:
``--no-record``), each in a fresh Python process so that one does not inherit
the other's memory, and samples the process's resident set size (RSS, from
``/proc/self/statm``) at every simulated hour.

Two missions, measured in the same run:

1. the patrol of ``missions/patrol.yaml`` with ``times: forever``, in the open
   campus world (in the corridor an open-loop patrol drifts into a wall after
   a few loops and the run ends);
2. the baseline: an almost empty mission, a ``forever`` loop of one-minute
   waits, on the same robot and world (the parts, the estimator and the
   emulators run as they do for the patrol; the tree does nearly nothing).

For each it prints the RSS after the warm-up, its growth over the soak (MB,
goal: under 5 MB over 10 simulated hours), the growth per simulated hour (a
least-squares slope, MB/h) and per completed step (kB), and the ratio of the
patrol's growth to the baseline's. Before the fix of issue 25 the patrol grew
about 20.7 MB per simulated hour (about 24 kB per completed step).

``--record`` soaks with the recording on (a run folder in a temporary
directory); it is slower (the MCAP writer process works too) and measures this
process only, not the writer's.

Run: python benchmarks/soak_memory.py [--hours 10] [--warmup 1] [--record]
(about 3 minutes on a Raspberry-Pi-class core for the defaults; the figure is
printed at the end).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

WORLD = REPO / "worlds" / "campus.yaml"
PATROL = f"""
mission: soak_patrol
world: {WORLD}
limits: {{speed: 0.3 m/s}}
tasks:
  look_around:
    - look: {{pan: -45 deg}}
    - wait: 2 s
    - look: {{pan: 45 deg}}
    - wait: 2 s
    - look: {{pan: 0 deg}}
steps:
  - repeat:
      times: forever
      steps:
        - drive: {{distance: 3 m, speed: 0.15 m/s}}
        - do: look_around
        - turn: {{angle: 180 deg}}
        - drive: {{distance: 3 m, speed: 0.15 m/s}}
        - do: look_around
        - turn: {{angle: 180 deg}}
"""
"""``missions/patrol.yaml`` with ``times: forever``, in the open campus world."""
WAITS = f"""
mission: soak_waits
world: {WORLD}
steps:
  - repeat:
      times: forever
      steps:
        - wait: 60 s
"""
"""The baseline: a ``forever`` loop of one-minute waits."""
GOAL_MB = 5.0
"""Largest RSS growth over the soak that counts as flat (MB)."""


def rss_mb() -> float:
    """This process's resident set size now (MB), from ``/proc/self/statm``."""
    with open("/proc/self/statm", "rb") as f:
        resident_pages = int(f.read().split()[1])
    return resident_pages * os.sysconf("SC_PAGE_SIZE") / 1e6


def child(mission_text: str, warmup_h: float, hours: float, record: bool, every_h: float) -> dict:
    """Run one mission for ``warmup_h + hours`` simulated hours in this process.

    RSS (MB) and steps completed at the start, at the end of the warm-up and every ``every_h`` simulated hours
    after it.
    """
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    base = Path(tempfile.mkdtemp(prefix="beastbt-soak-"))
    opts = RunOptions(record=record, runs_dir=str(base / "runs"), max_time_s=(warmup_h + hours) * 3600.0)
    p = prepare(str(base / "mission.yaml"), opts, mission_text=mission_text)
    run = p.run
    samples: list[tuple[float, float, int]] = []  # (sim h, RSS MB, steps completed)
    at_h = [0.0] + [warmup_h + k * every_h for k in range(int(round(hours / every_h)) + 1)]
    state = {"steps": 0, "next": 0}

    def sample(rec: Any) -> None:
        # A completed step: a tree node that changed to SUCCESS at this tick.
        state["steps"] += sum(1 for change in rec.changed_nodes if change[1] == "SUCCESS")
        hour = rec.now_s / 3600.0
        if state["next"] < len(at_h) and hour + 1e-9 >= at_h[state["next"]]:
            samples.append((round(hour, 3), rss_mb(), state["steps"]))
            state["next"] += 1

    run.recorders.append(sample)
    wall0 = time.perf_counter()
    with open(os.devnull, "w") as devnull:
        summary = execute(p, devnull)
    end_h = round(run.elapsed_s / 3600.0, 3)
    if not samples or samples[-1][0] != end_h:
        samples.append((end_h, rss_mb(), state["steps"]))  # the last tick, for certain
    return {"samples": samples, "wall_s": time.perf_counter() - wall0, "status": summary["status"],
            "sim_time_s": summary["sim_time_s"]}


def soak(name: str, warmup_h: float, hours: float, record: bool, every_h: float) -> dict:
    """Run ``child`` for mission ``name`` in a fresh interpreter; its result."""
    cmd = [sys.executable, __file__, "--child", name, "--warmup", str(warmup_h), "--hours", str(hours),
           "--every", str(every_h)]
    if record:
        cmd.append("--record")
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, cwd=str(REPO))
    return json.loads(out.stdout.strip().splitlines()[-1])


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of ys over xs (0 for fewer than two points)."""
    n = len(xs)
    if n < 2:
        return 0.0
    mx, my = sum(xs) / n, sum(ys) / n
    den = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / den if den else 0.0


def figures(result: dict, warmup_h: float) -> dict:
    """Growth after the warm-up: total (MB), per simulated hour (MB/h), per completed step (kB)."""
    after = [s for s in result["samples"] if s[0] + 1e-6 >= warmup_h]
    first, last = after[0], after[-1]
    growth = last[1] - first[1]
    steps = last[2] - first[2]
    return {"start_mb": first[1], "end_mb": last[1], "growth_mb": growth, "hours": last[0] - first[0],
            "per_hour_mb": slope([s[0] for s in after], [s[1] for s in after]), "steps": steps,
            "per_step_kb": growth * 1000.0 / steps if steps else None}


def main(argv: Optional[list[str]] = None) -> int:
    """Soak the patrol and the baseline; print the figures; 0 when the patrol is flat, else 1."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=10.0, help="simulated hours measured after the warm-up")
    ap.add_argument("--warmup", type=float, default=1.0, help="simulated hours before the measurement")
    ap.add_argument("--every", type=float, default=1.0, help="simulated hours between two samples of the RSS")
    ap.add_argument("--record", action="store_true", help="with the recording on")
    ap.add_argument("--child", choices=("patrol", "waits"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        text = PATROL if args.child == "patrol" else WAITS
        print(json.dumps(child(text, args.warmup, args.hours, args.record, args.every)))
        return 0
    t0 = time.perf_counter()
    results = {name: soak(name, args.warmup, args.hours, args.record, args.every) for name in ("waits", "patrol")}
    print(f"soak: {args.warmup:g} h warm-up, then {args.hours:g} simulated hours, recording "
          f"{'on' if args.record else 'off'}; RSS of the run's process from /proc/self/statm")
    figs = {name: figures(r, args.warmup) for name, r in results.items()}
    for name, r in results.items():
        f = figs[name]
        per_step = f"{f['per_step_kb']:.3f} kB/step" if f["per_step_kb"] is not None else "no steps"
        print(f"  {name:6s}: {r['status']} at {r['sim_time_s'] / 3600:.2f} h sim, wall {r['wall_s']:.1f} s; "
              f"RSS {f['start_mb']:.1f} -> {f['end_mb']:.1f} MB: growth {f['growth_mb']:+.2f} MB over "
              f"{f['hours']:.1f} h ({f['per_hour_mb']:+.3f} MB/h, {f['steps']} steps, {per_step})")
        print("          RSS by sim hour: " + " ".join(f"{s[1]:.1f}" for s in r["samples"]))
    base = figs["waits"]["growth_mb"]
    patrol = figs["patrol"]["growth_mb"]
    ratio = f"{patrol / base:.2f}" if abs(base) > 0.05 else "n/a (the baseline grew less than 0.05 MB)"
    print(f"  patrol growth - baseline growth: {patrol - base:+.2f} MB; ratio patrol/baseline: {ratio}")
    flat = patrol < GOAL_MB
    print(f"  goal: patrol growth < {GOAL_MB:g} MB over the soak: {'FLAT' if flat else 'GROWS'} "
          f"(before the fix: about 20.7 MB per simulated hour)")
    print(f"  benchmark wall time: {time.perf_counter() - t0:.0f} s")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    saved = Figures("soak_memory")
    for name, f in figs.items():
        saved.put(f"{name}.growth_mb", f["growth_mb"])
        saved.put(f"{name}.per_hour_mb", f["per_hour_mb"])
    saved.put("hours", args.hours)
    saved.save()
    return 0 if flat else 1


if __name__ == "__main__":
    sys.exit(main())
