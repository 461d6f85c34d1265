"""Joystick to velocity, the way ROS ``teleop_twist_joy`` does it (deadman, turbo, one stop).

:class:`TeleopTwistJoy` reads the named :class:`JoystickState` the joystick
driver produces. Nothing moves unless the enable (deadman) button is held;
while it is, every update yields a command (turbo scales when the turbo
button is held too); when it is released, or the joystick is lost, exactly
one zero command follows, and then nothing, so the mission can take over
again. Unlike ``teleop_twist_joy``, the turbo button alone does not drive:
it only changes the scale while the deadman is held.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import JoystickState, VelocityCommand
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.joystick import AXIS_ANGULAR, AXIS_LINEAR, BUTTON_ENABLE, BUTTON_ESTOP, BUTTON_ESTOP_RESET, BUTTON_TURBO

TELEOP_SOURCE = "teleop"


@dataclass
@schema_defaults("parts/teleop.schema.json")
class TeleopConfig:
    """Teleop speeds (robot profile ``teleop:``), as teleop_twist_joy's scale parameters."""

    # Forward speed in m/s at full stick deflection (enable held).
    scale_linear_mps: float
    # Turn rate in rad/s at full stick deflection (enable held).
    scale_angular_rps: float
    # Forward speed in m/s at full deflection with enable and turbo held.
    scale_linear_turbo_mps: float
    # Turn rate in rad/s at full deflection with enable and turbo held.
    scale_angular_turbo_rps: float

    def __post_init__(self) -> None:
        for key in ("scale_linear_mps", "scale_angular_rps", "scale_linear_turbo_mps", "scale_angular_turbo_rps"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{key} must be zero or positive, got {value}")

    @classmethod
    def from_dict(cls, d: Any) -> "TeleopConfig":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "teleop")


def _held(state: Optional[JoystickState], name: str) -> bool:
    return state is not None and state.connected and bool(state.buttons.get(name, False))


def _axis(state: JoystickState, name: str) -> float:
    value = float(state.axes.get(name, 0.0))
    # A non-finite reading cannot be trusted to mean anything: treat it as centred.
    return max(-1.0, min(1.0, value)) if math.isfinite(value) else 0.0


class TeleopTwistJoy:
    """Deadman teleop: joystick state in, at most one velocity command out per update."""

    def __init__(self, config: Optional[TeleopConfig] = None) -> None:
        self.config = config if config is not None else TeleopConfig()
        self._active = False

    @property
    def active(self) -> bool:
        """True while the enable button was held at the last update (teleop has the robot)."""
        return self._active

    def update(self, state: Optional[JoystickState], now_s: float) -> Optional[VelocityCommand]:
        """Command for this tick (m/s, rad/s; source ``teleop``), or None when teleop is idle.

        Enable held: a command from the sticks, every call. Enable just
        released (or joystick lost / None): one zero command. Otherwise None.
        """
        if _held(state, BUTTON_ENABLE):
            assert state is not None
            c = self.config
            turbo = _held(state, BUTTON_TURBO)
            k_lin = c.scale_linear_turbo_mps if turbo else c.scale_linear_mps
            k_ang = c.scale_angular_turbo_rps if turbo else c.scale_angular_rps
            self._active = True
            return VelocityCommand(
                linear_mps=_axis(state, AXIS_LINEAR) * k_lin,
                angular_rps=_axis(state, AXIS_ANGULAR) * k_ang,
                stamp_s=now_s,
                source=TELEOP_SOURCE,
            )
        if self._active:
            self._active = False
            return VelocityCommand(0.0, 0.0, stamp_s=now_s, source=TELEOP_SOURCE)
        return None

    def reset(self) -> None:
        """Forget the enable state (no zero command will follow)."""
        self._active = False

    @staticmethod
    def estop_pressed(state: Optional[JoystickState]) -> bool:
        """True when the joystick's emergency stop button is held (connected pads only)."""
        return _held(state, BUTTON_ESTOP)

    @staticmethod
    def estop_reset_pressed(state: Optional[JoystickState]) -> bool:
        """True when the joystick's emergency stop reset button is held."""
        return _held(state, BUTTON_ESTOP_RESET)
