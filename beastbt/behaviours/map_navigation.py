"""Driving to places on the mission's map: ``go_to``, ``route`` and ``return_home`` indoors, by a planned path.

On a mission with ``map:`` whose places are on the map (``{x, y}``), the
navigation steps compile to :class:`MapGoTo` instead of the GPS
:class:`~beastbt.behaviours.navigation.GoTo`. It reads the robot's pose on
the map (``map_pose``, from the localiser), plans a path with the global
planner (:mod:`beastbt.navigation.global_planner`: A* on the map inflated by
the footprint) and follows it with regulated pure pursuit toward a carrot a
look-ahead along the path; on a robot with a LiDAR that command is the
preference the local planner (DWA on the rolling costmap) turns into one
that goes around what is there, exactly as outdoors.

It plans again (Nav2's replanning):

* every ``global_planner.replan_period_s``, from where the robot is;
* when it has come no closer along the path for ``blocked_replan_s``: what
  the LiDAR sees within a metre ahead on the path is marked lethal on the
  map's costmap first, so the new path goes another way (through another
  door) if there is one;
* when the robot has strayed farther than ``navigation.replan_cross_track_m``
  from the path.

It fails at once, with the reason, when no path exists (the goal off the
map, in a wall or an unknown cell, enclosed, or every way blocked), when the
robot has not been localised on the map for ``gps_timeout`` (the GPS step's
own "no position" limit; until then it drives on the localiser's pose, carried
by odometry, as Nav2 does on AMCL's), and when blocked for ``blocked_after``
without progress. ``return_home`` goes to where the mission started on the map.
Nothing here reads a clock but the context's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from beastbt.behaviours.base import Status
from beastbt.behaviours.context import MissionContext
from beastbt.behaviours.navigation import GoTo
from beastbt.blackboard.types import FusedPose, GlobalPlan, MapPose
from beastbt.estimation.estimator import wrap_angle

MapTarget = Callable[[], Optional[tuple[float, float]]]
"""Where to go on the map: a function giving (x, y) in metres (map frame), or None while unknown."""

MAP_PLANNER = "map_planner"
"""The key of the run's :class:`MapPlanner` in ``ctx.services.plugins``."""

LOCAL_GOAL_AHEAD_M = 2.0
"""The local planner aims at the path's point this far ahead (m): within its window (local_costmap.width_m / 2)."""

BLOCKED_LOOK_M = 1.0
"""On a blocked replan, scan points this far ahead along the path (m) and near it are marked lethal."""

NARROW_PROGRESS_M = 0.05
"""Near a narrow door the path crosses, this much travel by the wheels (m) counts as progress along the path for the
blocked replan: the robot creeps there (narrow_speed_mps, or slower in the collision monitor's slow zone: 0.024 m/s,
2 s), and a blocked replan would mark what it sees of the door's jambs, which may close it."""


@dataclass
class MapVisit:
    """One place on the map a go_to aimed for (the summary's ``map_waypoints``): metres, seconds."""

    name: str
    x: Optional[float]
    y: Optional[float]
    tolerance_m: float
    reached: bool = False
    time_s: Optional[float] = None
    estimated_error_m: Optional[float] = None
    true_error_m: Optional[float] = None
    path_m: Optional[float] = None
    """The length of the first path planned to it (m)."""
    replans: int = 0


