"""A mission test's events and substitutions carried out in a run, through the robot's own paths.

:class:`TestFaults` is what a test adds to a run on the simulator (given to
:func:`beastbt.assembly.prepare`): persons that join the world before the
simulator is built, a part (:class:`FaultsPart`) whose tick fires each event
when its trigger holds, and the forced results of steps. Each event goes
where such a thing happens on a robot, never around it:

- ``gps: lost``: a dropout window of the emulated receiver (it sends
  sentences without a fix, as the world's ``gps.dropouts_s`` do); the driver,
  the estimator and the mission's ``gps_lost`` failsafe see what follows.
- ``gps: {jump: D}``: a multipath jump of the receiver's fixes, D metres east.
- ``lidar: silent``: the emulated LiDAR head sends no bytes (the driver reads
  nothing, the scan goes stale, the collision monitor's ``silent`` acts).
- ``battery: 21 %``: the emulated base's battery set to that charge (or volts).
- ``person``: a person of the world (standing at ``from`` until the event)
  sets off, seen by the LiDAR and touched as the world's persons are.
- ``operator: pause|abort``: the operator console's controls
  (:class:`~beastbt.live.console_control.ConsoleControls`), resumed after ``for``.
- ``estop``: the console's e-stop (:func:`~beastbt.run.safety.request_estop`).

Each event fired is an event of the run (kind ``test``), so the summary,
the recording and the report show it. A substituted step is a leaf named
``<step> [substituted: failure after 5 s]`` in the tree; it stands still for
that long and ends so, saying so in an event (kind ``substitute``).
Times are seconds of the simulated clock; positions metres in the world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Optional

import py_trees

from beastbt.behaviours.base import BeastBehaviour, Status
from beastbt.behaviours.context import MissionContext, RunServices
from beastbt.robot.part import Part
from beastbt.testing.spec import Fault, Substitution, TestEvent, matches

if TYPE_CHECKING:
    from beastbt.run.runner import MissionRun
    from beastbt.run.session import Prepared
    from beastbt.sim.world import World

FAR_FUTURE_S = math.inf
"""A test's person who waits for its event sets off at this time until the event comes (s)."""


class SubstitutedStep(BeastBehaviour):
    """Stand in for a step whose result a test forces: stand still, then end with the forced result.

    RUNNING (commanding zero velocity) for ``after_s`` seconds from its first
    tick, then SUCCESS or FAILURE as forced, with an event of kind
    ``substitute`` naming the step it stands in for.
    """

    WRITES = ("cmd_mission",)

    def __init__(self, step: str, ctx: MissionContext, result: str, after_s: float) -> None:
        super().__init__(f"{step} [substituted: {result} after {after_s:g} s]", ctx)
        self.step = step
        self.result = result
        self.after_s = after_s
        self.started_s = 0.0

    def initialise(self) -> None:
        self.started_s = self.now()

    def update(self) -> Status:
        self.command(0.0, 0.0)
        if self.now() - self.started_s + 1e-9 < self.after_s:
            self.feedback_message = f"substituted by the test: {self.result} after {self.after_s:g} s"
            return Status.RUNNING
        if self.result == "success":
            self.ctx.events.add("substitute", f"{self.step}: success (substituted by the test)")
            self.feedback_message = "success (substituted)"
            return Status.SUCCESS
        self.ctx.events.add("substitute", f"{self.step}: failure (substituted by the test)")
        return self.fail("failure forced by the test (substituted)")


def substitute_steps(root: py_trees.behaviour.Behaviour, substitutions: list[Substitution],
                     ctx_of: Any) -> py_trees.behaviour.Behaviour:
    """Put a :class:`SubstitutedStep` in place of every node of ``root``'s tree a substitution names; return root.

    ``ctx_of(node)`` gives the mission context of the stand-in (the context of the node it replaces).
    """
    found = []
    for node in root.iterate():
        for sub in substitutions:
            if node is not root and matches(sub.step, node.name):
                found.append((node, sub))
                break
    for node, sub in found:
        stand_in = SubstitutedStep(node.name, ctx_of(node), sub.result, sub.after_s)
        parent = node.parent
        if isinstance(parent, py_trees.decorators.Decorator):
            parent.decorated = stand_in
            parent.children[0] = stand_in
            stand_in.parent = parent
        elif parent is not None:
            parent.replace_child(node, stand_in)
    return root


