"""PwmBase on an emulated PCA9685, read back by the PWM motor emulator."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import pytest

from beastbt.actuation.pwm_base import PwmBase, PwmBaseConfig
from beastbt.blackboard.types import VelocityCommand
from beastbt.devices.pca9685 import Pca9685
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.pca9685_emulator import SimPca9685
from beastbt.sim.pwm_motor_emulator import SimPwmMotors

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas" / "parts"


def rig(cfg: PwmBaseConfig, wiring: PwmBaseConfig | None = None):
    bus = SimI2CBus()
    chip = SimPca9685()
    bus.attach(0x40, chip)
    events: list[tuple[str, str]] = []
    base = PwmBase(Pca9685(bus), cfg, events=lambda k, t: events.append((k, t)))
    base.start(0.0)
    return bus, chip, base, SimPwmMotors(chip, wiring or cfg), events


def test_esc_start_programs_50hz_and_outputs_neutral():
    bus, chip, base, motors, _ = rig(PwmBaseConfig())
    assert chip.registers[0xFE] == 121
    assert chip.pulse_s(0) * 1e3 == pytest.approx(1.5, abs=0.005)
    assert chip.pulse_s(1) * 1e3 == pytest.approx(1.5, abs=0.005)
    assert motors.wheel_targets_mps() == (0.0, 0.0)


def test_esc_forward_turn_and_reverse_pulses():
    cfg = PwmBaseConfig(max_wheel_speed_mps=0.5, track_width_m=0.2)
    bus, chip, base, motors, _ = rig(cfg)
    base.send_velocity(VelocityCommand(0.25, 0.0), 0.1)
    assert chip.pulse_s(0) * 1e3 == pytest.approx(1.75, abs=0.005)
    assert motors.wheel_targets_mps() == pytest.approx((0.25, 0.25), abs=0.002)
    # Turn in place CCW at 1 rad/s: left -0.1 m/s, right +0.1 m/s
    base.send_velocity(VelocityCommand(0.0, 1.0), 0.2)
    assert chip.pulse_s(0) * 1e3 == pytest.approx(1.4, abs=0.005)
    assert chip.pulse_s(1) * 1e3 == pytest.approx(1.6, abs=0.005)
    assert motors.wheel_targets_mps() == pytest.approx((-0.1, 0.1), abs=0.002)


def test_too_fast_is_scaled_keeping_curvature():
    cfg = PwmBaseConfig(max_wheel_speed_mps=0.5, track_width_m=0.2)
    bus, chip, base, motors, _ = rig(cfg)
    base.send_velocity(VelocityCommand(1.0, 2.0), 0.0)  # wants 0.8 / 1.2 m/s
    left, right = motors.wheel_targets_mps()
    assert right == pytest.approx(0.5, abs=0.006)  # one count is ~0.005 m/s here
    assert left / right == pytest.approx(0.8 / 1.2, abs=0.01)
    assert 1.0 <= chip.pulse_s(0) * 1e3 <= 2.0 and 1.0 <= chip.pulse_s(1) * 1e3 <= 2.0


def test_invert_flag_compensates_a_mirrored_motor():
    wiring = PwmBaseConfig(invert_right=True)
    # The driver knows about the mirrored motor: the robot goes straight forward.
    bus, chip, base, motors, _ = rig(wiring, wiring)
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.0)
    assert chip.pulse_s(1) * 1e3 < 1.5  # the right ESC gets a "reverse" pulse
    assert motors.wheel_targets_mps() == pytest.approx((0.2, 0.2), abs=0.002)
    # A profile that forgets the flag spins the robot.
    bus, chip, base, motors, _ = rig(PwmBaseConfig(), wiring)
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.0)
    assert motors.wheel_targets_mps() == pytest.approx((0.2, -0.2), abs=0.002)


def test_emergency_stop_and_close_send_neutral():
    bus, chip, base, motors, _ = rig(PwmBaseConfig())
    base.send_velocity(VelocityCommand(0.4, 0.5), 0.0)
    assert motors.wheel_targets_mps() != (0.0, 0.0)
    base.emergency_stop(0.1)
    assert chip.pulse_s(0) * 1e3 == pytest.approx(1.5, abs=0.005)
    assert motors.wheel_targets_mps() == (0.0, 0.0)
    base.send_velocity(VelocityCommand(0.4, 0.0), 0.2)
    base.close()
    assert motors.wheel_targets_mps() == (0.0, 0.0)
    assert base.poll(0.3) == []


def test_hbridge_duty_and_direction():
    cfg = PwmBaseConfig(mode="hbridge", frequency_hz=1000.0, max_wheel_speed_mps=0.5)
    bus, chip, base, motors, _ = rig(cfg)
    assert chip.registers[0xFE] == 5  # round(25e6 / 4096e3) - 1
    assert chip.duty(0) == 0.0 and chip.duty(1) == 0.0
    base.send_velocity(VelocityCommand(-0.25, 0.0), 0.0)
    assert chip.duty(0) == pytest.approx(0.5, abs=1e-3)
    assert chip.duty(2) == 1.0 and chip.duty(3) == 1.0  # both direction pins: reverse
    assert motors.wheel_targets_mps() == pytest.approx((-0.25, -0.25), abs=1e-3)
    base.send_velocity(VelocityCommand(0.5, 0.0), 0.1)
    assert chip.duty(0) == 1.0 and chip.duty(2) == 0.0
    assert motors.wheel_targets_mps() == pytest.approx((0.5, 0.5))
    base.emergency_stop(0.2)
    assert [chip.duty(ch) for ch in range(4)] == [0.0, 0.0, 0.0, 0.0]


def test_i2c_failure_is_counted_and_survived():
    bus, chip, base, motors, events = rig(PwmBaseConfig())
    bus.fail_next = 1
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.0)  # must not raise
    assert base.failed_writes == 1
    base.send_velocity(VelocityCommand(0.2, 0.0), 0.1)
    assert motors.wheel_targets_mps() == pytest.approx((0.2, 0.2), abs=0.002)


def test_non_finite_command_stops():
    bus, chip, base, motors, events = rig(PwmBaseConfig())
    base.send_velocity(VelocityCommand(0.3, 0.0), 0.0)
    base.send_velocity(VelocityCommand(math.nan, 0.0), 0.1)
    assert motors.wheel_targets_mps() == (0.0, 0.0)
    assert events and events[-1][0] == "pwm_base_bad_command"


def test_unpowered_esc_signal_means_stop():
    bus, chip, base, motors, _ = rig(PwmBaseConfig())
    base.send_velocity(VelocityCommand(0.3, 0.0), 0.0)
    base.pca.all_off()
    assert motors.wheel_targets_mps() == (0.0, 0.0)


def test_config_from_dict_and_schema():
    schema = json.loads((SCHEMAS / "pwm_base.schema.json").read_text())
    cfg = PwmBaseConfig()
    assert set(schema["properties"]) == set(vars(cfg))
    for key, value in vars(cfg).items():
        assert schema["properties"][key]["default"] == value
    d = {"mode": "hbridge", "left_channel": 4, "right_channel": 5, "left_dir_channel": 6, "right_dir_channel": 7, "max_wheel_speed_mps": 1}
    jsonschema.validate(d, schema)
    assert PwmBaseConfig.from_dict(d).max_wheel_speed_mps == 1.0
    with pytest.raises(ValueError, match="did you mean 'track_width_m'"):
        PwmBaseConfig.from_dict({"trak_width_m": 0.3})
    with pytest.raises(ValueError, match="own channel"):
        PwmBaseConfig.from_dict({"left_channel": 1, "right_channel": 1})
    with pytest.raises(ValueError, match="mode"):
        PwmBaseConfig.from_dict({"mode": "servo"})


def test_a_pwm_base_without_odometry_is_said_at_validate_at_start_and_at_the_failure(tmp_path):
    import os
    import subprocess
    import sys

    from conftest import REPO

    def beastbt(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, timeout=120,
                              cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(REPO)))

    patrol, pwm = str(REPO / "missions" / "patrol.yaml"), str(REPO / "robots" / "diy_pwm.yaml")
    checked = beastbt("validate", patrol, "--robot", pwm)
    assert checked.returncode == 0 and "patrol.yaml:17:18: warning: robot 'diy_pwm' has no odometry" in checked.stderr
    assert "this turn cannot measure how far it turned" in checked.stderr
    assert "no odometry" not in beastbt("validate", patrol, "--robot", "ugv_beast").stderr  # it reports wheel travel
    assert beastbt("validate", patrol, "--robot", pwm, "--strict").returncode == 2
    ran = beastbt("run", patrol, "--robot", pwm, "--sim", "--no-record", "--summary", "s.json")
    assert ran.returncode == 1
    assert "warning: robot 'diy_pwm' has no odometry" in ran.stderr  # said before it starts
    failed = next(line for line in ran.stdout.splitlines() if "step_failed" in line)
    assert "no odometry: this robot's base reports no wheel travel" in failed and "drive: {time: 20 s" in failed
    assert "after 0.00 m" not in ran.stdout  # no 'blocked after 0.00 m' beside a summary saying it moved
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["distance_m"] > 0.3  # it did move (the truth), and the failure no longer says otherwise
