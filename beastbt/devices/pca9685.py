"""PCA9685 16-channel PWM driver (Adafruit Servo HAT) and the servos hung on it.

:class:`Pca9685` speaks the chip's register protocol over an ``SMBusLike``
(``smbus2.SMBus`` on the robot, :class:`beastbt.sim.i2c_bus.SimI2CBus` in the
simulator): MODE1/MODE2/PRESCALE and four 12-bit count registers per
channel (see HARDWARE.md). :class:`PcaServos` positions hobby servos by name
from per-servo calibrations in the robot profile, and never drives a servo
outside its calibrated pulse range. I2C errors are counted and reported
through the ``EventSink``; the ``set_*`` methods answer ``False`` instead of
raising.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable, Optional

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import ServoCommand
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, SMBusLike, ignore_events

# --- registers (PCA9685 datasheet, section 7.3) ---------------------------------
MODE1 = 0x00
MODE2 = 0x01
LED0_ON_L = 0x06  # channel n: ON_L, ON_H, OFF_L, OFF_H at LED0_ON_L + 4 n
ALL_LED_ON_L = 0xFA
ALL_LED_ON_H = 0xFB
ALL_LED_OFF_L = 0xFC
ALL_LED_OFF_H = 0xFD
PRESCALE = 0xFE

# --- MODE1 / MODE2 bits ------------------------------------------------------------
MODE1_RESTART = 0x80
MODE1_EXTCLK = 0x40
MODE1_AI = 0x20
MODE1_SLEEP = 0x10
MODE1_ALLCALL = 0x01
MODE2_OUTDRV = 0x04

FULL_BIT = 0x10  # bit 4 of ON_H (fully on) or OFF_H (fully off): count value 4096
COUNTS_PER_PERIOD = 4096
MAX_COUNT = 4095
CHANNELS = 16
PRESCALE_MIN = 3  # the chip refuses smaller values (1526 Hz at 25 MHz)
PRESCALE_MAX = 255  # about 24 Hz at 25 MHz
INTERNAL_OSCILLATOR_HZ = 25_000_000.0
OSCILLATOR_SETTLE_S = 500e-6  # wait after leaving SLEEP before RESTART (datasheet 7.3.1.1)


def no_wait(duration_s: float) -> None:
    """A ``wait`` that returns at once: the simulator and tests need no real delay."""


def prescale_for(frequency_hz: float, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> int:
    """PRESCALE value for ``frequency_hz``: round(osc / (4096 f)) - 1, limited to 3..255."""
    if not frequency_hz > 0:
        raise ValueError(f"PWM frequency must be positive, got {frequency_hz} Hz")
    value = int(round(oscillator_hz / (COUNTS_PER_PERIOD * frequency_hz))) - 1
    return max(PRESCALE_MIN, min(PRESCALE_MAX, value))


def frequency_for(prescale: int, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> float:
    """The PWM frequency in Hz the chip really runs at with ``prescale``."""
    return oscillator_hz / (COUNTS_PER_PERIOD * (prescale + 1))


@dataclass
@schema_defaults("parts/pca9685.schema.json")
class Pca9685Config:
    """Where the PCA9685 is and how it is clocked (robot profile ``pca9685:``)."""

    # I2C bus number: /dev/i2c-1 on a Raspberry Pi.
    bus: int
    # 7-bit I2C address; 0x40 on the Adafruit HAT with no address jumpers soldered.
    address: int
    # Oscillator frequency in Hz. Nominally 25 MHz, but real chips are off by a few
    # percent: measure the output period with a scope and put the calibrated value here.
    oscillator_hz: float
    # PWM frequency in Hz. 50 Hz suits analog servos and RC ESCs; every channel shares it.
    frequency_hz: float

    def __post_init__(self) -> None:
        if not 0 <= self.bus:
            raise ValueError(f"pca9685.bus must be >= 0, got {self.bus}")
        if not 0x03 <= self.address <= 0x77:
            raise ValueError(f"pca9685.address must be a 7-bit I2C address (0x03..0x77), got {self.address}")
        if not 1e6 <= self.oscillator_hz <= 50e6:
            raise ValueError(f"pca9685.oscillator_hz must be 1..50 MHz, got {self.oscillator_hz}")
        if not 1.0 <= self.frequency_hz <= 3500.0:
            raise ValueError(f"pca9685.frequency_hz must be 1..3500 Hz, got {self.frequency_hz}")

    @classmethod
    def from_dict(cls, d: Any) -> "Pca9685Config":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "pca9685")


class Pca9685:
    """Register-level PCA9685 driver: frequency, raw counts, pulses in seconds, full on/off.

    Nothing is written until a method is called. :meth:`start` must run
    before pulses can be set (it programs the frequency and turns on register
    auto-increment). OSErrors from the bus are counted in ``errors``,
    reported as ``pca9685_i2c_error`` and answered with ``False``.
    """

    def __init__(
        self,
        bus: SMBusLike,
        address: int = 0x40,
        oscillator_hz: float = INTERNAL_OSCILLATOR_HZ,
        events: EventSink = ignore_events,
    ) -> None:
        self.bus = bus
        self.address = address
        self.oscillator_hz = float(oscillator_hz)
        self.events = events
        self.errors = 0
        """I2C transactions that failed since construction."""
        self.prescale: Optional[int] = None
        """PRESCALE programmed by the last successful :meth:`start`, else None."""
        self._auto_increment = False  # block writes are only safe once MODE1.AI is set

    # --- state ---------------------------------------------------------------------
    @property
    def frequency_hz(self) -> Optional[float]:
        """The actual PWM frequency in Hz (from the programmed prescale), None before start."""
        if self.prescale is None:
            return None
        return frequency_for(self.prescale, self.oscillator_hz)

    @property
    def period_s(self) -> Optional[float]:
        """One PWM period in seconds, None before start."""
        f = self.frequency_hz
        return None if f is None else 1.0 / f

    # --- low level ---------------------------------------------------------------------
    def _fail(self, what: str, exc: OSError) -> bool:
        self.errors += 1
        self.events("pca9685_i2c_error", f"PCA9685 at 0x{self.address:02x}: {what} failed: {exc}")
        return False

    def _reject(self, text: str) -> bool:
        self.events("pca9685_bad_request", f"PCA9685 at 0x{self.address:02x}: {text}")
        return False

    def _write_channel(self, channel: int, regs: list[int]) -> None:
        base = LED0_ON_L + 4 * channel
        if self._auto_increment:
            # One transaction, so ON and OFF change together within one PWM period.
            self.bus.write_i2c_block_data(self.address, base, regs)
        else:
            for i, value in enumerate(regs):
                self.bus.write_byte_data(self.address, base + i, value)

    # --- public ---------------------------------------------------------------------
    def start(self, frequency_hz: float, wait: Callable[[float], None] = no_wait) -> bool:
        """Program the PWM frequency (Hz) and wake the chip with auto-increment on.

        Sequence (datasheet 7.3.1.1 and 7.3.5): MODE2 = OUTDRV; read MODE1;
        MODE1 = SLEEP (PRESCALE is only writable asleep); PRESCALE; MODE1
        restored (awake); ``wait(500 us)`` for the oscillator; MODE1 |=
        RESTART | AI. ``wait`` is a sleeper the real runtime passes; the
        default returns at once (the emulator needs no delay). Returns False
        (and reports) when the bus fails or the frequency is invalid.
        """
        try:
            prescale = prescale_for(frequency_hz, self.oscillator_hz)
        except ValueError as exc:
            return self._reject(str(exc))
        try:
            self.bus.write_byte_data(self.address, MODE2, MODE2_OUTDRV)
            old = self.bus.read_byte_data(self.address, MODE1)
            # Never write RESTART back (writing 1 would restart stale channels) and
            # never keep SLEEP in the "awake" value we restore.
            awake = old & ~(MODE1_RESTART | MODE1_SLEEP) & 0xFF
            self.bus.write_byte_data(self.address, MODE1, awake | MODE1_SLEEP)
            self.bus.write_byte_data(self.address, PRESCALE, prescale)
            self.bus.write_byte_data(self.address, MODE1, awake)
            wait(OSCILLATOR_SETTLE_S)
            self.bus.write_byte_data(self.address, MODE1, awake | MODE1_RESTART | MODE1_AI)
        except OSError as exc:
            self.prescale = None
            self._auto_increment = False
            return self._fail(f"start at {frequency_hz} Hz", exc)
        self.prescale = prescale
        self._auto_increment = True
        return True

    def set_counts(self, channel: int, on: int, off: int) -> bool:
        """Set a channel's raw 12-bit ON and OFF counts (0..4095): high from ``on`` to ``off``."""
        if not 0 <= channel < CHANNELS:
            return self._reject(f"no channel {channel} (0..15)")
        if not (0 <= on <= MAX_COUNT and 0 <= off <= MAX_COUNT):
            return self._reject(f"counts on={on} off={off} outside 0..4095 on channel {channel}")
        try:
            self._write_channel(channel, [on & 0xFF, (on >> 8) & 0x0F, off & 0xFF, (off >> 8) & 0x0F])
        except OSError as exc:
            return self._fail(f"setting channel {channel}", exc)
        return True

    def counts_for(self, pulse_s: float) -> Optional[int]:
        """The OFF count for a pulse of ``pulse_s`` seconds at the actual frequency (None before start)."""
        f = self.frequency_hz
        if f is None:
            return None
        return int(round(pulse_s * f * COUNTS_PER_PERIOD))

    def set_pulse(self, channel: int, pulse_s: float, limits_s: Optional[tuple[float, float]] = None) -> bool:
        """Output a high pulse of ``pulse_s`` seconds each period on ``channel``.

        Counts come from the actual (prescaled, calibrated) frequency. A pulse
        of zero is fully off; a pulse of a whole period or more is rejected
        (use :meth:`full_on`). False before :meth:`start`. With ``limits_s``
        = (min, max) seconds, rounding to whole counts never leaves that range
        (the count is moved one step inwards instead).
        """
        if not (isinstance(pulse_s, numbers.Real) and math.isfinite(pulse_s)) or pulse_s < 0:
            return self._reject(f"pulse {pulse_s!r} s is not a valid pulse on channel {channel}")
        counts = self.counts_for(pulse_s)
        if counts is None:
            return self._reject(f"pulse on channel {channel} requested before start()")
        if counts > MAX_COUNT:
            return self._reject(f"pulse {pulse_s!r} s does not fit in one period on channel {channel}")
        if limits_s is not None:
            count_s = 1.0 / (self.frequency_hz * COUNTS_PER_PERIOD)  # type: ignore[operator]
            lo_s, hi_s = limits_s
            if counts * count_s > hi_s + 1e-12:
                counts -= 1
            elif counts * count_s < lo_s - 1e-12:
                counts += 1
        if counts == 0:
            return self.full_off(channel)
        return self.set_counts(channel, 0, counts)

    def set_duty(self, channel: int, duty: float) -> bool:
        """Output a duty cycle ``duty`` (0..1, fraction of the period) on ``channel``."""
        if not (math.isfinite(duty) and 0.0 <= duty <= 1.0):
            return self._reject(f"duty {duty!r} outside 0..1 on channel {channel}")
        counts = int(round(duty * COUNTS_PER_PERIOD))
        if counts <= 0:
            return self.full_off(channel)
        if counts >= COUNTS_PER_PERIOD:
            return self.full_on(channel)
        return self.set_counts(channel, 0, counts)

    def full_on(self, channel: int) -> bool:
        """Hold ``channel`` high (ON_H bit 4, OFF_H bit 4 cleared)."""
        if not 0 <= channel < CHANNELS:
            return self._reject(f"no channel {channel} (0..15)")
        try:
            self._write_channel(channel, [0, FULL_BIT, 0, 0])
        except OSError as exc:
            return self._fail(f"full_on channel {channel}", exc)
        return True

    def full_off(self, channel: int) -> bool:
        """Hold ``channel`` low (OFF_H bit 4, which wins over everything else)."""
        if not 0 <= channel < CHANNELS:
            return self._reject(f"no channel {channel} (0..15)")
        try:
            self._write_channel(channel, [0, 0, 0, FULL_BIT])
        except OSError as exc:
            return self._fail(f"full_off channel {channel}", exc)
        return True

    def all_off(self) -> bool:
        """Turn every channel fully off at once through the ALL_LED registers.

        Two single-byte writes, so it works before :meth:`start` too: clear
        the full-on bit, then set the full-off bit (which has priority).
        """
        try:
            self.bus.write_byte_data(self.address, ALL_LED_ON_H, 0)
            self.bus.write_byte_data(self.address, ALL_LED_OFF_H, FULL_BIT)
        except OSError as exc:
            return self._fail("all_off", exc)
        return True


