"""The emulated MPU9250 / AK8963 register maps, spoken to byte by byte as a driver would."""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.devices import mpu9250 as hw
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.imu_emulator import ImuNoiseModel, SimAk8963, attach_imu
from beastbt.sim.truth import RobotTruth

QUIET = ImuNoiseModel(gyro_noise_density_rps_sqrthz=0.0, gyro_bias_sigma_rps=0.0, gyro_bias_walk_rps_sqrts=0.0,
                      accel_noise_density_mps2_sqrthz=0.0, mag_noise_ut=0.0)
MPU = hw.MPU9250_DEFAULT_ADDRESS
AK = hw.AK8963_DEFAULT_ADDRESS


def _words_be(raw: list[int]) -> list[int]:
    return [int.from_bytes(bytes(raw[i:i + 2]), "big", signed=True) for i in range(0, len(raw), 2)]


def _wake(bus: SimI2CBus) -> None:
    bus.write_byte_data(MPU, hw.REG_PWR_MGMT_1, hw.PWR_MGMT_1_CLKSEL_AUTO)


def _mag_on(bus: SimI2CBus, mode: int = hw.AK_MODE_CONTINUOUS_100HZ | hw.AK_CNTL1_16BIT) -> None:
    bus.write_byte_data(MPU, hw.REG_INT_PIN_CFG, hw.INT_PIN_CFG_BYPASS_EN)
    bus.write_byte_data(AK, hw.AK_REG_CNTL1, mode)


def test_who_am_i_and_override() -> None:
    bus = SimI2CBus()
    attach_imu(bus, QUIET, np.random.default_rng(0))
    assert bus.read_byte_data(MPU, hw.REG_WHO_AM_I) == 0x71
    bus.write_byte_data(MPU, hw.REG_WHO_AM_I, 0x00)  # read-only
    assert bus.read_byte_data(MPU, hw.REG_WHO_AM_I) == 0x71
    bus2 = SimI2CBus()
    attach_imu(bus2, ImuNoiseModel(whoami=0x68), np.random.default_rng(0))
    assert bus2.read_byte_data(MPU, hw.REG_WHO_AM_I) == 0x68


def test_asleep_until_woken_then_samples_appear() -> None:
    bus = SimI2CBus()
    imu = attach_imu(bus, QUIET, np.random.default_rng(0))
    imu.update(RobotTruth(), 0.01)
    assert bus.read_i2c_block_data(MPU, hw.REG_ACCEL_XOUT_H, 14) == [0] * 14
    _wake(bus)
    imu.update(RobotTruth(), 0.01)
    ax, ay, az, _t, gx, gy, gz = _words_be(bus.read_i2c_block_data(MPU, hw.REG_ACCEL_XOUT_H, 14))
    assert (ax, ay, gx, gy, gz) == (0, 0, 0, 0, 0)
    assert az == 16384  # +1 g on z at the power-on full scale of +-2 g


def test_h_reset_puts_it_back_to_sleep_and_cuts_bypass() -> None:
    bus = SimI2CBus()
    imu = attach_imu(bus, QUIET, np.random.default_rng(0))
    _wake(bus)
    _mag_on(bus)
    assert bus.read_byte_data(AK, hw.AK_REG_WIA) == 0x48
    bus.write_byte_data(MPU, hw.REG_PWR_MGMT_1, hw.PWR_MGMT_1_H_RESET)
    assert not imu.mpu.awake
    with pytest.raises(OSError):
        bus.read_byte_data(AK, hw.AK_REG_WIA)


@pytest.mark.parametrize("fs_sel,lsb_per_g", [(0, 16384), (1, 8192), (2, 4096), (3, 2048)])
def test_accel_full_scale_changes_lsb(fs_sel: int, lsb_per_g: int) -> None:
    bus = SimI2CBus()
    imu = attach_imu(bus, QUIET, np.random.default_rng(0))
    _wake(bus)
    bus.write_byte_data(MPU, hw.REG_ACCEL_CONFIG, fs_sel << 3)
    imu.update(RobotTruth(), 0.01)
    az = _words_be(bus.read_i2c_block_data(MPU, hw.REG_ACCEL_XOUT_H + 4, 2))[0]
    assert az == lsb_per_g


@pytest.mark.parametrize("fs_sel,lsb_per_dps", [(0, 131.0), (1, 65.5), (2, 32.8), (3, 16.4)])
def test_gyro_full_scale_changes_lsb(fs_sel: int, lsb_per_dps: float) -> None:
    bus = SimI2CBus()
    imu = attach_imu(bus, QUIET, np.random.default_rng(0))
    _wake(bus)
    bus.write_byte_data(MPU, hw.REG_GYRO_CONFIG, fs_sel << 3)
    imu.update(RobotTruth(w_rps=math.radians(100.0)), 0.01)
    gz = _words_be(bus.read_i2c_block_data(MPU, hw.REG_GYRO_XOUT_H + 4, 2))[0]
    assert gz == round(100.0 * lsb_per_dps)


