"""What a recording holds and how often (issue 26): each channel at its own rate, and no sensor woken for it.

The poses and what is drawn from them (/odom, /tf, /estimate/*, /truth) go at
``pose_rate_hz`` (10 Hz), and once a second while nothing moves; commands
and the readings the run used go every tick (replay needs them). Readings
nothing in the run reads (the base's IMU and battery while the EKF sleeps)
and sensors nothing reads (the GPS, the IMU, the camera) are recorded only
with ``--record-sensors``, which keeps them awake.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from beastbt.cli import main
from beastbt.recording.reader import read_recording
from beastbt.replay import replay
from recording_support import REPO, record_run

DRIVE_AND_LOOK = """
mission: drive_and_look
world: WORLD
steps:
  - wait: 2 s
  - look: {pan: 45 deg}
  - wait: 1 s
  - drive: {distance: 0.5 m, speed: 0.2 m/s}
"""
"""Stands still 2 s, turns the camera, waits, drives: still, a gimbal move, then motion."""


def drive_and_look(tmp_path: Path, **options) -> tuple[Path, dict]:
    mission = tmp_path / "drive_and_look.yaml"
    mission.write_text(DRIVE_AND_LOOK.replace("WORLD", str(REPO / "worlds" / "corridor.yaml")), encoding="utf-8")
    return record_run(mission, tmp_path / "runs", seed=2, **options)


def times_s(rec, topic: str) -> np.ndarray:
    """Log times of ``topic``'s messages, seconds from the recording's first tick."""
    t0 = rec.messages["/cmd/gate"][0][0]
    return np.array([(t - t0) * 1e-9 for t, _ in rec.messages.get(topic, [])])


def test_poses_go_at_ten_hz_and_once_a_second_while_still_and_commands_every_tick(tmp_path):
    folder, summary = drive_and_look(tmp_path)
    rec = read_recording(folder / "run.mcap")
    ticks = len(rec.topic("/cmd/gate"))
    assert ticks == summary["ticks"] and len(rec.topic("/cmd/mux")) == ticks  # every tick
    assert len(rec.topic("/sensors/odometry")) == ticks  # what the run's dead reckoning used
    tf = times_s(rec, "/tf")
    for topic in ("/odom", "/estimate/odom", "/truth"):
        assert np.array_equal(times_s(rec, topic), tf), topic  # drawn from the same poses, at the same turns
    steps = np.diff(tf)
    assert steps.min() >= 0.1 - 1e-6  # never above 10 Hz
    # Standing still for the first 2 s: once a second (0, 1, 2 s), not ten times.
    assert list(np.round(tf[tf < 1.95], 3)) == [0.0, 1.0]
    # Driving (the last leg): 10 Hz.
    servo_s = times_s(rec, "/cmd/servo")
    driving = tf[tf > servo_s[0] + 1.5]
    assert len(driving) >= 10 and np.allclose(np.diff(driving), 0.1, atol=1e-6)
    # The gimbal moved: /tf goes at the next turn (within 0.1 s), showing the camera panned.
    after = tf[tf >= servo_s[0] - 1e-9]
    assert after[0] - servo_s[0] <= 0.1 + 1e-6
    at = next(m for t, m in zip(tf, rec.topic("/tf")) if t == after[0])
    camera = next(x for x in at["transforms"] if x["child_frame_id"] == "camera_link")
    q = camera["rotation"]
    assert abs(2 * np.arctan2(q["z"], q["w"]) - np.radians(45)) < 1e-6


def test_a_recording_wakes_no_sensor_and_keeps_what_the_run_used(tmp_path):
    folder, summary = drive_and_look(tmp_path)
    rec = read_recording(folder / "run.mcap")
    asleep = [e["text"] for e in summary["events"] if e["kind"] == "asleep"]
    # The GPS stays awake for the recording (where the robot was: beastbt/recording/track.py), the rest sleeps.
    assert asleep and asleep[0].endswith(": imu, navigation")
    for topic in ("/sensors/imu", "/sensors/battery", "/camera/image", "/sensors/camera"):
        assert not rec.messages.get(topic), topic
    assert "camera" not in summary  # the camera was never switched on for the recording
    # Each reading still says which device it came from.
    assert {m["source"] for m in rec.topic("/sensors/odometry")} == {"base"}
    assert rec.topic("/scan") and {m["source"] for m in rec.topic("/scan")} == {"lidar"}
    result = replay(str(folder))
    assert result.identical, result.differences[:3]


def test_record_sensors_records_every_sensor_and_still_replays(tmp_path):
    folder, summary = drive_and_look(tmp_path, record_sensors=True)
    rec = read_recording(folder / "run.mcap")
    assert not any(e["kind"] == "asleep" for e in summary["events"])
    ticks = len(rec.topic("/cmd/gate"))
    # (The corridor is indoors: the GPS, awake, has no fix to give.)
    assert len(rec.topic("/sensors/battery")) == ticks and rec.topic("/sensors/imu")
    assert rec.messages.get("/camera/image")  # the camera runs for the recording, at the default 2 Hz
    assert summary["camera"]["enabled_for"] == ["recording"]
    assert replay(str(folder)).identical


def test_the_cli_takes_record_sensors(tmp_path):
    summary = tmp_path / "summary.json"
    mission = tmp_path / "wait.yaml"
    mission.write_text("mission: wait\nsteps:\n  - wait: 0.5 s\n", encoding="utf-8")
    assert main(["run", str(mission), "--runs-dir", str(tmp_path / "runs"), "--summary", str(summary),
                 "--record-sensors", "--record-images", "0"]) == 0
    events = json.loads(summary.read_text())["events"]
    assert not any(e["kind"] == "asleep" for e in events)
    [folder] = list((tmp_path / "runs").iterdir())
    assert read_recording(folder / "run.mcap").topic("/sensors/imu")
