"""Global planning for GPS go_to: a rolling global costmap with memory in the odom frame, and A* on it.

:class:`GlobalNavigator` is what a GPS ``go_to`` (and so ``route`` and
``return_home``) plans with on a robot with a LiDAR, as Nav2's planner
server plans on its global costmap:

* the **obstacle layer** (:class:`~beastbt.navigation.obstacle_layer.ObstacleLayer`)
  is a window of ``global_costmap.width_m`` (40 m) at ``resolution_m``
  (0.1 m) in ``odom`` that rolls with the robot; each new scan marks and
  clears it (ray tracing), placed with the odom pose at the scan's time;
* the **costmap** is the global planner's
  (:class:`~beastbt.navigation.global_planner.GlobalCostmap`: inflation by
  the footprint radius plus ``global_planner.footprint_padding_m``, then
  Nav2's exponential cost), built from the layer only when a plan is made;
* :meth:`GlobalNavigator.plan` is :func:`~beastbt.navigation.global_planner.plan_path`
  (A* with string pulling) from the robot to the goal, the goal clipped to
  the window when it lies beyond (it is planned to again as the window
  rolls).

Planning is needed only when the straight way is blocked:
:meth:`GlobalNavigator.blocked` answers that from the marks alone (a mark
within the inscribed radius of the line), so a robot in the open pays for
no costmap and no search. Nothing here reads a clock.
"""

from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

from beastbt.blackboard.types import LaserScan
from beastbt.devices.lidar_scan import LidarMounting
from beastbt.mapping.occupancy_map import FREE, OccupancyMap
from beastbt.navigation.global_planner import (COST_NARROW, GlobalCostmap, GlobalPath, GlobalPlannerConfig, NoPath,
                                                plan_path)
from beastbt.navigation.obstacle_layer import GlobalCostmapConfig, ObstacleLayer

EDGE_MARGIN_M = 1.0
"""A goal beyond the window is planned to at the window's edge less this (m)."""

GAP_APPROACH_M = 0.8
"""A path through a narrow gap comes in straight along the gap's normal for this long before its centre (m), and
leaves along it for half as long: the collision monitor's stop zone leaves a few cm to either side, so the robot
must enter centred and square."""

GAP_SAME_M = 0.2
"""Two runs of narrow cells on a path whose gaps' centres lie closer than this (m) go through one gap."""


TENTATIVE_SLACK_M = 0.01
"""A gap measured narrower than the costmap lets through by up to this (m) on either side (a gap measured at least
0.31 m for the simulator's 0.30 m robot) is planned through when there is no other way, and looked at from close by
before the goal is given up (:meth:`GlobalNavigator.plan`). A jamb seen on the slant from a few metres is marked a
few cm into the gap: a 0.40 m gap seen from 2.2 m at 45 degrees measured under the limit. The fine grid's distances
come in steps (0.025 m times the root of a whole number): 0.015 m would take in 0.15 m, a gap of the robot's very
width, and a 0.32 m gap would be driven to before it failed."""

VERIFY_M = 1.0
"""A gap planned through tentatively is judged as measured once the robot is this close to its centre (m): there
the LiDAR looks through it, and its beams clear what was marked into it from afar."""


REJOIN_M = 1.0
"""A blocked way is mended (:meth:`GlobalNavigator.replan`) up to this far past its last blocked point (m)."""

REJOIN_TOLERANCE_M = 0.3
"""Where the mended way rejoins may move this far to a passable cell (m): the old way may pass within the padding."""

SWITCH_MIN_M = 2.0
SWITCH_FRACTION = 0.25
"""A way is given up for a new plan only when the new one is shorter than what is left of it (a way still clear) or
than it mended (:meth:`GlobalNavigator.replan`, a way blocked) by this fraction (or SWITCH_MIN_M, the larger). Two
ways of about the same length (either side of a dead end, either end of a wall) must not swap at every plan, the
robot turning back and forth between them; and cells never seen count as free, so the side the robot goes along
grows as more of its wall is seen while the other side's end, seen from afar, looks near: at 10 % the robot on a
16 m fence still turned back twice (1.46x the empty field's time)."""


def lidar_pose(mounting: LidarMounting, base: tuple[float, float, float]) -> tuple[float, float, float]:
    """The LiDAR's pose (x m, y m, yaw rad) in the frame where base_link is at ``base`` (x m, y m, yaw rad)."""
    x, y, yaw = base
    c, s = math.cos(yaw), math.sin(yaw)
    return (x + c * mounting.x_m - s * mounting.y_m, y + s * mounting.x_m + c * mounting.y_m,
            yaw + math.radians(mounting.yaw_deg))


