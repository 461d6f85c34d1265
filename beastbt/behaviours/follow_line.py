"""Following the line the camera sees: ``follow_line`` with its ``until`` conditions.

:class:`FollowLine` steers by pure pursuit on the line detector's offset at
its look-ahead distance ``L`` (``line_detector.lookahead_m``): the arc
through the robot centre and the line point ``(L, y)`` has curvature
``k = 2 y / (L^2 + y^2)``, commanded as ``w = v k`` (clamped); the speed is
reduced in curves, ``v = speed / (1 + curve_slowdown_m |k|)`` (but not below
``min_speed_fraction`` of it). While the line is briefly out of sight the
last turn rate is held at reduced speed.

``until``:

* ``intersection``: the camera sees a junction 0.75 m to 0.25 m ahead,
  before the robot is there. Each sighting is turned into a position in the
  odometry frame (the pose when the frame was taken plus the reported
  distance along the heading); sightings within ``junction_merge_m`` are one
  junction, confirmed after ``junction_confirm_frames`` frames. The robot then
  drives on, slowing down, until odometry says its centre is over the
  junction, and the step succeeds there (so that a ``turn`` that follows
  puts it on the new branch). The last stretch, under the camera, is driven
  on odometry: losing the line there does not fail the step.
* ``line_end``: losing the line (out of sight for ``lost_after``) is success.
* ``{distance}``: the odometric path length since the step started (slowing
  down to stop on the mark).
* ``{time}``: the time since the step started.

Before moving, the step points the camera where the detector expects it (pan
and tilt servos at 0, the ``camera.mounting``) and, unless they were already
there, waits ``default_settle_s`` for them. Fails when the line is out of
sight for longer than ``lost_after`` (default 1 s), except with ``line_end``,
and when odometry shows no progress towards the distance mark or the
junction for ``stuck_after`` (``control.default_stuck_after_s``, 5 s).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Optional

from beastbt.core.schema_defaults import schema_defaults
from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import FusedPose, LineObservation, ServoCommand
from beastbt.core.config import dataclass_from_dict

UNTIL_KINDS = ("intersection", "line_end", "distance", "time")

POSE_HISTORY_S = 1.0
"""Odometry poses kept to place a junction at the time its frame was taken (s)."""


@dataclass
@schema_defaults("parts/line_follower.schema.json")
class FollowLineConfig:
    """Tuning of ``follow_line`` (robot profile ``line_follower:``), SI units."""

    # Speed when the step gives none, m/s. The detector is tested at 0.12-0.15 m/s.
    default_speed_mps: float
    # Highest turn rate the follower commands, rad/s (the mission's and robot's limits still apply).
    max_turn_rate_rps: float
    # Slow down in curves: speed / (1 + curve_slowdown_m x curvature); 0 keeps the speed, metres.
    curve_slowdown_m: float
    # Never slower than this fraction of the step's speed because of a curve (0-1).
    min_speed_fraction: float
    # While the line is briefly out of sight: this fraction of the speed, last turn rate held (0-1).
    lost_speed_fraction: float
    # How long the line may be out of sight before the step fails, s (the step's lost_after overrides it).
    default_lost_after_s: float
    # A line observation older than this counts as not seeing the line, s (3 frames at 15 fps + a tick).
    observation_max_age_s: float
    # Frames that must see a junction (within junction_merge_m) before the step heads for it.
    junction_confirm_frames: int
    # Sightings closer than this are the same junction, m.
    junction_merge_m: float
    # until intersection / distance: done when the centre is this close to the mark, m.
    stop_tolerance_m: float
    # Deceleration planned to stop on the junction or the distance mark, m/s^2.
    stop_decel_mps2: float
    # Slowest speed of the final approach, so it never stalls short, m/s.
    min_approach_speed_mps: float

    def __post_init__(self) -> None:
        for name in ("default_speed_mps", "max_turn_rate_rps", "default_lost_after_s", "observation_max_age_s",
                     "junction_merge_m", "stop_tolerance_m", "stop_decel_mps2", "min_approach_speed_mps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"line_follower.{name} must be > 0, got {getattr(self, name)}")
        if self.curve_slowdown_m < 0:
            raise ValueError(f"line_follower.curve_slowdown_m must be >= 0 m, got {self.curve_slowdown_m}")
        for name in ("min_speed_fraction", "lost_speed_fraction"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ValueError(f"line_follower.{name} must be in (0, 1], got {getattr(self, name)}")
        if self.junction_confirm_frames < 1:
            raise ValueError(f"line_follower.junction_confirm_frames must be >= 1, got {self.junction_confirm_frames}")

    @classmethod
    def from_dict(cls, d: Any) -> "FollowLineConfig":
        """Build from a profile's ``line_follower:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "line_follower")


