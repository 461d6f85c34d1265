"""The extended Kalman filter that fuses wheel odometry, the IMU and GPS into a pose.

:class:`EkfEstimator` implements the :class:`~beastbt.estimation.estimator.Estimator`
protocol on top of ``filterpy.kalman.ExtendedKalmanFilter``. It works in a
local east-north-up frame (:class:`~beastbt.estimation.geodesy.LocalFrame`)
anchored at a given datum or, without one, at the first GPS fix.

State (SI units, ENU, yaw counter-clockwise from east)::

    [x_m, y_m, yaw_rad, v_mps, yaw_rate_rps, gyro_bias_z_rps]

Motion model: a unicycle (constant speed and yaw rate between calls, with
random-walk process noise). Measurements: odometry forward speed and yaw rate
(from the wheel travel since the previous reading; the yaw rate only at
standstill or without a gyro unless configured, because tracks skid), gyro z
(= yaw rate + bias), magnetometer heading (optional), GPS position with the
fix's covariance (gated by Mahalanobis distance; a fix stamped earlier than
the update is compared with where the robot was then), GPS course over
ground while moving (its variance grows as the speed falls).

Without a magnetometer the heading is found from the first metres of motion:
a precise enough GPS course, or the rotation that maps the odometric track
onto the GPS track once ``heading_init_distance_m`` has been driven. Until
then ``heading_valid`` is False and, once a position is known, the position
does not follow the (unknown) heading: it is held, its uncertainty grows with
the distance driven, and the fixes correct it. Before the first fix (and
without a datum) the pose is dead reckoning from (0, 0) and
``position_valid`` is False.

Cost: one stacked filterpy update for odometry + gyro per call, one for GPS
position + course per fix; about 40-60 us per call on a desktop core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any, Optional, Sequence

import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import FusedPose, GpsFix, ImuSample, WheelOdometry
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.estimation.estimator import wrap_angle
from beastbt.estimation.geodesy import LocalFrame

IX, IY, IYAW, IV, IW, IB = range(6)
"""Indices of the state vector: x, y, yaw, speed, yaw rate, gyro z bias."""
STATE_SIZE = 6
_HEADING_INIT_MAX_FIXES = 600
"""Fixes kept for the motion-based heading fit (about 10 minutes at 1 Hz)."""
_COURSE_INIT_MAX_YAW_RATE_RPS = 0.3
"""The course initialises the heading only while not turning faster than this (the track lags in turns)."""
_GYRO_RECENT_S = 0.5
"""A gyro sample this recent means the gyro is working (so the wheels' yaw rate can be left out)."""
_SQRT_HALF = math.sqrt(0.5)
_GRAVITY_MPS2 = 9.80665
_TILT_ACCEL_TOLERANCE_MPS2 = 1.5
"""Tilt compensation uses the accelerometer only while |a| is this close to g (not accelerating)."""


@dataclass(frozen=True)
@schema_defaults("parts/ekf.schema.json")
class EkfConfig:
    """Tuning of the EKF (the robot profile's ``ekf`` section), in the spirit of robot_localization.

    Process noises are per sqrt(second) (random-walk intensities);
    measurement noises are standard deviations of one reading.
    """

    # --- robot geometry -------------------------------------------------------------------
    track_width_m: float
    """Effective distance between left and right wheels/tracks, m: odometry yaw rate = (vr - vl) / this.

    Tracked robots skid: calibrate by spinning in place and comparing with the gyro."""

    # --- process noise ----------------------------------------------------------------------
    accel_noise_mps2: float
    """Unmodelled forward acceleration, m/s^2 per sqrt(s) (speed random walk). Raise for jerky driving."""
    yaw_accel_noise_rps2: float
    """Unmodelled yaw acceleration, rad/s^2 per sqrt(s) (yaw-rate random walk)."""
    position_noise_mps: float
    """Position random walk, m per sqrt(s): slip and sideways motion the unicycle model lacks."""
    yaw_noise_rps: float
    """Heading random walk, rad per sqrt(s), on top of the integrated yaw rate."""
    gyro_bias_walk_rps_sqrts: float
    """How fast the gyro z bias may drift, rad/s per sqrt(s). Larger re-learns a changed bias faster."""

    # --- initial uncertainty ----------------------------------------------------------------
    initial_position_sigma_m: float
    """Position uncertainty at the datum when starting there (start_at_datum), m."""
    initial_speed_sigma_mps: float
    """Speed uncertainty at start, m/s."""
    initial_yaw_rate_sigma_rps: float
    """Yaw rate uncertainty at start, rad/s. Large, so a first gyro reading is taken as turning, not bias."""
    initial_gyro_bias_sigma_rps: float
    """Gyro z bias uncertainty at start, rad/s (the driver removes most of it at rest)."""
    start_at_datum: bool
    """With a datum given, the robot starts at the datum (position valid at once); false: wait for a fix."""

    # --- wheel odometry ---------------------------------------------------------------------
    odom_speed_noise_mps: float
    """Odometry forward speed noise, m/s (constant part)."""
    odom_speed_noise_frac: float
    """Odometry forward speed noise growing with speed (fraction of |v|): wheel slip, radius error."""
    odom_yaw_rate_noise_rps: float
    """Odometry yaw rate noise, rad/s (constant part)."""
    odom_yaw_rate_noise_frac: float
    """Odometry yaw rate noise growing with the turn rate (fraction of |w|): tracks skid in turns."""
    odom_yaw_rate_with_gyro: bool
    """Also fuse the wheels' yaw rate while the gyro works.

    Off for tracked/skid-steer bases: they turn less than their wheels say, and the filter would blame
    the gyro bias. The wheels' yaw rate is always used at standstill (to learn the bias) and when no
    gyro sample came in the last 0.5 s."""
    standstill_speed_mps: float
    """Below this wheel speed (each side) the robot is standing still: a zero-velocity update."""
    standstill_speed_noise_mps: float
    """Speed noise while standing still, m/s (small: the wheels really are stopped)."""
    standstill_yaw_rate_noise_rps: float
    """Yaw rate noise while standing still, rad/s: lets the filter learn the gyro bias at rest."""
    odom_max_step_m: float
    """A wheel travel jump larger than this between two readings is a counter reset, not motion, m."""

    # --- gyro -------------------------------------------------------------------------------
    use_gyro: bool
    """Fuse the IMU's z rate."""
    gyro_noise_rps: float
    """Noise of one gyro z sample, rad/s (several samples in one call are averaged)."""

    # --- magnetometer -----------------------------------------------------------------------
    use_magnetometer: bool
    """Fuse the magnetometer heading. Off by default: motors and steel disturb it on small robots."""
    mag_heading_noise_rad: float
    """Magnetometer heading noise, rad."""
    declination_deg: float
    """Magnetic declination at the site, degrees, positive east (true heading = magnetic + this)."""
    mag_tilt_compensation: bool
    """Use the accelerometer's gravity direction to level the field before taking the heading."""
    mag_gate_chi2: float
    """Reject a magnetometer heading beyond this chi-square (1 dof; 10.83 = 99.9 %)."""

    # --- GPS position -----------------------------------------------------------------------
    use_gps: bool
    """Fuse GPS fixes."""
    min_gps_quality: int
    """Lowest NMEA fix quality used (1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float)."""
    gps_gate_chi2: float
    """Reject a fix whose Mahalanobis distance squared exceeds this (chi-square 2 dof; 13.82 = 99.9 %)."""
    gps_reset_after_s: float
    """When fixes have been rejected for this long the filter is lost: accept the fix and inflate, s."""
    gps_reset_inflation: float
    """On such a reset the position covariance becomes the fix covariance times this (unitless)."""
    gps_max_lag_s: float
    """Fixes older than the update time are moved back along the motion by at most this lag, s."""

    # --- GPS course over ground -------------------------------------------------------------
    use_gps_course: bool
    """Fuse the receiver's course over ground as a heading while moving."""
    course_min_speed_mps: float
    """Course is used only above this speed (GPS and odometry), m/s: it is noise when slow."""
    course_speed_noise_mps: float
    """GPS velocity noise, m/s: the course noise is this / speed rad, so it grows as speed falls."""
    course_noise_floor_rad: float
    """Smallest course noise, rad."""
    course_gate_chi2: float
    """Reject a course beyond this chi-square (1 dof)."""

    # --- heading initialisation without magnetometer ----------------------------------------
    heading_init_distance_m: float
    """Odometric distance after which the heading is fitted from GPS displacement, m."""
    heading_init_from_course: bool
    """Also initialise the heading from the first GPS course that is precise enough."""
    heading_init_course_max_sigma_rad: float
    """A course this precise (or better) may initialise the heading, rad (0.35 = 20 deg)."""

    def __post_init__(self) -> None:
        self.validate()

    @classmethod
    def from_dict(cls, d: dict) -> "EkfConfig":
        """Build from a profile dict; unknown keys, wrong types or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "ekf")

    def validate(self) -> None:
        """Raise ``ValueError`` naming the knob when a value cannot work."""
        if self.track_width_m <= 0.0:
            raise ValueError(f"ekf: track_width_m must be > 0, got {self.track_width_m}")
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and value < 0.0 and f.name != "declination_deg":
                raise ValueError(f"ekf: '{f.name}' must be >= 0, got {value}")
        for name in ("gyro_noise_rps", "mag_heading_noise_rad", "standstill_speed_noise_mps",
                     "standstill_yaw_rate_noise_rps", "odom_speed_noise_mps", "odom_yaw_rate_noise_rps",
                     "course_noise_floor_rad", "gps_gate_chi2", "mag_gate_chi2", "course_gate_chi2"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"ekf: '{name}' must be > 0, got {getattr(self, name)}")


@lru_cache(maxsize=None)
def _unicycle_ekf_class() -> type:
    """The class of filterpy's EKF with the unicycle motion model, defined on first use.

    filterpy's package imports SciPy's statistics (about half a second of start-up): it is
    imported only when a filter is built, so that the profile's ``estimator`` section (:class:`EkfConfig`)
    is checked, and a run whose EKF sleeps starts, without it.
    """
    from filterpy.kalman import ExtendedKalmanFilter

    class _UnicycleEkf(ExtendedKalmanFilter):  # type: ignore[misc]
        """filterpy's EKF with the unicycle motion model as its state transition.

        The Jacobian ``F`` and ``Q`` are set by the caller before ``predict()``;
        ``dt_s`` is the prediction step in seconds.
        """

        def __init__(self) -> None:
            super().__init__(dim_x=STATE_SIZE, dim_z=1)
            self.dt_s = 0.0
            self.move_position = True

        def predict_x(self, u: Any = 0) -> None:
            """Move the state by ``dt_s`` along the arc (midpoint heading); position only if ``move_position``."""
            x = self.x
            dt = self.dt_s
            v = x[IV, 0]
            w = x[IW, 0]
            if self.move_position:
                yaw_mid = x[IYAW, 0] + 0.5 * w * dt
                x[IX, 0] += v * math.cos(yaw_mid) * dt
                x[IY, 0] += v * math.sin(yaw_mid) * dt
            x[IYAW, 0] = wrap_angle(x[IYAW, 0] + w * dt)

    return _UnicycleEkf


def _angle_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Measurement residual for angles: the difference wrapped to [-pi, pi)."""
    return (a - b + math.pi) % (2.0 * math.pi) - math.pi


def _gps_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Residual of [east, north, course]: metres as they are, the course wrapped to [-pi, pi)."""
    r = a - b
    r[2, 0] = (r[2, 0] + math.pi) % (2.0 * math.pi) - math.pi
    return r


class EkfEstimator:
    """Fuses odometry, gyro, optional magnetometer and GPS into a :class:`FusedPose`.

    ``frame``: the local ENU frame (the world's datum) or None to anchor it at
    the first good fix. ``track_width_m`` overrides the config's. Faults the
    filter notices (a GPS reset after persistent rejections, an odometry
    counter jump) go to ``events``. Counters: ``gps_rejected_count``,
    ``gps_reset_count``, ``course_rejected_count``, ``mag_rejected_count``.
    """

    def __init__(self, config: Optional[EkfConfig] = None, frame: Optional[LocalFrame] = None,
                 events: EventSink = ignore_events, track_width_m: Optional[float] = None) -> None:
        self.config = config if config is not None else EkfConfig()
        self.events = events
        self.track_width_m = float(track_width_m) if track_width_m is not None else self.config.track_width_m
        if self.track_width_m <= 0.0:
            raise ValueError(f"ekf: track_width_m must be > 0, got {self.track_width_m}")
        cfg = self.config
        self._kf = _unicycle_ekf_class()()
        self._kf.P = np.diag([1.0, 1.0, 1.0, cfg.initial_speed_sigma_mps ** 2, cfg.initial_yaw_rate_sigma_rps ** 2,
                              cfg.initial_gyro_bias_sigma_rps ** 2])
        self._frame = frame
        self._position_valid = frame is not None and cfg.start_at_datum
        if self._position_valid:
            self._kf.P[IX, IX] = self._kf.P[IY, IY] = cfg.initial_position_sigma_m ** 2
        self._heading_valid = False
        self._last_t: Optional[float] = None
        self._last_odo: Optional[WheelOdometry] = None
        self._last_gyro_s: Optional[float] = None
        self.distance_m = 0.0
        self.gps_rejected_count = 0
        self.gps_reset_count = 0
        self.course_rejected_count = 0
        self.mag_rejected_count = 0
        self._rejecting_since_s: Optional[float] = None
        # motion-based heading initialisation: odometric track in the filter's own (unknown) yaw
        self._odo_x = 0.0
        self._odo_y = 0.0
        self._init_pairs: list[tuple[float, float, float, float]] = []
        # preallocated matrices (the update runs every tick, >100x real time in the simulator)
        self._F = np.eye(STATE_SIZE)
        self._Q = np.zeros((STATE_SIZE, STATE_SIZE))
        self._kf.F = self._F
        self._kf.Q = self._Q
        self._H_motion = np.zeros((3, STATE_SIZE))
        self._H_motion[0, IV] = 1.0                          # odometry speed
        self._H_motion[1, IW] = 1.0                          # odometry yaw rate
        self._H_motion[2, IW] = self._H_motion[2, IB] = 1.0  # gyro z = yaw rate + bias
        self._H_gps = np.zeros((3, STATE_SIZE))           # east, north (lag-corrected), course
        self._H_gps[0, IX] = self._H_gps[1, IY] = self._H_gps[2, IYAW] = 1.0
        self._H_yaw = np.zeros((1, STATE_SIZE))
        self._H_yaw[0, IYAW] = 1.0
        self._z1 = np.zeros((1, 1))
        self._R1 = np.zeros((1, 1))

    # -- public state -----------------------------------------------------------------------

    @property
    def frame(self) -> Optional[LocalFrame]:
        """The georeferenced local frame: the datum given, or the one anchored at the first fix."""
        return self._frame

    @property
    def heading_valid(self) -> bool:
        """True once the heading is known in the world (magnetometer, GPS course or motion)."""
        return self._heading_valid

    @property
    def position_valid(self) -> bool:
        """True once the position is known in the world (a fix, or the datum at start)."""
        return self._position_valid

    @property
    def state(self) -> np.ndarray:
        """A copy of the state vector [x_m, y_m, yaw_rad, v_mps, yaw_rate_rps, gyro_bias_rps]."""
        return self._kf.x[:, 0].copy()

    @property
    def covariance(self) -> np.ndarray:
        """A copy of the 6x6 state covariance (SI units squared)."""
        return self._kf.P.copy()

    # -- the Estimator protocol ---------------------------------------------------------------

    def update(self, now_s: float, odometry: Sequence[WheelOdometry] = (), imu: Sequence[ImuSample] = (),
               gps: Sequence[GpsFix] = ()) -> FusedPose:
        """Predict to ``now_s`` (s), fuse the new readings (oldest first) and return the pose."""
        if self._last_t is None:
            self._last_t = now_s
        dt = now_s - self._last_t
        if dt > 0.0:
            self._predict(dt)
            self._last_t = now_s
        self._fuse_motion(now_s, odometry, imu)
        if imu and self.config.use_magnetometer:
            self._fuse_magnetometer(imu)
        if self.config.use_gps:
            for fix in gps:
                self._fuse_gps(now_s, fix)
        return self._pose(now_s)

    # -- prediction -------------------------------------------------------------------------

    def _predict(self, dt: float) -> None:
        cfg = self.config
        kf = self._kf
        x = kf.x
        v = x[IV, 0]
        F = self._F
        Q = self._Q
        Q[IX, IX] = Q[IY, IY] = cfg.position_noise_mps ** 2 * dt
        # Once the position is known in the world but the heading is not, moving the position
        # along an arbitrary yaw would be wrong: hold it and let it wander by the distance driven.
        move = self._heading_valid or not self._position_valid
        kf.move_position = move
        if move:
            yaw_mid = x[IYAW, 0] + 0.5 * x[IW, 0] * dt
            c, s = math.cos(yaw_mid), math.sin(yaw_mid)
            F[IX, IYAW] = -v * s * dt
            F[IX, IV] = c * dt
            F[IX, IW] = -0.5 * v * s * dt * dt
            F[IY, IYAW] = v * c * dt
            F[IY, IV] = s * dt
            F[IY, IW] = 0.5 * v * c * dt * dt
        else:
            F[IX, IYAW] = F[IX, IV] = F[IX, IW] = F[IY, IYAW] = F[IY, IV] = F[IY, IW] = 0.0
            # driving in an unknown direction: each axis' standard deviation grows by the
            # distance / sqrt(2) (coherent motion, not a random walk of independent steps)
            step = abs(v) * dt * _SQRT_HALF
            for i in (IX, IY):
                Q[i, i] += step * (2.0 * math.sqrt(max(kf.P[i, i], 0.0)) + step)
        F[IYAW, IW] = dt
        Q[IYAW, IYAW] = cfg.yaw_noise_rps ** 2 * dt
        Q[IV, IV] = cfg.accel_noise_mps2 ** 2 * dt
        Q[IW, IW] = cfg.yaw_accel_noise_rps2 ** 2 * dt
        Q[IB, IB] = cfg.gyro_bias_walk_rps_sqrts ** 2 * dt
        kf.dt_s = dt
        kf.predict()

    # -- odometry and gyro --------------------------------------------------------------------

    def _fuse_motion(self, now_s: float, odometry: Sequence[WheelOdometry], imu: Sequence[ImuSample]) -> None:
        """Fuse odometry speed/yaw rate and the mean gyro z in one stacked update."""
        cfg = self.config
        rows: list[int] = []
        z: list[float] = []
        r: list[float] = []
        if odometry:
            v_odo, w_odo, still = self._odometry_rates(odometry)
            if still:
                sigma_v, sigma_w = cfg.standstill_speed_noise_mps, cfg.standstill_yaw_rate_noise_rps
            else:
                sigma_v = cfg.odom_speed_noise_mps + cfg.odom_speed_noise_frac * abs(v_odo)
                sigma_w = cfg.odom_yaw_rate_noise_rps + cfg.odom_yaw_rate_noise_frac * abs(w_odo)
            rows.append(0)
            z.append(v_odo)
            r.append(sigma_v * sigma_v)
            gyro_working = self._last_gyro_s is not None and now_s - self._last_gyro_s <= _GYRO_RECENT_S
            if still or cfg.odom_yaw_rate_with_gyro or not (gyro_working or (imu and cfg.use_gyro)):
                rows.append(1)
                z.append(w_odo)
                r.append(sigma_w * sigma_w)
        if imu and cfg.use_gyro:
            gz = 0.0
            for sample in imu:
                gz += sample.gyro_rps[2]
            self._last_gyro_s = now_s
            rows.append(2)
            z.append(gz / len(imu))
            r.append(cfg.gyro_noise_rps ** 2 / len(imu))
        if not rows:
            return
        H = self._H_motion[rows]
        self._kf.update(np.array(z).reshape(-1, 1), lambda _x: H, lambda x: H @ x, R=np.diag(r))

    def _odometry_rates(self, odometry: Sequence[WheelOdometry]) -> tuple[float, float, bool]:
        """Forward speed (m/s), yaw rate (rad/s) and standstill flag from the new odometry readings.

        Uses the wheel travel since the previous reading (a mean over the
        interval); falls back to the reported wheel speeds for the first reading.
        Also advances the odometric path length and the dead-reckoned track.
        """
        cfg = self.config
        sum_l = sum_r = 0.0
        dt_sum = 0.0
        for odo in odometry:
            prev = self._last_odo
            self._last_odo = odo
            if prev is None:
                continue
            dl = odo.left_m - prev.left_m
            dr = odo.right_m - prev.right_m
            if abs(dl) > cfg.odom_max_step_m or abs(dr) > cfg.odom_max_step_m:
                self.events("ekf_odometry_jump", f"wheel travel jumped by {dl:+.2f}/{dr:+.2f} m between "
                                                 "two readings (base restarted?); step ignored")
                continue
            sum_l += dl
            sum_r += dr
            dt_sum += odo.stamp_s - prev.stamp_s
        last = odometry[-1]
        if dt_sum > 1e-6:
            v = 0.5 * (sum_l + sum_r) / dt_sum
            w = (sum_r - sum_l) / self.track_width_m / dt_sum
        else:
            v = 0.5 * (last.left_mps + last.right_mps)
            w = (last.right_mps - last.left_mps) / self.track_width_m
        ds = 0.5 * (sum_l + sum_r)
        self.distance_m += abs(ds)
        if not self._heading_valid and ds != 0.0:
            yaw = self._kf.x[IYAW, 0]
            self._odo_x += ds * math.cos(yaw)
            self._odo_y += ds * math.sin(yaw)
        still_limit = cfg.standstill_speed_mps
        still = (abs(last.left_mps) < still_limit and abs(last.right_mps) < still_limit
                 and (dt_sum <= 1e-6 or (abs(sum_l) < still_limit * dt_sum and abs(sum_r) < still_limit * dt_sum)))
        return v, w, still

    # -- magnetometer -----------------------------------------------------------------------

    def magnetic_heading(self, sample: ImuSample) -> Optional[float]:
        """True heading (yaw, rad CCW from east) from one sample's magnetometer, or None.

        The field is levelled with the accelerometer's gravity direction when
        ``mag_tilt_compensation`` is on and the robot is not accelerating
        much; the declination turns magnetic north into true north.
        """
        if sample.mag_t is None:
            return None
        mx, my, mz = sample.mag_t
        ux, uy, uz = 0.0, 0.0, 1.0
        if self.config.mag_tilt_compensation:
            ax, ay, az = sample.accel_mps2
            norm = math.sqrt(ax * ax + ay * ay + az * az)
            if abs(norm - _GRAVITY_MPS2) < _TILT_ACCEL_TOLERANCE_MPS2:
                ux, uy, uz = ax / norm, ay / norm, az / norm
        # horizontal parts (perpendicular to "up") of the field and of the body x axis
        mu = mx * ux + my * uy + mz * uz
        hx, hy, hz = mx - mu * ux, my - mu * uy, mz - mu * uz
        bx, by, bz = 1.0 - ux * ux, -ux * uy, -ux * uz
        dot = bx * hx + by * hy + bz * hz
        cross_up = ux * (by * hz - bz * hy) + uy * (bz * hx - bx * hz) + uz * (bx * hy - by * hx)
        if dot == 0.0 and cross_up == 0.0:
            return None
        # angle from the body x axis to magnetic north, CCW about up; magnetic north lies at
        # pi/2 - declination CCW from east, so yaw = that minus this angle
        north_rel = math.atan2(cross_up, dot)
        return wrap_angle(math.pi / 2.0 - math.radians(self.config.declination_deg) - north_rel)

    def _fuse_magnetometer(self, imu: Sequence[ImuSample]) -> None:
        heading = None
        for sample in reversed(imu):
            heading = self.magnetic_heading(sample)
            if heading is not None:
                break
        if heading is None:
            return
        sigma = self.config.mag_heading_noise_rad
        if not self._heading_valid:
            self._set_heading(heading, sigma * sigma)
            return
        if not self._fuse_yaw(heading, sigma * sigma, self.config.mag_gate_chi2):
            self.mag_rejected_count += 1

    def _fuse_yaw(self, yaw_meas: float, var: float, gate_chi2: float) -> bool:
        """Fuse a heading measurement (rad) with variance ``var`` unless gated out; True if fused."""
        kf = self._kf
        innovation = wrap_angle(yaw_meas - kf.x[IYAW, 0])
        s = kf.P[IYAW, IYAW] + var
        if innovation * innovation / s > gate_chi2:
            return False
        self._z1[0, 0] = yaw_meas
        self._R1[0, 0] = var
        H = self._H_yaw
        kf.update(self._z1, lambda _x: H, lambda x: H @ x, R=self._R1, residual=_angle_residual)
        kf.x[IYAW, 0] = wrap_angle(kf.x[IYAW, 0])
        return True

    def _set_heading(self, yaw: float, var: float) -> None:
        """Declare the heading known: set yaw and its variance, forget its old correlations."""
        kf = self._kf
        kf.x[IYAW, 0] = wrap_angle(yaw)
        kf.P[IYAW, :] = 0.0
        kf.P[:, IYAW] = 0.0
        kf.P[IYAW, IYAW] = var
        self._heading_valid = True
        self._init_pairs.clear()

    # -- GPS --------------------------------------------------------------------------------

    def _set_position(self, e: float, n: float, cov: np.ndarray) -> None:
        """Put the position at (e, n) m with covariance ``cov`` (2x2), uncorrelated with the rest."""
        kf = self._kf
        kf.x[IX, 0] = e
        kf.x[IY, 0] = n
        kf.P[0:2, :] = 0.0
        kf.P[:, 0:2] = 0.0
        kf.P[0:2, 0:2] = cov

    def _fuse_gps(self, now_s: float, fix: GpsFix) -> None:
        cfg = self.config
        if fix.quality < cfg.min_gps_quality:
            return
        if self._frame is None:
            alt = fix.alt_msl if fix.alt_msl is not None else 0.0
            self._frame = LocalFrame(fix.lat, fix.lon, alt)
        e, n, _ = self._frame.to_enu(fix.lat, fix.lon, None)
        c = fix.covariance_enu
        R = np.array(((c[0][0], c[0][1]), (c[1][0], c[1][1])), dtype=float)
        if not (R[0, 0] > 0.0 and R[1, 1] > 0.0):
            R = np.diag([max(R[0, 0], 1e-4), max(R[1, 1], 1e-4)])
        if not self._position_valid:
            self._set_position(e, n, R)
            self._position_valid = True
            self._rejecting_since_s = None
            if not self._heading_valid:
                self._odo_x = self._odo_y = 0.0
                self._init_pairs.clear()
                self._init_pairs.append((0.0, 0.0, e, n))
            return
        kf = self._kf
        x = kf.x
        P = kf.P
        heading_known = self._heading_valid
        # a fix measured `lag` seconds ago saw the robot where it was then (only meaningful
        # once the heading is known; before that the position does not move with the speed)
        lag = min(max(now_s - fix.stamp_s, 0.0), cfg.gps_max_lag_s) if heading_known else 0.0
        v = x[IV, 0]
        yaw = x[IYAW, 0]
        cy, sy = math.cos(yaw), math.sin(yaw)
        H = self._H_gps
        H[0, IYAW] = v * sy * lag
        H[0, IV] = -cy * lag
        H[1, IYAW] = -v * cy * lag
        H[1, IV] = -sy * lag
        hx0 = x[IX, 0] - v * cy * lag
        hx1 = x[IY, 0] - v * sy * lag
        # Mahalanobis gate on the position, with plain floats (2x2): cheaper than numpy here
        ye = e - hx0
        yn = n - hx1
        H2 = H[0:2]
        S = H2 @ P @ H2.T + R
        det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
        d2 = (S[1, 1] * ye * ye - (S[0, 1] + S[1, 0]) * ye * yn + S[0, 0] * yn * yn) / det if det > 0.0 else math.inf
        if d2 > cfg.gps_gate_chi2:
            self.gps_rejected_count += 1
            if self._rejecting_since_s is None:
                self._rejecting_since_s = fix.stamp_s
            elif fix.stamp_s - self._rejecting_since_s >= cfg.gps_reset_after_s:
                # every fix disagreed for a long time: the filter, not the GPS, is wrong
                self._set_position(e, n, R * cfg.gps_reset_inflation)
                self.gps_reset_count += 1
                self.events("ekf_gps_reset", f"GPS fixes rejected for {fix.stamp_s - self._rejecting_since_s:.1f} s "
                                             f"(last {math.sqrt(d2):.1f} sigma off): position reset to the GPS")
                self._rejecting_since_s = None
                if not heading_known:
                    self._init_pairs.clear()
            return
        self._rejecting_since_s = None
        course = self._course(fix)
        if not heading_known:
            found = self._heading_from_motion(fix, e, n, R, course)
            if found == "fit":
                return  # position and heading both set from the fitted track
            course = None  # used up by the initialisation, or no heading to compare it with
        # the course over ground, gated on its own, joins the position in one stacked update
        if course is not None and abs(v) >= cfg.course_min_speed_mps:
            yaw_meas, var = course
            if v < 0.0:
                yaw_meas = wrap_angle(yaw_meas + math.pi)  # reversing: the track points backwards
            innovation = wrap_angle(yaw_meas - yaw)
            if innovation * innovation / (P[IYAW, IYAW] + var) > cfg.course_gate_chi2:
                self.course_rejected_count += 1
                course = None
            else:
                course = (yaw_meas, var)
        else:
            course = None
        if course is None:
            zv = np.array(((e,), (n,)))
            hx = np.array(((hx0,), (hx1,)))
            kf.update(zv, lambda _x: H2, lambda _x: hx, R=R)
        else:
            zv = np.array(((e,), (n,), (course[0],)))
            hx = np.array(((hx0,), (hx1,), (yaw,)))
            R3 = np.zeros((3, 3))
            R3[0:2, 0:2] = R
            R3[2, 2] = course[1]
            kf.update(zv, lambda _x: H, lambda _x: hx, R=R3, residual=_gps_residual)
        kf.x[IYAW, 0] = wrap_angle(kf.x[IYAW, 0])

    def _course(self, fix: GpsFix) -> Optional[tuple[float, float]]:
        """(yaw rad CCW from east, variance rad^2) of the fix's course over ground, if usable."""
        cfg = self.config
        if not cfg.use_gps_course or fix.track_deg is None or fix.speed_mps is None:
            return None
        if fix.speed_mps < cfg.course_min_speed_mps:
            return None
        sigma = max(cfg.course_noise_floor_rad, cfg.course_speed_noise_mps / fix.speed_mps)
        # track is clockwise from north; yaw counter-clockwise from east
        return wrap_angle(math.pi / 2.0 - math.radians(fix.track_deg)), sigma * sigma

    def _heading_from_motion(self, fix: GpsFix, e: float, n: float, R: np.ndarray,
                             course: Optional[tuple[float, float]]) -> Optional[str]:
        """Try to find the heading from a GPS course or from the GPS track against the odometric one.

        Returns "course" when the course set the heading, "fit" when the
        track fit set heading and position, None while still unknown.
        """
        cfg = self.config
        kf = self._kf
        if (course is not None and cfg.heading_init_from_course and kf.x[IV, 0] >= cfg.course_min_speed_mps
                and abs(kf.x[IW, 0]) < _COURSE_INIT_MAX_YAW_RATE_RPS
                and course[1] <= cfg.heading_init_course_max_sigma_rad ** 2):
            self._set_heading(course[0], course[1])
            return "course"
        pairs = self._init_pairs
        pairs.append((self._odo_x, self._odo_y, e, n))
        if len(pairs) > _HEADING_INIT_MAX_FIXES:
            del pairs[0]
        first = pairs[0]
        if len(pairs) < 3 or math.hypot(self._odo_x - first[0], self._odo_y - first[1]) < cfg.heading_init_distance_m:
            return None
        # Rotation that best maps the odometric track onto the GPS track (2-D Procrustes fit).
        a = np.array(pairs)
        odo = a[:, 0:2] - a[:, 0:2].mean(axis=0)
        gps = a[:, 2:4] - a[:, 2:4].mean(axis=0)
        dot = float(np.sum(odo[:, 0] * gps[:, 0] + odo[:, 1] * gps[:, 1]))
        cross = float(np.sum(odo[:, 0] * gps[:, 1] - odo[:, 1] * gps[:, 0]))
        spread = float(np.sum(odo * odo))
        if spread <= 0.0:
            return None
        angle = math.atan2(cross, dot)
        fix_var = 0.5 * (R[0, 0] + R[1, 1])
        # least-squares angle variance, doubled because GPS errors are correlated in time
        yaw_var = 2.0 * fix_var / spread
        ca, sa = math.cos(angle), math.sin(angle)
        last = odo[-1]
        centre = a[:, 2:4].mean(axis=0)
        px = centre[0] + ca * last[0] - sa * last[1]
        py = centre[1] + sa * last[0] + ca * last[1]
        pos_var = fix_var / len(pairs) + yaw_var * float(last @ last)
        self._set_heading(kf.x[IYAW, 0] + angle, yaw_var)
        self._set_position(px, py, np.eye(2) * pos_var)
        return "fit"

    # -- output -------------------------------------------------------------------------------

    def _pose(self, now_s: float) -> FusedPose:
        x = self._kf.x
        P = self._kf.P
        lat = lon = None
        if self._position_valid and self._frame is not None:
            lat, lon, _ = self._frame.to_geodetic(x[IX, 0], x[IY, 0], 0.0)
        return FusedPose(
            stamp_s=now_s,
            x=float(x[IX, 0]), y=float(x[IY, 0]), yaw=float(x[IYAW, 0]),
            speed_mps=float(x[IV, 0]), yaw_rate_rps=float(x[IW, 0]),
            covariance=((float(P[0, 0]), float(P[0, 1]), float(P[0, 2])),
                        (float(P[1, 0]), float(P[1, 1]), float(P[1, 2])),
                        (float(P[2, 0]), float(P[2, 1]), float(P[2, 2]))),
            distance_m=self.distance_m,
            heading_valid=self._heading_valid,
            position_valid=self._position_valid,
            lat=lat, lon=lon,
        )
