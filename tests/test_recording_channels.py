"""Every run recorded: the MCAP file, its channels, their schemas, and what the recorder promises.

The example runs (patrol, a failsafe, teleop with a scripted joystick) are
read back with the ``mcap`` library's own reader; every channel is declared
with a JSON schema and every message validates against it.
"""

from __future__ import annotations

import base64
import dataclasses
import datetime
import json
import math
from pathlib import Path

import cv2
import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from beastbt.blackboard.types import (BatteryState, CameraFrame, FusedPose, GpsFix, ImuSample, JoystickState,
                                      LaserScan, LineObservation, ServoCommand, VelocityCommand, WheelOdometry)
from beastbt.cli import main
from beastbt.core.events import Event
from beastbt.recording.recorder import McapRecorder, RecordingConfig, contribute_summary
from beastbt.recording.reader import read_recording
from beastbt.recording.schemas import CHANNELS
from beastbt.run.runner import TickRecord
from beastbt.sim.truth import RobotTruth
from recording_support import PATROL, REPO, record_run, shared_run, without_timestamps

FOXGLOVE = {"/gps/fix": "foxglove.LocationFix", "/pose/fused": "foxglove.PoseInFrame",
            "/camera/image": "foxglove.CompressedImage", "/log": "foxglove.Log"}


def official_read(path: Path) -> dict[str, list]:
    """topic -> [(schema, channel, message, decoded)] with mcap's own (seeking) reader; checks the summary."""
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        for ch in summary.channels.values():
            out.setdefault(ch.topic, [])
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            out[channel.topic].append((schema, channel, message, json.loads(message.data)))
    return out


def validate_all(topics: dict[str, list]) -> None:
    """Every message of every channel matches the channel's JSON schema, which is the one beastbt declares."""
    for topic, entries in topics.items():
        for schema, channel, _message, decoded in entries[:400]:
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            declared = json.loads(schema.data)
            assert declared["title"] == schema.name
            if topic in CHANNELS:
                assert declared == CHANNELS[topic], topic
            jsonschema.Draft202012Validator(declared).validate(decoded)


@pytest.fixture(scope="module")
def example_runs():
    """Patrol (40 s), a failsafe run, teleop with a scripted joystick, the GPS route (the tree reads the fix),
    and the camera on the line track (recorded with --record-sensors)."""
    return {name: shared_run(name) for name in ("patrol", "failsafe", "teleop", "gps", "camera")}


def test_example_runs_have_every_channel_with_messages_that_match_their_schemas(example_runs):
    with_messages: set[str] = {"/vision/answers"}  # no camera words here: tests/test_replay_camera.py records it
    for name, (folder, summary) in example_runs.items():
        snapshots = ["tape.jpg"] if name == "camera" else []
        assert sorted(p.name for p in folder.iterdir()) == ["events.log", "run.mcap", "summary.json"] + snapshots
        topics = official_read(folder / "run.mcap")
        assert set(CHANNELS) <= set(topics), f"{name}: channels missing: {set(CHANNELS) - set(topics)}"
        validate_all(topics)
        with_messages |= {t for t, v in topics.items() if v}
        assert summary["recording"]["dropped"] == 0
        assert summary["recording"]["messages"] == sum(len(v) for v in topics.values())
    # The local planner's costmap and plan (go_to, route, return_home) and walking persons are not in these runs
    # (tests/test_obstacle_views.py records them), nor is what an operator did from the console or a terminal
    # (/operator/input: tests/test_replay_operator.py records and validates it).
    # Nor is a map (/localisation/*: tests/test_map_localiser_views.py records them; /map, /path, /map/pose:
    # tests/test_map_show.py). Nor a detector (/camera/detections, /camera/tags: tests/test_recording_detections.py),
    # nor anything the global costmap marks (/global_costmap, /plan: tests/test_global_views.py).
    missing = set(CHANNELS) - with_messages - {"/costmap", "/local_plan", "/sim/persons", "/operator/input",
                                               "/localisation/particles", "/localisation/quality", "/map", "/path",
                                               "/map/pose", "/camera/detections", "/camera/tags", "/global_costmap",
                                               "/plan"}
    assert not missing, f"no messages on {sorted(missing)}"


