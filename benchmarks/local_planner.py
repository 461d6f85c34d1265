"""The local planner: its cost per tick, and plain DWA against DWA on a navigation function, on the same obstacles.

Three measurements, each printing figures (nothing is asserted):

1. **Cost per 20 Hz tick** of :meth:`DwaPlanner.plan` on a costmap with a
   bench 1 m ahead: in the open (the preference's arc meets nothing: one arc
   checked), plain DWA (``navigation_function: false``), and DWA on the
   navigation function, on a tick that computes it (a new scan) and on one
   that reuses it (the second tick of a 10 Hz scan). The ratio against plain
   DWA is measured in the same run.
2. **Benches on a plane**: a unicycle driven by the planner at 10 Hz from the
   origin to a goal 3 m ahead, with a bench across the way (widths 0.6 to
   2.4 m, offsets -0.6 to 0.6 m from the line): how many reach the goal
   within 60 s, their median time and the closest approach of the robot's
   centre to the bench, for both planners on the same benches.
3. **The campus route** (``missions/gps_route.yaml`` on
   ``worlds/campus_obstacles.yaml``, the issue's scenario) on the simulator,
   seeds 1..N (``--seeds``, 0 to skip), with both planners (the profile's
   ``local_planner: {navigation_function: false}`` for plain DWA), and the
   same route on ``worlds/campus.yaml`` as the reference time.

Run: python benchmarks/local_planner.py [--seeds 1]
"""

from __future__ import annotations

import argparse
import math
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from beastbt.navigation.local_costmap import LocalCostmapConfig, RollingCostmap  # noqa: E402
from beastbt.navigation.local_planner import DwaPlanner, Limits, LocalPlannerConfig  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)

LIMITS = Limits(max_speed_mps=0.35, max_turn_rate_rps=math.radians(120), max_accel_mps2=1.0,
                max_angular_accel_rps2=math.radians(360))
FOOTPRINT_M = 0.15


def bench_points(x: float, width: float, offset: float, depth: float = 0.4, step: float = 0.03) -> np.ndarray:
    """The outline of a bench across the x axis: from ``x`` to ``x + depth``, ``width`` long, centred on ``offset``."""
    xs = np.arange(x, x + depth + 1e-9, step)
    ys = np.arange(offset - width / 2, offset + width / 2 + 1e-9, step)
    return np.concatenate((np.column_stack((xs, np.full_like(xs, ys[0]))),
                           np.column_stack((xs, np.full_like(xs, ys[-1]))),
                           np.column_stack((np.full_like(ys, x), ys)),
                           np.column_stack((np.full_like(ys, x + depth), ys))))


def costmap_of(points: np.ndarray, centre: tuple[float, float]) -> RollingCostmap:
    cm = RollingCostmap(LocalCostmapConfig(), FOOTPRINT_M)
    cm.add_scan(0.0, points, (0.0, 0.0, 0.0))
    cm.build(0.0, centre)
    return cm


def pursue(pose: tuple[float, float, float], goal: tuple[float, float], speed: float) -> tuple[float, float]:
    """A plain pure pursuit toward ``goal`` (what go_to prefers)."""
    alpha = math.atan2(goal[1] - pose[1], goal[0] - pose[0]) - pose[2]
    alpha = (alpha + math.pi) % (2 * math.pi) - math.pi
    if abs(alpha) > math.radians(50):
        return 0.0, math.copysign(1.0, alpha)
    ld = max(math.hypot(goal[0] - pose[0], goal[1] - pose[1]), 1e-3)
    return speed, speed * 2.0 * math.sin(alpha) / ld


def per_tick(repeats: int) -> None:
    bench = bench_points(0.7, 1.6, 0.0)
    cm = costmap_of(bench, (0.0, 0.0))
    empty = costmap_of(np.zeros((0, 2)), (0.0, 0.0))
    pose, last, goal = (0.0, 0.0, 0.0), (0.2, 0.0), (3.0, 0.0)
    results = {}
    for name, cfg, pref in (("open (preference unchanged)", LocalPlannerConfig(), (0.2, 0.0)),
                            ("plain DWA", LocalPlannerConfig(navigation_function=False), (0.2, 0.0)),
                            ("DWA + navigation function, new scan", LocalPlannerConfig(), (0.2, 0.0)),
                            ("DWA + navigation function, same scan", LocalPlannerConfig(), (0.2, 0.0))):
        planner = DwaPlanner(cfg, LIMITS)
        same = name.endswith("same scan")
        times = []
        for _ in range(repeats):
            if not same:
                planner._nf_for = None  # a new scan: the navigation function is computed again
            grid = empty.latest if name.startswith("open") else cm.latest
            t0 = time.perf_counter()
            planner.plan(grid, pose, last, pref, goal, 0.3, LIMITS.max_turn_rate_rps, goal)
            times.append(time.perf_counter() - t0)
        results[name] = statistics.median(times) * 1e6
    base = results["plain DWA"]
    print("Cost per tick (median, a bench 0.7 m ahead; 9 x 25 twists + 2, 1.7 s arcs in 0.1 s steps):")
    for name, us in results.items():
        print(f"  {name:38s} {us:7.0f} us  (ratio to plain DWA {us / base:.2f})")
    per_s = (results["DWA + navigation function, new scan"] * 10 + results["DWA + navigation function, same scan"] * 10)
    print(f"  while going round (10 Hz scans, 20 Hz ticks): {per_s / 1e4:.2f} % of a core; in the open "
          f"{results['open (preference unchanged)'] * 20 / 1e4:.3f} %")
    for name, us in results.items():
        key = re.sub(r"[^a-z0-9]+", "_", name.lower().replace("(preference unchanged)", "")).strip("_")
        FIGURES.put(f"tick.{key}_us", us)
        FIGURES.put(f"tick.{key}_ratio", us / base)
    FIGURES.put("going_round_pct", per_s / 1e4)
    FIGURES.put("open_pct", results["open (preference unchanged)"] * 20 / 1e4)


