"""The local planner: a dynamic window (DWA) over (v, w) that turns a preferred command into one that goes around.

Given the robot's pose and last command in the ``odom`` frame, the local
costmap, a preferred command (go_to's regulated pure pursuit) and a carrot
(the point it steers for), :meth:`DwaPlanner.plan`:

1. samples ``vx_samples`` x ``vtheta_samples`` twists in the dynamic window:
   the speeds reachable from the last command within ``window_s`` at the
   profile's acceleration limits, clipped to [0, top speed] and the turn-rate
   limit (no reversing: the LiDAR sees all round, but a Nav2 user expects
   ``min_vel_x: 0``); the preference (clipped into the window) and stopping
   are always among them;
2. follows each for ``sim_time_s`` as an arc (constant v, w), in steps of
   ``time_step_s``, all at once with NumPy;
3. refuses an arc that enters a cell of cost >= :data:`COST_INSCRIBED` (the
   footprint would touch), unless the robot is already that close and the
   arc turns in place or never gets costlier and ends cheaper (out, not
   deeper);
   An arc that enters a narrow cell (:data:`COST_NARROW`: in the padding, not
   the footprint; a profile with ``narrow_speed_mps`` above 0) is admissible
   only at ``narrow_speed_mps`` or slower, and that speed is sampled at
   every turn rate: a gap the robot fits is driven through slowly;
4. scores the others, lowest best: ``path_align_scale`` x the squared
   distance to the preference (per top speed and top turn rate) +
   ``goal_dist_scale`` x the change in distance to the goal (per top-speed
   arc length) + ``obstacle_scale`` x the mean cost along the arc / 252.

The distance to the goal is, in plain DWA (``navigation_function: false``),
the straight line from the arc's end to the carrot. Plain DWA pushes at a
bench across the way: every arc round it first gets no closer. With
``navigation_function: true`` (the default) it is the length of the shortest
way round obstacles from the arc's end to the goal (the target, or the point
``goal_lookahead_m`` toward it), read from a navigation function: Dijkstra
(``scipy.sparse.csgraph``) from the goal over the costmap coarsened to
``navigation_function_resolution_m``, through cells below the inscribed cost,
each step's length weighted up by the cells' cost so that the way keeps its
distance. This is Brock and Khatib's "global dynamic window" (1999); in Nav2
terms a planner on the local costmap with DWB's PathDist critic. Where the
goal cannot be reached on the costmap (a wall across the window) it falls
back to the straight line. ``benchmarks/local_planner.py`` runs both on the
same bench.

When the preference's own arc meets no cost at all it is returned as it is:
in the open the robot drives exactly as without a LiDAR, and no navigation
function is computed. ``blocked`` is true when no admissible arc gets closer
to the goal. Nothing here reads a clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from beastbt.blackboard.types import COST_INSCRIBED, LocalCostmap
from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults
from beastbt.navigation.local_costmap import COST_NARROW, cost_at


def graph_search() -> tuple[Any, Any]:
    """SciPy's ``csr_matrix`` and ``csgraph.dijkstra``, imported on first use.

    scipy.sparse costs about 60 ms of start-up: a run whose tree has no go_to
    never pays it, and one that has is given it before its first tick
    (:func:`beastbt.parts.navigation.install_navigation`), not at its first plan.
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    return csr_matrix, dijkstra


PROGRESS_EPS_M = 0.05
"""An arc must end this much closer to the goal to count as progress (m): creeping at under 3 cm/s over the
horizon toward a wall is blocked, not progress."""
NF_COST_WEIGHT = 3.0
"""A step of the navigation function through a cell of cost c is (1 + this * c / 252) times its length: the way
round keeps away from obstacles where it can."""