def test_foxglove_channels_use_the_well_known_schema_names(example_runs):
    topics = official_read(example_runs["patrol"][0] / "run.mcap")
    for topic, name in FOXGLOVE.items():
        assert CHANNELS[topic]["title"] == name
    schema, _, _, msg = topics["/pose/fused"][10]
    assert schema.name == "foxglove.PoseInFrame"
    q = msg["pose"]["orientation"]
    assert math.isclose(q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2, 1.0)


def test_log_time_is_epoch_nanoseconds_and_the_reader_gives_back_the_run_clock(example_runs):
    path = example_runs["patrol"][0] / "run.mcap"
    topics = official_read(path)
    # In the file: Unix epoch nanoseconds, the wall time of the run's start plus the simulated time.
    first_gate = topics["/cmd/gate"][0][2]
    started = datetime.datetime.fromisoformat(read_recording(path, topics=[]).info["start_utc"].replace("Z", "+00:00"))
    assert abs(first_gate.log_time * 1e-9 - started.timestamp()) < 60.0
    assert first_gate.publish_time == first_gate.log_time
    for topic, entries in topics.items():
        for _, _, message, decoded in entries[:50]:
            if "timestamp" in decoded:  # a Foxglove message: its own stamp is its log time
                assert decoded["timestamp"]["sec"] * 10**9 + decoded["timestamp"]["nsec"] == message.log_time, topic
    # Read back: the run's clock (0 at the first tick in the simulator), which replay and the report use.
    rec = read_recording(path)
    assert rec.log_time_offset_ns == first_gate.log_time
    gates = rec.messages["/cmd/gate"]
    assert [m["tick"] for _, m in gates] == list(range(len(gates)))
    for t_ns, m in gates[:50]:
        assert t_ns == round(m["now_s"] * 1e9)
        assert math.isclose(m["now_s"], m["tick"] * 0.05, abs_tol=1e-9)
    # Readings are logged at the tick that received them, stamped with when they were measured.
    odo_times = {t for t, _ in rec.messages["/sensors/odometry"]}
    assert odo_times <= {t for t, _ in gates}


def test_sensor_streams_are_every_reading_the_run_used_as_it_arrived(example_runs):
    rec = read_recording(example_runs["patrol"][0] / "run.mcap")
    n_ticks = len(rec.topic("/cmd/gate"))
    assert len(rec.topic("/sensors/odometry")) == n_ticks  # the run's dead reckoning: every reading
    # The base reports its battery and IMU every tick too, but nothing in the patrol reads them (the EKF
    # sleeps): they are not recorded (--record-sensors records them, as the camera run shows).
    assert not rec.topic("/sensors/battery") and not rec.topic("/sensors/imu") and not rec.topic("/sensors/gps")
    camera = read_recording(example_runs["camera"][0] / "run.mcap")
    assert len(camera.topic("/sensors/battery")) == len(camera.topic("/cmd/gate"))
    assert camera.topic("/sensors/imu")
    assert read_recording(example_runs["gps"][0] / "run.mcap").topic("/sensors/gps")  # the route reads the fix
    # The true pose, like the estimates, goes at the recording's pose rate (10 Hz), not every tick, and while
    # the robot stands still once a second.
    truth_s = [m["t_s"] for m in rec.topic("/truth")]
    assert len(truth_s) <= n_ticks / 2 + 1 and max(np.diff(truth_s)) <= 1.0 + 1e-6
    assert min(np.diff(truth_s)) >= 0.1 - 1e-6
    assert rec.topic("/cmd/servo"), "the patrol looks around: servo commands"
    odo = rec.topic("/sensors/odometry")
    assert odo[-1]["left_m"] > 3.0  # the robot drove its first 3 m
    teleop = read_recording(example_runs["teleop"][0] / "run.mcap")
    assert teleop.topic("/cmd/teleop") and all(m["mux_source"] == "teleop" for m in teleop.topic("/cmd/teleop"))


