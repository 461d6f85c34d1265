"""An emulated PCA9685 PWM chip for :class:`beastbt.sim.i2c_bus.SimI2CBus`.

It holds the real register map and applies the rules the driver must obey:
PRESCALE only takes a write while MODE1.SLEEP is set; block accesses only
move to the next register when MODE1.AI is set; bit 4 of ON_H/OFF_H means
fully on/off (off wins); writes to ALL_LED (0xFA..0xFD) go to all sixteen
channels. The simulator and tests read the outputs back as a frequency, a
pulse width in seconds or a duty cycle.
"""

from __future__ import annotations

from typing import Optional

from beastbt.devices.pca9685 import (
    ALL_LED_OFF_H,
    ALL_LED_ON_L,
    CHANNELS,
    COUNTS_PER_PERIOD,
    FULL_BIT,
    INTERNAL_OSCILLATOR_HZ,
    LED0_ON_L,
    MODE1,
    MODE1_AI,
    MODE1_RESTART,
    MODE1_SLEEP,
    MODE2,
    PRESCALE,
    PRESCALE_MIN,
    frequency_for,
)
from beastbt.core.bounded import trim_front
from beastbt.sim.i2c_bus import WRITES_KEPT, RegisterDevice

# Power-on register values (datasheet table 4 and 7.3): asleep with ALLCALL,
# totem-pole outputs, 200 Hz prescale, every channel fully off.
POWER_ON_MODE1 = MODE1_SLEEP | 0x01
POWER_ON_MODE2 = 0x04
POWER_ON_PRESCALE = 0x1E


class SimPca9685(RegisterDevice):
    """The PCA9685 register map with its write rules; outputs readable per channel.

    ``oscillator_hz`` is the chip's true clock (set it a few percent off
    25 MHz to exercise a profile's calibrated frequency). ``ignored_writes``
    counts writes the chip discarded (PRESCALE while awake).
    """

    def __init__(self, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> None:
        super().__init__()
        self.oscillator_hz = float(oscillator_hz)
        self.ignored_writes = 0
        self.restarts = 0
        """How many times a RESTART brought the channels back after sleep."""
        self.registers[MODE1] = POWER_ON_MODE1
        self.registers[MODE2] = POWER_ON_MODE2
        self.registers[PRESCALE] = POWER_ON_PRESCALE
        for ch in range(CHANNELS):
            self.registers[LED0_ON_L + 4 * ch + 3] = FULL_BIT

    # --- register semantics ---------------------------------------------------------
    @property
    def sleeping(self) -> bool:
        """True while MODE1.SLEEP is set (oscillator off, all outputs off)."""
        return bool(self.registers[MODE1] & MODE1_SLEEP)

    @property
    def auto_increment(self) -> bool:
        """True while MODE1.AI is set (block accesses walk through registers)."""
        return bool(self.registers[MODE1] & MODE1_AI)

    def write(self, register: int, value: int) -> None:
        """Apply one byte write with the chip's rules (logged in ``writes`` as sent)."""
        register &= 0xFF
        value &= 0xFF
        self.writes.append((register, value))
        trim_front(self.writes, WRITES_KEPT)
        if register == MODE1:
            self._write_mode1(value)
        elif register == PRESCALE:
            if self.sleeping:
                # The chip forces anything below 3 up to 3.
                self.registers[PRESCALE] = max(PRESCALE_MIN, value)
            else:
                self.ignored_writes += 1
        elif ALL_LED_ON_L <= register <= ALL_LED_OFF_H:
            offset = register - ALL_LED_ON_L
            for ch in range(CHANNELS):
                self.registers[LED0_ON_L + 4 * ch + offset] = value
            # The ALL_LED registers themselves read back as zero.
        else:
            self.registers[register] = value
        self.on_write(register, value)

    def _write_mode1(self, value: int) -> None:
        old = self.registers[MODE1]
        new = value & ~MODE1_RESTART
        restart_flag = old & MODE1_RESTART
        if (old & MODE1_SLEEP) == 0 and (value & MODE1_SLEEP):
            # Going to sleep while running: the chip remembers to restart (datasheet 7.3.1.1).
            restart_flag = MODE1_RESTART
        if (value & MODE1_RESTART) and restart_flag and not (value & MODE1_SLEEP):
            # Writing 1 to a set RESTART bit restarts the PWM and clears the bit.
            restart_flag = 0
            self.restarts += 1
        self.registers[MODE1] = (new | restart_flag) & 0xFF

    def on_read(self, register: int) -> int:
        """Read a register; the write-only ALL_LED registers read as zero."""
        register &= 0xFF
        if ALL_LED_ON_L <= register <= ALL_LED_OFF_H:
            return 0
        return self.registers[register]

    def next_register(self, register: int) -> int:
        """Block accesses advance only with MODE1.AI set; without it they stay on one register."""
        if self.auto_increment:
            return (register + 1) & 0xFF
        return register

    # --- outputs --------------------------------------------------------------------------
    def frequency_hz(self) -> float:
        """The PWM frequency in Hz the prescale and oscillator give."""
        return frequency_for(self.registers[PRESCALE], self.oscillator_hz)

    def counts(self, channel: int) -> tuple[int, int, bool, bool]:
        """``(on, off, full_on, full_off)`` as programmed for ``channel`` (12-bit counts)."""
        base = LED0_ON_L + 4 * channel
        on_l, on_h, off_l, off_h = self.registers[base : base + 4]
        return on_l | ((on_h & 0x0F) << 8), off_l | ((off_h & 0x0F) << 8), bool(on_h & FULL_BIT), bool(off_h & FULL_BIT)

    def duty(self, channel: int) -> float:
        """Fraction of each period ``channel`` is high (0 when asleep or fully off, 1 fully on)."""
        if not 0 <= channel < CHANNELS:
            raise ValueError(f"no channel {channel} (0..15)")
        if self.sleeping:
            return 0.0
        on, off, full_on, full_off = self.counts(channel)
        if full_off:
            return 0.0
        if full_on:
            return 1.0
        return ((off - on) % COUNTS_PER_PERIOD) / COUNTS_PER_PERIOD

    def pulse_s(self, channel: int) -> Optional[float]:
        """High time per period in seconds, or None when the output is a constant level (no pulse)."""
        d = self.duty(channel)
        if d <= 0.0 or d >= 1.0:
            return None
        return d / self.frequency_hz()
