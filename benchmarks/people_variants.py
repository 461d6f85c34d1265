"""People in corridors not shipped: each variant's people walk at the robot and do not give way, seeds 1-5.

benchmarks/people_corridor.py runs the one shipped corridor; here the corridor's width, the people's lines, speeds,
number and company change (issue 32, point 5 and its "Done when": "a corridor with people walking at the robot
succeeds 5/5 in at most 2x the empty corridor's time", with 0 collisions). Each variant is a world (YAML, in a
temporary folder) of a corridor 26 m long in the open, the robot at its south end facing north, and
missions/people_corridor.yaml's ``go_to`` 20 m up it; its baseline is the same corridor empty, same seed. People
(``gives_way: false``, radius 0.25 m unless said) walk from the far end to the robot's start along the lines given
(x across the corridor, m east of its middle: the robot's right):

* ``w2_right03``, ``w2_left03``: a 2 m corridor, one person 0.3 m right or left of the robot's line;
* ``w2_slant``: 2 m, one person walking from 0.5 m right to 0.5 m left (a slight diagonal);
* ``w2_two``: 2 m, two people 0.2 m right and left, 4 s apart;
* ``w16_middle``: 1.6 m, one person on the middle;
* ``w24_three_speeds``: 2.4 m, three people at 0.6, 1.0 and 1.2 m/s, on and beside the robot's line;
* ``w28_abreast``: 2.8 m, two people side by side 0.7 m apart;
* ``w28_three_close``: 2.8 m, three people 5 s apart on and 0.1 m beside the line;
* ``w28_three_off04``: 2.8 m, people 0.4 m right, 0.4 m left (1.0 m/s) and on the line (0.7 m/s, radius 0.3 m);
* ``w28_behind``: 2.8 m, one person catching the robot up from behind;
* ``w3_fast``: 3 m, people at 1.4 and 1.0 m/s (radius 0.3 m);
* ``w4_diagonal``: 4 m, one person walking from 1.5 m right to 1.5 m left.

A run passes when the mission succeeds with no collision in at most twice the empty corridor's time. Per variant it
prints the seeds passed and the time ratios, and how the others failed; then the totals. The figures go to
benchmarks/results/people_variants.json (docs/navigation.md, People).

Run: python benchmarks/people_variants.py [--seeds 1,2,3,4,5] [--jobs 2] [--only w2_two,w28_abreast]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import yaml  # noqa: E402

from beastbt.testing import MissionHarness  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)
from variant_runs import run_jobs, variant_arguments  # noqa: E402

MISSION = REPO / "missions" / "people_corridor.yaml"
LENGTH_M = 26.0
"""The corridor's length north of the robot (m); it also runs 2 m behind it."""
BOUND = 2.0
"""At most this many times the empty corridor's time (issue 32)."""
UNTIL_S = 400.0

# name: (width m, people: (x from m, x to m, speed m/s, start s, radius m, "ahead" or "behind"))
VARIANTS: dict[str, tuple[float, list[tuple[float, float, float, float, float, str]]]] = {
    "w2_right03": (2.0, [(0.3, 0.3, 0.8, 5, 0.25, "ahead")]),
    "w2_left03": (2.0, [(-0.3, -0.3, 0.8, 5, 0.25, "ahead")]),
    "w2_slant": (2.0, [(0.5, -0.5, 0.8, 5, 0.25, "ahead")]),
    "w2_two": (2.0, [(0.2, 0.2, 0.8, 5, 0.25, "ahead"), (-0.2, -0.2, 0.8, 9, 0.25, "ahead")]),
    "w16_middle": (1.6, [(0.0, 0.0, 0.8, 5, 0.25, "ahead")]),
    "w24_three_speeds": (2.4, [(0.0, 0.0, 0.6, 5, 0.25, "ahead"), (0.3, 0.3, 1.0, 20, 0.25, "ahead"),
                               (-0.3, -0.3, 1.2, 35, 0.25, "ahead")]),
    "w28_abreast": (2.8, [(0.35, 0.35, 0.8, 5, 0.25, "ahead"), (-0.35, -0.35, 0.8, 5, 0.25, "ahead")]),
    "w28_three_close": (2.8, [(0.0, 0.0, 0.8, 5, 0.25, "ahead"), (0.1, 0.1, 0.8, 10, 0.25, "ahead"),
                              (-0.1, -0.1, 0.8, 15, 0.25, "ahead")]),
    "w28_three_off04": (2.8, [(0.4, 0.4, 0.8, 5, 0.25, "ahead"), (-0.4, -0.4, 1.0, 25, 0.25, "ahead"),
                              (0.0, 0.0, 0.7, 45, 0.3, "ahead")]),
    "w28_behind": (2.8, [(0.0, 0.0, 0.8, 8, 0.25, "behind")]),
    "w3_fast": (3.0, [(0.0, 0.0, 1.4, 5, 0.3, "ahead"), (0.4, 0.4, 1.0, 15, 0.3, "ahead")]),
    "w4_diagonal": (4.0, [(1.5, -1.5, 0.8, 5, 0.25, "ahead")]),
}


