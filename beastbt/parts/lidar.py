"""The 2D LiDAR (the profile's ``lidar:``): an LDRobot LD19 / D500 or a Slamtec RPLIDAR A1 on a serial port.

On the robot the port is opened with pyserial; a port that does not exist at
start stops the run before anything moves with a
:class:`~beastbt.robot.hardware.DeviceUnavailable` saying what to check.
Faults once running (unplugged, garbage, a motor that stalls, silence) are
the driver's business: counted, reported as events, the scan goes stale, the
port is reopened. Each revolution is one :class:`~beastbt.devices.lidar_scan.LaserScan`
reading from ``io.sensors['lidar']``; the run keeps the latest as the
blackboard key ``scan`` (and ``run.latest[LaserScan]``).

On the simulator an emulated LD19 or RPLIDAR A1 (:mod:`beastbt.sim.lidar_emulator`)
ray-casts the world and writes the model's bytes into an emulated serial port
read by the same driver: the same ``io.sensors['lidar']`` poll as on the robot.

Nothing reads the scan unless the run does (a step, a condition, the
collision monitor, a recording): otherwise the part sleeps, neither polling
the driver nor emulating the LiDAR (:meth:`LidarPart.sleep`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Optional

from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.devices.lidar_scan import LaserScan, LidarConfig, SerialLidar
from beastbt.robot.hardware import open_serial
from beastbt.robot.part import REAL, SIM, Build, Part, sleep_device
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO
from beastbt.run.session import Prepared

if TYPE_CHECKING:  # the simulator is imported only on --sim
    from beastbt.sim.lidar_emulator import LidarEmulator
    from beastbt.sim.robot import Emulator, Simulator

LIDAR_RNG_STREAM = "lidar"
"""The name of the LiDAR emulator's random stream (:meth:`Simulator.stream_rng`): its own, so fitting a LiDAR
shifts no other emulator's noise."""

LIDAR_HINT = ("check the LiDAR's USB cable and power (ls /dev/ttyUSB* /dev/serial/by-id/), that lidar.port names it, "
              "and that your user is in the 'dialout' group; beastbt doctor checks it")


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


def attach_sim_lidar(sim: "Simulator", profile: RobotProfile, io: RobotIO,
                     events: EventLog) -> tuple[Optional["Emulator"], Optional[SerialLidar], Optional["LidarEmulator"]]:
    """An emulated LD19 or RPLIDAR A1 on an emulated serial port, read by the real driver (``io.sensors['lidar']``).

    Only when the profile has a ``lidar:`` section. Returns the emulator's
    update (one of ``sim.emulators``), the driver and the emulator, or Nones.
    """
    if profile.section("lidar") is None:
        return None, None, None
    from beastbt.sim.lidar_emulator import RayCaster, make_emulator

    config: LidarConfig = section_config(profile, "lidar", LidarConfig)
    m = config.mounting
    caster = RayCaster(sim.world.walls, sim.world.obstacles)
    device = make_emulator(config.type, caster, sim.truth, sim.drive.contact, (m.x_m, m.y_m, m.yaw_deg),
                           sim.stream_rng(LIDAR_RNG_STREAM))
    sim.emulators.append(device.update)

    def reopen() -> Any:
        device.port.open()
        return device.port

    driver = lidar_driver(config, device.port, events.clock, events, reopen)

    def poll(now_s: float) -> list[LaserScan]:
        return driver.poll()

    io.sensors["lidar"] = poll
    io.capabilities.add("lidar")
    io.closers.append(driver.close)
    return device.update, driver, device


class LidarPart(Part):
    """``lidar:``: one ``LaserScan`` per revolution of the LD19 or RPLIDAR A1 (``io.sensors['lidar']``)."""

    name = "lidar"
    section = "lidar"
    schema = "parts/lidar.schema.json"
    opens = "serial port (LD19 / RPLIDAR A1)"
    fills = ("scan",)
    driver: Optional[SerialLidar] = None
    """The driver (on the robot or the simulator; None in a replay)."""
    emulator: Optional["Emulator"] = None
    """The emulator's update on the simulator (removed when the part sleeps)."""
    device: Optional["LidarEmulator"] = None
    """The emulated LiDAR on the simulator."""

    def attach(self, build: Build) -> None:
        """Open the LiDAR on the robot, or the emulated one on the simulator."""
        assert build.io is not None
        if build.mode == REAL:
            self.driver = attach_real_lidar(build.profile, build.io, build.clock, build.events)
        elif build.mode == SIM:
            assert build.sim is not None
            self.emulator, self.driver, self.device = attach_sim_lidar(build.sim, build.profile, build.io,
                                                                       build.events)

    def sleep(self, prepared: Prepared) -> None:
        """Nothing reads the scans: neither poll the driver nor ray-cast the world."""
        sleep_device(prepared, "lidar", self.emulator)

    def install(self, prepared: Prepared) -> None:
        """Tell the ``obstacle_within`` conditions where the LiDAR sits, the footprint, and the collision monitor's
        rules for a scan (its ``source_timeout_s`` and ``min_points``), so both judge a scan alike."""
        from beastbt.actuation.collision_monitor import CollisionMonitorConfig, footprint_radius
        from beastbt.behaviours.obstacle_within import ObstacleSensing

        profile = prepared.profile
        lidar: LidarConfig = section_config(profile, "lidar", LidarConfig)
        monitor: CollisionMonitorConfig = section_config(profile, "collision_monitor", CollisionMonitorConfig)
        prepared.run.ctx.services.obstacle_sensing = ObstacleSensing(
            lidar.mounting, footprint_radius(profile.data), monitor.source_timeout_s, monitor.min_points)


__all__ = ["LidarPart", "attach_real_lidar", "attach_sim_lidar", "lidar_driver", "LIDAR_HINT", "LIDAR_RNG_STREAM"]
