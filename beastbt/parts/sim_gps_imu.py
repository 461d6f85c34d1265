"""The simulated robot's GPS and IMU: emulators read by the real drivers.

When a robot profile has a ``gps:`` section, :func:`attach_gps` puts an
emulated MTK3339 (:class:`~beastbt.sim.gps_emulator.SimGps`) in the world
and reads its serial port with the real :class:`~beastbt.devices.nmea_gps.NmeaGps`
driver; the world's ``gps:`` section is its noise model and the world's datum
is where its positions are on Earth. When the profile has an ``imu:``
section, :func:`attach_imu_device` puts an emulated MPU9250 and AK8963 on an
emulated I2C bus read by the real :class:`~beastbt.devices.mpu9250.Mpu9250`
driver; the world's ``imu:`` section is its noise model and magnetic field.

The emulators and drivers are left in ``io.extras`` (``sim_gps``,
``gps_driver``, ``sim_imu``, ``imu_bus``, ``imu_driver``) so that tests can
inject faults (garbage bytes, an unplugged port, I2C errors) during a run;
``imu_tap`` (:class:`~beastbt.estimation.imu_tap.ImuTap`) hands the MPU9250's
samples to the estimator.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from beastbt.blackboard.types import GpsFix, ImuSample
from beastbt.devices.mpu9250 import ImuConfig, Mpu9250
from beastbt.devices.nmea_gps import GpsConfig, NmeaGps
from beastbt.estimation.imu_tap import ImuTap
from beastbt.core.errors import InvalidInput
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO
from beastbt.sim.gps_emulator import GpsNoiseModel, SimGps
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.imu_emulator import ImuNoiseModel, SimImu, attach_imu
from beastbt.sim.robot import Simulator, register_sim_device
from beastbt.sim.world import World

IMU_EMULATOR_RATE_HZ = 20.0
"""How often the emulated IMU takes a new sample of the true motion, Hz.

The driver reads only the newest sample, once per tick (20 Hz by default),
so sampling the truth more often than the tick rate only costs time (each
emulated sample draws noise and rewrites registers): the IMU was a sixth of
the simulator's time at 100 Hz. The sample's noise is that of the chip's
configured bandwidth whatever this rate."""


def world_model(world: World, section: str, model_cls: Any) -> Any:
    """Build ``model_cls.from_dict`` from a world section; a ValueError becomes a positioned problem."""
    raw = world.section(section) or {}
    try:
        return model_cls.from_dict(raw)
    except (TypeError, ValueError) as exc:
        if world.doc is None:
            raise InvalidInput([]) from exc
        raise InvalidInput([world.doc.problem((section,), f"in '{section}': {exc}",
                                              "see the schema in schemas/parts/ for the knobs this section takes")])


def _child_rng(sim: Simulator) -> np.random.Generator:
    """A generator of its own for one emulator, drawn from the simulator's (deterministic per seed)."""
    return np.random.default_rng(sim.rng.integers(2**63))


@register_sim_device
def attach_gps(sim: Simulator, profile: RobotProfile, io: RobotIO, events: EventLog) -> None:
    """An emulated MTK3339 on a serial port, read by the NMEA driver (``io.sensors['gps']``).

    Only when the profile has a ``gps:`` section. The fixes are in the world's
    datum frame on Earth; nothing else of the world is told to the driver.
    """
    if profile.section("gps") is None:
        return
    config: GpsConfig = section_config(profile, "gps", GpsConfig)
    model: GpsNoiseModel = world_model(sim.world, "gps", GpsNoiseModel)
    gps = SimGps(sim.world.frame, model, _child_rng(sim))
    truth = sim.truth
    sim.emulators.append(lambda now_s, dt_s: gps.update(truth))

    def reopen() -> Any:
        # The device node comes back when the receiver does: opening fails while unplugged.
        gps.port.open()
        return gps.port

    # The GPS driver's messages already start with "GPS:", so they go to the log as they are.
    driver = NmeaGps(gps.port, events.clock, events.add, open_port=reopen, config=config)
    driver.configure()

    def poll(now_s: float) -> list[GpsFix]:
        return driver.poll()

    io.sensors["gps"] = poll
    io.capabilities.add("gps")
    io.extras["sim_gps"] = gps
    io.extras["gps_driver"] = driver


@register_sim_device
def attach_imu_device(sim: Simulator, profile: RobotProfile, io: RobotIO, events: EventLog) -> None:
    """An emulated MPU9250 + AK8963 on an I2C bus, read by the MPU9250 driver (``io.sensors['imu']``).

    Only when the profile has an ``imu:`` section. The board is mounted as
    the profile says (the emulator and the driver share the mounting).
    """
    if profile.section("imu") is None:
        return
    config: ImuConfig = section_config(profile, "imu", ImuConfig)
    model: ImuNoiseModel = world_model(sim.world, "imu", ImuNoiseModel)
    bus = SimI2CBus()
    imu = attach_imu(bus, model, _child_rng(sim), address=config.address, mag_address=config.mag_address,
                     body_from_sensor=config.body_from_sensor())
    sim.emulators.append(_sampler(imu, sim))
    driver = Mpu9250(bus, events.clock, events.sink("imu"), config)
    tap = ImuTap(ready=lambda: driver.bias_ready)

    def poll(now_s: float) -> list[ImuSample]:
        return tap.record(driver.poll())

    io.sensors["imu"] = poll
    io.capabilities.add("imu")
    io.extras["sim_imu"] = imu
    io.extras["imu_bus"] = bus
    io.extras["imu_driver"] = driver
    io.extras["imu_tap"] = tap


def _sampler(imu: SimImu, sim: Simulator) -> Callable[[float, float], None]:
    """An emulator update that samples the truth every 1/IMU_EMULATOR_RATE_HZ s (time accumulated between)."""
    period = 1.0 / IMU_EMULATOR_RATE_HZ
    pending = [0.0]
    truth = sim.truth

    def update(now_s: float, dt_s: float) -> None:
        pending[0] += dt_s
        if pending[0] + 1e-9 >= period:
            imu.update(truth, pending[0])
            pending[0] = 0.0
    return update
