"""The global costmap with memory and planning on it (GPS go_to), against baselines measured in the same run.

Figures printed (nothing is asserted; medians over ``--reps`` repetitions, CPU time of this process):

1. **a global plan on the 40 m window** (0.1 m cells, 400 x 400): :meth:`GlobalNavigator.plan` right after the
   obstacle layer changed (the costmap's inflation and step costs brought up to date, then A* with string
   pulling), for a fence across the way (worlds/field_fence.yaml's), a U-shaped dead end
   (worlds/field_dead_end.yaml's) and a field with 150 random boxes; the baseline is SciPy's plain Dijkstra on the
   same graph (no heuristic, every reachable cell), and the replan of a way that new marks block (a plan from
   scratch and the way mended on its side). Goal: at most 50 ms;
2. **per scan**: the obstacle layer's marking and ray-traced clearing of one 360-beam scan of the fence, against
   the local costmap's own work on the same scan (points kept, the 6 m grid rebuilt and inflated);
3. **the simulator's speed**: the patrol (missions/patrol.yaml, no go_to: the global costmap is never built)
   unrecorded at --speed max, sim s per CPU s (goal at least 100x), and the fence route
   (missions/fence_crossing.yaml) on the empty field and on the fenced one, where the robot plans about once a
   second while the fence is in the way;
4. **the narrowest gap** the global costmap plans through, by cell size, footprint padding and narrow gaps
   (global_planner.narrow_gaps) on or off: the width from which a gap passes wherever it falls on the grid, and the
   widest that never does (gaps 0.30-0.80 m in 2 cm steps, each at 4 offsets on the grid; the simulator's robot,
   footprint radius 0.15 m). benchmarks/tight_gaps.py drives the robot through them.

Run: python benchmarks/global_costmap.py [--reps 5] [--no-sim] [--only plans|scan|sim|gaps]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from beastbt.blackboard.types import LaserScan  # noqa: E402
from beastbt.devices.lidar_scan import LidarMounting, base_points_xy  # noqa: E402
from beastbt.navigation.global_navigator import GlobalNavigator, sample_polyline  # noqa: E402
from beastbt.navigation.global_planner import GlobalPlannerConfig, NoPath  # noqa: E402
from beastbt.navigation.local_costmap import LocalCostmapConfig, RollingCostmap  # noqa: E402
from beastbt.navigation.obstacle_layer import GlobalCostmapConfig  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)

FOOTPRINT_M = 0.15
MOUNT = LidarMounting(0.0, 0.0, 0.12, 0.0)
ANGLES = np.radians(np.arange(-180.0, 180.0, 1.0))
FENCE = [(-4.0, 8.0, -0.125, 8.0), (0.125, 8.0, 4.0, 8.0)]
U_SHAPE = [(-3.0, 8.0, -3.0, 13.0), (-3.0, 13.0, 3.0, 13.0), (3.0, 13.0, 3.0, 8.0)]


def median_s(fn, reps: int) -> tuple[float, object]:
    """Median CPU time (s) of ``fn()`` over ``reps`` runs, and its last result."""
    times, out = [], None
    for _ in range(reps):
        t = time.process_time()
        out = fn()
        times.append(time.process_time() - t)
    return statistics.median(times), out


def navigator() -> GlobalNavigator:
    return GlobalNavigator(GlobalCostmapConfig(), GlobalPlannerConfig(), FOOTPRINT_M, MOUNT)


def mark_segments(g: GlobalNavigator, segments) -> None:
    for x0, y0, x1, y1 in segments:
        pts = sample_polyline(np.array([[x0, y0], [x1, y1]]), 0.02)
        g.layer.mark_points(pts[:, 0], pts[:, 1])


def boxes(seed: int, n: int = 150) -> list:
    """``n`` random boxes (0.3-1.5 m a side) in the window, none within 1.5 m of the start or the goal."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < 4 * n:
        cx, cy = rng.uniform(-18, 18, 2)
        if math.hypot(cx, cy) < 1.5 or math.hypot(cx - 15.0, cy - 15.0) < 1.5:
            continue
        w, h = rng.uniform(0.3, 1.5, 2)
        out += [(cx - w / 2, cy - h / 2, cx + w / 2, cy - h / 2), (cx + w / 2, cy - h / 2, cx + w / 2, cy + h / 2),
                (cx + w / 2, cy + h / 2, cx - w / 2, cy + h / 2), (cx - w / 2, cy + h / 2, cx - w / 2, cy - h / 2)]
    return out


