"""The global planner: A* across a 40 m x 40 m map at 5 cm (800 x 800 cells), against plain Dijkstra in the same run.

The map is a floor plan: 8 x 8 rooms of 5 m, each wall with a 1 m door at a
random place (some walls without one), and random furniture (boxes and
columns) in the rooms; unknown outside the outer walls. The robot is the
simulator's (footprint radius 0.15 m) with the default ``global_planner:``.

Figures printed (nothing is asserted; medians over ``--reps`` repetitions):

1. **costmap**: the inflation (distance transform, costs, components) of the
   static map, done once per map, and the search graph's step costs (once per
   map and after a replan marks new lethal cells);
2. **A\\***: :func:`plan_path` from a corner room to the opposite one, and to
   a room half way, including the string pulling; cells settled;
3. **baselines**: SciPy's compiled Dijkstra on the same graph and the same step
   costs, without the heuristic and without stopping at the goal (what a
   planner gets from ``scipy.sparse.csgraph`` as it comes), and a textbook A*
   in plain Python (heapq, octile heuristic) on the same step costs, and the ratios;
4. the path's length against the baseline's (same costs: the cost-aware
   optimum) and the unshortened 8-connected one.

Run: python benchmarks/global_planner.py [--reps 7] [--seed 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from beastbt.mapping.occupancy_map import FREE, UNKNOWN, OccupancyMap, empty_map  # noqa: E402
from beastbt.mapping.rasterise import mark_outlines  # noqa: E402
from beastbt.navigation.global_planner import GlobalCostmap, GlobalPlannerConfig, plan_path  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)

FOOTPRINT_M = 0.15


def floor_plan(seed: int, size_m: float = 40.0, room_m: float = 5.0, res: float = 0.05) -> OccupancyMap:
    """A ``size_m`` square floor of rooms ``room_m`` wide with 1 m doors and furniture, 0.5 m of unknown round it."""
    rng = np.random.default_rng(seed)
    grid = empty_map(size_m + 1.0, size_m + 1.0, res, -0.5, -0.5, fill=UNKNOWN)
    data = grid.data.copy()
    data[10:-10, 10:-10] = FREE
    grid = grid.with_data(data)
    segments = [(0, 0, size_m, 0), (0, size_m, size_m, size_m), (0, 0, 0, size_m), (size_m, 0, size_m, size_m)]
    n = int(size_m / room_m)
    for i in range(1, n):
        for j in range(n):
            for vertical in (True, False):
                a, b = j * room_m, (j + 1) * room_m
                c = i * room_m
                if rng.random() < 0.15:  # no door in this wall
                    cuts = [(a, b)]
                else:
                    d = rng.uniform(a + 0.5, b - 1.5)
                    cuts = [(a, d), (d + 1.0, b)]
                for s, e in cuts:
                    segments.append((c, s, c, e) if vertical else (s, c, e, c))
    circles = []
    for _ in range(n * n):
        x, y = rng.uniform(0.8, size_m - 0.8, 2)
        if rng.random() < 0.5:
            circles.append((x, y, rng.uniform(0.1, 0.3)))
        else:
            w, h = rng.uniform(0.4, 1.5, 2)
            segments += [(x, y, x + w, y), (x, y + h, x + w, y + h), (x, y, x, y + h), (x + w, y, x + w, y + h)]
    return mark_outlines(grid, segments, circles)


def median_s(fn, reps: int) -> tuple[float, object]:
    """Median CPU time (s) of ``fn()`` over ``reps`` runs, and its result. CPU time of this process, not the wall
    clock: on a machine shared with other work the wall clock measures the others too (the search is single
    threaded, so on an idle machine the two agree)."""
    times, out = [], None
    for _ in range(reps):
        t = time.process_time()
        out = fn()
        times.append(time.process_time() - t)
    return statistics.median(times), out


def dijkstra_baseline(costmap: GlobalCostmap, start: tuple[float, float], goal: tuple[float, float]) -> float:
    """Plain Dijkstra (SciPy, no heuristic, every reachable cell) on the planner's own graph; the goal's cost."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    g = costmap.graph()
    matrix = csr_matrix((g.weights.ravel(), g.indices, g.indptr), shape=(g.n, g.n))
    col, row = costmap.grid.to_cells(*start)
    gcol, grow = costmap.grid.to_cells(*goal)
    dist = dijkstra(matrix, directed=True, indices=g.node(int(row), int(col)))
    return float(dist[g.node(int(grow), int(gcol))])


