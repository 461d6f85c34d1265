"""The Foxglove messages the writer builds, piece by piece: one fix per GNSS epoch, the fused fix, the frames.

Whole recorded runs against Foxglove's official schemas are in test_foxglove_conformance.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.blackboard.types import FusedPose, GpsFix, LineObservation
from beastbt.recording.config import FramesConfig
from beastbt.recording.foxglove import (CameraMount, EpochFixes, camera_calibration, frame_transforms,
                                        fused_location_fix, line_annotations, location_fix, map_to_odom, odometry)
from beastbt.vision.camera_model import CameraGeometry


def gga(t: float, utc: str, lat: float = 40.0) -> GpsFix:
    return GpsFix(t, lat, -3.0, alt_msl=650.0, quality=1, sats=8, hdop=0.9, time_utc=utc, sentence="GGA",
                  covariance_enu=((12.96, 0, 0), (0, 12.96, 0), (0, 0, 51.84)))


def rmc(t: float, utc: str, lat: float = 40.0) -> GpsFix:
    return GpsFix(t, lat, -3.0, alt_msl=None, quality=1, sats=None, hdop=0.9, speed_mps=0.2, track_deg=90.0,
                  time_utc=utc, sentence="RMC", covariance_enu=((12.96, 0, 0), (0, 12.96, 0), (0, 0, 51.84)))


def test_gga_and_rmc_of_one_epoch_make_one_fix_with_what_each_knew():
    epochs = EpochFixes()
    (fix,) = epochs.take([gga(1.0, "T1"), rmc(1.0, "T1", lat=40.00001)])
    assert fix.sentence == "GGA+RMC" and fix.lat == 40.00001  # the later sentence's position
    assert fix.alt_msl == 650.0 and fix.sats == 8  # from GGA, which RMC lacks
    assert fix.speed_mps == 0.2 and fix.track_deg == 90.0  # from RMC


def test_an_epoch_split_across_two_ticks_is_published_once():
    epochs = EpochFixes()
    assert len(epochs.take([gga(1.0, "T1")])) == 1
    assert epochs.take([rmc(1.05, "T1")]) == []  # the RMC of the epoch already out
    two = epochs.take([gga(2.0, "T2"), rmc(2.0, "T2"), gga(3.0, "T3")])  # a late poll: two epochs at once
    assert [f.time_utc for f in two] == ["T2", "T3"]


def test_fixes_without_a_date_join_the_epoch_after_them_or_come_one_per_tick():
    epochs = EpochFixes()
    (fix,) = epochs.take([gga(1.0, None), rmc(1.0, "T1")])
    assert fix.time_utc == "T1" and fix.alt_msl == 650.0
    assert len(epochs.take([gga(2.0, None)])) == 1 and len(epochs.take([gga(3.0, None)])) == 1


def test_location_fix_carries_the_hdop_covariance_approximated():
    msg = location_fix(gga(1.0, "T1"), 1_700_000_000_123_456_789, "gps")
    assert msg["timestamp"] == {"sec": 1_700_000_000, "nsec": 123_456_789}
    assert msg["position_covariance"] == [12.96, 0, 0, 0, 12.96, 0, 0, 0, 51.84]
    assert msg["position_covariance_type"] == 1 and msg["altitude"] == 650.0


def test_fused_fix_has_the_ekf_covariance_and_waits_for_a_place_on_earth():
    cov = ((0.5, 0.1, 0.0), (0.1, 0.4, 0.0), (0.0, 0.0, 0.01))
    pose = FusedPose(1.0, 2.0, 3.0, 0.0, covariance=cov, lat=40.0, lon=-3.0)
    msg = fused_location_fix(pose, 5, "base_link", 650.0, 51.84)
    assert msg["position_covariance"] == [0.5, 0.1, 0.0, 0.1, 0.4, 0.0, 0.0, 0.0, 51.84]
    assert (msg["latitude"], msg["longitude"], msg["altitude"]) == (40.0, -3.0, 650.0)
    assert fused_location_fix(FusedPose(1.0, 2.0, 3.0, 0.0, position_valid=False, lat=40.0, lon=-3.0), 5,
                              "base_link", 0.0, 1.0) is None
    assert fused_location_fix(FusedPose(1.0, 2.0, 3.0, 0.0), 5, "base_link", 0.0, 1.0) is None


# -- frames ------------------------------------------------------------------------------------------


def rotation(q: dict) -> np.ndarray:
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def chain(transforms: list[dict], child: str) -> tuple[np.ndarray, np.ndarray]:
    """(rotation, translation) of ``child`` in the root of the tree, composing parent after parent."""
    by_child = {t["child_frame_id"]: t for t in transforms}
    r, p = np.eye(3), np.zeros(3)
    frame = child
    while frame in by_child:
        t = by_child[frame]
        rt, tt = rotation(t["rotation"]), np.array([t["translation"][k] for k in "xyz"])
        r, p = rt @ r, rt @ p + tt
        frame = t["parent_frame_id"]
    assert frame == "map"
    return r, p


def test_map_odom_base_puts_the_robot_at_the_fused_pose():
    pose = FusedPose(1.0, 10.0, 5.0, 1.0)
    odom = FusedPose(1.0, 2.0, -1.0, 0.3)
    x, y, yaw = map_to_odom(pose, odom)
    assert yaw == pytest.approx(0.7)
    msg = frame_transforms(7, FramesConfig(), pose, odom, None, 0.0, 0.0)
    r, p = chain(msg["transforms"], "base_link")
    assert p[:2] == pytest.approx([10.0, 5.0]) and math.atan2(r[1, 0], r[0, 0]) == pytest.approx(1.0)
    assert {t["child_frame_id"] for t in msg["transforms"]} == {"odom", "base_link", "gps"}  # no camera


def test_the_camera_looks_where_its_mounting_and_the_gimbal_point():
    mount = CameraMount(x_m=0.1, y_m=0.0, z_m=0.2, pitch_deg=40.0)
    pose = FusedPose(1.0, 0.0, 0.0, 0.0)
    msg = frame_transforms(7, FramesConfig(), pose, pose, mount, 0.0, 0.0)
    r, p = chain(msg["transforms"], "camera_optical")
    assert p == pytest.approx([0.1, 0.0, 0.2])
    axis = r @ [0.0, 0.0, 1.0]  # the optical axis (z of the optical frame) in map
    assert axis == pytest.approx([math.cos(math.radians(40)), 0.0, -math.sin(math.radians(40))])
    assert r @ [1.0, 0.0, 0.0] == pytest.approx([0.0, -1.0, 0.0])  # image x is the robot's right
    # Pan 90 deg left and tilt 40 deg up: looking level, to the left of the robot.
    msg = frame_transforms(7, FramesConfig(), pose, pose, mount, math.pi / 2, math.radians(40))
    r, _ = chain(msg["transforms"], "camera_optical")
    assert r @ [0.0, 0.0, 1.0] == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)


def test_frame_names_come_from_the_profile():
    frames = FramesConfig.from_dict({"map": "world", "base_link": "beast/base"})
    msg = frame_transforms(7, frames, FusedPose(1.0, 0.0, 0.0, 0.0), None, None, 0.0, 0.0)
    assert [(t["parent_frame_id"], t["child_frame_id"]) for t in msg["transforms"]] == [
        ("world", "odom"), ("odom", "beast/base"), ("beast/base", "gps")]
    with pytest.raises(ValueError, match="must differ"):
        FramesConfig.from_dict({"odom": "map"})
    with pytest.raises(ValueError, match="mapp"):
        FramesConfig.from_dict({"mapp": "world"})


def test_odometry_puts_the_planar_covariance_at_x_y_and_yaw():
    odom = FusedPose(1.0, 2.0, 3.0, 0.5, speed_mps=0.2, yaw_rate_rps=0.1,
                     covariance=((1.0, 0.2, 0.3), (0.2, 2.0, 0.4), (0.3, 0.4, 0.05)))
    msg = odometry(9, FramesConfig(), odom)
    cov = np.array(msg["pose_covariance"]).reshape(6, 6)
    assert cov[0, 0] == 1.0 and cov[1, 1] == 2.0 and cov[5, 5] == 0.05 and cov[0, 5] == 0.3 and cov[5, 1] == 0.4
    assert cov[2, 2] == 0.0 and msg["linear_velocity"]["x"] == 0.2 and msg["angular_velocity"]["z"] == 0.1
    assert (msg["frame_id"], msg["body_frame_id"]) == ("odom", "base_link")


# -- camera ------------------------------------------------------------------------------------------


def test_calibration_projects_like_the_camera_model_at_the_published_size():
    geometry = CameraGeometry(width_px=320, height_px=240).scaled_to(160, 120)
    cal = camera_calibration(3, "camera_optical", geometry)
    assert (cal["width"], cal["height"]) == (160, 120)
    k = np.array(cal["K"]).reshape(3, 3)
    p = np.array(cal["P"]).reshape(3, 4)
    # A floor point seen through K (in the optical frame the camera model uses) lands where the model says.
    u, v = geometry.ground_to_pixel(0.6, 0.05)
    ray = geometry._r @ (np.array([0.6, 0.05, 0.0]) - geometry._t)  # optical frame, metres
    uvw = k @ ray
    assert (uvw[0] / uvw[2], uvw[1] / uvw[2]) == pytest.approx((u, v))
    assert np.allclose(p[:, :3], k) and np.allclose(p[:, 3], 0.0) and cal["D"] == [0.0] * 5


def test_annotations_draw_the_line_its_lookahead_point_and_the_junction_where_the_detector_saw_them():
    geometry = CameraGeometry(width_px=320, height_px=240)
    obs = LineObservation(1.0, True, offset_m=0.05, angle_rad=0.2, intersection=True, intersection_distance_m=0.5)
    ann = line_annotations(9, obs, geometry, lookahead_m=0.35)
    target, junction = ann["circles"]
    assert (target["position"]["x"], target["position"]["y"]) == pytest.approx(geometry.ground_to_pixel(0.35, 0.05))
    along = 0.05 + 0.15 * math.tan(0.2)
    assert (junction["position"]["x"], junction["position"]["y"]) == pytest.approx(geometry.ground_to_pixel(0.5, along))
    (strip,) = ann["points"]
    assert strip["type"] == 3 and len(strip["points"]) >= 2
    assert all(0 <= p["x"] <= 320 and 0 <= p["y"] <= 240 for p in strip["points"])  # clipped to the image
    assert "+5.0 cm" in ann["texts"][0]["text"] and "junction at 0.50 m" in ann["texts"][0]["text"]
    lost = line_annotations(9, LineObservation(1.0, False), geometry, 0.35)
    assert lost["points"] == [] and lost["circles"] == [] and lost["texts"][0]["text"] == "line: not seen"
