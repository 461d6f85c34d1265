"""The base class of every beastbt leaf: a py_trees behaviour with declared blackboard access."""

from __future__ import annotations

from typing import Any, ClassVar

import py_trees

from beastbt.behaviours.context import MissionContext
from beastbt.blackboard import catalogue
from beastbt.blackboard.types import VelocityCommand

Status = py_trees.common.Status


NO_ODOMETRY = ("no odometry: this robot's base reports no wheel travel (a PWM base drives open loop), so {what} "
               "cannot be measured and the robot seemed not to move")
"""Why a step that measures motion with the wheels failed on a base without odometry ({what}: what it measures)."""


class BeastBehaviour(py_trees.behaviour.Behaviour):
    """A leaf that reads the catalogue keys in ``READS`` and writes those in ``WRITES``.

    Subclasses implement ``initialise``/``update``/``terminate`` as in py_trees
    and use :meth:`read`, :meth:`command` and :meth:`now`.
    """

    READS: ClassVar[tuple[str, ...]] = ()
    WRITES: ClassVar[tuple[str, ...]] = ()

    def __init__(self, name: str, ctx: MissionContext) -> None:
        super().__init__(name=name)
        self.ctx = ctx
        self.bb = self.attach_blackboard_client(name=name)
        for key in self.READS:
            catalogue.register(self.bb, key)
        for key in self.WRITES:
            catalogue.register(self.bb, key, write=True)

    def now(self) -> float:
        """The current time (s) from the injected clock."""
        return self.ctx.clock.now()

    def read(self, key: str, default: Any = None) -> Any:
        """The value of blackboard key ``key``, or ``default`` when never written."""
        return catalogue.get(self.bb, key, default)

    def command(self, linear_mps: float, angular_rps: float) -> None:
        """Ask the base for a body velocity this tick (the mux and safety gate decide what is sent)."""
        self.bb.cmd_mission = VelocityCommand(linear_mps, angular_rps, self.now(), "mission")

    def fail(self, message: str) -> Status:
        """Set the feedback message, log it as an event, and return FAILURE."""
        self.feedback_message = message
        self.ctx.events.add("step_failed", f"{self.name}: {message}")
        return Status.FAILURE
