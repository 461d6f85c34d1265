"""A home-built differential base driven by two PWM motor channels on a PCA9685.

Two ways of wiring the motors are supported, chosen in the robot profile:
``esc`` (each side an RC speed controller taking a 1.0-2.0 ms pulse, 1.5 ms
neutral) and ``hbridge`` (each side a PWM duty channel for speed plus a
direction channel held fully on for reverse). There is no feedback: the base
is open loop, so :meth:`PwmBase.poll` returns nothing and the estimator must
rely on other sensors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Literal

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import VelocityCommand
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.devices.pca9685 import CHANNELS, Pca9685, no_wait

PwmMode = Literal["esc", "hbridge"]


@dataclass
@schema_defaults("parts/pwm_base.schema.json")
class PwmBaseConfig:
    """Wiring and scaling of a PWM-driven base (robot profile ``pwm_base:``)."""

    # How the motor drivers take speed: "esc" = RC pulses (neutral_pulse_ms stops),
    # "hbridge" = duty on the speed channel plus a direction channel.
    mode: PwmMode
    # PCA9685 channel of the left motor's ESC signal (esc) or PWM input (hbridge).
    left_channel: int
    # PCA9685 channel of the right motor's ESC signal (esc) or PWM input (hbridge).
    right_channel: int
    # hbridge only: PCA9685 channel wired to the left driver's DIR input (fully on = reverse).
    left_dir_channel: int
    # hbridge only: PCA9685 channel wired to the right driver's DIR input (fully on = reverse).
    right_dir_channel: int
    # PWM frequency in Hz for the whole chip. 50 Hz for ESCs (and any servos on the
    # same HAT); an H-bridge runs quieter at 1000 Hz if no servos share the chip.
    frequency_hz: float
    # esc only: pulse in ms at which the ESC stops. Trim if the robot creeps at zero.
    neutral_pulse_ms: float
    # esc only: pulse in ms for full reverse.
    min_pulse_ms: float
    # esc only: pulse in ms for full forward.
    max_pulse_ms: float
    # Wheel (or track) surface speed in m/s at full pulse or 100 % duty. Measure it:
    # higher commands are scaled down keeping the turn radius.
    max_wheel_speed_mps: float
    # Distance between the left and right wheel contact lines, metres.
    track_width_m: float
    # True when the left motor turns backwards for a positive command (wired reversed).
    invert_left: bool
    # True when the right motor turns backwards for a positive command (usually the
    # mirrored side of a base with identical motors).
    invert_right: bool

    def __post_init__(self) -> None:
        if self.mode not in ("esc", "hbridge"):
            raise ValueError(f"mode must be 'esc' or 'hbridge', got {self.mode!r}")
        used = [self.left_channel, self.right_channel]
        if self.mode == "hbridge":
            used += [self.left_dir_channel, self.right_dir_channel]
        for ch in used:
            if not 0 <= ch < CHANNELS:
                raise ValueError(f"channels must be 0..15, got {ch}")
        if len(set(used)) != len(used):
            raise ValueError(f"each motor signal needs its own channel, got {used}")
        if not 0.0 < self.min_pulse_ms < self.neutral_pulse_ms < self.max_pulse_ms <= 10.0:
            raise ValueError(
                "pulses must satisfy 0 < min_pulse_ms < neutral_pulse_ms < max_pulse_ms <= 10, got "
                f"{self.min_pulse_ms}, {self.neutral_pulse_ms}, {self.max_pulse_ms}"
            )
        if not 1.0 <= self.frequency_hz <= 3500.0:
            raise ValueError(f"frequency_hz must be 1..3500 Hz, got {self.frequency_hz}")
        if self.mode == "esc" and self.max_pulse_ms * 1e-3 * self.frequency_hz >= 1.0:
            raise ValueError(f"a {self.max_pulse_ms} ms pulse does not fit in one period at {self.frequency_hz} Hz")
        if not self.max_wheel_speed_mps > 0:
            raise ValueError(f"max_wheel_speed_mps must be positive, got {self.max_wheel_speed_mps}")
        if not self.track_width_m > 0:
            raise ValueError(f"track_width_m must be positive, got {self.track_width_m}")

    @classmethod
    def from_dict(cls, d: Any) -> "PwmBaseConfig":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "pwm_base")

    # --- shared arithmetic (the driver and the emulator must agree) --------------------------
    def wheel_speeds_mps(self, linear_mps: float, angular_rps: float) -> tuple[float, float]:
        """Left/right wheel speeds (m/s) for a body velocity, scaled down together to the maximum."""
        half = 0.5 * self.track_width_m
        left = linear_mps - angular_rps * half
        right = linear_mps + angular_rps * half
        biggest = max(abs(left), abs(right))
        if biggest > self.max_wheel_speed_mps:
            # Scale both sides alike so the robot keeps the commanded curvature.
            k = self.max_wheel_speed_mps / biggest
            left, right = left * k, right * k
        return left, right

    def esc_pulse_ms(self, fraction: float) -> float:
        """ESC pulse in ms for a signed speed fraction -1..1 (neutral at 0)."""
        f = max(-1.0, min(1.0, fraction))
        if f >= 0:
            return self.neutral_pulse_ms + f * (self.max_pulse_ms - self.neutral_pulse_ms)
        return self.neutral_pulse_ms + f * (self.neutral_pulse_ms - self.min_pulse_ms)

    def esc_fraction(self, pulse_ms: float) -> float:
        """Signed speed fraction -1..1 an ESC makes of ``pulse_ms`` (inverse of :meth:`esc_pulse_ms`)."""
        if pulse_ms >= self.neutral_pulse_ms:
            f = (pulse_ms - self.neutral_pulse_ms) / (self.max_pulse_ms - self.neutral_pulse_ms)
        else:
            f = (pulse_ms - self.neutral_pulse_ms) / (self.neutral_pulse_ms - self.min_pulse_ms)
        return max(-1.0, min(1.0, f))


class PwmBase:
    """:class:`~beastbt.actuation.adapter.BaseAdapter` for a PCA9685-driven base (open loop).

    ``wait`` is the sleeper handed to :meth:`Pca9685.start` (a real sleep on
    the robot; the default returns at once). Write failures are already
    reported by the chip driver; ``failed_writes`` counts them here too.
    """

    name = "pwm_base"

    def __init__(
        self,
        pca: Pca9685,
        config: PwmBaseConfig,
        events: EventSink = ignore_events,
        wait: Callable[[float], None] = no_wait,
    ) -> None:
        self.pca = pca
        self.config = config
        self.events = events
        self.wait = wait
        self.failed_writes = 0
        self.last_wheel_mps: tuple[float, float] = (0.0, 0.0)
        """The wheel speeds (m/s, left, right) last sent, after scaling."""

    def start(self, now_s: float) -> None:
        """Program the chip's frequency (unless already running at it) and output a stop."""
        wanted = self.config.frequency_hz
        current = self.pca.frequency_hz
        if current is None or abs(current - wanted) > 0.05 * wanted:
            if current is not None:
                # Every channel shares the frequency: servos on the same chip will notice.
                self.events("pwm_base_frequency_changed", f"PCA9685 reprogrammed from {current:.1f} Hz to {wanted:.1f} Hz for the motors")
            if not self.pca.start(wanted, self.wait):
                self.failed_writes += 1
        self._drive(0.0, 0.0)

    def _side(self, channel: int, dir_channel: int, fraction: float) -> bool:
        c = self.config
        if c.mode == "esc":
            limits_s = (c.min_pulse_ms / 1000.0, c.max_pulse_ms / 1000.0)
            return self.pca.set_pulse(channel, c.esc_pulse_ms(fraction) / 1000.0, limits_s)
        reverse = fraction < 0
        # Direction first, so a sign change never drives full duty the old way.
        ok = self.pca.full_on(dir_channel) if reverse else self.pca.full_off(dir_channel)
        return self.pca.set_duty(channel, min(1.0, abs(fraction))) and ok

    def _drive(self, left_mps: float, right_mps: float) -> None:
        c = self.config
        lf = left_mps / c.max_wheel_speed_mps * (-1.0 if c.invert_left else 1.0)
        rf = right_mps / c.max_wheel_speed_mps * (-1.0 if c.invert_right else 1.0)
        ok_l = self._side(c.left_channel, c.left_dir_channel, lf)
        ok_r = self._side(c.right_channel, c.right_dir_channel, rf)
        self.failed_writes += (not ok_l) + (not ok_r)
        self.last_wheel_mps = (left_mps, right_mps)

    def send_velocity(self, cmd: VelocityCommand, now_s: float) -> None:
        """Turn a body velocity (m/s, rad/s CCW) into the two motor outputs."""
        v, w = cmd.linear_mps, cmd.angular_rps
        if not (math.isfinite(v) and math.isfinite(w)):
            self.events("pwm_base_bad_command", f"non-finite velocity command ({v}, {w}): stopping")
            v, w = 0.0, 0.0
        self._drive(*self.config.wheel_speeds_mps(v, w))

    def emergency_stop(self, now_s: float) -> None:
        """Neutral pulse (esc) or zero duty (hbridge) on both sides: the base has no stop of its own."""
        self._drive(0.0, 0.0)

    def poll(self, now_s: float) -> list:
        """No feedback wire: always an empty list."""
        return []

    def close(self) -> None:
        """Send a final stop. The I2C bus belongs to whoever opened it and is left open."""
        self._drive(0.0, 0.0)
