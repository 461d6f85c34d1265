"""Standing still: wait a time, stop until still, wait until a condition holds."""

from __future__ import annotations

from typing import Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.conditions import Condition
from beastbt.behaviours.context import MissionContext


class Wait(BeastBehaviour):
    """Command zero velocity for ``duration_s``. Succeeds when the time has elapsed; never fails."""

    WRITES = ("cmd_mission",)

    def __init__(self, name: str, ctx: MissionContext, duration_s: float) -> None:
        super().__init__(name, ctx)
        self.duration_s = duration_s
        self.until_s = 0.0

    def initialise(self) -> None:
        self.until_s = self.now() + self.duration_s

    def update(self) -> Status:
        self.command(0.0, 0.0)
        left = self.until_s - self.now()
        if left <= 1e-9:
            return Status.SUCCESS
        self.feedback_message = f"{left:.1f} s left"
        return Status.RUNNING


class StopRobot(BeastBehaviour):
    """Command zero velocity and wait until the robot is still (odometry speeds near zero).

    Succeeds when the measured forward speed and turn rate are below the
    'still' thresholds; never fails (without odometry it succeeds after 1 s).
    """

    READS = ("pose_odom",)
    WRITES = ("cmd_mission",)
    NO_ODOMETRY_WAIT_S = 1.0

    def __init__(self, name: str, ctx: MissionContext) -> None:
        super().__init__(name, ctx)
        self.started_s = 0.0

    def initialise(self) -> None:
        self.started_s = self.now()

    def update(self) -> Status:
        self.command(0.0, 0.0)
        pose = self.read("pose_odom")
        p = self.ctx.params
        if pose is None or self.now() - pose.stamp_s > p.sensor_max_age_s:
            return Status.SUCCESS if self.now() - self.started_s >= self.NO_ODOMETRY_WAIT_S else Status.RUNNING
        if abs(pose.speed_mps) < p.still_speed_mps and abs(pose.yaw_rate_rps) < p.still_turn_rps:
            return Status.SUCCESS
        self.feedback_message = f"slowing: {pose.speed_mps:.2f} m/s"
        return Status.RUNNING


class WaitUntil(BeastBehaviour):
    """Stand still until ``condition`` holds. Succeeds when it holds; fails after ``timeout_s`` (if given)."""

    WRITES = ("cmd_mission",)

    def __init__(self, name: str, ctx: MissionContext, condition: Condition, timeout_s: Optional[float] = None) -> None:
        super().__init__(name, ctx)
        self.condition = condition
        self.timeout_s = timeout_s
        self.started_s = 0.0

    def initialise(self) -> None:
        self.started_s = self.now()

    def update(self) -> Status:
        self.command(0.0, 0.0)
        if self.condition.holds():
            return Status.SUCCESS
        if self.timeout_s is not None and self.now() - self.started_s >= self.timeout_s:
            return self.fail(f"'{self.condition}' did not hold within {self.timeout_s:g} s")
        return Status.RUNNING
