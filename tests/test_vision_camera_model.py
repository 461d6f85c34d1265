"""CameraGeometry: the pinhole mapping between the floor (body frame) and image pixels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.devices.camera import CameraConfig
from beastbt.vision.camera_model import CameraGeometry


@pytest.fixture
def geom() -> CameraGeometry:
    return CameraGeometry(width_px=320, height_px=240, hfov_deg=62.2, height_m=0.2, pitch_deg=40.0, x_offset_m=0.1)


def test_optical_axis_hits_the_floor_where_trigonometry_says(geom: CameraGeometry) -> None:
    x, y = geom.pixel_to_ground(159.5, 119.5)
    assert x == pytest.approx(0.1 + 0.2 / math.tan(math.radians(40.0)), abs=1e-9)
    assert y == pytest.approx(0.0, abs=1e-9)


def test_focal_length_follows_the_horizontal_field_of_view(geom: CameraGeometry) -> None:
    assert geom.focal_px == pytest.approx(160.0 / math.tan(math.radians(31.1)))


@pytest.mark.parametrize("pt", [(0.3, 0.0), (0.5, 0.1), (0.25, -0.05), (0.7, 0.3)])
def test_ground_pixel_round_trip(geom: CameraGeometry, pt: tuple[float, float]) -> None:
    uv = geom.ground_to_pixel(*pt)
    assert uv is not None
    back = geom.pixel_to_ground(*uv)
    assert back == pytest.approx(pt, abs=1e-9)
    hom = geom.image_from_ground @ np.array([pt[0], pt[1], 1.0])
    assert hom[:2] / hom[2] == pytest.approx(uv, abs=1e-6)


def test_left_is_left_and_far_is_up(geom: CameraGeometry) -> None:
    centre = geom.ground_to_pixel(0.4, 0.0)
    left = geom.ground_to_pixel(0.4, 0.05)
    far = geom.ground_to_pixel(0.6, 0.0)
    assert left[0] < centre[0]  # +y (left) appears on the image's left
    assert far[1] < centre[1]  # farther floor appears higher in the image


def test_above_the_horizon_there_is_no_floor(geom: CameraGeometry) -> None:
    tilted = geom.with_pan_tilt(0.0, math.radians(30.0))  # now only 10 deg down: horizon in view
    assert 0 < tilted.horizon_v < tilted.height_px
    assert tilted.pixel_to_ground(160, tilted.horizon_v - 5) is None
    assert tilted.pixel_to_ground(160, tilted.horizon_v + 5) is not None
    out = tilted.pixels_to_ground(np.array([[160, tilted.horizon_v - 5], [160, 239]]))
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()
    assert geom.ground_to_pixel(-1.0, 0.0) is None  # behind the camera


def test_pan_left_moves_the_view_left(geom: CameraGeometry) -> None:
    panned = geom.with_pan_tilt(math.radians(10.0), 0.0)
    u_straight = panned.ground_to_pixel(0.4, 0.0)[0]
    assert u_straight > 159.5  # what was ahead is now right of centre
    assert panned.pixel_to_ground(159.5, 119.5)[1] > 0.0  # the centre now looks left of ahead


def test_image_from_world_composes_pose_and_mounting(geom: CameraGeometry) -> None:
    x, y, yaw = 2.0, 1.0, math.radians(30.0)
    h = geom.image_from_world(x, y, yaw)
    body = (0.4, -0.05)
    world = (x + body[0] * math.cos(yaw) - body[1] * math.sin(yaw), y + body[0] * math.sin(yaw) + body[1] * math.cos(yaw))
    p = h @ np.array([world[0], world[1], 1.0])
    assert p[:2] / p[2] == pytest.approx(geom.ground_to_pixel(*body), abs=1e-6)


def test_scaled_geometry_maps_to_proportional_pixels(geom: CameraGeometry) -> None:
    big = geom.scaled_to(640, 480)
    u1, v1 = geom.ground_to_pixel(0.45, 0.07)
    u2, v2 = big.ground_to_pixel(0.45, 0.07)
    assert (u2 + 0.5) == pytest.approx(2 * (u1 + 0.5), abs=1e-6)
    assert (v2 + 0.5) == pytest.approx(2 * (v1 + 0.5), abs=1e-6)


def test_from_config_uses_size_and_mounting() -> None:
    cfg = CameraConfig.from_dict({"width_px": 640, "height_px": 480, "mounting": {"height_m": 0.3, "pitch_deg": 50, "hfov_deg": 66, "x_offset_m": 0.05}})
    g = CameraGeometry.from_config(cfg)
    assert (g.width_px, g.height_px, g.height_m, g.pitch_deg, g.hfov_deg, g.x_offset_m) == (640, 480, 0.3, 50.0, 66.0, 0.05)


def test_nearest_visible_floor(geom: CameraGeometry) -> None:
    vfov_half = math.atan(math.tan(math.radians(31.1)) * 120 / 160)
    expected = 0.1 + 0.2 / math.tan(math.radians(40.0) + vfov_half)
    assert geom.nearest_visible_x_m() == pytest.approx(expected, abs=0.002)
