"""Tight gaps in pens and fences not shipped: every gap of the robot's width plus 10 cm or more is passed, seeds 1-5.

benchmarks/tight_gaps.py sweeps the width of the one shipped pen's gap; here the pen, the gap's place, the robot's
start heading and the place beyond change too (issue 32, point 4: "a gap at least the footprint's width plus 10 cm
is passed at reduced speed when it is the way"; the simulator's robot is 0.30 m across). Each variant is built as a
world (YAML, in a temporary folder) and a mission of one ``go_to`` to a GPS place, as missions/tight_gap.yaml:

* pens of 3 m x 3 m (``p33``), 5 m x 4 m (``p54``) and 4 m x 4.5 m (``p45``), the robot at (0, 0), the only gap in
  the north (``N``) or east (``E``) wall: centred (``c``), 0.3 m from the north-east corner (``o``) or from the
  other corner (``w``);
* a 30 m fence across an open field (``fence``), its gap 0.5 m (``c``) or 2 m (``o``) east of the robot's line;
* the robot starting facing the gap (``to``), away from it (``away``), at 135 degrees to it (``ang``: the odom frame,
  and the global costmap's cells, at 45 degrees to the walls) or side on (``side``);
* the place 4 m beyond the gap, straight (``straight``) or 3 m to one side (``side``, ``nside``);
* gaps of 0.40, 0.42, 0.45 and 0.50 m.

A run passes when the mission succeeds with no collision and the robot ends beyond the gap. Per variant it prints
the seeds passed, the slowest pass (simulated s) and the least true clearance, and how the others failed; then
the totals. The figures go to benchmarks/results/tight_gap_variants.json (docs/navigation.md, Tight gaps).

Run: python benchmarks/tight_gap_variants.py [--seeds 1,2,3,4,5] [--jobs 2] [--only p33:N:o:ang:side:0.40,...]
"""

from __future__ import annotations

import math
import re
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import yaml  # noqa: E402

from beastbt.estimation.geodesy import LocalFrame  # noqa: E402
from beastbt.testing import MissionHarness  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)
from variant_runs import run_jobs, variant_arguments  # noqa: E402

DATUM = {"lat": 40.41680, "lon": -3.70380, "alt_m": 650}
SENSORS = {  # as worlds/field_gap.yaml: the worlds are about the gap, not the filter's worst case
    "battery": {"start_v": 12.3, "drain_v_per_s": 0.0002},
    "gps": {"rate_hz": 1.0, "white_sigma_m": 1.5, "bias_sigma_m": 0.5, "bias_tau_s": 60.0, "jump_rate_per_s": 0.0,
            "cold_start_s": 1.0, "hdop": 0.9, "sats": 9},
    "imu": {"mag_field_ut": 45.0, "mag_inclination_deg": 54.0, "mag_declination_deg": 1.0},
}
PENS = {"p33": (-1.5, 1.5, -1.0, 2.0), "p54": (-2.5, 2.5, -1.5, 2.5), "p45": (-2.0, 2.0, -1.5, 3.0)}
"""Pens: (west, east, south, north) walls (m); the robot starts at (0, 0)."""
SHAPES = ("p33:N:c:away:straight", "p33:N:o:ang:side", "p33:E:c:away:nside", "p33:E:o:to:straight",
          "p54:N:o:away:straight", "p54:N:w:ang:side", "p54:E:c:side:straight", "p54:E:o:away:side",
          "p45:N:c:away:side", "fence:-:c:to:straight", "fence:-:o:ang:side")
GAPS = (0.40, 0.42, 0.45, 0.50)
BEYOND_M = 4.0
"""The place lies this far beyond the gap (m)."""
MAX_S = 150.0
"""Simulated seconds a run may take."""


