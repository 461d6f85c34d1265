"""The part protocol: what one piece of a robot (a device, an estimator, a feature) tells the assembly.

A robot is assembled from an explicit list of parts (the composition root,
:mod:`beastbt.assembly`). Each part says what it is (``name``), which section
of the robot profile configures it (``section``, with its schema in
``schemas/parts/``), what it opens (``opens``), which readings and blackboard
keys it fills (``fills``), which commands it takes (``takes``), and which
mission steps it adds (:meth:`Part.steps`). The assembly then calls, in this
order and for every part:

1. :meth:`Part.attach` once the base is open: open the part's devices on the
   robot, or their emulators on the simulator (``build.mode``). In a replay
   nothing is opened: recorded readings stand in for every device.
2. :meth:`Part.estimator` until one part gives an estimator (the EKF).
3. :meth:`Part.install` once the run (tree, mux, gate, watchdog) exists:
   services for behaviours, recorders (``run.recorders``), summary fields
   (``run.summary_contributors``).
4. :meth:`Part.tick` every tick, after sensing and before the tree, but only
   for a part whose class overrides it (a part without per-tick work costs
   nothing per tick).
5. :meth:`Part.close` once the run has ended (whatever ended it), for a part
   that overrides it; devices are released by ``RobotIO.close``.
6. :meth:`Part.summarise` when the summary is built, for a part that
   overrides it.

A part that the profile and the mission do not use is not even imported
(the composition root decides from the profile and the run options). Base parts (:class:`BasePart`) open the
drive base named by the profile's ``base.type``.

Safety is not a part: the mux, the gate, the e-stop latch and the command
watchdog are wired by the run itself around whatever base a part opened.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Mapping, Optional

from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO

if TYPE_CHECKING:  # only for annotations: the run and the simulator are built elsewhere
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

    def steps(self) -> Mapping[str, "StepBuilder"]:
        """The mission steps it adds: keyword -> builder ``fn(compiler, step) -> Behaviour``."""
        return {}

    def attach(self, build: Build) -> None:
        """Open its devices (robot) or their emulators (simulator) into ``build.io``; nothing in a replay."""

    def estimator(self, build: Build) -> Optional["Estimator"]:
        """An estimator for this robot (the first part to give one wins), or None."""
        return None

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
        """True when this part's class overrides ``hook`` (``tick``, ``close``, ``summarise``) of :class:`Part`."""
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


PartFactory = Callable[[], Part]
"""What an entry point of group ``beastbt.parts`` names: a Part subclass or a function returning a part."""


def describe(part: Part) -> dict[str, Any]:
    """A part as a plain dict (for the docs and tools): name, section, schema, opens, fills, takes, steps, per-tick."""
    return {"name": part.name, "section": part.section, "schema": part.schema, "opens": part.opens,
            "fills": list(part.fills), "takes": list(part.takes), "steps": sorted(part.steps()),
            "per_tick": part.overrides("tick")}


__all__ = ["Part", "BasePart", "Build", "PartFactory", "REAL", "SIM", "REPLAY", "describe"]