FIGURES = Figures("local_planner")
"""The figures this run prints, saved at its end for benchmarks/check_docs.py (benchmarks/figures.py)."""


def drive(planner: DwaPlanner, cm: RollingCostmap, points: np.ndarray, goal: tuple[float, float], seconds: float = 60.0,
          dt: float = 0.1) -> tuple[bool, float, float]:
    """(reached, time s, closest approach of the centre to ``points`` m) of a unicycle driven by ``planner``."""
    pose, last, t, least = (0.0, 0.0, 0.0), (0.0, 0.0), 0.0, math.inf
    while t < seconds:
        if math.hypot(goal[0] - pose[0], goal[1] - pose[1]) <= 0.2:
            return True, t, least
        plan = planner.plan(cm.latest, pose, last, pursue(pose, goal, 0.3), goal, 0.3, LIMITS.max_turn_rate_rps, goal)
        v, w = plan.linear_mps, plan.angular_rps
        x, y, th = pose
        pose = (x + v * dt * math.cos(th + w * dt / 2), y + v * dt * math.sin(th + w * dt / 2), th + w * dt)
        last = (v, w)
        least = min(least, float(np.min(np.hypot(points[:, 0] - pose[0], points[:, 1] - pose[1]))))
        t += dt
    return False, t, least


def benches() -> None:
    cases = [(w, o) for w in (0.6, 1.2, 1.8, 2.4) for o in (-0.6, -0.3, 0.0, 0.3, 0.6)]
    print(f"\nBenches on a plane ({len(cases)}: widths 0.6-2.4 m, offsets -0.6-0.6 m, 1.5 m ahead, goal 3 m ahead):")
    inscribed = FOOTPRINT_M + LocalCostmapConfig().footprint_padding_m
    for name, cfg in (("plain DWA", LocalPlannerConfig(navigation_function=False)),
                      ("DWA + navigation function", LocalPlannerConfig())):
        reached, times, least = 0, [], []
        for width, offset in cases:
            pts = bench_points(1.5, width, offset)
            cm = costmap_of(pts, (1.5, 0.0))
            ok, t, closest = drive(DwaPlanner(cfg, LIMITS), cm, pts, (3.0, 0.0))
            reached += ok
            least.append(closest)
            if ok:
                times.append(t)
        median = statistics.median(times) if times else 0.0
        print(f"  {name:26s} reached {reached}/{len(cases)}, median time {median:.1f} s, "
              f"closest approach {min(least):.2f} m (inscribed {inscribed:.2f} m)")
        key = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        FIGURES.put(f"benches.{key}.reached", reached)
        FIGURES.put(f"benches.{key}.median_s", median)
        FIGURES.put(f"benches.{key}.closest_m", min(least))


def campus(seeds: int) -> None:
    from beastbt.testing import MissionHarness

    if seeds <= 0:
        return
    folder = Path(tempfile.mkdtemp())
    profile = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    profile["local_planner"] = {"navigation_function": False}
    plain = folder / "plain_dwa.yaml"
    plain.write_text(yaml.safe_dump(profile, sort_keys=False), encoding="utf-8")
    print(f"\nThe campus route (missions/gps_route.yaml), seeds 1-{seeds}: status, sim time, ratio to the empty lawn, "
          f"collisions, min clearance:")
    for seed in range(1, seeds + 1):
        rows = {}
        for name, world, robot in (("empty lawn", "campus.yaml", "sim"),
                                   ("plain DWA", "campus_obstacles.yaml", str(plain)),
                                   ("DWA + navigation function", "campus_obstacles.yaml", "sim")):
            h = MissionHarness.from_file(REPO / "missions" / "gps_route.yaml", robot=robot,
                                         world=str(REPO / "worlds" / world), seed=seed)
            h.run_to_end(timeout_s=1500)
            rows[name] = h.summary()
        ref = rows["empty lawn"]["sim_time_s"]
        for name, s in rows.items():
            truth = s.get("truth", {})
            print(f"  seed {seed} {name:26s} {s['status']:8s} {s['sim_time_s']:6.1f} s  x{s['sim_time_s'] / ref:.2f}  "
                  f"collisions {truth.get('collisions')}  min clearance {truth.get('min_clearance_m')}")
            if s["status"] != "success":
                fails = [e["text"] for e in s["events"] if e["kind"] == "step_failed"]
                print(f"      {fails[:1]}")
            key = f"campus.seed{seed}.{re.sub(r'[^a-z0-9]+', '_', name.lower()).strip('_')}"
            FIGURES.put(f"{key}.sim_s", s["sim_time_s"])
            FIGURES.put(f"{key}.ratio", s["sim_time_s"] / ref)
            FIGURES.put(f"{key}.success", int(s["status"] == "success"))
            FIGURES.put(f"{key}.collisions", truth.get("collisions") or 0)
            if truth.get("min_clearance_m") is not None:
                FIGURES.put(f"{key}.min_clearance_m", truth["min_clearance_m"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300)
    parser.add_argument("--seeds", type=int, default=1, help="campus route seeds (0: skip the simulator runs)")
    args = parser.parse_args()
    per_tick(args.repeats)
    benches()
    campus(args.seeds)
    FIGURES.save()


if __name__ == "__main__":
    main()