def test_tree_channel_holds_changes_with_feedback(example_runs):
    rec = read_recording(example_runs["patrol"][0] / "run.mcap")
    tree = rec.topic("/tree")
    first = {c["name"]: c for c in tree[0]["changes"]}
    assert tree[0]["tick"] == 0 and first["drive 3 m at 0.15 m/s"]["status"] == "RUNNING"
    done = [c for m in tree for c in m["changes"] if c["name"] == "drive 3 m at 0.15 m/s" and c["status"] == "SUCCESS"]
    assert done and done[0]["feedback"].startswith("covered")
    # Only changes: far fewer messages than ticks.
    assert len(tree) < len(rec.topic("/cmd/gate")) / 10


def test_failsafes_and_events_are_recorded(example_runs):
    folder, summary = example_runs["failsafe"]
    rec = read_recording(folder / "run.mcap")
    assert summary["status"] == "failure"
    fs = rec.topic("/failsafes")
    assert fs and fs[0]["kind"] == "failsafe" and "battery_low" in fs[0]["text"]
    kinds = [m["kind"] for m in rec.topic("/events")]
    # Before the start, only what the assembly said (which parts sleep).
    start = kinds.index("mission_start")
    assert set(kinds[:start]) <= {"asleep"} and "mission_end" in kinds[start:]
    logs = rec.topic("/log")
    assert any(m["level"] == 3 and "battery_low" in m["message"] for m in logs)


def test_metadata_and_attachments_make_the_recording_self_contained(example_runs):
    rec = read_recording(example_runs["patrol"][0] / "run.mcap")
    info = rec.info
    assert info["mission"] == "corridor_patrol" and info["seed"] == "1" and info["robot"] == "sim"
    assert Path(info["mission_file"]) == PATROL.resolve()
    assert info["world"] == "corridor" and json.loads(info["world_start"]) == [1.0, 0.0, 0.0]
    assert rec.text("mission.yaml") == PATROL.read_text(encoding="utf-8")
    assert "robot.yaml" in rec.attachments and "world.yaml" in rec.attachments
    assert rec.summary["status"] == example_runs["patrol"][1]["status"]
    nodes = json.loads(info["tree"])
    assert nodes[0] == {"id": "0", "name": nodes[0]["name"], "kind": "sequence", "parent": None}
    ids = {n["id"]: n for n in nodes}
    assert len(ids) == len(nodes) and all(n["parent"] in ids for n in nodes[1:])
    assert any(n["kind"] == "action" for n in nodes)
    # Every change on /tree names a node of that list by its stable id (the patrol's two drives share a name).
    changes = [c for m in rec.topic("/tree") for c in m["changes"]]
    assert changes and all(ids[c["id"]]["name"] == c["name"] for c in changes)
    drives = {c["id"] for c in changes if c["name"] == "drive 3 m at 0.15 m/s"}
    assert len(drives) == 2


def test_same_seed_same_recording_and_summary(tmp_path):
    a_dir, a = record_run(PATROL, tmp_path / "a", seed=4, max_time_s=10.0)
    b_dir, b = record_run(PATROL, tmp_path / "b", seed=4, max_time_s=10.0)
    a.pop("wall_time_s"), b.pop("wall_time_s")
    assert a == b and a["recording"]["messages"] > 0
    ra, rb = read_recording(a_dir / "run.mcap"), read_recording(b_dir / "run.mcap")
    assert without_timestamps(ra) == without_timestamps(rb)


def test_a_full_queue_in_the_simulator_waits_and_loses_nothing(tmp_path):
    _, normal = record_run(PATROL, tmp_path / "a", seed=5, max_time_s=8.0)
    folder, tiny = record_run(PATROL, tmp_path / "b", seed=5, max_time_s=8.0,
                              recording={"queue_max_items": 2, "overflow": "block"})
    assert tiny["recording"] == normal["recording"]
    assert read_recording(folder / "run.mcap").message_count() == tiny["recording"]["messages"]


