"""LineDetector on SimCamera renders: offset/angle accuracy, signs, junctions, line ends, robustness."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml

from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.floor import FloorMap
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.line_detector import LineDetector, LineDetectorConfig, junction_kind

REPO = Path(__file__).resolve().parent.parent
GEOM = CameraGeometry(width_px=320, height_px=240, hfov_deg=62.2, height_m=0.2, pitch_deg=40.0, x_offset_m=0.1)
L = LineDetectorConfig().lookahead_m


@pytest.fixture(scope="module")
def track() -> FloorMap:
    world = yaml.safe_load((REPO / "worlds" / "line_track.yaml").read_text())
    return FloorMap.from_dict(world["floor"], np.random.default_rng(0))


def make_floor(paths: list, **extra) -> FloorMap:
    d = {"margin_m": 0.6, "background": {"colour": 190, "texture": 8}, "lines": {"width_m": 0.019, "colour": "black", "paths": paths}}
    d.update(extra)
    return FloorMap.from_dict(d, np.random.default_rng(0))


@pytest.fixture(scope="module")
def straight() -> FloorMap:
    return make_floor([{"path": [[0, 0], [3, 0]]}])


def drive(floor: FloorMap, poses, effects: CameraEffects | None = None, config: LineDetectorConfig | None = None, seed: int = 1):
    """Detections for a sequence of poses (x, y, yaw) by one camera and one detector, like a moving robot."""
    cam = SimCamera(floor, GEOM, np.random.default_rng(seed), effects)
    det = LineDetector(config or LineDetectorConfig(), GEOM)
    out = []
    for k, (x, y, yaw) in enumerate(poses):
        out.append(det.detect_full(cam.render(x, y, yaw), float(k)))
    return out


def expected_on_x_axis_line(y0: float, yaw: float) -> tuple[float, float]:
    """Offset at the look-ahead and angle of the line y = 0 (heading east) seen from (., y0, yaw)."""
    return -math.tan(yaw) * L - y0 / math.cos(yaw), -yaw


# --- geometry and sign conventions ----------------------------------------------------------
@pytest.mark.parametrize("y0", [-0.06, -0.03, 0.0, 0.02, 0.05])
@pytest.mark.parametrize("yaw_deg", [-15.0, -5.0, 0.0, 8.0, 15.0])
def test_offset_and_angle_on_a_straight_line(straight: FloorMap, y0: float, yaw_deg: float) -> None:
    yaw = math.radians(yaw_deg)
    det = drive(straight, [(1.0, y0, yaw)], CameraEffects())[0]
    obs = det.observation
    off, ang = expected_on_x_axis_line(y0, yaw)
    assert obs.seen and obs.confidence > 0.8
    assert obs.offset_m == pytest.approx(off, abs=0.01)
    assert math.degrees(obs.angle_rad) == pytest.approx(math.degrees(ang), abs=2.0)
    assert obs.width_m == pytest.approx(0.019, abs=0.005)
    assert not obs.intersection and not obs.line_end


def test_sign_conventions(straight: FloorMap) -> None:
    right_of_line, left_of_line, turned_right, turned_left = (d.observation for d in drive(
        straight, [(1.0, -0.04, 0.0), (1.0, 0.04, 0.0), (1.0, 0.0, math.radians(-10)), (1.0, 0.0, math.radians(10))]
    ))
    assert right_of_line.offset_m > 0.03  # robot right of the line: the line is to the left, +
    assert left_of_line.offset_m < -0.03
    assert turned_right.angle_rad > 0.1  # robot turned clockwise: the line runs counter-clockwise of it, +
    assert turned_left.angle_rad < -0.1


def test_no_line_is_not_seen() -> None:
    blank = make_floor([{"path": [[5, 5], [6, 5]]}])
    obs = drive(blank, [(0.0, 0.0, 0.0)], CameraEffects())[0].observation
    assert not obs.seen and not obs.intersection and not obs.line_end


def test_any_image_size_with_the_same_field_of_view(straight: FloorMap) -> None:
    big = GEOM.scaled_to(640, 480)
    img = SimCamera(straight, big, np.random.default_rng(1)).render(1.0, -0.03, 0.0)
    obs = LineDetector(LineDetectorConfig(), GEOM).detect(img, 0.0)
    assert obs.seen and obs.offset_m == pytest.approx(0.03, abs=0.01)


# --- junctions -------------------------------------------------------------------------------
def approach(floor: FloorMap, start: tuple[float, float], heading: float, junction: tuple[float, float], distances: np.ndarray):
    """Drive straight towards ``junction`` along ``heading``, stopping at each remaining distance."""
    c, s = math.cos(heading), math.sin(heading)
    poses = [(junction[0] - d * c, junction[1] - d * s, heading) for d in distances]
    return drive(floor, poses, CameraEffects())


DISTANCES = np.arange(0.75, 0.2, -0.025)


def check_approach(dets, distances: np.ndarray, kind: str) -> None:
    """Reported in the middle of the view, at the right distance from the robot centre, with the right kind."""
    reported = 0
    for det, d in zip(dets, distances):
        obs = det.observation
        # (close to a T met from its stem, only a few centimetres of stem remain in view)
        assert obs.seen or d < 0.3
        if obs.intersection:
            reported += 1
            assert obs.intersection_distance_m == pytest.approx(d, abs=0.02)
            assert det.intersection_kind == kind
            assert not obs.line_end
        elif 0.3 <= d <= 0.65:
            pytest.fail(f"junction {d:.3f} m ahead not reported")
    assert reported >= 14


def test_crossing_detected_at_the_right_distance(track: FloorMap) -> None:
    check_approach(approach(track, (0.8, 0.0), 0.0, (2.0, 0.0), DISTANCES), DISTANCES, "+")


def test_t_junction_along_its_bar(track: FloorMap) -> None:
    check_approach(approach(track, (4.0, 0.5), math.pi / 2, (4.0, 1.25), DISTANCES), DISTANCES, "T")


def test_t_junction_from_its_stem(track: FloorMap) -> None:
    check_approach(approach(track, (3.0, 1.25), 0.0, (4.0, 1.25), DISTANCES), DISTANCES, "T")


def test_y_junction() -> None:
    fork = make_floor([{"path": [[0, 0], [1, 0]]}, {"path": [[1, 0], [1.8, 0.55]]}, {"path": [[1, 0], [1.8, -0.55]]}])
    check_approach(approach(fork, (0.0, 0.0), 0.0, (1.0, 0.0), DISTANCES), DISTANCES, "Y")


def test_junction_kind_rule() -> None:
    r = math.radians
    assert junction_kind([0, r(90), r(180), r(270)]) == "+"
    assert junction_kind([0, r(90), r(180)]) == "T"
    assert junction_kind([r(180), r(35), r(-35)]) == "Y"
    assert junction_kind([0, r(180)]) is None


def poses_along(floor: FloorMap, path_index: int, s0: float, s1: float, step: float = 0.02):
    """Poses on a path's centreline between arc lengths s0 and s1, heading along it."""
    segs = floor.lines[path_index].segments()
    lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    out = []
    for s in np.arange(s0, s1, step):
        i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(segs) - 1)
        a, b = segs[i]
        p = a + (s - cum[i]) / lengths[i] * (b - a)
        out.append((float(p[0]), float(p[1]), math.atan2(b[1] - a[1], b[0] - a[0])))
    return out