def python_astar(costmap: GlobalCostmap, start: tuple[float, float], goal: tuple[float, float]) -> float:
    """A textbook A* in plain Python (heapq, octile heuristic) on the planner's own step costs; the goal's cost
    (cells). What the planner would cost written the obvious way."""
    import heapq
    g = costmap.graph()
    col, row = costmap.grid.to_cells(*start)
    gcol, grow = costmap.grid.to_cells(*goal)
    s, t = g.node(int(row), int(col)), g.node(int(grow), int(gcol))
    weights = g.weights.tolist()
    nbrs = g.indices.reshape(-1, 8).tolist()
    cols = g.cols
    tr, tc = divmod(t, cols)
    best = {s: 0.0}
    closed = set()
    heap = [(0.0, 0.0, s)]
    while heap:
        _, d, u = heapq.heappop(heap)
        if u in closed:
            continue
        if u == t:
            return d
        closed.add(u)
        for v, w in zip(nbrs[u], weights[u]):
            nd = d + w
            if nd < best.get(v, float("inf")):
                best[v] = nd
                vr, vc = divmod(v, cols)
                dr, dc = abs(vr - tr), abs(vc - tc)
                heapq.heappush(heap, (nd + dr + dc + (1.4142135623730951 - 2.0) * min(dr, dc), nd, v))
    return float("inf")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    grid = floor_plan(args.seed)
    cfg = GlobalPlannerConfig()
    print(f"map: {grid.cols} x {grid.rows} cells at {grid.resolution_m} m, {np.count_nonzero(grid.occupied())} "
          f"occupied; footprint {FOOTPRINT_M} m, {cfg}")
    t_costmap, costmap = median_s(lambda: GlobalCostmap(grid, cfg, FOOTPRINT_M), args.reps)
    t_graph, _ = median_s(lambda: costmap.graph().set_costs(costmap.cost, cfg.cost_weight), args.reps)
    print(f"costmap (once per map): inflation {t_costmap * 1000:.0f} ms, step costs {t_graph * 1000:.0f} ms")
    figures = Figures("global_planner")  # saved for benchmarks/check_docs.py (benchmarks/figures.py prints them)
    figures.put("inflation_ms", t_costmap * 1000)
    figures.put("step_costs_ms", t_graph * 1000)
    start = (2.5, 2.5)
    for label, goal in (("corner to corner", (37.5, 37.5)), ("along one side", (37.5, 2.5)),
                        ("half way", (22.5, 17.5))):
        t_astar, path = median_s(lambda: plan_path(costmap, start, goal, 0.3), args.reps)
        t_raw, raw = median_s(lambda: plan_path(costmap, start, goal, 0.3, smooth=False), args.reps)
        t_base, _ = median_s(lambda: dijkstra_baseline(costmap, start, goal), args.reps)
        t_py, _ = median_s(lambda: python_astar(costmap, start, goal), args.reps)
        print(f"{label}: A* {t_astar * 1000:.0f} ms (search alone {t_raw * 1000:.0f} ms, {path.expanded} cells "
              f"settled of {grid.cols * grid.rows}), plain Dijkstra {t_base * 1000:.0f} ms: "
              f"A* is {t_base / t_astar:.1f}x faster; plain-Python heapq A* {t_py * 1000:.0f} ms "
              f"({t_py / t_astar:.0f}x slower); path {path.length_m:.2f} m shortened, "
              f"{raw.length_m:.2f} m 8-connected, straight line "
              f"{np.hypot(goal[0] - start[0], goal[1] - start[1]):.2f} m")
        key = label.replace(" ", "_")
        figures.put(f"{key}.astar_ms", t_astar * 1000)
        figures.put(f"{key}.settled_k", path.expanded / 1000)
        figures.put(f"{key}.dijkstra_ms", t_base * 1000)
        figures.put(f"{key}.python_astar_ms", t_py * 1000)
        figures.put(f"{key}.python_astar_ratio", t_py / t_astar)
        figures.put(f"{key}.path_m", path.length_m)
    print(f"(median CPU times over {args.reps} runs)")
    figures.save()


if __name__ == "__main__":
    main()
