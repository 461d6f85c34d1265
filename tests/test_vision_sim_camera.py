"""SimCamera: renders the floor as the robot's camera sees it, through the FrameSource interface."""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.floor import FloorMap
from beastbt.sim.truth import RobotTruth
from beastbt.vision.camera_model import CameraGeometry

GEOM = CameraGeometry(width_px=320, height_px=240, hfov_deg=62.2, height_m=0.2, pitch_deg=40.0, x_offset_m=0.1)


@pytest.fixture(scope="module")
def floor() -> FloorMap:
    # one line along y = 0 from x = 0 to 3, on plain grey
    return FloorMap.from_dict(
        {"margin_m": 0.5, "background": {"colour": 180, "texture": 0}, "lines": {"width_m": 0.02, "colour": 20, "paths": [{"path": [[0, 0], [3, 0]]}]}},
        np.random.default_rng(0),
    )


def world_to_body(x: float, y: float, rx: float, ry: float, yaw: float) -> tuple[float, float]:
    dx, dy = x - rx, y - ry
    return math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy


def test_the_line_appears_where_the_geometry_says(floor: FloorMap) -> None:
    cam = SimCamera(floor, GEOM, np.random.default_rng(1), CameraEffects.none())
    rx, ry, yaw = 1.0, 0.05, math.radians(10.0)
    cam.update(RobotTruth(x=rx, y=ry, yaw=yaw))
    ok, img = cam.read()
    assert ok and img.shape == (240, 320, 3) and img.dtype == np.uint8
    for wx in (1.3, 1.5, 1.7):
        u, v = GEOM.ground_to_pixel(*world_to_body(wx, 0.0, rx, ry, yaw))
        assert img[int(round(v)), int(round(u))].max() < 60  # on the tape
        u2, v2 = GEOM.ground_to_pixel(*world_to_body(wx, 0.06, rx, ry, yaw))
        assert img[int(round(v2)), int(round(u2))].min() > 160  # 6 cm beside it


def test_gimbal_pan_and_tilt_move_the_view(floor: FloorMap) -> None:
    cam = SimCamera(floor, GEOM, np.random.default_rng(1), CameraEffects.none())
    straight = cam.render(1.0, 0.0, 0.0)
    panned = cam.render(1.0, 0.0, 0.0, pan_rad=math.radians(15.0))
    dark_cols = lambda im: np.flatnonzero(im[200, :, 0] < 60)  # noqa: E731
    assert dark_cols(panned).mean() > dark_cols(straight).mean() + 20  # looking left: the line moves right
    up = cam.render(1.0, 0.0, 0.0, tilt_rad=math.radians(35.0))  # only 5 deg down: the horizon is in view
    assert (up[0] == CameraEffects().sky_grey).all()


def test_frames_are_deterministic_for_a_seed(floor: FloorMap) -> None:
    truth = RobotTruth(x=1.0, y=0.0, yaw=0.2, v_mps=0.3, w_rps=0.5)
    frames = []
    for seed in (7, 7, 8):
        cam = SimCamera(floor, GEOM, np.random.default_rng(seed))
        cam.update(truth)
        frames.append(cam.read()[1])
    assert np.array_equal(frames[0], frames[1])
    assert not np.array_equal(frames[0], frames[2])


def test_noise_has_the_configured_strength(floor: FloorMap) -> None:
    clean = SimCamera(floor, GEOM, np.random.default_rng(1), CameraEffects.none()).render(1.0, 0.5, 0.0)
    noisy = SimCamera(floor, GEOM, np.random.default_rng(1), CameraEffects(noise_std=6.0, exposure_jitter=0.0, vignetting=0.0, exposure_s=0.0)).render(1.0, 0.5, 0.0)
    diff = noisy.astype(float) - clean.astype(float)
    assert float(diff.std()) == pytest.approx(6.0, rel=0.15)


def test_motion_blur_grows_with_speed(floor: FloorMap) -> None:
    fx = CameraEffects(noise_std=0.0, exposure_jitter=0.0, vignetting=0.0, exposure_s=0.05)
    cam = SimCamera(floor, GEOM, np.random.default_rng(1), fx)
    # turning fast smears the line sideways: its dark core widens and its edges soften
    still = cam.render(1.0, 0.0, 0.0, v_mps=0.0, w_rps=0.0)[200, :, 0].astype(float)
    turning = cam.render(1.0, 0.0, 0.0, v_mps=0.0, w_rps=2.0)[200, :, 0].astype(float)
    assert (turning < 120).sum() > (still < 120).sum() + 3
    assert turning.min() > still.min()


def test_unplug_release_and_reopen(floor: FloorMap) -> None:
    cam = SimCamera(floor, GEOM, np.random.default_rng(1))
    assert cam.isOpened() and cam.read()[0]
    cam.unplug()
    assert not cam.isOpened()
    assert cam.read() == (False, None)
    assert not cam.reopen().isOpened()  # cannot reopen while unplugged
    cam.replug()
    assert not cam.isOpened()  # the driver must reopen it
    assert cam.reopen().isOpened() and cam.read()[0]
    cam.release()
    assert cam.read() == (False, None)
    assert cam.reopen() is cam and cam.read()[0]


def test_dropped_frames(floor: FloorMap) -> None:
    cam = SimCamera(floor, GEOM, np.random.default_rng(1), CameraEffects(drop_probability=1.0))
    assert cam.isOpened() and cam.read() == (False, None)


def test_effects_config_from_dict() -> None:
    fx = CameraEffects.from_dict({"noise_std": 5, "exposure_s": 0})
    assert fx.noise_std == 5.0 and fx.exposure_s == 0.0
    with pytest.raises(ValueError, match="did you mean 'noise_std'"):
        CameraEffects.from_dict({"noise_sd": 1.0})
    with pytest.raises(ValueError, match="vignetting"):
        CameraEffects.from_dict({"vignetting": 1.5})