class MapPlanner:
    """The run's global planner on the mission's map: its costmap (built on first use, with the profile's
    ``global_planner:`` and footprint), the plans made and the visits, for the summary and the views."""

    def __init__(self, grid: Any, start_xy_yaw: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        from beastbt.navigation.global_planner import GlobalPlannerConfig
        self.grid = grid
        self.start = start_xy_yaw
        """Where the mission started on the map (x m, y m, yaw rad): home."""
        self.config = GlobalPlannerConfig()
        self.layer_config: Any = None
        self.footprint_radius_m = 0.15
        self._costmap: Any = None
        self._map_only: Any = None
        self._layer: Any = None
        self.visits: list[MapVisit] = []
        self.plans = 0
        self.gaps: list[tuple[np.ndarray, np.ndarray]] = []
        """The narrow gaps (doors the padding would close) the last plan crosses square: (centre (2,) map m, unit
        normal (2,) along the path)."""
        self.mark_min_quality = 0.6
        """The obstacle layer takes a scan only while the localiser's match quality is at least this (its
        ``lost_quality``, set by the navigation part): below it the pose is in doubt, and returns placed with a wrong
        pose wall the robot in where the map is open (a start given wrongly)."""
        self.listeners: list[Callable[[MapVisit], None]] = []
        """Called with a visit when it ends (the simulator's truth listens here)."""

    def configure(self, config: Any, footprint_radius_m: float, layer_config: Any = None) -> None:
        """The profile's ``global_planner:`` section, the robot's footprint radius (m) and the ``global_costmap:``
        section (the obstacle layer's), before the first plan."""
        self.config = config
        self.footprint_radius_m = footprint_radius_m
        self.layer_config = layer_config
        self._costmap = None
        self._map_only = None
        self._layer = None

    @property
    def costmap(self) -> Any:
        """The :class:`~beastbt.navigation.global_planner.GlobalCostmap` of the map (built on first use)."""
        if self._costmap is None:
            from beastbt.navigation.global_planner import GlobalCostmap
            self._costmap = GlobalCostmap(self.grid, self.config, self.footprint_radius_m)
        return self._costmap

    @property
    def layer(self) -> Any:
        """The :class:`~beastbt.navigation.obstacle_layer.ObstacleLayer` over the map (built on first use): what the
        LiDAR has seen that the map does not show, marked and cleared by ray tracing. The map's walls and a band
        of ``footprint_padding_m`` (at least a cell) and one cell more round them are never marked."""
        if self._layer is None:
            import cv2

            from beastbt.navigation.obstacle_layer import GlobalCostmapConfig, ObstacleLayer
            grid = self.grid
            layer = ObstacleLayer(self.layer_config or GlobalCostmapConfig(), grid.rows, grid.cols, grid.resolution_m,
                                  grid.origin_x, grid.origin_y)
            # The padding and a cell more: the localiser's few cm of error put a wall's returns a cell beside it, and
            # at a door's jamb such a mark would close a door only the narrow cells open (docs/navigation.md).
            k = max(1, int(math.ceil(self.config.footprint_padding_m / grid.resolution_m))) + 1
            walls = grid.occupied().astype(np.uint8)
            layer.unmarkable = cv2.dilate(walls, np.ones((2 * k + 1, 2 * k + 1), np.uint8)).astype(bool)
            self._layer = layer
        return self._layer

    def way_on_the_map(self, start: tuple[float, float], goal: tuple[float, float], tolerance_m: float,
                       name: str) -> Optional[str]:
        """None when the map alone (without the obstacle layer's marks) has a way from ``start`` to ``goal`` (map m);
        else why not (``NoPath``'s reason). Its costmap is built on first use and never marked."""
        from beastbt.navigation.global_planner import GlobalCostmap, NoPath, plan_path
        if self._map_only is None:
            self._map_only = GlobalCostmap(self.grid, self.config, self.footprint_radius_m)
        try:
            plan_path(self._map_only, start, goal, tolerance_m, goal_name=name)
        except NoPath as exc:
            return exc.reason
        return None

    def costmap_now(self) -> Any:
        """The costmap with what the obstacle layer holds now (recomputed when the layer changed)."""
        cm = self.costmap
        if self._layer is not None and cm.layer_version != self._layer.version:
            cm.set_obstacles(self._layer.marked, self._layer.version)
        return cm

    def plan(self, start: tuple[float, float], goal: tuple[float, float], tolerance_m: float, name: str) -> Any:
        """A :class:`~beastbt.navigation.global_planner.GlobalPath` (map frame, m); raises ``NoPath``. A door only
        the narrow cells open is crossed square, as on GPS (:func:`~beastbt.navigation.global_navigator.through_gaps`:
        the collision monitor's stop zone leaves a few cm to a side)."""
        from beastbt.navigation.global_navigator import through_gaps
        from beastbt.navigation.global_planner import plan_path
        self.plans += 1
        costmap = self.costmap_now()
        path, self.gaps = through_gaps(plan_path(costmap, start, goal, tolerance_m, goal_name=name), costmap)
        return path


def map_waypoints(planner: MapPlanner) -> list[dict]:
    """The summary's ``map_waypoints``: each place on the map a go_to aimed for, in order (metres, seconds)."""
    def r(v: Optional[float], nd: int = 3) -> Optional[float]:
        return None if v is None else round(float(v), nd)
    return [{"name": v.name, "x": r(v.x), "y": r(v.y), "reached": v.reached, "time_s": r(v.time_s, 2),
             "tolerance_m": r(v.tolerance_m), "estimated_error_m": r(v.estimated_error_m),
             "arrival_error_m": r(v.true_error_m if v.true_error_m is not None else v.estimated_error_m),
             "path_m": r(v.path_m, 2), "replans": v.replans} for v in planner.visits]


def map_waypoint_rows(planner: MapPlanner) -> list[dict]:
    """The map's visits as rows of the summary's ``waypoints``, the table GPS places get: ``lat``/``lon`` null,
    ``x``/``y`` the place in the map frame (m); the arrival error the true one in the simulator (m)."""
    return [{"name": w["name"], "lat": None, "lon": None, "x": w["x"], "y": w["y"], "reached": w["reached"],
             "arrival_error_m": w["arrival_error_m"] if w["reached"] else None, "time_s": w["time_s"],
             "tolerance_m": w["tolerance_m"], "estimated_error_m": w["estimated_error_m"] if w["reached"] else None}
            for w in map_waypoints(planner)]


def mission_map_start(mission: Any) -> tuple[float, float, float]:
    """Where a mission with ``map:`` starts on its map (x m, y m, yaw rad): its ``start:`` pose, the place it names,
    or the map frame's origin. Home on the map."""
    name = getattr(mission, "map_start_place", None)
    place = mission.places.get(name) if name is not None else None
    if place is not None and place.on_map:
        return (place.x, place.y, place.yaw or 0.0)
    return tuple(mission.map_start)  # type: ignore[return-value]


def map_planner(ctx: MissionContext, grid: Any, start: tuple[float, float, float]) -> MapPlanner:
    """The run's :class:`MapPlanner` (made on first use, for the mission's map and its start on it)."""
    planner = ctx.services.plugins.get(MAP_PLANNER)
    if planner is None:
        planner = ctx.services.plugins[MAP_PLANNER] = MapPlanner(grid, start)
    return planner


def _to_body(dx: float, dy: float, yaw: float) -> tuple[float, float]:
    c, s = math.cos(yaw), math.sin(yaw)
    return c * dx + s * dy, -s * dx + c * dy


class MapGoTo(GoTo):
    """Drive to a place on the map along a planned path (regulated pure pursuit, DWA round obstacles with a LiDAR).

    Succeeds when the pose on the map is within ``tolerance_m`` of the place.
    Fails at once when no path exists (the reason names why); when the robot
    has not been localised on the map for ``gps_timeout_s``; when it makes no
    progress for ``stuck_after_s`` (``blocked_after_s`` while obstacles are in
    the way) even after replanning. Metres, seconds, map frame.
    """

    READS = ("map_pose", "pose_odom", "mission_start_s", "scan")
    WRITES = ("cmd_mission", "costmap", "local_plan", "global_plan")

    def __init__(self, name: str, ctx: MissionContext, place: str, target: MapTarget, planner: MapPlanner,
                 tolerance_m: Optional[float], speed_mps: Optional[float] = None,
                 gps_timeout_s: Optional[float] = None, stuck_after_s: Optional[float] = None,
                 blocked_after_s: Optional[float] = None, recovery_tries: Optional[int] = None) -> None:
        super().__init__(name, ctx, place, lambda: None, tolerance_m, speed_mps, gps_timeout_s, stuck_after_s,
                         blocked_after_s, recovery_tries)
        self.map_target = target
        self.planner = planner
        self.path: Optional[np.ndarray] = None
        self.cum: Optional[np.ndarray] = None
        self.along_m = 0.0
        self.planned_at_s = -math.inf
        self.best_along_m = -math.inf
        self.best_along_at_s = 0.0
        self.map_visit: Optional[MapVisit] = None
        self.unlocalised_since_s: Optional[float] = None
        self.replans = 0
        self.path_version = -1
        self.narrow_odom_m = -math.inf
        """The wheels' odometer (m) when creeping near a narrow door last counted as progress."""
        self.marks_forgotten = False
        """Whether this step has forgotten the obstacle layer's marks because only they closed the way."""

    # -- lifecycle ----------------------------------------------------------------------------------
    def initialise(self) -> None:
        super().initialise()
        self.global_nav = None  # on the map the obstacle layer is the map planner's, in the map frame
        self.path_version = -1
        # Places on the map are no GPS waypoints: the GPS visit GoTo opened keeps lat/lon None (the summary's
        # waypoints leave it out) and this step's visit is a map visit (the summary's map_waypoints).
        self.path = None
        self.cum = None
        self.along_m = 0.0
        self.planned_at_s = -math.inf
        self.best_along_m = -math.inf
        self.best_along_at_s = self.now()
        self.unlocalised_since_s = None
        self.replans = 0
        self.narrow_odom_m = -math.inf
        self.marks_forgotten = False
        goal = self.map_target()
        self.map_visit = MapVisit(self.place, goal[0] if goal else None, goal[1] if goal else None,
                                  self._tolerance())
        self.planner.visits.append(self.map_visit)

    def terminate(self, new_status: Status) -> None:
        super().terminate(new_status)
        self.bb.global_plan = None
        visit = self.map_visit
        if visit is None:
            return
        self.map_visit = None
        visit.reached = new_status == Status.SUCCESS
        if visit.reached:
            visit.estimated_error_m = self.distance_m
        visit.replans = self.replans
        start = self.read("mission_start_s")
        visit.time_s = self.now() - start if start is not None else None
        for listener in self.planner.listeners:
            listener(visit)

    def _tolerance(self) -> float:
        return self.tolerance_m if self.tolerance_m is not None else self.planner.config.default_tolerance_m

    # -- the tick -----------------------------------------------------------------------------------
    def update(self) -> Status:
        now = self.now()
        nav = self.nav
        if now - self.last_tick_s > nav.resume_gap_s:
            self._restart_progress(now)  # a hold or a take-over is not being stuck
            self.best_along_at_s = now
            self.path = None  # and the robot may have been driven anywhere: plan again from where it is
        self.last_tick_s = now
        self._observe(now)
        if self._recovering(now):
            return Status.RUNNING
        timeout = self.gps_timeout_s if self.gps_timeout_s is not None else nav.default_gps_timeout_s
        pose: Optional[MapPose] = self.read("map_pose")
        if pose is None or not pose.localized:
            # Not localised: without a pose at all it waits; with one it drives on (AMCL's pose carried by odometry,
            # as Nav2 does: an obstacle the map does not show spoils the match until the robot has gone round it;
            # the localization_lost failsafe is where a mission says to hold instead), for at most the timeout.
            since = self.unlocalised_since_s = self.unlocalised_since_s if self.unlocalised_since_s is not None \
                else now
            if now - since > timeout:
                self.command(0.0, 0.0)
                what = ("no pose on the map (is the map localisation running?)" if pose is None
                        else f"scan match quality {pose.match_quality:.2f}")
                return self.fail(f"not localized on the map for {timeout:g} s ({what}); not driving to "
                                 f"{self.place}")
            if pose is None:
                self.command(0.0, 0.0)
                self.feedback_message = "waiting for a pose on the map"
                return Status.RUNNING
        else:
            self.unlocalised_since_s = None
        goal = self.map_target()
        if goal is None:
            self.command(0.0, 0.0)
            return self.fail(f"{self.place} is not known on the map")
        if self.map_visit is not None and self.map_visit.x is None:
            self.map_visit.x, self.map_visit.y = goal
        gx, gy = goal
        dist = math.hypot(gx - pose.x, gy - pose.y)
        self.distance_m = dist
        tolerance = self._tolerance()
        if dist <= tolerance:
            self.command(0.0, 0.0)
            self.feedback_message = f"reached, {dist:.2f} m from {self.place}"
            return Status.SUCCESS
        status = self._replan_if_due(now, pose, goal, tolerance)
        if status is not None:
            return status
        return self._follow(now, pose, goal, dist, tolerance)

    # -- planning -------------------------------------------------------------------------------------
    def _replan_if_due(self, now: float, pose: MapPose, goal: tuple[float, float],
                       tolerance: float) -> Optional[Status]:
        """Plan when there is no path, periodically, when off the path, or when stalled (marking what blocks
        it); FAILURE with the reason when no path exists, else None."""
        cfg = self.planner.config
        why = None
        if self.path is None:
            why = "start"
        elif cfg.replan_period_s > 0.0 and now - self.planned_at_s >= cfg.replan_period_s:
            why = "period"
        elif self._off_path_m(pose) > cfg.replan_off_path_m:
            why = "off the path"
        elif now - self.best_along_at_s > cfg.blocked_replan_s:
            why = "blocked"
            self._mark_blocking(pose)
        elif self._path_blocked():
            why = "blocked by what the LiDAR sees"
        if why is None:
            return None
        from beastbt.navigation.global_planner import NoPath
        try:
            path = self.planner.plan((pose.x, pose.y), goal, max(tolerance * 0.5, 0.0), self.place)
        except NoPath as exc:
            self.command(0.0, 0.0)
            reason = exc.reason
            layer = self.planner._layer
            if layer is not None and layer.marked.any():
                # The LiDAR's marks may be what closes the way: marks made from a pose the localiser had wrong for a
                # moment (a start given wrongly) wall the robot in where the map is open. When the map alone has a
                # way, Nav2 clears its costmap and plans again, then runs its recoveries; when it has none, no
                # recovery makes one: fail at once.
                on_map = self.planner.way_on_the_map((pose.x, pose.y), goal, max(tolerance * 0.5, 0.0), self.place)
                if on_map is None and not self.marks_forgotten:
                    # the first time in a step: forget every mark (Nav2's ClearEntireCostmap) and plan on the map;
                    # the scans mark again what is truly there, from the pose as it is now
                    self.marks_forgotten = True
                    n = layer.forget()
                    self.ctx.events.add("replan", f"{self.name}: no way round what the LiDAR has marked, though the "
                                                  f"map has one: {n} marked cells forgotten, planning on the map")
                    self.path = None
                    return self._replan_if_due(now, pose, goal, tolerance)
                if on_map is None:
                    reason += "; the map has a way, what the LiDAR has marked closes it"
                    return self._give_up(now, f"blocked: no other way to {self.place} ({reason}); "
                                              f"{self._obstacle_text(0.0)}" if why.startswith("blocked")
                                         else f"no path to {self.place}: {reason}")
                reason = on_map
            if why.startswith("blocked"):
                return self.fail(f"blocked: no other way to {self.place} ({reason}); {self._obstacle_text(0.0)}")
            return self.fail(f"no path to {self.place}: {reason}")
        if why != "start":
            self.replans += 1
            if why != "period":
                self.ctx.events.add("replan", f"{self.name}: planned again ({why}), {path.length_m:.1f} m to go")
        elif self.map_visit is not None and self.map_visit.path_m is None:
            self.map_visit.path_m = path.length_m
        self.path = path.points
        seg = np.hypot(*np.diff(self.path, axis=0).T) if len(self.path) > 1 else np.zeros(0)
        self.cum = np.concatenate(([0.0], np.cumsum(seg)))
        self.along_m = 0.0
        self.planned_at_s = now
        self.best_along_m = -math.inf
        self.best_along_at_s = now
        self.bb.global_plan = GlobalPlan(now, self.path, self.place, path.length_m)
        return None

    def _off_path_m(self, pose: MapPose) -> float:
        """Distance (m) from the robot to the nearest segment of the path ahead."""
        p = self.path
        if p is None or len(p) < 2:
            return 0.0
        a, b = p[:-1], p[1:]
        ab = b - a
        t = np.clip(((pose.x - a[:, 0]) * ab[:, 0] + (pose.y - a[:, 1]) * ab[:, 1])
                    / np.maximum((ab ** 2).sum(axis=1), 1e-12), 0.0, 1.0)
        d = np.hypot(a[:, 0] + t * ab[:, 0] - pose.x, a[:, 1] + t * ab[:, 1] - pose.y)
        return float(d.min())

    def _mark_blocking(self, pose: MapPose) -> None:
        """Mark lethal on the map's costmap the LiDAR's points that lie near the path just ahead: what stopped the
        robot, so the next path goes round it or another way."""
        local = self.local
        odom: Optional[FusedPose] = self.read("pose_odom")
        if local is None or odom is None or self.path is None or self.cum is None:
            return
        pts = local.costmap.points_odom
        if len(pts) == 0:
            return
        # odom -> body -> map, through the robot's pose in each frame
        bx, by = _to_body(pts[:, 0] - odom.x, pts[:, 1] - odom.y, odom.yaw)
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        mx, my = pose.x + c * bx - s * by, pose.y + s * bx + c * by
        ahead = self.path[(self.cum >= self.along_m) & (self.cum <= self.along_m + BLOCKED_LOOK_M)]
        if len(ahead) == 0:
            return
        near = np.zeros(len(mx), bool)
        reach = self.planner.costmap.inscribed_m + 0.1
        for x, y in ahead:
            near |= np.hypot(mx - x, my - y) <= reach
        # densify the polyline ahead with the points near it, so that a thin door's gap is closed
        if near.any():
            self.planner.layer.mark_points(mx[near], my[near])

    def _observe(self, now: float) -> None:
        """As GoTo's, and a new scan also marks and clears the map's obstacle layer, placed on the map where the
        robot was when it was measured (its revolution's middle): its pose on the map now, moved back by the
        wheels' motion since then."""
        super()._observe(now)
        local = self.local
        pose: Optional[MapPose] = self.read("map_pose")
        odom: Optional[FusedPose] = self.read("pose_odom")
        if local is None or local.fresh is None or pose is None or odom is None or not pose.localized:
            return
        if pose.match_quality < self.planner.mark_min_quality:
            return  # the localiser is losing its place (or never had it): the scan would be placed wrongly
        if self.planner.layer_config is not None and not self.planner.layer_config.enabled:
            return
        from beastbt.estimation.map_localiser import compose, invert, scan_mid_s
        from beastbt.navigation.global_navigator import lidar_pose
        scan, at = local.fresh
        at = local.pose_at(scan_mid_s(scan)) or at  # where the localiser matches it too: its revolution's middle
        # Not map_pose's map -> odom composed with ``at``: that transform is for the localiser's own odometry (the
        # wheels' travel turned by the gyro), while ``at`` is on the wheels' (pose_odom), and a tracked base's
        # wheels drift from the gyro by 10-15 degrees over an office tour: a scan placed that way draws the walls
        # turned about the robot, as new obstacles across the corridors. Only the motion since the scan (a tick or
        # two) is taken from the wheels here.
        since = compose(invert((odom.x, odom.y, odom.yaw)), at)
        base = compose((pose.x, pose.y, pose.yaw), since)
        self.planner.layer.update(lidar_pose(local.mounting, base), scan.angles_rad, scan.ranges_m)

    def clear_costmaps_around(self, radius_m: float) -> int:
        """As GoTo's, and the map's obstacle layer round the robot's pose on the map; a new path is planned."""
        n = super().clear_costmaps_around(radius_m)
        pose: Optional[MapPose] = self.read("map_pose")
        layer = self.planner._layer
        if layer is not None and pose is not None:
            n += layer.clear_around(pose.x, pose.y, radius_m)
        self.path = None
        return n

    def _path_blocked(self) -> bool:
        """Whether a mark of the obstacle layer has come within the inscribed radius of the path ahead since the
        last look (checked once per change of the layer)."""
        layer = self.planner._layer
        if layer is None or self.path is None or self.cum is None or layer.version == self.path_version:
            return False
        self.path_version = layer.version
        from beastbt.navigation.global_navigator import disk_offsets, marks_near
        inscribed = self.planner.costmap.inscribed_m
        ahead = self.path[self.cum >= self.along_m]
        if len(ahead) == 0:
            return False
        start = np.array([self._point_at(self.along_m)])
        return marks_near(layer, np.vstack((start, ahead)), disk_offsets(inscribed / layer.resolution_m),
                          skip_m=inscribed)

    # -- following ------------------------------------------------------------------------------------
    def _project(self, pose: MapPose) -> float:
        """How far along the path (m) the robot is: the nearest point of the path from a little behind the last
        such point onward (so that a path passing near itself is not skipped ahead)."""
        p, cum = self.path, self.cum
        assert p is not None and cum is not None
        if len(p) < 2:
            return 0.0
        a, b = p[:-1], p[1:]
        ab = b - a
        L2 = np.maximum((ab ** 2).sum(axis=1), 1e-12)
        t = np.clip(((pose.x - a[:, 0]) * ab[:, 0] + (pose.y - a[:, 1]) * ab[:, 1]) / L2, 0.0, 1.0)
        d = np.hypot(a[:, 0] + t * ab[:, 0] - pose.x, a[:, 1] + t * ab[:, 1] - pose.y)
        along = cum[:-1] + t * np.sqrt(L2)
        window = (along >= self.along_m - 0.5) & (along <= self.along_m + 2.0 * self.planner.config.lookahead_m + 1.0)
        if window.any():
            d = np.where(window, d, np.inf)
        i = int(np.argmin(d))
        return float(max(self.along_m, along[i]))

    def _point_at(self, along_m: float) -> tuple[float, float]:
        """The path's point ``along_m`` (m) from its start (its end beyond)."""
        p, cum = self.path, self.cum
        assert p is not None and cum is not None
        if along_m >= cum[-1]:
            return float(p[-1, 0]), float(p[-1, 1])
        i = int(np.searchsorted(cum, along_m, side="right")) - 1
        f = (along_m - cum[i]) / max(cum[i + 1] - cum[i], 1e-12)
        return float(p[i, 0] + f * (p[i + 1, 0] - p[i, 0])), float(p[i, 1] + f * (p[i + 1, 1] - p[i, 1]))

    def _follow(self, now: float, pose: MapPose, goal: tuple[float, float], dist: float, tolerance: float) -> Status:
        nav, p = self.nav, self.ctx.params
        self.along_m = self._project(pose)
        self._creep_progress(now, pose)
        if self.along_m > self.best_along_m + nav.progress_m:
            self.best_along_m = self.along_m
            self.best_along_at_s = now
            self.progress_at_s = now
        cx, cy = self._point_at(self.along_m + self._lookahead_m(pose))
        dx, dy = cx - pose.x, cy - pose.y
        ld = math.hypot(dx, dy)
        alpha = wrap_angle(math.atan2(dy, dx) - pose.yaw)
        rotate = abs(alpha) > nav.rotate_to_heading_min_angle_rad
        if rotate:
            if self.mode != "rotate":
                self.best_turn_rad = math.inf
            if abs(alpha) < self.best_turn_rad - p.stuck_progress_rad:
                self.best_turn_rad = abs(alpha)
                self.progress_at_s = now
                self.best_along_at_s = now  # turning toward the path is progress too: not blocked
        self.mode = "rotate" if rotate else "drive"
        remaining = float(self.cum[-1] - self.along_m) if self.cum is not None else dist
        preferred = self._preference(rotate, alpha, ld, max(dist, min(remaining, dist + 1.0)), tolerance)
        v, w = preferred
        # The local planner's own goal is a point further along the path, inside its window (not the place, which
        # may lie beyond a wall it cannot see round): it follows the global path, as Nav2's controller does.
        tx, ty = self._point_at(self.along_m + LOCAL_GOAL_AHEAD_M)
        plan = self._steer_map(now, pose, preferred, (dx, dy), (tx - pose.x, ty - pose.y))
        if plan is not None:
            v, w = plan.linear_mps, plan.angular_rps
        obstructed = self.obstructed_at_s >= self.progress_at_s
        blocked_after = self._blocked_after()
        if obstructed and now - self.progress_at_s > max(blocked_after, self.stuck_after_s):
            self.command(0.0, 0.0)
            return self._give_up(now, f"blocked for {max(blocked_after, self.stuck_after_s):g} s: "
                                      f"{self._obstacle_text(alpha)}, {dist:.1f} m to {self.place}")
        if not obstructed and now - self.progress_at_s > self.stuck_after_s:
            self.command(0.0, 0.0)
            return self._give_up(now, f"stuck: no progress for {self.stuck_after_s:g} s, {dist:.1f} m to "
                                      f"{self.place}")
        self.command(v, w)
        self.last_cmd = (v, w)
        if plan is not None and (plan.linear_mps, plan.angular_rps) != preferred:
            what = "blocked, waiting" if plan.blocked and v == 0.0 and w == 0.0 else "going round an obstacle"
            self.feedback_message = f"{what}, {remaining:.1f} m to {self.place}"
        elif rotate:
            self.feedback_message = (f"turning toward {self.place}: {math.degrees(alpha):.0f} deg, "
                                     f"{remaining:.1f} m to go")
        else:
            self.feedback_message = f"{remaining:.1f} m to {self.place} along the path"
        return Status.RUNNING

    def _near_gap(self, pose: MapPose) -> bool:
        """Whether the robot is within a narrow gap's square crossing and a lookahead (m) of its centre."""
        from beastbt.navigation.global_navigator import GAP_APPROACH_M
        reach = GAP_APPROACH_M + self.planner.config.lookahead_m
        return any(math.hypot(c[0] - pose.x, c[1] - pose.y) < reach for c, _ in self.planner.gaps)

    def _creep_progress(self, now: float, pose: MapPose) -> None:
        """Creeping to and through a narrow door is progress, not a blockage: near a narrow gap the path crosses, each
        :data:`NARROW_PROGRESS_M` the wheels travel restarts the blocked replan's timer."""
        odom: Optional[FusedPose] = self.read("pose_odom")
        if odom is None or not self._near_gap(pose):
            return
        if odom.distance_m - self.narrow_odom_m >= NARROW_PROGRESS_M:
            if self.narrow_odom_m > -math.inf:
                self.best_along_at_s = now
            self.narrow_odom_m = odom.distance_m

    def _lookahead_m(self, pose: MapPose) -> float:
        """Pure pursuit's lookahead (m): :data:`~beastbt.behaviours.navigation.NARROW_LOOKAHEAD_M` near a narrow gap
        the path crosses, so that the robot keeps to the square crossing, as GoTo's does on GPS."""
        from beastbt.behaviours.navigation import NARROW_LOOKAHEAD_M
        la = self.planner.config.lookahead_m
        return min(la, NARROW_LOOKAHEAD_M) if self._near_gap(pose) else la

    def _steer_map(self, now: float, pose: MapPose, preferred: tuple[float, float], carrot: tuple[float, float],
                   target: tuple[float, float]) -> Any:
        """The local planner's command for the carrot and target given as map-frame offsets (m) from the robot."""
        odom: Optional[FusedPose] = self.read("pose_odom")
        if odom is None or self.local is None or not self.costmap_fresh:
            return None

        def to_odom(d: tuple[float, float]) -> tuple[float, float]:
            bx, by = _to_body(d[0], d[1], pose.yaw)
            c, s = math.cos(odom.yaw), math.sin(odom.yaw)
            return odom.x + c * bx - s * by, odom.y + s * bx + c * by
        return self._plan(now, odom, preferred, to_odom(carrot), to_odom(target))


def near_on_map(xy: tuple[float, float], within_m: float) -> Callable[[Any], bool]:
    """The condition ``near: place`` for a place on the map at ``xy`` (m): the pose on the map (``map_pose``) is
    within ``within_m`` (m) of it; false without a pose on the map."""
    def test(r: Any) -> bool:
        pose = r.get("map_pose")
        if pose is None:
            return False
        return math.hypot(pose.x - xy[0], pose.y - xy[1]) <= within_m
    return test


def map_place_target(x: float, y: float) -> MapTarget:
    """A fixed place on the map at (x, y) m."""
    return lambda: (x, y)


def map_home_target(planner: MapPlanner) -> MapTarget:
    """Home on the map: where the mission started on it."""
    return lambda: (planner.start[0], planner.start[1])


__all__ = ["MapGoTo", "MapPlanner", "MapVisit", "map_planner", "mission_map_start", "map_waypoints",
           "map_waypoint_rows", "near_on_map",
           "map_place_target", "map_home_target", "MAP_PLANNER"]
