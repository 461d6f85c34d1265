"""The camera's words on the simulator: ``{sees: ...}`` in conditions, ``photo``, ``alert``; and their errors."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import jsonschema
import pytest

from beastbt.core.errors import InvalidInput
from beastbt.core.schema_check import load_schema
from beastbt.mission.model import load_mission
from beastbt.testing import MissionHarness

ROOT = Path(__file__).resolve().parents[1]
ROOM = """world: room
gps: {sky: none}
start: {x: 1.0, y: 0.0, yaw_deg: 0}
walls:
  - [0.0, -3.0, 6.0, -3.0]
  - [0.0, 3.0, 6.0, 3.0]
  - [0.0, -3.0, 0.0, 3.0]
  - [6.0, -3.0, 6.0, 3.0]
"""
LEVEL = "  - look: {tilt: 40 deg}          # the camera level: it looks at the room, not the floor\n"


def room(tmp_path: Path, extra: str = "") -> str:
    path = tmp_path / "room.yaml"
    path.write_text(ROOM + extra, encoding="utf-8")
    return str(path)


def run(world: str, steps: str, seed: int = 1, **options) -> MissionHarness:
    return MissionHarness.from_yaml("mission: t\nsteps:\n" + LEVEL + steps, world=world, seed=seed, **options)


def test_sees_motion_fires_within_a_second_of_a_person_walking_into_view(tmp_path):
    world = room(tmp_path, "obstacles:\n  - {shape: person, radius_m: 0.25, speed_mps: 0.8, "
                           "path: [[4.0, -2.8], [4.0, 2.8]], start_s: 8}\n")
    h = run(world, "  - wait_until: {sees: motion}\n    timeout: 30 s\n")
    contact = h.run.io.sim.drive.contact
    entered = None
    cam_x = 1.0 + 0.1
    half_fov = math.radians(62.2 / 2)
    while not h.done and h.now_s < 40:
        h.tick()
        x, y = contact.person_xy[0]
        # the person's near edge inside the picture's edge
        if entered is None and abs(math.atan2(y, x - cam_x)) < half_fov + math.atan2(0.25, x - cam_x):
            entered = h.now_s
    assert h.result == "success"
    fired = next(e.time_s for e in h.events if e.kind == "mission_end")
    assert entered is not None and entered > 8.0
    assert 0.0 <= fired - entered <= 1.0, (entered, fired)


def test_no_motion_in_an_empty_room_and_none_while_turning(tmp_path):
    world = room(tmp_path)
    h = run(world, "  - parallel:\n      succeed_on: any\n      steps:\n"
                   "        - wait_until: {sees: motion}\n        - turn: {angle: 180 deg}\n"
                   "  - wait_until: {sees: motion}\n    timeout: 6 s\n")
    assert h.run_to_end(60) == "failure"
    # the turn ran to its end (motion while turning would have ended the parallel block half way round)
    assert abs(math.degrees(math.remainder(h.truth.yaw - math.pi, 2 * math.pi))) < 5.0
    failed = [e.text for e in h.events if e.kind == "step_failed"]
    assert len(failed) == 1 and "sees motion" in failed[0]  # then, standing still, an empty room: no motion


def test_sees_a_qr_board_and_not_another_text(tmp_path):
    world = room(tmp_path, "qr_boards:\n  - {text: door-3, size_m: 0.25, x: 1.7, y: 0.0, z_m: 0.2, "
                           "facing_deg: 180}\n")
    h = run(world, "  - wait_until: {sees: {qr: \"door-3\"}}\n    timeout: 3 s\n"
                   "  - wait_until: {sees: {qr: \"door-4\"}}\n    timeout: 3 s\n")
    assert h.run_to_end(30) == "failure"
    failed = [e.text for e in h.events if e.kind == "step_failed"]
    assert len(failed) == 1 and "door-4" in failed[0]


def test_sees_a_red_box_by_its_area_and_a_tag_by_its_id(tmp_path):
    world = room(tmp_path, "obstacles:\n  - {shape: box, x: 3.0, y: 0.3, size_m: [0.4, 0.4], colour: red}\n"
                           "tags:\n  - {id: 3, x: 2.8, y: -0.5, z_m: 0.25, facing_deg: 180, mount: post}\n")
    h = run(world, "  - if: {sees: {colour: red, min_area: 2 %}}\n    then: [{say: \"red\"}]\n"
                   "  - if: {sees: {colour: red, min_area: 40 %}}\n    then: [{say: \"red everywhere\"}]\n"
                   "  - if: {sees: {colour: blue}}\n    then: [{say: \"blue\"}]\n"
                   "  - if: {sees: {tag: 3}}\n    then: [{say: \"tag 3\"}]\n"
                   "  - if: {sees: {tag: 4}}\n    then: [{say: \"tag 4\"}]\n"
                   "  - if: {sees: {tag: 3, within: 1 m}}\n    then: [{say: \"tag 3 near\"}]\n"
                   "  - if: {sees: {tag: 3, within: 2 m}}\n    then: [{say: \"tag 3 within 2 m\"}]\n")
    assert h.run_to_end(30) == "success"
    said = [e.text for e in h.events if e.kind == "say"]
    assert said == ["red", "tag 3", "tag 3 within 2 m"]


def test_photo_and_alert_with_a_photo(tmp_path):
    world = room(tmp_path)
    h = run(world, "  - photo: {name: gate}\n  - photo\n  - alert: {text: \"someone in the lab\", photo: true}\n"
                   "  - alert: \"all quiet\"\n")
    assert h.run_to_end(30) == "success"
    s = h.summary()
    photos = s["vision"]["photos"]
    assert [p["name"] for p in photos] == ["gate", "photo-line5", "alert-1"]
    for p in photos:
        img = cv2.imread(p["file"])
        assert img is not None and img.shape == (240, 320, 3) and p["size_px"] == [320, 240]
    assert [a["text"] for a in s["alerts"]] == [f"someone in the lab (photo {photos[2]['file']})", "all quiet"]
    assert [e.kind for e in h.events].count("photo") == 3
    jsonschema.validate(s, load_schema("summary.schema.json"))


def test_without_a_camera_photo_and_sees_fail_saying_why_and_alert_still_goes():
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - alert: \"hello\"\n  - photo\n", robot="robots/diy_pwm.yaml")
    assert h.run_to_end(10) == "failure"
    assert any(e.kind == "alert" and e.text == "hello" for e in h.events)
    assert any("this robot has no camera" in e.text for e in h.events)
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - wait_until: {sees: motion}\n", robot="robots/diy_pwm.yaml")
    assert h.run_to_end(10) == "failure"
    assert any("'sees' needs a camera" in e.text for e in h.events)


@pytest.mark.parametrize("step, where, message", [
    ("- wait_until: {sees: {colour: {hsv: [[200, 0, 0], [10, 255, 255]]}}}", "3:33", "hue 0-179"),
    ("- wait_until: {sees: {colour: red, min_area: 200 %}}", "3:48", "at most 100 %"),
    ("- wait_until: {sees: {colour: purple}}", "3:33", "expected one of red, green, blue, yellow"),
    ("- wait_until: {sees: {tag: 3, within: 0 m}}", "3:41", "within must be greater than zero"),
    ("- wait_until: {sees: {tag: 3, size: -3 cm}}", "3:39", "size must be greater than zero"),
    ("- dock: {tag: 0, distance: -1 m}", "3:30", "distance must be greater than zero"),
    ("- wait_until: {sees: movement}", "3:24", "expected one of motion"),
    ("- wait_until: {sees: faces}", "3:24", "hint: or a mapping: {tag: ...}, {qr: ...}, {colour: ...}"),
    ("- wait_until: {sees: {tga: 3}}", "3:25", "unknown key 'tga' in 'sees'; did you mean 'tag'?"),
    ("- wait_until: {sees: {tag: 3, qr: door}}", "3:33", "'sees' takes one of tag, qr, colour, not both 'tag' and 'qr'"),
    ("- wait_until: {sees: {tag: 3, whithin: 2 m}}", "3:33", "unknown key 'whithin' in 'sees'; did you mean 'within'?"),
    ("- if: {sees: {colur: red}}\n    then: [stop]", "3:17", "unknown key 'colur' in 'sees'; did you mean 'colour'?"),
    ("- wait_until: {sees: {colour: {hsv: [10, 20]}}}", "3:33", "hsv needs two [h, s, v] triples"),
    ("- track: {colour: {hsv: [[0, 0], [x, 1, 2]]}, for: 2 s}", "3:21", "hsv needs two [h, s, v] triples"),
    ("- wait_until: {sees: {tag: 587}}", "3:30", "apriltag_36h11 has tags 0 to 586, not 587"),
    ("- dock: {tag: 50, family: aruco_4x4_50}", "3:17", "aruco_4x4_50 has tags 0 to 49, not 50"),
])
def test_mistakes_are_reported_at_their_line_and_column(tmp_path, step, where, message):
    path = tmp_path / "bad.yaml"
    path.write_text(f"mission: bad\nsteps:\n  {step}\n", encoding="utf-8")
    with pytest.raises(InvalidInput) as err:
        load_mission(path)
    text = str(err.value)
    assert f"bad.yaml:{where}" in text and message in text, text


def test_every_id_of_a_family_is_taken_and_the_table_of_ids_is_opencvs(tmp_path):
    from beastbt.mission.vision_steps import TAG_IDS
    from beastbt.vision.fiducials import FAMILIES
    assert TAG_IDS == {name: cv2.aruco.getPredefinedDictionary(d).bytesList.shape[0] for name, d in FAMILIES.items()}
    path = tmp_path / "ok.yaml"
    path.write_text("mission: ok\nsteps:\n  - wait_until: {sees: {tag: 1023, family: aruco_original}}\n"
                    "  - dock: {tag: 586}\n", encoding="utf-8")
    load_mission(path)


def test_sees_a_tag_within_a_distance_measured_by_the_size_the_mission_gives():
    # worlds/lab.yaml: tag 0 is 30 cm; the robot drives straight at it from 3 m. Measured as a 16 cm tag (the
    # default) it would look 1.5 m away from about 2.8 m.
    lab = str(Path(__file__).resolve().parents[1] / "worlds" / "lab.yaml")
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - look: {tilt: 40 deg}\n"
                                 "  - until: {sees: {tag: 0, within: 1.5 m, size: 30 cm}}\n    steps:\n"
                                 "      - drive: {distance: 2.5 m, speed: 0.1 m/s}\n", world=lab, seed=1)
    assert h.run_to_end(60) == "success"
    t = h.truth
    assert abs(math.hypot(7.99 - t.x, t.y) - 1.5) < 0.1  # robot centre to the tag, where the guard halted


def test_the_camera_stays_off_for_a_mission_that_does_not_look(tmp_path):
    world = room(tmp_path)
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - alert: \"nothing to see\"\n  - undock: {distance: 0.1 m}\n",
                                 world=world, seed=1)
    assert h.run_to_end(30) == "success"
    assert h.run.ctx.services.vision is None and not h.run.io.camera.enabled
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - alert: {text: \"look\", photo: true}\n", world=world, seed=1)
    assert h.run_to_end(30) == "success"
    assert h.run.io.camera.reasons == ["vision"]


BOX = (3.266, -1.057)
"""A red box 2.5 m from the robot's start, 25 deg to the right of where it faces: near the picture's edge."""
RED_BOX = f"obstacles:\n  - {{shape: box, x: {BOX[0]}, y: {BOX[1]}, size_m: [0.3, 0.3], colour: red}}\n"


def camera_bearing_deg(h: MissionHarness, box: tuple[float, float]) -> float:
    """The box's true bearing off the camera's axis (deg, left positive): the robot's heading and the pan's."""
    t = h.truth
    cam_x, cam_y = t.x + 0.1 * math.cos(t.yaw), t.y + 0.1 * math.sin(t.yaw)
    off = math.atan2(box[1] - cam_y, box[0] - cam_x) - t.yaw - t.pan_rad
    return math.degrees(math.atan2(math.sin(off), math.cos(off)))


def test_track_centres_a_red_box_with_the_pan_servo(tmp_path):
    world = room(tmp_path, RED_BOX)
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - track: {colour: red, for: 6 s}\n", world=world, seed=1)
    assert h.run_to_end(30) == "success"
    assert abs(camera_bearing_deg(h, BOX)) < 3.0  # the box in the middle of the picture
    assert math.degrees(h.truth.pan_rad) < -20.0  # by turning the camera right
    assert abs(math.degrees(h.truth.yaw)) < 2.0 and math.hypot(h.truth.x - 1.0, h.truth.y) < 0.02  # not the robot
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - track: {colour: blue, for: 2 s}\n", world=world, seed=1)
    assert h.run_to_end(30) == "failure"
    assert any("never saw blue" in e.text for e in h.events)


def test_track_turns_the_robot_when_the_pan_nears_its_limit(tmp_path):
    # the box 2 m away, 85 deg to the left; the camera already looking there: beyond the pan's free range
    box = (1.0 + 2.0 * math.cos(math.radians(85)), 2.0 * math.sin(math.radians(85)))
    world = room(tmp_path, f"obstacles:\n  - {{shape: box, x: {box[0]:.3f}, y: {box[1]:.3f}, size_m: [0.3, 0.3], "
                           "colour: red}\n")
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - look: {pan: 85 deg}\n  - track: {colour: red, for: 8 s}\n",
                                 world=world, seed=1)
    assert h.run_to_end(30) == "success"
    assert abs(camera_bearing_deg(h, box)) < 3.0
    assert math.degrees(h.truth.yaw) > 20.0  # the robot turned left toward it
    # so the pan came back to its free range (60 deg; it holds within 2 deg of it: no hunting)
    assert math.degrees(h.truth.pan_rad) < 63.0


def test_track_turns_a_robot_without_a_pan_servo(tmp_path):
    # the simulator's robot without its gimbal, its camera fixed and level
    text = (ROOT / "robots" / "sim.yaml").read_text(encoding="utf-8")
    text = text.replace("  gimbal: true", "  gimbal: false").replace("    pitch_deg: 40 ", "    pitch_deg: 0  ")
    assert "gimbal: false" in text and "pitch_deg: 0 " in text
    profile = tmp_path / "fixed_camera.yaml"
    profile.write_text(text, encoding="utf-8")
    world = room(tmp_path, RED_BOX)
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - track: {colour: red, for: 6 s}\n", world=world, seed=1,
                                 robot=str(profile))
    assert h.run_to_end(30) == "success"
    assert h.truth.pan_rad == 0.0
    assert abs(camera_bearing_deg(h, BOX)) < 4.0  # facing the box
    assert math.hypot(h.truth.x - 1.0, h.truth.y) < 0.05  # turned in place


def test_a_typed_colour_is_hashable_and_reads_back():
    from beastbt.mission.vision_steps import sees_of
    from beastbt.vision.colour import ColourRange
    c = sees_of({"colour": {"hsv": [[100, 120, 60], [130, 255, 255]]}, "min_area": "2 %"})
    hash(c)
    assert ColourRange.parse(c.colour).boxes == (((100, 120, 60), (130, 255, 255)),)
    assert abs(c.min_area_frac - 0.02) < 1e-12


def test_the_docs_track_example_runs_and_pans_to_the_caretaker():
    doc = (ROOT / "docs" / "vision.md").read_text(encoding="utf-8")
    example = doc.split("## Keeping a colour in view")[1].split("```yaml\n")[1].split("```")[0]
    h = MissionHarness.from_yaml(example, seed=1, base_dir=ROOT / "missions")
    assert h.run_to_end(60) == "success"
    assert abs(camera_bearing_deg(h, (3.0, -2.1))) < 3.0  # the caretaker (waiting to cross) in the middle
    assert math.degrees(h.truth.pan_rad) < -15.0  # by the pan