def test_no_false_junction_or_end_on_curves(track: FloorMap) -> None:
    # loop arc lengths: bottom straight 0-3.1, sharp corner 3.1-3.73, right straight to 5.43,
    # sharp corner to 6.06, top straight to 9.16, gentle 1.25 m arc (with a 4 cm gap) to 13.08
    sharp = poses_along(track, 0, 3.0, 3.75)
    gentle = poses_along(track, 0, 9.4, 13.0)
    for det in drive(track, sharp + gentle, CameraEffects()):
        obs = det.observation
        assert obs.seen
        assert not obs.intersection, det.points
        assert not obs.line_end


def test_curve_direction(track: FloorMap) -> None:
    # entering the gentle left-hand arc: the line bends left ahead
    obs = drive(track, [(0.5, 2.5, math.pi)], CameraEffects())[0].observation
    assert obs.offset_m > 0.0 and obs.angle_rad > math.radians(3)


def test_line_end_ahead(track: FloorMap) -> None:
    # north along the cross line past the top crossing, towards its free end at (2, 3.1)
    ys = np.arange(2.62, 2.81, 0.02)
    for y, det in zip(ys, drive(track, [(2.0, y, math.pi / 2) for y in ys], CameraEffects())):
        obs = det.observation
        assert obs.seen and obs.line_end and not obs.intersection
        assert det.end_xy[0] == pytest.approx(3.1 - y, abs=0.03)


def test_dead_end_spur(track: FloorMap) -> None:
    obs = drive(track, [(3.3, 1.25, math.pi)], CameraEffects())[0].observation
    assert obs.seen and obs.line_end and not obs.intersection