# ===================================================================================
# Servos
# ===================================================================================


@dataclass
@schema_defaults("parts/servos.schema.json#/$defs/servo", required=("channel",))
class ServoCalibration:
    """How one hobby servo on a PCA9685 channel maps angles to pulses (profile ``servos.<name>``).

    The centre pulse is the middle of the angle range; angles between the
    ends map linearly on each side of it, so a servo whose centre is not
    exactly halfway between its end pulses still centres correctly.
    """

    # PCA9685 channel the servo's signal wire is on (0..15).
    channel: int
    # Pulse in milliseconds at one end of travel (min_angle_deg for direction +1).
    # Find it by stepping the pulse until the horn stops moving, then back off a little.
    min_pulse_ms: float
    # Pulse in milliseconds at the middle of the angle range.
    center_pulse_ms: float
    # Pulse in milliseconds at the other end of travel (max_angle_deg for direction +1).
    max_pulse_ms: float
    # Angle in degrees reached at min_pulse_ms (direction +1). Commands below are clamped.
    min_angle_deg: float
    # Angle in degrees reached at max_pulse_ms (direction +1). Commands above are clamped.
    max_angle_deg: float
    # +1 when a longer pulse turns towards max_angle_deg; -1 when the servo is mounted reversed.
    direction: int

    def __post_init__(self) -> None:
        if not 0 <= self.channel < CHANNELS:
            raise ValueError(f"channel must be 0..15, got {self.channel}")
        if not 0.0 < self.min_pulse_ms < self.center_pulse_ms < self.max_pulse_ms <= 10.0:
            raise ValueError(
                "pulses must satisfy 0 < min_pulse_ms < center_pulse_ms < max_pulse_ms <= 10, got "
                f"{self.min_pulse_ms}, {self.center_pulse_ms}, {self.max_pulse_ms}"
            )
        if not self.min_angle_deg < self.max_angle_deg:
            raise ValueError(f"min_angle_deg must be below max_angle_deg, got {self.min_angle_deg} >= {self.max_angle_deg}")
        if self.direction not in (1, -1):
            raise ValueError(f"direction must be 1 or -1, got {self.direction}")

    @classmethod
    def from_dict(cls, d: Any, name: str = "servo") -> "ServoCalibration":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, f"servos.{name}")

    def clamp_angle_deg(self, angle_deg: float) -> float:
        """``angle_deg`` limited to the calibrated range."""
        return max(self.min_angle_deg, min(self.max_angle_deg, angle_deg))

    def pulse_ms_for(self, angle_deg: float) -> float:
        """The pulse in ms for ``angle_deg`` (clamped first: never outside min..max pulse)."""
        a = self.clamp_angle_deg(angle_deg)
        mid = 0.5 * (self.min_angle_deg + self.max_angle_deg)
        half = 0.5 * (self.max_angle_deg - self.min_angle_deg)
        u = (a - mid) / half * self.direction  # -1..1, +1 towards max_pulse_ms
        if u >= 0:
            pulse = self.center_pulse_ms + u * (self.max_pulse_ms - self.center_pulse_ms)
        else:
            pulse = self.center_pulse_ms + u * (self.center_pulse_ms - self.min_pulse_ms)
        # Belt and braces against rounding: the result must stay inside the range.
        return max(self.min_pulse_ms, min(self.max_pulse_ms, pulse))

    def angle_deg_for(self, pulse_ms: float) -> float:
        """The angle in degrees a pulse of ``pulse_ms`` points the servo at (inverse of :meth:`pulse_ms_for`)."""
        p = max(self.min_pulse_ms, min(self.max_pulse_ms, pulse_ms))
        if p >= self.center_pulse_ms:
            u = (p - self.center_pulse_ms) / (self.max_pulse_ms - self.center_pulse_ms)
        else:
            u = (p - self.center_pulse_ms) / (self.center_pulse_ms - self.min_pulse_ms)
        mid = 0.5 * (self.min_angle_deg + self.max_angle_deg)
        half = 0.5 * (self.max_angle_deg - self.min_angle_deg)
        return mid + u * self.direction * half

    def limits_s(self) -> tuple[float, float]:
        """(min, max) pulse in seconds: the range this servo may ever be driven with."""
        return self.min_pulse_ms / 1000.0, self.max_pulse_ms / 1000.0

    def pulse_in_range(self, pulse_ms: float) -> bool:
        """True when ``pulse_ms`` lies within this servo's calibrated pulse range."""
        return math.isfinite(pulse_ms) and self.min_pulse_ms <= pulse_ms <= self.max_pulse_ms


