"""Driving straight: by a distance measured by odometry, or for a time."""

from __future__ import annotations

import math
from typing import Optional

from beastbt.behaviours.base import NO_ODOMETRY, BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import FusedPose
from beastbt.estimation.estimator import wrap_angle


def held_by(ctx: MissionContext) -> str:
    """What a step that makes no progress adds to its failure: ``"; "`` and why the collision monitor holds the robot
    (the nearest obstacle's distance and bearing), or ``""`` when it does not."""
    why = ctx.services.collision_hold()
    return f"; {why}" if why else ""


class _Straight(BeastBehaviour):
    """Shared heading hold for straight driving on the odometry pose."""

    READS = ("pose_odom",)
    WRITES = ("cmd_mission",)

    def __init__(self, name: str, ctx: MissionContext, speed_mps: Optional[float]) -> None:
        super().__init__(name, ctx)
        self.speed_mps = min(speed_mps or ctx.params.default_speed_mps, ctx.speed_limit_mps)
        self.start: Optional[FusedPose] = None

    def initialise(self) -> None:
        self.start = self.read("pose_odom")

    def steer(self, pose: FusedPose) -> float:
        """Turn rate (rad/s) that keeps the heading the drive started with."""
        assert self.start is not None
        err = wrap_angle(self.start.yaw - pose.yaw)
        limit = self.ctx.turn_rate_limit_rps
        return max(-limit, min(limit, self.ctx.params.heading_gain * err))


class DriveDistance(_Straight):
    """Drive straight for ``distance_m`` (negative: backwards), measured by wheel odometry.

    Holds the starting heading and slows down before the mark so as to stop on it.
    Succeeds when the distance along the starting heading is covered (within
    ``drive_tolerance_m``). Fails when it makes less than ``stuck_progress_m`` of
    progress for ``stuck_after_s`` (blocked), or when there is no odometry.
    """

    READS = ("pose_odom", "odometry")

    def __init__(self, name: str, ctx: MissionContext, distance_m: float, speed_mps: Optional[float] = None,
                 stuck_after_s: Optional[float] = None) -> None:
        super().__init__(name, ctx, speed_mps)
        self.distance_m = distance_m
        self.stuck_after_s = stuck_after_s or ctx.params.default_stuck_after_s
        self.best_m = 0.0
        self.progress_at_s = 0.0

    def initialise(self) -> None:
        super().initialise()
        self.best_m = 0.0
        self.progress_at_s = self.now()

    def update(self) -> Status:
        pose = self.read("pose_odom")
        if pose is None or self.start is None:
            self.start = pose
            return self.fail("no odometry") if self.now() - self.progress_at_s > self.stuck_after_s else Status.RUNNING
        direction = 1.0 if self.distance_m >= 0 else -1.0
        along = (pose.x - self.start.x) * math.cos(self.start.yaw) + (pose.y - self.start.y) * math.sin(self.start.yaw)
        covered = along * direction
        remaining = abs(self.distance_m) - covered
        p = self.ctx.params
        if remaining <= p.drive_tolerance_m:
            self.command(0.0, 0.0)
            self.feedback_message = f"covered {covered:.2f} m"
            return Status.SUCCESS
        if covered > self.best_m + p.stuck_progress_m:
            self.best_m = covered
            self.progress_at_s = self.now()
        elif self.now() - self.progress_at_s > self.stuck_after_s:
            self.command(0.0, 0.0)
            if self.read("odometry") is None:
                return self.fail(NO_ODOMETRY.format(what="the distance driven") + "; drive for a time instead: "
                                 f"drive: {{time: {abs(self.distance_m) / max(self.speed_mps, 1e-3):.0f} s, "
                                 f"speed: {self.speed_mps:g} m/s}}")
            return self.fail(f"blocked: no progress for {self.stuck_after_s:g} s after {covered:.2f} m"
                             + held_by(self.ctx))
        speed = min(self.speed_mps, max(p.min_drive_speed_mps, math.sqrt(2.0 * p.decel_mps2 * remaining)))
        self.command(direction * speed, self.steer(pose))
        self.feedback_message = f"{covered:.2f} of {abs(self.distance_m):.2f} m"
        return Status.RUNNING


class DriveTime(_Straight):
    """Drive straight at ``speed_mps`` for ``duration_s`` seconds.

    Succeeds when the time has elapsed (then commands zero); never fails.
    """

    def __init__(self, name: str, ctx: MissionContext, duration_s: float, speed_mps: Optional[float] = None) -> None:
        super().__init__(name, ctx, speed_mps)
        self.duration_s = duration_s
        self.until_s = 0.0

    def initialise(self) -> None:
        super().initialise()
        self.until_s = self.now() + self.duration_s

    def update(self) -> Status:
        if self.now() >= self.until_s:
            self.command(0.0, 0.0)
            return Status.SUCCESS
        pose = self.read("pose_odom")
        if self.start is None:
            self.start = pose
        self.command(self.speed_mps, self.steer(pose) if pose is not None and self.start is not None else 0.0)
        self.feedback_message = f"{self.until_s - self.now():.1f} s left"
        return Status.RUNNING
