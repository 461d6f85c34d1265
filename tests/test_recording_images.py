"""``--record-images HZ``: camera frames kept per second whenever the robot has a camera, used by a step or not.

The simulated robot has a camera; the patrol never looks through it. Its
recording still holds ``/camera/image`` at the asked rate, each a JPEG; the
camera renders only the frames the recording keeps; ``0`` keeps none and
leaves the camera off.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from beastbt.cli import main
from beastbt.recording.reader import read_recording
from beastbt.replay import replay
from recording_support import PATROL


def run_patrol(tmp_path: Path, *extra: str) -> tuple[Path, dict]:
    """``beastbt run missions/patrol.yaml`` for 5 simulated seconds with ``extra``; (run folder, summary)."""
    summary = tmp_path / "summary.json"
    code = main(["run", str(PATROL), "--max-time", "5 s", "--runs-dir", str(tmp_path / "runs"),
                 "--summary", str(summary), *extra])
    assert code == 1  # stopped by --max-time, as asked
    [folder] = list((tmp_path / "runs").iterdir())
    return folder, json.loads(summary.read_text())


@pytest.mark.parametrize("hz", [2.0, 4.0])
def test_the_patrol_records_images_at_the_asked_rate(tmp_path, hz):
    folder, summary = run_patrol(tmp_path, "--record-images", f"{hz:g}")
    rec = read_recording(folder / "run.mcap")
    images = rec.messages.get("/camera/image", [])
    times = [round(t * 1e-9, 3) for t, _ in images]
    # One image every 1/hz s of the run's clock, from its first tick to its last (5 s).
    assert len(images) == int(5 * hz) + 1, times
    steps = np.diff(np.array([t for t, _ in images], dtype=np.int64)) * 1e-9
    assert np.allclose(steps, 1 / hz, atol=1e-6), steps
    jpeg = cv2.imdecode(np.frombuffer(base64.b64decode(images[-1][1]["data"]), np.uint8), cv2.IMREAD_COLOR)
    assert jpeg is not None and jpeg.ndim == 3 and jpeg.std() > 0  # a real picture, not a blank
    # The camera was on for the recording only, and rendered only the frames kept.
    assert summary["camera"]["enabled_for"] == ["recording"]
    assert len(rec.topic("/sensors/camera")) == len(images) == summary["camera"]["frames"]
    assert len(rec.topic("/camera/calibration")) == len(images)
    assert not rec.topic("/sensors/line")  # pictures only: no line observations nobody asked for
    # The patrol still replays exactly with its camera readings, to where --max-time stopped it (and says so).
    result = replay(str(folder))
    assert result.identical and any("max time 5 s reached" in n for n in result.notes)


def test_no_images_keeps_the_camera_off(tmp_path):
    folder, summary = run_patrol(tmp_path, "--record-images", "0")
    rec = read_recording(folder / "run.mcap")
    assert not rec.messages.get("/camera/image") and not rec.messages.get("/sensors/camera")
    assert "camera" not in summary


def test_a_step_that_uses_the_camera_still_gets_every_frame(tmp_path):
    mission = tmp_path / "look.yaml"
    mission.write_text("mission: look\nsteps:\n  - wait: 1 s\n  - snapshot: {name: view}\n", encoding="utf-8")
    summary = tmp_path / "summary.json"
    assert main(["run", str(mission), "--record-images", "2", "--runs-dir", str(tmp_path / "runs"),
                 "--summary", str(summary)]) == 0
    [folder] = list((tmp_path / "runs").iterdir())
    rec = read_recording(folder / "run.mcap")
    frames, images = rec.topic("/sensors/camera"), rec.messages.get("/camera/image", [])
    assert len(images) == 3  # 0, 0.5 and 1.0 s
    assert len(frames) > 3 * len(images)  # the camera's own frame rate, not the recording's
    assert len(rec.topic("/sensors/line")) == len(frames)  # and the line detector on every frame
    assert json.loads(summary.read_text())["camera"]["enabled_for"][0] == "snapshot"
