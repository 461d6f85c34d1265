"""The MPU9250 driver against the emulated chip: scaling, axes, magnetometer, bias and faults."""

from __future__ import annotations

import json
import math
from dataclasses import fields
from pathlib import Path
from typing import Optional

import jsonschema
import numpy as np
import pytest

from beastbt.blackboard.types import ImuSample
from beastbt.devices import mpu9250 as hw
from beastbt.devices.mpu9250 import ImuConfig, Mpu9250, rotation_from_axes
from beastbt.core.clock import SimClock
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.imu_emulator import ImuNoiseModel, SimImu, attach_imu
from beastbt.sim.truth import RobotTruth

G = hw.STANDARD_GRAVITY_MPS2
QUIET = ImuNoiseModel(gyro_noise_density_rps_sqrthz=0.0, gyro_bias_sigma_rps=0.0, gyro_bias_walk_rps_sqrts=0.0,
                      accel_noise_density_mps2_sqrthz=0.0, mag_noise_ut=0.0)
SCHEMA = Path(__file__).resolve().parents[1] / "schemas" / "parts" / "imu_device.schema.json"


class Rig:
    """A driver, the emulated IMU on a bus, a simulated clock and the events seen."""

    def __init__(self, model: ImuNoiseModel = QUIET, config: Optional[ImuConfig] = None, seed: int = 0,
                 body_from_sensor: Optional[np.ndarray] = None, mag_asa: tuple[int, int, int] = (128, 128, 128),
                 attach: bool = True, start: bool = True) -> None:
        self.bus = SimI2CBus()
        self.clock = SimClock()
        self.events: list[tuple[str, str]] = []
        self.imu: Optional[SimImu] = None
        if attach:
            self.imu = attach_imu(self.bus, model, np.random.default_rng(seed), body_from_sensor=body_from_sensor,
                                  mag_asa=mag_asa)
        self.driver = Mpu9250(self.bus, self.clock, lambda k, t: self.events.append((k, t)),
                              config if config is not None else ImuConfig(bias_window_s=0.0))
        if attach and start:
            self.driver.start()

    def step(self, truth: RobotTruth = RobotTruth(), dt_s: float = 0.01) -> Optional[ImuSample]:
        self.clock.advance(dt_s)
        if self.imu is not None:
            self.imu.update(truth, dt_s)
        return self.driver.poll()

    def kinds(self) -> list[str]:
        return [k for k, _ in self.events]


def test_start_configures_the_chip() -> None:
    rig = Rig(config=ImuConfig(gyro_range_dps=1000, accel_range_g=8, dlpf=4, sample_rate_hz=200.0), start=False)
    assert rig.driver.start()
    assert rig.driver.model == "MPU9250" and rig.driver.mag_running
    mpu = rig.imu.mpu
    assert mpu.awake and mpu.bypass_enabled
    assert mpu.gyro_range_dps == 1000 and mpu.accel_range_g == 8
    assert mpu.registers[hw.REG_CONFIG] == 4 and mpu.registers[hw.REG_ACCEL_CONFIG2] == 4
    assert mpu.registers[hw.REG_SMPLRT_DIV] == 4  # 1000 Hz / (1 + 4) = 200 Hz
    assert rig.imu.ak.mode == hw.AK_MODE_CONTINUOUS_100HZ
    assert rig.imu.ak.registers[hw.AK_REG_CNTL1] & hw.AK_CNTL1_16BIT
    assert rig.imu.ak.ignored_mode_changes == 0  # every mode change went through power-down
    assert rig.events == []


def test_mpu9255_is_accepted() -> None:
    rig = Rig(model=ImuNoiseModel(whoami=0x73), start=False)
    assert rig.driver.start() and rig.driver.model == "MPU9255"


