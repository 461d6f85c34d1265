"""The part protocol: what one piece of a robot (a device, an estimator, a feature) tells the assembly.

A robot is assembled from an explicit list of parts (the composition root,
:mod:`beastbt.assembly`). Each part says what it is (``name``), which section
of the robot profile configures it (``section``, with its schema in
``schemas/parts/``), what it opens (``opens``), which readings and blackboard
keys it fills (``fills``) and uses (``reads``), which commands it takes (``takes``), and which
mission steps it adds (:meth:`Part.steps`). The assembly then calls, in this
order and for every part:

1. :meth:`Part.attach` once the base is open: open the part's devices on the
   robot, or their emulators on the simulator (``build.mode``). In a replay
   nothing is opened: recorded readings stand in for every device.
2. :meth:`Part.estimator` until one part gives an estimator (the EKF).
3. :meth:`Part.sleep` for a part that can sleep and fills nothing the run
   reads (:func:`asleep`): the GPS, the IMU and the EKF of a mission that
   never looks at the fused pose cost nothing per tick. A recording wakes
   none of them (it holds what the run used) unless ``--record-sensors``.
4. :meth:`Part.install` once the run (tree, mux, gate, watchdog) exists:
   services for behaviours, recorders (``run.recorders``), summary fields
   (``run.summary_contributors``).
5. :meth:`Part.tick` every tick, after sensing and before the tree, but only
   for a part whose class overrides it (a part without per-tick work costs
   nothing per tick).
6. :meth:`Part.close` once the run has ended (whatever ended it), for a part
   that overrides it; devices are released by ``RobotIO.close``.
7. :meth:`Part.summarise` when the summary is built, for a part that
   overrides it.

A part that the profile and the mission do not use is not even imported
(the composition root decides from the profile and the run options). Base parts (:class:`BasePart`) open the
drive base named by the profile's ``base.type``.

Safety is not a part: the mux, the gate, the e-stop latch and the command
watchdog are wired by the run itself around whatever base a part opened.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Iterable, Mapping, Optional, Sequence

from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile

if TYPE_CHECKING:  # only for annotations: the run, the robot's ports and the simulator are built elsewhere
    from beastbt.robot.robot_io import RobotIO
    from beastbt.estimation.estimator import Estimator
    from beastbt.mission.compile import StepBuilder
    from beastbt.run.runner import MissionRun
    from beastbt.run.session import Prepared
    from beastbt.sim.robot import Simulator

REAL = "real"
"""Build mode: devices on the robot's ports."""
SIM = "sim"
"""Build mode: emulators behind the same ports, in lockstep with a simulated world."""
REPLAY = "replay"
"""Build mode: a recording's readings in place of every device."""


@dataclass
class Build:
    """What a part attaches to while a robot is assembled.

    ``mode`` is :data:`REAL`, :data:`SIM` or :data:`REPLAY`; ``sim`` is the
    simulator in :data:`SIM` mode (None otherwise); ``io`` holds the ports
    opened so far (the base first).
    """

    mode: str
    profile: RobotProfile
    clock: Clock
    events: EventLog
    io: Optional[RobotIO] = None
    sim: Optional["Simulator"] = None

    @property
    def simulated(self) -> bool:
        """True on the simulator."""
        return self.mode == SIM

    @property
    def real(self) -> bool:
        """True on the robot's own ports."""
        return self.mode == REAL