def dijkstra_baseline(g: GlobalNavigator, start, goal) -> float:
    """Plain Dijkstra (SciPy, no heuristic, every reachable cell) on the planner's graph; the goal's cost."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    cm = g.costmap()
    gr = cm.graph()
    matrix = csr_matrix((gr.weights.ravel(), gr.indices, gr.indptr), shape=(gr.n, gr.n))
    col, row = cm.grid.to_cells(*start)
    gcol, grow = cm.grid.to_cells(*goal)
    dist = dijkstra(matrix, directed=True, indices=gr.node(int(row), int(col)))
    return float(dist[gr.node(int(grow), int(gcol))])


def ranges_to(segments, pose) -> np.ndarray:
    """The range of each beam of :data:`ANGLES` from ``pose`` to the nearest segment (NaN: none within 12 m)."""
    x, y, yaw = pose
    out = np.full(len(ANGLES), np.nan)
    dx, dy = np.cos(ANGLES + yaw), np.sin(ANGLES + yaw)
    for x0, y0, x1, y1 in segments:
        ex, ey = x1 - x0, y1 - y0
        den = dx * ey - dy * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((x0 - x) * ey - (y0 - y) * ex) / den
            u = ((x0 - x) * dy - (y0 - y) * dx) / den
        hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1) & (t <= 12.0)
        out = np.where(hit & ~(out <= t), t, out)
    return out


def plans(figures: Figures, reps: int) -> None:
    print("1. a global plan on the 40 m window at 0.1 m (400 x 400 cells), CPU ms, median of", reps)
    for key, segments, start, goal in (("fence", FENCE, (0.0, 4.0), (0.0, 14.0)),
                                       ("dead_end", U_SHAPE, (0.0, 6.0), (0.0, 18.0)),
                                       ("boxes", boxes(1), (0.0, 0.0), (15.0, 15.0))):
        g = navigator()
        mark_segments(g, segments)
        g.plan(start, goal, 1.0, "warm up")           # SciPy imported, the graph built: once per run

        def changed_then_plan():
            g.layer.version += 1                        # a scan changed the layer: the costmap is brought up to date
            g.costmap().layer_version = -1
            g.costmap().lethal = g.costmap().static_lethal.copy()
            return g.plan(start, goal, 1.0, key)
        t_plan, path = median_s(changed_then_plan, reps)
        t_astar, _ = median_s(lambda: g.plan(start, goal, 1.0, key), reps)
        t_base, _ = median_s(lambda: dijkstra_baseline(g, start, goal), reps)
        print(f"   {key:9s} path {path.length_m:5.1f} m: plan after a change {t_plan * 1000:6.1f} ms, A* alone "
              f"{t_astar * 1000:6.1f} ms ({path.expanded / 1000:.0f}k cells settled); plain Dijkstra "
              f"{t_base * 1000:6.1f} ms (A* {t_base / t_astar:.1f}x quicker)")
        figures.put(f"plan.{key}.after_change_ms", t_plan * 1000)
        figures.put(f"plan.{key}.astar_ms", t_astar * 1000)
        figures.put(f"plan.{key}.dijkstra_ms", t_base * 1000)
        figures.put(f"plan.{key}.dijkstra_ratio", t_base / t_astar)
        figures.put(f"plan.{key}.path_m", path.length_m)


def mended(figures: Figures, reps: int) -> None:
    """A replan of a way that new marks block (:meth:`GlobalNavigator.replan`): a plan from scratch and the way
    mended on its side, as when more of a fence's end comes into view."""
    g = navigator()
    mark_segments(g, FENCE)
    start, goal = (0.3, 4.0), (0.0, 14.0)
    first = g.plan(start, goal, 1.0, "warm up")
    end_x = 1.0 if first.points[:, 0].max() > 4.0 else -1.0   # the end it went for grows by 1 m
    mark_segments(g, [(4.0 * end_x, 8.0, 5.0 * end_x, 8.0)])
    assert g.way_blocked(first.points, skip_m=g.inscribed_m)

    def changed_then_replan():
        g.layer.version += 1
        g.costmap().layer_version = -1
        g.costmap().lethal = g.costmap().static_lethal.copy()
        return g.replan(start, goal, 1.0, "far_side", first.points)
    t, path = median_s(changed_then_replan, reps)
    kept = (path.points[:, 0].max() > 5.0) == (end_x > 0)
    print(f"   fence, its end grown by 1 m across the way: replan after a change {t * 1000:6.1f} ms (a plan from "
          f"scratch and the way mended on its side; kept its side: {kept})")
    figures.put("plan.fence.mended_ms", t * 1000)


def per_scan(figures: Figures, reps: int) -> None:
    pose = (0.0, 6.0, math.pi / 2)                      # 2 m before the fence: both see it
    scan = LaserScan(0.0, ANGLES, ranges_to(FENCE, pose), np.zeros(len(ANGLES)), 10.0, "bench")
    g = navigator()
    g.observe(scan, pose)
    t_layer, _ = median_s(lambda: [g.observe(scan, pose) for _ in range(100)], reps)
    local = RollingCostmap(LocalCostmapConfig(), FOOTPRINT_M)
    pts = base_points_xy(scan, MOUNT)

    def local_scan():
        for i in range(100):
            local.add_scan(i * 0.1, pts, pose)
            local.build(i * 0.1, pose[:2])
    t_local, _ = median_s(local_scan, reps)
    print(f"2. per scan of the fence (360 beams): the obstacle layer {t_layer * 1e4:.0f} us, the local costmap "
          f"{t_local * 1e4:.0f} us (the layer is {t_layer / t_local:.2f}x the local costmap's work)")
    figures.put("scan.layer_us", t_layer * 1e4)
    figures.put("scan.local_costmap_us", t_local * 1e4)
    figures.put("scan.layer_ratio", t_layer / t_local)


