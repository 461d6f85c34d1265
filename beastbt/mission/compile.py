"""Compile a :class:`~beastbt.mission.model.Mission` into a py_trees behaviour tree.

The loader has already turned every step into a typed dataclass
(:mod:`beastbt.mission.steps`, SI units); here each step maps to its
behaviour. The builders of the language's own steps are in
:data:`CORE_STEPS`, keyed by keyword; parts of a robot that add steps
(navigation, line following, teleop) hand theirs to the compiler through the
assembly (``Part.steps``), and steps of installed packages come with the
mission (``Mission.external_steps``). Node names read like the mission
(``drive 3 m at 0.15 m/s``). A step whose part is missing on this robot
compiles to a leaf that fails with "not available on this robot" and says why.
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Any, Callable, Mapping, Optional, Sequence

import py_trees

from beastbt.behaviours import drive, stand, turn
from beastbt.behaviours.conditions import (Condition, ConditionReader, all_of, any_of, battery_below, elapsed, gps_fix,
                                           line_flag, near, not_of, teleop_active)
from beastbt.behaviours.localized import localized
from beastbt.behaviours.context import MissionContext
from beastbt.behaviours.flow import BlockStart, ClockTimeout, GuardedBlock, IfThenElse, RepeatTimes, RetryAttempts, WhileLoop
from beastbt.behaviours.operator import NotAvailable, Say, Snapshot
from beastbt.behaviours.servos import SetServos
from beastbt.blackboard.types import ServoCommand
from beastbt.core.units import format_quantity
from beastbt.mission import steps as st
from beastbt.mission.model import HOME, Mission

Behaviour = py_trees.behaviour.Behaviour
Status = py_trees.common.Status
StepBuilder = Callable[["Compiler", st.Step], Behaviour]
"""Makes the behaviour (or subtree) of one typed step: ``fn(compiler, step)``."""

CONDITION_READS: Mapping[type, tuple[str, ...]] = MappingProxyType({
    st.BatteryBelow: ("battery",), st.Near: ("pose",), st.Elapsed: ("mission_start_s",), st.ObstacleWithin: ("scan",)})
"""Blackboard keys each kind of condition reads (flags read the key they name, or ``line``)."""
LINE_FLAGS = MappingProxyType({"intersection": "intersection", "line_seen": "seen"})
"""Condition words read from the line observation, and the observation's flag each reads."""
FLAG_READS = MappingProxyType({"localized": "map_pose"})
"""The blackboard key a named condition reads, where it is not the word itself."""


class ConditionUnavailable(Exception):
    """A condition this robot cannot check (``obstacle_within`` without a LiDAR): the step that uses it fails at once.

    ``text``: the condition in words; ``why``: what the robot lacks.
    """

    def __init__(self, text: str, why: str) -> None:
        super().__init__(why)
        self.text = text
        self.why = why


