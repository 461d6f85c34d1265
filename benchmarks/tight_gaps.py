"""Tight gaps: the narrowest gap each planner setting passes, on the simulator, seeds 1-5.

missions/tight_gap.yaml leaves the pen of worlds/field_gap.yaml through the only gap in its north wall; here the gap
is given each width of ``--gaps`` (metres; the simulator's robot is 0.30 m across, footprint radius 0.15 m), and the
mission runs on each of ``--seeds`` with each planner setting:

* ``default``: ``global_planner.narrow_gaps: true``, ``local_planner.narrow_speed_mps: 0.08`` (the profile's
  defaults);
* ``narrow_fast``: the same at ``narrow_speed_mps: 0.15``;
* ``no_narrow``: ``narrow_gaps: false`` and ``narrow_speed_mps: 0`` (the whole padding impassable, as Nav2's
  footprint_padding, and as before).

A run passes when it succeeds with no collision. For each setting it prints, per width, the runs that passed, the
fastest true speed while the robot's centre was within 10 cm of the wall's line, how many times the collision
monitor stopped it, and how long a failure took to be declared; then the narrowest width from which every wider
width passed on every seed, and the widest that failed on every seed. The figures are saved to
benchmarks/results/tight_gaps.json (docs/navigation.md, Tight gaps). Nothing is asserted.

Run: python benchmarks/tight_gaps.py [--seeds 1,2,3,4,5] [--gaps 0.32,0.36,...] [--max-s 100]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import yaml  # noqa: E402

from beastbt.testing import MissionHarness  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)

GAP_X_M = 0.5
"""Where the gap's centre is on the pen's north wall (east, m), as in worlds/field_gap.yaml."""
WALL_Y_M = 3.0
"""The north wall's line (north, m)."""

SETTINGS = {
    "default": {},
    "narrow_fast": {"local_planner": {"narrow_speed_mps": 0.15}},
    "no_narrow": {"global_planner": {"narrow_gaps": False}, "local_planner": {"narrow_speed_mps": 0.0}},
}


def write_world(folder: Path, gap_m: float) -> str:
    """worlds/field_gap.yaml with its gap ``gap_m`` wide (same centre); the path of the copy."""
    data = yaml.safe_load((REPO / "worlds" / "field_gap.yaml").read_text(encoding="utf-8"))
    walls = [w for w in data["walls"] if not (w[1] == WALL_Y_M and w[3] == WALL_Y_M)]
    west, east = GAP_X_M - gap_m / 2.0, GAP_X_M + gap_m / 2.0
    data["walls"] = [[-2.0, WALL_Y_M, west, WALL_Y_M], [east, WALL_Y_M, 2.0, WALL_Y_M]] + walls
    path = folder / f"field_gap_{int(round(gap_m * 1000))}mm.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return str(path)


def write_robot(folder: Path, name: str, sections: dict) -> str:
    """robots/sim.yaml with ``sections`` merged in; the path of the copy."""
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    for key, value in sections.items():
        data[key] = {**(data.get(key) or {}), **value}
    path = folder / f"robot_{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return str(path)


def run(world: str, robot: str, seed: int, max_s: float) -> dict:
    """One run of missions/tight_gap.yaml: passed, sim time, fastest speed in the gap (m/s), monitor stops."""
    h = MissionHarness.from_file(REPO / "missions" / "tight_gap.yaml", robot=robot, world=world, seed=seed)
    fastest = 0.0
    while not h.done and h.now_s < max_s:
        h.tick()
        if abs(h.truth.y - WALL_Y_M) < 0.1:
            fastest = max(fastest, abs(h.truth.v_mps))
    s = h.summary()
    stops = sum(1 for e in s["events"] if e["kind"] == "collision_monitor" and ": stop (" in e["text"])
    passed = s["status"] == "success" and s["truth"]["collisions"] == 0 and h.truth.y > WALL_Y_M + 0.3
    return {"passed": passed, "sim_s": s["sim_time_s"], "fastest": fastest, "stops": stops,
            "collisions": s["truth"]["collisions"], "status": s["status"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="1,2,3,4,5")
    ap.add_argument("--gaps", default="0.32,0.34,0.36,0.38,0.40,0.45,0.50,0.55,0.60")
    ap.add_argument("--settings", default=",".join(SETTINGS))
    ap.add_argument("--max-s", type=float, default=100.0, help="sim seconds a run may take")
    args = ap.parse_args()
    seeds = [int(x) for x in args.seeds.split(",")]
    gaps = sorted(float(x) for x in args.gaps.split(","))
    figures = Figures("tight_gaps")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        worlds = {g: write_world(folder, g) for g in gaps}
        for name in args.settings.split(","):
            robot = write_robot(folder, name, SETTINGS[name])
            print(f"{name}: {SETTINGS[name] or 'the defaults'}")
            passes: dict[float, int] = {}
            for gap in gaps:
                t0 = time.process_time()
                runs = [run(worlds[gap], robot, seed, args.max_s) for seed in seeds]
                n = sum(r["passed"] for r in runs)
                passes[gap] = n
                ok = [r for r in runs if r["passed"]]
                failed = [r for r in runs if not r["passed"]]
                fastest = max((r["fastest"] for r in ok), default=math.nan)
                line = f"   gap {gap:.2f} m: {n}/{len(runs)} passed"
                if ok:
                    line += (f", fastest in the gap {fastest:.3f} m/s, {sum(r['stops'] for r in ok)} monitor stops, "
                             f"{max(r['sim_s'] for r in ok):.0f} s at most")
                if failed:
                    line += f"; failed after {max(r['sim_s'] for r in failed):.1f} s at most ({failed[0]['status']})"
                print(line + f"  [{time.process_time() - t0:.0f} s CPU]")
                key = f"{name}.gap_{int(round(gap * 100)):02d}cm"
                figures.put(f"{key}.passed", n)
                if ok:
                    figures.put(f"{key}.fastest_in_gap_mps", fastest)
                if failed:
                    figures.put(f"{key}.failed_after_s", max(r["sim_s"] for r in failed))
                figures.put(f"{key}.collisions", sum(r["collisions"] for r in runs))
            every = [g for i, g in enumerate(gaps) if all(passes[h] == len(seeds) for h in gaps[i:])]
            never = [g for g in gaps if passes[g] == 0]
            narrowest = min(every) if every else math.nan
            print(f"   narrowest gap passed on every seed (and every wider one): {narrowest:.2f} m; "
                  f"widest failed on every seed: {max(never) if never else math.nan:.2f} m")
            if every:
                figures.put(f"{name}.narrowest_passed_m", narrowest)
            if never:
                figures.put(f"{name}.widest_failed_m", max(never))
    figures.save()


if __name__ == "__main__":
    main()
