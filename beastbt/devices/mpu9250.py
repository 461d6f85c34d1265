"""MPU9250 / MPU9255 IMU driver (accelerometer, gyro, temperature) with its AK8963 magnetometer.

Talks I2C through an :class:`~beastbt.devices.interfaces.SMBusLike` (an
``smbus2.SMBus`` on the robot, a :class:`~beastbt.sim.i2c_bus.SimI2CBus` with
the emulator of :mod:`beastbt.sim.imu_emulator` in the simulator) and returns
:class:`~beastbt.blackboard.types.ImuSample` readings in the body frame (x
forward, y left, z up) in SI units: rad/s, m/s^2 (gravity included, +9.81 on
z at rest), tesla, degrees Celsius.

The register facts come from HARDWARE.md (MPU9250 section) and the InvenSense
MPU-9250 register map / AKM AK8963 datasheets; every number is a named
constant below. Bus errors are retried, counted, reported through the
:data:`~beastbt.devices.interfaces.EventSink` (rate limited) and make the data
stale; :meth:`Mpu9250.poll` never raises. The gyro bias is estimated while the
robot stands still after start and subtracted from then on.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import ImuSample
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, SMBusLike, ignore_events
from beastbt.core.clock import Clock

# --- MPU9250 register map (InvenSense RM-MPU-9250A-00) -------------------------------------
MPU9250_DEFAULT_ADDRESS = 0x68
"""7-bit address with AD0 low (0x69 with AD0 high)."""
REG_SMPLRT_DIV = 0x19
REG_CONFIG = 0x1A
REG_GYRO_CONFIG = 0x1B
REG_ACCEL_CONFIG = 0x1C
REG_ACCEL_CONFIG2 = 0x1D
REG_INT_PIN_CFG = 0x37
REG_INT_ENABLE = 0x38
REG_INT_STATUS = 0x3A
REG_ACCEL_XOUT_H = 0x3B
REG_TEMP_OUT_H = 0x41
REG_GYRO_XOUT_H = 0x43
REG_USER_CTRL = 0x6A
REG_PWR_MGMT_1 = 0x6B
REG_PWR_MGMT_2 = 0x6C
REG_WHO_AM_I = 0x75

WHO_AM_I_MODELS = {0x71: "MPU9250", 0x73: "MPU9255"}
"""WHO_AM_I values this driver accepts, and the chip each one names."""
PWR_MGMT_1_H_RESET = 0x80
PWR_MGMT_1_SLEEP = 0x40
PWR_MGMT_1_CLKSEL_AUTO = 0x01
"""Wake (SLEEP cleared) and use the gyro PLL when ready: the recommended clock."""
INT_PIN_CFG_BYPASS_EN = 0x02
"""Connects the auxiliary I2C pins to the main bus, so the AK8963 answers at 0x0C."""
USER_CTRL_I2C_MST_EN = 0x20
"""Bypass only works while the MPU's own I2C master is disabled."""
INT_STATUS_RAW_DATA_RDY = 0x01
FS_SEL_SHIFT = 3
"""GYRO_CONFIG / ACCEL_CONFIG full-scale select lives in bits 4:3."""
DATA_BLOCK_LENGTH = 14
"""Accel (6) + temperature (2) + gyro (6) bytes, read in one transaction from 0x3B."""

GYRO_FS_SEL = {250: 0, 500: 1, 1000: 2, 2000: 3}
GYRO_LSB_PER_DPS = {250: 131.0, 500: 65.5, 1000: 32.8, 2000: 16.4}
ACCEL_FS_SEL = {2: 0, 4: 1, 8: 2, 16: 3}
ACCEL_LSB_PER_G = {2: 16384.0, 4: 8192.0, 8: 4096.0, 16: 2048.0}
TEMP_LSB_PER_DEGC = 333.87
TEMP_OFFSET_DEGC = 21.0
INTERNAL_SAMPLE_RATE_HZ = 1000.0
"""Rate the sample-rate divider divides when the DLPF is on (DLPF_CFG 1..6)."""
STANDARD_GRAVITY_MPS2 = 9.80665

