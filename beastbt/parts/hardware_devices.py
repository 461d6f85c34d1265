"""Real CAN and PWM bases, PCA9685 servos and the gamepad, opened from a robot profile.

Registered with :mod:`beastbt.robot.hardware`: ``BASE_FACTORIES["can"]``
(python-can, SocketCAN ``can0`` by default), ``BASE_FACTORIES["pwm"]`` (a
PCA9685 on ``/dev/i2c-N`` through smbus2) and two ``HARDWARE_DEVICES``: the
``servos:`` on a PCA9685 and the ``joystick:`` (``/dev/input/jsN``). A base
or servo board that cannot be opened stops the run before anything moves
with a :class:`~beastbt.robot.hardware.DeviceUnavailable` that names the
device, the path tried and what to check. A missing gamepad is not fatal: it
is reported as a ``joystick_unavailable`` event, the driver keeps trying to
open it, and a ``teleop`` step fails with "no joystick" while it is absent.
"""

from __future__ import annotations

import time

from beastbt.actuation.can_base import CanBase, open_can_bus
from beastbt.actuation.pwm_base import PwmBase
from beastbt.actuation.servo_board import PcaServoBoard
from beastbt.devices.joystick import JoystickDevice, linux_joystick_opener
from beastbt.devices.pca9685 import MODE1, Pca9685
from beastbt.robot.actuator_profile import can_config, joystick_mapping, pca_config, pwm_config, servo_calibrations
from beastbt.core.clock import Clock
from beastbt.core.events import EventLog
from beastbt.robot.hardware import BASE_FACTORIES, HARDWARE_DEVICES, DeviceUnavailable
from beastbt.robot.profile import RobotProfile
from beastbt.robot.robot_io import RobotIO

JOYSTICK_HINT = ("check that the gamepad is plugged in or paired (ls /dev/input/js*; jstest {path}) and that your user "
                 "is in the 'input' group; teleop and the joystick e-stop work once it appears")


def real_sleep(duration_s: float) -> None:
    """The sleeper handed to drivers on the robot (the PCA9685's 500 us oscillator wait)."""
    time.sleep(duration_s)


def open_can_base(profile: RobotProfile, clock: Clock, events: EventLog) -> RobotIO:
    """The CAN base of ``profile`` on its SocketCAN interface, or :class:`DeviceUnavailable`."""
    config = can_config(profile)
    try:
        bus = open_can_bus(config)
    except Exception as exc:  # python-can raises CanInitializationError, OSError or ValueError by backend
        raise DeviceUnavailable(
            f"base (CAN motor controller): cannot open {config.interface} channel '{config.channel}' at "
            f"{config.bitrate} bit/s ({exc}); check that the CAN HAT is enabled (dtoverlay=mcp2515-can0 in "
            f"/boot/firmware/config.txt), that the interface is up (sudo ip link set {config.channel} up type can "
            f"bitrate {config.bitrate}; ip -details link show {config.channel}), and the wiring and 120 ohm termination"
        ) from exc
    base = CanBase(bus, config, events.sink("base"))
    return RobotIO(base=base)


def open_pca9685(profile: RobotProfile, events: EventLog, what: str) -> Pca9685:
    """Open the profile's PCA9685 and check it answers, or raise :class:`DeviceUnavailable` naming ``what`` needs it."""
    import smbus2

    cfg = pca_config(profile)
    path = f"/dev/i2c-{cfg.bus}"
    try:
        bus = smbus2.SMBus(cfg.bus)
    except (OSError, FileNotFoundError) as exc:
        raise DeviceUnavailable(
            f"{what} (PCA9685): cannot open {path} ({exc}); check that I2C is enabled (raspi-config: Interface "
            f"Options > I2C), that the HAT is seated, and that your user is in the 'i2c' group") from exc
    try:
        bus.read_byte_data(cfg.address, MODE1)
    except OSError as exc:
        bus.close()
        raise DeviceUnavailable(
            f"{what} (PCA9685): nothing answers at address 0x{cfg.address:02x} on {path} ({exc}); check "
            f"'i2cdetect -y {cfg.bus}' shows 0x{cfg.address:02x}, the HAT's power and its address jumpers") from exc
    return Pca9685(bus, cfg.address, cfg.oscillator_hz, events.sink("pca9685"))


def open_pwm_base(profile: RobotProfile, clock: Clock, events: EventLog) -> RobotIO:
    """The PWM base of ``profile`` on its PCA9685, or :class:`DeviceUnavailable`."""
    config = pwm_config(profile)
    pca = open_pca9685(profile, events, "base")
    base = PwmBase(pca, config, events.sink("base"), wait=real_sleep)
    io = RobotIO(base=base)
    io.extras["pca9685"] = pca
    return io


BASE_FACTORIES["can"] = open_can_base
BASE_FACTORIES["pwm"] = open_pwm_base


def attach_servos(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """The profile's ``servos:`` on the PCA9685 (the PWM base's chip when there is one)."""
    cals = servo_calibrations(profile)
    if not cals:
        return
    pca = io.extras.get("pca9685")
    if pca is None:
        pca = open_pca9685(profile, events, "servos")
        io.extras["pca9685"] = pca
    board = PcaServoBoard(pca, cals, pca_config(profile).frequency_hz, events.sink("servos"), wait=real_sleep)
    io.servos.append(board)
    io.capabilities.add("pwm_servos")
    io.extras["servo_board"] = board


def attach_joystick(profile: RobotProfile, io: RobotIO, clock: Clock, events: EventLog) -> None:
    """The profile's gamepad on ``/dev/input/jsN``; a missing one is an event, not an error."""
    if profile.section("joystick") is None:
        return
    mapping = joystick_mapping(profile)
    sink = events.sink("joystick")
    hint = JOYSTICK_HINT.format(path=mapping.device)

    def with_hint(kind: str, text: str) -> None:
        sink(kind, f"{text}; {hint}" if kind == "joystick_unavailable" else text)

    device = JoystickDevice(linux_joystick_opener(mapping.device), clock, with_hint, mapping)
    device.poll()  # open it now, so that a missing gamepad is reported before the run starts

    def poll(now_s: float) -> list:
        return [device.poll()]

    io.sensors["joystick"] = poll
    io.extras["joystick"] = device
    io.capabilities.add("joystick")


HARDWARE_DEVICES.append(attach_servos)
HARDWARE_DEVICES.append(attach_joystick)


__all__ = ["open_can_base", "open_pwm_base", "open_pca9685", "attach_servos", "attach_joystick", "real_sleep"]