def disk_offsets(radius_cells: float) -> tuple[np.ndarray, np.ndarray]:
    """(d_row, d_col) of the cells whose centres lie within ``radius_cells`` of a cell's centre."""
    k = int(math.floor(radius_cells))
    dr, dc = np.mgrid[-k:k + 1, -k:k + 1]
    inside = dr ** 2 + dc ** 2 <= radius_cells ** 2
    return dr[inside], dc[inside]


class GlobalNavigator:
    """The rolling global costmap (odom) of a GPS go_to and its planner; see the module docstring.

    ``footprint_radius_m`` is the robot's circle (m), ``mounting`` where the LiDAR sits on it.
    """

    def __init__(self, config: GlobalCostmapConfig, planner: GlobalPlannerConfig, footprint_radius_m: float,
                 mounting: LidarMounting) -> None:
        self.config = config
        self.planner_config = planner
        self.footprint_radius_m = footprint_radius_m
        self.inscribed_m = footprint_radius_m + planner.footprint_padding_m
        self.mounting = mounting
        n = int(round(config.width_m / config.resolution_m))
        half = n * config.resolution_m / 2.0
        # Half cells too: the narrow gaps the costmap lets through are measured on them (global_planner.narrow_gaps).
        self.layer = ObstacleLayer(config, n, n, config.resolution_m, -half, -half, fine=planner.narrow_gaps,
                                   dropouts_clear=False)
        self._costmap: Optional[GlobalCostmap] = None
        self._disk = disk_offsets(self.inscribed_m / config.resolution_m)
        # A planned way may pass within the padding when it goes through a narrow gap: only a mark within the
        # footprint radius blocks it (else the way through a gap would be "blocked" at every scan).
        way_reach = footprint_radius_m if planner.narrow_gaps else self.inscribed_m
        self._way_disk = disk_offsets(way_reach / config.resolution_m)
        self.plans = 0
        """Plans made so far."""
        self.gaps: list[tuple[np.ndarray, np.ndarray]] = []
        """The narrow gaps the last plan goes through: (centre (2,) odom m, unit normal (2,) along the path)."""
        self.scans_used = 0
        self.following: Optional[PathFollow] = None
        """The way round the running go_to follows (odom), or None while it drives the straight line or no go_to
        runs: set by the step, read by the views (``/plan``, the console)."""
        self.goal_name = ""
        """What the newest plan was made for (a place's name, or ``the way toward`` it when the goal was clipped)."""
        self.tentative: list[np.ndarray] = []
        """The centres (odom, m) of the gaps the newest plan goes through tentatively (:data:`TENTATIVE_SLACK_M`)."""
        self.refuted: list[np.ndarray] = []
        """Centres (odom, m) of gaps looked at from within :data:`VERIFY_M` and still too narrow: never tried again."""
        self._last_view: Optional[tuple[tuple[float, float, float], np.ndarray, np.ndarray]] = None
        """The newest scan observed: the LiDAR's pose (odom x m, y m, yaw rad), its beams' angles and ranges."""

    # -- scans --------------------------------------------------------------------------------------------
    def observe(self, scan: LaserScan, base_odom: tuple[float, float, float]) -> None:
        """Mark and clear with a new ``scan`` seen from base_link at ``base_odom`` (odom x m, y m, yaw rad, at the
        scan's time); the window first rolls to the robot if it has moved far enough."""
        self.layer.recentre(base_odom[0], base_odom[1])
        pose = lidar_pose(self.mounting, base_odom)
        self.layer.update(pose, scan.angles_rad, scan.ranges_m)
        self._last_view = (pose, scan.angles_rad, scan.ranges_m)
        self.scans_used += 1

    def clear_around(self, xy: tuple[float, float], radius_m: float) -> int:
        """Forget the marks within ``radius_m`` of ``xy`` (odom, m): the recovery that clears the costmap."""
        return self.layer.clear_around(xy[0], xy[1], radius_m)

    # -- is the way blocked? -------------------------------------------------------------------------------
    def blocked(self, points: np.ndarray, skip_m: float = 0.0) -> bool:
        """Whether a mark lies within the inscribed radius of the polyline ``points`` ((n, 2) odom, m), from
        ``skip_m`` along it (the robot's own surroundings may be left out), inside the window."""
        return marks_near(self.layer, points, self._disk, skip_m)

    def way_blocked(self, points: np.ndarray, skip_m: float = 0.0) -> bool:
        """Whether a planned way ((n, 2) odom, m) is blocked: a mark within the footprint radius of it (within the
        inscribed radius without ``narrow_gaps``), from ``skip_m`` along it, inside the window."""
        return marks_near(self.layer, points, self._way_disk, skip_m)

    # -- planning ------------------------------------------------------------------------------------------------
    def costmap(self) -> GlobalCostmap:
        """The global costmap of the window as the layer is now (built, or brought up to date, here)."""
        layer = self.layer
        rows, cols = layer.shape
        cm = self._costmap
        if cm is None:
            grid = OccupancyMap(np.full((rows, cols), FREE, np.int8), layer.resolution_m, layer.origin_x,
                                layer.origin_y)
            cm = self._costmap = GlobalCostmap(grid, self.planner_config, self.footprint_radius_m)
        if cm.layer_version != layer.version:
            grid = None
            if (cm.grid.origin_x, cm.grid.origin_y) != (layer.origin_x, layer.origin_y):
                grid = OccupancyMap(cm.grid.data, layer.resolution_m, layer.origin_x, layer.origin_y)
            cm.set_obstacles(layer.marked, layer.version, grid, layer.fine)
        return cm

    def clip_to_window(self, start: tuple[float, float], goal: tuple[float, float]) -> tuple[float, float]:
        """``goal`` (odom, m), or where the line from ``start`` to it leaves the window less :data:`EDGE_MARGIN_M`."""
        layer = self.layer
        rows, cols = layer.shape
        lo_x, lo_y = layer.origin_x + EDGE_MARGIN_M, layer.origin_y + EDGE_MARGIN_M
        hi_x = layer.origin_x + cols * layer.resolution_m - EDGE_MARGIN_M
        hi_y = layer.origin_y + rows * layer.resolution_m - EDGE_MARGIN_M
        gx, gy = goal
        if lo_x <= gx <= hi_x and lo_y <= gy <= hi_y:
            return goal
        sx, sy = start
        t = 1.0
        for s0, g0, lo, hi in ((sx, gx, lo_x, hi_x), (sy, gy, lo_y, hi_y)):
            d = g0 - s0
            if d > 1e-9 and g0 > hi:
                t = min(t, (hi - s0) / d)
            elif d < -1e-9 and g0 < lo:
                t = min(t, (lo - s0) / d)
        t = max(t, 0.0)
        return sx + t * (gx - sx), sy + t * (gy - sy)

    def plan(self, start: tuple[float, float], goal: tuple[float, float], tolerance_m: float,
             name: str) -> GlobalPath:
        """A path (odom, m) from ``start`` to ``goal`` on the costmap; raises
        :class:`~beastbt.navigation.global_planner.NoPath` with the reason when there is none."""
        target = self.clip_to_window(start, goal)
        clipped = target != goal
        self.plans += 1
        self.goal_name = name if not clipped else f"the way toward {name}"
        tolerance = tolerance_m if not clipped else max(tolerance_m, 2.0)
        cm = self.costmap()
        self.tentative = []
        try:
            path = plan_path(cm, start, target, tolerance, goal_name=self.goal_name)
        except NoPath as exc:
            return self._tentatively(cm, start, target, tolerance, exc)
        return self._through_gaps(path)

    def _tentatively(self, cm: GlobalCostmap, start: tuple[float, float], target: tuple[float, float],
                     tolerance_m: float, no_path: NoPath) -> GlobalPath:
        """With no way on the costmap as measured: a way through gaps that may be wide enough, narrower by up to
        :data:`TENTATIVE_SLACK_M` a side as measured, to go and look at them (:attr:`tentative`); ``no_path`` raised
        when there is none, or when one of its gaps was looked at from within :data:`VERIFY_M` (it is remembered in
        :attr:`refuted` then: the goal fails, named, rather than the robot going back and forth to it)."""
        if self.layer.fine is None or not self.planner_config.narrow_gaps:
            raise no_path
        before = cm.relax_narrow(TENTATIVE_SLACK_M)
        if before is None:
            raise no_path
        try:
            path, gaps = through_gaps(plan_path(cm, start, target, tolerance_m, goal_name=self.goal_name), cm)
            relaxed = cm.cost != before
        except NoPath:
            raise no_path from None
        finally:
            cm.restore(before)
        # Of the gaps the way crosses, those with cells made narrow only now (the others were measured wide enough).
        tentative = [centre for centre, _ in gaps if _changed_near(cm, relaxed, centre, GAP_SAME_M)]
        if tentative and not self._seen_through(tentative):
            raise no_path  # a hole between a wall's sparse marks (seen on the slant) is no gap: no beam went through
        here = np.asarray(start, dtype=float)
        for centre in tentative:
            if (float(np.hypot(*(centre - here))) < VERIFY_M
                    or any(float(np.hypot(*(centre - r))) < GAP_APPROACH_M for r in self.refuted)):
                self.refuted.append(centre)
                raise no_path
        self.gaps = gaps
        self.tentative = tentative
        return path

    def replan(self, start: tuple[float, float], goal: tuple[float, float], tolerance_m: float, name: str,
               previous: np.ndarray) -> GlobalPath:
        """A new path as :meth:`plan` for a way ``previous`` ((n, 2) odom m, from the robot on) that marks now block,
        committed to ``previous``'s side: the way mended round what blocks it (planned from ``start`` to where
        ``previous`` is clear again, :data:`REJOIN_M` past the last blocked point, then ``previous`` on) is kept
        unless the plan from scratch is shorter by :data:`SWITCH_FRACTION` of it (and at least :data:`SWITCH_MIN_M`).

        Along a wall longer than the LiDAR's reach the far end keeps moving as more of it is seen; a plan from
        scratch then finds the two ends at about the same length at every plan and the robot turns back and forth
        between them. Nav2's planner has the same trouble; a person walks on along the wall until the other way is
        clearly shorter. Raises :class:`~beastbt.navigation.global_planner.NoPath` as :meth:`plan` does."""
        fresh = self.plan(start, goal, tolerance_m, name)
        fresh_gaps, fresh_name = self.gaps, self.goal_name
        mended = self._mend(start, np.asarray(previous, dtype=float), fresh.points[-1], name)
        margin = max(SWITCH_MIN_M, SWITCH_FRACTION * mended.length_m) if mended is not None else 0.0
        if mended is None or fresh.length_m < mended.length_m - margin:
            self.gaps, self.goal_name = fresh_gaps, fresh_name
            return fresh
        self.tentative = []  # the mended way goes through gaps measured wide enough only
        return mended

    def _mend(self, start: tuple[float, float], previous: np.ndarray, end: np.ndarray, name: str
              ) -> Optional[GlobalPath]:
        """``previous`` with its blocked part replanned (:meth:`replan`) and its last point moved to ``end`` (the goal
        as it is now: the odom estimate of a place moves a little with each fix), or None when it cannot be: blocked
        up to its end, left the window, or no way to where it is clear again."""
        samples = sample_polyline(previous, self.layer.resolution_m * 0.5, self.inscribed_m)
        if len(samples) < 2:
            return None
        near = marks_near_each(self.layer, samples, self._way_disk)
        if not near.any():
            return None
        step = np.hypot(*np.diff(samples, axis=0).T)
        along = np.concatenate(([0.0], np.cumsum(step)))
        last = int(np.flatnonzero(near)[-1])
        after = np.flatnonzero(along >= along[last] + REJOIN_M)
        if after.size == 0 or near[after[0]:].any():
            return None
        rejoin = samples[after[0]]
        if self.clip_to_window(start, (float(rejoin[0]), float(rejoin[1]))) != (float(rejoin[0]), float(rejoin[1])):
            return None
        try:
            head = plan_path(self.costmap(), start, (float(rejoin[0]), float(rejoin[1])), REJOIN_TOLERANCE_M,
                             goal_name=name)
        except NoPath:
            return None
        # On along the old way from where it rejoins: its own corners, not the samples (a short /plan message).
        cum = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(previous, axis=0).T))))
        beyond = previous[1:-1][cum[1:-1] > self.inscribed_m + along[after[0]]]
        points = np.vstack((head.points, beyond, [end]))
        length = float(np.hypot(*np.diff(points, axis=0).T).sum())
        self.plans += 1
        return self._through_gaps(GlobalPath(points, length, head.expanded))

    def _seen_through(self, centres: list[np.ndarray]) -> bool:
        """Whether the newest scan saw through every one of these gaps' centres (odom, m)."""
        if self._last_view is None:
            return False
        pose, angles, ranges = self._last_view
        xy = np.array(centres, dtype=float)
        return bool(self.layer.seen_through(pose, angles, ranges, xy[:, 0], xy[:, 1]).all())

    def _through_gaps(self, path: GlobalPath) -> GlobalPath:
        """The path with each narrow gap it crosses crossed square (:func:`through_gaps`). Sets :attr:`gaps`."""
        self.gaps = []
        cm = self._costmap
        if cm is None or self.layer.fine is None:
            return path
        path, self.gaps = through_gaps(path, cm)
        return path


