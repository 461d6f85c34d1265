"""Emulated MPU9250 and AK8963 on a :class:`~beastbt.sim.i2c_bus.SimI2CBus`.

The emulators hold the real register maps, so the driver in
:mod:`beastbt.devices.mpu9250` runs unchanged against them: WHO_AM_I,
PWR_MGMT_1 (asleep until woken, H_RESET), full-scale bits that change the LSB
scaling, DLPF bandwidth that sets the noise, INT_PIN_CFG bypass that makes the
AK8963 reachable at 0x0C, INT_STATUS data-ready; on the AK8963 WIA, the
power-down rule between modes, the fuse ROM with the sensitivity adjustment
(ASA), ST1 DRDY/DOR, the data latch released by reading ST2, and ST2 overflow.

:func:`attach_imu` puts both on a bus; :meth:`SimImu.update` turns the robot's
true motion (:class:`~beastbt.sim.truth.RobotTruth`) into samples: gyro = body
rates + bias (constant + random walk) + white noise; accel = gravity (+1 g on
z at rest) + forward and centripetal acceleration + noise; magnetometer = the
world's Earth field rotated into the body by the true yaw + noise. All
randomness comes from the ``numpy.random.Generator`` given.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, fields
from typing import Callable, Optional, Sequence

import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.devices import mpu9250 as hw
from beastbt.core.config import dataclass_from_dict
from beastbt.core.bounded import trim_front
from beastbt.sim.i2c_bus import WRITES_KEPT, RegisterDevice, SimI2CBus
from beastbt.sim.truth import RobotTruth

GYRO_DLPF_BANDWIDTH_HZ = (250.0, 184.0, 92.0, 41.0, 20.0, 10.0, 5.0, 3600.0)
"""Gyro noise bandwidth for DLPF_CFG 0..7 (register map, CONFIG table)."""
ACCEL_DLPF_BANDWIDTH_HZ = (218.1, 218.1, 99.0, 44.8, 21.2, 10.2, 5.05, 420.0)
"""Accel noise bandwidth for A_DLPF_CFG 0..7 (register map, ACCEL_CONFIG2 table)."""
AK_MEASUREMENT_RANGE_UT = 4912.0
"""The AK8963 flags overflow (ST2 HOFL) when |X|+|Y|+|Z| reaches this."""
AK_DEFAULT_ASA = (0xB0, 0xB3, 0xA6)
"""Typical fuse-ROM adjustment values (factors about 1.17, 1.18, 1.15)."""
MPU_POWER_ON_PWR_MGMT_1 = hw.PWR_MGMT_1_SLEEP
"""The emulator powers up asleep, so a driver that forgets to wake it reads zeros."""

_MPU_READ_ONLY = range(hw.REG_INT_STATUS, hw.REG_GYRO_XOUT_H + 6)
"""INT_STATUS and the 14 data registers: writes to them are ignored."""


def _int16(value: float) -> int:
    """Round and saturate to the int16 range, as the ADC does at full scale."""
    return int(max(-32768, min(32767, round(value))))


# ------------------------------------------------------------------------------------------
# noise model
# ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
@schema_defaults("parts/imu_sim.schema.json")
class ImuNoiseModel:
    """How the simulated IMU errs and which Earth field it sees (the world file's ``imu`` section)."""

    gyro_noise_density_rps_sqrthz: float
    """Gyro white noise density, rad/s/sqrt(Hz) (datasheet 0.01 deg/s/sqrt(Hz)); times sqrt(DLPF bandwidth)."""
    gyro_bias_sigma_rps: float
    """Standard deviation of the constant gyro bias drawn per axis at start, rad/s (about 1 deg/s)."""
    gyro_bias_walk_rps_sqrts: float
    """Gyro bias random walk, rad/s per sqrt(s): how fast the bias drifts (temperature, ageing)."""
    accel_noise_density_mps2_sqrthz: float
    """Accelerometer white noise density, m/s^2/sqrt(Hz) (datasheet 300 ug/sqrt(Hz))."""
    mag_field_ut: float
    """Total intensity of the local Earth field, microtesla (25..65 on Earth)."""
    mag_inclination_deg: float
    """Field inclination (dip) below the horizontal, degrees: positive in the northern hemisphere."""
    mag_declination_deg: float
    """Magnetic declination, degrees, positive east: magnetic north is this far clockwise of true north."""
    mag_noise_ut: float
    """White noise of each magnetometer axis, microtesla."""
    mag_hard_iron_ut: tuple[float, float, float]
    """Constant field of the robot itself (hard iron), microtesla, in the accelerometer's axes."""
    temperature_c: float
    """Die temperature reported, degrees Celsius."""
    whoami: Optional[int]
    """Override of the MPU's WHO_AM_I value (fault tests); null (None) = 0x71, a genuine MPU9250."""
    mag_present: bool
    """False leaves the AK8963 off the bus (a breakout without a magnetometer)."""

    def __post_init__(self) -> None:
        v = self.mag_hard_iron_ut
        if not isinstance(v, (list, tuple)) or len(v) != 3 \
                or not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in v):
            raise ValueError(f"imu noise model: 'mag_hard_iron_ut' must be 3 numbers, got {v!r}")
        object.__setattr__(self, "mag_hard_iron_ut", tuple(float(a) for a in v))
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name.endswith(("_rps", "_sqrthz", "_sqrts", "_ut")) and f.name != "mag_hard_iron_ut" and value < 0:
                raise ValueError(f"imu noise model: '{f.name}' must be >= 0, got {value}")
        if not -90.0 <= self.mag_inclination_deg <= 90.0:
            raise ValueError(f"imu noise model: 'mag_inclination_deg' must be -90..90, got {self.mag_inclination_deg}")
        if self.whoami is not None and not 0 <= self.whoami <= 255:
            raise ValueError(f"imu noise model: 'whoami' must be a byte (0..255), got {self.whoami}")

    @classmethod
    def from_dict(cls, d: dict) -> "ImuNoiseModel":
        """Build from a world-file dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "imu noise model")

    def earth_field_enu_ut(self) -> np.ndarray:
        """The Earth field in the local east-north-up frame, microtesla."""
        inc = math.radians(self.mag_inclination_deg)
        dec = math.radians(self.mag_declination_deg)
        horizontal = self.mag_field_ut * math.cos(inc)
        return np.array((horizontal * math.sin(dec), horizontal * math.cos(dec),
                         -self.mag_field_ut * math.sin(inc)))


# ------------------------------------------------------------------------------------------
# register-level emulators
# ------------------------------------------------------------------------------------------


class SimMpu9250(RegisterDevice):
    """The MPU9250's register map: configuration, power, bypass and the sample registers.

    :meth:`set_sample` stores a new sample (sensor axes, SI units) scaled by
    the full-scale bits currently set; while asleep the data registers keep
    their old content. ``on_bypass_change(enabled)`` is called when the
    auxiliary bus is connected to or cut from the main bus.
    """

    def __init__(self, whoami: int = 0x71, on_bypass_change: Optional[Callable[[bool], None]] = None) -> None:
        super().__init__()
        self.whoami = whoami & 0xFF
        self.on_bypass_change = on_bypass_change
        self._bypass = False
        self._power_on_reset()

    def _power_on_reset(self) -> None:
        self.registers[:] = bytes(256)
        self.registers[hw.REG_PWR_MGMT_1] = MPU_POWER_ON_PWR_MGMT_1
        self.registers[hw.REG_WHO_AM_I] = self.whoami
        self._notify_bypass()

    # -- decoded configuration -------------------------------------------------------------

    @property
    def awake(self) -> bool:
        """False while PWR_MGMT_1 SLEEP is set (no new samples)."""
        return not self.registers[hw.REG_PWR_MGMT_1] & hw.PWR_MGMT_1_SLEEP

    @property
    def gyro_range_dps(self) -> int:
        """Gyro full scale selected by GYRO_CONFIG bits 4:3, deg/s."""
        return (250, 500, 1000, 2000)[(self.registers[hw.REG_GYRO_CONFIG] >> hw.FS_SEL_SHIFT) & 3]

    @property
    def accel_range_g(self) -> int:
        """Accel full scale selected by ACCEL_CONFIG bits 4:3, g."""
        return (2, 4, 8, 16)[(self.registers[hw.REG_ACCEL_CONFIG] >> hw.FS_SEL_SHIFT) & 3]

    @property
    def gyro_bandwidth_hz(self) -> float:
        """Gyro noise bandwidth from CONFIG DLPF_CFG, Hz."""
        return GYRO_DLPF_BANDWIDTH_HZ[self.registers[hw.REG_CONFIG] & 7]

    @property
    def accel_bandwidth_hz(self) -> float:
        """Accel noise bandwidth from ACCEL_CONFIG2 A_DLPF_CFG, Hz."""
        return ACCEL_DLPF_BANDWIDTH_HZ[self.registers[hw.REG_ACCEL_CONFIG2] & 7]

    @property
    def bypass_enabled(self) -> bool:
        """True when INT_PIN_CFG BYPASS_EN is set and the MPU's own I2C master is off."""
        return bool(self.registers[hw.REG_INT_PIN_CFG] & hw.INT_PIN_CFG_BYPASS_EN
                    and not self.registers[hw.REG_USER_CTRL] & hw.USER_CTRL_I2C_MST_EN)

    def _notify_bypass(self) -> None:
        state = self.bypass_enabled
        if state != self._bypass:
            self._bypass = state
            if self.on_bypass_change is not None:
                self.on_bypass_change(state)

    # -- register access ----------------------------------------------------------------

    def on_write(self, register: int, value: int) -> None:
        """React to configuration writes; read-only registers keep their value."""
        if register == hw.REG_WHO_AM_I:
            self.registers[register] = self.whoami
        elif register == hw.REG_PWR_MGMT_1 and value & hw.PWR_MGMT_1_H_RESET:
            self._power_on_reset()  # H_RESET: every register to its power-on value (asleep again)
        elif register in (hw.REG_INT_PIN_CFG, hw.REG_USER_CTRL):
            self._notify_bypass()

    def write(self, register: int, value: int) -> None:
        """Store a byte unless the register is read-only (status and data)."""
        register &= 0xFF
        if register in _MPU_READ_ONLY:
            self.writes.append((register, value & 0xFF))
            trim_front(self.writes, WRITES_KEPT)
            return
        super().write(register, value)

    def on_read(self, register: int) -> int:
        """Return the register; reading INT_STATUS clears its data-ready bit."""
        value = self.registers[register]
        if register == hw.REG_INT_STATUS:
            self.registers[register] = value & ~hw.INT_STATUS_RAW_DATA_RDY & 0xFF
        return value

    def set_sample(self, accel_mps2: Sequence[float], gyro_rps: Sequence[float], temperature_c: float) -> None:
        """Store one sample (sensor axes; m/s^2, rad/s, degC) as the chip would, if awake."""
        if not self.awake:
            return
        a_lsb = hw.ACCEL_LSB_PER_G[self.accel_range_g] / hw.STANDARD_GRAVITY_MPS2
        g_lsb = hw.GYRO_LSB_PER_DPS[self.gyro_range_dps] * (180.0 / math.pi)
        ax, ay, az = (float(a) for a in accel_mps2)
        gx, gy, gz = (float(g) for g in gyro_rps)
        block = struct.pack(
            ">7h",
            _int16(ax * a_lsb), _int16(ay * a_lsb), _int16(az * a_lsb),
            _int16((temperature_c - hw.TEMP_OFFSET_DEGC) * hw.TEMP_LSB_PER_DEGC),
            _int16(gx * g_lsb), _int16(gy * g_lsb), _int16(gz * g_lsb),
        )
        self.registers[hw.REG_ACCEL_XOUT_H:hw.REG_ACCEL_XOUT_H + hw.DATA_BLOCK_LENGTH] = block
        self.registers[hw.REG_INT_STATUS] |= hw.INT_STATUS_RAW_DATA_RDY