class Compiler:
    """Builds the tree of one mission for one robot (its context) with the given step builders."""

    def __init__(self, mission: Mission, ctx: MissionContext, builders: Optional[Mapping[str, StepBuilder]] = None,
                 on_step: Optional[Callable[[st.Step, Behaviour], None]] = None) -> None:
        self.mission = mission
        self.on_step = on_step
        """Told each step and the behaviour it became (the studio maps nodes back to their lines)."""
        self.ctx = ctx
        self.builders: Mapping[str, StepBuilder] = CORE_STEPS if builders is None else builders
        self.reader = ConditionReader(ctx)
        self.blocks: list[BlockStart] = [self.new_block()]
        """The guard blocks being compiled, innermost last; the first stands for the mission itself."""
        self.scan_watch: Optional[Any] = None
        """The latest scan for the mission's ``obstacle_within`` conditions (one for all), once one is compiled."""

    # -- structure --------------------------------------------------------
    def compile(self) -> Behaviour:
        """The whole mission: a sequence of its steps, named after the mission (a mission test's substituted steps
        in place: :attr:`RunServices.substitute`)."""
        root = self.sequence(f"mission {self.mission.name}", self.mission.steps, always_wrap=True)
        substitute = self.ctx.services.substitute
        return root if substitute is None else substitute(root)

    def sequence(self, name: str, steps: Sequence[st.Step], always_wrap: bool = False) -> Behaviour:
        """Run ``steps`` in order; a single step stands alone unless ``always_wrap``."""
        children = [self.step(s) for s in steps]
        if len(children) == 1 and not always_wrap:
            return children[0]
        return py_trees.composites.Sequence(name=name, memory=True, children=children)

    def step(self, s: st.Step) -> Behaviour:
        """The behaviour (or subtree) for one step."""
        built = self._step(s)
        if self.on_step is not None:
            self.on_step(s, built)
        return built

    def _step(self, s: st.Step) -> Behaviour:
        kind = st.keyword_of(s)
        if kind == "route":
            from beastbt.mission.route_tasks import needs_tasks, route_with_tasks
            if needs_tasks(s):  # tasks at each place, or going on after a failure: one go_to per place
                return route_with_tasks(self, s)  # type: ignore[arg-type]
        builder = self.builders.get(kind)
        if builder is None and kind in self.mission.external_steps:
            builder = self.mission.external_steps[kind].build
        if builder is None:
            needs = NEEDS_A_PART.get(kind)
            why = (f"'{kind}' needs {needs}, which this robot or version does not provide" if needs
                   else f"'{kind}' is not supported by this version of beastbt")
            return NotAvailable(kind, self.ctx, why)
        try:
            return builder(self, s)
        except ConditionUnavailable as exc:
            # A step whose condition this robot cannot check fails at once, saying why (as a step it cannot do).
            return NotAvailable(f"{kind.replace('_', ' ')} ({exc.text}: not on this robot)", self.ctx, exc.why)

    def place(self, name: str) -> tuple[Optional[float], Optional[float], Optional[float]]:
        """(lat, lon, tolerance_m) of a named place; ``home`` is (None, None, None) until known."""
        if name == HOME:
            return None, None, None
        p = self.mission.places[name]
        return p.lat, p.lon, p.tolerance_m

    def on_map(self, name: str) -> bool:
        """Whether place ``name`` is on the mission's saved map (``home`` is, on a mission with ``map:``)."""
        if getattr(self.mission, "map_grid", None) is None:
            return False
        return name == HOME or self.mission.places[name].on_map

    def new_block(self) -> BlockStart:
        """Where a guard block (or the mission) starts: the clock, and the odometry distance read then."""
        reader = self.reader

        def distance() -> float:
            pose = reader.get("pose_odom")
            return float(getattr(pose, "distance_m", 0.0) or 0.0)

        return BlockStart(self.ctx.clock, distance, lambda: reader.get("mission_start_s"))  # type: ignore[arg-type]

    # -- conditions -------------------------------------------------------
    def condition(self, c: st.Condition) -> Condition:
        """The test of a typed condition, named as the mission says it."""
        r = self.reader
        self.ctx.condition_reads.update(CONDITION_READS.get(type(c), ()))
        if isinstance(c, st.Flag):
            self.ctx.condition_reads.add("line" if c.word in LINE_FLAGS else FLAG_READS.get(c.word, c.word))
            test = {"gps_fix": gps_fix, "teleop_active": teleop_active, "localized": localized}.get(c.word)
            return Condition(c.word, test if test is not None else line_flag(LINE_FLAGS[c.word]), r)
        if isinstance(c, st.BatteryBelow):
            return Condition(f"battery below {c.volts:g} V", battery_below(c.volts), r)
        if isinstance(c, st.Near) and self.on_map(c.place):
            from beastbt.behaviours.map_navigation import near_on_map
            self.ctx.condition_reads.add("map_pose")
            m = self.mission
            xy = (m.map_start[0], m.map_start[1]) if c.place == HOME else (m.places[c.place].x, m.places[c.place].y)
            return Condition(f"near {c.place} within {c.within_m:g} m", near_on_map(xy, c.within_m), r)
        if isinstance(c, st.Near):
            lat, lon, _ = self.place(c.place)
            if lat is None:
                self.ctx.condition_reads.add("home")
            return Condition(f"near {c.place} within {c.within_m:g} m", near(lat, lon, c.within_m, c.place), r)
        if isinstance(c, st.Elapsed):
            return Condition(f"elapsed {c.duration_s:g} s", elapsed(c.duration_s), r)
        if isinstance(c, st.InFence):
            fence, inside = self.mission.fences[c.fence], c.inside
            self.ctx.condition_reads.add("pose")

            def where(rd: ConditionReader) -> bool:
                pose = rd.get("pose")
                if pose is None or not pose.position_valid or pose.lat is None:
                    return False
                return fence.contains(pose.lat, pose.lon) is inside
            return Condition(f"{'inside' if inside else 'outside'} {c.fence}", where, r)
        if isinstance(c, st.Answered):
            ctx, qid, choice = self.ctx, c.question_id, c.choice
            return Condition(f"{qid} answered {choice}",
                             lambda rd: ctx.services.questions is not None
                             and ctx.services.questions.answer_of(qid) == choice, r)
        if isinstance(c, st.DistanceTravelled):
            block, metres = self.blocks[-1], c.distance_m
            self.ctx.condition_reads.add("pose_odom")
            return Condition(f"distance travelled {format_quantity(metres, 'distance')}",
                             lambda rd: block.travelled_m() >= metres, r)
        if isinstance(c, st.TimeInBlock):
            block, seconds = self.blocks[-1], c.duration_s
            self.ctx.condition_reads.add("mission_start_s")
            return Condition(f"time in block {format_quantity(seconds, 'duration')}",
                             lambda rd: block.elapsed_s() >= seconds, r)
        if isinstance(c, st.ObstacleWithin):
            return self.obstacle_condition(c)
        if isinstance(c, st.Sees):
            return self.sees_condition(c)
        if isinstance(c, st.Not):
            inner = self.condition(c.condition)
            return Condition(f"not {inner}", not_of(inner.test), r)
        parts = [self.condition(x) for x in c.conditions]
        if isinstance(c, st.AllOf):
            return Condition("all of (" + ", ".join(map(str, parts)) + ")", all_of([p.test for p in parts]), r)
        return Condition("any of (" + ", ".join(map(str, parts)) + ")", any_of([p.test for p in parts]), r)

    def sees_condition(self, c: st.Sees) -> Condition:
        """``{sees: ...}``: on the camera's newest frame; :class:`ConditionUnavailable` on a robot without a camera."""
        from beastbt.behaviours.sees import sees_condition, sees_text
        if "camera" not in self.ctx.capabilities:
            raise ConditionUnavailable(sees_text(c), "'sees' needs a camera, and this robot has none "
                                                     "(no camera: section in its profile)")
        if c.what == "motion":
            self.ctx.condition_reads.add("pose_odom")
        return sees_condition(c, self.reader)

    def obstacle_condition(self, c: st.ObstacleWithin) -> Condition:
        """``obstacle_within``: on the latest LiDAR scan; :class:`ConditionUnavailable` on a robot without a LiDAR."""
        text = f"obstacle within {format_quantity(c.gap_m, 'distance')}"
        if "lidar" not in self.ctx.capabilities:
            raise ConditionUnavailable(text, "'obstacle_within' needs a LiDAR, and this robot has none "
                                             "(no lidar: section in its profile)")
        from beastbt.behaviours.obstacle_within import ObstacleTest, ScanWatch, sector_words
        if self.scan_watch is None:
            self.scan_watch = ScanWatch(self.ctx)
        self.ctx.condition_reads.add("scan")
        test = ObstacleTest(c.gap_m, c.sector_rad, self.scan_watch)
        return Condition(text + sector_words(c.sector_rad), test, self.reader, test.detail)


