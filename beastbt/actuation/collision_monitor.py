"""The collision monitor below the tree: stop, slow and approach zones on the latest LiDAR scan, like Nav2's.

It sits in the safety path after the mux (so teleop, failsafes and the
mission are all limited alike) and with the safety gate, and is given the
latest scan through one narrow interface, a callable ``latest_scan() ->
Optional[LaserScan]``. It knows nothing of the tree.

Each tick :meth:`CollisionMonitor.limit` takes the command and returns it,
scaled by a ratio in [0, 1] (at ratio 0 from the scan, the travel only: the
turn in place is kept, see below):

* **silent** (Nav2's ``source_timeout``): no scan, or a scan older than
  ``source_timeout_s``: every motion is held (ratio 0) until scans return;
* **stop** (``action_type: stop``): at least ``min_points`` points in the
  stop polygon that the command moves the robot toward: ratio 0;
* **slow** (``action_type: slowdown``): the same in the slow polygon: ratio
  ``slow.ratio``;
* **approach** (``action_type: approach``): the command is simulated forward
  for ``approach.time_s`` in steps of ``simulation_time_step_s``; if the
  footprint (a circle of the profile's footprint radius round base_link) would
  cover at least ``min_points`` points, ratio = free time / ``time_s``, so the
  robot keeps ``time_s`` from contact and stops one step short of it.

The smallest ratio wins. "Toward" is what makes the monitor let a robot drive
away: the footprint is a circle round base_link, so under a twist (v, w) a
point at (x, y) in base_link gets closer at the rate v * x / |p| (a turn does
not change the distance), and a point only counts for stop and slow when
v * x > 0. Reversing from a wall ahead, or turning in place beside it, is let
through; driving on into it is not. Approach counts a point only where the
simulated footprint is closer to it than now, for the same reason.

Each action is one event per episode (an episode ends after
:data:`EPISODE_GAP_S` without any limit); the silent state has its own
events, when the scans stop and when they return. Time comes from the
caller (``now_s``): nothing here reads a clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Callable, Optional

import numpy as np
import shapely

from beastbt.blackboard.types import VelocityCommand
from beastbt.core.schema_defaults import schema_defaults
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.devices.lidar_scan import LaserScan, LidarMounting, base_points_xy

SCHEMA = "parts/collision_monitor.schema.json"

NONE, SLOW, APPROACH, STOP, SILENT = "none", "slow", "approach", "stop", "silent"
ACTIONS = (NONE, SLOW, APPROACH, STOP, SILENT)
"""The monitor's actions, weakest first (a tie in ratio goes to the stronger)."""

EPISODE_GAP_S = 1.0
"""An episode of limiting ends after this long without any limit (then the same action is an event again), s."""

STOP_MARGIN_M = 0.05
"""Default stop zone: ahead and behind, the footprint plus this, plus :data:`STOP_MARGIN_TIME_S` at the top speed, m."""
STOP_MARGIN_TIME_S = 0.1
"""Default stop zone: how far the robot goes at the top speed in this long (a scan period), s."""
STOP_SIDE_MARGIN_M = 0.03
"""Default stop zone: to each side, the footprint plus this, metres (narrow, so that driving along a wall or
through a doorway is not stopped: the approach check sees what a turn would hit)."""
SLOW_AHEAD_TIME_S = 1.0
"""Default slow zone: the stop zone stretched forward by the top speed times this, s."""
SLOW_WIDEN_M = 0.05
"""Default slow zone: the stop zone widened by this on each side, metres."""
DEFAULT_FOOTPRINT_RADIUS_M = 0.15
"""Footprint radius when the profile states none (the simulator's default), metres."""


@dataclass
@schema_defaults(SCHEMA + "#/properties/stop", computed={"polygon_m": "from the footprint and the top speed"})
class StopZone:
    """``collision_monitor.stop``: Nav2's ``action_type: stop`` polygon (base_link, metres)."""

    enabled: bool
    polygon_m: Optional[list] = None
    """Corners [x, y], metres; None = from the footprint and the top speed."""