class SimAk8963(RegisterDevice):
    """The AK8963 magnetometer's register map, with its latch and mode rules.

    :meth:`advance` moves its measurement clock and stores a new sample
    (field in the AK8963's own axes, microtesla) whenever a measurement
    completes in continuous mode. Reading any data register protects the data
    until ST2 is read; a measurement finishing meanwhile waits (and sets DOR).
    Modes change only through power-down, as on the chip; ``ignored_mode_changes``
    counts the writes that broke that rule. ``force_overflow`` makes every new
    sample overflow (ST2 HOFL), for fault tests.
    """

    def __init__(self, asa: tuple[int, int, int] = AK_DEFAULT_ASA, whoami: int = hw.AK_WIA_VALUE) -> None:
        super().__init__()
        self.asa = tuple(int(a) & 0xFF for a in asa)
        self._asa_factors = tuple((a - 128) / 256.0 + 1.0 for a in self.asa)
        self.whoami = whoami & 0xFF
        self.force_overflow = False
        self.ignored_mode_changes = 0
        self._mode_reg = 0
        self._protected = False
        self._pending: Optional[bytes] = None
        self._since_sample_s = 0.0
        self._reset()

    def _reset(self) -> None:
        self.registers[:] = bytes(256)
        self.registers[hw.AK_REG_WIA] = self.whoami
        self.registers[0x01] = 0x9A  # INFO: device information, fixed
        self._mode_reg = 0
        self._protected = False
        self._pending = None

    @property
    def mode(self) -> int:
        """The operating mode bits (CNTL1 3:0)."""
        return self._mode_reg & 0x0F

    @property
    def sample_period_s(self) -> Optional[float]:
        """Seconds between measurements in the current mode (None when not measuring)."""
        return {hw.AK_MODE_CONTINUOUS_8HZ: 1.0 / 8.0, hw.AK_MODE_CONTINUOUS_100HZ: 1.0 / 100.0}.get(self.mode)

    def write(self, register: int, value: int) -> None:
        """CNTL1 changes the mode (only via power-down); CNTL2 SRST resets; status and data are read-only."""
        register &= 0xFF
        value &= 0xFF
        self.writes.append((register, value))
        trim_front(self.writes, WRITES_KEPT)
        if register == hw.AK_REG_CNTL1:
            new_mode = value & 0x0F
            if self.mode != hw.AK_MODE_POWER_DOWN and new_mode != hw.AK_MODE_POWER_DOWN:
                self.ignored_mode_changes += 1  # the chip needs power-down between two modes
                return
            self._mode_reg = value & 0x1F
            self.registers[register] = self._mode_reg
            self._since_sample_s = 0.0
        elif register == hw.AK_REG_CNTL2:
            if value & 0x01:
                self._reset()  # SRST: every register to its power-on value; the bit clears itself
        elif register in (0x0C, 0x0F):
            self.registers[register] = value  # ASTC (self-test) and I2CDIS are writable
        # everything else (WIA, INFO, ST1, data, ST2, ASA) is read-only for the host

    def on_read(self, register: int) -> int:
        """Serve the map: ASA only in fuse-ROM mode, data reads latch, ST2 releases."""
        if hw.AK_REG_ASAX <= register <= hw.AK_REG_ASAX + 2:
            # outside fuse-ROM access mode the chip does not expose the fuse ROM
            return self.asa[register - hw.AK_REG_ASAX] if self.mode == hw.AK_MODE_FUSE_ROM else 0x00
        if hw.AK_REG_HXL <= register <= hw.AK_REG_HXL + 5:
            self._protected = True
            return self.registers[register]
        if register == hw.AK_REG_ST2:
            value = self.registers[register]
            self._release()
            return value
        return self.registers[register]

    def _release(self) -> None:
        """Reading ST2 ends the read: DRDY/DOR clear, and a measurement that waited comes in."""
        self._protected = False
        self.registers[hw.AK_REG_ST1] = 0
        if self._pending is not None:
            pending = self._pending
            self._pending = None
            self._store(pending, overrun=True)

    def _store(self, block: bytes, overrun: bool) -> None:
        self.registers[hw.AK_REG_HXL:hw.AK_REG_HXL + 6] = block[:6]
        self.registers[hw.AK_REG_ST2] = block[6]
        st1 = hw.AK_ST1_DRDY | (hw.AK_ST1_DOR if overrun else 0)
        self.registers[hw.AK_REG_ST1] = st1

    def advance(self, dt_s: float, field_ut: Sequence[float]) -> None:
        """Let ``dt_s`` seconds pass; complete a measurement of ``field_ut`` (AK8963 axes, uT) when due."""
        period = self.sample_period_s
        if period is None:
            return
        self._since_sample_s += dt_s
        if self._since_sample_s + 1e-12 < period:
            return
        self._since_sample_s %= period
        sixteen = bool(self._mode_reg & hw.AK_CNTL1_16BIT)
        lsb_ut = hw.AK_UT_PER_LSB_16BIT if sixteen else hw.AK_UT_PER_LSB_14BIT
        limit = 32760 if sixteen else 8190
        factors = self._asa_factors
        # the chip reports the raw field; the driver multiplies by the ASA factor
        raw = [max(-limit, min(limit, round(float(field_ut[i]) / (lsb_ut * factors[i])))) for i in range(3)]
        overflow = self.force_overflow or abs(field_ut[0]) + abs(field_ut[1]) + abs(field_ut[2]) >= AK_MEASUREMENT_RANGE_UT
        st2 = (hw.AK_ST2_BITM if sixteen else 0) | (hw.AK_ST2_HOFL if overflow else 0)
        block = struct.pack("<3hB", raw[0], raw[1], raw[2], st2)
        if self._protected:
            self._pending = block  # the data registers are latched until ST2 is read
            return
        overrun = bool(self.registers[hw.AK_REG_ST1] & hw.AK_ST1_DRDY)  # previous sample never read
        self._store(block, overrun)


