"""Compile a :class:`~beastbt.mission.model.Mission` into a py_trees behaviour tree.

Each step keyword has a builder: the language's own are in :data:`CORE_STEPS`;
parts of a robot that add steps (navigation, vision, teleop) hand theirs to
the compiler through the assembly (``Part.steps``). Node names read like the mission (``drive 3 m at 0.15 m/s``).
A step whose part is missing on this robot compiles to a leaf that fails with
"not available on this robot" and says why.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Any, Callable, Mapping, Optional

import py_trees

from beastbt.behaviours.conditions import (Condition, ConditionReader, CheckCondition, battery_below, elapsed,
                                           gps_fix, line_flag, near, teleop_active)
from beastbt.behaviours.context import MissionContext
from beastbt.behaviours.drive import DriveDistance, DriveTime
from beastbt.behaviours.flow import ClockTimeout, IfThenElse, RepeatTimes, RetryAttempts, WhileLoop
from beastbt.behaviours.operator import NotAvailable, Say, Snapshot
from beastbt.behaviours.servos import SetServos
from beastbt.behaviours.stand import StopRobot, Wait, WaitUntil
from beastbt.behaviours.turn import TurnBy, TurnToHeading
from beastbt.blackboard.types import ServoCommand
from beastbt.mission.model import HOME, Mission, Step, parse_count, step_of, steps_of
from beastbt.core.units import format_quantity, parse_quantity

Behaviour = py_trees.behaviour.Behaviour
StepBuilder = Callable[["Compiler", Step], Behaviour]

DEFAULT_NEAR_WITHIN_M = 3.0
"""``{near: place}`` without ``within`` means within this many metres."""


def _q(value: Any, kind: str) -> str:
    return format_quantity(parse_quantity(value, kind), kind)


class Compiler:
    """Builds the tree of one mission for one robot (its context)."""

    def __init__(self, mission: Mission, ctx: MissionContext, builders: Optional[Mapping[str, StepBuilder]] = None) -> None:
        self.mission = mission
        self.ctx = ctx
        self.builders: Mapping[str, StepBuilder] = CORE_STEPS if builders is None else builders
        self.reader = ConditionReader(ctx)
        self.call_stack: list[str] = []

    # -- structure --------------------------------------------------------
    def compile(self) -> Behaviour:
        """The whole mission: a sequence of its steps, named after the mission."""
        return self.sequence(f"mission {self.mission.name}", self.mission.steps, always_wrap=True)

    def sequence(self, name: str, steps: list[Step], always_wrap: bool = False) -> Behaviour:
        """Run ``steps`` in order; a single step stands alone unless ``always_wrap``."""
        children = [self.step(s) for s in steps]
        if len(children) == 1 and not always_wrap:
            return children[0]
        return py_trees.composites.Sequence(name=name, memory=True, children=children)

    def step(self, s: Step) -> Behaviour:
        """The behaviour (or subtree) for one step."""
        builder = self.builders.get(s.kind)
        if builder is None and s.kind in self.mission.external_steps:
            builder = self.mission.external_steps[s.kind].build
        if builder is None:
            needs = NEEDS_A_PART.get(s.kind)
            why = (f"'{s.kind}' needs {needs}, which this robot or version does not provide" if needs
                   else f"'{s.kind}' is not supported by this version of beastbt")
            return NotAvailable(s.kind, self.ctx, why)
        return builder(self, s)

    def raw(self, s: Step) -> dict:
        """The whole mapping a step was written as (for keys beside the keyword, like ``then``)."""
        node: Any = self.mission.doc.data
        for part in s.path:
            node = node[part]
        return node

    def steps_at(self, values: list, path: tuple) -> list[Step]:
        """Steps of a nested list."""
        return steps_of(values, path, self.mission.external_steps)

    def place(self, name: str) -> tuple[Optional[float], Optional[float], Optional[float]]:
        """(lat, lon, tolerance_m) of a named place; ``home`` is (None, None, None) until known."""
        if name == HOME:
            return None, None, None
        p = self.mission.places[name]
        return p.lat, p.lon, p.tolerance_m

    # -- conditions -------------------------------------------------------
    def condition(self, raw: Any) -> Condition:
        """Compile a condition written in the mission language."""
        r = self.reader
        if isinstance(raw, str):
            tests = {"intersection": line_flag("intersection"), "line_seen": line_flag("seen"),
                     "gps_fix": gps_fix, "teleop_active": teleop_active}
            return Condition(raw, tests[raw], r)
        if "battery_below" in raw:
            v = parse_quantity(raw["battery_below"], "voltage")
            return Condition(f"battery below {v:g} V", battery_below(v), r)
        if "near" in raw:
            within = parse_quantity(raw.get("within", DEFAULT_NEAR_WITHIN_M), "distance")
            lat, lon, _ = self.place(raw["near"])
            return Condition(f"near {raw['near']} within {within:g} m", near(lat, lon, within, raw["near"]), r)
        if "elapsed" in raw:
            t = parse_quantity(raw["elapsed"], "duration")
            return Condition(f"elapsed {t:g} s", elapsed(t), r)
        if "not" in raw:
            inner = self.condition(raw["not"])
            return Condition(f"not {inner}", lambda rd, c=inner: not c.test(rd), r)
        if "all" in raw:
            parts = [self.condition(c) for c in raw["all"]]
            return Condition("all of (" + ", ".join(map(str, parts)) + ")", lambda rd: all(c.test(rd) for c in parts), r)
        parts = [self.condition(c) for c in raw["any"]]
        return Condition("any of (" + ", ".join(map(str, parts)) + ")", lambda rd: any(c.test(rd) for c in parts), r)


# -- actions ----------------------------------------------------------------

def _drive(c: Compiler, s: Step) -> Behaviour:
    v = s.value
    speed = parse_quantity(v["speed"], "speed") if "speed" in v else None
    at = f" at {_q(v['speed'], 'speed')}" if "speed" in v else ""
    if "distance" in v:
        d = parse_quantity(v["distance"], "distance")
        stuck = parse_quantity(v["stuck_after"], "duration") if "stuck_after" in v else None
        return DriveDistance(f"drive {_q(v['distance'], 'distance')}{at}", c.ctx, d, speed, stuck)
    t = parse_quantity(v["time"], "duration")
    return DriveTime(f"drive for {_q(v['time'], 'duration')}{at}", c.ctx, t, speed)


def _turn(c: Compiler, s: Step) -> Behaviour:
    v = s.value
    rate = parse_quantity(v["rate"], "turn_rate") if "rate" in v else None
    stuck = parse_quantity(v["stuck_after"], "duration") if "stuck_after" in v else None
    if "angle" in v:
        a = parse_quantity(v["angle"], "angle")
        return TurnBy(f"turn {math.degrees(a):g} deg", c.ctx, a, rate, stuck)
    h = parse_quantity(v["heading"], "angle")
    return TurnToHeading(f"turn to heading {math.degrees(h):g} deg", c.ctx, h, rate, stuck)


def _wait(c: Compiler, s: Step) -> Behaviour:
    return Wait(f"wait {_q(s.value, 'duration')}", c.ctx, parse_quantity(s.value, "duration"))


def _stop(c: Compiler, s: Step) -> Behaviour:
    return StopRobot("stop", c.ctx)


def _look(c: Compiler, s: Step) -> Behaviour:
    v = s.value
    cmds, words = [], []
    for axis in ("pan", "tilt"):
        if axis in v:
            angle = parse_quantity(v[axis], "angle")
            cmds.append(ServoCommand(name=axis, angle_rad=angle))
            words.append(f"{axis} {math.degrees(angle):g} deg")
    settle = parse_quantity(v["settle"], "duration") if "settle" in v else None
    return SetServos("look " + ", ".join(words), c.ctx, cmds, settle)


def _servo(c: Compiler, s: Step) -> Behaviour:
    v = s.value
    settle = parse_quantity(v["settle"], "duration") if "settle" in v else None
    if "name" in v:
        angle = parse_quantity(v["angle"], "angle")
        return SetServos(f"servo {v['name']} {math.degrees(angle):g} deg", c.ctx,
                         [ServoCommand(name=v["name"], angle_rad=angle)], settle)
    pulse = parse_quantity(v["pulse"], "pulse")
    return SetServos(f"servo channel {v['channel']} {pulse * 1000:g} ms", c.ctx,
                     [ServoCommand(channel=v["channel"], pulse_s=pulse)], settle)


def _say(c: Compiler, s: Step) -> Behaviour:
    text = str(s.value)
    short = text if len(text) <= 30 else text[:27] + "..."
    return Say(f'say "{short}"', c.ctx, text)


def _snapshot(c: Compiler, s: Step) -> Behaviour:
    if "camera" not in c.ctx.capabilities:
        return NotAvailable(f"snapshot {s.value['name']}", c.ctx, "this robot has no camera")
    return Snapshot(f"snapshot {s.value['name']}", c.ctx, s.value["name"])


NEEDS_A_PART: Mapping[str, str] = MappingProxyType({
    "go_to": "GPS navigation", "route": "GPS navigation", "return_home": "GPS navigation",
    "follow_line": "a camera and the line follower", "teleop": "a joystick",
})
"""Steps of the language that a part provides, and what a robot without that part lacks."""


# -- flow -------------------------------------------------------------------

def _repeat(c: Compiler, s: Step) -> Behaviour:
    times = parse_count(s.value["times"])
    body = c.sequence("pass", c.steps_at(s.value["steps"], s.path + ("repeat", "steps")), always_wrap=True)
    label = "forever" if times < 0 else f"{times} times"
    return RepeatTimes(f"repeat {label}", body, times)


def _do(c: Compiler, s: Step) -> Behaviour:
    name = s.value
    c.call_stack.append(name)
    try:
        return c.sequence(f"do {name}", c.mission.tasks[name], always_wrap=True)
    finally:
        c.call_stack.pop()


def _first_of(c: Compiler, s: Step) -> Behaviour:
    alts = [c.sequence(f"alternative {i + 1}", c.steps_at(alt, s.path + ("first_of", i)), always_wrap=True)
            for i, alt in enumerate(s.value)]
    return py_trees.composites.Selector(name=f"first of {len(alts)} alternatives", memory=True, children=alts)


def _retry(c: Compiler, s: Step) -> Behaviour:
    times = parse_count(s.value["times"])
    body = c.sequence("attempt", c.steps_at(s.value["steps"], s.path + ("retry", "steps")), always_wrap=True)
    label = "forever" if times < 0 else f"up to {times} attempts"
    return RetryAttempts(f"retry {label}", body, times)


def _timeout(c: Compiler, s: Step) -> Behaviour:
    after = parse_quantity(s.value["after"], "duration")
    body = c.sequence("steps", c.steps_at(s.value["steps"], s.path + ("timeout", "steps")), always_wrap=True)
    return ClockTimeout(f"timeout {_q(s.value['after'], 'duration')}", body, after, c.ctx.clock)


def _parallel(c: Compiler, s: Step) -> Behaviour:
    on = s.value.get("succeed_on", "all")
    children = [c.step(x) for x in c.steps_at(s.value["steps"], s.path + ("parallel", "steps"))]
    policy = (py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True) if on == "all"
              else py_trees.common.ParallelPolicy.SuccessOnOne())
    return py_trees.composites.Parallel(name=f"parallel (succeed on {on})", policy=policy, children=children)


def _if(c: Compiler, s: Step) -> Behaviour:
    raw = c.raw(s)
    cond = c.condition(raw["if"])
    then = c.sequence("then", c.steps_at(raw["then"], s.path + ("then",)), always_wrap=True)
    other = c.sequence("else", c.steps_at(raw["else"], s.path + ("else",)), always_wrap=True) if "else" in raw else None
    return IfThenElse(f"if {cond}", cond, then, other)


def _while(c: Compiler, s: Step) -> Behaviour:
    raw = c.raw(s)
    cond = c.condition(raw["while"])
    body = c.sequence("pass", c.steps_at(raw["steps"], s.path + ("steps",)), always_wrap=True)
    return WhileLoop(f"while {cond}", cond, body)


def _wait_until(c: Compiler, s: Step) -> Behaviour:
    raw = c.raw(s)
    cond = c.condition(raw["wait_until"])
    timeout = parse_quantity(raw["timeout"], "duration") if "timeout" in raw else None
    name = f"wait until {cond}" + (f" (at most {_q(raw['timeout'], 'duration')})" if timeout else "")
    return WaitUntil(name, c.ctx, cond, timeout)


CORE_STEPS: Mapping[str, StepBuilder] = MappingProxyType({
    "drive": _drive,
    "turn": _turn,
    "wait": _wait,
    "stop": _stop,
    "look": _look,
    "servo": _servo,
    "say": _say,
    "snapshot": _snapshot,
    "repeat": _repeat,
    "do": _do,
    "first_of": _first_of,
    "retry": _retry,
    "timeout": _timeout,
    "parallel": _parallel,
    "if": _if,
    "while": _while,
    "wait_until": _wait_until,
})
"""The builders of the language's own steps (read-only); parts add theirs through the assembly."""


