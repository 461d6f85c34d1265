"""The real GPS and IMU, opened from a robot profile's ``gps:`` and ``imu:`` sections.

Two :data:`~beastbt.robot.hardware.HARDWARE_DEVICES`: the NMEA GPS on its
serial port (pyserial) and the MPU9250 on its I2C bus (smbus2), read by the
same drivers the simulator's emulators feed. A port or bus that does not
exist at start stops the run before anything moves, with a
:class:`~beastbt.robot.hardware.DeviceUnavailable` saying what to check.
Faults once running (a receiver unplugged, garbage on the line, a chip that
stops answering) are the drivers' business: reported as events, the data
goes stale, the port is reopened and the chip re-initialised.
"""

from __future__ import annotations

from typing import Any

from beastbt.blackboard.types import GpsFix, ImuSample
from beastbt.devices.mpu9250 import ImuConfig, Mpu9250
from beastbt.devices.nmea_gps import GpsConfig, NmeaGps
from beastbt.estimation.imu_tap import ImuTap
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.robot.hardware import HARDWARE_DEVICES, DeviceUnavailable, open_serial
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO

GPS_HINT = ("check the GPS HAT is seated, that the serial port is enabled (raspi-config: serial hardware on, "
            "login shell off) and that your user is in the 'dialout' group")


def attach_real_gps(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """Open the profile's NMEA GPS (``io.sensors['gps']``), or raise :class:`DeviceUnavailable`."""
    if profile.section("gps") is None:
        return
    import serial

    config: GpsConfig = section_config(profile, "gps", GpsConfig)
    port = open_serial("gps (NMEA receiver)", config.port, config.port_baud, GPS_HINT)
    ports = [port]

    def reopen() -> Any:
        # The driver retries every reopen_interval_s; a SerialException here just means "not yet".
        # Reopened at the start-up baud rate: the driver sends its PMTK configuration (and a
        # PMTK251 baud change) again on every reopen, as it did at start.
        p = serial.Serial(config.port, config.port_baud, timeout=0, write_timeout=0.05)
        ports.append(p)
        return p

    driver = NmeaGps(port, clock, events.add, open_port=reopen, config=config)
    driver.configure()

    def poll(now_s: float) -> list[GpsFix]:
        return driver.poll()

    def close() -> None:
        try:
            ports[-1].close()
        except Exception:  # noqa: BLE001 - closing a vanished device may fail; it is gone anyway
            pass

    io.sensors["gps"] = poll
    io.capabilities.add("gps")
    io.closers.append(close)
    io.extras["gps_driver"] = driver


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
        raise DeviceUnavailable(f"imu (MPU9250): cannot open /dev/i2c-{config.bus} ({exc}); enable I2C "
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
    io.extras["imu_driver"] = driver
    io.extras["imu_tap"] = tap


HARDWARE_DEVICES.append(attach_real_gps)
HARDWARE_DEVICES.append(attach_real_imu)