def variant(name: str) -> tuple[dict, tuple[float, float], tuple[float, float], tuple[float, float]]:
    """The world (a dict) of ``name`` (``pen:wall:where:facing:place:width``), its place (x, y m), the gap's centre
    (x, y m) and the gap's normal pointing out."""
    pen, wall, where, facing, place, width = name.split(":")
    w = float(width)
    if pen == "fence":
        cx = {"c": 0.5, "o": 2.0}[where]
        walls = [[-15.0, 3.0, cx - w / 2, 3.0], [cx + w / 2, 3.0, 15.0, 3.0]]
        gap, normal, along = (cx, 3.0), (0.0, 1.0), (1.0, 0.0)
    else:
        x0, x1, y0, y1 = PENS[pen]
        if wall == "N":
            cx = {"c": (x0 + x1) / 2, "o": x1 - 0.3 - w / 2, "w": x0 + 0.3 + w / 2}[where]
            walls = [[x0, y1, cx - w / 2, y1], [cx + w / 2, y1, x1, y1], [x1, y1, x1, y0], [x1, y0, x0, y0],
                     [x0, y0, x0, y1]]
            gap, normal, along = (cx, y1), (0.0, 1.0), (1.0, 0.0)
        else:
            cy = {"c": (y0 + y1) / 2, "o": y1 - 0.3 - w / 2, "w": y0 + 0.3 + w / 2}[where]
            walls = [[x0, y1, x1, y1], [x1, y1, x1, cy + w / 2], [x1, cy - w / 2, x1, y0], [x1, y0, x0, y0],
                     [x0, y0, x0, y1]]
            gap, normal, along = (x1, cy), (1.0, 0.0), (0.0, 1.0)
    toward = math.degrees(math.atan2(normal[1], normal[0]))
    yaw = {"to": toward, "away": toward + 180.0, "ang": toward + 135.0, "side": toward - 90.0}[facing]
    side = {"straight": 0.0, "side": 3.0, "nside": -3.0}[place]
    goal = (gap[0] + BEYOND_M * normal[0] + side * along[0], gap[1] + BEYOND_M * normal[1] + side * along[1])
    world = {"world": "tight_gap_variant", "description": name, "datum": DATUM,
             "start": {"x": 0.0, "y": 0.0, "yaw_deg": yaw}, **SENSORS, "walls": walls}
    return world, goal, gap, normal


def run(job: tuple[str, int, str]) -> dict:
    """One run of variant ``name`` on ``seed``, its files in ``folder``: passed, status, sim time, least clearance."""
    name, seed, folder = job
    world, goal, gap, normal = variant(name)
    stem = Path(folder) / f"{name.replace(':', '_').replace('.', '')}_{seed}"
    world_path = stem.with_suffix(".world.yaml")
    world_path.write_text(yaml.safe_dump(world, sort_keys=False), encoding="utf-8")
    lat, lon, _ = LocalFrame(DATUM["lat"], DATUM["lon"], DATUM["alt_m"]).to_geodetic(*goal)
    mission = {"mission": "tight_gap_variant", "world": str(world_path),
               "places": {"outside": {"lat": round(lat, 9), "lon": round(lon, 9), "tolerance": "1.5 m"}},
               "steps": [{"go_to": "outside"}]}
    mission_path = stem.with_suffix(".mission.yaml")
    mission_path.write_text(yaml.safe_dump(mission, sort_keys=False), encoding="utf-8")
    h = MissionHarness.from_file(mission_path, world=str(world_path), seed=seed)
    while not h.done and h.now_s < MAX_S:
        h.tick()
    s = h.summary()
    t = h.truth
    beyond = (t.x - gap[0]) * normal[0] + (t.y - gap[1]) * normal[1] > 0.3
    passed = s["status"] == "success" and s["truth"]["collisions"] == 0 and beyond
    return {"name": name, "seed": seed, "passed": passed, "status": s["status"], "sim_s": s["sim_time_s"],
            "collisions": s["truth"]["collisions"], "clearance_m": s["truth"].get("min_clearance_m")}


def main() -> None:
    args, seeds, names = variant_arguments(__doc__.split("\n")[0], "every shape at every gap")
    names = names or [f"{s}:{g:.2f}" for g in GAPS for s in SHAPES]
    figures = Figures("tight_gap_variants")
    with tempfile.TemporaryDirectory() as tmp:
        results = run_jobs(run, [(n, seed, tmp) for n in names for seed in seeds], args.jobs)
    total = passed = collisions = 0
    for name in names:
        runs = [r for r in results if r["name"] == name]
        ok = [r for r in runs if r["passed"]]
        failed = [r for r in runs if not r["passed"]]
        total += len(runs)
        passed += len(ok)
        collisions += sum(r["collisions"] for r in runs)
        least = min(r["clearance_m"] for r in runs if r["clearance_m"] is not None)
        line = f"{name:28s} {len(ok)}/{len(runs)} passed"
        if ok:
            line += f", slowest {max(r['sim_s'] for r in ok):.0f} s"
        line += f", least clearance {least:.3f} m"
        if failed:
            line += "; failed: " + ", ".join(f"seed {r['seed']} {r['status']} at {r['sim_s']:.0f} s"
                                              + (f" ({r['collisions']} collisions)" if r["collisions"] else "")
                                              for r in failed)
        print(line)
        key = re.sub(r"[^a-z0-9]+", "_", name.lower())  # p33_n_o_ang_side_0_40
        figures.put(f"{key}.passed", len(ok))
        figures.put(f"{key}.least_clearance_m", least)
    print(f"passed {passed} of {total} runs, {collisions} collisions")
    figures.put("runs", total)
    figures.put("passed", passed)
    figures.put("collisions", collisions)
    figures.put("least_clearance_m", min(r["clearance_m"] for r in results if r["clearance_m"] is not None))
    figures.put("slowest_pass_s", max((r["sim_s"] for r in results if r["passed"]), default=math.nan))
    figures.save()


if __name__ == "__main__":
    main()