@pytest.mark.parametrize("gyro_range_dps", [250, 500, 1000, 2000])
def test_gyro_scaling_each_full_scale(gyro_range_dps: int) -> None:
    rig = Rig(config=ImuConfig(gyro_range_dps=gyro_range_dps, bias_window_s=0.0))
    sample = rig.step(RobotTruth(w_rps=1.2))
    lsb_rps = math.radians(1.0) / hw.GYRO_LSB_PER_DPS[gyro_range_dps]
    assert sample.gyro_rps[2] == pytest.approx(1.2, abs=lsb_rps)
    assert abs(sample.gyro_rps[0]) < 1e-12 and abs(sample.gyro_rps[1]) < 1e-12


@pytest.mark.parametrize("accel_range_g", [2, 4, 8, 16])
def test_accel_scaling_each_full_scale(accel_range_g: int) -> None:
    rig = Rig(config=ImuConfig(accel_range_g=accel_range_g, bias_window_s=0.0))
    rig.step(RobotTruth(v_mps=0.0))
    sample = rig.step(RobotTruth(v_mps=0.1), 0.1)  # 1 m/s^2 forward
    lsb = G / hw.ACCEL_LSB_PER_G[accel_range_g]
    assert sample.accel_mps2[2] == pytest.approx(G, abs=lsb)
    assert sample.accel_mps2[0] == pytest.approx(1.0, abs=lsb)
    assert sample.temperature_c == pytest.approx(25.0, abs=0.01)


def test_axes_follow_the_body_frame() -> None:
    """x forward, y left, z up; turning left is +z; north-facing sees the field ahead and down."""
    rig = Rig()
    rig.step(RobotTruth(v_mps=0.5, w_rps=0.5, yaw=math.pi / 2))
    s = rig.step(RobotTruth(v_mps=0.6, w_rps=0.5, yaw=math.pi / 2), 0.1)
    assert s.gyro_rps[2] == pytest.approx(0.5, abs=1e-3)
    assert s.accel_mps2[0] == pytest.approx(1.0, abs=0.01)       # speeding up
    assert s.accel_mps2[1] == pytest.approx(0.3, abs=0.01)       # centripetal, towards the left
    assert s.accel_mps2[2] == pytest.approx(G, abs=0.01)
    horizontal_t = 50e-6 * math.cos(math.radians(60.0))
    vertical_t = 50e-6 * math.sin(math.radians(60.0))
    mx, my, mz = s.mag_t
    assert mx == pytest.approx(horizontal_t, abs=0.3e-6)         # facing magnetic north
    assert my == pytest.approx(0.0, abs=0.3e-6)
    assert mz == pytest.approx(-vertical_t, abs=0.3e-6)          # northern hemisphere: field points down
    s = rig.step(RobotTruth(yaw=0.0))                            # facing east: north is to the left
    assert s.mag_t[1] == pytest.approx(horizontal_t, abs=0.3e-6) and abs(s.mag_t[0]) < 0.3e-6


@pytest.mark.parametrize("config_kw", [
    {"mounting_axes": ("-y", "x", "z")},          # board turned 90 deg: its y points forward... reversed
    {"mounting_rpy_deg": (180.0, 0.0, 0.0)},      # board upside down
    {"mounting_rpy_deg": (0.0, 0.0, 135.0)},
])
def test_mounting_rotation_gives_body_axes(config_kw: dict) -> None:
    config = ImuConfig(bias_window_s=0.0, **config_kw)
    rig = Rig(config=config, body_from_sensor=config.body_from_sensor())
    rig.step(RobotTruth(v_mps=0.5, w_rps=0.3, yaw=0.4))
    s = rig.step(RobotTruth(v_mps=0.6, w_rps=0.3, yaw=0.4), 0.1)
    ref = Rig()
    ref.step(RobotTruth(v_mps=0.5, w_rps=0.3, yaw=0.4))
    r = ref.step(RobotTruth(v_mps=0.6, w_rps=0.3, yaw=0.4), 0.1)
    assert np.allclose(s.gyro_rps, r.gyro_rps, atol=2e-3)
    assert np.allclose(s.accel_mps2, r.accel_mps2, atol=0.01)
    assert np.allclose(s.mag_t, r.mag_t, atol=0.4e-6)
    assert s.accel_mps2[2] == pytest.approx(G, abs=0.01)


