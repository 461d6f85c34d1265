"""Assemble a real robot from its profile: open every device, or stop before moving and say which one failed.

Each device section of the profile is opened in turn; a missing device is a
:class:`DeviceUnavailable` naming the device, the path tried and what to check,
and nothing has moved when it is raised.
"""

from __future__ import annotations

from typing import Callable

from beastbt.devices.waveshare_base import WaveshareBase, WaveshareConfig
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.robot.profile import RobotProfile, section_config
from beastbt.robot.robot_io import RobotIO


class DeviceUnavailable(Exception):
    """A device of the profile could not be opened; the message says which, where, and what to check."""


HardwareAttach = Callable[[RobotProfile, RobotIO, Clock, EventLog], None]
HARDWARE_DEVICES: list[HardwareAttach] = []
"""Functions that open one more kind of device for a real robot (GPS, IMU, camera, joystick...)."""


def open_serial(device: str, path: str, baud: int, hint: str):
    """Open a serial port non-blocking, or raise :class:`DeviceUnavailable`."""
    import serial
    try:
        return serial.Serial(path, baud, timeout=0, write_timeout=0.05)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise DeviceUnavailable(f"{device}: cannot open {path} at {baud} baud ({exc}); {hint}") from exc


def build_real_robot(profile: RobotProfile, clock: Clock, events: EventLog) -> RobotIO:
    """Open the profile's devices; raise :class:`DeviceUnavailable` before anything moves."""
    base_cfg = profile.section("base") or {}
    kind = base_cfg.get("type")
    if kind == "waveshare_serial":
        config = section_config(profile, "base", WaveshareConfig)
        port = open_serial("base (Waveshare ESP32)", config.port, config.baud,
                           "check the cable to the sub-controller, that the serial port is enabled "
                           "(raspi-config: serial on, login shell off) and that your user is in the 'dialout' group")
        base = WaveshareBase(port, config, events.sink("base"))
        io = RobotIO(base=base, servos=[base] if config.gimbal else [])
    else:
        factory = BASE_FACTORIES.get(kind)
        if factory is None:
            raise DeviceUnavailable(f"base: type '{kind}' is not supported by this version of beastbt")
        io = factory(profile, clock, events)
    for attach in HARDWARE_DEVICES:
        attach(profile, io, clock, events)
    return io


BaseFactory = Callable[[RobotProfile, Clock, EventLog], RobotIO]
BASE_FACTORIES: dict[str, BaseFactory] = {}
"""Other bases (``can``, ``pwm``) register how to open them here."""
