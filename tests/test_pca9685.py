"""PCA9685 driver, emulator and servos: exact register traffic against datasheet arithmetic."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import pytest

from beastbt.blackboard.types import ServoCommand
from beastbt.devices.pca9685 import (
    ALL_LED_OFF_H,
    ALL_LED_ON_H,
    LED0_ON_L,
    MODE1,
    MODE2,
    PRESCALE,
    Pca9685,
    Pca9685Config,
    PcaServos,
    ServoCalibration,
    prescale_for,
    servo_calibrations_from_dict,
)
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.pca9685_emulator import SimPca9685

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas" / "parts"


class Recorder:
    def __init__(self) -> None:
        self.events: list[tuple[str, str]] = []

    def __call__(self, kind: str, text: str) -> None:
        self.events.append((kind, text))

    def kinds(self) -> list[str]:
        return [k for k, _ in self.events]


def make(osc_hz: float = 25e6, chip_osc_hz: float = 25e6):
    bus = SimI2CBus()
    chip = SimPca9685(oscillator_hz=chip_osc_hz)
    bus.attach(0x40, chip)
    ev = Recorder()
    return bus, chip, Pca9685(bus, oscillator_hz=osc_hz, events=ev), ev


# --- frequency -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "freq, expected",
    [(50, 121), (60, 101), (200, 30), (1000, 5), (1526, 3), (5000, 3), (24, 253), (10, 255)],
)
def test_prescale_matches_datasheet_formula(freq, expected):
    # round(25e6 / (4096 f)) - 1, limited to 3..255
    assert prescale_for(freq) == expected


def test_start_writes_sleep_prescale_restore_restart_in_order():
    bus, chip, pca, _ = make()
    waits: list[float] = []
    assert pca.start(50.0, wait=waits.append)
    # Power-on MODE1 is 0x11 (SLEEP | ALLCALL): the awake value keeps ALLCALL only.
    assert chip.writes == [
        (MODE2, 0x04),  # OUTDRV
        (MODE1, 0x11),  # SLEEP set before PRESCALE
        (PRESCALE, 121),
        (MODE1, 0x01),  # restored, awake
        (MODE1, 0xA1),  # RESTART | AI
    ]
    assert waits == [pytest.approx(500e-6)]
    assert chip.registers[PRESCALE] == 121
    assert not chip.sleeping and chip.auto_increment
    assert chip.frequency_hz() == pytest.approx(25e6 / (4096 * 122))
    assert pca.frequency_hz == pytest.approx(50.0288, abs=1e-3)


def test_wait_is_called_between_wake_and_restart():
    bus, chip, pca, _ = make()
    seen: list[list] = []
    pca.start(50.0, wait=lambda s: seen.append(list(chip.writes)))
    # At the moment of waiting the chip is awake but RESTART|AI not yet written.
    assert seen[0][-1] == (MODE1, 0x01)


def test_restart_after_running_clears_restart_bit():
    bus, chip, pca, _ = make()
    pca.start(50.0)
    pca.start(60.0)  # second start from a running chip: sleep sets RESTART, restart clears it
    assert chip.registers[PRESCALE] == 101
    assert chip.registers[MODE1] & 0x80 == 0
    assert chip.restarts == 1
    assert chip.writes[-4:] == [(MODE1, 0x31), (PRESCALE, 101), (MODE1, 0x21), (MODE1, 0xA1)]


def test_emulator_ignores_prescale_written_while_awake():
    bus, chip, pca, _ = make()
    pca.start(50.0)
    bus.write_byte_data(0x40, PRESCALE, 30)
    assert chip.registers[PRESCALE] == 121
    assert chip.ignored_writes == 1


def test_emulator_block_write_needs_auto_increment():
    bus = SimI2CBus()
    chip = SimPca9685()
    bus.attach(0x40, chip)
    bus.write_byte_data(0x40, MODE1, 0x01)  # awake, AI off
    bus.write_i2c_block_data(0x40, LED0_ON_L, [1, 2, 3, 4])
    assert list(chip.registers[LED0_ON_L : LED0_ON_L + 4]) == [4, 0, 0, 0x10]  # all landed on ON_L
    bus.write_byte_data(0x40, MODE1, 0x21)  # AI on
    bus.write_i2c_block_data(0x40, LED0_ON_L, [1, 2, 3, 4])
    assert list(chip.registers[LED0_ON_L : LED0_ON_L + 4]) == [1, 2, 3, 4]


def test_calibrated_oscillator_gives_true_pulse():
    # The chip runs 3 % fast; the profile's calibrated oscillator compensates.
    bus, chip, pca, _ = make(osc_hz=25.75e6, chip_osc_hz=25.75e6)
    pca.start(50.0)
    assert pca.set_pulse(0, 1.5e-3)
    assert chip.pulse_s(0) == pytest.approx(1.5e-3, abs=6e-6)  # within one count (~4.9 us)
    # An uncalibrated driver on the same chip is off by the oscillator error.
    bus2, chip2, pca2, _ = make(osc_hz=25e6, chip_osc_hz=25.75e6)
    pca2.start(50.0)
    pca2.set_pulse(0, 1.5e-3)
    assert abs(chip2.pulse_s(0) - 1.5e-3) > 20e-6


# --- pulses and counts ------------------------------------------------------------------


def test_center_pulse_is_307_counts_with_exact_bytes():
    bus, chip, pca, _ = make()
    pca.start(50.0)
    n = len(chip.writes)
    assert pca.set_pulse(3, 1.5e-3)
    # channel 3 starts at 0x06 + 12 = 0x12; ON = 0, OFF = 307 = 0x133
    assert chip.writes[n:] == [(0x12, 0x00), (0x13, 0x00), (0x14, 0x33), (0x15, 0x01)]
    assert chip.counts(3) == (0, 307, False, False)
    assert pca.counts_for(1.0e-3) == 205 and pca.counts_for(2.0e-3) == 410


def test_set_counts_and_duty_read_back():
    bus, chip, pca, _ = make()
    pca.start(50.0)
    assert pca.set_counts(15, 100, 1124)
    assert chip.duty(15) == pytest.approx(1024 / 4096)
    assert pca.set_counts(14, 4000, 100)  # wraps around the period end
    assert chip.duty(14) == pytest.approx(196 / 4096)


def test_full_on_full_off_and_priority():
    bus, chip, pca, _ = make()
    pca.start(50.0)
    assert pca.full_on(2)
    assert chip.duty(2) == 1.0 and chip.pulse_s(2) is None
    assert chip.counts(2)[2:] == (True, False)
    assert pca.full_off(2)
    assert chip.duty(2) == 0.0 and chip.pulse_s(2) is None
    # Both bits set: off wins (datasheet).
    bus.write_byte_data(0x40, LED0_ON_L + 4 * 2 + 1, 0x10)
    assert chip.counts(2)[2:] == (True, True) and chip.duty(2) == 0.0


def test_all_off_uses_all_led_registers_and_works_before_start():
    bus, chip, pca, _ = make()
    bus.write_byte_data(0x40, MODE1, 0x01)  # awake but never started: AI off
    for ch in range(16):
        bus.write_byte_data(0x40, LED0_ON_L + 4 * ch + 1, 0x10)  # everything fully on
        bus.write_byte_data(0x40, LED0_ON_L + 4 * ch + 3, 0x00)  # (power-on full-off bit cleared)
    assert chip.duty(7) == 1.0
    assert pca.all_off()
    assert chip.writes[-2:] == [(ALL_LED_ON_H, 0), (ALL_LED_OFF_H, 0x10)]
    assert all(chip.duty(ch) == 0.0 for ch in range(16))
    assert bus.read_byte_data(0x40, ALL_LED_OFF_H) == 0  # ALL_LED reads back zero


def test_sleeping_chip_outputs_nothing():
    bus, chip, pca, _ = make()
    pca.start(50.0)
    pca.set_pulse(0, 1.5e-3)
    bus.write_byte_data(0x40, MODE1, 0x31)
    assert chip.pulse_s(0) is None and chip.duty(0) == 0.0


def test_bad_requests_refused_without_writes():
    bus, chip, pca, ev = make()
    assert not pca.set_pulse(0, 1.5e-3)  # before start: frequency unknown
    pca.start(50.0)
    n = len(chip.writes)
    assert not pca.set_pulse(0, 0.021)  # longer than the 20 ms period
    assert not pca.set_pulse(0, -1e-3)
    assert not pca.set_pulse(0, math.nan)
    assert not pca.set_counts(16, 0, 10)
    assert not pca.set_counts(0, 0, 4096)
    assert not pca.set_duty(0, 1.5)
    assert len(chip.writes) == n
    assert ev.kinds().count("pca9685_bad_request") == 7


def test_i2c_errors_are_counted_not_raised():
    bus, chip, pca, ev = make()
    pca.start(50.0)
    bus.fail_next = 1
    assert pca.set_pulse(0, 1.5e-3) is False
    assert pca.errors == 1 and "pca9685_i2c_error" in ev.kinds()
    assert pca.set_pulse(0, 1.5e-3) is True
    bus.detach(0x40)
    assert pca.full_off(0) is False and pca.all_off() is False
    assert pca.errors == 3


def test_failed_start_leaves_driver_unstarted():
    bus, chip, pca, ev = make()
    bus.fail_next = 1
    assert not pca.start(50.0)
    assert pca.frequency_hz is None
    assert not pca.set_pulse(0, 1.5e-3)


# --- servos -------------------------------------------------------------------------


def servos(ev=None, **extra):
    bus, chip, pca, ev0 = make()
    pca.start(50.0)
    cal = {
        "pan": ServoCalibration(channel=0),
        "tilt": ServoCalibration(channel=1, min_pulse_ms=0.8, center_pulse_ms=1.4, max_pulse_ms=2.2, min_angle_deg=-30, max_angle_deg=90, direction=-1),
    }
    cal.update(extra)
    return chip, PcaServos(pca, cal, events=ev or ev0), ev or ev0


def test_servo_angles_map_linearly_and_clamp():
    chip, s, ev = servos()
    assert s.servo_names() == ["pan", "tilt"]
    for deg, pulse_ms in [(0, 1.5), (90, 2.0), (-90, 1.0), (45, 1.75), (-45, 1.25)]:
        assert s.set_servo(ServoCommand(name="pan", angle_rad=math.radians(deg)), 0.0)
        assert chip.pulse_s(0) * 1e3 == pytest.approx(pulse_ms, abs=0.005)
    # Beyond the range: clamped to the end, never outside.
    assert s.set_servo(ServoCommand(name="pan", angle_rad=math.radians(170)), 0.0)
    assert chip.pulse_s(0) * 1e3 == pytest.approx(2.0, abs=0.005)
    assert chip.pulse_s(0) * 1e3 <= 2.0  # 2.0 ms is 409.6 counts: rounding must go down, not up
    assert s.set_servo(ServoCommand(name="pan", angle_rad=math.radians(-170)), 0.0)
    assert chip.pulse_s(0) * 1e3 >= 1.0
    assert s.angle_of("pan") == pytest.approx(math.radians(-90))
    assert s.angle_of("tilt") is None


def test_reversed_servo_with_offset_centre():
    chip, s, ev = servos()
    cal = s.servos["tilt"]
    # Centre of -30..90 is 30 deg -> 1.4 ms; direction -1: max angle -> min pulse.
    assert cal.pulse_ms_for(30) == pytest.approx(1.4)
    assert cal.pulse_ms_for(90) == pytest.approx(0.8)
    assert cal.pulse_ms_for(-30) == pytest.approx(2.2)
    assert cal.pulse_ms_for(60) == pytest.approx(1.1)
    assert cal.angle_deg_for(1.1) == pytest.approx(60)
    for deg in (-1000, -31, 500):
        assert 0.8 <= cal.pulse_ms_for(deg) <= 2.2


def test_servo_by_channel_accepts_in_range_rejects_outside():
    chip, s, ev = servos()
    assert s.set_servo(ServoCommand(channel=1, pulse_s=1.0e-3), 0.0)
    assert chip.pulse_s(1) * 1e3 == pytest.approx(1.0, abs=0.005)
    before = list(chip.writes)
    assert not s.set_servo(ServoCommand(channel=1, pulse_s=2.5e-3), 0.0)
    assert not s.set_servo(ServoCommand(channel=1, pulse_s=0.7e-3), 0.0)
    assert not s.set_servo(ServoCommand(channel=9, pulse_s=1.5e-3), 0.0)  # no calibrated servo there
    assert not s.set_servo(ServoCommand(name="gripper", angle_rad=0.0), 0.0)
    assert not s.set_servo(ServoCommand(), 0.0)
    assert chip.writes == before
    assert ev.kinds().count("servo_rejected") == 5


def test_servo_calibration_from_dict_and_schema():
    d = {"pan": {"channel": 0}, "gripper": {"channel": 3, "min_pulse_ms": 1, "max_pulse_ms": 2.4, "center_pulse_ms": 1.7, "min_angle_deg": 0, "max_angle_deg": 60}}
    cals = servo_calibrations_from_dict(d)
    assert cals["gripper"].max_pulse_ms == 2.4 and isinstance(cals["gripper"].min_pulse_ms, float)
    schema = json.loads((SCHEMAS / "servos.schema.json").read_text())
    jsonschema.validate(d, schema)
    with pytest.raises(ValueError, match="did you mean 'max_pulse_ms'"):
        servo_calibrations_from_dict({"pan": {"channel": 0, "max_puls_ms": 2.0}})
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"pan": {"channel": 0, "max_puls_ms": 2.0}}, schema)
    with pytest.raises(ValueError, match="already used"):
        servo_calibrations_from_dict({"a": {"channel": 1}, "b": {"channel": 1}})
    with pytest.raises(ValueError, match="min_pulse_ms < center_pulse_ms"):
        servo_calibrations_from_dict({"a": {"channel": 1, "center_pulse_ms": 2.5}})
    with pytest.raises(ValueError, match="expected int"):
        servo_calibrations_from_dict({"a": {"channel": True}})


def test_pca9685_config_and_schema_agree():
    schema = json.loads((SCHEMAS / "pca9685.schema.json").read_text())
    cfg = Pca9685Config()
    props = schema["properties"]
    assert set(props) == set(vars(cfg))
    for key, value in vars(cfg).items():
        assert props[key]["default"] == value
    assert Pca9685Config.from_dict({"oscillator_hz": 25500000}).oscillator_hz == 25.5e6
    with pytest.raises(ValueError, match="unknown key"):
        Pca9685Config.from_dict({"frequency": 50})
