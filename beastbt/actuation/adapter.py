"""The actuator adapter interface: the last software stage before a motor moves.

One adapter per kind of base (the simulator's Waveshare emulator and the real
Waveshare base both speak serial JSON; a CAN base; a PWM base on a PCA9685),
all interchangeable behind :class:`BaseAdapter` and chosen by the robot
profile, in the manner of python-can's ``Bus``. Adapters also return the
feedback their base sends (wheel odometry, IMU, battery) because on these
robots it arrives on the same wire.
"""

from __future__ import annotations

from typing import Protocol

from beastbt.blackboard.types import Feedback, ServoCommand, VelocityCommand


class BaseAdapter(Protocol):
    """A drive base: takes body velocity commands, yields feedback readings."""

    name: str

    def start(self, now_s: float) -> None:
        """Send whatever start-up sequence the base needs (feedback on, rates...)."""
        ...

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        """Send one body velocity command (m/s, rad/s). Must not block."""
        ...

    def emergency_stop(self, now_s: float) -> None:
        """Send the base's own stop (e.g. ``{"T":0}``), or zero velocity where it has none."""
        ...

    def poll(self, now_s: float) -> list[Feedback]:
        """Return the feedback that arrived since the last call. Never raises on bad bytes."""
        ...

    def close(self) -> None:
        """Send a final stop and release the port/bus."""
        ...


class ServoAdapter(Protocol):
    """Something that can position servos by name (a gimbal, a PCA9685 HAT)."""

    def servo_names(self) -> list[str]:
        """The names of the servos this adapter drives (``pan``, ``tilt``...)."""
        ...

    def set_servo(self, cmd: ServoCommand, now_s: float) -> bool:
        """Command one servo; False when there is no such servo or channel."""
        ...