def test_a_full_queue_on_the_robot_drops_and_counts(tmp_path):
    rec = McapRecorder([tmp_path / "x.mcap"], RecordingConfig(queue_max_items=3, overflow="drop"))
    for i in range(10):  # the writer is not running yet: the queue fills up
        rec.on_event(Event(0.1 * i, "say", f"hello {i}"))
    rec.on_event(Event(1.5, "failsafe", "gps_lost triggered: then hold"))
    assert rec.dropped_items == 8 and rec.dropped == 7 * 2 + 3  # /events + /log, and /failsafes too
    rec.finish(None)
    got = read_recording(tmp_path / "x.mcap")
    assert got.complete and [m["text"] for m in got.topic("/events")] == ["hello 0", "hello 1", "hello 2"]

    class FakeRun:  # the summary contributor finds the recorder by its run
        pass

    run = FakeRun()
    run.recorder = rec
    summary: dict = {}
    contribute_summary(run, summary)
    assert summary["recording"] == {"messages": 6, "dropped": 17}


def _synthetic_ticks(n: int, dt: float = 0.05) -> list[TickRecord]:
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    out = []
    truth = RobotTruth()
    for k in range(n):
        t = k * dt
        truth.t_s, truth.x = t, 0.1 * t
        readings = [WheelOdometry(t, 0.1 * t, 0.1 * t, 0.1, 0.1), ImuSample(t, (0.0, 0.0, 0.01), (0.0, 0.0, 9.81)),
                    BatteryState(t, 12.1), JoystickState(t, {"linear": 0.5, "angular": 0.0}, {"enable": True}),
                    LineObservation(t, True, 0.02, 0.1, 0.02, 0.9)]
        if k % 4 == 0:
            readings.append(GpsFix(t, 40.0, -3.0, 650.0, 1, 8, 0.9, 0.1, 90.0, "120000.00"))
        if k % 1 == 0:  # a frame every tick (20 fps)
            readings.append(CameraFrame(t, image, k + 1))
        if k % 2 == 0:  # a LiDAR revolution at 10 Hz, clockwise as the LD19 turns, with a few no-returns (NaN)
            angles = (-np.radians(np.arange(450) * 0.8) + np.pi) % (2 * np.pi) - np.pi
            ranges = np.where(np.arange(450) % 50 == 0, np.nan, 2.0)
            readings.append(LaserScan(t, angles, ranges, np.full(450, 200.0), 10.0, "ld19"))
        pose = FusedPose(t, 0.1 * t, 0.0, 0.0, lat=40.0, lon=-3.0)
        cmd = VelocityCommand(0.1, 0.0, t, "teleop")
        out.append(TickRecord(k, t, readings, pose, pose, None, cmd, cmd, "teleop",
                              [("teleop", "RUNNING", "driving", "0")] if k == 0 else [], truth))
    return out


def test_every_stream_type_gets_its_channel_and_validates(tmp_path):
    rec = McapRecorder([tmp_path / "s.mcap"], RecordingConfig(image_rate_hz=2.0, image_max_width_px=32),
                       info={"mission": "synthetic"})
    for r in _synthetic_ticks(41):
        rec.on_tick(r)
    rec.on_event(Event(1.0, "failsafe", "geofence triggered: then stop"))
    rec.on_servo(ServoCommand("pan", 0.5, stamp_s=1.0), 1.0)
    rec.finish({"status": "success"})
    topics = official_read(tmp_path / "s.mcap")
    validate_all(topics)
    empty = {t for t in CHANNELS if not topics.get(t)} - {"/vision/answers"}  # no mission asked the camera
    # No mission command (teleop drove), no watched device, no mission or world to draw (no scene item), no
    # camera mounting in the metadata to calibrate and annotate the images with, no run to draw obstacles of.
    assert empty == {"/cmd/mission", "/devices/state", "/scene", "/route", "/camera/calibration",
                     "/camera/annotations", "/costmap", "/local_plan", "/collision_monitor/zones", "/sim/persons",
                     "/sim/contact", "/operator/input", "/localisation/particles", "/localisation/quality", "/map",
                     "/path", "/map/pose", "/camera/photo",  # no photo taken
                     "/camera/detections", "/camera/tags",  # no detector awake
                     "/global_costmap", "/plan"}  # no go_to
    # Images at 2 Hz out of 20 fps over 2 s: at t = 0, 0.5, 1.0, 1.5, 2.0; each a real JPEG, scaled to 32 px wide.
    images = topics["/camera/image"]
    offset = read_recording(tmp_path / "s.mcap", topics=[]).log_time_offset_ns
    assert offset > 1_577_836_800 * 10**9  # after 2020: the wall time of the first tick
    assert [round((m.log_time - offset) * 1e-9, 2) for _, _, m, _ in images] == [0.0, 0.5, 1.0, 1.5, 2.0]
    jpeg = cv2.imdecode(np.frombuffer(base64.b64decode(images[0][3]["data"]), np.uint8), cv2.IMREAD_COLOR)
    assert jpeg.shape == (24, 32, 3)
    frames = [d for *_, d in topics["/sensors/camera"]]
    assert len(frames) == 41 and sum(f["image_recorded"] for f in frames) == 5 and frames[0]["width"] == 64
    # The Foxglove GPS view carries the driver's covariance, row-major ENU.
    fix = topics["/gps/fix"][0][3]
    assert fix["latitude"] == 40.0 and fix["position_covariance"][0] == 9.0 and fix["position_covariance"][8] == 36.0


