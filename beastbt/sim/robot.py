"""Assemble a simulated robot: the world, the dynamics, and an emulator behind every device.

The drivers that run on the robot are the ones used here: the Waveshare base
adapter talks serial JSON to :class:`SimWaveshareBase`, and so on. Parts of
beastbt that add devices (GPS, IMU, camera, joystick) register an attach
function with :func:`register_sim_device`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from beastbt.devices.waveshare_base import WaveshareBase, WaveshareConfig
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.dynamics import DiffDriveSim, DriveModel
from beastbt.sim.truth import RobotTruth
from beastbt.sim.waveshare_emulator import SimWaveshareBase
from beastbt.sim.world import World


@dataclass
class Simulator:
    """The simulated world in lockstep with the clock: physics at a fixed rate, then every emulator."""

    world: World
    truth: RobotTruth
    drive: DiffDriveSim
    rng: np.random.Generator
    physics_dt_s: float = 0.01
    emulators: list[Callable[[float, float], None]] = field(default_factory=list)
    """Each called as ``update(now_s, dt_s)`` after every physics step."""
    t_s: float = 0.0

    def advance(self, now_s: float) -> None:
        """Step physics and emulators until the simulated time reaches ``now_s``."""
        while self.t_s + 1e-9 < now_s:
            dt = min(self.physics_dt_s, now_s - self.t_s)
            self.drive.step(dt)
            self.t_s += dt
            for update in self.emulators:
                update(self.t_s, dt)


SimAttach = Callable[[Simulator, RobotProfile, RobotIO, EventLog], None]
SIM_DEVICES: list[SimAttach] = []


def register_sim_device(fn: SimAttach) -> SimAttach:
    """Decorator: ``fn(sim, profile, io, events)`` adds an emulated device and its driver to a sim robot."""
    SIM_DEVICES.append(fn)
    return fn


SimBase = Callable[[Simulator, RobotProfile, EventLog], RobotIO]
SIM_BASES: dict[str, SimBase] = {}
"""Base types (``can``, ``pwm``) whose own emulator drives the simulated robot: type -> fn(sim, profile, events) -> RobotIO."""


def build_sim_robot(profile: RobotProfile, world: World, seed: int, events: EventLog) -> RobotIO:
    """A simulated robot for ``profile`` in ``world``, deterministic for ``seed``."""
    rng = np.random.default_rng(seed)
    sim_cfg = dict(profile.section("sim") or {})
    physics_hz = float(sim_cfg.pop("physics_rate_hz", 100.0))
    sim_cfg.setdefault("track_width_m", profile.track_width_m)
    geometry = profile.section("geometry") or {}
    if "footprint_radius_m" in geometry:
        sim_cfg.setdefault("footprint_radius_m", geometry["footprint_radius_m"])
    model = DriveModel.from_dict(sim_cfg)
    truth = RobotTruth(x=world.start_x, y=world.start_y, yaw=world.start_yaw, battery_v=world.battery_start_v)
    drive = DiffDriveSim(model, truth, np.random.default_rng(rng.integers(2**63)), walls=list(world.walls))
    sim = Simulator(world, truth, drive, rng, physics_dt_s=1.0 / physics_hz)

    base_cfg = profile.section("base") or {}
    supply = SIM_BASES.get(str(base_cfg.get("type")))
    if supply is not None:
        io = supply(sim, profile, events)
        for attach in SIM_DEVICES:
            attach(sim, profile, io, events)
        return io
    if base_cfg.get("type") != "waveshare_serial":
        # Other bases (CAN, PWM) are emulated by their own parts; until then the
        # sim drives them through the Waveshare emulator with the same geometry.
        base_cfg = {"type": "waveshare_serial"}
    base_cfg = {k: v for k, v in base_cfg.items() if k != "port"}
    config = WaveshareConfig.from_dict(base_cfg)
    esp32 = SimWaveshareBase(drive, np.random.default_rng(rng.integers(2**63)), battery_v=world.battery_start_v,
                             battery_drain_v_per_s=world.battery_drain_v_per_s)
    sim.emulators.append(esp32.update)
    base = WaveshareBase(esp32.port, config, events.sink("base"))
    io = RobotIO(base=base, servos=[base] if config.gimbal else [], sim=sim)
    io.extras["esp32"] = esp32
    for attach in SIM_DEVICES:
        attach(sim, profile, io, events)
    return io