def test_wrong_mounting_is_visible() -> None:
    """Sanity check of the previous test: a board mounted upside down but configured upright reads -g."""
    rig = Rig(body_from_sensor=rotation_from_axes(("x", "-y", "-z")))
    s = rig.step(RobotTruth())
    assert s.accel_mps2[2] == pytest.approx(-G, abs=0.01)


def test_magnetometer_sensitivity_adjustment_is_applied() -> None:
    asa = (0xB0, 0x70, 0x95)
    rig = Rig(mag_asa=asa)
    s = rig.step(RobotTruth(yaw=0.7))
    assert rig.driver.mag_asa == pytest.approx([(a - 128) / 256 + 1 for a in asa])
    assert np.linalg.norm(s.mag_t) == pytest.approx(50e-6, abs=0.3e-6)
    # the chip's raw counts alone would be wrong by the factors
    raw = [int.from_bytes(bytes(rig.imu.ak.registers[r:r + 2]), "little", signed=True) for r in (3, 5, 7)]
    assert np.linalg.norm(np.array(raw) * 0.15e-6) == pytest.approx(50e-6 / 1.1, rel=0.1)


def test_hard_and_soft_iron_calibration() -> None:
    model = ImuNoiseModel(gyro_noise_density_rps_sqrthz=0.0, gyro_bias_sigma_rps=0.0, gyro_bias_walk_rps_sqrts=0.0,
                          accel_noise_density_mps2_sqrthz=0.0, mag_noise_ut=0.0, mag_hard_iron_ut=(12.0, -7.0, 4.0))
    plain = Rig(model=model).step(RobotTruth(yaw=0.0))
    assert plain.mag_t[0] == pytest.approx(12e-6, abs=0.3e-6)  # offset shows up uncorrected
    calibrated = Rig(model=model, config=ImuConfig(bias_window_s=0.0, mag_offset_ut=(12.0, -7.0, 4.0),
                                                   mag_scale=(1.0, 2.0, 1.0))).step(RobotTruth(yaw=0.0))
    assert abs(calibrated.mag_t[0]) < 0.3e-6
    assert calibrated.mag_t[1] == pytest.approx(2 * 25e-6, abs=0.5e-6)  # soft-iron factor on y


def test_magnetometer_overflow_drops_only_the_field() -> None:
    rig = Rig()
    assert rig.step().mag_t is not None
    rig.imu.ak.force_overflow = True
    s = rig.step()
    assert s is not None and s.mag_t is None and s.accel_mps2[2] == pytest.approx(G, abs=0.01)
    assert rig.driver.mag_overflow_count == 1
    assert rig.kinds() == ["imu_mag_overflow"]
    rig.imu.ak.force_overflow = False
    rig.step()  # the overflowed sample was latched; this one is clean
    assert rig.step().mag_t is not None


def test_magnetometer_slower_than_polling_gives_none_between_samples() -> None:
    rig = Rig(config=ImuConfig(bias_window_s=0.0, mag_rate_hz=8))
    got = [rig.step(dt_s=0.05).mag_t is not None for _ in range(20)]  # 1 s at 20 Hz
    assert 7 <= sum(got) <= 9


def test_missing_magnetometer_is_reported_and_imu_still_works() -> None:
    rig = Rig(model=ImuNoiseModel(mag_present=False))
    s = rig.step()
    assert s is not None and s.mag_t is None and not rig.driver.mag_running
    assert rig.kinds() == ["imu_mag_missing"]


def test_gyro_bias_estimated_at_rest() -> None:
    rig = Rig(model=ImuNoiseModel(), config=ImuConfig(bias_window_s=2.0), seed=5)
    true_bias = rig.imu.true_gyro_bias_body_rps()
    assert np.abs(true_bias).max() > 0.005  # the seed gives a bias worth finding
    first = rig.step()
    assert not rig.driver.bias_ready
    assert first.gyro_rps[2] == pytest.approx(true_bias[2], abs=0.005)  # raw until estimated
    for _ in range(100):
        rig.step()
    assert not rig.driver.bias_ready
    # provisional: the running mean is subtracted already, so the output does not jump later
    assert abs(rig.step().gyro_rps[2]) < 0.005
    for _ in range(150):
        rig.step()
    assert rig.driver.bias_ready
    assert np.allclose(rig.driver.gyro_bias_rps, true_bias, atol=1e-3)
    after = np.array([rig.step().gyro_rps for _ in range(100)])
    assert np.abs(after.mean(axis=0)).max() < 1e-3


