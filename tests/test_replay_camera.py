"""``beastbt replay`` of a run that uses the camera's words gives the tree the answers the detectors gave the run.

The run's detectors looked at every frame vision took (10 a second, uncompressed; motion's model
learnt from all of them), while the recording keeps JPEG images 2 a second. Before the answers were
recorded (``/vision/answers``) a replay had no detectors at all: the first ``{sees: ...}`` never held,
``dock`` and ``track`` failed at once. Run on the recorded images instead, the detectors answered
differently (a dock's commands differed from its 17th tick; motion fired a tick late).
"""

from __future__ import annotations

import io
import math

import jsonschema
import numpy as np
import orjson
import pytest

from beastbt.assembly import prepare
from beastbt.recording.reader import read_recording
from beastbt.recording.schemas import CHANNELS
from beastbt.replay import replay
from beastbt.run.session import RunOptions, execute
from beastbt.vision.answer_messages import TOPIC, value_json
from beastbt.vision.colour import ColourBlob
from beastbt.vision.fiducials import TagDetection
from beastbt.vision.motion import MotionResult
from beastbt.vision.qr_codes import QrDetection
from beastbt.vision.recorded_answers import value_of

WORLD = """world: camroom
gps: {sky: none}
start: {x: 4.8, y: 0.0, yaw_deg: 0}
walls:
  - [0.0, -3.0, 6.0, -3.0]
  - [0.0, 3.0, 6.0, 3.0]
  - [0.0, -3.0, 0.0, 3.0]
  - [6.0, -3.0, 6.0, 3.0]
tags:
  - {id: 3, size_m: 0.16, x: 5.99, y: 0.4, z_m: 0.3, facing_deg: 180}
qr_boards:
  - {text: door-3, size_m: 0.3, x: 5.99, y: -0.05, z_m: 0.25, facing_deg: 180}
obstacles:
  - {shape: box, x: 5.8, y: -0.5, size_m: [0.2, 0.2], colour: red}
  - {shape: person, radius_m: 0.2, speed_mps: 0.8, path: [[5.4, -2.8], [5.4, 2.8]], start_s: 3}
"""
"""A wall 1.2 m ahead with a tag and a QR board, a red box beside them, and a person who walks across from 3 s."""

STEPS = """  - look: {tilt: 40 deg}
  - wait_until: {sees: {tag: 3}}
    timeout: 3 s
  - wait_until: {sees: {qr: door-3}}
    timeout: 3 s
  - photo: {name: wall}
  - wait_until: {sees: motion}
    timeout: 10 s
  - alert: {text: "someone walked by", photo: true}
  - track: {colour: red, for: 2 s}
"""


@pytest.fixture(scope="module")
def camera_run(tmp_path_factory):
    """The run (seed 1) of a mission with each camera word but dock: its folder and summary."""
    tmp = tmp_path_factory.mktemp("camreplay")
    (tmp / "world.yaml").write_text(WORLD, encoding="utf-8")
    mission = tmp / "camera_words.yaml"
    mission.write_text("mission: camera_words\nworld: world.yaml\nsteps:\n" + STEPS, encoding="utf-8")
    p = prepare(str(mission), RunOptions(simulate=True, seed=1, runs_dir=str(tmp / "runs"), max_time_s=40))
    summary = execute(p, io.StringIO())
    assert p.folder is not None
    return p.folder.path, summary, tmp