def _at(speed_mps: Optional[float]) -> str:
    return f" at {format_quantity(speed_mps, 'speed')}" if speed_mps is not None else ""


# -- actions ----------------------------------------------------------------

def _drive(c: Compiler, s: st.Step) -> Behaviour:
    if isinstance(s, st.DriveDistance):
        return drive.DriveDistance(f"drive {format_quantity(s.distance_m, 'distance')}{_at(s.speed_mps)}", c.ctx,
                                   s.distance_m, s.speed_mps, s.stuck_after_s)
    assert isinstance(s, st.DriveTime)
    return drive.DriveTime(f"drive for {format_quantity(s.duration_s, 'duration')}{_at(s.speed_mps)}", c.ctx,
                           s.duration_s, s.speed_mps)


def _turn(c: Compiler, s: st.Step) -> Behaviour:
    if isinstance(s, st.TurnBy):
        return turn.TurnBy(f"turn {math.degrees(s.angle_rad):g} deg", c.ctx, s.angle_rad, s.rate_rps, s.stuck_after_s)
    assert isinstance(s, st.TurnToHeading)
    return turn.TurnToHeading(f"turn to heading {math.degrees(s.heading_rad):g} deg", c.ctx, s.heading_rad,
                              s.rate_rps, s.stuck_after_s)


