"""Pointing the camera and setting servos."""

from __future__ import annotations

from typing import Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import ServoCommand


class SetServos(BeastBehaviour):
    """Ask for servo positions, then stand still for ``settle_s`` while they move.

    ``commands`` are :class:`ServoCommand` by name (``pan``, ``tilt``...) or by
    PWM channel. Succeeds once the settle time has passed. Fails at once when
    the robot has no such servo (a channel command needs a PWM servo board).
    """

    WRITES = ("servo_requests", "cmd_mission")

    def __init__(self, name: str, ctx: MissionContext, commands: list[ServoCommand], settle_s: Optional[float] = None) -> None:
        super().__init__(name, ctx)
        self.commands = commands
        self.settle_s = ctx.params.default_settle_s if settle_s is None else settle_s
        self.until_s = 0.0

    def initialise(self) -> None:
        self.until_s = self.now() + self.settle_s
        self.sent = False

    def update(self) -> Status:
        self.command(0.0, 0.0)
        if not self.sent:
            for cmd in self.commands:
                key = cmd.name if cmd.name is not None else f"channel{cmd.channel}"
                if cmd.name is not None and cmd.name not in self.ctx.servo_names:
                    have = ", ".join(sorted(self.ctx.servo_names)) or "none"
                    return self.fail(f"no servo named '{cmd.name}' on this robot (it has: {have})")
                if cmd.channel is not None and "pwm_servos" not in self.ctx.capabilities:
                    return self.fail(f"no PWM servo board for channel {cmd.channel} on this robot")
                requests = self.read("servo_requests") or {}
                requests[key] = ServoCommand(cmd.name, cmd.angle_rad, cmd.channel, cmd.pulse_s, self.now())
                self.bb.servo_requests = requests
            self.sent = True
        if self.now() >= self.until_s - 1e-9:
            return Status.SUCCESS
        self.feedback_message = "settling"
        return Status.RUNNING