def through_gaps(path: GlobalPath, cm: GlobalCostmap) -> tuple[GlobalPath, list[tuple[np.ndarray, np.ndarray]]]:
    """``path`` (in ``cm``'s frame, m) with each narrow gap it crosses (a run of narrow cells) crossed square: in along
    the gap's normal from :data:`GAP_APPROACH_M` before its centre, out along it (the centre midway between the nearest
    obstacles on either side, on ``cm``'s fine grid when it keeps one, else on its cells); and the gaps crossed
    (centre (2,) m, unit normal (2,) along the path). Used on the GPS window and on a saved map alike."""
    res = cm.grid.resolution_m
    pts = sample_polyline(path.points, res / 2.0)
    rows, cols = cm.cost.shape
    col = np.floor((pts[:, 0] - cm.grid.origin_x) / res).astype(np.intp)
    row = np.floor((pts[:, 1] - cm.grid.origin_y) / res).astype(np.intp)
    inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    narrow = np.zeros(len(pts), bool)
    narrow[inside] = cm.cost[row[inside], col[inside]] == COST_NARROW
    if not narrow.any():
        return path, []
    edges = np.flatnonzero(np.diff(np.concatenate(([0], narrow.astype(np.int8), [0]))))
    points = path.points
    gaps: list[tuple[np.ndarray, np.ndarray]] = []
    for first, end in zip(edges[0::2], edges[1::2]):
        gap = _gap_at(cm, pts[(first + end - 1) // 2], pts[min(end, len(pts) - 1)] - pts[first])
        if gap is None or any(float(np.hypot(*(gap[0] - c))) < GAP_SAME_M for c, _ in gaps):
            continue  # none, or one already crossed (a path across a gap at a slant to the cells leaves its narrow
            # cells and comes back into them: two runs, one gap)
        gaps.append(gap)
        points = _cross_square(points, *gap)
    if not gaps:
        return path, []
    length = float(np.hypot(*np.diff(points, axis=0).T).sum())
    return GlobalPath(points, length, path.expanded), gaps


def _gap_at(cm: GlobalCostmap, p: np.ndarray, along: np.ndarray) -> Optional[tuple[np.ndarray, np.ndarray]]:
    """The gap round ``p`` (m, in ``cm``'s frame) that a path heading ``along`` crosses: its centre and unit normal
    (along the path), from the nearest obstacle and the nearest one on the other side of ``p`` (on the fine grid with
    the map's own lethal cells when ``cm`` keeps one, else on its lethal cells); None when there is none."""
    grid = cm.grid
    rows, cols = cm.lethal.shape
    f = cm.fine.shape[0] // rows if cm.fine is not None else 1
    step = grid.resolution_m / f
    k = int(math.ceil(2.0 * cm.inscribed_m / step))
    cr = int(math.floor((p[1] - grid.origin_y) / step))
    cc = int(math.floor((p[0] - grid.origin_x) / step))
    r0, c0 = max(0, cr - k), max(0, cc - k)
    r1, c1 = min(rows * f, cr + k + 1), min(cols * f, cc + k + 1)
    if r1 <= r0 or c1 <= c0:
        return None
    ri, ci = np.arange(r0, r1) // f, np.arange(c0, c1) // f
    if cm.fine is not None:
        obstacles = cm.fine[r0:r1, c0:c1] | cm.static_lethal[np.ix_(ri, ci)]
    else:
        obstacles = cm.lethal[np.ix_(ri, ci)]
    rr, ccs = np.nonzero(obstacles)
    if rr.size < 2:
        return None
    marks = np.column_stack((grid.origin_x + (ccs + c0 + 0.5) * step, grid.origin_y + (rr + r0 + 0.5) * step))

    def sides(q: np.ndarray) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """The nearest obstacle to ``q`` and the nearest on the other side of it (relative to ``q``), or None."""
        xy = marks - q
        d = np.hypot(xy[:, 0], xy[:, 1])
        a = xy[int(np.argmin(d))]
        other = xy @ a < 0.0
        if not other.any():
            return None
        return a, xy[other][int(np.argmin(d[other]))]

    found = sides(p)
    if found is None:
        return None
    # Judged again from midway between the two: the middle of a path's run of narrow cells may lie a few cm before
    # or beside the gap's middle (on a gap at a slant to the cells, the run is lopsided), and seen from there the
    # two jambs are not quite opposite.
    p = p + (found[0] + found[1]) / 2.0
    found = sides(p)
    if found is None:
        return None
    a, b = found
    # A gap: obstacles on both sides, each within the inscribed radius (and a fine cell) of the path. A path along
    # one wall, or past a corner, has none on the other side and is left as it is.
    reach = cm.inscribed_m + 2.0 * step
    na, nb = float(np.hypot(*a)), float(np.hypot(*b))
    if max(na, nb) > reach or a @ b > -0.9 * na * nb:
        return None  # not a gap: nothing within reach on the far side, or not across the path (a corner)
    centre = p + (a + b) / 2.0
    u = (b - a) / max(float(np.hypot(*(b - a))), 1e-9)
    normal = np.array([-u[1], u[0]])
    if normal @ along < 0.0:
        normal = -normal
    if normal @ along < 0.7 * float(np.hypot(*along)):
        return None  # the path runs along it, not through it
    return centre, normal


def _changed_near(cm: GlobalCostmap, changed: np.ndarray, centre: np.ndarray, radius_m: float) -> bool:
    """Whether a cell of ``changed`` (bool, ``cm``'s shape) lies within ``radius_m`` (m) of ``centre`` (m)."""
    grid = cm.grid
    res = grid.resolution_m
    k = int(math.ceil(radius_m / res))
    col = int(math.floor((centre[0] - grid.origin_x) / res))
    row = int(math.floor((centre[1] - grid.origin_y) / res))
    rows, cols = changed.shape
    return bool(changed[max(0, row - k):min(rows, row + k + 1), max(0, col - k):min(cols, col + k + 1)].any())


def _cross_square(points: np.ndarray, centre: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The polyline ``points`` ((n, 2) m) with its points within :data:`GAP_APPROACH_M` of ``centre`` replaced by a
    straight crossing along ``normal``: in from GAP_APPROACH_M before, through the centre, out half as far beyond."""
    near = np.hypot(points[:, 0] - centre[0], points[:, 1] - centre[1]) <= GAP_APPROACH_M
    idx = np.flatnonzero(near)
    crossing = np.array([centre - GAP_APPROACH_M * normal, centre, centre + 0.5 * GAP_APPROACH_M * normal])
    if idx.size == 0:
        # The gap lies between two points of the path: the crossing goes in between them.
        proj = (points - centre) @ normal
        i = int(np.searchsorted(np.maximum.accumulate(proj), 0.0))
        return np.vstack((points[:i], crossing, points[i:]))
    t = (crossing - centre) @ normal
    if idx[0] == 0:  # the robot is already on the way in (or through): the crossing from where it is
        crossing = np.vstack((points[:1], crossing[t > float((points[0] - centre) @ normal)]))
        t = np.concatenate(([-np.inf], t[t > float((points[0] - centre) @ normal)]))
    if idx[-1] == len(points) - 1:  # the goal is near the gap: the crossing up to it
        crossing = np.vstack((crossing[t < float((points[-1] - centre) @ normal)], points[-1:]))
        return np.vstack((points[:idx[0]] if idx[0] > 0 else points[:0], crossing))
    return np.vstack((points[:idx[0]], crossing, points[idx[-1] + 1:]))


def marks_near(layer: ObstacleLayer, points: Any, disk: tuple[np.ndarray, np.ndarray], skip_m: float = 0.0) -> bool:
    """Whether ``layer`` has a mark in the ``disk`` (:func:`disk_offsets`) round any point of the polyline ``points``
    ((n, 2) m, in the layer's frame) from ``skip_m`` along it, inside the grid."""
    samples = sample_polyline(np.asarray(points, dtype=float), layer.resolution_m * 0.5, skip_m)
    return bool(marks_near_each(layer, samples, disk).any())


def marks_near_each(layer: ObstacleLayer, samples: np.ndarray, disk: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """For each point of ``samples`` ((k, 2) m, in the layer's frame), whether ``layer`` has a mark in the ``disk``
    (:func:`disk_offsets`) round it ((k,) bool; False for a point outside the grid)."""
    near = np.zeros(len(samples), bool)
    if len(samples) == 0:
        return near
    row, col, inside = layer.cells(samples[:, 0], samples[:, 1])
    row, col = row[inside], col[inside]
    if row.size == 0:
        return near
    dr, dc = disk
    rr = row[:, None] + dr[None, :]
    cc = col[:, None] + dc[None, :]
    rows, cols = layer.shape
    ok = (rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols)
    hit = np.zeros(rr.shape, bool)
    hit[ok] = layer.marked[rr[ok], cc[ok]]
    near[inside] = hit.any(axis=1)
    return near


def sample_polyline(points: np.ndarray, step_m: float, skip_m: float = 0.0) -> np.ndarray:
    """Points (k, 2) every ``step_m`` (m) along a polyline ((n, 2), m), from ``skip_m`` along it, its end included."""
    p = np.asarray(points, dtype=float)
    if len(p) == 0:
        return p.reshape(0, 2)
    if len(p) == 1:
        return p if skip_m <= 0.0 else p[:0]
    seg = np.hypot(*np.diff(p, axis=0).T)
    cum = np.concatenate(([0.0], np.cumsum(seg)))
    s = np.arange(skip_m, cum[-1], step_m)
    s = np.append(s, cum[-1]) if cum[-1] >= skip_m else s
    x = np.interp(s, cum, p[:, 0])
    y = np.interp(s, cum, p[:, 1])
    return np.column_stack((x, y))


class PathFollow:
    """A planned path (``points`` (n, 2), m) and how far along it the robot is (``along_m``), for pure pursuit."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, dtype=float)
        seg = np.hypot(*np.diff(self.points, axis=0).T) if len(self.points) > 1 else np.zeros(0)
        self.cum = np.concatenate(([0.0], np.cumsum(seg)))
        self.along_m = 0.0

    @property
    def length_m(self) -> float:
        """The path's length (m)."""
        return float(self.cum[-1])

    def project(self, xy: tuple[float, float], reach_m: float) -> float:
        """Move ``along_m`` to the nearest point of the path to ``xy`` (m) from a little behind it to ``reach_m``
        beyond (a path that passes near itself is not skipped ahead); never backwards. The new ``along_m``."""
        p, cum = self.points, self.cum
        if len(p) < 2:
            return self.along_m
        a, b = p[:-1], p[1:]
        ab = b - a
        L2 = np.maximum((ab ** 2).sum(axis=1), 1e-12)
        t = np.clip(((xy[0] - a[:, 0]) * ab[:, 0] + (xy[1] - a[:, 1]) * ab[:, 1]) / L2, 0.0, 1.0)
        d = np.hypot(a[:, 0] + t * ab[:, 0] - xy[0], a[:, 1] + t * ab[:, 1] - xy[1])
        along = cum[:-1] + t * np.sqrt(L2)
        window = (along >= self.along_m - 0.5) & (along <= self.along_m + reach_m)
        if window.any():
            d = np.where(window, d, np.inf)
        i = int(np.argmin(d))
        self.along_m = float(max(self.along_m, along[i]))
        return self.along_m

    def point_at(self, along_m: float) -> tuple[float, float]:
        """The path's point ``along_m`` (m) from its start (its end beyond)."""
        p, cum = self.points, self.cum
        if along_m >= cum[-1] or len(p) < 2:
            return float(p[-1, 0]), float(p[-1, 1])
        i = int(np.searchsorted(cum, along_m, side="right")) - 1
        f = (along_m - cum[i]) / max(cum[i + 1] - cum[i], 1e-12)
        return float(p[i, 0] + f * (p[i + 1, 0] - p[i, 0])), float(p[i, 1] + f * (p[i + 1, 1] - p[i, 1]))

    def ahead(self) -> np.ndarray:
        """The rest of the path from where the robot is along it ((k, 2), m)."""
        start = self.point_at(self.along_m)
        return np.vstack(([start], self.points[self.cum > self.along_m]))


__all__ = ["GlobalNavigator", "PathFollow", "lidar_pose", "marks_near", "marks_near_each", "sample_polyline",
           "disk_offsets", "through_gaps", "EDGE_MARGIN_M", "REJOIN_M", "SWITCH_MIN_M", "SWITCH_FRACTION"]