def test_a_run_with_the_camera_words_replays_with_no_difference(camera_run):
    folder, summary, _ = camera_run
    assert summary["status"] == "success"
    assert [p["name"] for p in summary["vision"]["photos"]] == ["wall", "alert-1"]
    answers = read_recording(folder / "run.mcap").topic(TOPIC)
    assert {m["kind"] for m in answers} == {"tags:apriltag_36h11", "qr", "motion", "colour:red"}
    assert any(m["kind"] == "motion" and m["value"]["moving"] for m in answers)
    validator = jsonschema.Draft202012Validator(CHANNELS[TOPIC])
    for m in answers:
        validator.validate(m)

    result = replay(str(folder))
    assert result.identical, [d.describe() for d in result.differences[:5]]
    assert result.ticks == summary["ticks"] and result.differing_ticks == 0
    assert result.recorded_status == result.replay_status == "success"
    assert any(f"their {len(answers)} recorded answers" in n for n in result.notes), result.notes
    assert not any("computed again" in n for n in result.notes), result.notes
    # The same steps' outcomes at the same times: the photos, the alert, the end.
    kinds = ("photo", "alert", "step_failed", "mission_end")
    def outcome(text: str) -> str:  # without the photo's file (a replay writes none)
        return text.split(":")[0].split(" (photo")[0]
    recorded = [(e["time_s"], e["kind"], outcome(e["text"])) for e in read_recording(folder / "run.mcap").topic(
        "/events") if e["kind"] in kinds]
    replayed = [(t, k, outcome(text)) for t, k, text in result.events if k in kinds]
    assert replayed == recorded and [k for _, k, _ in recorded] == ["photo", "photo", "alert", "mission_end"]


def test_a_changed_mission_runs_the_detectors_the_run_did_not_and_says_so(camera_run):
    folder, _, tmp = camera_run
    changed = tmp / "changed.yaml"
    # Also asks for green, which the run never looked for: only the recorded JPEG images can answer that.
    changed.write_text("mission: camera_words\nworld: world.yaml\nsteps:\n"
                       + STEPS.replace("  - photo:", "  - first_of:\n      - - wait_until: {sees: {colour: green}}\n"
                                                     "          timeout: 0.5 s\n      - - say: no green\n  - photo:"),
                       encoding="utf-8")
    result = replay(str(folder), str(changed))
    again = [n for n in result.notes if "computed again" in n]
    assert len(again) == 1 and "colour:green (" in again[0] and "recorded JPEG images" in again[0], result.notes
    assert not any(k in again[0] for k in ("tags:", "qr (", "motion (", "colour:red")), again
    assert any("recorded answers" in n for n in result.notes), result.notes
    # The person still walks in at the same time: the half second spent looking for green is absorbed by the wait.
    assert result.replay_status == "success"
    assert any(k == "say" and text == "no green" for _, k, text in result.events), result.events


def test_answers_go_through_json_as_the_very_values_the_detectors_gave():
    tag = TagDetection("apriltag_36h11", 3, np.array([[1.1, 2.2], [3.3, 4.4], [5.5, 6.6], [7.7, 8.8]], np.float32),
                       0.16, np.array([0.1 + 0.2, -1e-17, math.pi]), np.array([0.3, 1 / 3, 1.2]),
                       (1.0000000000000002, -0.1, 0.3), 3.0000000001)
    cases = [("tags:apriltag_36h11", [tag]), ("qr", [QrDetection("door-3", np.array([[0.5, 1.5]] * 4, np.float32))]),
             ("motion", MotionResult(0.012345678901234, (1, 2, 3, 4), True, True)),
             ("colour:red", ColourBlob(0.1 + 0.2, (np.float64(160.25), 1 / 3), (1, 2, 3, 4))), ("qr", None)]
    for kind, value in cases:
        back = value_of(kind, orjson.loads(orjson.dumps(value_json(kind, value))))
        if kind.startswith("tags:"):
            b = back[0]
            assert b.corners_px.dtype == np.float32 and np.array_equal(b.corners_px, tag.corners_px)
            assert np.array_equal(b.rvec, tag.rvec) and np.array_equal(b.tvec_m, tag.tvec_m)
            assert (b.position_m, b.facing_rad, b.distance_m) == (tag.position_m, tag.facing_rad, tag.distance_m)
        elif kind == "qr" and value is not None:
            assert back[0].text == "door-3" and back[0].corners_px.dtype == np.float32
        else:
            assert back == value, kind