# ------------------------------------------------------------------------------------------
# the IMU as the simulator sees it
# ------------------------------------------------------------------------------------------


class SimImu:
    """The emulated IMU on a bus, driven by the robot's true motion.

    ``gyro_bias_rps`` is the true current gyro bias (sensor axes, rad/s),
    exposed for tests and ground-truth metrics. The arithmetic is plain
    Python on 3-vectors: cheaper than numpy at this size, and it runs at 100 Hz.
    """

    def __init__(self, bus: SimI2CBus, model: ImuNoiseModel, rng: np.random.Generator,
                 mpu: SimMpu9250, ak: SimAk8963, body_from_sensor: np.ndarray,
                 address: int, mag_address: int) -> None:
        self.bus = bus
        self.model = model
        self.rng = rng
        self.mpu = mpu
        self.ak = ak
        self.address = address
        self.mag_address = mag_address
        self.body_from_sensor = np.asarray(body_from_sensor, dtype=float)
        self._sensor_from_body = self.body_from_sensor.T
        bias = rng.normal(0.0, model.gyro_bias_sigma_rps, 3) if model.gyro_bias_sigma_rps > 0 else np.zeros(3)
        self._bias: tuple[float, float, float] = tuple(bias.tolist())
        self._earth_enu_ut = tuple(model.earth_field_enu_ut().tolist())
        self._hard_iron_ut = tuple(float(h) for h in model.mag_hard_iron_ut)
        self._sensor_from_body_rows = tuple(tuple(row) for row in self._sensor_from_body.tolist())
        self._prev_v_mps: Optional[float] = None

    def update(self, truth: RobotTruth, dt_s: float) -> None:
        """Advance the sensors by ``dt_s`` seconds and store a sample of ``truth`` in the registers."""
        m = self.model
        dt = max(0.0, float(dt_s))
        v = truth.v_mps
        w = truth.w_rps
        vdot = 0.0 if self._prev_v_mps is None or dt <= 0.0 else (v - self._prev_v_mps) / dt
        self._prev_v_mps = v
        # one draw for everything (runs at 100 Hz in a simulator that must beat 100x real time):
        # bias walk, gyro noise, accel noise, mag noise, three axes each
        noise = self.rng.standard_normal(12).tolist()
        walk = m.gyro_bias_walk_rps_sqrts * math.sqrt(dt)
        g_sd = m.gyro_noise_density_rps_sqrthz * math.sqrt(self.mpu.gyro_bandwidth_hz)
        a_sd = m.accel_noise_density_mps2_sqrthz * math.sqrt(self.mpu.accel_bandwidth_hz)
        f_sd = m.mag_noise_ut
        bx, by, bz = self._bias
        self._bias = (bx + walk * noise[0], by + walk * noise[1], bz + walk * noise[2])
        # body frame: yaw rate about z; specific force = gravity reaction (+z up) plus the
        # forward (v-dot) and centripetal (v * w, towards the left in a left turn) acceleration;
        # Earth field into the body: the ENU vector rotated by -yaw (yaw is CCW from east)
        c, s = math.cos(truth.yaw), math.sin(truth.yaw)
        e, n, u = self._earth_enu_ut
        rot = self._sensor_from_body_rows
        gyro = [r[2] * w + b + g_sd * k for r, b, k in zip(rot, self._bias, noise[3:6])]
        ax, ay, az = vdot, v * w, hw.STANDARD_GRAVITY_MPS2
        accel = [r[0] * ax + r[1] * ay + r[2] * az + a_sd * k for r, k in zip(rot, noise[6:9])]
        self.mpu.set_sample(accel, gyro, m.temperature_c)
        mx, my, mz = c * e + s * n, -s * e + c * n, u
        fx, fy, fz = [r[0] * mx + r[1] * my + r[2] * mz + h + f_sd * k
                      for r, h, k in zip(rot, self._hard_iron_ut, noise[9:12])]
        # the AK8963's axes: X = accel Y, Y = accel X, Z = -accel Z
        self.ak.advance(dt, (fy, fx, -fz))

    @property
    def gyro_bias_rps(self) -> np.ndarray:
        """The true current gyro bias, sensor axes, rad/s."""
        return np.array(self._bias)

    def true_gyro_bias_body_rps(self) -> np.ndarray:
        """The true gyro bias rotated into body axes, rad/s."""
        return self.body_from_sensor @ self.gyro_bias_rps


