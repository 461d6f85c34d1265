"""2D SLAM: keyframes from scans and odometry, matched, joined in a pose graph with loop closures, drawn as a map.

:class:`OnlineMapper` is fed the dead-reckoned pose (``pose_odom``: wheel
odometry, the prior) every tick with :meth:`~OnlineMapper.add_odom` and each
LiDAR revolution with :meth:`~OnlineMapper.add_scan`. Most scans cost a
comparison: a scan becomes a *keyframe* only once the robot has moved
``keyframe_distance_m`` or turned ``keyframe_turn_rad`` since the last one
(and is not turning fast, when a revolution smears). A keyframe's scan is

1. de-skewed: each point moved to where the robot was at the revolution's end,
   by the odometry between the two (the robot moves while the head turns);
2. matched (:mod:`beastbt.mapping.scan_matcher`) against the recent
   keyframes' points around the odometry prior, and joined to the previous
   keyframe by the match and by odometry (:mod:`beastbt.mapping.pose_graph`);
3. tried for a loop closure: against older keyframes close by when the
   robot comes back (a wide coarse search, then a fine one); accepted above
   ``loop_min_score``, and then the graph is optimised.

:meth:`~OnlineMapper.occupancy_map` draws the map from the optimised
keyframes: each scan ray-cast into log-odds (free along each beam, occupied
at its end, so later beams clear where a person stood; no return, NaN, is
skipped: a dropout says nothing), thresholded
into an :class:`~beastbt.mapping.occupancy_map.OccupancyMap`. The map frame
is the robot's pose when mapping began (x forward, y left), as slam_toolbox's.
Units: metres, radians, seconds.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from beastbt.mapping.occupancy_map import UNKNOWN, OccupancyMap, empty_map
from beastbt.mapping.pose_graph import PoseGraph, chain_covariance, compose, relative
from beastbt.mapping.scan_matcher import MatcherConfig, Pose2, ScanMatcher, thin_points, transform_points, wrap


MIN_KEYFRAME_RETURNS = 20
"""Returns a scan needs to become a keyframe: fewer (an empty hall, a LiDAR seeing the sky) place nothing."""


@dataclass(frozen=True)
class MappingConfig:
    """The knobs of the mapper (metres, radians, seconds), with the defaults docs/mapping.md lists.

    ``resolution_m`` the map's cell; ``keyframe_distance_m`` / ``keyframe_turn_rad`` how far the robot moves or
    turns between keyframes; ``max_keyframe_turn_rate_rps`` no keyframe while turning faster (the scan smears)
    unless the robot has driven three keyframe distances since the last one (a long curve);
    ``local_keyframes`` how many recent keyframes the scan matcher matches against; ``min_match_score`` below
    it a match is not trusted and odometry alone places the keyframe; ``loop_search_radius_m`` how close an
    older keyframe must be to try a loop closure, ``loop_min_travel_m`` how far the robot must have driven since
    it, ``loop_window_xy_m`` / ``loop_window_yaw_rad`` the closure's search window, ``loop_min_score`` the score
    a closure needs; ``hit_log_odds`` / ``free_log_odds`` what one return adds to the cell it ends in / takes
    from each cell it crosses, clamped to ``+-max_log_odds``; ``max_range_m`` returns beyond are ignored.
    """

    resolution_m: float = 0.05
    keyframe_distance_m: float = 0.3
    keyframe_turn_rad: float = math.radians(15.0)
    max_keyframe_turn_rate_rps: float = math.radians(10.0)
    scan_latency_s: float = 0.025
    local_keyframes: int = 12
    min_match_score: float = 0.35
    loop_search_radius_m: float = 2.0
    loop_min_travel_m: float = 5.0
    loop_window_xy_m: float = 1.0
    loop_window_yaw_rad: float = math.radians(20.0)
    loop_min_score: float = 0.6
    loop_keyframes: int = 15
    optimise_every_keyframes: int = 5
    # Transient returns (a person walking or standing a while, then gone) must not stay walls: one look through a
    # cell hit once clears it (0.9 - 0.35 = 0.55, below 0.62, occupied_thresh 0.65 in log-odds), a wall hit twice
    # or more survives the odd grazing beam crossing it, and the clamp at 2.5 lets a cell a standing person
    # saturated clear after six looks through it once the person has gone (with -0.25 and +-5 it took 18).
    # A harsher crossing (-0.4) cleared a little more but eroded the office's walls (93.6 % marked at worst, not
    # 95.2 %). docs/mapping.md has the figures.
    hit_log_odds: float = 0.9
    free_log_odds: float = -0.35
    max_log_odds: float = 2.5
    max_range_m: float = 12.0
    matcher: MatcherConfig = field(default_factory=MatcherConfig)


@dataclass
class Keyframe:
    """One keyframe: the clock time of its scan's end (s), the scan's returns in base_link (n, 2; m, de-skewed
    to that time), the sensor's position in base_link (m), its dead-reckoned pose (odom frame), the path length
    driven up to it (m) and the points the matcher uses (thinned)."""

    stamp_s: float
    points: np.ndarray
    sensor_xy: tuple[float, float]
    odom: Pose2
    travelled_m: float
    match_points: np.ndarray


@dataclass
class MapperStats:
    """What the mapper did: scans seen, keyframes, matches trusted, loop closures tried and accepted,
    optimisations."""

    scans: int = 0
    keyframes: int = 0
    matched: int = 0
    loops_tried: int = 0
    loops_closed: int = 0
    optimisations: int = 0


class OnlineMapper:
    """Incremental 2D SLAM (see the module's docstring). ``sensor_xy`` / ``sensor_yaw_rad`` is the LiDAR's mounting
    on base_link (m, rad); scans handed to :meth:`add_scan` are ranges and angles in the LiDAR's frame."""

    def __init__(self, config: Optional[MappingConfig] = None, sensor_xy: tuple[float, float] = (0.0, 0.0),
                 sensor_yaw_rad: float = 0.0) -> None:
        self.config = config if config is not None else MappingConfig()
        self.sensor_xy = (float(sensor_xy[0]), float(sensor_xy[1]))
        self.sensor_yaw_rad = float(sensor_yaw_rad)
        self.matcher = ScanMatcher(self.config.matcher)
        loop_cfg = MatcherConfig(resolution_m=0.05, sigma_m=0.08, window_xy_m=self.config.loop_window_xy_m,
                                 window_yaw_rad=self.config.loop_window_yaw_rad, yaw_step_rad=math.radians(1.0),
                                 coarse_factor=4, max_points=160, refine_iterations=0)
        self.loop_matcher = ScanMatcher(loop_cfg)
        self.graph = PoseGraph()
        self.keyframes: list[Keyframe] = []
        self.stats = MapperStats()
        self._odom: deque[tuple[float, float, float, float, float]] = deque(maxlen=64)  # t, x, y, yaw, yaw rate
        self._travelled = 0.0
        self._last_odom_xy: Optional[tuple[float, float]] = None
        self._last_loop = -1_000
        self._last_optimised = -1_000
        self._pending = False  # a loop closure not yet optimised

    # -- input -------------------------------------------------------------------------------------------------
    def add_odom(self, stamp_s: float, x: float, y: float, yaw: float, yaw_rate_rps: float = 0.0) -> None:
        """The dead-reckoned pose at ``stamp_s`` (s): odom frame, m and rad; its yaw rate (rad/s)."""
        if self._odom and stamp_s <= self._odom[-1][0]:
            return
        if self._last_odom_xy is not None:
            self._travelled += math.hypot(x - self._last_odom_xy[0], y - self._last_odom_xy[1])
        self._last_odom_xy = (x, y)
        self._odom.append((float(stamp_s), float(x), float(y), float(yaw), float(yaw_rate_rps)))

    def odom_at(self, t_s: float) -> Optional[tuple[Pose2, float]]:
        """The dead-reckoned pose at ``t_s`` (interpolated; the nearest end outside the history) and its yaw rate,
        or None before any."""
        if not self._odom:
            return None
        h = self._odom
        if t_s >= h[-1][0]:
            return (h[-1][1], h[-1][2], h[-1][3]), h[-1][4]
        if t_s <= h[0][0]:
            return (h[0][1], h[0][2], h[0][3]), h[0][4]
        for k in range(len(h) - 1, 0, -1):
            t0, t1 = h[k - 1][0], h[k][0]
            if t0 <= t_s <= t1:
                f = (t_s - t0) / (t1 - t0) if t1 > t0 else 1.0
                a, b = h[k - 1], h[k]
                return ((a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]), wrap(a[3] + f * wrap(b[3] - a[3]))),
                        b[4])
        return (h[-1][1], h[-1][2], h[-1][3]), h[-1][4]

    def add_scan(self, stamp_s: float, angles_rad: np.ndarray, ranges_m: np.ndarray, scan_time_s: float) -> bool:
        """One LiDAR revolution ending at ``stamp_s`` (s), taking ``scan_time_s``: angles (rad, LiDAR frame, in
        the order measured) and ranges (m, NaN no return). True when it became a keyframe."""
        self.stats.scans += 1
        at = self.odom_at(stamp_s)
        if at is None:
            return False
        odom, yaw_rate = at
        cfg = self.config
        moved = math.inf
        if self.keyframes:
            d = relative(self.keyframes[-1].odom, odom)
            moved = math.hypot(d[0], d[1])
            if moved < cfg.keyframe_distance_m and abs(d[2]) < cfg.keyframe_turn_rad:
                return False
        # While turning fast wait for the turn to end, unless driving a long curve (teleop, a planned path): then a
        # de-skewed keyframe beats none.
        if abs(yaw_rate) > cfg.max_keyframe_turn_rate_rps and moved < 3 * cfg.keyframe_distance_m:
            return False
        points = self._deskewed(stamp_s, np.asarray(angles_rad, float), np.asarray(ranges_m, float), scan_time_s,
                                odom)
        if len(points) < MIN_KEYFRAME_RETURNS:
            return False
        self._add_keyframe(stamp_s, points, odom)
        return True

    def _deskewed(self, stamp_s: float, angles: np.ndarray, ranges: np.ndarray, scan_time_s: float,
                  odom_end: Pose2) -> np.ndarray:
        """The returns in base_link at the revolution's end: each point where it was seen from, moved by the
        odometry between its time and the end."""
        n = len(ranges)
        ok = np.isfinite(ranges) & (ranges > 0.0) & (ranges <= self.config.max_range_m)
        idx = np.nonzero(ok)[0]
        a = angles[ok] + self.sensor_yaw_rad
        r = ranges[ok]
        pts = np.column_stack((r * np.cos(a) + self.sensor_xy[0], r * np.sin(a) + self.sensor_xy[1]))
        if not (scan_time_s > 0 and math.isfinite(scan_time_s)) or n == 0:
            return pts
        times = stamp_s - self.config.scan_latency_s - scan_time_s * (1.0 - (idx + 1) / n)
        # Points in a few groups by time (a pose per group): the robot's motion in a tenth of a second is smooth.
        out = np.empty_like(pts)
        groups = np.array_split(np.arange(len(pts)), 8)
        for g in groups:
            if len(g) == 0:
                continue
            at = self.odom_at(float(times[g].mean()))
            pose_t = at[0] if at is not None else odom_end
            out[g] = transform_points(pts[g], relative(odom_end, pose_t))
        return out

    # -- keyframes ---------------------------------------------------------------------------------------------
    def _add_keyframe(self, stamp_s: float, points: np.ndarray, odom: Pose2) -> None:
        cfg = self.config
        match_points = thin_points(points, cfg.matcher.resolution_m * 2, cfg.matcher.max_points)
        kf = Keyframe(stamp_s, points, self.sensor_xy, odom, self._travelled, match_points)
        if not self.keyframes:
            self.graph.add_node((0.0, 0.0, 0.0))
            self.keyframes.append(kf)
            self.stats.keyframes += 1
            return
        prev = len(self.keyframes) - 1
        prev_pose = self.graph.poses[prev]
        step = relative(self.keyframes[prev].odom, odom)
        prior = compose(prev_pose, step)
        reference = self._points_of(range(max(0, prev + 1 - cfg.local_keyframes), prev + 1))
        pose = prior
        result = None
        if len(reference) >= 20:
            result = self.matcher.match(match_points, self.matcher.field(reference), prior)
        node = self.graph.add_node(prior)
        self.keyframes.append(kf)
        self.stats.keyframes += 1
        odo_cov = chain_covariance(math.hypot(step[0], step[1]), step[2])
        self.graph.add_edge(prev, node, step, odo_cov, "odometry")
        if result is not None and result.score >= cfg.min_match_score:
            pose = result.pose
            self.graph.poses[node] = pose
            self.graph.add_edge(prev, node, relative(prev_pose, pose), _in_frame(result.covariance, prev_pose[2]),
                                "scan")
            self.stats.matched += 1
        self._try_loop_closure(node)
        self._optimise_if_due(node)

    def _points_of(self, indices: Sequence[int] | range) -> np.ndarray:
        """The match points of keyframes ``indices`` in the map frame, at their current poses (n, 2)."""
        chunks = [transform_points(self.keyframes[i].match_points, self.graph.poses[i]) for i in indices]
        return np.concatenate(chunks) if chunks else np.empty((0, 2))

    def _try_loop_closure(self, node: int) -> None:
        """Match keyframe ``node`` against the older keyframes close by; on a good match add the edge and
        optimise."""
        cfg = self.config
        if node - self._last_loop < 3:
            return
        here = self.graph.poses[node]
        travelled = self.keyframes[node].travelled_m
        poses = np.array(self.graph.poses[:node])
        old = np.array([travelled - k.travelled_m >= cfg.loop_min_travel_m for k in self.keyframes[:node]])
        if not old.any():
            return
        dist = np.hypot(poses[:, 0] - here[0], poses[:, 1] - here[1])
        dist[~old] = np.inf
        nearest = int(np.argmin(dist))
        if not dist[nearest] <= cfg.loop_search_radius_m:
            return
        self.stats.loops_tried += 1
        near = np.nonzero(old & (dist <= cfg.loop_search_radius_m + 2.0))[0]
        near = near[np.argsort(dist[near])][: cfg.loop_keyframes]
        reference = self._points_of(near.tolist())
        scan = self.keyframes[node].match_points
        coarse = self.loop_matcher.match(scan, self.loop_matcher.field(reference), here)
        if coarse is None or coarse.score < cfg.loop_min_score * 0.8:
            return
        fine = self.matcher.match(scan, self.matcher.field(reference), coarse.pose, window_xy_m=0.1,
                                  window_yaw_rad=math.radians(2.0))
        if fine is None or fine.score < cfg.loop_min_score:
            return
        anchor = int(near[0])
        anchor_pose = self.graph.poses[anchor]
        # The match places the scan against the old keyframes at their poses: a constraint to the nearest one.
        self.graph.add_edge(anchor, node, relative(anchor_pose, fine.pose),
                            _in_frame(fine.covariance, anchor_pose[2]) * 4.0, "loop")
        self.stats.loops_closed += 1
        self._last_loop = node
        self._pending = True

    def _optimise_if_due(self, node: int) -> None:
        """Optimise after a loop closure, at most once per ``optimise_every_keyframes`` keyframes."""
        if self._pending and node - self._last_optimised >= self.config.optimise_every_keyframes:
            self.optimise()
            self._last_optimised = node

    def optimise(self) -> None:
        """Optimise the pose graph (after a loop closure, and before drawing the map)."""
        if len(self.graph.poses) > 1:
            self.graph.optimise()
            self.stats.optimisations += 1
        self._pending = False

    # -- output ------------------------------------------------------------------------------------------------
    def poses(self) -> list[Pose2]:
        """The keyframes' poses in the map frame (m, m, rad), as optimised so far."""
        return list(self.graph.poses)

    def odometry_poses(self) -> list[Pose2]:
        """The keyframes' dead-reckoned poses moved into the map frame (what odometry alone would have drawn)."""
        if not self.keyframes:
            return []
        first = self.keyframes[0].odom
        return [relative(first, k.odom) for k in self.keyframes]

    def occupancy_map(self, resolution_m: Optional[float] = None,
                      poses: Optional[Sequence[Pose2]] = None) -> Optional[OccupancyMap]:
        """The map drawn from every keyframe at ``poses`` (the optimised ones by default), at ``resolution_m``
        (the config's by default): None before the first keyframe."""
        if not self.keyframes:
            return None
        return render_map(self.keyframes, list(self.graph.poses if poses is None else poses),
                          resolution_m or self.config.resolution_m, self.config)


