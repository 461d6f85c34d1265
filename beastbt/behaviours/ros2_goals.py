"""``ros2_goals: {}``: wait for rviz2's "2D Goal Pose" goals on ``/goal_pose`` and drive to each on the mission's map.

The ROS 2 link (:mod:`beastbt.ros2.link`, ``--ros2``) hands each goal it takes,
on the tick thread, to the run's :class:`GoalInbox`; :class:`Ros2Goals` drives to
the newest one with the planned ``go_to`` of a place on the map
(:class:`~beastbt.behaviours.map_navigation.MapGoTo`, the one ``beastbt serve
--ros2`` runs for a goal), as Nav2's ``navigate_to_pose`` does: a new goal
while one is driven replaces it. Between goals the robot stands still.
Metres, seconds, map frame; the clock is the context's.
"""

from __future__ import annotations

import typing
from dataclasses import dataclass
from typing import Any, Callable, Optional

import py_trees

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.conditions import Condition
from beastbt.behaviours.context import MissionContext

GOAL_INBOX = "ros2_goal_inbox"
"""The key of the run's :class:`GoalInbox` in ``ctx.services.plugins`` (set by the ROS 2 link when it opens)."""


@dataclass(frozen=True)
class Goal:
    """One goal from ROS 2: where (x, y in metres, map frame), and its number in the run (from 1)."""

    x: float
    y: float
    number: int


class GoalInbox:
    """The goals ROS 2 sent to this run, newest last; a goal counts only while a ``ros2_goals`` step listens.

    Written and read on the tick thread (the link carries out what Zenoh's threads received there).
    """

    def __init__(self) -> None:
        self.listening = 0
        """How many ``ros2_goals`` steps run now (0: a goal is not taken)."""
        self.latest: Optional[Goal] = None
        self.taken = 0

    def put(self, x: float, y: float) -> Optional[Goal]:
        """Take a goal (m, map frame) if a step listens; the goal, or None when none does."""
        if not self.listening:
            return None
        self.taken += 1
        self.latest = Goal(float(x), float(y), self.taken)
        return self.latest


class WaitForGoal(BeastBehaviour):
    """Stand still while no goal is being driven to. Always RUNNING (its parent decides when waiting ends)."""

    WRITES = ("cmd_mission",)

    def update(self) -> Status:
        self.command(0.0, 0.0)
        self.feedback_message = "waiting for a goal on /goal_pose (rviz2's 2D Goal Pose)"
        return Status.RUNNING