class Part:
    """One piece of a robot. Subclasses override what they need; every hook does nothing by default."""

    name: ClassVar[str] = "part"
    """A short name: ``gps``, ``teleop``, ``navigation``."""
    section: ClassVar[Optional[str]] = None
    """The robot profile section that configures it (``gps:``), or None."""
    schema: ClassVar[Optional[str]] = None
    """Its section's schema, relative to ``schemas/`` (``parts/gps.schema.json``), or None."""
    opens: ClassVar[str] = ""
    """The ports it opens, in words (``serial port (NMEA)``, ``I2C bus``)."""
    fills: ClassVar[tuple[str, ...]] = ()
    """Blackboard keys (and readings) it fills."""
    takes: ClassVar[tuple[str, ...]] = ()
    """Commands it takes (``velocity``, ``servo``)."""
    reads: ClassVar[tuple[str, ...]] = ()
    """Blackboard keys (and readings) it uses: the parts that fill them stay awake while this one is in the run."""

    def steps(self) -> Mapping[str, "StepBuilder"]:
        """The mission steps it adds: keyword -> builder ``fn(compiler, step) -> Behaviour``."""
        return {}

    def attach(self, build: Build) -> None:
        """Open its devices (robot) or their emulators (simulator) into ``build.io``; nothing in a replay."""

    def estimator(self, build: Build) -> Optional["Estimator"]:
        """An estimator for this robot (the first part to give one wins), or None."""
        return None

    def sleep(self, prepared: "Prepared") -> None:
        """Nothing in the run reads what this part fills: drop its per-tick work (polling, emulation, fusion).

        Called once, before :meth:`install`, and only for a part whose class
        overrides it (a part that does not is always awake): see
        :func:`asleep`. Like a lazy ROS publisher, a sensor nobody listens
        to is neither read nor emulated.
        """

    def install(self, prepared: "Prepared") -> None:
        """Hook into the assembled run: services, ``run.recorders``, ``run.summary_contributors``."""

    def tick(self, run: "MissionRun", now_s: float) -> None:
        """Per-tick work after sensing, before the tree (``now_s`` clock seconds). Only called when overridden."""

    def close(self) -> None:
        """Release what :meth:`install` started, once the run has ended. Only called when overridden."""

    def summarise(self, run: "MissionRun", summary: dict) -> None:
        """Add this part's fields to the run summary. Only called when overridden."""

    def settings(self, profile: RobotProfile) -> dict[str, Any]:
        """A part of another package's settings: the mapping under its name in the profile's ``parts:``."""
        return dict((profile.section("parts") or {}).get(self.name) or {})

    def overrides(self, hook: str) -> bool:
        """True when this part's class overrides ``hook`` (``tick``, ``close``, ``summarise``, ``sleep``) of :class:`Part`."""
        return getattr(type(self), hook) is not getattr(Part, hook)


class BasePart(Part):
    """A drive base: it opens the robot's :class:`RobotIO` for ``base.type`` in ``base_types``."""

    base_types: ClassVar[tuple[str, ...]] = ()
    """The profile ``base.type`` values this part opens."""
    takes = ("velocity",)

    def open_real(self, build: Build) -> RobotIO:
        """Open the base on the robot's ports; raise DeviceUnavailable before anything moves."""
        raise NotImplementedError

    def open_sim(self, build: Build) -> RobotIO:
        """The base's emulator driving ``build.sim``, behind the same driver."""
        raise NotImplementedError


class RefusalCheck(Part):
    """A part that may refuse a run before anything moves (``check`` raises InvalidInput); never in a replay, which
    carries out what was recorded."""

    mode = ""

    def attach(self, build: Build) -> None:
        """Note the build's mode."""
        self.mode = build.mode

    def install(self, prepared: "Prepared") -> None:
        """:meth:`check` the prepared run, unless this is a replay."""
        if self.mode != REPLAY:
            self.check(prepared)

    def check(self, prepared: "Prepared") -> None:
        """Raise InvalidInput, positioned in the mission or profile, when the run must not start."""
        raise NotImplementedError


PartFactory = Callable[[], Part]
"""What an entry point of group ``beastbt.parts`` names: a Part subclass or a function returning a part."""


def describe(part: Part) -> dict[str, Any]:
    """A part as a plain dict (for the docs and tools): name, section, schema, opens, fills, takes, steps, per-tick."""
    return {"name": part.name, "section": part.section, "schema": part.schema, "opens": part.opens,
            "fills": list(part.fills), "takes": list(part.takes), "steps": sorted(part.steps()),
            "reads": list(part.reads), "per_tick": part.overrides("tick"), "can_sleep": part.overrides("sleep")}


def sleep_device(prepared: "Prepared", sensor: str, emulator: Optional[Callable[[float, float], None]]) -> None:
    """Put a device part to sleep: stop polling ``io.sensors[sensor]`` and drop its emulator from the simulator."""
    io = prepared.run.io
    io.sensors.pop(sensor, None)
    sim = io.sim
    if emulator is not None and sim is not None and emulator in sim.emulators:
        sim.emulators.remove(emulator)


def asleep(parts: "Sequence[Part]", demand: "Iterable[str]") -> list[Part]:
    """The parts that may sleep (they override :meth:`Part.sleep`) and fill nothing that is read.

    ``demand`` is what the run itself reads (its tree, conditions, failsafes).
    A part that is awake (one that cannot sleep, or one whose ``fills`` meet
    the demand) adds its ``reads`` to the demand, so a sensor feeding an
    awake estimator stays awake; this repeats until nothing changes.
    """
    wanted = set(demand)
    awake = [p for p in parts if not p.overrides("sleep")]
    for part in awake:
        wanted.update(part.reads)
    sleepy = [p for p in parts if p.overrides("sleep")]
    changed = True
    while changed:
        changed = False
        for part in list(sleepy):
            if wanted.intersection(part.fills):
                sleepy.remove(part)
                wanted.update(part.reads)
                changed = True
    return sleepy


__all__ = ["Part", "BasePart", "RefusalCheck", "Build", "PartFactory", "REAL", "SIM", "REPLAY", "describe", "asleep", "sleep_device"]