# --- AK8963 register map (AKM AK8963 datasheet) --------------------------------------------
AK8963_DEFAULT_ADDRESS = 0x0C
AK_REG_WIA = 0x00
AK_REG_ST1 = 0x02
AK_REG_HXL = 0x03
AK_REG_ST2 = 0x09
AK_REG_CNTL1 = 0x0A
AK_REG_CNTL2 = 0x0B
AK_REG_ASAX = 0x10
AK_WIA_VALUE = 0x48
AK_ST1_DRDY = 0x01
AK_ST1_DOR = 0x02
AK_ST2_HOFL = 0x08
"""Magnetic sensor overflow: |X|+|Y|+|Z| exceeded the range; the sample is meaningless."""
AK_ST2_BITM = 0x10
"""Set when the sample is 16-bit (0.15 uT/LSB), clear for 14-bit (0.6 uT/LSB)."""
AK_MODE_POWER_DOWN = 0x00
AK_MODE_CONTINUOUS_8HZ = 0x02
AK_MODE_CONTINUOUS_100HZ = 0x06
AK_MODE_FUSE_ROM = 0x0F
AK_CNTL1_16BIT = 0x10
AK_MODES_BY_RATE_HZ = {8: AK_MODE_CONTINUOUS_8HZ, 100: AK_MODE_CONTINUOUS_100HZ}
AK_UT_PER_LSB_16BIT = 0.15
AK_UT_PER_LSB_14BIT = 0.6
AK_MAG_BLOCK_LENGTH = 8
"""ST1, HXL..HZH, ST2 in one transaction: reading ST2 last releases the data latch."""

_BIAS_MIN_SAMPLES = 5
"""Samples needed before the motion test of the bias window means anything."""
_BIAS_PROVISIONAL_FRACTION = 0.25
"""After this fraction of a still bias window its running mean is subtracted provisionally."""


# ------------------------------------------------------------------------------------------
# configuration
# ------------------------------------------------------------------------------------------

_AXES = {"x": 0, "y": 1, "z": 2}


def _check_vec3(name: str, value: Any) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ValueError(f"imu: '{name}' must be a list of 3 numbers, got {value!r}")
    try:
        return (float(value[0]), float(value[1]), float(value[2]))
    except (TypeError, ValueError):
        raise ValueError(f"imu: '{name}' must be a list of 3 numbers, got {value!r}") from None