def test_bias_window_restarts_while_moving() -> None:
    rig = Rig(model=ImuNoiseModel(), config=ImuConfig(bias_window_s=1.0), seed=6)
    for k in range(150):  # 1.5 s of wiggling turns
        rig.step(RobotTruth(w_rps=0.5 * math.sin(k * 0.2)))
    assert not rig.driver.bias_ready
    for _ in range(80):
        rig.step()
    assert not rig.driver.bias_ready  # 0.8 s still: the window is not full yet
    for _ in range(40):
        rig.step()
    assert rig.driver.bias_ready
    assert np.allclose(rig.driver.gyro_bias_rps, rig.imu.true_gyro_bias_body_rps(), atol=1.5e-3)


def test_steady_turn_is_not_taken_for_bias() -> None:
    rig = Rig(model=ImuNoiseModel(), config=ImuConfig(bias_window_s=1.0), seed=7)
    for _ in range(300):
        rig.step(RobotTruth(w_rps=0.6))
    assert not rig.driver.bias_ready


def test_missing_device_reports_and_never_raises() -> None:
    rig = Rig(attach=False)
    assert rig.driver.start() is False
    assert rig.kinds() == ["imu_missing"]
    assert "0x68" in rig.events[0][1]
    for _ in range(300):  # 3 s of polling a missing device
        assert rig.step() is None
    # retried every reinit_interval_s, but reported at most once per event_interval_s
    assert rig.kinds() == ["imu_missing"]


def test_wrong_who_am_i() -> None:
    rig = Rig(model=ImuNoiseModel(whoami=0x68), start=False)
    assert rig.driver.start() is False
    kind, text = rig.events[0]
    assert kind == "imu_wrong_id" and "0x68" in text and "0x71" in text
    assert rig.step() is None
    assert not rig.imu.mpu.awake  # nothing was written to a chip we do not know


def test_single_i2c_error_is_retried() -> None:
    rig = Rig()
    rig.step()
    rig.bus.fail_next = 1
    s = rig.step()
    assert s is not None and rig.driver.error_count == 1 and rig.driver.failed_reads == 0
    assert rig.events == []


def test_persistent_i2c_error_makes_data_stale_and_is_reported() -> None:
    rig = Rig(config=ImuConfig(bias_window_s=0.0, retries=2))
    rig.step()
    rig.bus.fail_next = 3  # more than the retries
    assert rig.step() is None
    assert rig.driver.failed_reads == 1 and rig.driver.error_count == 3
    assert rig.kinds() == ["imu_i2c_error"]
    assert rig.step() is not None


def test_i2c_error_events_are_rate_limited() -> None:
    rig = Rig(config=ImuConfig(bias_window_s=0.0, retries=0, failures_before_reinit=1000, event_interval_s=5.0))
    rig.step()
    for _ in range(50):
        rig.bus.fail_next = 1
        assert rig.step() is None
    assert rig.kinds() == ["imu_i2c_error"]
    rig.clock.advance(5.0)
    rig.bus.fail_next = 1
    rig.step()
    assert rig.kinds() == ["imu_i2c_error", "imu_i2c_error"]
    assert "49 more" in rig.events[-1][1]