def compile_mission(mission: Mission, ctx: MissionContext,
                    builders: Optional[Mapping[str, StepBuilder]] = None) -> Behaviour:
    """Compile ``mission`` for the robot described by ``ctx`` with step ``builders`` (default: the core steps)."""
    return Compiler(mission, ctx, builders).compile()


def tree_to_dot(root: Behaviour) -> str:
    """Graphviz DOT text of a tree: composites as boxes, leaves as ellipses, in tick order."""
    lines = ["digraph mission {", '  graph [rankdir=TB, fontname="Helvetica"];', '  node [fontname="Helvetica"];']
    ids: dict[int, str] = {}

    def node_id(b: Behaviour) -> str:
        return ids.setdefault(id(b), f"n{len(ids)}")

    def visit(b: Behaviour) -> None:
        shape = "box" if b.children else "ellipse"
        label = b.name.replace('"', '\\"')
        lines.append(f'  {node_id(b)} [label="{label}", shape={shape}];')
        for child in b.children:
            visit(child)
            lines.append(f"  {node_id(b)} -> {node_id(child)};")

    visit(root)
    lines.append("}")
    return "\n".join(lines) + "\n"


__all__ = ["Compiler", "compile_mission", "CORE_STEPS", "NEEDS_A_PART", "StepBuilder", "tree_to_dot", "CheckCondition", "step_of"]