def rotation_from_rpy_deg(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """Rotation matrix Rz(yaw) @ Ry(pitch) @ Rx(roll) (angles in degrees, ROS fixed-axis order)."""
    r, p, y = (math.radians(a) for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def rotation_from_axes(axes: Sequence[str]) -> np.ndarray:
    """Rotation matrix from an axis mapping such as ``("-y", "x", "z")``.

    Entry ``i`` names which sensor axis (with sign) points along body axis
    ``i`` (x forward, y left, z up). The mapping must be a proper rotation.
    """
    if len(axes) != 3:
        raise ValueError(f"imu: 'mounting_axes' must name 3 axes, got {list(axes)!r}")
    m = np.zeros((3, 3))
    for i, name in enumerate(axes):
        s = str(name).strip().lower()
        sign = -1.0 if s.startswith("-") else 1.0
        s = s.lstrip("+-")
        if s not in _AXES:
            raise ValueError(f"imu: 'mounting_axes' entry {name!r} is not one of x, y, z, -x, -y, -z")
        m[i, _AXES[s]] = sign
    if abs(np.linalg.det(m) - 1.0) > 1e-9:
        raise ValueError(
            f"imu: 'mounting_axes' {list(axes)!r} is not a right-handed rotation "
            "(each sensor axis once, and an even number of sign flips or a cyclic swap)")
    return m


@dataclass(frozen=True)
@schema_defaults("parts/imu_device.schema.json")
class ImuConfig:
    """Configuration of the MPU9250 driver (the robot profile's ``imu`` section).

    Every field has a unit and a default; :meth:`from_dict` rejects unknown keys.
    """

    bus: int
    """Linux I2C bus number (/dev/i2c-N). 1 on the Raspberry Pi header."""
    address: int
    """7-bit I2C address of the MPU9250 (decimal in YAML: 104 = 0x68, 105 = 0x69 with AD0 high)."""
    mag_address: int
    """7-bit address of the AK8963 once bypass is on (12 = 0x0C). Change only for odd breakouts."""
    gyro_range_dps: int
    """Gyro full scale, deg/s: 250, 500, 1000 or 2000. 500 covers a spinning tracked robot with margin."""
    accel_range_g: int
    """Accelerometer full scale, g: 2, 4, 8 or 16. Raise it if bumps saturate the readings."""
    dlpf: int
    """Digital low-pass filter setting (DLPF_CFG and A_DLPF_CFG) 1..6: 1=184 Hz ... 3=41 Hz ... 6=5 Hz.

    Lower bandwidth means less vibration noise but more lag."""
    sample_rate_hz: float
    """Output data rate, Hz (4..1000): sets SMPLRT_DIV = 1000 / rate - 1. Keep >= twice the poll rate."""
    mag_enabled: bool
    """Use the AK8963 magnetometer. Off when the breakout has none or the robot's motors disturb it."""
    mag_rate_hz: int
    """Magnetometer continuous-mode rate, Hz: 8 or 100."""
    mag_offset_ut: tuple[float, float, float]
    """Hard-iron offset subtracted from the field, microtesla, in the accelerometer's axes."""
    mag_scale: tuple
    """Soft-iron correction applied after the offset: 3 per-axis factors or a 3x3 matrix (unitless)."""
    mounting_rpy_deg: tuple[float, float, float]
    """Orientation of the sensor in the body frame, degrees [roll, pitch, yaw] (ROS order Rz*Ry*Rx).

    Zero: sensor x forward, y left, z up."""
    mounting_axes: Optional[tuple[str, str, str]]
    """Alternative to mounting_rpy_deg: which sensor axis points along body x, y, z, e.g. ["-y", "x", "z"]."""
    retries: int
    """Extra attempts for a failed I2C transaction before the reading counts as lost."""
    failures_before_reinit: int
    """Consecutive failed readings after which the device is treated as lost and re-initialised."""
    reinit_interval_s: float
    """Seconds between attempts to start the device again while it is lost or missing."""
    event_interval_s: float
    """At most one event of each kind per this many seconds (the rest are counted in the next one)."""
    bias_window_s: float
    """Seconds of standstill averaged for the gyro bias after start. 0 disables the estimation.

    The running mean is subtracted once a quarter of the window was still, the final mean when it is full."""
    bias_motion_threshold_rps: float
    """Gyro standard deviation, rad/s, above which the robot counts as moving (the window restarts)."""
    bias_max_rps: float
    """A mean rate above this, rad/s, is a turn, not a bias (the window restarts)."""

    def __post_init__(self) -> None:
        # YAML gives lists: store tuples (the dataclass is frozen and hashable), then check ranges
        set_ = object.__setattr__
        set_(self, "mag_offset_ut", _check_vec3("mag_offset_ut", self.mag_offset_ut))
        set_(self, "mounting_rpy_deg", _check_vec3("mounting_rpy_deg", self.mounting_rpy_deg))
        v = self.mag_scale
        if isinstance(v, (list, tuple)) and len(v) == 3 and all(isinstance(r, (list, tuple)) for r in v):
            set_(self, "mag_scale", tuple(_check_vec3("mag_scale", r) for r in v))
        else:
            set_(self, "mag_scale", _check_vec3("mag_scale", v))
        if self.mounting_axes is not None:
            if not isinstance(self.mounting_axes, (list, tuple)):
                raise ValueError(f"imu: 'mounting_axes' must be a list of 3 axis names, got {self.mounting_axes!r}")
            set_(self, "mounting_axes", tuple(str(a) for a in self.mounting_axes))
        self.validate()

    @classmethod
    def from_dict(cls, d: dict) -> "ImuConfig":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "imu")

    def validate(self) -> None:
        """Raise ``ValueError`` naming the knob when a value is out of range."""
        if self.gyro_range_dps not in GYRO_FS_SEL:
            raise ValueError(f"imu: gyro_range_dps must be one of {sorted(GYRO_FS_SEL)}, got {self.gyro_range_dps}")
        if self.accel_range_g not in ACCEL_FS_SEL:
            raise ValueError(f"imu: accel_range_g must be one of {sorted(ACCEL_FS_SEL)}, got {self.accel_range_g}")
        if not 1 <= int(self.dlpf) <= 6:
            raise ValueError(f"imu: dlpf must be 1..6, got {self.dlpf}")
        if not 4.0 <= float(self.sample_rate_hz) <= 1000.0:
            raise ValueError(f"imu: sample_rate_hz must be 4..1000, got {self.sample_rate_hz}")
        if self.mag_rate_hz not in AK_MODES_BY_RATE_HZ:
            raise ValueError(f"imu: mag_rate_hz must be 8 or 100, got {self.mag_rate_hz}")
        if self.retries < 0 or self.failures_before_reinit < 1:
            raise ValueError("imu: retries must be >= 0 and failures_before_reinit >= 1")
        if self.mounting_axes is not None and any(a != 0.0 for a in self.mounting_rpy_deg):
            raise ValueError("imu: give either mounting_rpy_deg or mounting_axes, not both")
        self.body_from_sensor()
        self.mag_scale_matrix()

    def body_from_sensor(self) -> np.ndarray:
        """The 3x3 rotation taking a vector in sensor (accelerometer) axes to body axes."""
        if self.mounting_axes is not None:
            return rotation_from_axes(self.mounting_axes)
        return rotation_from_rpy_deg(*self.mounting_rpy_deg)

    def mag_scale_matrix(self) -> np.ndarray:
        """The soft-iron matrix (3x3) from ``mag_scale``."""
        m = np.array(self.mag_scale, dtype=float)
        if m.shape == (3,):
            return np.diag(m)
        if m.shape == (3, 3):
            return m
        raise ValueError(f"imu: mag_scale must be 3 numbers or a 3x3 matrix, got {self.mag_scale!r}")


# ------------------------------------------------------------------------------------------
# driver
# ------------------------------------------------------------------------------------------


class _BusFailure(Exception):
    """A transaction failed on every attempt; carries the last OSError."""

    def __init__(self, error: OSError) -> None:
        super().__init__(str(error))
        self.error = error


class Mpu9250:
    """Driver for an MPU9250/MPU9255 and its AK8963 magnetometer over I2C.

    Call :meth:`start` once (or let :meth:`poll` do it), then :meth:`poll` at
    the tick rate: each call returns the newest sample as an
    :class:`ImuSample` in the body frame, SI units, or ``None`` when the
    device is not running or the read failed (the data is then stale).
    Counters: ``error_count`` (failed I2C attempts), ``failed_reads``
    (readings lost after all retries), ``mag_overflow_count``.
    """

    def __init__(self, bus: SMBusLike, clock: Clock, events: EventSink = ignore_events,
                 config: ImuConfig | None = None) -> None:
        self.bus = bus
        self.clock = clock
        self.events = events
        self.config = config if config is not None else ImuConfig()
        self._body_from_sensor = self.config.body_from_sensor()
        self._mag_scale = self.config.mag_scale_matrix()
        self._mag_offset = np.array(self.config.mag_offset_ut, dtype=float)
        self._gyro_scale_rps = math.radians(1.0) / GYRO_LSB_PER_DPS[self.config.gyro_range_dps]
        self._accel_scale_mps2 = STANDARD_GRAVITY_MPS2 / ACCEL_LSB_PER_G[self.config.accel_range_g]
        self.model: Optional[str] = None
        """The chip named by WHO_AM_I once started ("MPU9250" or "MPU9255")."""
        self.running = False
        self.mag_running = False
        self.mag_asa = (1.0, 1.0, 1.0)
        """AK8963 sensitivity adjustment factors read from its fuse ROM (unitless)."""
        self.error_count = 0
        self.failed_reads = 0
        self.mag_overflow_count = 0
        self._consecutive_failures = 0
        self._ever_started = False
        self._next_start_s = -math.inf
        self._last_event_s: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        # gyro bias estimation (body axes, rad/s), Welford running mean/variance
        self._bias = np.zeros(3)
        self._bias_ready = self.config.bias_window_s <= 0.0
        self._bias_n = 0
        self._bias_t0 = 0.0
        self._bias_mean = np.zeros(3)
        self._bias_m2 = np.zeros(3)
        self.standstill: Optional[Callable[[], Optional[bool]]] = None
        """Whether the robot is known to stand still (the wheels: True stopped, False turning, None unknown), or
        None. A slow steady turn under ``bias_max_rps`` looks to the gyro alone like a bias; while this says
        False the bias window restarts, so such a turn is never learnt as one."""

    # -- public state -------------------------------------------------------------------

    @property
    def bias_ready(self) -> bool:
        """True once the gyro bias has been estimated (and is being subtracted)."""
        return self._bias_ready

    @property
    def gyro_bias_rps(self) -> tuple[float, float, float]:
        """The gyro bias subtracted from the readings, body axes, rad/s (zeros until ready)."""
        return (float(self._bias[0]), float(self._bias[1]), float(self._bias[2]))

    # -- events and bus access ------------------------------------------------------------

    def _event(self, kind: str, text: str) -> None:
        """Report ``kind`` at most once per ``event_interval_s``; count what is held back."""
        now = self.clock.now()
        last = self._last_event_s.get(kind)
        if last is not None and now - last < self.config.event_interval_s:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return
        held = self._suppressed.pop(kind, 0)
        if held:
            text = f"{text} ({held} more since the last report)"
        self._last_event_s[kind] = now
        self.events(kind, text)

    def _xfer(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Run one bus transaction with retries; raise :class:`_BusFailure` when all fail."""
        last: Optional[OSError] = None
        for _ in range(1 + self.config.retries):
            try:
                return fn(*args)
            except OSError as exc:  # the kernel's I2C errors (EIO, EREMOTEIO, ETIMEDOUT...)
                self.error_count += 1
                last = exc
        assert last is not None
        raise _BusFailure(last)

    def _where(self, address: int) -> str:
        return f"I2C bus {self.config.bus} address 0x{address:02x}"

    # -- start ----------------------------------------------------------------------------

    def start(self) -> bool:
        """Probe, wake and configure the MPU9250 and (if enabled) the AK8963.

        Returns True when the accelerometer and gyro are running (the
        magnetometer may still be missing: see ``mag_running``). On failure an
        event says why (``imu_missing``, ``imu_wrong_id``, ``imu_i2c_error``)
        and False is returned; nothing raises.
        """
        cfg = self.config
        bus = self.bus
        addr = cfg.address
        self.running = False
        self.mag_running = False
        self._next_start_s = self.clock.now() + cfg.reinit_interval_s
        try:
            who = self._xfer(bus.read_byte_data, addr, REG_WHO_AM_I)
        except _BusFailure as exc:
            self._event("imu_missing", f"no MPU9250 answers at {self._where(addr)}: {exc.error}")
            return False
        if who not in WHO_AM_I_MODELS:
            expected = " or ".join(f"0x{v:02x} ({n})" for v, n in WHO_AM_I_MODELS.items())
            self._event("imu_wrong_id", f"device at {self._where(addr)} has WHO_AM_I 0x{who:02x}, "
                                        f"expected {expected}: wrong chip or wrong address")
            return False
        self.model = WHO_AM_I_MODELS[who]
        div = max(0, min(255, int(round(INTERNAL_SAMPLE_RATE_HZ / float(cfg.sample_rate_hz))) - 1))
        setup = (
            (REG_PWR_MGMT_1, PWR_MGMT_1_CLKSEL_AUTO),   # wake (clears SLEEP), PLL clock
            (REG_PWR_MGMT_2, 0x00),                     # all accel and gyro axes on
            (REG_CONFIG, int(cfg.dlpf) & 0x07),         # gyro + temperature DLPF
            (REG_ACCEL_CONFIG2, int(cfg.dlpf) & 0x07),  # accel DLPF (ACCEL_FCHOICE_B = 0)
            (REG_SMPLRT_DIV, div),
            (REG_GYRO_CONFIG, GYRO_FS_SEL[cfg.gyro_range_dps] << FS_SEL_SHIFT),
            (REG_ACCEL_CONFIG, ACCEL_FS_SEL[cfg.accel_range_g] << FS_SEL_SHIFT),
            (REG_USER_CTRL, 0x00),                      # own I2C master off, or bypass does nothing
            (REG_INT_PIN_CFG, INT_PIN_CFG_BYPASS_EN),   # AK8963 appears on the main bus
        )
        try:
            for reg, value in setup:
                self._xfer(bus.write_byte_data, addr, reg, value)
        except _BusFailure as exc:
            self._event("imu_i2c_error", f"configuring the {self.model} at {self._where(addr)} failed: {exc.error}")
            return False
        if cfg.mag_enabled:
            self.mag_running = self._start_mag()
        self.running = True
        self._consecutive_failures = 0
        if self._ever_started:
            self._event("imu_reinit", f"{self.model} at {self._where(addr)} re-initialised")
        self._ever_started = True
        if not self._bias_ready:
            self._bias_n = 0
        return True

    def _start_mag(self) -> bool:
        """Check the AK8963, read its ASA from fuse ROM and start continuous 16-bit mode."""
        cfg = self.config
        bus = self.bus
        mag = cfg.mag_address
        try:
            wia = self._xfer(bus.read_byte_data, mag, AK_REG_WIA)
        except _BusFailure as exc:
            self._event("imu_mag_missing", f"no AK8963 magnetometer at {self._where(mag)} "
                                           f"(bypass enabled): {exc.error}; continuing without it")
            return False
        if wia != AK_WIA_VALUE:
            self._event("imu_mag_missing", f"device at {self._where(mag)} has WIA 0x{wia:02x}, expected "
                                           f"0x{AK_WIA_VALUE:02x} (AK8963); continuing without magnetometer")
            return False
        try:
            # The AK8963 only changes mode through power-down; the >=100 us it needs between
            # modes is covered by the I2C transfers themselves (one byte write takes longer).
            self._xfer(bus.write_byte_data, mag, AK_REG_CNTL1, AK_MODE_POWER_DOWN)
            self._xfer(bus.write_byte_data, mag, AK_REG_CNTL1, AK_MODE_FUSE_ROM)
            asa = self._xfer(bus.read_i2c_block_data, mag, AK_REG_ASAX, 3)
            self._xfer(bus.write_byte_data, mag, AK_REG_CNTL1, AK_MODE_POWER_DOWN)
            mode = AK_MODES_BY_RATE_HZ[cfg.mag_rate_hz] | AK_CNTL1_16BIT
            self._xfer(bus.write_byte_data, mag, AK_REG_CNTL1, mode)
        except _BusFailure as exc:
            self._event("imu_i2c_error", f"configuring the AK8963 at {self._where(mag)} failed: {exc.error}")
            return False
        self.mag_asa = tuple((a - 128) / 256.0 + 1.0 for a in asa)  # type: ignore[assignment]
        return True

    # -- poll -------------------------------------------------------------------------------

    def poll(self) -> Optional[ImuSample]:
        """Read the newest sample; ``None`` when the device is not running or the read failed.

        Never raises. While the device is lost or missing it is started again
        every ``reinit_interval_s``.
        """
        now = self.clock.now()
        if not self.running:
            if now < self._next_start_s or not self.start():
                return None
        cfg = self.config
        try:
            raw = self._xfer(self.bus.read_i2c_block_data, cfg.address, REG_ACCEL_XOUT_H, DATA_BLOCK_LENGTH)
            if len(raw) != DATA_BLOCK_LENGTH:
                raise _BusFailure(OSError(f"short read: {len(raw)} of {DATA_BLOCK_LENGTH} bytes"))
        except _BusFailure as exc:
            self._read_failed(now, exc)
            return None
        self._consecutive_failures = 0
        if not any(raw):
            return None  # just woken: the first conversion has not landed in the registers yet
        ax, ay, az, t_raw, gx, gy, gz = struct.unpack(">7h", bytes(raw))
        rot = self._body_from_sensor
        accel = rot @ (np.array((ax, ay, az), dtype=float) * self._accel_scale_mps2)
        gyro = rot @ (np.array((gx, gy, gz), dtype=float) * self._gyro_scale_rps)
        temperature_c = t_raw / TEMP_LSB_PER_DEGC + TEMP_OFFSET_DEGC
        mag_t = self._read_mag() if self.mag_running else None
        self._update_bias(now, gyro)
        gyro = gyro - self._bias
        return ImuSample(
            stamp_s=now,
            gyro_rps=(float(gyro[0]), float(gyro[1]), float(gyro[2])),
            accel_mps2=(float(accel[0]), float(accel[1]), float(accel[2])),
            mag_t=mag_t,
            temperature_c=temperature_c,
        )

    def _read_failed(self, now: float, exc: _BusFailure) -> None:
        """Count a lost reading; after too many in a row, treat the device as lost."""
        self.failed_reads += 1
        self._consecutive_failures += 1
        attempts = 1 + self.config.retries
        self._event("imu_i2c_error", f"IMU read at {self._where(self.config.address)} failed "
                                     f"{attempts} times ({exc.error}); data is stale")
        if self._consecutive_failures >= self.config.failures_before_reinit:
            self.running = False
            self._next_start_s = now + self.config.reinit_interval_s
            self._event("imu_lost", f"IMU lost after {self._consecutive_failures} failed readings; "
                                    f"re-initialising every {self.config.reinit_interval_s:g} s")

    def _read_mag(self) -> Optional[tuple[float, float, float]]:
        """Read ST1, data and ST2 of the AK8963 in one transaction; tesla in body axes or None."""
        try:
            raw = self._xfer(self.bus.read_i2c_block_data, self.config.mag_address, AK_REG_ST1,
                             AK_MAG_BLOCK_LENGTH)
        except _BusFailure as exc:
            self.failed_reads += 1
            self._event("imu_i2c_error", f"magnetometer read at {self._where(self.config.mag_address)} "
                                         f"failed ({exc.error}); no heading data this sample")
            return None
        if len(raw) != AK_MAG_BLOCK_LENGTH:
            return None
        st1, st2 = raw[0], raw[7]
        if not st1 & AK_ST1_DRDY:
            return None  # no new measurement since the last read
        if st2 & AK_ST2_HOFL:
            self.mag_overflow_count += 1
            self._event("imu_mag_overflow", "magnetometer overflow (field beyond range, magnet nearby?); "
                                            "sample dropped")
            return None
        hx, hy, hz = struct.unpack("<3h", bytes(raw[1:7]))
        lsb_ut = AK_UT_PER_LSB_16BIT if st2 & AK_ST2_BITM else AK_UT_PER_LSB_14BIT
        asa = self.mag_asa
        mx, my, mz = hx * asa[0] * lsb_ut, hy * asa[1] * lsb_ut, hz * asa[2] * lsb_ut
        # AK8963 axes differ from the accelerometer's (MPU-9250 datasheet, orientation figure):
        # mag X = accel Y, mag Y = accel X, mag Z = -accel Z.
        sensor_ut = np.array((my, mx, -mz))
        calibrated_ut = self._mag_scale @ (sensor_ut - self._mag_offset)
        body_t = (self._body_from_sensor @ calibrated_ut) * 1e-6
        return (float(body_t[0]), float(body_t[1]), float(body_t[2]))

    def _update_bias(self, now: float, gyro: np.ndarray) -> None:
        """Average the gyro while the robot stands still; restart the window on motion."""
        if self._bias_ready:
            return
        if self.standstill is not None and self.standstill() is False:
            self._bias_n = 0  # the wheels turn: the window starts again once they stop
            return
        cfg = self.config
        if self._bias_n == 0:
            self._bias_t0 = now
            self._bias_mean[:] = 0.0
            self._bias_m2[:] = 0.0
        self._bias_n += 1
        delta = gyro - self._bias_mean
        self._bias_mean += delta / self._bias_n
        self._bias_m2 += delta * (gyro - self._bias_mean)
        if self._bias_n < _BIAS_MIN_SAMPLES:
            return
        variance = self._bias_m2 / (self._bias_n - 1)
        moving = (float(variance.max()) > cfg.bias_motion_threshold_rps ** 2
                  or float(np.abs(self._bias_mean).max()) > cfg.bias_max_rps)
        if moving:
            # start a fresh window with the next sample (this one may be part of the motion);
            # the provisional bias from the still samples before stays subtracted
            self._bias_n = 0
            return
        elapsed = now - self._bias_t0
        if elapsed >= _BIAS_PROVISIONAL_FRACTION * cfg.bias_window_s:
            # Subtract the running mean already: the output then does not jump by the whole bias
            # when the window completes, which a filter downstream would take for a real turn.
            self._bias[:] = self._bias_mean
        if elapsed >= cfg.bias_window_s:
            self._bias_ready = True
