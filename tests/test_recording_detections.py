"""What the detectors found goes to the recording: /camera/detections over the image, /camera/tags in 3D.

A short run in worlds/lab.yaml: the camera levelled at the dock's tag 0 (30 cm, 2.9 m away, straight ahead
at the start), the tag looked for, two seconds with no detector asked, the tag looked for again. Every message
validates against Foxglove's own schema (tests/data/foxglove/), the tag's outline lies on the tag's corners
projected from the world with the robot's true pose and the camera's mounting, each message is stamped with
its frame's time, and nothing is drawn while no detector runs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
from mcap.reader import make_reader

from beastbt.sim.markers import project, square_corners
from beastbt.vision.camera_model import CameraGeometry
from recording_support import REPO, record_run

OFFICIAL = REPO / "tests" / "data" / "foxglove"
MISSION = """mission: look_for_the_dock
world: WORLD
steps:
  - look: {tilt: 40 deg}
  - wait_until: {sees: {tag: 0}}
    timeout: 3 s
  - wait: 2 s
  - wait_until: {sees: {tag: 0}}
    timeout: 3 s
""".replace("WORLD", str(REPO / "worlds" / "lab.yaml"))
TAG = {"x": 7.99, "y": 0.0, "z_m": 0.25, "facing_deg": 180.0, "size_m": 0.3}
"""Tag 0 of worlds/lab.yaml."""


def _read(path: Path) -> dict[str, list[tuple[int, dict, str]]]:
    """topic -> [(log time ns, message, schema name)] with the mcap library's reader."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data), schema.name))
    return out


def _ns(stamp: dict) -> int:
    return stamp["sec"] * 10**9 + stamp["nsec"]


def test_detections_are_recorded_on_the_tag_stamped_with_their_frame_and_only_while_a_detector_runs(tmp_path):
    mission = tmp_path / "look.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    folder, summary = record_run(mission, tmp_path / "runs")
    assert summary["status"] == "success" and summary["recording"]["dropped"] == 0
    topics = _read(Path(folder) / "run.mcap")
    detections, tags = topics["/camera/detections"], topics["/camera/tags"]
    for topic, rows in (("/camera/detections", detections), ("/camera/tags", tags)):
        official = json.loads((OFFICIAL / f"{rows[0][2].removeprefix('foxglove.')}.json").read_text("utf-8"))
        check = jsonschema.Draft202012Validator(official)
        for _, msg, _ in rows:
            assert not list(check.iter_errors(msg)), topic

    # Stamped like the camera frame they came from: each at the log time of a /sensors/camera message.
    frame_times = {t for t, _, _ in topics["/sensors/camera"]}
    outlined = [(t, m) for t, m, _ in detections if m["points"]]
    assert len(outlined) >= 2
    for t, m in outlined:
        assert t in frame_times
        assert all(_ns(p["timestamp"]) == t for p in m["points"] + m["texts"])

    # The outline on the tag: its corners projected from the world with the true pose and the camera levelled.
    truth = topics["/truth"][0][1]
    tilt = next(m["angle_rad"] for _, m, _ in topics["/cmd/servo"] if m["name"] == "tilt")
    geom = CameraGeometry(width_px=320, height_px=240, hfov_deg=62.2, height_m=0.2, pitch_deg=40.0,
                          x_offset_m=0.1).with_pan_tilt(0.0, tilt)
    c, s = math.cos(truth["yaw"]), math.sin(truth["yaw"])
    body_from_world = np.array([[c, s, 0.0, -(c * truth["x"] + s * truth["y"])],
                                [-s, c, 0.0, s * truth["x"] - c * truth["y"]], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    cam = geom.camera_from_body @ body_from_world
    corners = square_corners(TAG["x"], TAG["y"], TAG["z_m"], math.radians(TAG["facing_deg"]), TAG["size_m"])
    expected = project(corners @ cam[:, :3].T + cam[:, 3], geom.camera_matrix)
    for _, m in outlined:
        [outline] = m["points"]
        got = np.array([[p["x"], p["y"]] for p in outline["points"]])
        assert np.abs(got - expected).max() < 2.5, (got, expected)
        assert m["texts"][0]["text"].startswith("tag 0 ")

    # The tag in 3D: a plate in base_link, in front of the robot (2.9 m; the mission gives no size, so 16 cm is
    # assumed and the distance reads short, but the bearing holds).
    entity = tags[0][1]["entities"][0]
    assert entity["frame_id"] == "base_link" and entity["id"] == "tag/apriltag_36h11/0"
    p = entity["cubes"][0]["pose"]["position"]
    assert p["x"] > 1.0 and abs(math.atan2(p["y"], p["x"])) < math.radians(3)

    # Only while a detector is awake: during the 2 s wait no outline, and one empty message clears the image.
    times = [t for t, _, _ in detections]
    gaps = [(a, b) for a, b in zip(times, times[1:]) if b - a > 1.0e9]
    assert len(gaps) == 1
    before_gap = next(m for t, m, _ in detections if t == gaps[0][0])
    assert before_gap == {"circles": [], "points": [], "texts": []}
    assert any(gaps[0][0] < t < gaps[0][1] for t in frame_times)  # the camera ran on: only the detectors slept