def sim_speed(figures: Figures) -> None:
    """Simulated seconds per CPU second of this process (the wall clock, on a shared machine, measures the others
    too; on an idle one the two agree: the run is single threaded)."""
    from sim_speed import patrol  # noqa: E402  (benchmarks/sim_speed.py, beside this script)
    t = time.process_time()
    per_tick, ticks, factor = patrol()
    cpu = time.process_time() - t
    sim_s = factor * per_tick * ticks
    print(f"3. the patrol unrecorded at --speed max: {sim_s / cpu:.0f}x real time per CPU second, setup included "
          f"({factor:.0f}x by the wall clock here; goal at least 100x)")
    figures.put("sim.patrol_x", sim_s / cpu)
    from beastbt.testing import MissionHarness
    for key, world in (("empty", "field.yaml"), ("fence", "field_fence.yaml")):
        h = MissionHarness.from_file(REPO / "missions" / "fence_crossing.yaml", world=str(REPO / "worlds" / world),
                                     seed=1)
        t = time.process_time()
        h.run_to_end(timeout_s=600)
        cpu = time.process_time() - t
        s = h.summary()
        print(f"   the fence route on {world:16s}: {s['status']} in {s['sim_time_s']:.0f} s simulated, "
              f"{s['sim_time_s'] / cpu:.0f}x real time per CPU second (the harness, ticked from Python)")
        figures.put(f"sim.fence_route.{key}_x", s["sim_time_s"] / cpu)
        figures.put(f"sim.fence_route.{key}_sim_s", s["sim_time_s"])
    figures.put("sim.fence_route.ratio", figures.values["sim.fence_route.empty_x"]
                / figures.values["sim.fence_route.fence_x"])


def narrowest_gaps(figures: Figures) -> None:
    print("4. the narrowest gap the global costmap plans through (footprint radius 0.15 m):")
    gaps = np.round(np.arange(0.30, 0.801, 0.02), 2)
    for narrow in (True, False):
        for res in (0.05, 0.1, 0.2):
            for pad in (0.05, 0.0):
                if narrow and pad == 0.0:
                    continue  # no padding, no narrow band
                passes = []
                for gap in gaps:
                    n = 0
                    for off in np.linspace(0.0, res, 4, endpoint=False):
                        g = GlobalNavigator(GlobalCostmapConfig(width_m=20.0, resolution_m=res),
                                            GlobalPlannerConfig(footprint_padding_m=pad, narrow_gaps=narrow),
                                            FOOTPRINT_M, MOUNT)
                        xs = np.arange(-10.0, 10.0, 0.01) + off
                        xs = xs[np.abs(xs - off) > gap / 2]
                        g.layer.mark_points(xs, np.full(len(xs), 3.0))
                        try:
                            g.plan((0.0, 0.0), (0.0, 6.0), 0.0, "b")
                            n += 1
                        except NoPath:
                            pass
                    passes.append(n)
                always = next((float(gaps[i]) for i in range(len(gaps)) if all(p == 4 for p in passes[i:])),
                              math.nan)
                never = max((float(gaps[i]) for i in range(len(gaps)) if passes[i] == 0), default=math.nan)
                what = f"cells {res:.2f} m, padding {pad:.2f} m, narrow gaps {'on' if narrow else 'off'}"
                print(f"   {what}: passes every gap from {always:.2f} m; never {never:.2f} m or less"
                      if math.isfinite(never) else f"   {what}: passes every gap from {always:.2f} m; some at 0.30 m")
                key = f"gap.cells_{int(round(res * 100)):02d}cm.padding_{int(round(pad * 100)):02d}cm"
                if narrow:
                    key += ".narrow"
                figures.put(f"{key}.always_m", always)
                if math.isfinite(never):
                    figures.put(f"{key}.never_m", never)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--no-sim", action="store_true", help="leave out the simulator runs (part 3)")
    ap.add_argument("--only", choices=("plans", "scan", "sim", "gaps"), help="one part only (1, 2, 3 or 4)")
    args = ap.parse_args()
    figures = Figures("global_costmap")
    if args.only in (None, "plans"):
        plans(figures, args.reps)
        mended(figures, args.reps)
    if args.only in (None, "scan"):
        per_scan(figures, args.reps)
    if args.only == "sim" or (args.only is None and not args.no_sim):
        sim_speed(figures)
    if args.only in (None, "gaps"):
        narrowest_gaps(figures)
    figures.save()


if __name__ == "__main__":
    main()
