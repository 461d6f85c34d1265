"""Servos on a PCA9685 HAT as the runner's servo adapter, starting the chip when first needed.

:class:`PcaServoBoard` is the :class:`~beastbt.actuation.adapter.ServoAdapter`
the runner hands servo commands to for a profile's ``servos:`` section. It
wraps :class:`~beastbt.devices.pca9685.PcaServos` (which maps angles to
pulses within each servo's calibrated range) and programs the chip's PWM
frequency on the first command, unless a PWM base on the same chip already
did. Chip programming waits through the injected ``wait`` sleeper.
"""

from __future__ import annotations

from typing import Callable, Mapping, Optional

from beastbt.blackboard.types import ServoCommand
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.devices.pca9685 import Pca9685, PcaServos, ServoCalibration, no_wait


class PcaServoBoard:
    """Named servos on a PCA9685; ``frequency_hz`` is the PWM rate it programs if the chip is not running."""

    def __init__(self, pca: Pca9685, servos: Mapping[str, ServoCalibration], frequency_hz: float = 50.0,
                 events: EventSink = ignore_events, wait: Callable[[float], None] = no_wait) -> None:
        self.pca = pca
        self.servos = PcaServos(pca, servos, events)
        self.frequency_hz = frequency_hz
        self.events = events
        self.wait = wait

    def servo_names(self) -> list[str]:
        """The calibrated servo names, in profile order."""
        return self.servos.servo_names()

    def set_servo(self, cmd: ServoCommand, now_s: float) -> bool:
        """Position one servo (by name and angle, or by channel and pulse); False when refused or the bus failed."""
        if cmd.name is not None and cmd.name not in self.servos.servos:
            return False  # another adapter (a gimbal) may own this name
        if self.pca.frequency_hz is None and not self.pca.start(self.frequency_hz, self.wait):
            return False
        return self.servos.set_servo(cmd, now_s)

    def angle_of(self, name: str) -> Optional[float]:
        """The last angle (rad) commanded to servo ``name``, or None."""
        return self.servos.angle_of(name)


__all__ = ["PcaServoBoard"]