def test_gyro_saturates_at_full_scale() -> None:
    bus = SimI2CBus()
    imu = attach_imu(bus, QUIET, np.random.default_rng(0))
    _wake(bus)  # +-250 deg/s
    imu.update(RobotTruth(w_rps=math.radians(400.0)), 0.01)
    assert _words_be(bus.read_i2c_block_data(MPU, hw.REG_GYRO_XOUT_H + 4, 2))[0] == 32767


def test_int_status_data_ready_clears_on_read() -> None:
    bus = SimI2CBus()
    imu = attach_imu(bus, QUIET, np.random.default_rng(0))
    _wake(bus)
    imu.update(RobotTruth(), 0.01)
    assert bus.read_byte_data(MPU, hw.REG_INT_STATUS) & 0x01
    assert not bus.read_byte_data(MPU, hw.REG_INT_STATUS) & 0x01


def test_bypass_makes_magnetometer_reachable() -> None:
    bus = SimI2CBus()
    attach_imu(bus, QUIET, np.random.default_rng(0))
    with pytest.raises(OSError):
        bus.read_byte_data(AK, hw.AK_REG_WIA)
    bus.write_byte_data(MPU, hw.REG_INT_PIN_CFG, hw.INT_PIN_CFG_BYPASS_EN)
    assert bus.read_byte_data(AK, hw.AK_REG_WIA) == 0x48
    # the MPU's own I2C master takes the auxiliary bus away again
    bus.write_byte_data(MPU, hw.REG_USER_CTRL, hw.USER_CTRL_I2C_MST_EN)
    with pytest.raises(OSError):
        bus.read_byte_data(AK, hw.AK_REG_WIA)


def test_no_magnetometer_when_absent() -> None:
    bus = SimI2CBus()
    attach_imu(bus, ImuNoiseModel(mag_present=False), np.random.default_rng(0))
    bus.write_byte_data(MPU, hw.REG_INT_PIN_CFG, hw.INT_PIN_CFG_BYPASS_EN)
    with pytest.raises(OSError):
        bus.read_byte_data(AK, hw.AK_REG_WIA)


def test_fuse_rom_only_in_fuse_mode_and_modes_change_via_power_down() -> None:
    ak = SimAk8963(asa=(0xA0, 0x80, 0x60))
    assert [ak.on_read(r) for r in (0x10, 0x11, 0x12)] == [0, 0, 0]
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_FUSE_ROM)
    assert [ak.on_read(r) for r in (0x10, 0x11, 0x12)] == [0xA0, 0x80, 0x60]
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_CONTINUOUS_100HZ | hw.AK_CNTL1_16BIT)  # not via power-down
    assert ak.mode == hw.AK_MODE_FUSE_ROM and ak.ignored_mode_changes == 1
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_POWER_DOWN)
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_CONTINUOUS_100HZ | hw.AK_CNTL1_16BIT)
    assert ak.mode == hw.AK_MODE_CONTINUOUS_100HZ


def _ak_sample(ak: SimAk8963) -> tuple[int, list[int], int]:
    raw = [ak.on_read(r) for r in range(0x02, 0x0A)]
    return raw[0], [int.from_bytes(bytes(raw[i:i + 2]), "little", signed=True) for i in (1, 3, 5)], raw[7]


def test_ak_raw_is_field_over_asa_and_resolution() -> None:
    ak = SimAk8963(asa=(128 + 64, 128, 128 - 64))  # factors 1.25, 1.0, 0.75
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_CONTINUOUS_100HZ | hw.AK_CNTL1_16BIT)
    ak.advance(0.01, np.array((30.0, -15.0, 45.0)))
    st1, (hx, hy, hz), st2 = _ak_sample(ak)
    assert st1 & hw.AK_ST1_DRDY and st2 & hw.AK_ST2_BITM and not st2 & hw.AK_ST2_HOFL
    assert (hx, hy, hz) == (round(30 / 0.15 / 1.25), round(-15 / 0.15), round(45 / 0.15 / 0.75))


def test_ak_14_bit_mode_resolution() -> None:
    ak = SimAk8963(asa=(128, 128, 128))
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_CONTINUOUS_8HZ)
    ak.advance(0.125, np.array((30.0, 0.0, 0.0)))
    _st1, (hx, _hy, _hz), st2 = _ak_sample(ak)
    assert hx == 50 and not st2 & hw.AK_ST2_BITM


def test_ak_sample_rate_follows_mode() -> None:
    ak = SimAk8963()
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_CONTINUOUS_8HZ | hw.AK_CNTL1_16BIT)
    ak.advance(0.1, np.array((10.0, 0.0, 0.0)))
    assert not ak.on_read(hw.AK_REG_ST1) & hw.AK_ST1_DRDY  # 8 Hz: nothing after 0.1 s
    ak.advance(0.03, np.array((10.0, 0.0, 0.0)))
    assert ak.on_read(hw.AK_REG_ST1) & hw.AK_ST1_DRDY


