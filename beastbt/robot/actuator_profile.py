"""The robot profile's actuator and teleop sections, turned into the configs of their drivers.

One place that reads ``can_base:``, ``pwm_base:``, ``pca9685:``, ``servos:``,
``joystick:``, ``teleop:`` and ``watchdog:`` for both the real robot
and the simulator (the parts in ``beastbt.parts``), so that a profile means the same on both.
A bad value becomes an :class:`~beastbt.core.errors.InvalidInput` at the
section's line, before anything moves. Wheel geometry the base section leaves
out (``track_width_m``, ``wheel_radius_m``) comes from the profile's ``geometry:``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from beastbt.actuation.pwm_base import PwmBaseConfig
from beastbt.actuation.teleop import TeleopConfig
from beastbt.actuation.watchdog import WatchdogConfig
from beastbt.devices.joystick import JoystickMapping
from beastbt.devices.pca9685 import Pca9685Config, ServoCalibration, servo_calibrations_from_dict
from beastbt.core.errors import InvalidInput
from beastbt.robot.profile import RobotProfile

if TYPE_CHECKING:  # python-can comes with it: imported only for a robot with a CAN base
    from beastbt.actuation.can_base import CanBaseConfig


def _build(profile: RobotProfile, section: str, build: Any, raw: Any) -> Any:
    try:
        return build(raw)
    except (TypeError, ValueError) as exc:
        raise InvalidInput([profile.doc.problem((section,) if section in profile.data else (),
                                                f"in '{section}': {exc}",
                                                f"see schemas/parts/ for the knobs '{section}' takes")]) from None


def _with_geometry(profile: RobotProfile, raw: dict, keys: tuple[str, ...]) -> dict:
    geometry = profile.section("geometry") or {}
    out = dict(raw)
    for key in keys:
        if key not in out and key in geometry:
            out[key] = geometry[key]
    return out


def can_config(profile: RobotProfile) -> "CanBaseConfig":
    """The ``can_base:`` section (defaults: HARDWARE.md's example protocol; geometry from ``geometry:``)."""
    from beastbt.actuation.can_base import CanBaseConfig
    raw = _with_geometry(profile, profile.section("can_base") or {}, ("track_width_m", "wheel_radius_m"))
    return _build(profile, "can_base", CanBaseConfig.from_dict, raw)


def pwm_config(profile: RobotProfile) -> PwmBaseConfig:
    """The ``pwm_base:`` section (track width from ``geometry:`` unless given)."""
    raw = _with_geometry(profile, profile.section("pwm_base") or {}, ("track_width_m",))
    return _build(profile, "pwm_base", PwmBaseConfig.from_dict, raw)


def pca_config(profile: RobotProfile) -> Pca9685Config:
    """The ``pca9685:`` section (bus 1, address 0x40, 25 MHz, 50 Hz by default)."""
    return _build(profile, "pca9685", Pca9685Config.from_dict, profile.section("pca9685") or {})


def servo_calibrations(profile: RobotProfile) -> dict[str, ServoCalibration]:
    """The ``servos:`` section: name -> calibration (empty when the robot has none)."""
    return _build(profile, "servos", servo_calibrations_from_dict, profile.section("servos") or {})


TELEOP_TWIST_JOY_NAMES = ("axis_linear", "axis_angular", "scale_linear", "scale_linear_turbo", "scale_angular",
                          "scale_angular_turbo", "enable_button", "enable_turbo_button", "require_enable_button")
"""teleop_twist_joy's parameter names, accepted in ``teleop:`` so that a ROS user's config ports over."""


def _ros_value(value: Any, key: str) -> Any:
    """``{x: 1}`` / ``{yaw: 0.5}`` (ROS 2 parameter files) or a plain value (ROS 1)."""
    if isinstance(value, dict):
        return value[key]
    return value


def teleop_twist_joy(profile: RobotProfile) -> tuple[dict[str, Any], dict[str, Any]]:
    """The teleop_twist_joy names in ``teleop:`` as (``joystick:`` values, ``teleop:`` values).

    ``axis_linear.x``/``axis_angular.yaw`` are axis numbers; ``enable_button``
    and ``enable_turbo_button`` buttons; ``scale_*`` speeds in m/s and rad/s
    per full stick, whose sign says the direction: ROS's joy node reports
    stick-up and stick-left as positive (the kernel as negative), so a
    positive scale is beastbt's inverted axis. ``require_enable_button``
    must be true: beastbt never drives without the deadman.
    """
    raw = profile.section("teleop") or {}
    joystick: dict[str, Any] = {}
    teleop: dict[str, Any] = {}
    if "axis_linear" in raw:
        joystick["linear_axis"] = _ros_value(raw["axis_linear"], "x")
    if "axis_angular" in raw:
        joystick["angular_axis"] = _ros_value(raw["axis_angular"], "yaw")
    if "enable_button" in raw:
        joystick["enable_button"] = raw["enable_button"]
    if "enable_turbo_button" in raw:
        joystick["turbo_button"] = raw["enable_turbo_button"]
    for ros, ours, axis, invert in (("scale_linear", "scale_linear_mps", "x", "invert_linear"),
                                    ("scale_linear_turbo", "scale_linear_turbo_mps", "x", None),
                                    ("scale_angular", "scale_angular_rps", "yaw", "invert_angular"),
                                    ("scale_angular_turbo", "scale_angular_turbo_rps", "yaw", None)):
        if ros in raw:
            value = float(_ros_value(raw[ros], axis))
            teleop[ours] = abs(value)
            if invert is not None:
                joystick[invert] = value >= 0.0
    return joystick, teleop


def _merged(profile: RobotProfile, section: str, native: dict, aliases: dict) -> dict:
    both = sorted(set(native) & set(aliases))
    if both:
        raise InvalidInput([profile.doc.problem(("teleop",), f"'{both[0]}' is set twice: in '{section}:' and by a "
                                                f"teleop_twist_joy name in 'teleop:'",
                                                "keep one of them")])
    return {**native, **aliases}


def joystick_mapping(profile: RobotProfile) -> JoystickMapping:
    """The ``joystick:`` section, with teleop_twist_joy's names from ``teleop:`` (a preset fills the rest)."""
    aliases, _ = teleop_twist_joy(profile)
    raw = _merged(profile, "joystick", dict(profile.section("joystick") or {}), aliases)
    return _build(profile, "joystick", JoystickMapping.from_dict, raw)


def teleop_config(profile: RobotProfile) -> TeleopConfig:
    """The ``teleop:`` section (teleop_twist_joy's scales by default; its parameter names accepted too)."""
    _, aliases = teleop_twist_joy(profile)
    native = {k: v for k, v in (profile.section("teleop") or {}).items() if k not in TELEOP_TWIST_JOY_NAMES}
    return _build(profile, "teleop", TeleopConfig.from_dict, _merged(profile, "teleop", native, aliases))


def watchdog_config(profile: RobotProfile) -> WatchdogConfig:
    """The ``watchdog:`` section (zero after 0.45 s without a fresh command by default)."""
    return _build(profile, "watchdog", WatchdogConfig.from_dict, profile.section("watchdog") or {})


__all__ = ["can_config", "pwm_config", "pca_config", "servo_calibrations", "joystick_mapping", "teleop_config",
           "watchdog_config"]