def servo_calibrations_from_dict(d: Any) -> dict[str, ServoCalibration]:
    """Build the profile's ``servos:`` mapping (name -> calibration); ``ValueError`` when invalid.

    Two servos on one channel are rejected: one of them would be driven with
    the other's calibration.
    """
    if d is None:
        return {}
    if not isinstance(d, Mapping):
        raise ValueError(f"servos: expected a mapping of name -> calibration, got {type(d).__name__}")
    out: dict[str, ServoCalibration] = {}
    by_channel: dict[int, str] = {}
    for name, body in d.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"servos: servo names must be non-empty strings, got {name!r}")
        cal = ServoCalibration.from_dict(body, name)
        if cal.channel in by_channel:
            raise ValueError(f"servos.{name}: channel {cal.channel} is already used by '{by_channel[cal.channel]}'")
        by_channel[cal.channel] = name
        out[name] = cal
    return out


class PcaServos:
    """Servos on a PCA9685, addressed by name (angle) or by channel (raw pulse).

    Implements :class:`beastbt.actuation.adapter.ServoAdapter`. By name: the
    angle (``ServoCommand.angle_rad``) is clamped to the servo's calibrated
    range and turned into a pulse. By channel: ``pulse_s`` must lie inside
    the calibrated range of the servo on that channel, else the command is
    refused (False and a ``servo_rejected`` event); channels without a
    calibrated servo are refused, since there is no known safe range.
    The chip must have been started (:meth:`Pca9685.start`) at servo rate.
    """

    def __init__(
        self,
        pca: Pca9685,
        servos: Mapping[str, ServoCalibration],
        events: EventSink = ignore_events,
    ) -> None:
        self.pca = pca
        self.servos = dict(servos)
        self.events = events
        self._by_channel = {cal.channel: name for name, cal in self.servos.items()}
        self._angle_rad: dict[str, float] = {}

    def servo_names(self) -> list[str]:
        """Names of the calibrated servos, in profile order."""
        return list(self.servos)

    def angle_of(self, name: str) -> Optional[float]:
        """The last angle (radians, after clamping) successfully commanded to ``name``, or None.

        A raw pulse command by channel counts too: its angle is the calibrated
        angle that pulse corresponds to.
        """
        return self._angle_rad.get(name)

    def _reject(self, text: str) -> bool:
        self.events("servo_rejected", text)
        return False

    def set_servo(self, cmd: ServoCommand, now_s: float) -> bool:
        """Command one servo; False when unknown, out of range or the I2C write failed."""
        if cmd.name is not None:
            cal = self.servos.get(cmd.name)
            if cal is None:
                return self._reject(f"no servo named '{cmd.name}' (have: {', '.join(self.servos) or 'none'})")
            if cmd.angle_rad is None or not math.isfinite(cmd.angle_rad):
                return self._reject(f"servo '{cmd.name}': no valid angle in the command")
            angle_deg = cal.clamp_angle_deg(math.degrees(cmd.angle_rad))
            if not self.pca.set_pulse(cal.channel, cal.pulse_ms_for(angle_deg) / 1000.0, cal.limits_s()):
                return False
            self._angle_rad[cmd.name] = math.radians(angle_deg)
            return True
        if cmd.channel is not None:
            name = self._by_channel.get(cmd.channel)
            if name is None:
                return self._reject(f"no calibrated servo on channel {cmd.channel}: refusing to guess a safe pulse")
            cal = self.servos[name]
            if cmd.pulse_s is None:
                return self._reject(f"channel {cmd.channel}: no pulse in the command")
            pulse_ms = cmd.pulse_s * 1000.0
            if not cal.pulse_in_range(pulse_ms):
                return self._reject(
                    f"pulse {pulse_ms:.3f} ms on channel {cmd.channel} ('{name}') is outside "
                    f"{cal.min_pulse_ms}..{cal.max_pulse_ms} ms"
                )
            if not self.pca.set_pulse(cal.channel, cmd.pulse_s, cal.limits_s()):
                return False
            self._angle_rad[name] = math.radians(cal.angle_deg_for(pulse_ms))
            return True
        return self._reject("servo command names neither a servo nor a channel")