@dataclass
class _Junction:
    """Sightings of one junction in the odometry frame (weighted: near sightings are more precise)."""

    sx: float = 0.0
    sy: float = 0.0
    sw: float = 0.0
    hits: int = 0

    def add(self, x: float, y: float, weight: float) -> None:
        self.sx += weight * x
        self.sy += weight * y
        self.sw += weight
        self.hits += 1

    @property
    def xy(self) -> tuple[float, float]:
        return self.sx / self.sw, self.sy / self.sw


class FollowLine(BeastBehaviour):
    """Follow the camera's line until ``until`` holds (see the module docstring).

    ``until``: ``intersection``, ``line_end``, ``distance`` (``amount`` metres)
    or ``time`` (``amount`` seconds). Succeeds when it holds (then commands
    zero); fails when the line is out of sight longer than ``lost_after_s``
    (success instead with ``line_end``), or when odometry shows no progress
    towards the distance mark or the junction for ``default_stuck_after_s``.
    """

    READS = ("line", "pose_odom", "servo_angles")
    WRITES = ("cmd_mission", "servo_requests")

    def __init__(self, name: str, ctx: MissionContext, until: str, amount: Optional[float] = None,
                 speed_mps: Optional[float] = None, lost_after_s: Optional[float] = None) -> None:
        super().__init__(name, ctx)
        if until not in UNTIL_KINDS:
            raise ValueError(f"follow_line until must be one of {', '.join(UNTIL_KINDS)}, not {until!r}")
        self.until = until
        self.amount = amount
        self.speed_arg = speed_mps
        self.lost_after_arg = lost_after_s
        self.config = FollowLineConfig()
        self._reset()

    def _reset(self) -> None:
        self.start_s = 0.0
        self.ready_s = 0.0
        self.start_distance_m: Optional[float] = None
        self.last_seen_s = 0.0
        self.ever_seen = False
        self.last_obs_stamp: Optional[float] = None
        self.w_hold = 0.0
        self.poses: deque = deque()
        self.candidates: list[_Junction] = []
        self.target: Optional[_Junction] = None
        self.junction_xy: Optional[tuple[float, float]] = None
        """Where the junction the step stopped at is, odometry frame (m), once known."""
        self.remaining_m: Optional[float] = None
        self.best_remaining_m: Optional[float] = None
        self.progress_at_s = 0.0

    # -- lifecycle -----------------------------------------------------------------
    def initialise(self) -> None:
        self._reset()
        services = self.ctx.services
        follower = services.line_follower
        if isinstance(follower, FollowLineConfig):
            self.config = follower
        camera = services.camera
        if camera is not None:
            camera.enable("follow_line")
            camera.reset_detector()
        cfg = self.config
        self.speed_mps = min(self.speed_arg or cfg.default_speed_mps, self.ctx.speed_limit_mps)
        self.lost_after_s = self.lost_after_arg if self.lost_after_arg is not None else cfg.default_lost_after_s
        self.lookahead_m = camera.lookahead_m if camera is not None else 0.25
        now = self.now()
        self.start_s = now
        self.ready_s = now + self._point_camera()
        self.last_seen_s = self.ready_s

    def terminate(self, new_status: Status) -> None:
        # Off again when the step ends (whatever else still needs the camera keeps it on: a condition, the
        # recording, a viewer): a simulated camera renders, and a real one is decoded, only while a step looks.
        camera = self.ctx.services.camera
        disable = getattr(camera, "disable", None)
        if disable is not None:
            disable("follow_line")

    def _point_camera(self) -> float:
        """Ask for pan 0 / tilt 0 (the mounting the detector assumes); return how long to wait for it (s)."""
        angles = self.read("servo_angles") or {}
        requests = dict(self.read("servo_requests") or {})
        wait = 0.0
        for axis in ("pan", "tilt"):
            if axis not in self.ctx.servo_names:
                continue
            if angles.get(axis) != 0.0:
                wait = self.ctx.params.default_settle_s
            requests[axis] = ServoCommand(name=axis, angle_rad=0.0, stamp_s=self.now())
        if requests:
            self.bb.servo_requests = requests
        return wait

    # -- the tick ------------------------------------------------------------------------
    def update(self) -> Status:
        now = self.now()
        cfg = self.config
        pose: Optional[FusedPose] = self.read("pose_odom")
        if pose is None:
            self.command(0.0, 0.0)
            if now - self.ready_s > self.lost_after_s:
                return self.fail("no odometry")
            return Status.RUNNING
        self.poses.append(pose)
        while self.poses and pose.stamp_s - self.poses[0].stamp_s > POSE_HISTORY_S:
            self.poses.popleft()
        if self.start_distance_m is None:
            self.start_distance_m = pose.distance_m
        if now < self.ready_s - 1e-9:
            self.command(0.0, 0.0)
            self.feedback_message = "pointing the camera ahead"
            return Status.RUNNING

        obs: Optional[LineObservation] = self.read("line")
        fresh = obs is not None and obs.stamp_s >= self.ready_s - 1e-9 and now - obs.stamp_s <= cfg.observation_max_age_s
        seen = bool(fresh and obs.seen)
        if seen:
            self.last_seen_s = obs.stamp_s
            self.ever_seen = True
        if fresh and obs.stamp_s != self.last_obs_stamp:
            self.last_obs_stamp = obs.stamp_s
            if self.until == "intersection" and seen and obs.intersection and obs.intersection_distance_m is not None:
                self._note_junction(obs)

        # -- is it done?
        remaining: Optional[float] = None
        if self.until == "time":
            if now - self.start_s >= self.amount - 1e-9:
                return self._done(f"followed the line for {now - self.start_s:.1f} s")
        elif self.until == "distance":
            travelled = pose.distance_m - self.start_distance_m
            remaining = self.amount - travelled
            if remaining <= cfg.stop_tolerance_m:
                return self._done(f"followed the line for {travelled:.2f} m")
        elif self.until == "intersection" and self.target is not None:
            jx, jy = self.target.xy
            self.junction_xy = (jx, jy)
            remaining = (jx - pose.x) * math.cos(pose.yaw) + (jy - pose.y) * math.sin(pose.yaw)
            if remaining <= cfg.stop_tolerance_m:
                return self._done(f"centre over the intersection ({self.target.hits} sightings)")
        self.remaining_m = remaining
        if remaining is not None:
            # Odometry must show progress towards the mark: a blocked robot, or a base without
            # wheel odometry (a PWM base), would otherwise creep on for ever.
            p = self.ctx.params
            if self.best_remaining_m is None or remaining < self.best_remaining_m - p.stuck_progress_m:
                self.best_remaining_m = remaining
                self.progress_at_s = now
            elif now - self.progress_at_s > p.default_stuck_after_s:
                self.command(0.0, 0.0)
                return self.fail(f"no progress by odometry for {p.default_stuck_after_s:g} s "
                                 f"({remaining:.2f} m to go): blocked, or no wheel odometry")

        # -- is the line lost?
        finishing = self.until == "intersection" and self.target is not None
        lost_for = now - self.last_seen_s
        if not seen and not finishing and lost_for > self.lost_after_s + 1e-9:
            self.command(0.0, 0.0)
            if self.until == "line_end" and self.ever_seen:
                return self._done(f"the line ended (out of sight for {lost_for:.1f} s)")
            if not self.ever_seen:
                return self.fail(f"no line in sight for {lost_for:.1f} s")
            return self.fail(f"line lost for {lost_for:.1f} s")

        # -- steer (the speed again each tick: live tuning may change the follower's speed or the speed limit)
        self.speed_mps = min(self.speed_arg or cfg.default_speed_mps, self.ctx.speed_limit_mps)
        limit_w = min(cfg.max_turn_rate_rps, self.ctx.turn_rate_limit_rps)
        if seen:
            y = obs.offset_m
            curvature = 2.0 * y / (self.lookahead_m ** 2 + y * y)
            v = self.speed_mps * max(cfg.min_speed_fraction, 1.0 / (1.0 + cfg.curve_slowdown_m * abs(curvature)))
            w = max(-limit_w, min(limit_w, v * curvature))
            self.w_hold = w
            self.feedback_message = f"line {y * 100:+.1f} cm at {self.lookahead_m:.2f} m"
        elif finishing:
            v, w = self.speed_mps, 0.0  # the junction is under the camera: straight on, by odometry
            self.feedback_message = "over the junction by odometry"
        else:
            v, w = self.speed_mps * cfg.lost_speed_fraction, self.w_hold
            self.feedback_message = f"line out of sight for {lost_for:.1f} s"
        if remaining is not None:
            v = min(v, max(cfg.min_approach_speed_mps, math.sqrt(2.0 * cfg.stop_decel_mps2 * max(0.0, remaining))))
            if finishing:
                self.feedback_message = f"{remaining:.2f} m to the intersection"
        self.command(v, w)
        return Status.RUNNING

    def _done(self, message: str) -> Status:
        self.command(0.0, 0.0)
        self.feedback_message = message
        return Status.SUCCESS

    # -- junctions ---------------------------------------------------------------------
    def _pose_at(self, stamp_s: float) -> FusedPose:
        """The odometry pose nearest in time to ``stamp_s`` (the frame's time)."""
        return min(self.poses, key=lambda p: abs(p.stamp_s - stamp_s))

    def _note_junction(self, obs: LineObservation) -> None:
        """Place a sighting in the odometry frame and merge it with the junction it belongs to."""
        cfg = self.config
        p = self._pose_at(obs.stamp_s)
        d = float(obs.intersection_distance_m)
        x, y = p.x + d * math.cos(p.yaw), p.y + d * math.sin(p.yaw)
        weight = 1.0 / max(d, 0.1) ** 2  # the junction's image is sharper (and its fit better) when near
        pool = [self.target] if self.target is not None else self.candidates
        for j in pool:
            jx, jy = j.xy
            if math.hypot(x - jx, y - jy) <= cfg.junction_merge_m:
                j.add(x, y, weight)
                break
        else:
            if self.target is not None:
                return  # a junction beyond the one being approached
            j = _Junction()
            j.add(x, y, weight)
            self.candidates.append(j)
        if self.target is None:
            # sightings the robot has driven past without confirming them were glimpses of nothing
            c, s = math.cos(p.yaw), math.sin(p.yaw)
            self.candidates = [j for j in self.candidates
                               if (j.xy[0] - p.x) * c + (j.xy[1] - p.y) * s > -cfg.junction_merge_m]
            for j in self.candidates:
                if j.hits >= cfg.junction_confirm_frames:
                    self.target = j
                    self.ctx.events.add("line", f"{self.name}: intersection {d:.2f} m ahead")
                    break


__all__ = ["FollowLine", "FollowLineConfig", "UNTIL_KINDS"]