def test_ak_data_latched_until_st2_read() -> None:
    ak = SimAk8963(asa=(128, 128, 128))
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_CONTINUOUS_100HZ | hw.AK_CNTL1_16BIT)
    ak.advance(0.01, np.array((15.0, 0.0, 0.0)))
    assert ak.on_read(hw.AK_REG_HXL) == 100  # read started: data now protected
    ak.advance(0.01, np.array((30.0, 0.0, 0.0)))  # a new measurement completes meanwhile
    assert ak.on_read(hw.AK_REG_HXL) == 100  # still the old sample
    ak.on_read(hw.AK_REG_ST2)  # releases: the waiting measurement comes in, flagged as overrun
    st1, (hx, _, _), _ = _ak_sample(ak)
    assert hx == 200
    assert st1 & hw.AK_ST1_DRDY and st1 & hw.AK_ST1_DOR
    # after the complete read DRDY is clear until the next measurement
    assert not ak.on_read(hw.AK_REG_ST1) & hw.AK_ST1_DRDY


def test_ak_overflow_flag() -> None:
    ak = SimAk8963()
    ak.write(hw.AK_REG_CNTL1, hw.AK_MODE_CONTINUOUS_100HZ | hw.AK_CNTL1_16BIT)
    ak.advance(0.01, np.array((3000.0, 2000.0, 0.0)))  # |x|+|y|+|z| beyond 4912 uT
    assert _ak_sample(ak)[2] & hw.AK_ST2_HOFL
    ak.advance(0.01, np.array((30.0, 20.0, 0.0)))
    assert not _ak_sample(ak)[2] & hw.AK_ST2_HOFL
    ak.force_overflow = True  # fault injection: a magnet next to the sensor
    ak.advance(0.01, np.array((30.0, 20.0, 0.0)))
    assert _ak_sample(ak)[2] & hw.AK_ST2_HOFL


def test_sample_content_follows_truth_in_sensor_axes() -> None:
    """Body accel (v-dot, v*w), gravity on z, yaw rate on z; mag on the AK8963's swapped axes."""
    bus = SimI2CBus()
    model = ImuNoiseModel(gyro_noise_density_rps_sqrthz=0.0, gyro_bias_sigma_rps=0.0, gyro_bias_walk_rps_sqrts=0.0,
                          accel_noise_density_mps2_sqrthz=0.0, mag_noise_ut=0.0,
                          mag_field_ut=50.0, mag_inclination_deg=60.0, mag_declination_deg=0.0)
    imu = attach_imu(bus, model, np.random.default_rng(0), mag_asa=(128, 128, 128))
    _wake(bus)
    bus.write_byte_data(MPU, hw.REG_ACCEL_CONFIG, 1 << 3)  # +-4 g
    _mag_on(bus)
    imu.update(RobotTruth(v_mps=0.0, w_rps=0.0, yaw=0.0), 0.01)
    imu.update(RobotTruth(v_mps=0.5, w_rps=0.4, yaw=0.0), 0.1)  # v-dot = 5 m/s^2, v*w = 0.2 m/s^2
    ax, ay, az, _t, _gx, _gy, gz = _words_be(bus.read_i2c_block_data(MPU, hw.REG_ACCEL_XOUT_H, 14))
    lsb = 8192 / hw.STANDARD_GRAVITY_MPS2
    assert ax == round(5.0 * lsb) and ay == round(0.2 * lsb) and az == 8192
    assert gz == round(math.degrees(0.4) * 131.0)
    # facing east (yaw 0): magnetic north is to the left (+y), the field dips down (-z)
    hx, hy, hz = _ak_sample(imu.ak)[1]
    horizontal = 50.0 * math.cos(math.radians(60.0)) / 0.15
    vertical = 50.0 * math.sin(math.radians(60.0)) / 0.15
    assert hx == round(horizontal)  # AK X = accel Y (left)
    assert hy == 0  # AK Y = accel X (forward)
    assert hz == round(vertical)  # AK Z = -accel Z: down is positive


def test_noise_and_bias_are_seeded() -> None:
    def run(seed: int) -> list[int]:
        bus = SimI2CBus()
        imu = attach_imu(bus, ImuNoiseModel(), np.random.default_rng(seed))
        _wake(bus)
        out = []
        for _ in range(5):
            imu.update(RobotTruth(), 0.01)
            out += bus.read_i2c_block_data(MPU, hw.REG_ACCEL_XOUT_H, 14)
        return out

    assert run(3) == run(3)
    assert run(3) != run(4)


def test_noise_model_from_dict() -> None:
    m = ImuNoiseModel.from_dict({"mag_field_ut": 58.0, "mag_declination_deg": 12.5, "mag_hard_iron_ut": [1, 2, 3]})
    assert m.mag_field_ut == 58.0 and m.mag_hard_iron_ut == (1.0, 2.0, 3.0)
    with pytest.raises(ValueError, match="mag_feild_ut"):
        ImuNoiseModel.from_dict({"mag_feild_ut": 50})
    with pytest.raises(ValueError, match="gyro_bias_sigma_rps"):
        ImuNoiseModel.from_dict({"gyro_bias_sigma_rps": -1.0})
    e, n, u = ImuNoiseModel(mag_field_ut=50.0, mag_inclination_deg=0.0, mag_declination_deg=90.0) \
        .earth_field_enu_ut()
    assert e == pytest.approx(50.0) and abs(n) < 1e-9 and abs(u) < 1e-9