@dataclass
class _Pending:
    """A fault's end to carry out at clock time ``at_s`` (s): the operator's resume."""

    at_s: float
    control: str


class TestFaults:
    """What a mission test adds to one run: its events, persons and substitutions (see the module docstring)."""

    __test__ = False  # not a pytest test class, whatever its name

    def __init__(self, events: list[TestEvent], substitutions: list[Substitution],
                 fences: Optional[list[str]] = None) -> None:
        self.events = list(events)
        self.substitutions = list(substitutions)
        self.fences = list(fences or [])
        """Fences whose entry by the robot's true position is watched (``expect: never_in``)."""
        self.fired: list[dict] = []
        """Each event carried out: ``{index, time_s, what, trigger}`` (mission time s)."""
        self.persons: dict[int, int] = {}
        """Event index -> the index of its person among the contact world's persons."""
        self.part = FaultsPart(self)
        self.ctx: Optional[MissionContext] = None

    def enter(self, world: "World") -> None:
        """Add the test's persons to ``world`` before its simulator is built (each waits for its event)."""
        from beastbt.sim.obstacles import Person
        known = sum(1 for o in world.obstacles if isinstance(o, Person))
        for event in self.events:
            if event.fault.kind != "person":
                continue
            p = event.fault.params
            world.obstacles.append(Person(radius_m=0.25, speed_mps=p["speed_mps"], path=(p["from_xy"], p["to_xy"]),
                                          start_s=FAR_FUTURE_S, gives_way=p["gives_way"]))
            self.persons[event.index] = known
            known += 1

    def services(self) -> RunServices:
        """The run's services with the substitutions in (a fresh :class:`RunServices` otherwise as usual)."""
        services = RunServices()
        if self.substitutions:
            services.substitute = lambda root: substitute_steps(root, self.substitutions,
                                                                lambda node: self._ctx_of(node))
        return services

    def _ctx_of(self, node: Any) -> MissionContext:
        ctx = getattr(node, "ctx", None)
        if ctx is None:  # a composite: the context of any leaf under it
            ctx = next((n.ctx for n in node.iterate() if getattr(n, "ctx", None) is not None), None)
        if ctx is None:
            raise ValueError(f"cannot substitute '{node.name}': no mission context under it")
        return ctx

    def add(self, event: TestEvent) -> None:
        """One more event for a run under way (the harness's :meth:`~beastbt.testing.MissionHarness.inject`)."""
        if event.fault.kind == "person":
            raise ValueError("a person joins the world before the run is built: give it in events= when the "
                             "harness is made")
        self.events.append(event)