@dataclass
@schema_defaults(SCHEMA + "#/properties/slow", computed={"polygon_m": "from the stop zone and the top speed"})
class SlowZone:
    """``collision_monitor.slow``: Nav2's ``action_type: slowdown`` polygon and ``slowdown_ratio``."""

    enabled: bool
    ratio: float
    """What the command is multiplied by (0-1)."""
    polygon_m: Optional[list] = None
    """Corners [x, y], metres; None = from the stop zone and the top speed."""


@dataclass
@schema_defaults(SCHEMA + "#/properties/approach")
class ApproachZone:
    """``collision_monitor.approach``: Nav2's ``action_type: approach`` (``time_before_collision``)."""

    enabled: bool
    time_s: float
    """How far ahead the command is simulated, seconds."""
    simulation_time_step_s: float
    """Step of that simulation, seconds."""


@dataclass
@schema_defaults(SCHEMA, computed={"stop": "a nested config with its own schema (StopZone)",
                                   "slow": "a nested config with its own schema (SlowZone)",
                                   "approach": "a nested config with its own schema (ApproachZone)"})
class CollisionMonitorConfig:
    """The profile's ``collision_monitor:`` section; see the schema for each knob."""

    enabled: bool
    min_points: int
    """Fewest points that trigger a zone or a collision."""
    source_timeout_s: float
    """A scan older than this holds the robot, seconds."""
    stop: StopZone = field(default_factory=StopZone)
    slow: SlowZone = field(default_factory=SlowZone)
    approach: ApproachZone = field(default_factory=ApproachZone)

    @classmethod
    def from_dict(cls, d: Any) -> "CollisionMonitorConfig":
        """Build from a profile dict (already unit-converted); unknown keys or bad values raise ``ValueError``."""
        if not isinstance(d, dict):
            raise ValueError(f"collision_monitor must be a mapping, got {type(d).__name__}")
        cfg = cls()
        nested = {"stop": StopZone, "slow": SlowZone, "approach": ApproachZone}
        _check_keys("collision_monitor", d, {f.name for f in fields(cls)})
        for name, value in d.items():
            if name in nested:
                if not isinstance(value, dict):
                    raise ValueError(f"{name} must be a mapping")
                sub = nested[name]()
                _check_keys(name, value, {f.name for f in fields(sub)})
                for key, v in value.items():
                    setattr(sub, key, _polygon(f"{name}.{key}", v) if key == "polygon_m" and v is not None else v)
                value = sub
            setattr(cfg, name, value)
        if isinstance(cfg.min_points, bool) or not isinstance(cfg.min_points, int) or cfg.min_points < 1:
            raise ValueError(f"min_points must be a whole number >= 1, got {cfg.min_points!r}")
        if not cfg.source_timeout_s > 0 or not cfg.approach.time_s > 0 or not cfg.approach.simulation_time_step_s > 0:
            raise ValueError("source_timeout_s, approach.time_s and approach.simulation_time_step_s must be > 0")
        if not 0.0 < cfg.slow.ratio <= 1.0:
            raise ValueError(f"slow.ratio must be in (0, 1], got {cfg.slow.ratio!r}")
        return cfg


def _check_keys(where: str, d: dict, known: set[str]) -> None:
    unknown = sorted(map(str, set(d) - known))
    if unknown:
        raise ValueError(f"unknown {where} key(s): {', '.join(unknown)} (known: {', '.join(sorted(known))})")


def _polygon(name: str, value: Any) -> list:
    try:
        pts = [[float(x), float(y)] for x, y in value]
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a list of [x, y] corners in metres, got {value!r}") from None
    if len(pts) < 3:
        raise ValueError(f"{name} needs at least 3 corners, got {len(pts)}")
    return pts


