"""Flow constructs that py_trees does not have in the form the mission language needs.

``timeout`` takes its time from the injected clock (py_trees' own Timeout reads
the wall clock); ``if`` chooses once, when reached, and then runs only the
chosen branch (a failure in ``then`` is not a reason to run ``else``);
``while`` checks its condition before each pass.
"""

from __future__ import annotations

import typing
from typing import Optional

import py_trees

from beastbt.behaviours.conditions import Condition
from beastbt.core.clock import Clock

Status = py_trees.common.Status
Behaviour = py_trees.behaviour.Behaviour


class ClockTimeout(py_trees.decorators.Decorator):
    """Run the child; FAILURE if it is still running ``duration_s`` after it started.

    Otherwise returns the child's own status.
    """

    def __init__(self, name: str, child: Behaviour, duration_s: float, clock: Clock) -> None:
        super().__init__(name=name, child=child)
        self.duration_s = duration_s
        self.clock = clock
        self.deadline_s = 0.0

    def initialise(self) -> None:
        self.deadline_s = self.clock.now() + self.duration_s

    def update(self) -> Status:
        if self.decorated.status == Status.RUNNING and self.clock.now() >= self.deadline_s:
            self.decorated.stop(Status.INVALID)
            self.feedback_message = f"timed out after {self.duration_s:g} s"
            return Status.FAILURE
        return self.decorated.status


class IfThenElse(py_trees.composites.Composite):
    """Evaluate ``condition`` once when reached, then run ``then`` or ``else`` to completion.

    Returns the chosen branch's status; SUCCESS at once when the condition is
    false and there is no ``else``.
    """

    def __init__(self, name: str, condition: Condition, then: Behaviour, otherwise: Optional[Behaviour] = None) -> None:
        children = [then] + ([otherwise] if otherwise is not None else [])
        super().__init__(name=name, children=children)
        self.condition = condition
        self.then = then
        self.otherwise = otherwise

    def tick(self) -> typing.Iterator[Behaviour]:
        if self.status != Status.RUNNING:
            for child in self.children:
                if child.status != Status.INVALID:
                    child.stop(Status.INVALID)
            self.current_child = self.then if self.condition.holds() else self.otherwise
            self.feedback_message = f"chose {'then' if self.current_child is self.then else 'else'}"
            self.initialise()
        if self.current_child is None:
            self.stop(Status.SUCCESS)
            yield self
            return
        for node in self.current_child.tick():
            yield node
        status = self.current_child.status
        if status == Status.RUNNING:
            self.status = Status.RUNNING
        else:
            self.stop(status)
        yield self


class WhileLoop(py_trees.composites.Composite):
    """Run ``body`` again and again while ``condition`` holds, checked before each pass.

    SUCCESS when the condition is false before a pass; FAILURE when a pass fails.
    At most one pass starts per tick.
    """

    def __init__(self, name: str, condition: Condition, body: Behaviour) -> None:
        super().__init__(name=name, children=[body])
        self.condition = condition
        self.body = body
        self.in_pass = False
        self.passes = 0

    def tick(self) -> typing.Iterator[Behaviour]:
        if self.status != Status.RUNNING:
            if self.body.status != Status.INVALID:
                self.body.stop(Status.INVALID)
            self.in_pass = False
            self.passes = 0
            self.initialise()
        if not self.in_pass:
            if not self.condition.holds():
                self.feedback_message = f"condition false after {self.passes} pass(es)"
                self.stop(Status.SUCCESS)
                yield self
                return
            self.in_pass = True
            self.current_child = self.body
        for node in self.body.tick():
            yield node
        if self.body.status == Status.FAILURE:
            self.stop(Status.FAILURE)
        else:
            if self.body.status == Status.SUCCESS:
                self.in_pass = False
                self.passes += 1
            self.status = Status.RUNNING
        yield self


class RepeatTimes(py_trees.decorators.Repeat):
    """py_trees' Repeat, with ``times=-1`` meaning forever and a readable feedback message."""

    def __init__(self, name: str, child: Behaviour, times: int) -> None:
        super().__init__(name=name, child=child, num_success=times)


class RetryAttempts(py_trees.decorators.Retry):
    """Run the child again after a failure, up to ``attempts`` attempts in all (-1: forever)."""

    FOREVER = 2**62

    def __init__(self, name: str, child: Behaviour, attempts: int) -> None:
        super().__init__(name=name, child=child, num_failures=self.FOREVER if attempts < 0 else attempts)


class GuardedBlock(py_trees.composites.Composite):
    """``until`` / ``abort_if``: run ``body``, checking ``condition`` on every tick before it, while it runs.

    When the condition holds, the running step is halted at once (its
    ``terminate`` runs; with no leaf commanding, the robot is commanded to
    stop) and the block ends: SUCCESS for ``until``, FAILURE for ``abort_if``
    (the condition, in words, as the reason). When the body ends first, the
    block ends as it did. ``block`` records when and where (odometry
    distance) the block started, for ``time_in_block`` and
    ``distance_travelled``.
    """

    def __init__(self, name: str, condition: Condition, body: Behaviour, on_hold: Status, block: "BlockStart",
                 events: typing.Any) -> None:
        super().__init__(name=name, children=[body])
        self.condition = condition
        self.body = body
        self.on_hold = on_hold
        self.block = block
        self.events = events

    def tick(self) -> typing.Iterator[Behaviour]:
        if self.status != Status.RUNNING:
            if self.body.status != Status.INVALID:
                self.body.stop(Status.INVALID)
            self.block.start()
            self.initialise()
        if self.condition.holds():
            halted = self.body.tip() if self.body.status == Status.RUNNING else None
            if self.body.status == Status.RUNNING:
                self.body.stop(Status.INVALID)  # the running step's terminate runs now
            what = f", halting {halted.name}" if halted is not None else ""
            self.feedback_message = f"{self.condition} holds{self.condition.details()}{what}"
            self.events.add("guard" if self.on_hold == Status.SUCCESS else "step_failed",
                            f"{self.name}: {self.feedback_message}")
            self.current_child = None  # the block itself is where it ended (tip() is this block)
            self.stop(self.on_hold)
            yield self
            return
        self.current_child = self.body
        for node in self.body.tick():
            yield node
        if self.body.status in (Status.SUCCESS, Status.FAILURE):
            self.feedback_message = self.body.feedback_message
            self.stop(self.body.status)
        else:
            self.status = Status.RUNNING
        yield self


class BlockStart:
    """When and where a guard block started: ``start_s`` (clock s) and ``start_distance_m`` (odometry, m).

    Outside any block the mission itself is the block (its start time, and
    the odometry distance 0 it starts from).
    """

    def __init__(self, clock: Clock, distance: typing.Callable[[], float],
                 mission_start: typing.Callable[[], Optional[float]]) -> None:
        self.clock = clock
        self.distance = distance
        self.mission_start = mission_start
        self.start_s: Optional[float] = None
        self.start_distance_m = 0.0

    def start(self) -> None:
        """The block starts now."""
        self.start_s = self.clock.now()
        self.start_distance_m = self.distance()

    def elapsed_s(self) -> float:
        """Seconds since the block (or the mission) started."""
        start = self.start_s if self.start_s is not None else self.mission_start()
        return 0.0 if start is None else self.clock.now() - start

    def travelled_m(self) -> float:
        """Odometry distance (m) since the block (or the mission) started."""
        return self.distance() - (self.start_distance_m if self.start_s is not None else 0.0)
