"""The ``ros2_goals`` step: its builder (the ROS 2 part adds it to the language) and the checks before a run.

A mission step ``ros2_goals: {}`` compiles to
:class:`~beastbt.behaviours.ros2_goals.Ros2Goals`, whose leg is the planned
``go_to`` of a place on the map (:class:`~beastbt.behaviours.map_navigation.MapGoTo`),
the same one ``beastbt serve --ros2`` runs for a goal. The step needs the ROS 2
link and a map: a run without either is refused before anything moves, at the
step's line (:func:`refuse_without_link_or_map`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Iterator

from beastbt.core.units import format_quantity
from beastbt.mission import steps as st

KEYWORD = "ros2_goals"


def goal_steps(mission: Any) -> Iterator[st.Ros2Goals]:
    """Every ``ros2_goals`` step of ``mission`` (its steps and its tasks', nested ones included)."""
    def walk(steps: Any) -> Iterator[st.Ros2Goals]:
        for step in steps:
            if isinstance(step, st.Ros2Goals):
                yield step
            for value in (getattr(step, f.name) for f in dataclasses.fields(step)):
                if isinstance(value, tuple) and value and isinstance(value[0], st.Step):
                    yield from walk(value)
                elif isinstance(value, tuple) and value and all(isinstance(v, tuple) for v in value):
                    # first_of's alternatives (tuples of steps); a task's parameters are tuples of names and values
                    for alternative in value:
                        if alternative and isinstance(alternative[0], st.Step):
                            yield from walk(alternative)
    yield from walk(getattr(mission, "steps", ()))
    for steps in list(getattr(mission, "tasks", {}).values()) + list(getattr(mission, "task_variants", {}).values()):
        yield from walk(steps)


def uses_goals(mission: Any) -> bool:
    """Whether ``mission`` has a ``ros2_goals`` step anywhere."""
    return next(goal_steps(mission), None) is not None


def refuse_without_link_or_map(mission: Any, has_link: bool, takes_goals: bool = True) -> None:
    """InvalidInput at the first ``ros2_goals`` step when the run has no ROS 2 link, a link that takes no commands
    (``takes_goals`` false: plain TCP beyond loopback publishes only), or the mission no map."""
    from beastbt.core.errors import InvalidInput, Problem
    step = next(goal_steps(mission), None)
    if step is None:
        return
    if not has_link:
        raise InvalidInput([Problem(mission.file, step.at, "ros2_goals waits for goals from ROS 2 (/goal_pose), and "
                                    "this run has no ROS 2 link", "run it with --ros2 (beastbt run MISSION --ros2, or "
                                    "beastbt serve --ros2; the profile's ros2: section says how), docs/ros2.md")])
    if not takes_goals:
        raise InvalidInput([Problem(mission.file, step.at, "ros2_goals waits for goals from ROS 2 (/goal_pose), and "
                                    "this run's ROS 2 link publishes only: it listens beyond loopback without keys, "
                                    "so it takes no commands", "give --ros2-config a Zenoh configuration with TLS, or "
                                    "listen on loopback (docs/ros2.md, who may command)")])
    if getattr(mission, "map_grid", None) is None:
        raise InvalidInput([Problem(mission.file, step.at, "ros2_goals plans each goal on a map, and this mission "
                                    "has none", "add map: office (a map_server YAML: a name or a path) at the top of "
                                    "the mission, or run it in a world with a map:")])


def _label(s: st.Ros2Goals) -> str:
    ends = []
    if s.goals is not None:
        ends.append(f"{s.goals} goal{'s' if s.goals != 1 else ''}")
    if s.duration_s is not None:
        ends.append(f"for {format_quantity(s.duration_s, 'duration')}")
    return "ros2_goals" + (f" ({', '.join(ends)})" if ends else "")


def build_ros2_goals(c: Any, s: st.Ros2Goals) -> Any:
    """``ros2_goals: {goals:, for:, until:, tolerance:, speed:}``: a :class:`Ros2Goals` over a MapGoTo leg."""
    from beastbt.behaviours.map_navigation import MapGoTo, map_planner, mission_map_start
    from beastbt.behaviours.operator import NotAvailable
    from beastbt.behaviours.ros2_goals import Ros2Goals
    m = c.mission
    if getattr(m, "map_grid", None) is None:  # refused before the run; a tree printed without a map says so
        return NotAvailable(_label(s), c.ctx, "ros2_goals plans each goal on a map, and this mission has none")
    planner = map_planner(c.ctx, m.map_grid, mission_map_start(m))
    until = c.condition(s.until) if s.until is not None else None
    shown = f"within {s.tolerance_m:g} m" if s.tolerance_m is not None else "on the map"

    def leg(target: Any) -> Any:
        return MapGoTo(f"go_to the goal ({shown})", c.ctx, "goal", target, planner, s.tolerance_m,
                       speed_mps=s.speed_mps)
    label = _label(s) + (f" until {until}" if until is not None else "")
    return Ros2Goals(label, c.ctx, leg, s.goals, s.duration_s, until)


def goal_in_map_frame(frame_id: str, map_frame: str = "map") -> bool:
    """Whether a goal's ``header.frame_id`` is the map frame (``map_frame``, the profile's ``frames: map:``; rviz2
    stamps its goals with its Fixed Frame), an empty frame counting as it."""
    return frame_id.lstrip("/") in ("", map_frame.lstrip("/"))


__all__ = ["build_ros2_goals", "goal_steps", "uses_goals", "refuse_without_link_or_map", "goal_in_map_frame",
           "KEYWORD"]