def _wait(c: Compiler, s: st.Wait) -> Behaviour:
    return stand.Wait(f"wait {format_quantity(s.duration_s, 'duration')}", c.ctx, s.duration_s)


def _stop(c: Compiler, s: st.Stop) -> Behaviour:
    return stand.StopRobot("stop", c.ctx)


def _look(c: Compiler, s: st.Look) -> Behaviour:
    cmds, words = [], []
    for axis, angle in (("pan", s.pan_rad), ("tilt", s.tilt_rad)):
        if angle is not None:
            cmds.append(ServoCommand(name=axis, angle_rad=angle))
            words.append(f"{axis} {math.degrees(angle):g} deg")
    return SetServos("look " + ", ".join(words), c.ctx, cmds, s.settle_s)


def _servo(c: Compiler, s: st.Step) -> Behaviour:
    if isinstance(s, st.ServoAngle):
        return SetServos(f"servo {s.name} {math.degrees(s.angle_rad):g} deg", c.ctx,
                         [ServoCommand(name=s.name, angle_rad=s.angle_rad)], s.settle_s)
    assert isinstance(s, st.ServoPulse)
    return SetServos(f"servo channel {s.channel} {s.pulse_s * 1000:g} ms", c.ctx,
                     [ServoCommand(channel=s.channel, pulse_s=s.pulse_s)], s.settle_s)


def _say(c: Compiler, s: st.Say) -> Behaviour:
    short = s.text if len(s.text) <= 30 else s.text[:27] + "..."
    return Say(f'say "{short}"', c.ctx, s.text)


def _snapshot(c: Compiler, s: st.Snapshot) -> Behaviour:
    if "camera" not in c.ctx.capabilities:
        return NotAvailable(f"snapshot {s.name}", c.ctx, "this robot has no camera")
    return Snapshot(f"snapshot {s.name}", c.ctx, s.name)


NEEDS_A_PART: Mapping[str, str] = MappingProxyType({
    "go_to": "GPS navigation", "route": "GPS navigation", "return_home": "GPS navigation",
    "follow_line": "a camera and the line follower", "teleop": "a joystick",
    "photo": "a camera", "alert": "the camera's part", "dock": "a camera", "undock": "a drive base",
    "track": "a camera", "ros2_goals": "the ROS 2 link (--ros2)",
})
"""Steps of the language that a part provides, and what a robot without that part lacks."""


# -- flow -------------------------------------------------------------------

def _repeat(c: Compiler, s: st.Repeat) -> Behaviour:
    body = c.sequence("pass", s.steps, always_wrap=True)
    label = "forever" if s.times < 0 else f"{s.times} times"
    return RepeatTimes(f"repeat {label}", body, s.times)


def _do(c: Compiler, s: st.Do) -> Behaviour:
    if s.args:
        label = ", ".join(f"{k}: {v}" for k, v in s.args)
        return c.sequence(f"do {s.task} ({label})", c.mission.task_variants[(s.task, s.args)], always_wrap=True)
    return c.sequence(f"do {s.task}", c.mission.tasks[s.task], always_wrap=True)


def _first_of(c: Compiler, s: st.FirstOf) -> Behaviour:
    alts = [c.sequence(f"alternative {i + 1}", alt, always_wrap=True) for i, alt in enumerate(s.alternatives)]
    return py_trees.composites.Selector(name=f"first of {len(alts)} alternatives", memory=True, children=alts)


