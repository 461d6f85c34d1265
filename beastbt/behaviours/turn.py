"""Turning in place: by an angle (odometry), or to a compass heading (fused pose)."""

from __future__ import annotations

import math
from typing import Optional

from beastbt.behaviours.base import NO_ODOMETRY, BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.behaviours.drive import held_by
from beastbt.estimation.estimator import wrap_angle


class _TurnInPlace(BeastBehaviour):
    """A proportional turn in place with a top and a bottom rate, and stuck detection."""

    WRITES = ("cmd_mission",)

    def __init__(self, name: str, ctx: MissionContext, rate_rps: Optional[float], stuck_after_s: Optional[float]) -> None:
        super().__init__(name, ctx)
        self.rate_rps = min(rate_rps or ctx.params.default_turn_rate_rps, ctx.turn_rate_limit_rps)
        self.stuck_after_s = stuck_after_s or ctx.params.default_stuck_after_s
        self.best_err = math.inf
        self.progress_at_s = 0.0

    def initialise(self) -> None:
        self.best_err = math.inf
        self.progress_at_s = self.now()

    def steer_to(self, err_rad: float) -> Status:
        """Command a turn rate for the remaining angle ``err_rad``; SUCCESS within tolerance."""
        p = self.ctx.params
        if abs(err_rad) <= p.turn_tolerance_rad:
            self.command(0.0, 0.0)
            self.feedback_message = f"within {math.degrees(abs(err_rad)):.1f} deg"
            return Status.SUCCESS
        if abs(err_rad) < self.best_err - p.stuck_progress_rad:
            self.best_err = abs(err_rad)
            self.progress_at_s = self.now()
        elif self.now() - self.progress_at_s > self.stuck_after_s:
            self.command(0.0, 0.0)
            if "odometry" in self.READS and self.read("odometry") is None:
                return self.fail(NO_ODOMETRY.format(what="the angle turned"))
            return self.fail(f"no progress for {self.stuck_after_s:g} s, {math.degrees(err_rad):.1f} deg to go"
                             + held_by(self.ctx))
        rate = max(p.min_turn_rate_rps, min(self.rate_rps, p.turn_gain * abs(err_rad)))
        self.command(0.0, math.copysign(rate, err_rad))
        self.feedback_message = f"{math.degrees(err_rad):.1f} deg to go"
        return Status.RUNNING


class TurnBy(_TurnInPlace):
    """Turn in place by ``angle_rad`` (positive: left, counter-clockwise), measured by odometry.

    Succeeds within ``turn_tolerance_rad`` (3 deg) of the target. Fails when the
    remaining angle does not shrink for ``stuck_after_s``.
    """

    READS = ("pose_odom", "odometry")

    def __init__(self, name: str, ctx: MissionContext, angle_rad: float, rate_rps: Optional[float] = None,
                 stuck_after_s: Optional[float] = None) -> None:
        super().__init__(name, ctx, rate_rps, stuck_after_s)
        self.angle_rad = angle_rad
        self.turned = 0.0
        self.last_yaw: Optional[float] = None

    def initialise(self) -> None:
        super().initialise()
        self.turned = 0.0
        pose = self.read("pose_odom")
        self.last_yaw = pose.yaw if pose is not None else None

    def update(self) -> Status:
        pose = self.read("pose_odom")
        if pose is None:
            return self.fail("no odometry")
        if self.last_yaw is None:
            self.last_yaw = pose.yaw
        # Accumulate unwrapped increments so that turns beyond 180 deg are measured.
        self.turned += wrap_angle(pose.yaw - self.last_yaw)
        self.last_yaw = pose.yaw
        return self.steer_to(self.angle_rad - self.turned)


class TurnToHeading(_TurnInPlace):
    """Turn in place to a compass heading (``heading_rad``: 0 north, pi/2 east, clockwise).

    Uses the fused pose. Succeeds within 3 deg. While there is no heading
    estimate yet (the IMU calibrates its gyro for a few seconds at start) it
    stands still; it fails when there is still none after ``stuck_after_s``
    (no magnetometer and no GPS motion), or when it makes no progress for that long.
    """

    READS = ("pose",)

    def __init__(self, name: str, ctx: MissionContext, heading_rad: float, rate_rps: Optional[float] = None,
                 stuck_after_s: Optional[float] = None) -> None:
        super().__init__(name, ctx, rate_rps, stuck_after_s)
        self.target_yaw = wrap_angle(math.pi / 2.0 - heading_rad)

    def update(self) -> Status:
        pose = self.read("pose")
        if pose is None or not pose.heading_valid:
            self.command(0.0, 0.0)
            if self.now() - self.progress_at_s >= self.stuck_after_s:
                return self.fail("no heading estimate (needs a magnetometer, or GPS and some driving first)")
            self.feedback_message = "waiting for a heading estimate"
            return Status.RUNNING
        return self.steer_to(wrap_angle(self.target_yaw - pose.yaw))
