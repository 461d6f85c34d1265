"""Handing the robot to the joystick operator: the ``teleop`` step."""

from __future__ import annotations

from typing import Optional

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext

JOYSTICK_MAX_AGE_S = 0.5
"""A joystick state older than this (s) means there is no joystick."""


class TeleopStep(BeastBehaviour):
    """Let the operator drive with the joystick, for ``duration_s`` or until the deadman is released.

    While it runs the mission asks for zero; the operator's commands come in
    above it through the mux whenever the enable (deadman) button is held,
    even in a mission written with ``teleop: false``. With ``duration_s``:
    succeeds when the time has elapsed. With ``until_released``: waits for the
    operator to hold enable, then succeeds on the tick it is released (an
    unplugged pad counts as released). Fails with "no joystick" when there is
    no connected joystick when the step starts (or, waiting for the operator,
    when it goes away before enable was ever held).
    """

    READS = ("joystick", "teleop_active")
    WRITES = ("cmd_mission",)

    def __init__(self, name: str, ctx: MissionContext, duration_s: Optional[float] = None,
                 until_released: bool = False) -> None:
        super().__init__(name, ctx)
        self.duration_s = duration_s
        self.until_released = until_released
        self.start_s = 0.0
        self.engaged = False
        self.first = True

    def initialise(self) -> None:
        self.start_s = self.now()
        self.engaged = False
        self.first = True
        service = self.ctx.services.teleop
        if service is not None:
            service.request_handover(self)

    def _connected(self) -> bool:
        if getattr(self.ctx.services.teleop, "remote_attached", False):
            return True  # an operator console can drive this run: its on-page stick is the joystick
        js = self.read("joystick")
        return js is not None and js.connected and self.now() - js.stamp_s <= JOYSTICK_MAX_AGE_S

    def update(self) -> Status:
        self.command(0.0, 0.0)
        first, self.first = self.first, False
        if self.ctx.services.teleop is None:
            return self.fail("no joystick (teleop is not available on this robot)")
        connected = self._connected()
        active = bool(self.read("teleop_active"))
        if not connected and (first or (self.until_released and not self.engaged)):
            hint = getattr(self.ctx.services.teleop, "no_joystick_hint", None)
            return self.fail("no joystick" + (f": {hint()}" if callable(hint) else ""))
        if self.duration_s is not None:
            left = self.start_s + self.duration_s - self.now()
            if left <= 1e-9:
                return Status.SUCCESS
            self.feedback_message = f"operator driving, {left:.1f} s left" if active else f"{left:.1f} s left"
            return Status.RUNNING
        if active:
            self.engaged = True
            self.feedback_message = "operator driving"
            return Status.RUNNING
        if self.engaged:
            self.feedback_message = "deadman released"
            return Status.SUCCESS
        self.feedback_message = "waiting for the operator to hold enable"
        return Status.RUNNING

    def terminate(self, new_status: Status) -> None:
        service = self.ctx.services.teleop
        if service is not None:
            service.release_handover(self)