class Ros2Goals(py_trees.composites.Composite):
    """Drive to each goal ROS 2 sends (``/goal_pose``), one after another, on the mission's map.

    ``leg`` is a :class:`~beastbt.behaviours.map_navigation.MapGoTo` whose target is the goal being driven to.
    SUCCESS when ``goals`` goals have been reached, when ``duration_s`` has passed (a goal under way is given
    up), or when ``until`` holds. A goal that cannot be reached (no path, blocked, stuck) is an event and the
    step waits for the next one: it does not fail. FAILURE only when the run has no ROS 2 link to listen on.
    """

    def __init__(self, name: str, ctx: MissionContext, leg_factory: Callable[[Callable[[], Optional[tuple]]], Any],
                 goals: Optional[int] = None, duration_s: Optional[float] = None,
                 until: Optional[Condition] = None) -> None:
        self.ctx = ctx
        self.goals = goals
        self.duration_s = duration_s
        self.until = until
        self.goal: Optional[Goal] = None
        self.seen = 0
        self.reached = 0
        self.started_s = 0.0
        self.inbox: Optional[GoalInbox] = None
        self.listening = False
        self.waiting = WaitForGoal("wait for a ROS 2 goal", ctx)
        self.leg = leg_factory(self._target)
        super().__init__(name=name, children=[self.waiting, self.leg])

    def _target(self) -> Optional[tuple[float, float]]:
        return (self.goal.x, self.goal.y) if self.goal is not None else None

    # -- lifecycle ----------------------------------------------------------------------------------
    def _start(self) -> None:
        for child in self.children:
            if child.status != Status.INVALID:
                child.stop(Status.INVALID)
        inbox = self.ctx.services.plugins.get(GOAL_INBOX)
        self.inbox = inbox if isinstance(inbox, GoalInbox) else None
        if self.inbox is not None:
            self.inbox.listening += 1
            self.listening = True
            # Goals sent before the step listened are not this step's (rviz2's user clicks for a robot that waits).
            self.seen = self.inbox.taken
        self.goal = None
        self.reached = 0
        self.started_s = self.ctx.clock.now()
        self.initialise()

    def stop(self, new_status: Status = Status.INVALID) -> None:
        if self.listening and self.inbox is not None:
            self.inbox.listening = max(0, self.inbox.listening - 1)
        self.listening = False
        super().stop(new_status)

    def _end(self, status: Status, message: str) -> Status:
        self.feedback_message = message
        self.ctx.events.add("ros2", f"{self.name}: {message}")
        for child in self.children:  # a goal under way is given up (py_trees stops running children on INVALID only)
            if child.status != Status.INVALID:
                child.stop(Status.INVALID)
        self.stop(status)
        return status

    # -- the tick -----------------------------------------------------------------------------------
    def tick(self) -> typing.Iterator[py_trees.behaviour.Behaviour]:
        if self.status != Status.RUNNING:
            self._start()
            if self.inbox is None:
                self.feedback_message = ("the run has no ROS 2 link to take goals from (run it with --ros2; "
                                         "docs/ros2.md)")
                self.ctx.events.add("step_failed", f"{self.name}: {self.feedback_message}")
                self.stop(Status.FAILURE)
                yield self
                return
        status = self._finished()
        if status is not None:
            yield self
            return
        self._take_new_goal()
        child = self.leg if self.goal is not None else self.waiting
        if child is self.leg and self.waiting.status == Status.RUNNING:
            self.waiting.stop(Status.INVALID)  # the tree shows one thing under way: the drive to the goal
        self.current_child = child
        for node in child.tick():
            yield node
        if child is self.leg and self.leg.status in (Status.SUCCESS, Status.FAILURE):
            self._leg_ended()
            if self.goals is not None and self.reached >= self.goals:
                self._end(Status.SUCCESS, f"{self.reached} goal{'s' if self.reached != 1 else ''} reached")
                yield self
                return
        self.status = Status.RUNNING
        yield self

    def _finished(self) -> Optional[Status]:
        """SUCCESS when ``for`` has passed or ``until`` holds (what was under way is given up), else None."""
        if self.duration_s is not None and self.ctx.clock.now() - self.started_s >= self.duration_s - 1e-9:
            return self._end(Status.SUCCESS, f"{self.duration_s:g} s of taking goals are over "
                                             f"({self.reached} reached)")
        if self.until is not None and self.until.holds():
            return self._end(Status.SUCCESS, f"{self.until} holds ({self.reached} goals reached)")
        return None

    def _take_new_goal(self) -> None:
        inbox = self.inbox
        latest = inbox.latest if inbox is not None else None
        if latest is None or latest.number <= self.seen:
            return
        self.seen = latest.number
        if self.goal is not None and self.leg.status == Status.RUNNING:
            self.ctx.events.add("ros2", f"ROS 2 goal {self.goal.number} ({self.goal.x:.2f}, {self.goal.y:.2f}) m "
                                        f"replaced by goal {latest.number}")
            self.leg.stop(Status.INVALID)  # its visit ends unreached; the next tick plans to the new goal
        elif self.leg.status != Status.INVALID:
            self.leg.stop(Status.INVALID)
        self.goal = latest
        self.leg.place = f"goal {latest.number}"  # what its visit (the summary's map_waypoints) is called
        self.ctx.events.add("ros2", f"ROS 2 goal {latest.number}: ({latest.x:.2f}, {latest.y:.2f}) m on the map")

    def _leg_ended(self) -> None:
        goal = self.goal
        assert goal is not None
        if self.leg.status == Status.SUCCESS:
            self.reached += 1
            self.ctx.events.add("ros2", f"ROS 2 goal {goal.number} reached")
        else:
            self.ctx.events.add("ros2", f"ROS 2 goal {goal.number} not reached ({self.leg.feedback_message}); "
                                        f"waiting for the next")
        self.leg.stop(Status.INVALID)
        self.goal = None


__all__ = ["Ros2Goals", "GoalInbox", "Goal", "WaitForGoal", "GOAL_INBOX"]
