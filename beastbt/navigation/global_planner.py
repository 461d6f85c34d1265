"""The global planner: A* on a saved map, inflated by the robot's footprint, like Nav2's planner server.

:class:`GlobalCostmap` turns an :class:`~beastbt.mapping.occupancy_map.OccupancyMap`
into Nav2's costs, once per map (and again when new lethal cells are marked):

* **lethal** (:data:`COST_LETHAL`): occupied cells, and unknown ones unless
  ``allow_unknown`` (Nav2's ``allow_unknown: false``, the default);
* **inscribed** (:data:`COST_INSCRIBED`): cells whose centre lies within the
  footprint radius plus ``footprint_padding_m`` of a lethal cell: the robot's
  centre there would touch the wall, so they are as impassable as lethal ones;
* **narrow** (:data:`COST_NARROW`, with ``narrow_gaps``): of those, the cells
  farther than the footprint radius plus half a cell (where in its cell the
  obstacle lies) from every obstacle: only the padding would touch. They are
  passable at the highest cost, so that a gap at least the robot's width plus a
  little is taken when it is the way, and not when a way round costs little
  more. With a finer grid of the obstacles beside the cells (``fine``, kept by
  the obstacle layer) the clearance is measured on it (along the cell's best
  fine column, row or diagonal line, less half a fine cell): a 0.1 m cell alone
  cannot tell a 0.32 m gap from a 0.40 m one, and a gap at a slant to the cells
  is crossed on the slant;
* **inflated**: beyond, up to ``inflation_radius_m``, ``252 * exp(-cost_scaling_factor * (d - inscribed))``
  as in Nav2's ``inflation_layer`` (the distance ``d`` from ``cv2.distanceTransform``, exact Euclidean).

:func:`plan_path` searches the 8-connected grid with A* (octile heuristic; a
diagonal step may not cut the corner of an impassable cell). A step costs its
length times ``1 + cost_weight * cost / 252`` (Smac's
``cost_travel_multiplier``), so the path keeps off walls where there is room
and passes doors through their middle. The search is SciPy's compiled
Dijkstra (:func:`scipy.sparse.csgraph.dijkstra`) on *reduced* step costs
``w(u, v) - h(u) + h(v)`` with ``h`` the heuristic: Dijkstra on reduced costs
expands the nodes in the order A* does (the textbook equivalence of A* with a
consistent heuristic), and its ``limit`` stops the search round the start once
the goal is settled (the limit grows fourfold until it is). The grid's edges
are built once per map shape, vectorised. The 8-connected path is then
shortened (string pulling: a point is dropped when the straight line past it
crosses no cell costlier than the path it replaces, so shortcuts never go
nearer the walls) and the result is a list of map-frame points.

An impossible goal fails at once with :class:`NoPath`, whose ``reason`` names
why: off the map, in an occupied or unknown cell, too near a wall for the
robot, or enclosed (not connected to the start: a connected-components label
of the passable cells answers that without a search; 4-connected, which is
how the search moves, since a diagonal step never cuts a corner).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional, Sequence

import cv2
import numpy as np

from beastbt.blackboard.types import COST_INSCRIBED, COST_LETHAL
from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults
from beastbt.mapping.occupancy_map import OccupancyMap
from beastbt.navigation.local_costmap import COST_NARROW, between_obstacles

SQRT2 = math.sqrt(2.0)
_OFFSETS = ((0, 1, 1.0), (1, 0, 1.0), (0, -1, 1.0), (-1, 0, 1.0), (1, 1, SQRT2), (1, -1, SQRT2), (-1, 1, SQRT2),
            (-1, -1, SQRT2))
"""(d_row, d_col, length in cells) of the 8 neighbours."""

MAX_COST = 252.0
"""The highest cost of a passable cell (Nav2's MAX_NON_OBSTACLE)."""


@dataclass(frozen=True)
@schema_defaults("parts/global_planner.schema.json")
class GlobalPlannerConfig:
    """The profile's ``global_planner:`` section (Nav2's global costmap and planner knobs), metres and seconds."""

    footprint_padding_m: float
    """Added to the footprint radius for the inscribed (impassable) zone round walls (m)."""
    inflation_radius_m: float
    """Cells this close to a wall get a cost that falls off with the distance (m)."""
    cost_scaling_factor: float
    """How fast the inflated cost falls off beyond the inscribed radius (1/m)."""
    cost_weight: float
    """A step costs its length times 1 + cost_weight * cost / 252: 0 takes the shortest way, larger keeps off
    walls more (Smac's cost_travel_multiplier)."""
    allow_unknown: bool
    """Whether the path may cross cells the map does not know (Nav2's allow_unknown)."""
    replan_period_s: float
    """The path is planned again this often while following it (s); 0: only when blocked."""
    blocked_replan_s: float
    """Replan when the robot has made no progress along the path for this long (s)."""
    lookahead_m: float
    """go_to on a map steers toward a carrot this far ahead along the path (m): shorter than outdoors (navigation's
    lookahead_m), so that it turns through a door instead of cutting the door's corner."""
    replan_off_path_m: float
    """Plan again when the robot is this far from the path (m)."""
    default_tolerance_m: float
    """A place on the map counts as reached this close when neither the place nor the step says (m)."""
    start_search_m: float
    """A start in the inscribed zone (the robot close to a wall) plans from the nearest passable cell within this
    distance (m)."""
    narrow_gaps: bool
    """Cells within the padding but farther than the footprint radius from an obstacle are passable at the highest
    cost (true), or impassable like the rest of the inscribed zone (false)."""

    def __post_init__(self) -> None:
        for name in ("inflation_radius_m", "cost_scaling_factor", "blocked_replan_s", "default_tolerance_m",
                     "lookahead_m", "replan_off_path_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"global_planner: '{name}' must be > 0, got {getattr(self, name)}")
        for name in ("footprint_padding_m", "cost_weight", "replan_period_s", "start_search_m"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"global_planner: '{name}' must be >= 0, got {getattr(self, name)}")

    @classmethod
    def from_dict(cls, d: Any) -> "GlobalPlannerConfig":
        """Build from a profile's ``global_planner:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "global_planner")


class NoPath(Exception):
    """No path to the goal; ``reason`` says why in words (``the goal lies in an occupied cell``)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class GlobalPath:
    """A planned path: ``points`` (n, 2) map-frame metres from the start to the goal, its ``length_m``,
    and the cells A* settled (``expanded``, for the benchmark)."""

    points: np.ndarray
    length_m: float
    expanded: int


class GlobalCostmap:
    """The static map's costs for a robot of ``footprint_radius_m`` (m), as Nav2's global costmap.

    ``cost`` is uint8 (rows, cols) in the map's cell order: 254 lethal, 253
    inscribed, 0..252 inflated. :meth:`mark_lethal` adds cells found blocked
    since (a door closed) and recomputes the costs.
    """

    def __init__(self, grid: OccupancyMap, config: GlobalPlannerConfig, footprint_radius_m: float) -> None:
        self.grid = grid
        self.config = config
        self.footprint_radius_m = footprint_radius_m
        self.inscribed_m = footprint_radius_m + config.footprint_padding_m
        self.fine: Optional[np.ndarray] = None
        """Obstacles on a finer grid (f rows, f cols a cell; an obstacle layer's ``fine``), or None."""
        lethal = grid.occupied()
        if not config.allow_unknown:
            lethal = lethal | grid.unknown()
        self.static_lethal = lethal
        """The map's own lethal cells (occupied, and unknown unless allowed)."""
        self.lethal = lethal
        self.layer_version = -1
        """The obstacle layer's version the costs were last computed with (:meth:`set_obstacles`)."""
        self._graph: Optional[_Graph] = None
        self._coarse: Optional[_Graph] = None
        self._update()

    def _update(self) -> None:
        cfg, res = self.config, self.grid.resolution_m
        src = np.where(self.lethal, 0, 255).astype(np.uint8)
        # Distance (m) from each cell's centre to the nearest lethal cell's centre (exact Euclidean).
        self.distance_m = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * res
        d = self.distance_m
        inflated = np.floor(MAX_COST * np.exp(-cfg.cost_scaling_factor * (d - self.inscribed_m)))
        cost = np.where(d <= cfg.inflation_radius_m, np.minimum(inflated, MAX_COST), 0.0)
        cost = np.where(d <= self.inscribed_m, COST_INSCRIBED, cost)
        cost[self.lethal] = COST_LETHAL
        self.narrow_ready = not cfg.narrow_gaps
        """Whether the narrow cells are in :attr:`cost` (or need not be): with a fine grid they are measured only
        when a plan asks (:meth:`add_narrow`)."""
        if cfg.narrow_gaps and self.fine is None:
            self._set_cost(self._with_narrow(cost))
            self.narrow_ready = True
        else:
            self._set_cost(cost)

    def add_narrow(self) -> bool:
        """Bring the narrow cells into the costs (measured on the fine grid); False when they already were."""
        if self.narrow_ready:
            return False
        self._set_cost(self._with_narrow(self.cost))
        self.narrow_ready = True
        return True

    def _with_narrow(self, cost: np.ndarray, slack_m: float = 0.0) -> np.ndarray:
        """``cost`` with the inscribed cells clear of the footprint by half a cell of the grid the clearance was
        measured on (where in its cell the obstacle lies), less ``slack_m`` (m), made narrow."""
        inscribed = cost == COST_INSCRIBED
        clearance, cell_m = self._clearance_m(inscribed)
        narrow = inscribed & (clearance > self.footprint_radius_m + cell_m / 2.0 - slack_m + 1e-9)
        return np.where(narrow, COST_NARROW, cost)

    def relax_narrow(self, slack_m: float) -> Optional[np.ndarray]:
        """Make narrow the inscribed cells that are so with ``slack_m`` (m) less clearance (a gap seen from afar that
        may be wide enough: :class:`~beastbt.navigation.global_navigator.GlobalNavigator` goes to look); the costs
        before, to give back to :meth:`restore`, or None when no cell changed (nothing is relaxed then)."""
        before = self.cost
        relaxed = self._with_narrow(before, slack_m)
        if np.array_equal(relaxed, before):
            return None
        self._set_cost(relaxed)
        return before

    def restore(self, cost: np.ndarray) -> None:
        """Put back the costs :meth:`relax_narrow` returned."""
        self._set_cost(cost)

    def _set_cost(self, cost: np.ndarray) -> None:
        self.cost = cost.astype(np.uint8)
        self.passable = self.cost < COST_INSCRIBED
        # Which passable cells can reach which, as the search moves: 4-connected components. The search steps
        # diagonally too, but never across the corner of an impassable cell, so a diagonal step joins only cells
        # that two straight steps join as well; 8-connected labels would join a door closed to a diagonal thread
        # of free cells, and the goal would then fail in the search ("no way") instead of at once, named.
        _, self.labels = cv2.connectedComponents(self.passable.astype(np.uint8), connectivity=4)
        if self._graph is not None:
            self._graph.set_costs(self.cost, self.config.cost_weight)

    def _clearance_m(self, candidates: np.ndarray) -> tuple[np.ndarray, float]:
        """The clearance (m) of the ``candidates`` cells (bool, the map's shape) as well as the grids tell, and the
        cell (m) it was measured on; 0 elsewhere with ``fine``.

        Without ``fine``, the distance from each cell's centre (:attr:`distance_m`). With it, on the fine grid (the
        map's lethal cells, whole, among its obstacles), for the candidates between obstacles only (a gap: lethal
        cells within reach on two opposite sides; a band along one wall is never needed to get through): the robot
        crosses a cell along one of its fine columns or rows, so a cell's clearance is the best over its fine
        columns of the least over the column's fine cells, or the same over its rows (a fine cell beside the wall's
        line must not lend its clearance to the cell on it), or over its diagonal lines of fine cells (each as long
        as the cell's diagonal, :func:`_diagonal_clearance`): a gap at 45 degrees to the cells (the odom frame turns
        with the robot's heading at the start) measures 0.7 times its width along a column. The distance transform runs on a box round each group
        of such cells (with a margin beyond the inscribed radius, so the distances that matter are exact)."""
        res = self.grid.resolution_m
        if self.fine is None:
            return self.distance_m, res
        rows, cols = self.lethal.shape
        f = self.fine.shape[0] // rows
        clearance = np.zeros((rows, cols), np.float32)
        reach = int(math.ceil(2.0 * self.inscribed_m / res)) + 1  # the far side of a gap the padding would close
        wanted = (candidates & between_obstacles(self.lethal, reach)).astype(np.uint8)
        n, _, stats, _ = cv2.connectedComponentsWithStats(wanted, connectivity=8)
        m = reach + 1
        for c0, r0, w, h, _ in stats[1:]:
            r0, r1 = max(0, int(r0) - m), min(rows, int(r0 + h) + m)
            c0, c1 = max(0, int(c0) - m), min(cols, int(c0 + w) + m)
            static = np.repeat(np.repeat(self.static_lethal[r0:r1, c0:c1], f, axis=0), f, axis=1)
            obstacles = self.fine[f * r0:f * r1, f * c0:f * c1] | static
            src = np.where(obstacles, 0, 255).astype(np.uint8)
            d = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            R, C = r1 - r0, c1 - c0
            along_columns = d.reshape(R, f, C * f).min(axis=1).reshape(R, C, f).max(axis=2)
            along_rows = d.reshape(R * f, C, f).min(axis=2).reshape(R, f, C).max(axis=1)
            # Across either diagonal too: a gap at a slant to the grid (the odom frame turns with the robot's
            # heading at the start) is crossed on the slant, and along a column it looks narrower than it is (by
            # cos 45 degrees at worst).
            along_diagonals = np.maximum(_diagonal_clearance(d, R, C, f),
                                         _diagonal_clearance(d[:, ::-1], R, C, f)[:, ::-1])
            best = np.maximum(np.maximum(along_columns, along_rows), along_diagonals)
            box = clearance[r0:r1, c0:c1]
            np.maximum(box, best * np.float32(res / f), out=box)
        return clearance, res / f

    def set_obstacles(self, marked: np.ndarray, version: int, grid: Optional[OccupancyMap] = None,
                      fine: Optional[np.ndarray] = None) -> bool:
        """The map's lethal cells plus those ``marked`` by an obstacle layer (a bool array of the map's shape; its
        ``version``), on ``grid`` when the window moved (same shape, another origin), with the layer's fine marks
        ``fine`` (a whole number of times the rows and columns) when it keeps them. The costs are recomputed when the
        lethal cells or the fine marks changed; True when they were."""
        if grid is not None:
            if grid.data.shape != self.grid.data.shape:
                raise ValueError("GlobalCostmap.set_obstacles: the grid's shape may not change")
            self.grid = grid
        self.layer_version = version
        lethal = self.static_lethal | marked
        fine_changed = fine is not None and (self.fine is None or not np.array_equal(fine, self.fine))
        if fine is not None:
            self.fine = fine.copy() if fine_changed else self.fine
        if np.array_equal(lethal, self.lethal) and not fine_changed:
            return False
        self.lethal = lethal
        self._update()
        return True

    def mark_lethal(self, x: np.ndarray, y: np.ndarray) -> int:
        """Mark the cells holding map-frame points (m) lethal (something is there the map did not show); the number
        of cells newly marked. Costs are recomputed when any is."""
        col, row = self.grid.to_cells(x, y)
        keep = self.grid.inside(col, row)
        col, row = col[keep], row[keep]
        new = ~self.lethal[row, col]
        if not new.any():
            return 0
        lethal = self.lethal.copy()
        lethal[row[new], col[new]] = True
        self.lethal = lethal
        if self.fine is not None:  # the whole cells, on the fine grid too
            fine = self.fine.copy()
            f = fine.shape[0] // self.lethal.shape[0]
            for dr in range(f):
                for dc in range(f):
                    fine[f * row[new] + dr, f * col[new] + dc] = True
            self.fine = fine
        self._update()
        return int(np.count_nonzero(new))

    def graph(self) -> "_Graph":
        """The search graph of this costmap (built on first use)."""
        if self._graph is None:
            self._graph = _Graph(self.cost.shape)
            self._graph.set_costs(self.cost, self.config.cost_weight)
        return self._graph

    def coarse_graph(self, shape: tuple[int, int]) -> "_Graph":
        """The graph of the heuristic's coarse grid of ``shape`` blocks (built on first use)."""
        if self._coarse is None or (self._coarse.rows - 2, self._coarse.cols - 2) != shape:
            self._coarse = _Graph(shape)
        return self._coarse

    def cost_at(self, x: float, y: float) -> int:
        """The cost of the cell holding map-frame point (x, y) (m); lethal off the map."""
        col, row = self.grid.to_cells(x, y)
        if not self.grid.inside(col, row):
            return COST_LETHAL
        return int(self.cost[int(row), int(col)])


def _diagonal_clearance(d: np.ndarray, rows: int, cols: int, f: int) -> np.ndarray:
    """Per cell of a (``rows``, ``cols``) grid whose fine grid ``d`` ((f rows, f cols) a cell) holds the distances to
    the nearest obstacle: the best, over the lines of fine cells through the cell along the diagonal (row and column
    rising together), of the least distance on the line from the cell's first fine row and column to its last (the
    cell crossed diagonally, as a column crosses it from its first fine row to its last: a line through the cell's
    corner runs on beyond it; those beyond the grid count 0)."""
    pad = 2 * f
    padded = np.pad(d, pad, constant_values=0)
    best = np.zeros((rows, cols), d.dtype)
    for k in range(-(f - 1), f):  # the line of fine cells j - i = k in the cell's own (i row, j column)
        line = np.full((rows, cols), np.inf, d.dtype)
        for i in range(min(0, -k), max(f, f - k)):  # every fine row of the cell, and every fine column
            j = i + k
            np.minimum(line, padded[pad + i:pad + i + rows * f:f, pad + j:pad + j + cols * f:f], out=line)
        np.maximum(best, line, out=best)
    return best


class _Graph:
    """The 8-connected grid as a CSR matrix of (rows + 2) x (cols + 2) nodes (a one-cell impassable border, so every
    cell has 8 neighbours), its step costs set per costmap."""

    def __init__(self, shape: tuple[int, int]) -> None:
        rows, cols = shape
        self.rows, self.cols = rows + 2, cols + 2
        n = self.rows * self.cols
        self.n = n
        node = np.arange(n, dtype=np.int64)
        nbr = np.empty((n, 8), dtype=np.int32)
        for k, (dr, dc, _) in enumerate(_OFFSETS):
            nbr[:, k] = np.clip(node + dr * self.cols + dc, 0, n - 1)
        self.indices = nbr.ravel()
        self.indptr = np.arange(0, 8 * n + 1, 8, dtype=np.int32)
        self.length = np.array([o[2] for o in _OFFSETS])
        self.weights = np.full((n, 8), np.inf)

    def set_costs(self, cost: np.ndarray, cost_weight: float) -> None:
        """Step costs (cells): length * (1 + cost_weight * mean cost of the two cells / 252); inf into or across an
        impassable cell."""
        R, C = self.rows, self.cols
        pad = np.full((R, C), float(COST_LETHAL))
        pad[1:-1, 1:-1] = cost
        mult = 1.0 + cost_weight * np.minimum(pad, MAX_COST) / MAX_COST
        blocked = pad >= COST_INSCRIBED
        w = np.full((R, C, 8), np.inf)
        inner = (slice(1, -1), slice(1, -1))
        for k, (dr, dc, length) in enumerate(_OFFSETS):
            there = (slice(1 + dr, R - 1 + dr), slice(1 + dc, C - 1 + dc))
            step = length * 0.5 * (mult[inner] + mult[there])
            bad = blocked[inner] | blocked[there]
            if dr and dc:  # no cutting the corner of an impassable cell
                bad = bad | blocked[1 + dr:R - 1 + dr, 1:-1] | blocked[1:-1, 1 + dc:C - 1 + dc]
            w[1:-1, 1:-1, k] = np.where(bad, np.inf, step)
        self.weights = w.reshape(-1, 8)

    def node(self, row: int, col: int) -> int:
        """The node of map cell (row, col)."""
        return (row + 1) * self.cols + col + 1

    def cell(self, node: int) -> tuple[int, int]:
        """The map cell (row, col) of a node."""
        r, c = divmod(int(node), self.cols)
        return r - 1, c - 1

    def search(self, start: int, goal: int, h: np.ndarray) -> tuple[list[int], int]:
        """A* from ``start`` to ``goal`` (nodes) with the heuristic ``h`` ((rows, cols) of this graph, cells); the
        nodes of the cheapest path and the number settled. Raises :class:`NoPath` when there is none."""
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import dijkstra

        R, C = self.rows, self.cols
        reduced = self.weights.reshape(R, C, 8).copy()  # the border's steps stay inf
        here = h[1:-1, 1:-1]
        for k, (dr, dc, _) in enumerate(_OFFSETS):
            reduced[1:-1, 1:-1, k] += h[1 + dr:R - 1 + dr, 1 + dc:C - 1 + dc] - here
        # An inconsistent heuristic can make a reduced cost negative, which Dijkstra refuses: clipped at 0.
        np.maximum(reduced, 0.0, out=reduced)
        matrix = csr_matrix((reduced.ravel(), self.indices, self.indptr), shape=(self.n, self.n))
        limit = 8.0 + 0.045 * float(h.flat[start])
        while True:
            dist, pred = dijkstra(matrix, directed=True, indices=start, return_predecessors=True, limit=limit)
            if np.isfinite(dist[goal]):
                break
            if not np.isfinite(limit):
                raise NoPath("no way to the goal")
            # Everything within the limit is settled and the goal is not among it: look farther.
            limit = limit * 1.5 if limit < 8.0 * self.n else np.inf
        nodes = [goal]
        while nodes[-1] != start:
            nodes.append(int(pred[nodes[-1]]))
        nodes.reverse()
        return nodes, int(np.count_nonzero(np.isfinite(dist)))


COARSE = 4
HEURISTIC_SCALE = 0.95
"""The coarse estimate is scaled by this: a little below 1 keeps it from overestimating much where a block's mean
cost is above the cheapest way through it."""
"""Cells per side of a block of the coarse grid whose cost-aware distances guide A* (Smac's obstacle heuristic)."""


def heuristic(costmap: "GlobalCostmap", goal: tuple[int, int]) -> np.ndarray:
    """Cost-to-go estimates (cells) to the goal cell (row, col) for the search graph's (padded) nodes: the larger of
    the octile distance and the cost-aware distance on a grid of :data:`COARSE` x :data:`COARSE` blocks (a block
    passable when any of its cells is, at its cheapest cell's cost), less a block's diagonal. The coarse distance
    sees walls the octile distance does not, so A* settles a band along the way instead of every room nearer than
    the goal; it can overestimate a little (as Smac's does), which costs at most a little optimality."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    rows, cols = costmap.cost.shape
    f = COARSE
    br, bc = -(-rows // f), -(-cols // f)
    cost = np.zeros((br * f, bc * f))
    ok = np.zeros((br * f, bc * f))
    cost[:rows, :cols] = np.where(costmap.passable, costmap.cost, 0.0)
    ok[:rows, :cols] = costmap.passable
    n_ok = ok.reshape(br, f, bc, f).sum(axis=(1, 3))
    mean = cost.reshape(br, f, bc, f).sum(axis=(1, 3)) / np.maximum(n_ok, 1.0)
    block_cost = np.where(n_ok > 0, np.floor(mean), COST_LETHAL).astype(np.uint8)
    coarse = costmap.coarse_graph((br, bc))
    coarse.set_costs(block_cost, costmap.config.cost_weight)
    matrix = csr_matrix((coarse.weights.ravel(), coarse.indices, coarse.indptr), shape=(coarse.n, coarse.n))
    d = dijkstra(matrix, directed=True, indices=coarse.node(goal[0] // f, goal[1] // f))
    d = d.reshape(coarse.rows, coarse.cols)[1:-1, 1:-1]
    # Bilinear between block centres: a step-shaped estimate would drop by a block's cost at each block edge, more
    # than the step there costs, and A* would settle every cell of a block before leaving it.
    # Between reached blocks only (a normalised interpolation): a wall's block, never reached, must not pull its
    # neighbours' estimates up.
    reach = np.isfinite(d)
    size = (bc * f, br * f)
    num = cv2.resize(np.where(reach, d, 0.0).astype(np.float32), size, interpolation=cv2.INTER_LINEAR)
    den = cv2.resize(reach.astype(np.float32), size, interpolation=cv2.INTER_LINEAR)
    with np.errstate(divide="ignore", invalid="ignore"):
        smooth = np.where(den > 1e-6, num / den, np.inf)[:rows, :cols].astype(float)
    fine = HEURISTIC_SCALE * smooth * f
    rr = np.abs(np.arange(rows) - goal[0]).astype(float)[:, None]
    cc = np.abs(np.arange(cols) - goal[1]).astype(float)[None, :]
    octile = (rr + cc) + (SQRT2 - 2.0) * np.minimum(rr, cc)
    h = np.where(np.isfinite(fine), np.maximum(octile, fine), octile)
    out = np.zeros((rows + 2, cols + 2))
    out[1:-1, 1:-1] = h
    return out


def _describe(x: float, y: float) -> str:
    return f"({x:.2f}, {y:.2f}) m"


def _nearest_passable(costmap: GlobalCostmap, row: int, col: int, radius_m: float) -> Optional[tuple[int, int]]:
    """The passable cell nearest (row, col) within ``radius_m``, or None."""
    r = int(math.ceil(radius_m / costmap.grid.resolution_m))
    r0, r1 = max(0, row - r), min(costmap.grid.rows, row + r + 1)
    c0, c1 = max(0, col - r), min(costmap.grid.cols, col + r + 1)
    window = costmap.passable[r0:r1, c0:c1]
    if not window.any():
        return None
    rr, cc = np.nonzero(window)
    d2 = (rr + r0 - row) ** 2 + (cc + c0 - col) ** 2
    i = int(np.argmin(d2))
    if d2[i] > r * r:
        return None
    return int(rr[i] + r0), int(cc[i] + c0)


def check_goal(costmap: GlobalCostmap, x: float, y: float, tolerance_m: float = 0.0,
               name: str = "the goal") -> tuple[int, int]:
    """The cell (row, col) to plan to for the goal (x, y) (map, m): its own, or the nearest passable one within
    ``tolerance_m`` (Nav2's planner tolerance). Raises :class:`NoPath` naming why the goal cannot be reached."""
    grid = costmap.grid
    col, row = grid.to_cells(x, y)
    col, row = int(col), int(row)
    where = _describe(x, y)
    if not grid.inside(col, row):
        x0, y0 = grid.origin_x, grid.origin_y
        raise NoPath(f"{name} {where} is off the map (it covers x {x0:.1f} to {x0 + grid.width_m:.1f} m, "
                     f"y {y0:.1f} to {y0 + grid.height_m:.1f} m)")
    if costmap.passable[row, col]:
        return row, col
    near = _nearest_passable(costmap, row, col, tolerance_m)
    if near is not None:
        return near
    if grid.occupied()[row, col]:
        raise NoPath(f"{name} {where} lies in an occupied cell of the map (a wall)")
    if grid.unknown()[row, col] and not costmap.config.allow_unknown:
        raise NoPath(f"{name} {where} lies in an unknown cell of the map (global_planner.allow_unknown is false)")
    if costmap.lethal[row, col]:
        raise NoPath(f"{name} {where} is blocked (an obstacle seen since the map was made)")
    reach = costmap.footprint_radius_m if costmap.config.narrow_gaps else costmap.inscribed_m
    what = "footprint radius" if costmap.config.narrow_gaps else "footprint radius plus padding"
    raise NoPath(f"{name} {where} is {costmap.distance_m[row, col]:.2f} m from a wall, closer than the robot's "
                 f"{reach:.2f} m ({what})")


NARROW_DETOUR = 1.5
NARROW_DETOUR_M = 2.0
"""With a fine grid, narrow gaps are measured when the way without them is longer than NARROW_DETOUR times the
straight line plus NARROW_DETOUR_M (m), or missing."""


def _ends(costmap: GlobalCostmap, start_xy: tuple[float, float], goal_xy: tuple[float, float], tolerance_m: float,
          goal_name: str) -> tuple[int, int, int, int]:
    """The start's and the goal's cells (srow, scol, grow, gcol) to search between; :class:`NoPath` naming why there
    are none."""
    grid = costmap.grid
    gr, gc = check_goal(costmap, goal_xy[0], goal_xy[1], tolerance_m, goal_name)
    scol, srow = grid.to_cells(start_xy[0], start_xy[1])
    scol, srow = int(scol), int(srow)
    if not grid.inside(scol, srow):
        raise NoPath(f"the robot {_describe(*start_xy)} is off the map: is it localised?")
    if not costmap.passable[srow, scol]:
        near = _nearest_passable(costmap, srow, scol, costmap.config.start_search_m)
        if near is None:
            raise NoPath(f"the robot {_describe(*start_xy)} is inside a wall or obstacle on the map, with no free "
                         f"cell within {costmap.config.start_search_m:g} m: is it localised?")
        srow, scol = near
    return srow, scol, gr, gc


def _search(costmap: GlobalCostmap, srow: int, scol: int, gr: int, gc: int, goal_xy: tuple[float, float],
            goal_name: str) -> tuple[list[int], int]:
    """A* between the cells: the nodes and the number settled; :class:`NoPath` when the goal is enclosed."""
    enclosed = (f"{goal_name} {_describe(*goal_xy)} cannot be reached from here: walls enclose it, or no gap on "
                f"the way is wide enough for the robot (wider than {narrowest_gap_m(costmap):.2f} m)")
    if costmap.labels[srow, scol] != costmap.labels[gr, gc]:
        raise NoPath(enclosed)
    graph = costmap.graph()
    try:
        nodes, expanded = graph.search(graph.node(srow, scol), graph.node(gr, gc), heuristic(costmap, (gr, gc)))
    except NoPath:
        # Connected only by a diagonal between two impassable cells (the search does not cut corners): enclosed too.
        raise NoPath(enclosed) from None
    return nodes, expanded


def plan_path(costmap: GlobalCostmap, start_xy: tuple[float, float], goal_xy: tuple[float, float],
              tolerance_m: float = 0.0, goal_name: str = "the goal", smooth: bool = True) -> GlobalPath:
    """The cheapest path from ``start_xy`` to ``goal_xy`` (map frame, m) on ``costmap``, shortened when ``smooth``.

    The goal may move to the nearest passable cell within ``tolerance_m``; a
    start too near a wall plans from the nearest passable cell within
    ``start_search_m``. Raises :class:`NoPath` with the reason when there is no path.

    With narrow gaps measured on a fine grid (GPS), they are measured only when the way without them is missing
    or more than :data:`NARROW_DETOUR` times the straight line (plus :data:`NARROW_DETOUR_M`): a tight gap is worth
    its cost where it saves a detour, and measuring it costs more than a plan.
    """
    if not costmap.narrow_ready:
        try:
            path = _plan_path(costmap, start_xy, goal_xy, tolerance_m, goal_name, smooth)
            straight = math.hypot(goal_xy[0] - start_xy[0], goal_xy[1] - start_xy[1])
            if path.length_m <= NARROW_DETOUR * straight + NARROW_DETOUR_M:
                return path
        except NoPath:
            pass
        costmap.add_narrow()
    return _plan_path(costmap, start_xy, goal_xy, tolerance_m, goal_name, smooth)


def _plan_path(costmap: GlobalCostmap, start_xy: tuple[float, float], goal_xy: tuple[float, float],
               tolerance_m: float, goal_name: str, smooth: bool) -> GlobalPath:
    """:func:`plan_path` on the costs as they are."""
    grid = costmap.grid
    srow, scol, gr, gc = _ends(costmap, start_xy, goal_xy, tolerance_m, goal_name)
    nodes, expanded = _search(costmap, srow, scol, gr, gc, goal_xy, goal_name)
    graph = costmap.graph()
    cells = np.array([graph.cell(n) for n in nodes])
    if smooth:
        cells = shorten(costmap, cells)
    xs, ys = grid.cell_centres(cells[:, 1], cells[:, 0])
    points = np.column_stack((xs, ys))
    # The path starts where the robot is and ends on the goal itself when that cell is the goal's own.
    points[0] = start_xy
    col_g, row_g = grid.to_cells(goal_xy[0], goal_xy[1])
    if (int(row_g), int(col_g)) == (gr, gc):
        points[-1] = goal_xy
    length = float(np.hypot(*np.diff(points, axis=0).T).sum()) if len(points) > 1 else 0.0
    return GlobalPath(points, length, expanded)


def narrowest_gap_m(costmap: GlobalCostmap) -> float:
    """The width (m) a gap must exceed for the costmap to let a path through, as the robot needs it: the footprint's
    width with ``narrow_gaps`` (the padding may be entered; the grid asks a little more), else the footprint's width
    plus twice the padding."""
    reach = costmap.footprint_radius_m if costmap.config.narrow_gaps else costmap.inscribed_m
    return 2.0 * reach


def _multiplier(costmap: GlobalCostmap, cost: np.ndarray) -> np.ndarray:
    """What a step through cells of ``cost`` costs per cell of length: 1 + cost_weight * cost / 252."""
    return 1.0 + costmap.config.cost_weight * np.minimum(cost, MAX_COST) / MAX_COST


def _segment_cost(costmap: GlobalCostmap, a: np.ndarray, b: np.ndarray) -> float:
    """The travel cost (cells, as A* counts it) of the straight line between cells ``a`` and ``b`` (row, col),
    sampled at a third of a cell; inf when the band the robot's centre sweeps (the cells beside each sample on a
    diagonal) touches an impassable cell."""
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    n = int(max(abs(b[0] - a[0]), abs(b[1] - a[1])) * 3) + 1
    t = (np.arange(n) + 0.5) / n
    r = a[0] + t * (b[0] - a[0])
    c = a[1] + t * (b[1] - a[1])
    lo_r, hi_r = np.floor(r + 0.25).astype(np.intp), np.floor(r + 0.75).astype(np.intp)
    lo_c, hi_c = np.floor(c + 0.25).astype(np.intp), np.floor(c + 0.75).astype(np.intp)
    band = np.concatenate((costmap.cost[lo_r, lo_c], costmap.cost[lo_r, hi_c], costmap.cost[hi_r, lo_c],
                           costmap.cost[hi_r, hi_c]))
    if band.max() >= COST_INSCRIBED:
        return math.inf
    cells = costmap.cost[np.floor(r + 0.5).astype(np.intp), np.floor(c + 0.5).astype(np.intp)]
    return float(_multiplier(costmap, cells).mean() * length)


def shorten(costmap: GlobalCostmap, cells: np.ndarray) -> np.ndarray:
    """String pulling: from each kept cell, the farthest later cell of the path that a straight line reaches at no
    more travel cost (as A* counts it) than the path between them, so that a shortcut never trades length for
    nearness to walls (it does not cross a door on the slant); the cells (k, 2) kept, first and last included."""
    n = len(cells)
    if n <= 2:
        return cells
    mult = _multiplier(costmap, costmap.cost[cells[:, 0], cells[:, 1]].astype(float))
    steps = np.hypot(*np.diff(cells, axis=0).T) * 0.5 * (mult[:-1] + mult[1:])
    along = np.concatenate(([0.0], np.cumsum(steps)))

    def ok(i: int, j: int) -> bool:
        return _segment_cost(costmap, cells[i], cells[j]) <= along[j] - along[i] + 1e-6

    kept = [0]
    i = 0
    while i < n - 1:
        # Doubling then bisecting the reach: a line of sight is checked some log(n) times per kept cell.
        step = 1
        while i + step * 2 < n and ok(i, i + step * 2):
            step *= 2
        best, hi = i + step, min(n - 1, i + step * 2)
        if best > i + 1 and not ok(i, best):
            best = i + 1
        while hi > best + 1:
            mid = (best + hi) // 2
            if ok(i, mid):
                best = mid
            else:
                hi = mid
        if hi == n - 1 and hi > best and ok(i, hi):
            best = hi
        kept.append(best)
        i = best
    return cells[kept]


def path_length_m(points: Sequence[Sequence[float]]) -> float:
    """Length (m) of a polyline of (x, y) points (m)."""
    p = np.asarray(points, dtype=float)
    return float(np.hypot(*np.diff(p, axis=0).T).sum()) if len(p) > 1 else 0.0


__all__ = ["GlobalPlannerConfig", "GlobalCostmap", "GlobalPath", "NoPath", "plan_path", "check_goal", "shorten",
           "path_length_m", "narrowest_gap_m", "COST_NARROW"]
