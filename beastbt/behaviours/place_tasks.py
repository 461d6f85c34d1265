"""A route's places visited whatever happens at one of them: ``route: {..., stop_on_failure: false}``."""

from __future__ import annotations

import py_trees

from beastbt.behaviours.context import MissionContext

Status = py_trees.common.Status


class CarryOn(py_trees.decorators.Decorator):
    """Run one place of a route (getting there and its tasks); when it fails, note it and go on.

    Succeeds when the child succeeds or fails (a failure is an event of kind ``place_missed`` naming the place
    and why, as Nav2's waypoint follower lists its missed waypoints); RUNNING while the child runs.
    """

    def __init__(self, name: str, child: py_trees.behaviour.Behaviour, ctx: MissionContext, place: str) -> None:
        super().__init__(name=name, child=child)
        self.ctx = ctx
        self.place = place

    def update(self) -> Status:
        status = self.decorated.status
        if status == Status.FAILURE:
            why = _failure_of(self.decorated)
            self.ctx.events.add("place_missed", f"{self.place}: {why or 'failed'}; going on to the next place")
            self.feedback_message = f"missed {self.place}"
            return Status.SUCCESS
        return status


def _failure_of(node: py_trees.behaviour.Behaviour) -> str:
    """The feedback of the leaf that failed under ``node`` (the last one, in tick order), or ''."""
    why = ""
    for n in node.iterate():
        if n.status == Status.FAILURE and not n.children and n.feedback_message:
            why = f"{n.name}: {n.feedback_message}"
    return why


__all__ = ["CarryOn"]