def world(width_m: float, people: list) -> dict:
    """The corridor world (the shipped corridor's sensors and datum), with ``people`` walking in it."""
    doc = yaml.safe_load((REPO / "worlds" / "corridor_people_empty.yaml").read_text(encoding="utf-8"))
    w = width_m / 2.0
    doc["world"] = "people_variant"
    doc["walls"] = [[-w, -2.0, -w, LENGTH_M], [w, -2.0, w, LENGTH_M], [-w, -2.0, w, -2.0],
                    [-w, LENGTH_M, w, LENGTH_M]]
    far, near = LENGTH_M - 1.0, -1.5
    doc["obstacles"] = [{"shape": "person", "radius_m": r, "speed_mps": v, "start_s": t, "gives_way": False,
                         "path": [[x0, far], [x1, near]] if where == "ahead" else [[x0, near], [x1, far]]}
                        for x0, x1, v, t, r, where in people]
    if not people:
        del doc["obstacles"]
    return doc


def run(job: tuple[str, int, str, bool]) -> dict:
    """One run at full speed, unrecorded, of variant ``name`` (or its empty corridor): what it did."""
    name, seed, tmp, empty = job
    width, people = VARIANTS[name]
    path = Path(tmp) / f"{name}_{seed}_{'empty' if empty else 'people'}.yaml"
    path.write_text(yaml.safe_dump(world(width, [] if empty else people)), encoding="utf-8")
    h = MissionHarness.from_file(MISSION, world=str(path), seed=seed)
    while not h.done and h.now_s < UNTIL_S:
        h.tick()
    s = h.summary()
    return {"name": name, "seed": seed, "empty": empty, "status": s["status"], "sim_s": s["sim_time_s"],
            "collisions": s["truth"]["collisions"]}


def main() -> None:
    """Run the variants and print and save the figures."""
    args, seeds, names = variant_arguments(__doc__.split("\n")[0], "all")
    names = names or list(VARIANTS)
    with tempfile.TemporaryDirectory() as tmp:
        jobs = [(n, seed, tmp, empty) for n in names for seed in seeds for empty in (False, True)]
        results = run_jobs(run, jobs, args.jobs)
    total = passed = collisions = 0
    worst = 0.0
    for name in names:
        line, ok = [], 0
        failed = []
        for seed in seeds:
            r = next(x for x in results if x["name"] == name and x["seed"] == seed and not x["empty"])
            e = next(x for x in results if x["name"] == name and x["seed"] == seed and x["empty"])
            ratio = r["sim_s"] / e["sim_s"]
            good = r["status"] == "success" and r["collisions"] == 0 and ratio <= BOUND
            ok += good
            collisions += r["collisions"]
            worst = max(worst, ratio) if r["status"] == "success" else worst
            line.append(f"{ratio:.2f}")
            if not good:
                failed.append(f"seed {seed} {r['status']} at {r['sim_s']:.0f} s"
                              + (f" ({r['collisions']} collisions)" if r["collisions"] else ""))
        total += len(seeds)
        passed += ok
        print(f"{name:18s} {ok}/{len(seeds)} passed, time ratios {' '.join(line)}"
              + (f"; failed: {', '.join(failed)}" if failed else ""), flush=True)
    print(f"passed {passed} of {total} runs, {collisions} collisions, worst time ratio of a success {worst:.2f}")
    if args.only or seeds != [1, 2, 3, 4, 5]:
        return  # the saved figures are those of the whole sweep
    figures = Figures("people_variants")
    figures.put("runs", total)
    figures.put("passed", passed)
    figures.put("collisions", collisions)
    figures.put("ratio.max", round(worst, 2))
    figures.save()


if __name__ == "__main__":
    main()
