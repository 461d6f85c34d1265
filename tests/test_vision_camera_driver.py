"""Camera driver: newest frame, clock stamps, frame rate, staleness, loss and reopen."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Optional

import cv2
import jsonschema
import numpy as np
import pytest

from beastbt.devices.camera import Camera, CameraConfig, open_video_capture
from beastbt.core.clock import SimClock
from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.floor import FloorMap
from beastbt.vision.camera_model import CameraGeometry

REPO = Path(__file__).resolve().parent.parent


class ScriptedSource:
    """A FrameSource whose reads follow a script: 'ok', 'fail', 'raise', 'grey' or 'junk'."""

    def __init__(self, script: list[str]) -> None:
        self.script = list(script)
        self.opened = True
        self.released = 0

    def isOpened(self) -> bool:  # noqa: N802
        return self.opened

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        step = self.script.pop(0) if self.script else "ok"
        if step == "raise":
            raise cv2.error("simulated V4L2 failure")
        if step == "fail":
            return False, None
        if step == "grey":
            return True, np.full((24, 32), 77, np.uint8)
        if step == "junk":
            return True, np.zeros((24, 32, 3), np.float32)
        return True, np.full((24, 32, 3), 99, np.uint8)

    def release(self) -> None:
        self.opened = False
        self.released += 1


class Events:
    def __init__(self) -> None:
        self.seen: list[tuple[str, str]] = []

    def __call__(self, kind: str, text: str) -> None:
        self.seen.append((kind, text))

    def kinds(self) -> list[str]:
        return [k for k, _ in self.seen]


@pytest.fixture(scope="module")
def sim_camera_parts() -> tuple[FloorMap, CameraGeometry]:
    floor = FloorMap.from_dict({"margin_m": 0.5, "lines": {"paths": [{"path": [[0, 0], [2, 0]]}]}}, np.random.default_rng(0))
    return floor, CameraGeometry(width_px=160, height_px=120)


def test_frames_are_stamped_and_numbered_and_rate_limited(sim_camera_parts) -> None:
    floor, geom = sim_camera_parts
    sim = SimCamera(floor, geom, np.random.default_rng(0), CameraEffects.none())
    clock = SimClock()
    cam = Camera(sim.reopen, clock, config=CameraConfig(width_px=160, height_px=120, fps=15.0))
    frames = []
    for _ in range(40):  # 2 s of 20 Hz ticks
        f = cam.poll()
        if f is not None:
            frames.append(f)
        clock.advance(0.05)
    assert 29 <= len(frames) <= 31  # 15 fps, not every tick and not every other tick
    assert [f.seq for f in frames] == list(range(1, len(frames) + 1))
    assert frames[0].stamp_s == 0.0 and all(b.stamp_s > a.stamp_s for a, b in zip(frames, frames[1:]))
    assert frames[0].image.shape == (120, 160, 3) and frames[0].image.dtype == np.uint8


def test_staleness(sim_camera_parts) -> None:
    floor, geom = sim_camera_parts
    clock = SimClock()
    cam = Camera(SimCamera(floor, geom, np.random.default_rng(0)).reopen, clock, config=CameraConfig(stale_after_s=0.2))
    assert cam.is_stale(clock.now())  # no frame yet
    assert cam.poll() is not None
    assert not cam.is_stale(clock.now())
    assert not cam.is_stale(0.2) and cam.is_stale(0.21)


def test_unplugged_camera_is_reported_once_retried_and_reopened(sim_camera_parts) -> None:
    floor, geom = sim_camera_parts
    sim = SimCamera(floor, geom, np.random.default_rng(0))
    opens = []

    def open_source() -> SimCamera:
        opens.append(clock.now())
        return sim.reopen()

    clock, events = SimClock(), Events()
    cam = Camera(open_source, clock, events, CameraConfig(fps=10.0, reopen_interval_s=1.0, stale_after_s=0.3))
    assert cam.poll() is not None
    sim.unplug()
    got = []
    for _ in range(30):  # 3 s unplugged, polled at 10 Hz
        clock.advance(0.1)
        got.append(cam.poll())
    assert got == [None] * 30
    assert events.kinds() == ["camera_lost"]
    assert cam.is_stale(clock.now()) and not cam.connected
    assert len(opens) == 1 + 2  # the first open, then one attempt per reopen_interval_s after the loss at 0.1 s
    assert all(b - a >= 1.0 - 1e-9 for a, b in zip(opens[1:], opens[2:]))
    sim.replug()
    frames = []
    for _ in range(12):
        clock.advance(0.1)
        frames.append(cam.poll())
    assert events.kinds() == ["camera_lost", "camera_reopened"]
    assert cam.reopens == 1 and cam.connected
    assert sum(f is not None for f in frames) >= 2
    assert not cam.is_stale(clock.now())


def test_single_failed_reads_are_counted_without_declaring_the_camera_lost() -> None:
    clock, events = SimClock(), Events()
    src = ScriptedSource(["ok", "fail", "ok", "raise", "ok"])
    cam = Camera(lambda: src, clock, events, CameraConfig(fps=10.0, lost_after_failures=3))
    results = []
    for _ in range(5):
        results.append(cam.poll())
        clock.advance(0.1)
    assert [r is not None for r in results] == [True, False, True, False, True]
    assert cam.read_errors == 2
    assert "camera_lost" not in events.kinds() and "camera_read_error" in events.kinds()
    assert src.released == 0


def test_repeated_failed_reads_make_the_camera_lost_and_it_is_reopened() -> None:
    clock, events = SimClock(), Events()
    sources: list[ScriptedSource] = []

    def open_source() -> ScriptedSource:
        sources.append(ScriptedSource(["ok", "fail", "fail", "fail"] if not sources else []))
        return sources[-1]

    cam = Camera(open_source, clock, events, CameraConfig(fps=10.0, lost_after_failures=3, reopen_interval_s=0.5))
    for _ in range(12):
        cam.poll()
        clock.advance(0.1)
    assert events.kinds()[:2] == ["camera_lost", "camera_reopened"]
    assert sources[0].released == 1 and len(sources) == 2
    assert cam.seq >= 3 and cam.connected  # frames flow again from the new source


def test_open_that_raises_or_fails_never_escapes() -> None:
    clock, events = SimClock(), Events()
    attempts = []

    def broken() -> ScriptedSource:
        attempts.append(clock.now())
        if len(attempts) == 1:
            raise OSError("No such device")
        src = ScriptedSource([])
        src.opened = len(attempts) >= 3
        return src

    cam = Camera(broken, clock, events, CameraConfig(reopen_interval_s=1.0))
    assert cam.poll() is None
    for _ in range(25):
        clock.advance(0.1)
        cam.poll()
    assert events.kinds() == ["camera_lost", "camera_reopened"]
    assert "No such device" in events.seen[0][1]
    assert cam.seq > 0


def test_grey_frames_are_expanded_and_junk_is_refused() -> None:
    clock = SimClock()
    cam = Camera(lambda: ScriptedSource(["grey", "junk"]), clock, config=CameraConfig(fps=10.0))
    f = cam.poll()
    assert f is not None and f.image.shape == (24, 32, 3) and (f.image == 77).all()
    clock.advance(0.1)
    assert cam.poll() is None and cam.read_errors == 1


def test_missing_real_device_gives_an_unopened_capture() -> None:
    cap = open_video_capture(CameraConfig(device="/dev/video-beastbt-test-missing"))
    try:
        assert not cap.isOpened()
    finally:
        cap.release()


def test_config_from_dict_and_schema_agree() -> None:
    cfg = CameraConfig.from_dict({"device": 0, "fps": 30, "mounting": {"pitch_deg": 45}})
    assert cfg.device == 0 and cfg.fps == 30.0 and cfg.mounting.pitch_deg == 45.0 and cfg.mounting.height_m == 0.2
    with pytest.raises(ValueError, match="did you mean 'width_px'"):
        CameraConfig.from_dict({"widht_px": 640})
    with pytest.raises(ValueError, match="did you mean 'pitch_deg'"):
        CameraConfig.from_dict({"mounting": {"pich_deg": 10}})
    with pytest.raises(ValueError, match="fps"):
        CameraConfig.from_dict({"fps": 0})
    schema = json.loads((REPO / "schemas" / "parts" / "camera.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    defaults = asdict(CameraConfig())
    jsonschema.Draft202012Validator(schema).validate(defaults)
    assert set(schema["properties"]) == set(defaults)
    assert set(schema["properties"]["mounting"]["properties"]) == set(defaults["mounting"])
    for name, prop in schema["properties"].items():
        if name != "mounting":
            assert prop["default"] == defaults[name], name
    for name, prop in schema["properties"]["mounting"]["properties"].items():
        assert prop["default"] == defaults["mounting"][name], name