@dataclass(frozen=True)
@schema_defaults("parts/local_planner.schema.json")
class LocalPlannerConfig:
    """The profile's ``local_planner:`` section (Nav2 DWB-like knobs), SI units."""

    sim_time_s: float
    """How far ahead each arc is followed (s)."""
    time_step_s: float
    """Step between checked poses of an arc (s)."""
    vx_samples: int
    """Forward speeds sampled."""
    vtheta_samples: int
    """Turn rates sampled."""
    window_s: float
    """Speeds reachable from the last command within this long at the acceleration limits (s)."""
    path_align_scale: float
    """Weight of staying close to the preferred command."""
    goal_dist_scale: float
    """Weight of getting closer to the carrot."""
    obstacle_scale: float
    """Weight of the mean cost along the arc."""
    navigation_function: bool
    """Score by the way round obstacles to the goal (true) or the straight line to the carrot (false, plain DWA)."""
    navigation_function_resolution_m: float
    """Cell of the navigation function's grid (m)."""
    goal_lookahead_m: float
    """The navigation function leads to the target or the point this far toward it (m)."""
    scan_timeout_s: float
    """A scan older than this is not steered around (s)."""
    step_aside: bool
    """Pass a person who walks at the robot on ``pass_side`` (:mod:`beastbt.navigation.people`)."""
    pass_side: str
    """The side people are passed on: ``right`` or ``left``."""
    pass_clearance_m: float
    """Room kept between the footprint and a person passing (m)."""
    pass_react_time_s: float
    """Step aside for a person who would meet the robot within this long (s)."""
    person_min_speed_mps: float
    """What moves slower than this is not a walking person (m/s)."""
    person_max_range_m: float
    """People are tracked up to this far (m)."""
    narrow_speed_mps: float
    """Top speed on an arc through a narrow cell (within the padding, not the footprint) (m/s); 0: narrow cells are
    as impassable as the rest of the inscribed band."""

    def __post_init__(self) -> None:
        for name in ("sim_time_s", "time_step_s", "window_s", "scan_timeout_s", "navigation_function_resolution_m",
                     "goal_lookahead_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"local_planner: '{name}' must be > 0, got {getattr(self, name)}")
        for name in ("pass_react_time_s", "person_min_speed_mps", "person_max_range_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"local_planner: '{name}' must be > 0, got {getattr(self, name)}")
        if self.pass_side not in ("right", "left"):
            raise ValueError(f"local_planner: 'pass_side' must be 'right' or 'left', got {self.pass_side!r}")
        for name in ("path_align_scale", "goal_dist_scale", "obstacle_scale", "pass_clearance_m",
                     "narrow_speed_mps"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"local_planner: '{name}' must be >= 0, got {getattr(self, name)}")
        for name in ("vx_samples", "vtheta_samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 2 <= value <= 200:
                raise ValueError(f"local_planner: '{name}' must be a whole number from 2 to 200, got {value!r}")
        if self.sim_time_s / self.time_step_s > 200:
            raise ValueError("local_planner: sim_time_s / time_step_s must be at most 200 steps")

    @classmethod
    def from_dict(cls, d: Any) -> "LocalPlannerConfig":
        """Build from a profile's ``local_planner:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "local_planner")


@dataclass(frozen=True)
class Limits:
    """What the robot may do: top speed (m/s), top turn rate (rad/s), accelerations (m/s^2, rad/s^2)."""

    max_speed_mps: float
    max_turn_rate_rps: float
    max_accel_mps2: float
    max_angular_accel_rps2: float


@dataclass(frozen=True)
class PlanResult:
    """What :meth:`DwaPlanner.plan` chose: the twist (m/s, rad/s), its arc in odom ((k+1, 2), m, from the robot),
    whether the preference's own arc met no cost (``free``; then the twist is the preference unless asked to keep
    planning), whether no admissible arc gets closer to the carrot
    (``blocked``), how many arcs were admissible of how many sampled, and whether the arc chosen enters a narrow
    cell or starts in one (``narrow``: the twist is at most ``narrow_speed_mps``)."""

    linear_mps: float
    angular_rps: float
    points_xy: np.ndarray
    free: bool
    blocked: bool
    admissible: int
    sampled: int
    narrow: bool = False


def arcs(pose: tuple[float, float, float], v: np.ndarray, w: np.ndarray, times: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray]:
    """Positions (x, y) in odom, each (len(v), len(times)), of the robot following each twist (v[i], w[i]) from
    ``pose`` (x m, y m, yaw rad) for ``times`` seconds: exact arcs (straight lines where w is 0)."""
    x0, y0, th0 = pose
    v = v[:, None]
    w = w[:, None]
    t = times[None, :]
    straight = np.abs(w) < 1e-6
    w_safe = np.where(straight, 1.0, w)
    th = th0 + w * t
    r = v / w_safe
    x = np.where(straight, x0 + v * t * math.cos(th0), x0 + r * (np.sin(th) - math.sin(th0)))
    y = np.where(straight, y0 + v * t * math.sin(th0), y0 - r * (np.cos(th) - math.cos(th0)))
    return x, y


class NavigationFunction:
    """Dijkstra from a goal over a costmap coarsened by merging ``factor`` x ``factor`` cells (the costliest kept):
    the length (m, weighted by cost) of the shortest way from each cell to the goal; inf where there is none."""

    def __init__(self) -> None:
        self._edges: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def _grid_edges(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The 8-neighbour edges of an n x n grid (each once): cell a, cell b, length in cells."""
        if n not in self._edges:
            idx = np.arange(n * n).reshape(n, n)
            a, b, length = [], [], []
            for dy, dx, ln in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, math.sqrt(2.0)), (1, -1, math.sqrt(2.0))):
                a.append(idx[0:n - dy, max(0, -dx):n - max(0, dx)].ravel())
                b.append(idx[dy:n, max(0, dx):n - max(0, -dx)].ravel())
                length.append(np.full(a[-1].shape, ln))
            self._edges[n] = (np.concatenate(a), np.concatenate(b), np.concatenate(length))
        return self._edges[n]

    def compute(self, costmap: LocalCostmap, factor: int, goal_xy: tuple[float, float], narrow: bool = False
                ) -> tuple[np.ndarray, float]:
        """The navigation function (n, n) over the coarse grid (same origin as ``costmap``) and its cell (m).
        With ``narrow``, a block of inscribed and passable cells (no lethal one) is passable at the narrow cost: a
        gap a cell or two wide (a narrow gap) need not fall on the coarse grid's blocks to be a way."""
        cost = costmap.cost
        n = cost.shape[0] // factor
        blocks = cost[:n * factor, :n * factor].reshape(n, factor, n, factor)
        coarse = blocks.max(axis=(1, 3)).ravel()
        if narrow and factor > 1:
            some_way = (blocks < COST_INSCRIBED).any(axis=(1, 3)).ravel() & (coarse == COST_INSCRIBED)
            coarse = np.where(some_way, np.uint8(COST_NARROW), coarse)
        res = costmap.resolution_m * factor
        ok = coarse < COST_INSCRIBED
        gx = int(min(max((goal_xy[0] - costmap.origin_x_m) // res, 0), n - 1))
        gy = int(min(max((goal_xy[1] - costmap.origin_y_m) // res, 0), n - 1))
        goal = gy * n + gx
        if not ok[goal]:
            # The goal is in or beside an obstacle: lead to the nearest free cell to it instead.
            free = np.flatnonzero(ok)
            if free.size == 0:
                return np.full((n, n), np.inf), res
            fy, fx = np.divmod(free, n)
            goal = int(free[np.argmin((fx - gx) ** 2 + (fy - gy) ** 2)])
        a, b, length = self._grid_edges(n)
        keep = ok[a] & ok[b]
        c = coarse.astype(np.float32)
        w = length[keep] * res * (1.0 + NF_COST_WEIGHT * (c[a[keep]] + c[b[keep]]) / (2.0 * (COST_INSCRIBED - 1)))
        csr_matrix, dijkstra = graph_search()
        graph = csr_matrix((w, (a[keep], b[keep])), shape=(n * n, n * n))
        return dijkstra(graph, directed=False, indices=goal).reshape(n, n), res


def nf_at(nf: np.ndarray, res: float, costmap: LocalCostmap, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The navigation function's values at odom points (``x``, ``y`` arrays, m); inf outside its grid."""
    n = nf.shape[0]
    ix = np.floor((x - costmap.origin_x_m) / res).astype(np.intp)
    iy = np.floor((y - costmap.origin_y_m) / res).astype(np.intp)
    inside = (ix >= 0) & (ix < n) & (iy >= 0) & (iy < n)
    out = np.full(np.shape(x), np.inf)
    out[inside] = nf[iy[inside], ix[inside]]
    return out


class DwaPlanner:
    """The dynamic window planner of the module docstring, for a robot with ``limits``."""

    def __init__(self, config: LocalPlannerConfig, limits: Limits) -> None:
        self.config = config
        self.limits = limits
        n = int(math.ceil(config.sim_time_s / config.time_step_s - 1e-9))
        self.times = np.arange(0, n + 1) * (config.sim_time_s / n)
        self.nf = NavigationFunction()
        self.nf_computed = 0
        """Navigation functions computed so far (only while something is in the way)."""
        self._nf_for: Optional[LocalCostmap] = None
        self._narrow_for: Optional[LocalCostmap] = None
        self._narrow_seen = False
        self._nf: tuple[np.ndarray, float] = (np.zeros((0, 0)), 1.0)

    def window(self, last: tuple[float, float], max_speed_mps: float, max_turn_rps: float
               ) -> tuple[np.ndarray, np.ndarray]:
        """The sampled twists (v, w) (flat arrays): the grid over the dynamic window round ``last``."""
        cfg, lim = self.config, self.limits
        dv = lim.max_accel_mps2 * cfg.window_s
        dw = lim.max_angular_accel_rps2 * cfg.window_s
        v_lo, v_hi = max(0.0, last[0] - dv), min(max_speed_mps, max(0.0, last[0]) + dv)
        w_lo, w_hi = max(-max_turn_rps, last[1] - dw), min(max_turn_rps, last[1] + dw)
        if v_lo > v_hi:  # the last command was faster than allowed now: slow down as fast as possible
            v_lo = v_hi
        if w_lo > w_hi:
            w_lo = w_hi = min(max(last[1], -max_turn_rps), max_turn_rps)
        vs = np.linspace(v_lo, v_hi, cfg.vx_samples)
        ws = np.linspace(w_lo, w_hi, cfg.vtheta_samples)
        if w_lo < 0.0 < w_hi:
            ws = np.append(ws, 0.0)
        vv, ww = np.meshgrid(vs, ws, indexing="ij")
        return vv.ravel(), ww.ravel()

    def plan(self, costmap: Optional[LocalCostmap], pose: tuple[float, float, float], last: tuple[float, float],
             preferred: tuple[float, float], carrot_xy: tuple[float, float], max_speed_mps: float,
             max_turn_rps: float, target_xy: Optional[tuple[float, float]] = None, keep_planning: bool = False
             ) -> PlanResult:
        """Choose a twist: see the module docstring. ``pose`` odom (x m, y m, yaw rad); ``last`` and ``preferred``
        (v m/s, w rad/s); ``carrot_xy`` and ``target_xy`` odom (m; no target: the carrot);
        ``max_speed_mps`` and ``max_turn_rps`` the step's limits. ``keep_planning``: choose among the window even
        when the preference's arc is free (the robot is half way round something: a pure-pursuit turn in place
        back toward the line would undo it)."""
        cfg = self.config
        vp = min(max(preferred[0], 0.0), max_speed_mps)
        wp = min(max(preferred[1], -max_turn_rps), max_turn_rps)
        px, py = arcs(pose, np.array([vp]), np.array([wp]), self.times)
        free = costmap is None or not cost_at(costmap, px[0], py[0]).any()
        if free and (not keep_planning or costmap is None):
            # Nothing near the preference's arc: drive it as it is (and compute nothing more).
            return PlanResult(vp, wp, np.column_stack((px[0], py[0])), True, False, 1, 1)
        assert costmap is not None
        vs, ws = self.window(last, max_speed_mps, max_turn_rps)
        # The preference clipped into the window, and stopping, are always candidates.
        v_in = min(max(vp, float(vs.min())), float(vs.max()))
        w_in = min(max(wp, float(ws.min())), float(ws.max()))
        vs = np.concatenate(([v_in, 0.0], vs))
        ws = np.concatenate(([w_in, 0.0], ws))
        slow = cfg.narrow_speed_mps
        if 0.0 < slow < float(vs.max()) and self._has_narrow(costmap):
            # The narrow speed (within the window) at every turn rate: the twists a narrow gap admits.
            v_slow = min(max(slow, float(vs[2:].min())), slow)
            turns = np.unique(ws[2:])
            vs = np.concatenate((vs, np.full(len(turns), v_slow)))
            ws = np.concatenate((ws, turns))
        x, y = arcs(pose, vs, ws, self.times)
        cost = cost_at(costmap, x, y).astype(np.float32)
        here = float(cost[0, 0])
        worst = cost[:, 1:].max(axis=1)
        # A robot already too close (in the inscribed band) may turn in place (its footprint is a circle) or take
        # an arc that never gets costlier and ends cheaper: out, not deeper.
        admissible = (worst < COST_INSCRIBED) | ((worst <= here) & ((vs == 0.0) | (cost[:, -1] < here)))
        if slow > 0.0:
            # Through a narrow gap (or out of one) at the narrow speed at most.
            admissible &= (np.maximum(worst, here) < COST_NARROW) | (vs <= slow + 1e-9)
        d0, d_end = self._goal_distances(costmap, pose, carrot_xy, target_xy, x[:, -1], y[:, -1])
        admissible &= np.isfinite(d_end)
        reach = max(max_speed_mps * cfg.sim_time_s, 1e-3)
        score = (cfg.path_align_scale * (((vs - vp) / max(max_speed_mps, 1e-3)) ** 2
                                         + ((ws - wp) / max(max_turn_rps, 1e-3)) ** 2)
                 + cfg.goal_dist_scale * (d_end - d0) / reach
                 + cfg.obstacle_scale * cost.mean(axis=1) / (COST_INSCRIBED - 1))
        score = np.where(admissible, score, np.inf)
        best = int(np.argmin(score))
        progress = admissible & (d_end < d0 - PROGRESS_EPS_M)
        n_ok = int(np.count_nonzero(admissible))
        if not np.isfinite(score[best]):
            # Nothing admissible (hemmed in): stand still.
            return PlanResult(0.0, 0.0, np.array([[pose[0], pose[1]]]), free, True, 0, len(vs))
        narrow = slow > 0.0 and max(float(worst[best]), here) >= COST_NARROW
        return PlanResult(float(vs[best]), float(ws[best]), np.column_stack((x[best], y[best])), free,
                          not bool(progress.any()), n_ok, len(vs), narrow)

    def _has_narrow(self, costmap: LocalCostmap) -> bool:
        """Whether ``costmap`` holds a narrow cell (looked up once per costmap): the narrow speed's extra twists are
        sampled only then."""
        if self._narrow_for is not costmap:
            self._narrow_for = costmap
            self._narrow_seen = bool((costmap.cost == COST_NARROW).any())
        return self._narrow_seen

    def _goal_distances(self, costmap: LocalCostmap, pose: tuple[float, float, float], carrot_xy: tuple[float, float],
                        target_xy: Optional[tuple[float, float]], x_end: np.ndarray, y_end: np.ndarray
                        ) -> tuple[float, np.ndarray]:
        """Distance to the goal (m) from the robot and from each arc's end: the way round obstacles with the
        navigation function, else (or where it does not reach the robot) the straight line to the carrot."""
        cfg = self.config
        cx, cy = carrot_xy
        straight = (math.hypot(cx - pose[0], cy - pose[1]), np.hypot(cx - x_end, cy - y_end))
        if not cfg.navigation_function:
            return straight
        gx, gy = target_xy if target_xy is not None else carrot_xy
        dx, dy = gx - pose[0], gy - pose[1]
        d = math.hypot(dx, dy)
        reach = min(cfg.goal_lookahead_m, costmap.width_m / 2.0 - costmap.resolution_m)
        if d > reach:
            gx, gy = pose[0] + dx * reach / d, pose[1] + dy * reach / d
        if self._nf_for is not costmap:
            # Once per costmap (per scan), not per tick: the goal moves little in a scan's time.
            factor = max(1, int(round(cfg.navigation_function_resolution_m / costmap.resolution_m)))
            self._nf = self.nf.compute(costmap, factor, (gx, gy), cfg.narrow_speed_mps > 0.0)
            self._nf_for = costmap
            self.nf_computed += 1
        nf, res = self._nf
        here = float(nf_at(nf, res, costmap, np.array([pose[0]]), np.array([pose[1]]))[0])
        ends = nf_at(nf, res, costmap, x_end, y_end)
        if not np.isfinite(ends).any():
            return straight  # no way round on the costmap (a wall across the window): the straight line
        if not math.isfinite(here):
            # The robot's own cell is too close to something to be on the grid: measure from its best neighbour.
            here = float(np.min(ends[np.isfinite(ends)]))
        return here, ends


__all__ = ["LocalPlannerConfig", "Limits", "PlanResult", "DwaPlanner", "NavigationFunction", "arcs", "nf_at",
           "PROGRESS_EPS_M", "NF_COST_WEIGHT"]
