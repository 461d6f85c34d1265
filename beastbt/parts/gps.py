"""The GPS (the profile's ``gps:``): an NMEA receiver on a serial port, or the emulated MTK3339.

On the robot the port is opened with pyserial; a port that does not exist at
start stops the run before anything moves with a
:class:`~beastbt.robot.hardware.DeviceUnavailable` saying what to check.
Faults once running (a receiver unplugged, garbage on the line) are the
driver's business: reported as events, the data goes stale, the port is
reopened. On the simulator an emulated MTK3339 writes NMEA into an emulated
serial port read by the same driver; the fixes are in the world's datum
frame on Earth, and nothing else of the world is told to the driver.
"""

from __future__ import annotations

from typing import Any, Optional

from beastbt.blackboard.types import GpsFix
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.devices.nmea_gps import GpsConfig, NmeaGps
from beastbt.robot.hardware import open_serial
from beastbt.robot.part import REAL, SIM, Build, Part, sleep_device
from beastbt.robot.serial_hint import serial_port_hint
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO
from beastbt.run.session import Prepared
from beastbt.sim.gps_emulator import GpsNoiseModel, SimGps
from beastbt.sim.robot import Emulator, Simulator


def gps_hint(port: str) -> str:
    """What to check when the GPS's ``port`` cannot be opened: the HAT, then that kind of port's set-up."""
    return f"check the GPS HAT is seated; {serial_port_hint(port)}"


def attach_real_gps(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """Open the profile's NMEA GPS (``io.sensors['gps']``), or raise :class:`DeviceUnavailable`."""
    if profile.section("gps") is None:
        return
    import serial

    config: GpsConfig = section_config(profile, "gps", GpsConfig)
    port = open_serial("gps (NMEA receiver)", config.port, config.port_baud, gps_hint(config.port))
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
    io.gps_driver = driver


def attach_sim_gps(sim: Simulator, profile: RobotProfile, io: RobotIO, events: EventLog) -> Optional[Emulator]:
    """An emulated MTK3339 on a serial port, read by the NMEA driver (``io.sensors['gps']``).

    Only when the profile has a ``gps:`` section. The fixes are in the world's
    datum frame on Earth; nothing else of the world is told to the driver.
    Returns the emulator's update (one of ``sim.emulators``), or None.
    """
    if profile.section("gps") is None:
        return None
    config: GpsConfig = section_config(profile, "gps", GpsConfig)
    model: GpsNoiseModel = sim.world_model("gps", GpsNoiseModel)
    gps = SimGps(sim.world.frame, model, sim.child_rng())
    truth = sim.truth

    def emulate(now_s: float, dt_s: float) -> None:
        gps.update(truth)
    sim.emulators.append(emulate)

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
    io.sim_gps = gps
    io.gps_driver = driver
    return emulate


class GpsPart(Part):
    """``gps:``: one ``GpsFix`` per NMEA sentence with a position (``io.sensors['gps']``)."""

    name = "gps"
    section = "gps"
    schema = "parts/gps_device.schema.json"
    opens = "serial port (NMEA 0183)"
    fills = ("gps_fix", "home",)
    emulator: Optional[Emulator] = None
    """The emulator's update on the simulator (removed when the part sleeps)."""

    def attach(self, build: Build) -> None:
        """Open the receiver (robot) or the emulated one (simulator) when the profile has ``gps:``."""
        assert build.io is not None
        if build.mode == REAL:
            attach_real_gps(build.profile, build.io, build.clock, build.events)
        elif build.mode == SIM:
            assert build.sim is not None
            self.emulator = attach_sim_gps(build.sim, build.profile, build.io, build.events)

    def sleep(self, prepared: Prepared) -> None:
        """Nothing reads the fixes: neither poll the driver nor emulate the chip."""
        sleep_device(prepared, "gps", self.emulator)


__all__ = ["GpsPart", "attach_real_gps", "attach_sim_gps", "gps_hint"]