def test_a_reading_type_without_a_schema_still_gets_a_channel(tmp_path):
    @dataclasses.dataclass(frozen=True)
    class Thermometer:
        stamp_s: float
        temperature_c: float

    rec = McapRecorder([tmp_path / "t.mcap"])
    tick = _synthetic_ticks(1)[0]
    tick.readings = [Thermometer(0.0, 21.5)]
    rec.on_tick(tick)
    rec.finish(None)
    got = read_recording(tmp_path / "t.mcap")
    assert got.topic("/sensors/thermometer") == [{"stamp_s": 0.0, "temperature_c": 21.5, "source": None}]
    assert got.schemas["/sensors/thermometer"][0] == "beastbt.Thermometer"


def test_record_file_without_a_run_folder_and_both(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    lone = tmp_path / "lone.mcap"
    code = main(["run", str(PATROL), "--no-record", "--record", str(lone), "--max-time", "5 s",
                 "--record-images", "0"])
    assert code == 1  # stopped by --max-time
    assert not (tmp_path / "runs").exists()
    got = read_recording(lone)
    assert got.complete and got.summary is None and len(got.topic("/cmd/gate")) == 101  # ticks at 0, 0.05 ... 5 s
    both = tmp_path / "both.mcap"
    main(["run", str(PATROL), "--runs-dir", str(tmp_path / "r"), "--record", str(both), "--max-time", "5 s"])
    (folder,) = (tmp_path / "r").iterdir()
    assert (folder / "run.mcap").read_bytes() == both.read_bytes()
    assert read_recording(both).summary["status"] == "stopped"


def test_recording_config_rejects_unknown_keys_and_matches_its_schema():
    with pytest.raises(ValueError, match="image_rate"):
        RecordingConfig.from_dict({"image_rate": 5})
    with pytest.raises(ValueError, match="overflow"):
        RecordingConfig.from_dict({"overflow": "sometimes"})
    schema = json.loads((REPO / "schemas" / "parts" / "recording.schema.json").read_text(encoding="utf-8"))
    fields = {f.name: f.default for f in dataclasses.fields(RecordingConfig)}
    assert set(schema["properties"]) == set(fields)
    for name, default in fields.items():
        assert schema["properties"][name]["default"] == default, name
        assert "default" in schema["properties"][name]["description"]


def test_camera_frames_images_line_and_snapshots(example_runs):
    folder, summary = example_runs["camera"]
    rec = read_recording(folder / "run.mcap")
    frames = rec.topic("/sensors/camera")
    images = rec.messages["/camera/image"]
    assert len(frames) > len(images) >= 2  # every frame described, pixels at 2 Hz
    assert all(m["source"] == "camera" for m in frames)
    # Images at most 2 per clock second, and each one a JPEG of the camera's size.
    times = [t * 1e-9 for t, _ in images]
    assert all(b - a >= 0.5 - 1e-6 for a, b in zip(times, times[1:]))
    jpeg = cv2.imdecode(np.frombuffer(base64.b64decode(images[0][1]["data"]), np.uint8), cv2.IMREAD_COLOR)
    assert (jpeg.shape[1], jpeg.shape[0]) == (frames[0]["width"], frames[0]["height"])
    assert any(m["seen"] for m in rec.topic("/sensors/line")), "the robot starts on the tape"
    assert rec.attachments["tape.jpg"] == (folder / "tape.jpg").read_bytes()