def _retry(c: Compiler, s: st.Retry) -> Behaviour:
    body = c.sequence("attempt", s.steps, always_wrap=True)
    label = "forever" if s.times < 0 else f"up to {s.times} attempts"
    return RetryAttempts(f"retry {label}", body, s.times)


def _timeout(c: Compiler, s: st.Timeout) -> Behaviour:
    body = c.sequence("steps", s.steps, always_wrap=True)
    return ClockTimeout(f"timeout {format_quantity(s.after_s, 'duration')}", body, s.after_s, c.ctx.clock)


def _parallel(c: Compiler, s: st.Parallel) -> Behaviour:
    children = [c.step(x) for x in s.steps]
    policy = (py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=True) if s.succeed_on == "all"
              else py_trees.common.ParallelPolicy.SuccessOnOne())
    return py_trees.composites.Parallel(name=f"parallel (succeed on {s.succeed_on})", policy=policy, children=children)


def _if(c: Compiler, s: st.If) -> Behaviour:
    cond = c.condition(s.condition)
    then = c.sequence("then", s.then, always_wrap=True)
    other = c.sequence("else", s.otherwise, always_wrap=True) if s.otherwise is not None else None
    return IfThenElse(f"if {cond}", cond, then, other)


def _while(c: Compiler, s: st.While) -> Behaviour:
    cond = c.condition(s.condition)
    return WhileLoop(f"while {cond}", cond, c.sequence("pass", s.steps, always_wrap=True))


def _guarded(c: Compiler, s: st.Step, on_hold: Status, word: str) -> Behaviour:
    block = c.new_block()
    c.blocks.append(block)
    try:
        cond = c.condition(s.condition)  # type: ignore[attr-defined]
        body = c.sequence("steps", s.steps, always_wrap=True)  # type: ignore[attr-defined]
    finally:
        c.blocks.pop()
    return GuardedBlock(f"{word} {cond}", cond, body, on_hold, block, c.ctx.events)


def _ask(c: Compiler, s: st.Ask) -> Behaviour:
    from beastbt.behaviours.ask import AskOperator
    limit = f", {format_quantity(s.timeout_s, 'duration')} then {s.default or 'fail'}" if s.timeout_s else ""
    ask = AskOperator(f"ask {s.question_id}: {s.question}{limit}", c.ctx, s.question_id, s.question, s.timeout_s,
                      s.default)
    if not s.then and not s.otherwise:
        return ask
    cond = c.condition(st.Answered(question_id=s.question_id, choice="yes"))
    then = c.sequence("then", s.then, always_wrap=True)
    other = c.sequence("else", s.otherwise, always_wrap=True) if s.otherwise else None
    choose = IfThenElse(f"if {cond}", cond, then, other)
    return py_trees.composites.Sequence(name=f"ask {s.question_id}", memory=True, children=[ask, choose])


def _until(c: Compiler, s: st.UntilBlock) -> Behaviour:
    return _guarded(c, s, Status.SUCCESS, "until")


def _abort_if(c: Compiler, s: st.AbortIf) -> Behaviour:
    return _guarded(c, s, Status.FAILURE, "abort if")


def _wait_until(c: Compiler, s: st.WaitUntil) -> Behaviour:
    cond = c.condition(s.condition)
    limit = f" (at most {format_quantity(s.timeout_s, 'duration')})" if s.timeout_s else ""
    return stand.WaitUntil(f"wait until {cond}{limit}", c.ctx, cond, s.timeout_s)


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
    "until": _until,
    "abort_if": _abort_if,
    "ask": _ask,
})
"""The builders of the language's own steps by keyword (read-only); parts add theirs through the assembly."""


def compile_mission(mission: Mission, ctx: MissionContext,
                    builders: Optional[Mapping[str, StepBuilder]] = None,
                    on_step: Optional[Callable[[st.Step, Behaviour], None]] = None) -> Behaviour:
    """Compile ``mission`` for the robot described by ``ctx`` with step ``builders`` (default: the core steps);
    ``on_step`` is told each step and the behaviour it became."""
    return Compiler(mission, ctx, builders, on_step).compile()


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


__all__ = ["Compiler", "ConditionUnavailable", "compile_mission", "CORE_STEPS", "NEEDS_A_PART", "StepBuilder", "Behaviour",
           "tree_to_dot"]