def default_zones(footprint_radius_m: float, max_speed_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """The default stop and slow polygons (base_link, metres) for a footprint radius and a top speed.

    Stop: a box round the footprint, reaching radius + 0.05 m + 0.1 s at the
    top speed ahead and behind, and radius + 0.03 m to each side. Slow: that
    box stretched forward by 1 s at the top speed and widened by 0.05 m each side.
    """
    h = footprint_radius_m + STOP_MARGIN_M + STOP_MARGIN_TIME_S * max_speed_mps
    side = footprint_radius_m + STOP_SIDE_MARGIN_M
    stop = np.array([[h, side], [-h, side], [-h, -side], [h, -side]])
    ahead = h + SLOW_AHEAD_TIME_S * max_speed_mps
    w = side + SLOW_WIDEN_M
    slow = np.array([[ahead, w], [-h, w], [-h, -w], [ahead, -w]])
    return stop, slow


def inside_polygon(points: np.ndarray, polygon: Any) -> np.ndarray:
    """Boolean mask of the (n, 2) ``points`` inside ``polygon`` ((k, 2) corners or a shapely polygon).

    shapely's vectorised ``contains_xy`` on a prepared polygon (a zone is
    prepared once): about 3x quicker than a numpy even-odd test on a scan's
    ~450 points (benchmarks/collision_monitor.py). A point on the border is outside.
    """
    if not isinstance(polygon, shapely.Polygon):
        polygon = shapely.Polygon(polygon)
    return np.asarray(shapely.contains_xy(polygon, points[:, 0], points[:, 1]), dtype=bool)


@dataclass
class _ScanView:
    """What the monitor keeps of one scan: its points in base_link, and the near ones with their zones.

    Near means closer than the monitor's ``near_m``: every point of a zone,
    and every point the approach check can reach at the top speed, is near.
    The checks of each tick look at the near points only (a handful: most of
    a scan is farther away).
    """

    scan: LaserScan
    points: np.ndarray
    ranges: np.ndarray
    near_points: np.ndarray
    near_ranges: np.ndarray
    in_stop: np.ndarray
    """For each near point: inside the stop zone."""
    in_slow: np.ndarray
    """For each near point: inside the slow zone."""
    nearest: dict = field(default_factory=dict)
    """What :meth:`CollisionMonitor._describe` said of the nearest point, by zone and direction (this scan's)."""


class CollisionMonitor:
    """Limits velocity commands from the latest scan: stop, slow, approach, and hold while the LiDAR is silent.

    ``latest_scan()`` gives the newest :class:`LaserScan` (or None), in the
    LiDAR's frame, placed on the robot by ``mounting``;
    ``footprint_radius_m`` (metres) and ``max_speed_mps`` (m/s) give the
    default zones; ``events(kind, text)`` receives one event per action per
    episode. :attr:`action` and :attr:`ratio` say what the last
    :meth:`limit` did, :meth:`status` all of it.
    """

    def __init__(self, config: CollisionMonitorConfig, latest_scan: Callable[[], Optional[LaserScan]],
                 footprint_radius_m: float, max_speed_mps: float,
                 mounting: Optional[LidarMounting] = None, events: EventSink = ignore_events) -> None:
        self.config = config
        self.latest_scan = latest_scan
        self.footprint_radius_m = footprint_radius_m
        self.mounting = mounting if mounting is not None else LidarMounting()
        self.events = events
        stop, slow = default_zones(footprint_radius_m, max_speed_mps)
        self.stop_polygon = np.array(config.stop.polygon_m, dtype=float) if config.stop.polygon_m else stop
        self.slow_polygon = np.array(config.slow.polygon_m, dtype=float) if config.slow.polygon_m else slow
        self._stop_shape = shapely.Polygon(self.stop_polygon)
        self._slow_shape = shapely.Polygon(self.slow_polygon)
        shapely.prepare(self._stop_shape)
        shapely.prepare(self._slow_shape)
        self.near_m = float(max(np.hypot(*self.stop_polygon.T).max(), np.hypot(*self.slow_polygon.T).max(),
                                footprint_radius_m + max_speed_mps * config.approach.time_s)) + 0.01
        """Points closer than this (m) are all a tick looks at at up to the top speed: both zones lie within it
        (a polygon lies within its farthest corner's distance) and so does the approach's reach."""
        step = config.approach.simulation_time_step_s
        self._sim_t = np.arange(1, int(math.ceil(config.approach.time_s / step)) + 1) * step
        """The approach simulation's times, s."""
        self.action = NONE
        self.ratio = 1.0
        self.reason = ""
        self.limited_source = ""
        self._view: Optional[_ScanView] = None
        self._reported: set[str] = set()
        self._last_limit_s = -math.inf
        self._silent_reported = False
        self._had_scan = False
        self.limited_ticks: dict[str, int] = {}
        """Action -> how many calls of :meth:`limit` it cut a command (for the summary)."""
        self.episodes: dict[str, int] = {}
        """Action -> how many events (episodes) it had."""

    # -- the scan ---------------------------------------------------------------
    def _current(self, now_s: float) -> Optional[_ScanView]:
        """The view of the latest scan, or None when there is none or it is older than ``source_timeout_s``."""
        scan = self.latest_scan()
        if scan is None or now_s - scan.stamp_s > self.config.source_timeout_s:
            return None
        if self._view is None or self._view.scan is not scan:
            pts = base_points_xy(scan, self.mounting)
            ranges = np.hypot(pts[:, 0], pts[:, 1])
            near = ranges < self.near_m
            near_pts = pts[near]
            off = np.zeros(len(near_pts), bool)
            self._view = _ScanView(scan, pts, ranges, near_pts, ranges[near],
                                   inside_polygon(near_pts, self._stop_shape) if self.config.stop.enabled and
                                   len(near_pts) else off,
                                   inside_polygon(near_pts, self._slow_shape) if self.config.slow.enabled and
                                   len(near_pts) else off)
        return self._view

    # -- the limit ----------------------------------------------------------------
    def limit(self, cmd: VelocityCommand, now_s: float) -> VelocityCommand:
        """``cmd`` scaled by the strongest action that applies at ``now_s`` (``cmd`` itself when none does)."""
        if not self.config.enabled:
            return cmd
        view = self._current(now_s)
        moving = not cmd.is_zero()
        if view is None:
            self._silent(cmd, now_s, moving)
            if not moving:
                return cmd
            self._set(SILENT, 0.0, self.reason, cmd, now_s)
            return VelocityCommand(0.0, 0.0, cmd.stamp_s, cmd.source)
        self._back(now_s)
        if not moving:
            self._set(NONE, 1.0, "", cmd, now_s)
            return cmd
        action, ratio, why = self._evaluate(view, cmd.linear_mps, cmd.angular_rps)
        self._set(action, ratio, why, cmd, now_s)
        if ratio >= 1.0:
            return cmd
        if ratio <= 0.0:
            # Stopped: the travel, not the turn. Turning in place brings no point closer to the footprint (the rule
            # above), and a robot held whole beside a wall's corner stayed there: the planner's turning arc was
            # stopped at every scan, and nothing turned it to where its arc is free.
            return VelocityCommand(0.0, cmd.angular_rps, cmd.stamp_s, cmd.source)
        return VelocityCommand(cmd.linear_mps * ratio, cmd.angular_rps * ratio, cmd.stamp_s, cmd.source)

    def _evaluate(self, view: _ScanView, v: float, w: float) -> tuple[str, float, str]:
        """The strongest action for the twist (v m/s, w rad/s) against ``view``: (action, ratio, why)."""
        cfg = self.config
        best = (NONE, 1.0, "")
        if v == 0.0:
            # Turning in place brings no point closer to a circular footprint round base_link: nothing to limit
            # (the checks below would find nothing: no point is toward, none gets closer in the simulation).
            return best
        # Points the twist brings closer: d|p|/dt = -v x / |p| for a circular footprint round base_link.
        # Counted among the near points (the zones hold no other).
        toward = v * view.near_points[:, 0] > 1e-9
        n_stop = int(np.count_nonzero(view.in_stop & toward))
        if n_stop >= cfg.min_points:
            return STOP, 0.0, self._describe(f"{n_stop} points in the stop zone", view, STOP, v)
        if cfg.approach.enabled:
            free_s = self._free_time(view, v, w)
            if free_s < cfg.approach.time_s:
                ratio = free_s / cfg.approach.time_s
                best = (APPROACH, ratio, self._describe(
                    f"contact in {free_s + cfg.approach.simulation_time_step_s:.2f} s at this command", view,
                    APPROACH, v))
        n_slow = int(np.count_nonzero(view.in_slow & toward))
        if n_slow >= cfg.min_points and cfg.slow.ratio < best[1]:
            best = (SLOW, cfg.slow.ratio, self._describe(f"{n_slow} points in the slow zone", view, SLOW, v))
        return best

    def _free_time(self, view: _ScanView, v: float, w: float) -> float:
        """How long the twist (v, w) can be followed before the footprint covers ``min_points`` points, s.

        The robot's centre after t seconds of the twist, in the present
        base_link: (sin(wt) v/w, (1 - cos(wt)) v/w). A point counts at a step
        when it is inside the footprint there and closer than it is now (so
        points the robot drives away from never block it). Steps of
        ``simulation_time_step_s``; the result is the last free step's time.
        """
        cfg = self.config.approach
        r = self.footprint_radius_m
        reach = r + abs(v) * cfg.time_s + 1e-6
        # Only points the footprint can reach in time_s (an arc is no longer than |v| t): near ones up to the
        # top speed, any beyond it (a command above the top speed: the gate clamps it only afterwards).
        pts, ranges = (view.near_points, view.near_ranges) if reach < self.near_m else (view.points, view.ranges)
        near = ranges < reach
        if np.count_nonzero(near) < self.config.min_points:
            return cfg.time_s
        p = pts[near]
        # Inside the footprint and closer than now: squared distance below min(r, d0) squared.
        limit = np.minimum(ranges[near], r) ** 2
        t = self._sim_t
        if abs(w) < 1e-9:
            cx, cy = v * t, np.zeros_like(t)
        else:
            cx, cy = np.sin(w * t) * v / w, (1.0 - np.cos(w * t)) * v / w
        dx = p[:, 0] - cx[:, None]
        dy = p[:, 1] - cy[:, None]
        hits = np.count_nonzero(dx * dx + dy * dy < limit, axis=1)
        blocked = np.flatnonzero(hits >= self.config.min_points)
        if blocked.size == 0:
            return cfg.time_s
        return float(blocked[0]) * cfg.simulation_time_step_s

    @staticmethod
    def _describe(what: str, view: _ScanView, zone: str, v: float) -> str:
        """``what``, and where the nearest point is of those in ``zone`` (all points for the approach) that
        the linear speed ``v`` drives toward."""
        key = (zone, v > 0.0)
        nearest = view.nearest.get(key)
        if nearest is None:
            # The same for every tick of this scan in this zone and direction: said once, kept with the scan.
            # Among the near points (all of a zone's; for the approach, the nearest point driven toward is a
            # near one if any near one is driven toward), else among all.
            points, ranges = view.near_points, view.near_ranges
            mask = v * points[:, 0] > 1e-9
            if zone != APPROACH:
                mask &= view.in_stop if zone == STOP else view.in_slow
            elif not np.any(mask):
                points, ranges = view.points, view.ranges
                mask = v * points[:, 0] > 1e-9
            nearest = ""
            if np.any(mask):
                i = int(np.argmin(np.where(mask, ranges, np.inf)))
                x, y = points[i]
                nearest = f"; nearest {ranges[i]:.2f} m at {math.degrees(math.atan2(y, x)):.0f} deg"
            view.nearest[key] = nearest
        return what + nearest

    # -- state and events -----------------------------------------------------------
    def _set(self, action: str, ratio: float, why: str, cmd: VelocityCommand, now_s: float) -> None:
        self.action, self.ratio, self.reason = action, ratio, why
        if now_s - self._last_limit_s > EPISODE_GAP_S:
            self._reported.clear()
        if action == NONE:
            return
        self._last_limit_s = now_s
        self.limited_source = cmd.source
        self.limited_ticks[action] = self.limited_ticks.get(action, 0) + 1
        if action in self._reported or action == SILENT:
            return
        self._reported.add(action)
        self.episodes[action] = self.episodes.get(action, 0) + 1
        what = {STOP: "stop", SLOW: f"slow to {ratio:.0%}", APPROACH: f"approach at {ratio:.0%}"}[action]
        self.events("collision_monitor", f"collision monitor: {what} ({cmd.source}'s command): {why}")

    def _silent(self, cmd: VelocityCommand, now_s: float, moving: bool) -> None:
        scan = self.latest_scan()
        if scan is None:
            why = "no scan yet"
        else:
            why = f"no scan for {now_s - scan.stamp_s:.2f} s (source_timeout_s {self.config.source_timeout_s:g} s)"
        self.reason = f"LiDAR silent: {why}"
        if not moving:
            self.action, self.ratio = SILENT, 1.0
        # Before the first scan (a motor spinning up) say so only when it holds a motion back.
        if not self._silent_reported and (self._had_scan or moving):
            self._silent_reported = True
            self.episodes[SILENT] = self.episodes.get(SILENT, 0) + 1
            self.events("collision_monitor", f"collision monitor: LiDAR silent, {why}: the robot is held "
                                             f"until scans return")

    def _back(self, now_s: float) -> None:
        first = not self._had_scan
        self._had_scan = True
        if self._silent_reported:
            self._silent_reported = False
            self.events("collision_monitor", "collision monitor: " + ("first LiDAR scan" if first else
                                                                      "LiDAR scans are back") + ": the robot may move")

    def zones(self) -> dict[str, Any]:
        """The zones in base_link: polygons as lists of [x, y] metres, the footprint radius and approach time."""
        cfg = self.config
        return {"stop": self.stop_polygon.tolist() if cfg.stop.enabled else None,
                "slow": self.slow_polygon.tolist() if cfg.slow.enabled else None,
                "slow_ratio": cfg.slow.ratio, "footprint_radius_m": self.footprint_radius_m,
                "approach_time_s": cfg.approach.time_s if cfg.approach.enabled else None,
                "min_points": cfg.min_points, "source_timeout_s": cfg.source_timeout_s}

    def summary(self) -> dict[str, Any]:
        """For the run summary: the zones, and per action the episodes (events) and the ticks it cut a command."""
        return {"zones": self.zones(), "episodes": dict(self.episodes), "limited_ticks": dict(self.limited_ticks)}

    def holding(self) -> Optional[str]:
        """Why the last :meth:`limit` held a motion back (stop, approach, slow or a silent LiDAR), naming the nearest
        point's distance (m from base_link) and bearing (deg, left positive); None when it let the command through.

        What a step that makes no progress adds to its failure, so that "blocked" says what blocked it.
        """
        if self.action == NONE or self.ratio >= 1.0:
            return None
        what = {STOP: "stopped it", SLOW: f"slowed it to {self.ratio:.0%}", APPROACH: f"held it to {self.ratio:.0%}",
                SILENT: "held it"}[self.action]
        return f"the collision monitor {what}: {self.reason}"

    def status(self) -> dict[str, Any]:
        """What the last :meth:`limit` did: action (none/slow/approach/stop/silent), ratio, why, whose command."""
        return {"action": self.action, "ratio": self.ratio, "reason": self.reason, "source": self.limited_source}


def footprint_radius(profile_data: dict) -> float:
    """The profile's footprint radius: ``geometry.footprint_radius_m``, else ``sim.footprint_radius_m``, else 0.15 m."""
    for section in ("geometry", "sim"):
        value = (profile_data.get(section) or {}).get("footprint_radius_m")
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    return DEFAULT_FOOTPRINT_RADIUS_M


__all__ = ["CollisionMonitor", "CollisionMonitorConfig", "StopZone", "SlowZone", "ApproachZone", "default_zones",
           "inside_polygon", "footprint_radius", "ACTIONS", "NONE", "SLOW", "APPROACH", "STOP",
           "SILENT", "EPISODE_GAP_S"]
