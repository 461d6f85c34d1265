"""The IMU (the profile's ``imu:``): an MPU9250 + AK8963 on I2C, on the robot or emulated.

On the robot smbus2 opens ``/dev/i2c-N``; a bus that does not exist stops
the run before anything moves. A chip that does not answer on an existing bus
is not fatal: the driver reports it (``imu_missing``, ``imu_wrong_id``) and
keeps trying. On the simulator an emulated chip sits on an emulated I2C bus
behind the same driver, mounted as the profile says. The driver's samples go
through an :class:`~beastbt.estimation.imu_tap.ImuTap` for the EKF.
"""

from __future__ import annotations

from typing import Callable, Optional

from beastbt.blackboard.types import ImuSample, WheelOdometry
from beastbt.core.clock import Clock
from beastbt.core.errors import plain_reason
from beastbt.core.events import EventLog
from beastbt.devices.mpu9250 import ImuConfig, Mpu9250
from beastbt.estimation.imu_tap import ImuTap
from beastbt.robot.hardware import DeviceUnavailable
from beastbt.robot.part import REAL, SIM, Build, Part, sleep_device
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO
from beastbt.run.session import Prepared
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.imu_emulator import ImuNoiseModel, SimImu, attach_imu
from beastbt.sim.robot import Emulator, Simulator


IMU_EMULATOR_RATE_HZ = 20.0
"""How often the emulated IMU takes a new sample of the true motion, Hz.

The driver reads only the newest sample, once per tick (20 Hz by default),
so sampling the truth more often than the tick rate only costs time (each
emulated sample draws noise and rewrites registers): the IMU was a sixth of
the simulator's time at 100 Hz. The sample's noise is that of the chip's
configured bandwidth whatever this rate."""


def attach_real_imu(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """Open the I2C bus of the profile's MPU9250 (``io.sensors['imu']``), or raise :class:`DeviceUnavailable`.

    A chip that does not answer on an existing bus is not fatal: the driver
    reports it (``imu_missing``, ``imu_wrong_id``) and keeps trying.
    """
    if profile.section("imu") is None:
        return
    import smbus2

    config: ImuConfig = section_config(profile, "imu", ImuConfig)
    try:
        bus = smbus2.SMBus(config.bus)
    except (OSError, ValueError) as exc:
        raise DeviceUnavailable(f"imu (MPU9250): cannot open /dev/i2c-{config.bus} ({plain_reason(exc)}); enable I2C "
                                f"(raspi-config: interface options, I2C) and check that your user is in the 'i2c' "
                                f"group") from exc
    driver = Mpu9250(bus, clock, events.sink("imu"), config)
    driver.start()
    tap = ImuTap(ready=lambda: driver.bias_ready)

    def poll(now_s: float) -> list[ImuSample]:
        return tap.record(driver.poll())

    io.sensors["imu"] = poll
    io.capabilities.add("imu")
    io.closers.append(bus.close)
    io.imu_driver = driver
    io.imu_tap = tap


def attach_sim_imu(sim: Simulator, profile: RobotProfile, io: RobotIO, events: EventLog) -> Optional[Emulator]:
    """An emulated MPU9250 + AK8963 on an I2C bus, read by the MPU9250 driver (``io.sensors['imu']``).

    Only when the profile has an ``imu:`` section. The board is mounted as
    the profile says (the emulator and the driver share the mounting).
    Returns the emulator's update (one of ``sim.emulators``), or None.
    """
    if profile.section("imu") is None:
        return None
    config: ImuConfig = section_config(profile, "imu", ImuConfig)
    model: ImuNoiseModel = sim.world_model("imu", ImuNoiseModel)
    bus = SimI2CBus()
    imu = attach_imu(bus, model, sim.child_rng(), address=config.address, mag_address=config.mag_address,
                     body_from_sensor=config.body_from_sensor())
    emulate = _sampler(imu, sim)
    sim.emulators.append(emulate)
    driver = Mpu9250(bus, events.clock, events.sink("imu"), config)
    tap = ImuTap(ready=lambda: driver.bias_ready)

    def poll(now_s: float) -> list[ImuSample]:
        return tap.record(driver.poll())

    io.sensors["imu"] = poll
    io.capabilities.add("imu")
    io.sim_imu = imu
    io.imu_bus = bus
    io.imu_driver = driver
    io.imu_tap = tap
    return emulate


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


WHEELS_STILL_MPS = 0.005
"""Both wheels slower than this (m/s) is standing still for the gyro bias window (encoder noise is below it)."""


def wheels_still(odometry: Optional[WheelOdometry]) -> Optional[bool]:
    """True when both wheels stand still, False when either turns, None without wheel odometry."""
    if odometry is None:
        return None
    return abs(odometry.left_mps) < WHEELS_STILL_MPS and abs(odometry.right_mps) < WHEELS_STILL_MPS


class ImuPart(Part):
    """``imu:``: gyro, accelerometer and magnetometer samples (``io.sensors['imu']``)."""

    name = "imu"
    section = "imu"
    schema = "parts/imu_device.schema.json"
    opens = "I2C bus (MPU9250 + AK8963)"
    fills = ("imu",)
    emulator: Optional[Emulator] = None
    """The emulator's update on the simulator (removed when the part sleeps)."""

    def attach(self, build: Build) -> None:
        """Open the chip's bus (robot) or the emulated chip (simulator) when the profile has ``imu:``."""
        assert build.io is not None
        if build.mode == REAL:
            attach_real_imu(build.profile, build.io, build.clock, build.events)
        elif build.mode == SIM:
            assert build.sim is not None
            self.emulator = attach_sim_imu(build.sim, build.profile, build.io, build.events)

    def install(self, prepared: Prepared) -> None:
        """Tell the driver when the wheels turn (the blackboard's ``odometry``), so that its gyro bias window never
        averages a slow steady turn."""
        driver = prepared.run.io.imu_driver
        if driver is not None:
            bb = prepared.run.bb

            def standstill() -> Optional[bool]:
                try:
                    odometry = bb.odometry
                except (KeyError, AttributeError):  # no wheel reading yet (py_trees raises KeyError)
                    return None
                return wheels_still(odometry)
            driver.standstill = standstill

    def sleep(self, prepared: Prepared) -> None:
        """Nothing reads the samples: neither poll the driver nor emulate the chip."""
        sleep_device(prepared, "imu", self.emulator)


__all__ = ["ImuPart", "wheels_still", "attach_real_imu", "attach_sim_imu", "IMU_EMULATOR_RATE_HZ"]