class FaultsPart(Part):
    """The part that fires a mission test's events on each tick (after sensing, before the tree)."""

    name = "mission_test"

    def __init__(self, faults: TestFaults) -> None:
        self.faults = faults
        self.run: Optional["MissionRun"] = None
        self.lidar: Any = None
        self.controls: Any = None
        self.done: set[int] = set()
        self.pending: list[_Pending] = []
        self.world: Optional["World"] = None
        self.fences: list[tuple[str, Any]] = []
        self.entered: list[str] = []
        """The watched fences the robot's true position has been inside, in the order it entered them."""
        self.places: dict[Optional[str], Optional[tuple[float, float]]] = {}
        """Where each place an event waits for is in the world (m), or None when it is not in the world."""

    def install(self, prepared: "Prepared") -> None:
        """Keep the run and its world, and the fences ``expect: never_in`` watches (the devices are found when an
        event fires; the LiDAR's emulator is given by :meth:`use_lidar`)."""
        self.run = prepared.run
        self.world = prepared.world
        self.fences = [(name, prepared.mission.fences[name]) for name in self.faults.fences
                       if name in prepared.mission.fences]

    def use_lidar(self, device: Any) -> None:
        """The LiDAR emulator whose head the ``lidar: silent`` events quiet."""
        self.lidar = device

    def tick(self, run: "MissionRun", now_s: float) -> None:
        """Fire the events whose trigger holds now (each once), and end what lasted long enough."""
        for item in [p for p in self.pending if p.at_s <= now_s + 1e-9]:
            self.pending.remove(item)
            self._console(run, item.control, now_s)
        start = run.start_s if run.start_s is not None else now_s
        for event in self.faults.events:
            if event.index in self.done or not self._due(event, run, now_s - start):
                continue
            self.done.add(event.index)
            self.fire(event, run, now_s)
        if self.fences and self.world is not None:
            truth = run.io.sim.truth
            lat, lon, _ = self.world.frame.to_geodetic(truth.x, truth.y)
            for name, fence in self.fences:
                if name not in self.entered and fence.contains(lat, lon):
                    self.entered.append(name)
                    run.events.add("test", f"the robot entered fence '{name}' (true position)")

    def _due(self, event: TestEvent, run: "MissionRun", mission_s: float) -> bool:
        trigger = event.trigger
        if trigger.at_s is not None:
            return mission_s + 1e-9 >= trigger.at_s
        if trigger.near not in self.places:  # where the place is in the world, worked out once
            self.places[trigger.near] = self._place_xy(run, trigger.near)
        place = self.places[trigger.near]
        if place is None:
            return False
        truth = run.io.sim.truth
        return math.hypot(truth.x - place[0], truth.y - place[1]) <= trigger.within_m

    def _place_xy(self, run: "MissionRun", name: Optional[str]) -> Optional[tuple[float, float]]:
        world = self.world
        if world is None:
            return None
        if name == "home":
            return world.start_x, world.start_y
        place = run.mission.places.get(name)
        if place is None or place.lat is None:
            return None  # a place on a map only: not in the world's frame
        x, y, _ = world.frame.to_enu(place.lat, place.lon, 0.0)
        return x, y

    def fire(self, event: TestEvent, run: "MissionRun", now_s: float) -> None:
        """Carry out ``event``'s fault now (clock s), and note it as an event of the run."""
        fault = event.fault
        note = self._carry_out(fault, event, run, now_s)
        start = run.start_s if run.start_s is not None else now_s
        text = f"{fault.words()} ({event.trigger.words()}, events[{event.index}])" + (f": {note}" if note else "")
        self.faults.fired.append({"index": event.index, "time_s": round(now_s - start, 3), "what": fault.words(),
                                  "trigger": event.trigger.words()})
        run.events.add("test", text)

    def _carry_out(self, fault: Fault, event: TestEvent, run: "MissionRun", now_s: float) -> Optional[str]:
        io, sim = run.io, run.io.sim
        kind, p = fault.kind, fault.params
        if kind in ("gps_lost", "gps_jump"):
            gps = getattr(io, "sim_gps", None)
            if gps is None:
                return "this robot has no GPS: nothing happens"
            if kind == "gps_lost":
                gps.model.dropouts_s.append((sim.t_s, sim.t_s + fault.for_s))
            else:
                gps.inject_jump(p["jump_m"], 0.0, sim.t_s, fault.for_s)
            return None
        if kind == "lidar_silent":
            if self.lidar is None:
                return "this robot has no LiDAR: nothing happens"
            self.lidar.silent_until_s = sim.t_s + fault.for_s
            return None
        if kind == "battery":
            esp32 = getattr(io, "esp32", None)
            if esp32 is None:
                return "this robot's base has no battery: nothing happens"
            esp32.battery_v = p["battery_v"]
            return None
        if kind == "person":
            contact = sim.drive.contact
            i = self.faults.persons.get(event.index)
            if contact is None or i is None:
                return "the world has no room for the person: nothing happens"
            contact.persons[i] = replace(contact.persons[i], start_s=sim.t_s)
            return None
        if kind == "estop":
            from beastbt.run.safety import request_estop
            request_estop(run, "operator console")  # what the console's e-stop button does
            return None
        self._console(run, kind, now_s)
        if kind == "pause":
            self.pending.append(_Pending(now_s + fault.for_s, "resume"))
        return None

    def _console(self, run: "MissionRun", control: str, now_s: float) -> None:
        """A control of the operator console (pause, resume, abort), carried out as the console carries it out."""
        if self.controls is None:
            from beastbt.live.console_control import ConsoleControls
            self.controls = ConsoleControls(run, wall=lambda: run.clock.now())
        self.controls.submit(control)
        self.controls.apply_pending(now_s)

    def summarise(self, run: "MissionRun", summary: dict) -> None:
        """The events fired and the substituted steps, for the test's expectations and for whoever reads it."""
        summary["test_events"] = list(self.faults.fired)
        summary["substituted"] = [{"step": s.step, "result": s.result, "after_s": s.after_s}
                                  for s in self.faults.substitutions]
        if self.fences:
            summary.setdefault("truth", {})["fences_entered"] = list(self.entered)


__all__ = ["TestFaults", "FaultsPart", "SubstitutedStep", "substitute_steps"]