def test_lost_device_is_reinitialised() -> None:
    config = ImuConfig(bias_window_s=0.0, failures_before_reinit=5, reinit_interval_s=0.5, gyro_range_dps=2000)
    rig = Rig(config=config)
    assert rig.step(RobotTruth(w_rps=1.0)) is not None
    mpu = rig.imu.mpu
    rig.bus.detach(hw.MPU9250_DEFAULT_ADDRESS)  # unplugged
    for _ in range(10):
        assert rig.step() is None
    assert "imu_lost" in rig.kinds()
    # plugged back in: the chip powered up again with its defaults (asleep, +-250 deg/s)
    rig.bus.attach(hw.MPU9250_DEFAULT_ADDRESS, mpu)
    mpu.write(hw.REG_PWR_MGMT_1, hw.PWR_MGMT_1_H_RESET)
    samples = [rig.step(RobotTruth(w_rps=1.0)) for _ in range(60)]
    assert samples[-1] is not None
    assert samples[-1].gyro_rps[2] == pytest.approx(1.0, abs=0.01)  # configured again, right scale
    assert "imu_reinit" in rig.kinds()


def test_config_from_dict_and_errors() -> None:
    cfg = ImuConfig.from_dict({"gyro_range_dps": 2000, "mag_offset_ut": [1, 2, 3],
                               "mag_scale": [[1, 0, 0], [0, 1.1, 0], [0, 0, 0.9]], "mounting_axes": ["y", "-x", "z"]})
    assert cfg.mag_offset_ut == (1.0, 2.0, 3.0)
    assert np.allclose(cfg.mag_scale_matrix(), np.diag([1.0, 1.1, 0.9]))
    assert np.allclose(cfg.body_from_sensor() @ np.array([1.0, 0.0, 0.0]), [0.0, -1.0, 0.0])
    with pytest.raises(ValueError, match="gyro_range_dps"):
        ImuConfig.from_dict({"gyro_range": 500})
    with pytest.raises(ValueError, match="250, 500"):
        ImuConfig.from_dict({"gyro_range_dps": 300})
    with pytest.raises(ValueError, match="right-handed"):
        ImuConfig.from_dict({"mounting_axes": ["x", "y", "-z"]})
    with pytest.raises(ValueError, match="not both"):
        ImuConfig.from_dict({"mounting_axes": ["x", "y", "z"], "mounting_rpy_deg": [0, 0, 90]})


def test_schema_matches_the_config() -> None:
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["additionalProperties"] is False
    props = schema["properties"]
    assert set(props) == {f.name for f in fields(ImuConfig)}
    for f in fields(ImuConfig):
        default = f.default if not isinstance(f.default, tuple) else json.loads(json.dumps(f.default))
        assert props[f.name]["default"] == default, f.name
        assert "Default" in props[f.name]["description"]
    validator = jsonschema.Draft202012Validator(schema)
    validator.validate({"gyro_range_dps": 1000, "mag_scale": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]})
    assert list(validator.iter_errors({"gyro_rnage_dps": 1000}))
    assert list(validator.iter_errors({"gyro_range_dps": 300}))


def test_a_slow_steady_turn_is_not_learnt_as_bias_while_the_wheels_say_they_turn() -> None:
    # 0.05 rad/s is under bias_max_rps and steady: to the gyro alone it looks like a bias (the first rig learns it).
    # With the wheels' word that they turn, the window never fills and nothing of the turn is subtracted.
    turning = RobotTruth(w_rps=0.05)
    alone = Rig(model=ImuNoiseModel(), config=ImuConfig(bias_window_s=1.0), seed=8)
    for _ in range(300):
        alone.step(turning)
    true_z = alone.imu.true_gyro_bias_body_rps()[2]
    assert alone.driver.bias_ready and alone.driver.gyro_bias_rps[2] - true_z > 0.04
    told = Rig(model=ImuNoiseModel(), config=ImuConfig(bias_window_s=1.0), seed=8)
    told.driver.standstill = lambda: False
    for _ in range(300):
        sample = told.step(turning)
    assert not told.driver.bias_ready
    assert abs(told.driver.gyro_bias_rps[2]) < 0.01  # nothing learnt: the turn stays in the output
    assert sample is not None and abs(sample.gyro_rps[2] - true_z - 0.05) < 0.02
    told.driver.standstill = lambda: True  # the wheels stop: the window fills as before
    for _ in range(120):
        told.step()
    assert told.driver.bias_ready
    assert np.allclose(told.driver.gyro_bias_rps, told.imu.true_gyro_bias_body_rps(), atol=1.5e-3)