# --- robustness ------------------------------------------------------------------------------
def robust_floor() -> FloorMap:
    return make_floor(
        [{"path": [[0, 0], [4, 0]]}],
        lighting={"gradient": {"direction_deg": 90, "min_gain": 0.5, "max_gain": 1.1}},
        shadows=[
            {"rect": {"center": [0.9, 0.1], "size_m": [0.15, 1.0], "angle_deg": 30}, "darkness": 0.55, "softness_m": 0.0},
            {"circle": {"center": [1.6, 0.15], "radius_m": 0.2}, "darkness": 0.5, "softness_m": 0.03},
        ],
        glare=[{"center": [2.2, 0.0], "radius_m": 0.08, "strength": 0.9}],
        gaps=[{"at": [2.7, 0.0], "length_m": 0.04}, {"at": [3.1, 0.0], "length_m": 0.03}],
    )


@pytest.mark.parametrize("y0", [-0.04, 0.03])
def test_robust_to_shadow_gradient_glare_gaps_and_noise(y0: float) -> None:
    floor = robust_floor()
    poses = [(x, y0, 0.0) for x in np.arange(0.4, 3.2, 0.02)]
    effects = CameraEffects(noise_std=10.0, exposure_jitter=0.08, vignetting=0.3)
    for (x, _, _), det in zip(poses, drive(floor, poses, effects)):
        obs = det.observation
        assert obs.seen, x
        assert obs.offset_m == pytest.approx(-y0, abs=0.015), x
        assert abs(obs.angle_rad) < math.radians(3), x
        assert not obs.intersection, x
        assert not obs.line_end, x


def test_colour_mode_finds_yellow_tape_and_ignores_black() -> None:
    floor = make_floor([{"path": [[0, 0.05], [3, 0.05]], "colour": "yellow"}, {"path": [[0, -0.08], [3, -0.08]]}], background={"colour": 120, "texture": 6})
    cfg = LineDetectorConfig(mode="colour")
    obs = drive(floor, [(1.0, 0.0, 0.0)], CameraEffects(), cfg)[0].observation
    assert obs.seen and obs.offset_m == pytest.approx(0.05, abs=0.01)


def test_light_on_dark_mode() -> None:
    floor = make_floor([{"path": [[0, 0], [3, 0]], "colour": "white"}], background={"colour": 50, "texture": 5})
    assert not drive(floor, [(1.0, 0.03, 0.0)], CameraEffects())[0].observation.seen  # dark-on-light sees nothing
    obs = drive(floor, [(1.0, 0.03, 0.0)], CameraEffects(), LineDetectorConfig(mode="light_on_dark"))[0].observation
    assert obs.seen and obs.offset_m == pytest.approx(-0.03, abs=0.01)


def test_overlay_draws_on_a_copy(straight: FloorMap) -> None:
    img = SimCamera(straight, GEOM, np.random.default_rng(1)).render(1.0, 0.0, 0.0)
    det = LineDetector(LineDetectorConfig(), GEOM)
    obs = det.detect(img, 0.0)
    out = det.draw_overlay(img, obs)
    assert out.shape == img.shape and out is not img and not np.array_equal(out, img)


# --- configuration ---------------------------------------------------------------------------
def test_config_from_dict_and_schema_agree() -> None:
    cfg = LineDetectorConfig.from_dict({"mode": "colour", "hsv_low": [0, 100, 100], "lookahead_m": 0.3, "roi_near_m": None})
    assert cfg.mode == "colour" and cfg.lookahead_m == 0.3
    with pytest.raises(ValueError, match="did you mean 'lookahead_m'"):
        LineDetectorConfig.from_dict({"look_ahead_m": 0.3})
    with pytest.raises(ValueError, match="mode"):
        LineDetectorConfig.from_dict({"mode": "bright"})
    with pytest.raises(ValueError, match="hsv_low"):
        LineDetectorConfig.from_dict({"hsv_low": [0, 300, 0]})
    with pytest.raises(ValueError, match="background_kernel_m"):
        LineDetectorConfig.from_dict({"line_width_max_m": 0.05})
    schema = json.loads((REPO / "schemas" / "parts" / "line_detector.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    defaults = asdict(LineDetectorConfig())
    jsonschema.Draft202012Validator(schema).validate(defaults)
    assert set(schema["properties"]) == set(defaults)
    for name, prop in schema["properties"].items():
        assert prop["default"] == defaults[name], name
    effects_schema = json.loads((REPO / "schemas" / "parts" / "camera_effects.schema.json").read_text())
    fx_defaults = asdict(CameraEffects())
    jsonschema.Draft202012Validator(effects_schema).validate(fx_defaults)
    assert {k: v["default"] for k, v in effects_schema["properties"].items()} == fx_defaults