def attach_imu(bus: SimI2CBus, model: ImuNoiseModel, rng: np.random.Generator, *,
               address: int = hw.MPU9250_DEFAULT_ADDRESS, mag_address: int = hw.AK8963_DEFAULT_ADDRESS,
               body_from_sensor: Optional[np.ndarray] = None,
               mag_asa: tuple[int, int, int] = AK_DEFAULT_ASA) -> SimImu:
    """Put an emulated MPU9250 (at ``address``) with its AK8963 on ``bus``.

    The AK8963 appears at ``mag_address`` only while the MPU's bypass is on
    (and never when ``model.mag_present`` is False). ``body_from_sensor`` is
    how the board is mounted (3x3 rotation, default identity); use the same
    one as the driver's :meth:`~beastbt.devices.mpu9250.ImuConfig.body_from_sensor`.
    """
    ak = SimAk8963(asa=mag_asa)

    def bypass(enabled: bool) -> None:
        if enabled and model.mag_present:
            bus.attach(mag_address, ak)
        else:
            bus.detach(mag_address)

    mpu = SimMpu9250(whoami=0x71 if model.whoami is None else model.whoami, on_bypass_change=bypass)
    bus.attach(address, mpu)
    rot = np.eye(3) if body_from_sensor is None else np.asarray(body_from_sensor, dtype=float)
    return SimImu(bus, model, rng, mpu, ak, rot, address, mag_address)
