"""What the tick loop drives: the robot's base, servos and sensors, real or simulated.

A :class:`RobotIO` is assembled from a robot profile: on the robot from real
ports (``beastbt.robot.hardware``), in the simulator from emulators
(``beastbt.sim.robot``). The tick loop cannot tell them apart, except that a
simulated one has a world to step and a ground truth to compare against.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Optional

from beastbt.actuation.adapter import BaseAdapter, ServoAdapter

SensorPoll = Callable[[float], list]
"""A device's poll: given the time (s), the readings that arrived since the last call."""


@dataclass
class RobotIO:
    """The devices of one robot.

    ``sensors``: name -> poll function; ``capabilities``: words such as ``gps``,
    ``imu``, ``camera``, ``joystick``, ``pwm_servos``; ``sim``: the simulator
    (None on the robot), which the loop advances before polling.
    """

    base: BaseAdapter
    servos: list[ServoAdapter] = field(default_factory=list)
    sensors: dict[str, SensorPoll] = field(default_factory=dict)
    capabilities: set[str] = field(default_factory=set)
    sim: Optional[Any] = None
    closers: list[Callable[[], None]] = field(default_factory=list)
    extras: dict[str, Any] = field(default_factory=dict)
    """Anything else the parts of beastbt attach (a joystick device, the camera, the line detector...)."""

    def servo_names(self) -> frozenset[str]:
        """Every servo name any adapter drives."""
        names: set[str] = set()
        for s in self.servos:
            names.update(s.servo_names())
        return frozenset(names)

    def close(self) -> None:
        """Stop and release everything (the base last sends a stop)."""
        for close in self.closers:
            try:
                close()
            except Exception:
                pass
        try:
            self.base.close()
        except Exception:
            pass
