"""Tick-by-tick testing of missions on the simulated robot.

Build a mission from a file or a YAML string, tick it on the simulated clock,
and look at everything: each node's status, the blackboard, the commands at
every stage and the bytes that reached the emulated base::

    from beastbt.testing import MissionHarness

    h = MissionHarness.from_yaml('''
    mission: t
    steps:
      - drive: {distance: 1 m, speed: 0.2 m/s}
    ''')
    h.tick()
    assert h.status_of("drive 1 m at 0.2 m/s") == "RUNNING"
    assert h.tick_until(lambda h: h.done, timeout_s=30)
    assert h.result == "success"

Time only moves when you tick: ``tick()`` advances the simulated clock by one
tick period (1 / the mission's rate) after ticking.

Faults and forced step results are those of mission test files
(docs/testing.md), through the same code (:mod:`beastbt.testing.faults`):
``events=[{at: ...}]`` and ``substitute={...}`` when the harness is made, or
:meth:`MissionHarness.inject` now::

    h = MissionHarness.from_file("missions/gps_route.yaml", substitute={"go_to b": {"result": "failure"}})
    h.tick_until(lambda h: h.now_s >= 20)
    h.inject(gps="lost", for_s=10)
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Optional, Union

import py_trees

from beastbt.blackboard import catalogue
from beastbt.blackboard.types import VelocityCommand
from beastbt.core.clock import SimClock
from beastbt.run.runner import MissionRun, TickRecord
from beastbt.assembly import prepare
from beastbt.run.session import Prepared, RunOptions
from beastbt.run.summary import build_summary
from beastbt.testing.faults import TestFaults
from beastbt.testing.spec import faults_from


def _faults(events: Optional[list], substitute: Optional[dict]) -> TestFaults:
    """The faults of a harness run, as a test file's (every harness has them, so :meth:`MissionHarness.inject`
    works on any); InvalidInput names the entry at fault."""
    checked, subs = faults_from(events, substitute)
    return TestFaults(checked, subs)


class MissionHarness:
    """A mission prepared on the simulator and ticked by hand.

    ``records`` holds one :class:`~beastbt.run.runner.TickRecord` per tick
    (the commands at each stage, the nodes that changed, the true state).
    """

    def __init__(self, prepared: Prepared, faults: Optional[TestFaults] = None) -> None:
        self.prepared = prepared
        self.faults = faults
        """The run's mission test faults (events, substitutions): what :meth:`inject` adds to."""
        self.run: MissionRun = prepared.run
        if not isinstance(prepared.clock, SimClock):
            raise ValueError("MissionHarness needs the simulator (robot 'sim' or simulate=True)")
        self.clock: SimClock = prepared.clock
        self.dt_s = 1.0 / prepared.mission.rate_hz
        self.records: list[TickRecord] = []
        self.run.recorders.append(self.records.append)
        esp32 = self.run.io.esp32
        # The emulated base keeps only its latest commands (a long run must not grow); a test sees them all.
        self._wire: list[dict] = list(esp32.commands) if esp32 is not None else []
        if esp32 is not None:
            esp32.command_listeners.append(self._wire.append)
        self._reader = py_trees.blackboard.Client(name="harness")
        for key in catalogue.KEYS:
            catalogue.register(self._reader, key)
        if faults is not None:
            self._check_faults(faults)

    def _check_faults(self, faults: TestFaults) -> None:
        """The places the events wait for and the steps substituted must be the mission's (ValueError)."""
        places = set(self.prepared.mission.places) | {"home"}
        for event in faults.events:
            if event.trigger.near is not None and event.trigger.near not in places:
                raise ValueError(f"events[{event.index}]: the mission has no place '{event.trigger.near}'; "
                                 f"its places: {', '.join(sorted(places))}")
        names = [n.name for n in self.run.root.iterate()]
        for sub in faults.substitutions:
            if not any(n.startswith(sub.step) and "[substituted:" in n for n in names):
                raise KeyError(f"no step named {sub.step!r} to substitute; the tree has: {sorted(set(names))}")

    # -- building ---------------------------------------------------------------
    @classmethod
    def from_file(cls, path: Union[str, Path], robot: str = "sim", world: Optional[str] = None, seed: int = 0,
                  joystick: Optional[Union[str, Path, list]] = None, events: Optional[list] = None,
                  substitute: Optional[dict] = None, **options: Any) -> "MissionHarness":
        """Prepare the mission file at ``path`` on the simulator (``joystick``: a script; ``options``: RunOptions fields).

        ``events`` and ``substitute`` are written as in a test file (docs/testing.md): ``[{"at": "5 s", "gps":
        "lost"}]``, ``{"go_to b": {"result": "failure"}}``.
        """
        opts = RunOptions(robot=robot, world=world, seed=seed, record=False, simulate=True, joystick_script=joystick,
                          **options)
        faults = _faults(events, substitute)
        return cls(prepare(str(path), opts, faults=faults), faults)

    @classmethod
    def from_yaml(cls, text: str, robot: str = "sim", world: Optional[str] = None, seed: int = 0,
                  name: str = "<test mission>", base_dir: Optional[Union[str, Path]] = None,
                  joystick: Optional[Union[str, Path, list]] = None, events: Optional[list] = None,
                  substitute: Optional[dict] = None, **options: Any) -> "MissionHarness":
        """Prepare a mission written as a YAML string (relative paths resolve from ``base_dir``).

        ``joystick`` is a joystick script played on the simulator; ``events`` and ``substitute`` as in
        :meth:`from_file`; ``options`` are other RunOptions fields.
        """
        base = Path(base_dir) if base_dir is not None else Path(tempfile.gettempdir())
        opts = RunOptions(robot=robot, world=world, seed=seed, record=False, simulate=True, joystick_script=joystick,
                          **options)
        faults = _faults(events, substitute)
        return cls(prepare(str(base / "mission.yaml"), opts, mission_text=text, faults=faults), faults)

    # -- faults -----------------------------------------------------------------
    def inject(self, for_s: Optional[float] = None, **happening: Any) -> None:
        """Carry out one event of a test file now, through the same code: ``inject(gps="lost", for_s=10)``,
        ``inject(gps={"jump": "25 m"})``, ``inject(lidar="silent", for_s=2)``, ``inject(battery="20 %")``,
        ``inject(operator="pause", for_s=5)``, ``inject(estop=True)`` (``for_s`` seconds). A person joins the
        world before the run is built: give it in ``events=`` when the harness is made.
        """
        if self.faults is None:
            raise ValueError("this harness was made without mission test faults")
        raw: dict[str, Any] = {"at": f"{self.run.elapsed_s:.6f} s", **happening}
        if for_s is not None:
            raw["for"] = f"{for_s} s"
        (event,), _ = faults_from([raw], places=self.prepared.mission.places)
        event = replace(event, index=len(self.faults.events))
        self.faults.add(event)  # fired now, by the part, and never again
        self.faults.part.done.add(event.index)
        self.faults.part.fire(event, self.run, self.clock.now())

    # -- time -------------------------------------------------------------------
    @property
    def now_s(self) -> float:
        """Simulated time since the start, seconds."""
        return self.clock.now()

    def tick(self, n: int = 1) -> Optional[str]:
        """Tick ``n`` times (stopping early when the run ends); return the run's status (None while running)."""
        for _ in range(n):
            if self.run.status is not None:
                break
            self.run.tick()
            self.clock.advance(self.dt_s)
        return self.run.status

    def tick_until(self, predicate: Callable[["MissionHarness"], bool], timeout_s: float = 60.0) -> bool:
        """Tick until ``predicate(self)`` holds (True) or ``timeout_s`` of simulated time passes (False)."""
        end = self.now_s + timeout_s
        while not predicate(self):
            if self.now_s >= end or (self.run.status is not None and not predicate(self)):
                return predicate(self)
            self.tick()
        return True

    def run_to_end(self, timeout_s: float = 600.0) -> Optional[str]:
        """Tick until the run ends or ``timeout_s`` passes; return the status."""
        self.tick_until(lambda h: h.done, timeout_s)
        return self.run.status

    # -- looking ----------------------------------------------------------------
    @property
    def done(self) -> bool:
        """True once the run has ended."""
        return self.run.status is not None

    @property
    def result(self) -> Optional[str]:
        """``success``, ``failure``, ``stopped``, or None while running."""
        return self.run.status

    @property
    def root(self) -> py_trees.behaviour.Behaviour:
        """The compiled tree's root."""
        return self.run.root

    def nodes(self, name: str) -> list[py_trees.behaviour.Behaviour]:
        """Every node called ``name``."""
        return [n for n in self.run.root.iterate() if n.name == name]

    def node(self, name: str) -> py_trees.behaviour.Behaviour:
        """The node called ``name`` (the first one in tick order)."""
        found = self.nodes(name)
        if not found:
            names = sorted({n.name for n in self.run.root.iterate()})
            raise KeyError(f"no node named {name!r}; the tree has: {names}")
        return found[0]

    def status_of(self, name: str) -> str:
        """``RUNNING``, ``SUCCESS``, ``FAILURE`` or ``INVALID`` for the node called ``name``."""
        return self.node(name).status.name

    def blackboard(self, key: str, default: Any = None) -> Any:
        """The value of a catalogue key on the blackboard."""
        return catalogue.get(self._reader, key, default)

    @property
    def sent(self) -> list[VelocityCommand]:
        """The velocity sent to the base at each tick (after mux and safety gate)."""
        return [r.cmd_gate for r in self.records]

    @property
    def last_sent(self) -> VelocityCommand:
        """The velocity sent at the last tick."""
        return self.run.last_sent

    @property
    def wire(self) -> list[dict]:
        """Every JSON command the emulated Waveshare base received, in order."""
        return self._wire

    @property
    def truth(self) -> Any:
        """The simulated robot's true state."""
        return self.run.io.sim.truth

    @property
    def events(self) -> list:
        """The run's events so far."""
        return self.run.events.events

    def summary(self) -> dict:
        """The run summary as ``--summary`` would write it (wall time 0)."""
        return build_summary(self.run, self.prepared.options.seed, 0.0,
                             self.prepared.world.name if self.prepared.world else None, self.prepared.profile.name)
