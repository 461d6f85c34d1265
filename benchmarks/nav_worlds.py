"""The navigation worlds built for the global costmap, swept over seeds 1..N (issue 32's "Done when").

For each course, the mission runs on its world and on the empty field (worlds/field.yaml) with the same seed, at
full speed and unrecorded, and the script prints per seed: the status, the collisions (true contacts), the
simulated time against the empty field's (the ratio the issue bounds) and the recoveries and replans counted.

* ``fence``: missions/fence_crossing.yaml on worlds/field_fence.yaml (an 8 m fence whose only gap, 0.25 m, is
  narrower than the robot). Goal: 5/5, 0 collisions, at most 1.5x the empty field's time.
* ``dead_end``: missions/dead_end.yaml on worlds/field_dead_end.yaml (a U 6 m x 5 m open towards the robot).
  Goal: 5/5, 0 collisions, at most 3x.
* ``long_fence``: missions/fence_long.yaml on worlds/field_fence_long.yaml (a 16 m fence, 8 m either side, whose
  ends the LiDAR does not see from the start; the shortest way round is 1.28x the straight line). Goal: 5/5,
  0 collisions, at most 1.5x.

The tests (tests/test_nav_global_worlds.py) run two of these seeds; this script is the whole sweep.

Run: python benchmarks/nav_worlds.py [--seeds 5] [--only fence|dead_end|long_fence]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.testing import MissionHarness  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)

COURSES = {
    "fence": ("fence_crossing.yaml", "field_fence.yaml", 1.5),
    "dead_end": ("dead_end.yaml", "field_dead_end.yaml", 3.0),
    "long_fence": ("fence_long.yaml", "field_fence_long.yaml", 1.5),
}


def run(mission: str, world: str, seed: int, until_s: float = 400.0) -> dict:
    """One run at full speed, unrecorded: its run summary."""
    h = MissionHarness.from_file(REPO / "missions" / mission, world=str(REPO / "worlds" / world), seed=seed)
    while not h.done and h.now_s < until_s:
        h.tick()
    return h.summary()


def count(summary: dict, kind: str) -> int:
    """How many of the summary's events are of ``kind``."""
    return sum(1 for e in summary["events"] if e["kind"] == kind)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5, help="seeds 1..N (default 5)")
    parser.add_argument("--only", choices=sorted(COURSES), help="one course only")
    args = parser.parse_args()
    figures = Figures("nav_worlds")
    for name, (mission, world, bound) in COURSES.items():
        if args.only and name != args.only:
            continue
        ok, worst_ratio, contacts = 0, 0.0, 0
        print(f"{name}: {mission} on {world} (bound {bound}x the empty field)")
        for seed in range(1, args.seeds + 1):
            empty = run(mission, "field.yaml", seed)
            s = run(mission, world, seed)
            ratio = s["sim_time_s"] / empty["sim_time_s"]
            good = s["status"] == "success" and s["truth"]["collisions"] == 0 and ratio <= bound
            ok += good
            worst_ratio = max(worst_ratio, ratio)
            contacts += s["truth"]["collisions"]
            print(f"  seed {seed}: {s['status']:8s} collisions {s['truth']['collisions']}  "
                  f"{s['sim_time_s']:6.1f} s vs {empty['sim_time_s']:6.1f} s empty = {ratio:4.2f}x  "
                  f"replans {count(s, 'replan')}  recoveries {count(s, 'recovery')}")
        figures.put(f"{name}.succeeded", ok)
        figures.put(f"{name}.seeds", args.seeds)
        figures.put(f"{name}.worst_time_ratio", round(worst_ratio, 2))
        figures.put(f"{name}.collisions", contacts)
    figures.save()


if __name__ == "__main__":
    main()
