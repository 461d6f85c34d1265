"""Driving to GPS places: ``go_to`` (and through it ``route`` and ``return_home``).

:class:`GoTo` follows the straight line from where it set off to the target
in the style of Nav2's regulated pure pursuit: it steers toward a carrot a
look-ahead distance along the line, turns in place when the carrot is far
off to the side, slows down in sharp turns and on the approach, and
succeeds once the fused position is within the tolerance of the target.
Before the heading is known (no magnetometer, no motion yet) it drives
straight ahead for a few metres so that the estimator can find it.

Positions are compared in a local east-north-up frame anchored at the
target (:class:`~beastbt.estimation.geodesy.LocalFrame`), exact at any
distance. The tuning is :class:`NavConfig` (the robot profile's
``navigation:`` section, ``schemas/parts/navigation.schema.json``).

On a robot with a LiDAR (the run's ``services.local_navigator``, a
:class:`~beastbt.navigation.local_navigator.LocalNavigator`) and a fresh
scan, the pure-pursuit command is only the preference: each tick the scan
goes into the rolling local costmap (odom frame) and the local planner
(DWA) turns the preference into a command that goes around what is there.
While obstacles are in the way the step is not "stuck" after
``stuck_after`` but "blocked" after ``blocked_after`` (default
``navigation.default_blocked_after_s``, 20 s) without progress, and the
reason names the obstacle's distance and bearing. Without a LiDAR the step
drives exactly the pure-pursuit command.
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass
from typing import Callable, Optional

import py_trees

from beastbt.core.bounded import HeadTail
from beastbt.core.schema_defaults import schema_defaults
from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import FusedPose, LaserScan, LocalPlan
from beastbt.core.config import dataclass_from_dict
from beastbt.estimation.estimator import wrap_angle
from beastbt.estimation.geodesy import TYPO_DISTANCE_M, LocalFrame, distance_m
if typing.TYPE_CHECKING:  # OpenCV and SciPy load when a robot with a LiDAR navigates, not with the language
    from beastbt.behaviours.recovery import Recoveries
    from beastbt.navigation.global_navigator import GlobalNavigator, PathFollow
    from beastbt.navigation.local_navigator import LocalNavigator
    from beastbt.navigation.local_planner import PlanResult


@dataclass(frozen=True)
@schema_defaults("parts/navigation.schema.json")
class NavConfig:
    """Tuning of go_to, route and return_home (the robot profile's ``navigation:`` section), SI units.

    Named after Nav2's regulated pure pursuit parameters where they match.
    """

    default_tolerance_m: float
    """A place counts as reached this close to it when neither the place nor the step says (m).
    The language says 2 m."""
    default_gps_timeout_s: float
    """go_to fails after this long without a GPS fix when the step gives no gps_timeout (s)."""
    lookahead_m: float
    """Distance of the carrot ahead along the line to the target (m). Longer: smoother, cuts
    corners more; shorter: tracks the line tighter but reacts to every GPS wobble."""
    rotate_to_heading_min_angle_rad: float
    """Turn in place instead of driving when the carrot is more than this off the heading (rad)."""
    regulated_min_radius_m: float
    """Below this turning radius the speed is scaled down by radius / this (m): slow in sharp turns."""
    replan_cross_track_m: float
    """When the fused position is this far to the side of the line (the estimate jumped, or the
    robot was pushed off), the line starts again from where the robot is (m)."""
    approach_dist_m: float
    """Start slowing down this far before the tolerance circle around the target (m)."""
    min_speed_mps: float
    """Slowest speed while approaching or turning on the move, so it never stalls short (m/s)."""
    heading_init_distance_m: float
    """Without a heading, drive straight at most this far for the estimator to find it (m);
    then stop and fail if it still has none. Keep it above the estimator's own
    heading_init_distance_m (10 m by default)."""
    progress_m: float
    """Getting this much closer to the target (by the fused position, or by the wheels' travel
    toward it), or this much farther along while finding the heading, counts as progress for
    stuck detection (m). Larger than the fused position's wobble at standstill."""
    stuck_position_factor: float
    """Also fail when the fused position has come no progress_m closer for this many times
    stuck_after, even though the wheels turn (tracks slipping against an obstacle)."""
    resume_gap_s: float
    """A gap this long between two ticks of the step (the mission was held or teleoperated)
    restarts the stuck timer, so that the pause does not count as being stuck (s)."""
    default_blocked_after_s: float
    """With a LiDAR: a step that obstacles keep from making progress for this long fails as blocked, when the
    step gives no blocked_after (s). The language says 20 s."""

    def __post_init__(self) -> None:
        for name in ("default_tolerance_m", "default_gps_timeout_s", "lookahead_m", "rotate_to_heading_min_angle_rad",
                     "regulated_min_radius_m", "replan_cross_track_m", "min_speed_mps", "heading_init_distance_m",
                     "progress_m",
                     "stuck_position_factor", "resume_gap_s", "default_blocked_after_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"navigation: '{name}' must be > 0, got {getattr(self, name)}")
        if self.approach_dist_m < 0.0:
            raise ValueError(f"navigation: 'approach_dist_m' must be >= 0, got {self.approach_dist_m}")

    @classmethod
    def from_dict(cls, d: dict) -> "NavConfig":
        """Build from a profile's ``navigation:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "navigation")


@dataclass
class Visit:
    """One place a go_to aimed for: ``reached`` and ``time_s`` (mission time) once it ended.

    ``estimated_error_m`` is the fused distance to the place when it was
    reached; the simulator adds ``true_error_m`` (from ground truth).
    ``tolerance_m`` is how close the step had to come to count as arrived.
    """

    name: str
    lat: Optional[float]
    lon: Optional[float]
    reached: bool = False
    time_s: Optional[float] = None
    end_stamp_s: Optional[float] = None
    estimated_error_m: Optional[float] = None
    true_error_m: Optional[float] = None
    tolerance_m: Optional[float] = None


VISITS_KEPT = 1000
"""Place visits a run keeps (the summary's ``waypoints``): the first and the last half of this many; a
``route`` that loops ``forever`` visits places for as long as the robot runs."""


class VisitLog:
    """The place visits of a run, in order (the summary's ``waypoints``): the first and the last
    ``VISITS_KEPT / 2``, and a count of those in between (``visits.dropped``)."""

    def __init__(self) -> None:
        self.visits: HeadTail[Visit] = HeadTail(VISITS_KEPT // 2, VISITS_KEPT - VISITS_KEPT // 2)
        self.listeners: list[Callable[[Visit], None]] = []
        """Called with a visit when it ends (the simulator's truth metrics listen here)."""

    def start(self, name: str, lat: Optional[float], lon: Optional[float],
              tolerance_m: Optional[float] = None) -> Visit:
        """Open a visit of place ``name`` (lat/lon None until home is known; arrival tolerance in m)."""
        v = Visit(name, lat, lon, tolerance_m=tolerance_m)
        self.visits.append(v)
        return v

    def end(self, visit: Visit) -> None:
        """Tell the listeners that ``visit`` ended."""
        for listener in self.listeners:
            listener(visit)


def visit_log(ctx: MissionContext) -> VisitLog:
    """The run's visit log (created on first use)."""
    log = ctx.services.nav_visits
    if log is None:
        log = ctx.services.nav_visits = VisitLog()
    return log


Target = Callable[[], Optional[tuple[float, float]]]
"""Where to go: a function giving (lat, lon) in degrees, or None while unknown (home before a fix)."""


LOCAL_GOAL_AHEAD_M = 2.0
"""Following a planned way, the local planner aims at the way's point this far ahead (m): inside its window."""

WAY_PATIENCE_FACTOR = 3.0
"""Following ways round, a step gives up (stuck) once the place has come no closer for this many times its
position limit (4 x stuck_after, or blocked_after: 60 s by default)."""

NARROW_LOOKAHEAD_M = 0.3
"""Near a narrow gap on the way (within the approach and a lookahead of its centre), pure pursuit aims this far ahead
(m): it keeps to the straight crossing instead of cutting in at an angle the collision monitor would stop."""

KEEP_PLANNING_S = 2.0
"""After obstacles were last in the pure-pursuit command's way, the local planner keeps choosing for this long (s)."""

FARTHEST_TARGET_M = TYPO_DISTANCE_M
"""A go_to target farther than this from the robot (m) is refused: a typo, not a destination."""


class GoTo(BeastBehaviour):
    """Drive to a GPS position (a place, coordinates or home), regulated-pure-pursuit style.

    Succeeds when the fused position is within ``tolerance_m`` of the target.
    Fails when no GPS fix came for ``gps_timeout_s`` (or home is still
    unknown by then), when it makes no progress toward the target for
    ``stuck_after_s`` (``blocked_after_s`` when obstacles were in the way
    since the last progress), or when the heading is still unknown after
    driving ``heading_init_distance_m``. Speeds m/s, times s, distances m.
    """

    READS = ("pose", "pose_odom", "gps_fix", "mission_start_s", "scan")
    WRITES = ("cmd_mission", "costmap", "local_plan")

    def __init__(self, name: str, ctx: MissionContext, place: str, target: Target, tolerance_m: Optional[float],
                 speed_mps: Optional[float] = None, gps_timeout_s: Optional[float] = None,
                 stuck_after_s: Optional[float] = None, blocked_after_s: Optional[float] = None,
                 recovery_tries: Optional[int] = None) -> None:
        super().__init__(name, ctx)
        self.recovery_tries = recovery_tries
        """Recoveries this step may run before giving up (None: the profile's ``recovery.tries``; 0: none)."""
        self.recoveries: Optional[Recoveries] = None
        self.place = place
        self.target = target
        self.tolerance_m = tolerance_m
        self.speed_mps = min(speed_mps or ctx.params.default_speed_mps, ctx.speed_limit_mps)
        self.gps_timeout_s = gps_timeout_s
        self.stuck_after_s = stuck_after_s or ctx.params.default_stuck_after_s
        self.blocked_after_s = blocked_after_s
        self.nav = NavConfig()
        self.local: Optional[LocalNavigator] = None
        self.global_nav: Optional[GlobalNavigator] = None
        self.way: Optional[PathFollow] = None
        """The planned way round what the global costmap holds (odom), or None: the straight line."""
        self.way_version = -1
        self.way_planned_at_s = -math.inf
        self.way_best_m = 0.0
        self.costmap_fresh = False
        self.last_cmd = (0.0, 0.0)
        self.obstructed_at_s = -math.inf
        self.narrow_at_m = -math.inf
        """The odometer (m) when the local planner last chose an arc through a narrow cell: until the robot has gone
        its footprint radius farther (its tail out of the gap), it drives at local_planner.narrow_speed_mps."""
        self.visit: Optional[Visit] = None
        self.goal: Optional[tuple[float, float]] = None
        self.frame: Optional[LocalFrame] = None
        self.line_start: Optional[tuple[float, float]] = None
        self.started_s = 0.0
        self.last_tick_s = 0.0
        self.progress_at_s = 0.0
        self.best_dist_m = math.inf
        self.best_dist_at_s = 0.0
        self.closer_at_s = 0.0
        """When the fused position last came closer to the place (s): on a way round, progress along the way counts,
        but not for longer than WAY_PATIENCE_FACTOR times the position limit without coming closer."""
        self.best_turn_rad = math.inf
        self.odom_at_progress_m = 0.0
        self.last_odom_m: Optional[float] = None
        self.closing_m = 0.0
        self.mode = ""
        self.init_start: Optional[FusedPose] = None
        self.distance_m = math.inf

    @property
    def way(self) -> Optional[PathFollow]:
        """The planned way round what the global costmap holds (odom), or None: the straight line. Setting it tells
        the global navigator too (``GlobalNavigator.following``), whose way the views draw (``/plan``)."""
        return self._way

    @way.setter
    def way(self, way: Optional[PathFollow]) -> None:
        self._way = way
        if self.global_nav is not None:
            self.global_nav.following = way

    # -- lifecycle ------------------------------------------------------------------------
    def initialise(self) -> None:
        self.nav = self.ctx.services.navigation or NavConfig()
        self.local = self.ctx.services.local_navigator
        self.global_nav = self.local.global_nav if self.local is not None else None
        self.recoveries = None
        if self.local is not None:  # recoveries need the LiDAR: to clear its costmaps and to look behind
            from beastbt.behaviours.recovery import (RECOVERY_CONFIG, RECOVERY_LOG, RecoveryConfig, RecoveryLog,
                                                     Recoveries)
            plugins = self.ctx.services.plugins
            config = plugins.get(RECOVERY_CONFIG) or RecoveryConfig()
            tries = self.recovery_tries if self.recovery_tries is not None else config.tries
            log = plugins.get(RECOVERY_LOG)
            if log is None:
                log = plugins[RECOVERY_LOG] = RecoveryLog()
            self.recoveries = Recoveries(config, tries, self.local.footprint_radius_m, log)
        self.way = None
        self.way_version = -1
        self.way_planned_at_s = -math.inf
        self.way_best_m = 0.0
        self.costmap_fresh = False
        self.obstructed_at_s = -math.inf
        odom = self.read("pose_odom")
        self.last_cmd = (max(0.0, odom.speed_mps), odom.yaw_rate_rps) if odom is not None else (0.0, 0.0)
        now = self.now()
        self.started_s = self.last_tick_s = now
        self.goal = None
        self.frame = None
        self.line_start = None
        self.init_start = None
        self.distance_m = math.inf
        self._restart_progress(now)
        tolerance = self.tolerance_m if self.tolerance_m is not None else self.nav.default_tolerance_m
        self.visit = visit_log(self.ctx).start(self.place, None, None, tolerance)
        self._resolve_goal()

    def terminate(self, new_status: Status) -> None:
        if self.local is not None:
            self.bb.local_plan = None  # no plan is followed once the step has ended (the costmap keeps its stamp)
        self.way = None  # nor a way round (the views take it off)
        visit = self.visit
        if visit is None:
            return
        self.visit = None
        if new_status == Status.SUCCESS:
            visit.reached = True
            visit.estimated_error_m = self.distance_m
        start = self.read("mission_start_s")
        now = self.now()
        visit.end_stamp_s = now
        visit.time_s = now - start if start is not None else None
        visit_log(self.ctx).end(visit)

    def _resolve_goal(self) -> None:
        if self.goal is None:
            goal = self.target()
            if goal is not None:
                self.goal = goal
                self.frame = LocalFrame(goal[0], goal[1])
                if self.visit is not None:
                    self.visit.lat, self.visit.lon = goal

    def _restart_progress(self, now: float) -> None:
        self.progress_at_s = now
        self.best_dist_m = math.inf
        self.best_dist_at_s = now
        self.closer_at_s = now
        self.best_turn_rad = math.inf
        odom = self.read("pose_odom")
        self.odom_at_progress_m = odom.distance_m if odom is not None else 0.0
        self.last_odom_m = None
        self.closing_m = 0.0

    # -- the tick -------------------------------------------------------------------------
    def update(self) -> Status:
        now = self.now()
        nav = self.nav
        if now - self.last_tick_s > nav.resume_gap_s:
            # The tree was not ticked for a while (hold, teleop): a pause is not being stuck.
            self._restart_progress(now)
            self.line_start = None
        self.last_tick_s = now
        self._observe(now)
        if self._recovering(now):
            return Status.RUNNING
        tolerance = self.tolerance_m if self.tolerance_m is not None else nav.default_tolerance_m
        timeout = self.gps_timeout_s if self.gps_timeout_s is not None else nav.default_gps_timeout_s
        fix = self.read("gps_fix")
        last_fix_s = fix.stamp_s if fix is not None else self.started_s
        no_fix_s = now - max(last_fix_s, self.started_s)
        self._resolve_goal()
        pose: Optional[FusedPose] = self.read("pose")
        if self.goal is None or pose is None or not pose.position_valid or pose.lat is None:
            self.command(0.0, 0.0)
            if no_fix_s > timeout:
                what = "home is not known" if self.goal is None else "no position"
                return self.fail(f"no GPS fix for {timeout:g} s ({what})")
            if fix is None:
                self.feedback_message = "waiting for a GPS fix"
            elif self.goal is None:
                # A fix is in but home (or a place relative to it) waits for the estimate to settle.
                self.feedback_message = "waiting for home: the position estimate is settling"
            else:
                self.feedback_message = "waiting for the fused position"
            return Status.RUNNING
        if no_fix_s > timeout:
            self.command(0.0, 0.0)
            return self.fail(f"no GPS fix for {timeout:g} s")
        assert self.frame is not None
        # The robot's position relative to the target (east, north), m.
        e, n, _ = self.frame.to_enu(pose.lat, pose.lon, 0.0)
        dist = math.hypot(e, n)
        self.distance_m = dist
        if dist > FARTHEST_TARGET_M:
            # Thousands of kilometres away is a typo (lat and lon swapped), not a destination.
            self.command(0.0, 0.0)
            return self.fail(f"{self.place} is {dist / 1000:.0f} km away (more than {FARTHEST_TARGET_M / 1000:g} km): "
                             f"are its lat and lon swapped? Not driving there")
        if dist <= tolerance:
            self.command(0.0, 0.0)
            self.feedback_message = f"reached, {dist:.1f} m from {self.place}"
            return Status.SUCCESS
        odom = self.read("pose_odom")
        odom_m = odom.distance_m if odom is not None else 0.0
        if not pose.heading_valid:
            return self._find_heading(now, odom, dist)
        self.init_start = None
        if self.line_start is None or self._cross_track_m(e, n) > self.nav.replan_cross_track_m:
            self.line_start = (e, n)
        return self._pursue(now, pose, e, n, dist, tolerance, odom_m)

    # -- heading unknown: drive straight ------------------------------------------------------
    def _find_heading(self, now: float, odom: Optional[FusedPose], dist: float) -> Status:
        """Drive straight ahead on the odometric heading until the estimator knows the heading."""
        nav = self.nav
        if odom is None:
            self.command(0.0, 0.0)
            self.feedback_message = "waiting for odometry"
            return Status.RUNNING
        if self.mode != "init" or self.init_start is None:
            self.mode = "init"
            self.init_start = odom
            self._restart_progress(now)
        driven = odom.distance_m - self.init_start.distance_m
        if driven > nav.heading_init_distance_m:
            self.command(0.0, 0.0)
            return self.fail(f"no heading estimate after driving {driven:.1f} m")
        hold = wrap_angle(self.init_start.yaw - odom.yaw)
        limit = self.ctx.turn_rate_limit_rps
        preferred = (self.speed_mps, max(-limit, min(limit, self.ctx.params.heading_gain * hold)))
        # With a LiDAR, round what is in the way too: the carrot is ahead on the line it set off along (odom).
        start, ux, uy = self.init_start, math.cos(self.init_start.yaw), math.sin(self.init_start.yaw)
        ahead = max(0.0, (odom.x - start.x) * ux + (odom.y - start.y) * uy) + nav.lookahead_m
        carrot = (start.x + ux * ahead, start.y + uy * ahead)
        plan = self._plan(now, odom, preferred, carrot, carrot)
        v, w = (plan.linear_mps, plan.angular_rps) if plan is not None else preferred
        if odom.distance_m - self.odom_at_progress_m >= nav.progress_m:
            self.progress_at_s = now
            self.odom_at_progress_m = odom.distance_m
        elif self.obstructed_at_s >= self.progress_at_s:
            blocked_after = max(self._blocked_after(), self.stuck_after_s)
            if now - self.progress_at_s > blocked_after:
                self.command(0.0, 0.0)
                toward = wrap_angle(math.atan2(carrot[1] - odom.y, carrot[0] - odom.x) - odom.yaw)
                return self._give_up(now, f"blocked for {blocked_after:g} s: {self._obstacle_text(toward)}, "
                                          f"while finding the heading")
        elif now - self.progress_at_s > self.stuck_after_s:
            self.command(0.0, 0.0)
            return self._give_up(now, f"stuck: no progress for {self.stuck_after_s:g} s while finding the heading")
        self.command(v, w)
        self.last_cmd = (v, w)
        self.feedback_message = f"finding the heading: {driven:.1f} m driven, {dist:.1f} m to {self.place}"
        return Status.RUNNING

    def _blocked_after(self) -> float:
        """The step's blocked_after, else the profile's default (s)."""
        return self.blocked_after_s if self.blocked_after_s is not None else self.nav.default_blocked_after_s

    # -- heading known: regulated pure pursuit -------------------------------------------------
    def _cross_track_m(self, e: float, n: float) -> float:
        """Distance (m) of the robot (target-relative ENU) from the line it follows."""
        assert self.line_start is not None
        se, sn = self.line_start
        length = math.hypot(se, sn)
        if length < 1e-6:
            return 0.0
        return abs(e * sn - n * se) / length

    def _carrot(self, e: float, n: float, dist: float) -> tuple[float, float]:
        """The point ``lookahead_m`` ahead of the robot's projection on the line, in target-relative ENU."""
        assert self.line_start is not None
        se, sn = self.line_start
        length = math.hypot(se, sn)
        la = self.nav.lookahead_m
        if length < 1e-6 or dist <= la:
            return 0.0, 0.0
        # unit vector from the start toward the target (the target is the origin)
        ue, un = -se / length, -sn / length
        along = (e - se) * ue + (n - sn) * un
        ahead = min(length, max(0.0, along) + la)
        return se + ue * ahead, sn + un * ahead

    def _pursue(self, now: float, pose: FusedPose, e: float, n: float, dist: float, tolerance: float,
                odom_m: float) -> Status:
        nav = self.nav
        p = self.ctx.params
        failed = self._global_way(now, pose, e, n, tolerance)
        if failed is not None:
            return failed
        way = self.way
        odom: Optional[FusedPose] = self.read("pose_odom")
        if way is not None and odom is not None:
            # Round what the global costmap holds: pure pursuit along the planned way (odom frame).
            along = way.project((odom.x, odom.y), 2.0 * nav.lookahead_m + 1.0)
            carrot_odom = way.point_at(along + self._way_lookahead_m(odom))
            local_goal = way.point_at(along + LOCAL_GOAL_AHEAD_M)
            dx, dy = carrot_odom[0] - odom.x, carrot_odom[1] - odom.y
            ld = math.hypot(dx, dy)
            alpha = wrap_angle(math.atan2(dy, dx) - odom.yaw)
            if along > self.way_best_m + nav.progress_m:
                # Along the way round is progress, even where it leads away from the place (out of a dead end).
                self.way_best_m = along
                self.progress_at_s = now
                self.best_dist_at_s = now
        else:
            way = None
            if self.line_start is None:
                self.line_start = (e, n)
            ce, cn = self._carrot(e, n, dist)
            de, dn = ce - e, cn - n
            ld = math.hypot(de, dn)
            alpha = wrap_angle(math.atan2(dn, de) - pose.yaw)
        # Progress: the fused position got closer to the target, or the wheels carried the robot
        # toward it (the fused distance alone stalls on the slow approach while the GPS pulls the
        # estimate about), or the heading error shrinks while turning in place.
        step_m = 0.0 if self.last_odom_m is None else odom_m - self.last_odom_m
        self.last_odom_m = odom_m
        self.closing_m += step_m * math.cos(wrap_angle(math.atan2(-n, -e) - pose.yaw))
        if self.best_dist_m == math.inf or dist > self.best_dist_m + 5.0 * nav.progress_m:
            # first look, or the estimate jumped away from the target: measure from here
            self.best_dist_m = dist
            self.best_dist_at_s = now
        elif self.best_dist_m - dist >= nav.progress_m:
            self.best_dist_m = dist
            self.best_dist_at_s = now
            self.closer_at_s = now
            self.progress_at_s = now
            self.closing_m = 0.0
        elif self.closing_m >= nav.progress_m:
            self.progress_at_s = now
            self.closing_m = 0.0
        rotate = abs(alpha) > nav.rotate_to_heading_min_angle_rad
        if rotate:
            if self.mode != "rotate":
                self.best_turn_rad = math.inf
            if abs(alpha) < self.best_turn_rad - p.stuck_progress_rad:
                self.best_turn_rad = abs(alpha)
                self.progress_at_s = now
        self.mode = "rotate" if rotate else "drive"
        preferred = self._preference(rotate, alpha, ld, dist, tolerance)
        v, w = preferred
        if way is not None and odom is not None:
            plan = self._plan(now, odom, preferred, carrot_odom, local_goal)
        else:
            plan = self._steer(now, pose, preferred, (de, dn), (-e, -n))
        if plan is not None:
            v, w = plan.linear_mps, plan.angular_rps
        # Obstacles in the way since the last progress: going round them or waiting for them is not being
        # stuck; only blocked_after without progress is.
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
        position_after = nav.stuck_position_factor * self.stuck_after_s
        if obstructed:
            position_after = max(position_after, blocked_after)
        patience = WAY_PATIENCE_FACTOR * position_after
        if way is not None and now - self.closer_at_s > patience:
            # Ways round that lead nowhere closer, one after the other (the far side of an enclosure the LiDAR has
            # not seen yet, explored back and forth): progress along each is not progress for ever.
            self.command(0.0, 0.0)
            return self._give_up(now, f"stuck: no closer to {self.place} for {patience:g} s on ways round, "
                                      f"{dist:.1f} m to go")
        if now - self.best_dist_at_s > position_after:
            # The wheels turn but the position does not follow (tracks slipping against an obstacle).
            self.command(0.0, 0.0)
            return self._give_up(now, f"stuck: no closer to {self.place} for {position_after:g} s, "
                                      f"{dist:.1f} m to go")
        self.command(v, w)
        self.last_cmd = (v, w)
        if plan is not None and (plan.linear_mps, plan.angular_rps) != preferred:
            what = "blocked, waiting" if plan.blocked and v == 0.0 and w == 0.0 else "going round an obstacle"
            self.feedback_message = f"{what}, {dist:.1f} m to {self.place}"
        elif rotate:
            self.feedback_message = f"turning toward {self.place}: {math.degrees(alpha):.0f} deg, {dist:.1f} m to go"
        elif way is not None:
            self.feedback_message = f"{dist:.1f} m to {self.place}, on the way round ({way.length_m:.1f} m planned)"
        else:
            self.feedback_message = f"{dist:.1f} m to {self.place}"
        return Status.RUNNING

    # -- recoveries: before giving up ---------------------------------------------------------------------------
    def _give_up(self, now: float, reason: str) -> Status:
        """FAILURE with ``reason``, unless a recovery is left: then it starts (RUNNING) and the step tries again
        once it has ended (:mod:`beastbt.behaviours.recovery`)."""
        rec = self.recoveries
        if rec is None or rec.left() == 0:
            return self.fail(reason)
        self.command(0.0, 0.0)
        rec.begin(self, self.ctx.events, now, reason)
        self.feedback_message = f"recovering: {rec.what}"
        return Status.RUNNING

    def _recovering(self, now: float) -> bool:
        """Tick the recovery under way; True while it runs, and on the tick it ends (the step then starts afresh:
        progress timers, the way round and the local planner's memory)."""
        rec = self.recoveries
        if rec is None or not rec.running:
            return False
        if rec.tick(self, self.ctx.events, now):
            self.feedback_message = f"recovering: {rec.what}"
            return True
        self._restart_progress(now)
        self.obstructed_at_s = -math.inf
        self.way = None
        self.way_version = -1
        self.way_planned_at_s = -math.inf
        self.last_cmd = (0.0, 0.0)
        self.feedback_message = f"trying again after {rec.what}"
        return True

    def clear_costmaps_around(self, radius_m: float) -> int:
        """The recovery ``clear``: forget the local costmap and the global costmap's marks within ``radius_m`` (m)
        of the robot; the number of global cells forgotten."""
        n = 0
        if self.local is not None:
            self.local.costmap.clear()
        odom: Optional[FusedPose] = self.read("pose_odom")
        if self.global_nav is not None and odom is not None:
            n += self.global_nav.clear_around((odom.x, odom.y), radius_m)
        return n

    def points_base(self) -> Optional[typing.Any]:
        """The newest scan's returns in base_link ((n, 2) m), or None without a LiDAR or a fresh scan."""
        scan: Optional[LaserScan] = self.read("scan")
        if self.local is None or scan is None or self.now() - scan.stamp_s > self.local.planner_config.scan_timeout_s:
            return None
        from beastbt.devices.lidar_scan import base_points_xy
        return base_points_xy(scan, self.local.mounting)

    # -- the global costmap: planning round what the LiDAR has seen -------------------------------------------
    def _global_way(self, now: float, pose: FusedPose, e: float, n: float, tolerance: float) -> Optional[Status]:
        """Keep :attr:`way` up to date: None while the straight line to the place is clear on the global costmap;
        else a path planned round the marks, again every ``global_costmap.replan_period_s`` and at once when a new
        mark blocks it. FAILURE (the reason named) when no way exists; otherwise None."""
        g = self.global_nav
        odom: Optional[FusedPose] = self.read("pose_odom")
        if g is None or odom is None:
            self.way = None
            return None
        version = g.layer.version
        due = now - self.way_planned_at_s >= g.config.replan_period_s
        if version == self.way_version and not due:
            return None
        self.way_version = version
        here = (odom.x, odom.y)
        goal = self._to_odom(-e, -n, pose, odom)
        if not g.blocked((here, goal), skip_m=g.inscribed_m):
            if self.way is not None:
                self.way = None
                self.line_start = None  # the straight line again, from where the robot is
            self.way_planned_at_s = now
            return None
        kept = self.way is not None and not g.way_blocked(self.way.ahead(), skip_m=g.inscribed_m)
        if kept and not due:
            return None  # the way planned is still clear: kept until the period is up
        from beastbt.navigation.global_navigator import SWITCH_FRACTION, SWITCH_MIN_M, PathFollow
        from beastbt.navigation.global_planner import NoPath
        try:
            if self.way is not None and not kept:
                # Blocked: mended on the side it went, unless the other way is clearly shorter (a long wall).
                path = g.replan(here, goal, tolerance, self.place, self.way.ahead())
            else:
                path = g.plan(here, goal, tolerance, self.place)
        except NoPath as exc:
            self.command(0.0, 0.0)
            return self.fail(f"no way to {self.place}: {exc.reason}")
        self.way_planned_at_s = now
        if kept and self.way is not None:
            # The way followed is still clear: only a clearly shorter one replaces it. Two ways round of about the
            # same length (either side of a dead end) would otherwise swap at every plan and the robot dither.
            ahead = self.way.ahead()
            remaining = math.hypot(ahead[0, 0] - here[0], ahead[0, 1] - here[1]) + self.way.length_m - self.way.along_m
            if path.length_m > remaining - max(SWITCH_MIN_M, SWITCH_FRACTION * remaining):
                return None
        if self.way is None:
            look = (" through a gap that looks too narrow from here, to look at it from close by" if g.tentative
                    else "")
            self.ctx.events.add("replan", f"{self.name}: the straight way is blocked; planned round, "
                                          f"{path.length_m:.1f} m{look}")
            carried = 0.0
        else:
            # What the robot went along the old way since progress was last counted counts on the new one: ways
            # replaced faster than the robot covers progress_m (new marks along a wall it follows, 4 a second)
            # otherwise never show progress, and a robot driving on round an enclosure was "stuck".
            carried = max(0.0, self.way.along_m - self.way_best_m)
        self.way = PathFollow(path.points)
        self.way_best_m = -carried
        return None

    def _way_lookahead_m(self, odom: FusedPose) -> float:
        """Pure pursuit's lookahead on a way round (m): :data:`NARROW_LOOKAHEAD_M` near a narrow gap it crosses."""
        g = self.global_nav
        la = self.nav.lookahead_m
        if g is not None:
            from beastbt.navigation.global_navigator import GAP_APPROACH_M
            for centre, _ in g.gaps:
                if math.hypot(centre[0] - odom.x, centre[1] - odom.y) < GAP_APPROACH_M + la:
                    return min(la, NARROW_LOOKAHEAD_M)
        return la

    def _preference(self, rotate: bool, alpha: float, ld: float, dist: float, tolerance: float
                    ) -> tuple[float, float]:
        """The regulated-pure-pursuit command (m/s, rad/s) toward a carrot ``alpha`` rad off the heading, ``ld`` m
        away, the target ``dist`` m away."""
        nav = self.nav
        p = self.ctx.params
        limit = self.ctx.turn_rate_limit_rps
        if rotate:
            rate = max(p.min_turn_rate_rps, min(p.default_turn_rate_rps, limit, p.turn_gain * abs(alpha)))
            return 0.0, math.copysign(rate, alpha)
        curvature = 2.0 * math.sin(alpha) / max(ld, 1e-3)
        v = self.speed_mps
        radius = 1.0 / abs(curvature) if curvature != 0.0 else math.inf
        if radius < nav.regulated_min_radius_m:
            v *= radius / nav.regulated_min_radius_m
        if nav.approach_dist_m > 0.0:
            v = min(v, self.speed_mps * (dist - tolerance) / nav.approach_dist_m)
        v = max(v, min(nav.min_speed_mps, self.speed_mps))
        w = v * curvature
        if abs(w) > limit:
            # keep the curvature: slow down rather than cut the turn
            v *= limit / abs(w)
            w = math.copysign(limit, w)
        return v, w

    # -- obstacles: the local costmap and planner ----------------------------------------------
    def _observe(self, now: float) -> None:
        """Put a new scan into the run's local costmap (robots with a LiDAR); note whether it is fresh."""
        self.costmap_fresh = False
        local = self.local
        if local is None:
            return
        scan: Optional[LaserScan] = self.read("scan")
        costmap = local.observe(scan, self.read("pose_odom"), now)
        if local.fresh_steady is not None and self.global_nav is not None:
            self.global_nav.observe(*local.fresh_steady)
        if costmap is not None:
            self.costmap_fresh = True
            self.bb.costmap = costmap

    def _to_odom(self, de: float, dn: float, pose: FusedPose, odom: FusedPose) -> tuple[float, float]:
        """A point ``de``, ``dn`` m east/north of the fused position, in the odom frame (through the body frame)."""
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        bx, by = c * de + s * dn, -s * de + c * dn
        c, s = math.cos(odom.yaw), math.sin(odom.yaw)
        return odom.x + c * bx - s * by, odom.y + s * bx + c * by

    def _steer(self, now: float, pose: FusedPose, preferred: tuple[float, float], carrot: tuple[float, float],
               target: tuple[float, float]) -> Optional[PlanResult]:
        """:meth:`_plan` for the carrot and the target given east, north m from the robot (by the fused pose)."""
        odom: Optional[FusedPose] = self.read("pose_odom")
        if odom is None:
            return None
        return self._plan(now, odom, preferred, self._to_odom(carrot[0], carrot[1], pose, odom),
                          self._to_odom(target[0], target[1], pose, odom))

    def _plan(self, now: float, odom: FusedPose, preferred: tuple[float, float], carrot: tuple[float, float],
              target: tuple[float, float]) -> Optional[PlanResult]:
        """The local planner's plan for the preferred command (v m/s, w rad/s), the carrot and the target (odom,
        m), written to ``local_plan``; None without a LiDAR or a fresh scan (drive the preference)."""
        local = self.local
        if local is None:
            return None
        if not self.costmap_fresh:
            return self._narrow_hold(odom, preferred, None)
        # Half way round something (obstructed a moment ago), the planner keeps choosing: pure pursuit would turn
        # straight back toward the line, into what it is going round.
        result = local.planner.plan(local.costmap.latest, (odom.x, odom.y, odom.yaw), self.last_cmd, preferred,
                                    carrot, self.speed_mps, self.ctx.turn_rate_limit_rps, target,
                                    keep_planning=now - self.obstructed_at_s < KEEP_PLANNING_S)
        if not result.free:
            self.obstructed_at_s = now
        if result.narrow:
            # Creeping through a narrow gap (the monitor slows it further) is being obstructed, not stuck.
            self.narrow_at_m = odom.distance_m
            self.obstructed_at_s = now
        else:
            result = self._narrow_hold(odom, (result.linear_mps, result.angular_rps), result) or result
        self.bb.local_plan = LocalPlan(now, result.points_xy, result.linear_mps, result.angular_rps, result.blocked)
        return result

    def _narrow_hold(self, odom: FusedPose, twist: tuple[float, float], plan: Optional[PlanResult]
                     ) -> Optional[PlanResult]:
        """The twist (m/s, rad/s; of ``plan``, or the preference between scans) slowed to ``narrow_speed_mps`` on its
        own curvature while the robot is less than its footprint radius past the last arc through a narrow cell (its
        tail may still be in the gap); None when it need not be (drive it as it is)."""
        local = self.local
        assert local is not None
        slow = local.planner_config.narrow_speed_mps
        v, w = twist
        if odom.distance_m - self.narrow_at_m > local.footprint_radius_m or v <= slow:
            return None
        import numpy as np

        from beastbt.navigation.local_planner import PlanResult
        points = plan.points_xy if plan is not None else np.zeros((0, 2))
        free = plan.free if plan is not None else False
        return PlanResult(slow, w * slow / v, points, free, False, 1, 1, True)

    def _obstacle_text(self, toward_rad: float) -> str:
        """``obstacle 0.6 m ahead, 15 deg to the left``: the nearest obstacle round the bearing ``toward_rad``
        (rad CCW from the heading)."""
        local = self.local
        odom: Optional[FusedPose] = self.read("pose_odom")
        if local is None or odom is None:
            return "an obstacle in the way"
        found = local.nearest_obstacle(odom, toward_rad)
        from beastbt.navigation.local_navigator import describe_obstacle
        return describe_obstacle(*found) if found is not None else "an obstacle in the way"


def place_target(lat: float, lon: float) -> Target:
    """A fixed target at (lat, lon) degrees."""
    return lambda: (lat, lon)


def home_target(ctx: MissionContext) -> Target:
    """Home: where the mission started (the first good fix), once known."""
    def target() -> Optional[tuple[float, float]]:
        return ctx.services.home()
    return target


BREADCRUMB_SPACING_M = 2.0
"""return_home along the path keeps a point of the fused path every this many metres (m)."""


class DrivenPath:
    """A path thinned to one point every ``spacing_m`` (m): the fused path driven so far for ``return_home: {along:
    path}``, a recorded one for ``beastbt route from-run``."""

    def __init__(self, spacing_m: float = BREADCRUMB_SPACING_M) -> None:
        self.spacing_m = spacing_m
        self.points: list[tuple[float, float]] = []

    def add(self, lat: float, lon: float) -> None:
        """A position (deg): kept when it is at least ``spacing_m`` from the last point kept."""
        if not self.points or distance_m(self.points[-1][0], self.points[-1][1], lat, lon) >= self.spacing_m:
            self.points.append((lat, lon))


class RetracePath(py_trees.composites.Composite):
    """``return_home: {along: path}``: drive the path driven so far backwards, point by point, then home.

    ``leg`` is a :class:`GoTo` whose target is this block's current point.
    SUCCESS at home; FAILURE when a leg fails (as the leg says).
    """

    def __init__(self, name: str, leg_factory: Callable[[Target], "GoTo"], path: DrivenPath,
                 home: Target) -> None:
        self.points: list[tuple[float, float]] = []
        self.home_known = False
        self.index = 0
        self.path = path
        self.home = home
        self.leg = leg_factory(self._current)
        super().__init__(name=name, children=[self.leg])

    def _current(self) -> Optional[tuple[float, float]]:
        return self.points[self.index] if self.index < len(self.points) else None

    def _point_name(self) -> str:
        """The current point in words: ``path point 3 of 20`` (counted from where the retrace starts), or ``home``."""
        along = len(self.points) - (1 if self.home_known else 0)
        if self.home_known and self.index == len(self.points) - 1:
            return "home"
        return f"path point {self.index + 1} of {along}"

    def tick(self) -> typing.Iterator[py_trees.behaviour.Behaviour]:
        if self.status != Status.RUNNING:
            if self.leg.status != Status.INVALID:
                self.leg.stop(Status.INVALID)
            home = self.home()
            self.points = list(reversed(self.path.points)) + ([home] if home is not None else [])
            self.home_known = home is not None
            self.index = 0
            self.initialise()
        if self.leg.status != Status.RUNNING:
            self.leg.place = self._point_name()  # what the visit (the summary's waypoint) is called
        self.current_child = self.leg
        for node in self.leg.tick():
            yield node
        if self.leg.status == Status.FAILURE:
            self.feedback_message = self.leg.feedback_message
            self.stop(Status.FAILURE)
        elif self.leg.status == Status.SUCCESS:
            self.index += 1
            if self.index >= len(self.points):
                self.feedback_message = "home, along the path driven"
                self.stop(Status.SUCCESS)
            else:
                self.leg.stop(Status.INVALID)  # the next tick starts the leg to the next point
                self.feedback_message = f"back along the path: point {self.index + 1} of {len(self.points)}"
                self.status = Status.RUNNING
        else:
            self.status = Status.RUNNING
        yield self


class RouteLegs(py_trees.composites.Sequence):
    """The legs of a ``route`` in order; with ``resume: nearest``, a pause moves on to the nearest remaining leg.

    A pause is a gap between ticks longer than the navigation's
    ``resume_gap_s`` (a hold, a take-over). Then the leg whose place is the
    closest to the fused position, among the one under way and those after
    it, is driven next; the legs skipped are not visited.
    """

    def __init__(self, name: str, ctx: MissionContext, legs: list["GoTo"], resume: str) -> None:
        super().__init__(name=name, memory=True, children=legs)
        self.ctx = ctx
        self.resume = resume
        self.last_tick_s: Optional[float] = None
        self.reader = py_trees.blackboard.Client(name=f"{name} (resume)")
        self.reader.register_key("pose", access=py_trees.common.Access.READ)

    def tick(self) -> typing.Iterator[py_trees.behaviour.Behaviour]:
        now = self.ctx.clock.now()
        nav = self.ctx.services.navigation or NavConfig()
        if (self.resume == "nearest" and self.status == Status.RUNNING and self.current_child is not None
                and self.last_tick_s is not None and now - self.last_tick_s > nav.resume_gap_s):
            self._go_on_from_the_nearest()
        self.last_tick_s = now
        yield from super().tick()

    def _go_on_from_the_nearest(self) -> None:
        try:
            pose = self.reader.get("pose")
        except KeyError:
            return
        if pose is None or not pose.position_valid or pose.lat is None:
            return
        start = self.children.index(self.current_child)
        best, best_m = None, math.inf
        for leg in self.children[start:]:
            goal = leg.target() if isinstance(leg, GoTo) else None
            if goal is not None:
                d = distance_m(pose.lat, pose.lon, goal[0], goal[1])
                if d < best_m:
                    best, best_m = leg, d
        if best is not None and best is not self.current_child:
            if self.current_child.status == Status.RUNNING:
                self.current_child.stop(Status.INVALID)
            self.ctx.events.add("route", f"{self.name}: resuming at the nearest place, {best.place} "
                                         f"({best_m:.1f} m away)")
            self.current_child = best