def test_a_frame_the_camera_thread_gave_vision_before_the_tick_loop_is_the_frame_the_replay_looks_at():
    """On the robot the camera thread's newest frame may be one the tick loop hands over only at the next tick:
    the replay's watch looks at the frame the run's did (from the answers), not at the last one handed over."""
    from beastbt.blackboard.types import CameraFrame
    from beastbt.devices.camera import CameraConfig
    from beastbt.recording.writer import encode_json
    from beastbt.robot.profile import load_profile, section_config
    from beastbt.vision.answer_messages import answer_message
    from beastbt.vision.camera_model import CameraGeometry
    from beastbt.vision.colour import ColourRange
    from beastbt.vision.recorded_answers import AnswerTap, RecordedAnswers, ReplayVisionWatch, replay_frames
    from beastbt.vision.watch import VisionWatch

    frames = []
    for seq in range(12):  # a red square moving right 10 px a frame, 10 frames a second
        image = np.full((240, 320, 3), 200, np.uint8)
        image[100:140, 20 + 10 * seq:60 + 10 * seq] = (0, 0, 220)
        frames.append(CameraFrame(0.1 * seq, image, seq + 1))
    geometry = CameraGeometry.from_config(section_config(load_profile("sim"), "camera", CameraConfig))
    red = ColourRange.parse("red")
    tick = {"k": 0}
    live = VisionWatch(lambda: frames[tick["k"] + 1], geometry)  # the thread is a frame ahead of the tick loop
    tap = AnswerTap.attach(live)
    seen = []
    for k in range(10):
        tick["k"] = k
        seen.append(live.colour(0.1 * k + 0.01, red)[0])
    messages = [orjson.loads(encode_json(answer_message(a))) for a in tap.take()]

    answers = RecordedAnswers(messages)
    latest = replay_frames(lambda: frames[tick["k"]], lambda: 0.1 * tick["k"] + 0.01, answers)
    again = ReplayVisionWatch(latest, geometry, answers=answers)
    for k in range(10):
        tick["k"] = k
        assert again.colour(0.1 * k + 0.01, red)[0] == seen[k], k
    assert again.computed == {} and answers.given == 10


def test_a_recording_without_answers_is_replayed_on_its_images_and_the_notes_say_so(camera_run, monkeypatch):
    import beastbt.replay as replay_module
    folder, _, _ = camera_run
    # As a recording made before /vision/answers: the replay reads the file without them.
    monkeypatch.setattr(replay_module, "NOT_REPLAYED", replay_module.NOT_REPLAYED + (TOPIC,))
    result = replay(str(folder))
    again = [n for n in result.notes if "computed again" in n]
    assert len(again) == 1 and "recorded before /vision/answers" in again[0], result.notes
    assert all(k in again[0] for k in ("tags:apriltag_36h11 (", "qr (", "motion (", "colour:red (")), again
    assert not any("recorded answers" in n for n in result.notes)


def test_a_changed_mission_that_looks_where_the_run_did_not_is_told_there_are_no_frames(camera_run):
    _, _, tmp = camera_run
    blind = tmp / "blind.yaml"
    blind.write_text("mission: blind\nworld: world.yaml\nsteps:\n  - wait: 1 s\n", encoding="utf-8")
    p = prepare(str(blind), RunOptions(simulate=True, seed=1, runs_dir=str(tmp / "blind_runs")))
    execute(p, io.StringIO())
    looks = tmp / "looks.yaml"
    looks.write_text("mission: blind\nworld: world.yaml\nsteps:\n  - wait_until: {sees: {tag: 3}}\n"
                     "    timeout: 0.5 s\n", encoding="utf-8")
    result = replay(str(p.folder.path), str(looks))
    assert any("took no camera frames" in n for n in result.notes), result.notes
    assert result.replay_status == "failure"  # the tag is never seen: no frame to see it in