def _in_frame(covariance: np.ndarray, yaw: float) -> np.ndarray:
    """A map-frame (x, y, yaw) covariance expressed in a frame turned by ``yaw`` (rad)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array(((c, s, 0.0), (-s, c, 0.0), (0.0, 0.0, 1.0)))
    return rot @ covariance @ rot.T


def render_map(keyframes: Sequence[Keyframe], poses: Sequence[Pose2], resolution_m: float,
               config: MappingConfig) -> OccupancyMap:
    """Ray-cast every keyframe's scan at its pose into log-odds, thresholded into an occupancy map.

    Each return makes the cells its beam crosses freer (``free_log_odds``, once per cell and scan) and the cell
    it ends in more occupied (``hit_log_odds``), clamped to ``+-max_log_odds`` after each scan, in the keyframes'
    order. So a return from something that moved (a person) is cleared by the later beams that pass where it
    was, and a wall, hit again and again, stays. Cells no beam touched stay unknown (-1); the others get the
    percentage ``100 p`` of their probability, so map_saver's thresholds decide. A dropout (no return, NaN) or
    a range beyond ``max_range_m`` never reaches here (see :meth:`OnlineMapper.add_scan`): it marks nothing and
    clears nothing.
    """
    ends = [transform_points(k.points, p) for k, p in zip(keyframes, poses)]
    origins = [transform_points(np.array([k.sensor_xy]), p)[0] for k, p in zip(keyframes, poses)]
    allxy = np.concatenate(ends + [np.array(origins)])
    res = resolution_m
    # Cell centres on multiples of the resolution: the map frame's origin (where mapping began) is a cell's centre,
    # and a wall square to it at a whole number of cells lies along cells, not on their borders.
    lo = (np.floor(allxy.min(axis=0) / res + 0.5) - 0.5) * res - 2 * res
    hi = allxy.max(axis=0) + 2 * res
    grid = empty_map(hi[0] - lo[0], hi[1] - lo[1], res, float(lo[0]), float(lo[1]))
    rows, cols = grid.rows, grid.cols
    log_odds = np.zeros(rows * cols, dtype=np.float32)
    touched = np.zeros(rows * cols, dtype=bool)
    step = res * 0.5
    for end, origin in zip(ends, origins):
        d = end - origin
        length = np.hypot(d[:, 0], d[:, 1])
        # Free samples every half cell from the sensor up to one cell short of the return.
        counts = np.maximum(0, np.floor((length - res) / step).astype(np.int64))
        total = int(counts.sum())
        beam = np.repeat(np.arange(len(end)), counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        t = (np.arange(total) - first + 0.5) * step / np.repeat(np.maximum(length, 1e-9), counts)
        fx = origin[0] + t * d[beam, 0]
        fy = origin[1] + t * d[beam, 1]
        fcol, frow = grid.to_cells(fx, fy)
        hcol, hrow = grid.to_cells(end[:, 0], end[:, 1])
        hit = np.unique(hrow * cols + hcol)
        free = np.setdiff1d(np.unique(frow * cols + fcol), hit, assume_unique=True)
        log_odds[free] += config.free_log_odds
        log_odds[hit] += config.hit_log_odds
        np.clip(log_odds, -config.max_log_odds, config.max_log_odds, out=log_odds)
        touched[free] = True
        touched[hit] = True
    p = 1.0 - 1.0 / (1.0 + np.exp(log_odds))
    data = np.where(touched, np.rint(100 * p), UNKNOWN).astype(np.int8).reshape(rows, cols)
    return grid.with_data(data)


__all__ = ["OnlineMapper", "MappingConfig", "MIN_KEYFRAME_RETURNS", "Keyframe", "MapperStats", "render_map"]
