"""The 2D LiDAR (the profile's ``lidar:``): an LDRobot LD19 / D500 or a Slamtec RPLIDAR A1 on a serial port.

On the robot the port is opened with pyserial; a port that does not exist at
start stops the run before anything moves with a
:class:`~beastbt.robot.hardware.DeviceUnavailable` saying what to check.
Faults once running (unplugged, garbage, a motor that stalls, silence) are
the driver's business: counted, reported as events, the scan goes stale, the
port is reopened. Each revolution is one :class:`~beastbt.devices.lidar_scan.LaserScan`
reading from ``io.sensors['lidar']``; nothing on the blackboard reads it yet.

The simulator has no LiDAR emulator yet: a profile with ``lidar:`` runs on
``--sim`` without it, and an event says so once.
"""

from __future__ import annotations

from typing import Any, Optional

from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.devices.lidar_scan import LaserScan, LidarConfig, SerialLidar
from beastbt.robot.hardware import open_serial
from beastbt.robot.part import REAL, SIM, Build, Part
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO

LIDAR_HINT = ("check the LiDAR's USB cable and power (ls /dev/ttyUSB* /dev/serial/by-id/), that lidar.port names it, "
              "and that your user is in the 'dialout' group; beastbt doctor checks it")
NOT_SIMULATED = ("LiDAR: the simulator has no LiDAR emulator yet: the profile's lidar ({type}) is left out of "
                 "this run (no scans)")
NOT_SIMULATED_WARNING = "lidar: the simulator has no LiDAR emulator yet: this run has no scans"
"""The run warning for a profile with ``lidar:`` on ``--sim`` (printed before the run starts)."""
NOT_SIMULATED_HINT = "the LiDAR is used on the robot; on the simulator it is left out (an emulator is to come)"


def lidar_driver(config: LidarConfig, port: Any, clock: Clock, events: EventLog,
                 reopen: Optional[Any] = None) -> SerialLidar:
    """The driver for ``config.type`` on ``port`` (``reopen()`` gives a fresh port after a failure)."""
    if config.type == "rplidar_a1":
        from beastbt.devices.rplidar import RplidarA1
        return RplidarA1(port, clock, events.add, open_port=reopen, config=config)
    from beastbt.devices.ld19 import Ld19Lidar
    return Ld19Lidar(port, clock, events.add, open_port=reopen, config=config)


def attach_real_lidar(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> Optional[SerialLidar]:
    """Open the profile's LiDAR (``io.sensors['lidar']``), or raise :class:`DeviceUnavailable`; the driver."""
    if profile.section("lidar") is None:
        return None
    import serial

    config: LidarConfig = section_config(profile, "lidar", LidarConfig)
    name = f"lidar ({config.model['name']})"
    port = open_serial(name, config.port, config.port_baud, LIDAR_HINT)

    def reopen() -> Any:
        # The driver retries every reopen_interval_s; a SerialException here just means "not yet".
        return serial.Serial(config.port, config.port_baud, timeout=0, write_timeout=0.05)

    driver = lidar_driver(config, port, clock, events, reopen)

    def poll(now_s: float) -> list[LaserScan]:
        return driver.poll()

    io.sensors["lidar"] = poll
    io.capabilities.add("lidar")
    io.closers.append(driver.close)
    return driver


class LidarPart(Part):
    """``lidar:``: one ``LaserScan`` per revolution of the LD19 or RPLIDAR A1 (``io.sensors['lidar']``)."""

    name = "lidar"
    section = "lidar"
    schema = "parts/lidar.schema.json"
    opens = "serial port (LD19 / RPLIDAR A1)"
    driver: Optional[SerialLidar] = None
    """The driver on the robot (None on the simulator and in a replay)."""

    def attach(self, build: Build) -> None:
        """Open the LiDAR on the robot; on the simulator say once that it is not simulated yet."""
        assert build.io is not None
        if build.mode == REAL:
            self.driver = attach_real_lidar(build.profile, build.io, build.clock, build.events)
        elif build.mode == SIM and build.profile.section("lidar") is not None:
            config: LidarConfig = section_config(build.profile, "lidar", LidarConfig)
            build.events.add("lidar_not_simulated", NOT_SIMULATED.format(type=config.type))


__all__ = ["LidarPart", "attach_real_lidar", "lidar_driver", "LIDAR_HINT", "NOT_SIMULATED_WARNING"]
