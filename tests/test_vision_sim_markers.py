"""The simulated camera draws a world's tags, QR boards and painted boxes, and the detectors find them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.core.errors import InvalidInput
from beastbt.parts.camera import PLAIN_FLOOR, build_floor, world_markers
from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.obstacles import obstacle_of
from beastbt.sim.scenery import Scenery
from beastbt.sim.world import load_world, world_of
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.colour import ColourFinder, ColourRange
from beastbt.vision.fiducials import FiducialDetector
from beastbt.vision.qr_codes import QrReader

LEVEL = CameraGeometry(width_px=320, height_px=240, hfov_deg=62.2, height_m=0.2, pitch_deg=0.0, x_offset_m=0.1)
WALLS = [[0.0, -2.0, 6.0, -2.0], [0.0, 2.0, 6.0, 2.0], [6.0, -2.0, 6.0, 2.0], [0.0, -2.0, 0.0, 2.0]]


def _camera(world: dict, effects: CameraEffects) -> SimCamera:
    w = world_of(world)
    scenery = Scenery.of_world(w.walls, w.obstacles, False, 1)
    return SimCamera(build_floor(PLAIN_FLOOR, 1), LEVEL, np.random.default_rng(1), effects, scenery,
                     markers=world_markers(w))


@pytest.mark.parametrize("effects", [CameraEffects.none(), CameraEffects()], ids=["perfect", "effects"])
@pytest.mark.parametrize("x, y, yaw_deg", [(4.0, 0.0, 0.0), (3.5, -0.6, 15.0), (5.0, 0.3, -10.0)])
def test_a_tag_on_the_wall_is_found_where_it_is(effects, x, y, yaw_deg):
    world = {"world": "room", "walls": WALLS,
             "tags": [{"id": 0, "size_m": 0.2, "x": 5.99, "y": 0.0, "z_m": 0.2, "facing_deg": 180}]}
    yaw = math.radians(yaw_deg)
    img = _camera(world, effects).render(x, y, yaw)
    tags = FiducialDetector(size_m=0.2).detect(img, LEVEL.camera_matrix, None, LEVEL.camera_from_body)
    assert [t.id for t in tags] == [0]
    # the tag in the base frame, from the true pose: body = R(-yaw) (tag - robot)
    dx, dy = 5.99 - x, 0.0 - y
    bx, by = math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy
    px, py, pz = tags[0].position_m
    rng = math.hypot(bx, by)
    assert abs(px - bx) < 0.04 * rng and abs(py - by) < 0.03 and abs(pz - 0.2) < 0.03
    if rng < 2.1:  # a tag 20 px wide (2.5 m) may flip between IPPE's two poses: its facing is trusted only nearer
        assert abs(math.degrees(math.remainder(tags[0].facing_rad - (math.pi - yaw), 2 * math.pi))) < 8.0


def test_a_tag_seen_from_behind_is_a_blank_sheet_and_a_post_holds_it_up():
    world = {"world": "yard", "tags": [{"id": 4, "x": 3.0, "y": 0.0, "z_m": 0.25, "facing_deg": 0, "mount": "post"}]}
    img = _camera(world, CameraEffects.none()).render(1.5, 0.0, 0.0)
    assert FiducialDetector().detect(img) == []
    centre = img[110:130, 150:170].reshape(-1, 3).mean(axis=0)
    assert centre.min() > 180  # the white back of the sheet
    below = img[135:152, 158:162].reshape(-1, 3).mean(axis=0)
    assert below.max() < 100  # the dark pole under it
    front = _camera(world, CameraEffects.none()).render(4.5, 0.0, math.pi)
    assert [t.id for t in FiducialDetector().detect(front)] == [4]


def test_a_qr_board_is_read_and_a_red_box_is_found():
    world = {"world": "lab", "walls": WALLS,
             "qr_boards": [{"text": "door-3", "size_m": 0.25, "x": 5.99, "y": 0.8, "z_m": 0.25, "facing_deg": 180}],
             "obstacles": [{"shape": "box", "x": 4.5, "y": -1.0, "size_m": [0.3, 0.3], "colour": "red"}]}
    cam = _camera(world, CameraEffects())
    img = cam.render(5.2, 0.6, 0.0)
    assert [q.text for q in QrReader().read(img)] == ["door-3"]
    view = cam.render(3.0, 0.0, math.radians(-35))
    blob = ColourFinder().find(view, ColourRange.parse("red"))
    assert blob is not None and blob.area_frac > 0.01
    # the box is ahead, a little right or left of the axis: 35 deg turned right, the box is at -34 deg
    bearing = blob.bearing_rad(LEVEL.camera_matrix)
    assert abs(math.degrees(bearing) - (math.degrees(math.atan2(-1.0, 1.4)) + 35)) < 6
    assert ColourFinder().find(view, ColourRange.parse("blue")) is None


def test_a_tag_its_family_lacks_is_an_error_at_tags(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("world: bad\ntags:\n  - {id: 60, family: aruco_4x4_50, x: 1, y: 0}\n")
    with pytest.raises(InvalidInput) as err:
        world_markers(load_world(path))
    text = str(err.value)
    assert "bad.yaml:3:10" in text and "aruco_4x4_50 has ids 0 to 49, got 60" in text


def test_validate_finds_a_tag_its_family_lacks_as_the_run_does(tmp_path):
    # beastbt validate said "ok" to a world whose tags the run then refused (the run checked them, the file's check
    # did not); a mission in that world too.
    from beastbt.validate import validate_file
    from beastbt.vision.fiducials import FAMILIES
    from beastbt.vision.tag_families import TAG_IDS
    import cv2
    assert TAG_IDS == {name: cv2.aruco.getPredefinedDictionary(d).bytesList.shape[0] for name, d in FAMILIES.items()}
    world = tmp_path / "w.yaml"
    world.write_text("world: w\ntags:\n  - {id: 34, family: apriltag_25h9, x: 1, y: 0}\n"
                     "  - {id: 35, family: apriltag_25h9, x: 1, y: 0}\n")
    mission = tmp_path / "m.yaml"
    mission.write_text("mission: m\nworld: w.yaml\nsteps:\n  - wait: 1 s\n")
    for path in (world, mission):
        text = "\n".join(p.format() for p in validate_file(str(path)))
        assert "w.yaml:4:10: error: tags: apriltag_25h9 has ids 0 to 34, got 35" in text, text


def test_a_misspelt_key_of_a_worlds_tag_is_not_called_a_step(tmp_path):
    # it was "unknown key 'facing' in the 'id' step": a tag (or an obstacle) is not a step of a mission
    world = tmp_path / "w.yaml"
    world.write_text("world: w\ntags:\n  - {id: 4, x: 1, y: 1, facing: 0}\n"
                     "obstacles:\n  - {shape: box, x: 1, y: 1, size_m: [1, 1], colr: red}\n")
    with pytest.raises(InvalidInput) as err:
        load_world(world)
    text = str(err.value)
    assert "w.yaml:3:25: error: unknown key 'facing' in 'tags'; did you mean 'facing_deg'?" in text, text
    assert "w.yaml:5:46: error: unknown key 'colr' in 'obstacles'; did you mean 'colour'?" in text, text
    assert " step" not in text


def test_box_colour_is_in_the_world_schema(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text("world: w\nobstacles:\n  - {shape: box, x: 1, y: 0, size_m: [0.3, 0.3], colour: purple}\n")
    with pytest.raises(InvalidInput) as err:
        load_world(path)
    assert "w.yaml:3" in str(err.value)
    assert obstacle_of({"shape": "box", "x": 1, "y": 0, "size_m": [0.3, 0.3], "colour": "red"}).colour == "red"
