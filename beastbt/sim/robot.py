"""The simulator: the world and the robot's dynamics in lockstep with the clock, and every emulator stepped with them.

:func:`build_simulator` makes the :class:`Simulator` of a robot profile in a
world, deterministic for a seed. The emulators themselves (the Waveshare
ESP32, the GPS, the IMU, the camera...) are attached by the robot's parts,
behind the same serial, I2C, CAN and frame interfaces the drivers use on the
robot.
"""

from __future__ import annotations

import time
import zlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Optional, Sequence

import numpy as np

from beastbt.core.errors import InvalidInput
from beastbt.core.schema_defaults import schema_default
from beastbt.sim.contact import ContactWorld
from beastbt.sim.cpu_account import KINDS, PHYSICS, SIM_CPU, SPLIT, kind_of
from beastbt.sim.dynamics import DiffDriveSim, DriveModel
from beastbt.sim.obstacles import OtherRobot
from beastbt.sim.truth import RobotTruth
from beastbt.sim.world import World

if TYPE_CHECKING:  # the simulator reads a profile's sections; it does not depend on the robot package
    from beastbt.robot.profile import RobotProfile

DEFAULT_PHYSICS_RATE_HZ: float = schema_default("robot.schema.json#/properties/sim", "physics_rate_hz")
"""Physics steps per simulated second unless the profile's ``sim.physics_rate_hz`` says otherwise (Hz)."""


Emulator = Callable[[float, float], None]
"""An emulator's update, called as ``update(now_s, dt_s)`` after every physics step (s)."""


@dataclass
class Simulator:
    """The simulated world in lockstep with the clock: physics at a fixed rate, then every emulator."""

    world: World
    truth: RobotTruth
    drive: DiffDriveSim
    rng: np.random.Generator
    physics_dt_s: float = 0.01
    emulators: list[Emulator] = field(default_factory=list)
    """Each called as ``update(now_s, dt_s)`` after every physics step."""
    t_s: float = 0.0
    others: Optional[Callable[[], Sequence[OtherRobot]]] = None
    """Where the other robots of a shared world are now (the fleet's hand-over), asked once per :meth:`advance`;
    None: this robot is alone in its world."""
    _plan: Optional[list[tuple[Emulator, int]]] = field(default=None, repr=False, compare=False)
    """The emulators with the kind their CPU time is charged to (made again when :attr:`emulators` changes)."""

    def advance(self, now_s: float) -> None:
        """Step physics and emulators until the simulated time reaches ``now_s``.

        The other robots (:attr:`others`) are placed first and stand there for the whole advance (between two
        ticks), so the steps depend only on the poses handed over. When the simulator's CPU is accounted
        (:mod:`beastbt.sim.cpu_account`), the thread's CPU time is charged to the physics and to each emulator's
        kind (the watchdog's is the robot's); nothing else changes.
        """
        if self.others is not None and self.drive.contact is not None:
            self.drive.contact.set_others(self.others())
        if SIM_CPU.enabled:
            self._advance_accounted(now_s)
            return
        while self.t_s + 1e-9 < now_s:
            dt = min(self.physics_dt_s, now_s - self.t_s)
            self.drive.step(dt)
            self.t_s += dt
            for update in self.emulators:
                update(self.t_s, dt)

    def _advance_accounted(self, now_s: float) -> None:
        """:meth:`advance`'s steps, each piece's wall time noted to split the advance's CPU time by kind."""
        plan = self._plan
        if plan is None or len(plan) != len(self.emulators) or any(p[0] is not u for p, u in zip(plan, self.emulators)):
            plan = self._plan = [(u, kind_of(u)) for u in self.emulators]
        weights = [0.0] * len(KINDS)
        wall = time.perf_counter  # for the split only: the CPU clock, read at both ends, gives the total
        outer = SIM_CPU.enter(SPLIT)
        try:
            t = wall()
            while self.t_s + 1e-9 < now_s:
                dt = min(self.physics_dt_s, now_s - self.t_s)
                self.drive.step(dt)
                self.t_s += dt
                t1 = wall()
                weights[PHYSICS] += t1 - t
                t = t1
                for update, kind in plan:
                    update(self.t_s, dt)
                    t1 = wall()
                    weights[kind] += t1 - t
                    t = t1
        finally:
            SIM_CPU.leave_split(outer, weights)

    def child_rng(self) -> np.random.Generator:
        """A generator of its own for one emulator, drawn from the simulator's (deterministic per seed and order)."""
        return np.random.default_rng(self.rng.integers(2**63))

    def stream_rng(self, name: str) -> np.random.Generator:
        """A generator of its own for ``name``, derived from the seed without drawing from the simulator's.

        For an emulator added after the others were in place (the LiDAR): the
        others' draws do not shift when it is fitted, and its own depend only on the seed and ``name``.
        """
        key = zlib.crc32(name.encode("utf-8"))
        entropy = self.rng.bit_generator.seed_seq.entropy  # type: ignore[attr-defined]
        return np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(key,)))

    def world_model(self, section: str, model_cls: Any) -> Any:
        """``model_cls.from_dict`` of the world's ``section``; a bad value is a positioned InvalidInput."""
        raw = self.world.section(section) or {}
        try:
            return model_cls.from_dict(raw)
        except (TypeError, ValueError) as exc:
            raise world_problem(self.world, section, exc) from exc


def world_problem(world: World, section: str, exc: Exception) -> InvalidInput:
    """The InvalidInput for a bad ``section`` of a world file, at that section's line."""
    if world.doc is None:
        return InvalidInput([])
    return InvalidInput([world.doc.problem((section,), f"in '{section}': {exc}",
                                           "see the schema in schemas/parts/ for the knobs this section takes")])


def build_simulator(profile: "RobotProfile", world: World, seed: int, shared: bool = False) -> Simulator:
    """The simulated robot of ``profile`` in ``world`` (dynamics only, no emulators yet), deterministic for ``seed``.

    ``shared``: other robots may join the world (a fleet's), so the robot has a contact world even when its own
    world has nothing to touch (the LiDAR and the contact then see the others once :attr:`Simulator.others` is set).
    """
    SIM_CPU.open_from_environment()  # a benchmark that asked for the simulator's CPU apart gets it
    rng = np.random.default_rng(seed)
    sim_cfg = dict(profile.section("sim") or {})
    physics_hz = float(sim_cfg.pop("physics_rate_hz", DEFAULT_PHYSICS_RATE_HZ))
    sim_cfg.setdefault("track_width_m", profile.track_width_m)
    geometry = profile.section("geometry") or {}
    if "footprint_radius_m" in geometry:
        sim_cfg.setdefault("footprint_radius_m", geometry["footprint_radius_m"])
    model = DriveModel.from_dict(sim_cfg)
    truth = RobotTruth(x=world.start_x, y=world.start_y, yaw=world.start_yaw, battery_v=world.battery_start_v)
    contact = (ContactWorld(world.walls, world.obstacles, model.footprint_radius_m)
               if world.walls or world.obstacles or shared else None)
    drive = DiffDriveSim(model, truth, np.random.default_rng(rng.integers(2**63)), walls=list(world.walls),
                         contact=contact)
    return Simulator(world, truth, drive, rng, physics_dt_s=1.0 / physics_hz)


__all__ = ["Simulator", "Emulator", "build_simulator", "world_problem", "DEFAULT_PHYSICS_RATE_HZ"]
