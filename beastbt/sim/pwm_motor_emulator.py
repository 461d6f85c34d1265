"""The motors of a PWM-driven base, as seen from the outputs of an emulated PCA9685.

:class:`SimPwmMotors` reads the pulses (ESC wiring) or duty and direction
levels (H-bridge wiring) on :class:`~beastbt.sim.pca9685_emulator.SimPca9685`
channels and tells the simulator which wheel surface speeds (m/s) the motors
are trying to reach. Like real ESCs, a channel with no pulse (off, asleep)
means stop. The wiring comes from the same :class:`PwmBaseConfig` the robot
profile gives the driver, including ``invert_*``: an inverted motor really
turns the other way, so a driver that forgets the flag drives wrong.
"""

from __future__ import annotations

from beastbt.actuation.pwm_base import PwmBaseConfig
from beastbt.sim.pca9685_emulator import SimPca9685


class SimPwmMotors:
    """Wheel speed targets (m/s, left/right, forward positive) from PCA9685 outputs.

    ``esc_deadband_ms`` is the band around neutral an ESC treats as stop
    (real ESCs have one; 0.02 ms by default).
    """

    def __init__(self, chip: SimPca9685, wiring: PwmBaseConfig, esc_deadband_ms: float = 0.02) -> None:
        self.chip = chip
        self.wiring = wiring
        self.esc_deadband_ms = esc_deadband_ms

    def _fraction(self, channel: int, dir_channel: int) -> float:
        w = self.wiring
        if w.mode == "esc":
            pulse_s = self.chip.pulse_s(channel)
            if pulse_s is None:
                return 0.0  # no signal: ESCs fail safe to stop
            pulse_ms = pulse_s * 1000.0
            if abs(pulse_ms - w.neutral_pulse_ms) <= self.esc_deadband_ms:
                return 0.0
            return w.esc_fraction(pulse_ms)
        duty = self.chip.duty(channel)
        reverse = self.chip.duty(dir_channel) >= 0.5
        return -duty if reverse else duty

    def wheel_targets_mps(self) -> tuple[float, float]:
        """(left, right) wheel speed targets in m/s that the motors are being driven to."""
        w = self.wiring
        left = self._fraction(w.left_channel, w.left_dir_channel) * w.max_wheel_speed_mps
        right = self._fraction(w.right_channel, w.right_dir_channel) * w.max_wheel_speed_mps
        if w.invert_left:
            left = -left
        if w.invert_right:
            right = -right
        return left, right
