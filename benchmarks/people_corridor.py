"""People walking straight at the robot in a corridor: success, contacts and the time against the empty corridor.

missions/people_corridor.yaml (a go_to 20 m up a 2.8 m corridor in the open) on worlds/corridor_people_oncoming.yaml
(three people who walk straight at the robot along its line and do not give way: ``gives_way: false``) and on its
empty twin worlds/corridor_people_empty.yaml, for each seed. Printed per seed: the status, the collisions, the least
clearance between the footprint and a person (truth, m), how often the robot stepped aside or stopped for a person,
the mission time on both worlds and their ratio. Goal (issue 32): 5/5 succeed, 0 collisions, ratio at most 2.0.
With ``--no-step-aside`` the robot's profile turns ``local_planner.step_aside`` off (how it was before: people are
steered round like any obstacle).

Not a test: tests/test_people.py checks one seed. Run: python benchmarks/people_corridor.py [--seeds 1 2 3 4 5]
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
sys.path.insert(0, str(REPO / "benchmarks"))

from beastbt.testing import MissionHarness  # noqa: E402
from figures import Figures  # noqa: E402

MISSION = REPO / "missions" / "people_corridor.yaml"
WORLD = REPO / "worlds" / "corridor_people_oncoming.yaml"
EMPTY = REPO / "worlds" / "corridor_people_empty.yaml"
UNTIL_S = 600.0


def robot_without_step_aside(folder: Path) -> str:
    """robots/sim.yaml with ``local_planner: {step_aside: false}``, written to ``folder``; its path."""
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    path = folder / "sim_no_step_aside.yaml"
    path.write_text(text + "\nlocal_planner:\n  step_aside: false\n", encoding="utf-8")
    return str(path)


def run(world: Path, seed: int, robot: str = "sim") -> dict:
    """One run at full speed: the summary, with ``least_person_gap_m`` (truth, m) added."""
    h = MissionHarness.from_file(MISSION, world=str(world), seed=seed, robot=robot)
    contact = h.run.io.sim.drive.contact
    least = math.inf
    while not h.done and h.now_s < UNTIL_S:
        h.tick()
        t = h.truth
        for person, (x, y) in zip(contact.persons, contact.person_xy):
            least = min(least, math.hypot(x - t.x, y - t.y) - person.radius_m - contact.radius_m)
    summary = h.summary()
    summary["least_person_gap_m"] = least
    return summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    ap.add_argument("--no-step-aside", action="store_true", help="the robot without local_planner.step_aside")
    args = ap.parse_args()
    robot = "sim"
    tmp = tempfile.TemporaryDirectory()
    if args.no_step_aside:
        robot = robot_without_step_aside(Path(tmp.name))
    ok, collisions, ratios, gaps, asides = 0, 0, [], [], []
    print("seed  status   collisions  least gap  step asides  waits  time   empty   ratio")
    started = time.process_time()
    for seed in args.seeds:
        empty = run(EMPTY, seed, robot)
        s = run(WORLD, seed, robot)
        texts = [e["text"] for e in s["events"] if e["kind"] == "step_aside"]
        n_aside = sum(t.startswith("stepping aside") for t in texts)
        n_wait = sum(t.startswith("no room") for t in texts)
        ratio = s["sim_time_s"] / empty["sim_time_s"]
        coll = s["truth"]["collisions"]
        ok += s["status"] == "success" and empty["status"] == "success"
        collisions += coll
        ratios.append(ratio)
        gaps.append(s["least_person_gap_m"])
        asides.append(n_aside)
        print(f"{seed:4d}  {s['status']:8s} {coll:10d}  {s['least_person_gap_m']:7.2f} m  {n_aside:11d}  {n_wait:5d}"
              f"  {s['sim_time_s']:5.1f}  {empty['sim_time_s']:5.1f}  {ratio:5.2f}", flush=True)
    print(f"succeeded {ok}/{len(args.seeds)}, collisions {collisions}, time ratio {min(ratios):.2f}-{max(ratios):.2f} "
          f"(goal: {len(args.seeds)}/{len(args.seeds)}, 0, at most 2.0); least gap to a person "
          f"{min(gaps):.2f} m; CPU {time.process_time() - started:.0f} s")
    if args.no_step_aside or args.seeds != [1, 2, 3, 4, 5]:
        return  # the saved figures are those of the default run
    figures = Figures("people_corridor")
    figures.put("succeeded", ok)
    figures.put("collisions", collisions)
    figures.put("ratio.max", round(max(ratios), 2))
    figures.put("ratio.min", round(min(ratios), 2))
    figures.put("least_gap_m", round(min(gaps), 2))
    figures.put("step_asides.min", min(asides))
    figures.put("step_asides.max", max(asides))
    figures.save()


if __name__ == "__main__":
    main()
