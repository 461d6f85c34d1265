"""The EKF on synthetic drives: a small kinematic truth, noisy odometry, gyro and GPS from a seeded rng."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Optional

import jsonschema
import numpy as np
import pytest

from beastbt.blackboard.types import FusedPose, GpsFix, ImuSample, WheelOdometry
from beastbt.estimation.ekf import EkfConfig, EkfEstimator
from beastbt.estimation.estimator import Estimator, wrap_angle
from beastbt.estimation.geodesy import LocalFrame

TRACK_M = 0.2
DT_S = 0.05
SCHEMA = Path(__file__).resolve().parents[1] / "schemas" / "parts" / "ekf.schema.json"


@dataclass
class Step:
    """One tick of a synthetic drive: the truth and what the filter said."""

    t: float
    x: float
    y: float
    yaw: float
    pose: FusedPose


@dataclass
class Drive:
    """The outcome of :func:`drive`."""

    est: EkfEstimator
    frame: LocalFrame
    steps: list[Step]
    raw_gps_errors_m: list[float] = field(default_factory=list)
    update_s: float = 0.0

    def position_errors_m(self) -> np.ndarray:
        """Horizontal error of each valid fused position (through lat/lon, so the frames may differ)."""
        out = []
        for s in self.steps:
            if s.pose.position_valid:
                e, n, _ = self.frame.to_enu(s.pose.lat, s.pose.lon, None)
                out.append(math.hypot(e - s.x, n - s.y))
        return np.array(out)

    def heading_error_deg(self, t: float) -> float:
        s = min(self.steps, key=lambda st: abs(st.t - t))
        return abs(math.degrees(wrap_angle(s.pose.yaw - s.yaw)))

    def at(self, t: float) -> Step:
        return min(self.steps, key=lambda st: abs(st.t - t))


def speed_profile(t: float) -> tuple[float, float]:
    """Stand still 3 s, speed up to 1 m/s, weave left and right (40 s period)."""
    v = 0.0 if t < 3.0 else min(1.0, (t - 3.0) / 2.0)
    w = 0.0 if t < 8.0 else 0.25 * math.sin(2.0 * math.pi * t / 40.0)
    return v, w


def drive(seed: int = 1, duration_s: float = 300.0, datum: tuple[float, float] = (47.0, 8.0),
          gps_sigma_m: float = 3.0, gps_period_s: float = 1.0, with_course: bool = True,
          velocity_sigma_mps: float = 0.1, jump_at_s: Optional[float] = None,
          dropout: Optional[tuple[float, float]] = None, gps_shift_after: Optional[tuple[float, float]] = None,
          gyro_bias_rps: float = 0.01, start_yaw: float = 0.7, config: Optional[EkfConfig] = None,
          give_datum: bool = False, profile=speed_profile) -> Drive:
    """Drive a unicycle truth and feed the EKF noisy odometry (1 % scale error), gyro and GPS.

    GPS: white noise of ``gps_sigma_m`` per axis every ``gps_period_s``, with a course from a velocity
    with ``velocity_sigma_mps`` noise; gyro: ``gyro_bias_rps`` plus 0.003 rad/s noise.
    """
    rng = np.random.default_rng(seed)
    frame = LocalFrame(*datum)
    est = EkfEstimator(config or EkfConfig(track_width_m=TRACK_M), frame=frame if give_datum else None)
    x = y = 0.0
    yaw = start_yaw
    left = right = 0.0
    next_gps = gps_period_s
    result = Drive(est, frame, [])
    for k in range(int(round(duration_s / DT_S))):
        t = (k + 1) * DT_S
        v, w = profile(t)
        for _ in range(5):  # finer truth integration than the filter's
            h = DT_S / 5
            x += v * math.cos(yaw + 0.5 * w * h) * h
            y += v * math.sin(yaw + 0.5 * w * h) * h
            yaw += w * h
        # encoders: 1 % scale error and 1 % slip noise on the travel, nothing while standing
        dl = (v - w * TRACK_M / 2) * DT_S
        dr = (v + w * TRACK_M / 2) * DT_S
        left += 1.01 * dl + rng.normal(0.0, 0.01 * abs(dl))
        right += 1.01 * dr + rng.normal(0.0, 0.01 * abs(dr))
        odo = WheelOdometry(t, left, right, v - w * TRACK_M / 2, v + w * TRACK_M / 2)
        imu = ImuSample(t, (0.0, 0.0, w + gyro_bias_rps + rng.normal(0, 0.003)), (0.0, 0.0, 9.81))
        fixes = []
        if t >= next_gps - 1e-9:
            next_gps += gps_period_s
            if not (dropout and dropout[0] <= t < dropout[1]):
                e = x + rng.normal(0, gps_sigma_m)
                n = y + rng.normal(0, gps_sigma_m)
                result.raw_gps_errors_m.append(math.hypot(e - x, n - y))
                if jump_at_s is not None and abs(t - jump_at_s) < 0.5 * gps_period_s:
                    e += 20.0
                if gps_shift_after is not None and t >= gps_shift_after[0]:
                    n += gps_shift_after[1]
                lat, lon, _ = frame.to_geodetic(e, n, 0.0)
                speed = track = None
                if with_course:
                    vx = v * math.cos(yaw) + rng.normal(0, velocity_sigma_mps)
                    vy = v * math.sin(yaw) + rng.normal(0, velocity_sigma_mps)
                    speed = math.hypot(vx, vy)
                    track = math.degrees(math.atan2(vx, vy)) % 360.0
                var = gps_sigma_m ** 2
                fixes.append(GpsFix(t, lat, lon, speed_mps=speed, track_deg=track,
                                    covariance_enu=((var, 0.0, 0.0), (0.0, var, 0.0), (0.0, 0.0, 4 * var))))
        start = time.perf_counter()
        pose = est.update(t, [odo], [imu], fixes)
        result.update_s += time.perf_counter() - start
        result.steps.append(Step(t, x, y, yaw, pose))
    return result


def rms(a) -> float:
    a = np.asarray(a)
    return float(np.sqrt(np.mean(a * a)))


def test_implements_the_estimator_protocol() -> None:
    est: Estimator = EkfEstimator()
    pose = est.update(0.0, [], [], [])
    assert isinstance(pose, FusedPose) and est.frame is None


def test_fused_position_beats_raw_gps() -> None:
    d = drive(seed=1)
    fused = rms(d.position_errors_m())
    raw = rms(d.raw_gps_errors_m)
    per_call_us = d.update_s / len(d.steps) * 1e6
    print(f"\nEKF: raw GPS RMS {raw:.2f} m, fused RMS {fused:.2f} m, {per_call_us:.0f} us per update()")
    assert 3.5 < raw < 5.0  # the GPS really is that bad
    assert fused <= 0.4 * raw
    assert d.est.gps_rejected_count <= 2  # honest 3 m noise is not rejected


def test_single_gps_jump_barely_moves_the_estimate() -> None:
    base = drive(seed=2, duration_s=200.0)
    jumped = drive(seed=2, duration_s=200.0, jump_at_s=120.0)
    assert jumped.est.gps_rejected_count == base.est.gps_rejected_count + 1
    moved = max(math.hypot(a.pose.x - b.pose.x, a.pose.y - b.pose.y) for a, b in zip(base.steps, jumped.steps))
    assert moved < 1.0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_heading_holds_through_gps_dropout(seed: int) -> None:
    d = drive(seed=seed, duration_s=175.0, dropout=(160.0, 170.0))
    assert d.heading_error_deg(169.95) < 3.0
    end = d.at(169.95)
    e, n, _ = d.frame.to_enu(end.pose.lat, end.pose.lon, None)
    assert math.hypot(e - end.x, n - end.y) < 2.0  # ten seconds of dead reckoning at 1 m/s


def test_heading_found_from_motion_without_magnetometer_or_course() -> None:
    d = drive(seed=4, duration_s=120.0, with_course=False)
    standing = [s for s in d.steps if s.t < 3.0 and s.pose.position_valid]
    assert standing and not any(s.pose.heading_valid for s in standing)  # GPS wander is not motion
    first = next(s for s in d.steps if s.pose.heading_valid)
    assert 3.0 + 9.0 < first.t < 3.0 + 20.0  # after about heading_init_distance_m of driving
    claimed_deg = math.degrees(math.sqrt(first.pose.covariance[2][2]))
    error_deg = abs(math.degrees(wrap_angle(first.pose.yaw - first.yaw)))
    assert error_deg < 3.0 * claimed_deg and error_deg < 30.0
    late = [abs(math.degrees(wrap_angle(s.pose.yaw - s.yaw))) for s in d.steps if s.t > 60.0]
    assert max(late) < 10.0


def test_heading_found_from_gps_course() -> None:
    d = drive(seed=5, duration_s=30.0)
    first = next(s for s in d.steps if s.pose.heading_valid)
    assert first.t < 8.0  # as soon as the robot moves fast enough for a usable course
    assert abs(math.degrees(wrap_angle(first.pose.yaw - first.yaw))) < 20.0
    assert d.heading_error_deg(29.0) < 5.0


def test_no_position_before_first_fix_then_anchored_there() -> None:
    est = EkfEstimator(EkfConfig(track_width_m=TRACK_M))
    pose = est.update(0.0, [WheelOdometry(0.0, 0.0, 0.0)], [], [])
    assert not pose.position_valid and not pose.heading_valid and pose.lat is None
    est.update(0.5, [WheelOdometry(0.5, 0.25, 0.25, 0.5, 0.5)], [], [])
    pose = est.update(1.0, [WheelOdometry(1.0, 0.5, 0.5, 0.5, 0.5)], [], [])
    assert not pose.position_valid
    assert pose.x == pytest.approx(0.25, abs=0.05)  # dead reckoning from (0, 0) meanwhile
    fix = GpsFix(1.5, -12.5, 130.8, alt_msl=30.0)
    pose = est.update(1.5, [WheelOdometry(1.5, 0.75, 0.75, 0.5, 0.5)], [], [fix])
    assert pose.position_valid and est.frame is not None
    assert est.frame.lat0_deg == -12.5 and est.frame.lon0_deg == 130.8
    assert (pose.x, pose.y) == (0.0, 0.0)
    assert pose.lat == pytest.approx(-12.5, abs=1e-9) and pose.lon == pytest.approx(130.8, abs=1e-9)
    assert pose.covariance[0][0] == pytest.approx(9.0)


def test_starts_valid_at_a_given_datum() -> None:
    frame = LocalFrame(51.5, -0.1)
    est = EkfEstimator(EkfConfig(track_width_m=TRACK_M), frame=frame)
    pose = est.update(0.0, [WheelOdometry(0.0, 0.0, 0.0)], [], [])
    assert pose.position_valid and est.frame is frame
    assert (pose.lat, pose.lon) == pytest.approx((51.5, -0.1))
    late = EkfEstimator(EkfConfig(track_width_m=TRACK_M, start_at_datum=False), frame=frame)
    assert not late.update(0.0, [], [], []).position_valid


def test_southern_hemisphere_across_the_antimeridian() -> None:
    d = drive(seed=6, duration_s=200.0, datum=(-33.9, 179.9999), start_yaw=0.0,
              profile=lambda t: (0.0 if t < 3.0 else 1.0, 0.0))
    lons = [s.pose.lon for s in d.steps if s.pose.position_valid]
    assert max(lons) > 179.9995 and min(lons) < -179.999  # it really crossed
    assert rms(d.position_errors_m()) <= 0.4 * rms(d.raw_gps_errors_m)
    end = d.steps[-1]
    assert end.pose.lat == pytest.approx(-33.9, abs=2e-4)
    assert d.heading_error_deg(end.t) < 5.0


def test_given_datum_is_used_as_the_frame() -> None:
    d = drive(seed=7, duration_s=60.0, datum=(-33.9, 179.9999), give_datum=True)
    assert d.est.frame == LocalFrame(-33.9, 179.9999)
    assert all(s.pose.position_valid for s in d.steps)
    assert rms(d.position_errors_m()[-400:]) < 2.5


def test_reset_after_persistent_rejection() -> None:
    cfg = EkfConfig(track_width_m=TRACK_M, gps_reset_after_s=10.0)
    d = drive(seed=8, duration_s=140.0, gps_shift_after=(100.0, 60.0), config=cfg)  # the GPS moved 60 m north
    assert d.est.gps_reset_count == 1
    at_105 = d.at(105.0)
    e, n, _ = d.frame.to_enu(at_105.pose.lat, at_105.pose.lon, None)
    assert abs(n - at_105.y) < 3.0  # still trusting itself shortly after the shift
    end = d.steps[-1]
    e, n, _ = d.frame.to_enu(end.pose.lat, end.pose.lon, None)
    assert abs(n - (end.y + 60.0)) < 5.0  # following the GPS again


def test_reset_reports_an_event() -> None:
    events: list[tuple[str, str]] = []
    est = EkfEstimator(EkfConfig(track_width_m=TRACK_M), frame=LocalFrame(0.0, 0.0),
                       events=lambda k, t: events.append((k, t)))
    frame = est.frame
    for k in range(400):
        t = k * DT_S
        fixes = []
        if k % 20 == 0:
            lat, lon, _ = frame.to_geodetic(0.0, 0.0 if t < 5.0 else 100.0)
            fixes = [GpsFix(t, lat, lon)]
        est.update(t, [WheelOdometry(t, 0.0, 0.0)], [], fixes)
    assert [k for k, _ in events] == ["ekf_gps_reset"]
    assert est.gps_rejected_count >= 10


def test_gyro_bias_learned_while_standing_still() -> None:
    est = EkfEstimator(EkfConfig(track_width_m=TRACK_M))
    rng = np.random.default_rng(9)
    for k in range(600):  # 30 s still, the gyro reads its bias
        t = k * DT_S
        pose = est.update(t, [WheelOdometry(t, 0.0, 0.0)],
                          [ImuSample(t, (0.0, 0.0, 0.02 + rng.normal(0, 0.003)), (0.0, 0.0, 9.81))], [])
    assert est.state[5] == pytest.approx(0.02, abs=1e-3)
    assert abs(pose.yaw) < math.radians(0.5)
    assert pose.speed_mps == pytest.approx(0.0, abs=0.01)


def test_gyro_rate_used_when_wheels_skid() -> None:
    """Tracks skid: the wheels claim half the turn; the gyro wins the yaw rate."""
    est = EkfEstimator(EkfConfig(track_width_m=TRACK_M))
    left = right = 0.0
    for k in range(1, 101):
        t = k * DT_S
        left += (0.5 - 0.25 * TRACK_M / 2) * DT_S
        right += (0.5 + 0.25 * TRACK_M / 2) * DT_S
        pose = est.update(t, [WheelOdometry(t, left, right, 0.5 - 0.025, 0.5 + 0.025)],
                          [ImuSample(t, (0.0, 0.0, 0.5), (0.0, 0.0, 9.81))], [])
    assert pose.yaw_rate_rps == pytest.approx(0.5, abs=0.03)
    assert pose.speed_mps == pytest.approx(0.5, abs=0.02)
    assert pose.distance_m == pytest.approx(2.5 - 0.5 * DT_S)  # travel since the first reading


def test_distance_is_odometric_path_length_and_counter_jumps_are_ignored() -> None:
    events: list[tuple[str, str]] = []
    est = EkfEstimator(EkfConfig(track_width_m=TRACK_M), events=lambda k, t: events.append((k, t)))
    est.update(0.0, [WheelOdometry(0.0, 0.0, 0.0)], [], [])
    est.update(1.0, [WheelOdometry(1.0, 1.0, 1.0, 1.0, 1.0)], [], [])
    est.update(2.0, [WheelOdometry(2.0, 0.5, 0.5, -0.5, -0.5)], [], [])  # backwards
    pose = est.update(3.0, [WheelOdometry(3.0, 100.0, 100.0, 0.0, 0.0)], [], [])  # counter reset
    assert pose.distance_m == pytest.approx(1.5)
    assert [k for k, _ in events] == ["ekf_odometry_jump"]


def _mag_sample(yaw: float, declination_deg: float, pitch: float = 0.0, roll: float = 0.0) -> ImuSample:
    """A magnetometer + accelerometer sample of a robot at ``yaw`` (and tilted), field 50 uT, dip 60 deg."""
    dec = math.radians(declination_deg)
    h, vert = 50e-6 * math.cos(math.radians(60.0)), 50e-6 * math.sin(math.radians(60.0))
    field_enu = np.array((h * math.sin(dec), h * math.cos(dec), -vert))
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    # body orientation in the world: Rz(yaw) Ry(pitch) Rx(roll); world -> body is its transpose
    rz = np.array(((cy, -sy, 0), (sy, cy, 0), (0, 0, 1)))
    ry = np.array(((cp, 0, sp), (0, 1, 0), (-sp, 0, cp)))
    rx = np.array(((1, 0, 0), (0, cr, -sr), (0, sr, cr)))
    world_to_body = (rz @ ry @ rx).T
    mag = world_to_body @ field_enu
    accel = world_to_body @ np.array((0.0, 0.0, 9.80665))
    return ImuSample(0.0, (0.0, 0.0, 0.0), tuple(accel), tuple(mag))


@pytest.mark.parametrize("yaw", [0.0, 1.0, 2.5, -2.0])
def test_magnetic_heading_with_declination(yaw: float) -> None:
    est = EkfEstimator(EkfConfig(use_magnetometer=True, declination_deg=12.0))
    assert est.magnetic_heading(_mag_sample(yaw, 12.0)) == pytest.approx(yaw, abs=1e-9)
    tilted = _mag_sample(yaw, 12.0, pitch=math.radians(12.0), roll=math.radians(-8.0))
    assert est.magnetic_heading(tilted) == pytest.approx(yaw, abs=1e-9)
    flat = EkfEstimator(EkfConfig(use_magnetometer=True, declination_deg=12.0, mag_tilt_compensation=False))
    assert abs(wrap_angle(flat.magnetic_heading(tilted) - yaw)) > math.radians(2.0)  # tilt matters


def test_magnetometer_gives_heading_at_once() -> None:
    est = EkfEstimator(EkfConfig(track_width_m=TRACK_M, use_magnetometer=True, declination_deg=-5.0))
    rng = np.random.default_rng(10)
    for k in range(100):
        t = k * DT_S
        s = _mag_sample(2.0, -5.0)
        noisy = ImuSample(t, (0.0, 0.0, rng.normal(0, 0.003)), s.accel_mps2,
                          tuple(np.array(s.mag_t) + rng.normal(0, 0.3e-6, 3)))
        pose = est.update(t, [WheelOdometry(t, 0.0, 0.0)], [noisy], [])
        if k == 0:
            assert pose.heading_valid
    assert pose.yaw == pytest.approx(2.0, abs=math.radians(1.0))
    off = EkfEstimator(EkfConfig(track_width_m=TRACK_M))  # off by default
    assert not off.update(0.0, [], [_mag_sample(2.0, 0.0)], []).heading_valid


def test_config_from_dict_and_schema() -> None:
    cfg = EkfConfig.from_dict({"track_width_m": 0.25, "use_magnetometer": True, "declination_deg": -11})
    assert cfg.track_width_m == 0.25 and cfg.declination_deg == -11.0
    with pytest.raises(ValueError, match="track_width_m"):
        EkfConfig.from_dict({"trackwidth_m": 0.25})
    with pytest.raises(ValueError, match="gps_gate_chi2"):
        EkfConfig.from_dict({"gps_gate_chi2": -1})
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["additionalProperties"] is False
    assert set(schema["properties"]) == {f.name for f in fields(EkfConfig)}
    for f in fields(EkfConfig):
        assert schema["properties"][f.name]["default"] == f.default, f.name
    validator = jsonschema.Draft202012Validator(schema)
    assert not list(validator.iter_errors({"track_width_m": 0.3, "use_gps_course": False}))
    assert list(validator.iter_errors({"track_widht_m": 0.3}))
