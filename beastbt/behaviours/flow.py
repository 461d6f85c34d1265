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
