"""The camera's own JPEG goes to the console untouched; only what vision needs is decoded; nobody watching, nothing
rendered (issue 26, item 1)."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from beastbt.core.clock import SimClock
from beastbt.devices.camera import Camera, CameraConfig, MjpegCapture, MjpegReplay, open_video_capture, split_jpegs
from beastbt.live.console_video import HEADER, PASSED_THROUGH
from beastbt.sim.camera_emulator import SimMjpegCamera
from beastbt.vision.camera_pipeline import CameraPipeline
from console_support import capture_reads, run_with_console

REPO = Path(__file__).resolve().parent.parent


def jpegs(n: int, width: int = 640, height: int = 480) -> list[bytes]:
    """``n`` different real JPEG frames (a bar that moves), as a camera's encoder gives them."""
    out = []
    for i in range(n):
        image = np.full((height, width, 3), 170, np.uint8)
        cv2.rectangle(image, (40 + 30 * i, 0), (80 + 30 * i, height - 1), (20, 20, 20), -1)
        out.append(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 80])[1].tobytes())
    return out


def pipeline_on(frames: list[bytes], clock: SimClock, width: int = 640, height: int = 480) -> CameraPipeline:
    config = CameraConfig(width_px=width, height_px=height, fps=10.0)
    return CameraPipeline(lambda: Camera(lambda: MjpegReplay(frames), clock, config=config), config)


def test_an_mjpeg_file_splits_into_its_frames_and_replays_through_the_driver(tmp_path: Path) -> None:
    frames = jpegs(3)
    path = tmp_path / "camera.mjpeg"
    path.write_bytes(b"".join(frames))
    assert split_jpegs(path.read_bytes()) == frames
    clock = SimClock()
    camera = Camera(lambda: open_video_capture(CameraConfig(device=str(path), fps=10.0)), clock,
                    config=CameraConfig(device=str(path), fps=10.0))
    got = []
    for _ in range(4):
        frame = camera.poll(pixels=False)
        clock.advance(0.1)
        got.append(frame)
    assert camera.compressed
    assert [f.jpeg for f in got] == frames + frames[:1]  # in order, untouched, then round again
    assert all(f.image is None for f in got)  # nothing decoded when nobody asked for pixels
    decoded = camera.decode(got[1], 2)
    assert decoded is not None and decoded.image.shape == (240, 320, 3) and decoded.jpeg == frames[1]
    with_pixels = camera.poll()
    assert with_pixels is not None and with_pixels.image.shape == (480, 640, 3)


def test_a_missing_or_empty_mjpeg_file_is_a_lost_camera_not_a_crash(tmp_path: Path) -> None:
    (tmp_path / "empty.mjpeg").write_bytes(b"no jpeg here")
    for path in (tmp_path / "empty.mjpeg", tmp_path / "missing.mjpeg"):
        events: list[str] = []
        config = CameraConfig(device=str(path))
        camera = Camera(lambda: open_video_capture(config), SimClock(), lambda kind, text: events.append(kind), config)
        assert camera.poll() is None and not camera.connected and events == ["camera_lost"]


class RawMjpegCapture:
    """What OpenCV's V4L2 backend returns with FOURCC MJPG and CONVERT_RGB 0: each frame's buffer as 1 x N bytes."""

    def __init__(self, frames: list[bytes]) -> None:
        self.frames = list(frames)

    def isOpened(self) -> bool:  # noqa: N802
        return True

    def read(self) -> tuple[bool, Any]:
        data = self.frames.pop(0)
        return True, np.frombuffer(data, np.uint8).reshape(1, -1)

    def release(self) -> None:
        pass


def test_a_v4l2_mjpeg_buffer_is_handed_over_as_the_cameras_bytes() -> None:
    frames = jpegs(2)
    capture = MjpegCapture(RawMjpegCapture(frames))
    assert capture.read_jpeg() == (True, frames[0])
    ok, image = capture.read()
    assert ok and image.shape == (480, 640, 3)


def test_only_the_console_watching_reads_jpeg_and_decodes_nothing_vision_decodes_small() -> None:
    frames = jpegs(5)
    clock = SimClock()
    pipeline = pipeline_on(frames, clock)
    pipeline.enable("console", pixels=False)
    for _ in range(5):
        assert pipeline.poll(clock.now()) == []  # no frame for the blackboard: nobody needs pixels
        clock.advance(0.1)
    assert pipeline.jpeg_frames == 5 and pipeline.decoded == 0 and pipeline.frames == 0
    assert pipeline.latest_jpeg is not None and pipeline.latest_jpeg.jpeg == frames[4]
    pipeline.enable("follow_line")  # the line detector works 320 wide: a 640-wide JPEG is decoded at half size
    readings = pipeline.poll(clock.now())
    assert pipeline.decoded == 1 and len(readings) == 2
    assert readings[0].image.shape == (240, 320, 3) and readings[0].jpeg == frames[0]
    assert readings[1].seen  # the detector found the bar in the decoded frame
    pipeline.enable("recording", max_rate_hz=2.0, lines=False)  # a recording keeps whole pictures
    clock.advance(0.1)
    assert pipeline.poll(clock.now())[0].image.shape == (480, 640, 3)
    pipeline.disable("console")
    pipeline.disable("follow_line")
    pipeline.disable("recording")
    read = pipeline.jpeg_frames
    clock.advance(1.0)
    assert pipeline.poll(clock.now()) == [] and pipeline.jpeg_frames == read  # no reason left: not read at all


def test_vision_decodes_only_at_the_rate_it_needs() -> None:
    clock = SimClock()
    pipeline = pipeline_on(jpegs(3), clock)
    pipeline.enable("console", pixels=False)
    pipeline.enable("recording", max_rate_hz=2.0, lines=False)
    for _ in range(20):  # 2 s of a 10 fps camera
        pipeline.poll(clock.now())
        clock.advance(0.1)
    assert pipeline.jpeg_frames == 20  # the console got every frame
    assert pipeline.decoded == 4  # the recording's 2 a second, nothing more


# -- end to end: a run with the console, in this process ------------------------------------------------

def mjpeg_profile(folder: Path, fmt: str = "mjpeg") -> Path:
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    assert "  device: sim\n" in text
    path = folder / f"sim_{fmt}.yaml"
    path.write_text(text.replace("  device: sim\n", f"  device: sim\n  format: {fmt}\n"), encoding="utf-8")
    return path


def test_jpeg_from_the_fake_mjpeg_camera_arrives_at_api_video_byte_identical(tmp_path: Path,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    made = capture_reads(monkeypatch, SimMjpegCamera, "read_jpeg")
    # The run lasts until the viewer has had 8 pictures (about half a second of the camera's 15 a second), however
    # long a loaded machine takes to start the camera and the console's process: not a fixed wall-clock time.
    prepared, messages = run_with_console(tmp_path, mjpeg_profile(tmp_path), "mission: m\nsteps:\n  - wait: 60 s\n",
                                          "realtime", True, max_time_s=90.0, until=lambda got: len(got) >= 8)
    assert len(messages) >= 8
    pipeline = prepared.run.io.camera
    for message in messages:
        _, _, quality, overlay_length = HEADER.unpack_from(message)
        assert quality == PASSED_THROUGH
        assert message[HEADER.size + overlay_length:] in made  # the camera's bytes, not a re-encoding of them
    assert pipeline.decoded == 0 and pipeline.frames == 0  # the console alone: nothing decoded in the run
    assert len(made) == pipeline.jpeg_frames <= 15 * prepared.run.elapsed_s + 2  # the camera's rate, not the loop's (50 Hz)


@pytest.mark.parametrize("fmt", ["mjpeg", "raw"])
def test_nobody_watching_and_no_vision_the_simulator_renders_no_frame(tmp_path: Path, fmt: str) -> None:
    prepared, _ = run_with_console(tmp_path, mjpeg_profile(tmp_path, fmt), "mission: m\nsteps:\n  - wait: 20 s\n",
                                   "max", False)
    io_ = prepared.run.io
    assert io_.camera is not None and not io_.camera.enabled
    assert io_.sim_camera is None or io_.sim_camera.frames_rendered == 0
    assert io_.camera.jpeg_frames == 0 and io_.camera.frames == 0


def test_the_overlay_goes_with_the_frame_for_the_page_to_draw(tmp_path: Path) -> None:
    import json
    mission = (REPO / "missions" / "line_to_intersection.yaml").read_text(encoding="utf-8")
    mission = mission.replace("world: ", f"world: {REPO / 'missions'}/").replace(f"{REPO / 'missions'}/../",
                                                                               f"{REPO}/")
    prepared, messages = run_with_console(tmp_path, mjpeg_profile(tmp_path), mission, "max", True)
    assert messages
    overlays = []
    for message in messages:
        _, _, quality, n = HEADER.unpack_from(message)
        assert quality == PASSED_THROUGH
        overlays.append(json.loads(message[HEADER.size:HEADER.size + n]))
    assert all(o["caption"][0].startswith(prepared.run.mission.name) for o in overlays)
    seen = [o for o in overlays if "line" in o]
    assert seen, "the detected line goes with the frames while follow_line runs"
    assert all(0.0 <= u <= 1.0 and 0.0 <= v <= 1.0 for o in seen for u, v in o["line"])
    pipeline = prepared.run.io.camera
    assert pipeline.decoded > 0  # vision decoded its frames (the same JPEG the console passed on)


class PixelSource:
    """A camera that gives pixels (a V4L2 camera without MJPEG, a Pi camera)."""

    def isOpened(self) -> bool:  # noqa: N802
        return True

    def read(self) -> tuple[bool, Any]:
        return True, np.full((240, 320, 3), 90, np.uint8)

    def release(self) -> None:
        pass


def test_frames_read_for_a_viewer_alone_are_not_the_runs_readings_nor_looked_at() -> None:
    clock = SimClock()
    config = CameraConfig(fps=10.0)
    pipeline = CameraPipeline(lambda: Camera(PixelSource, clock, config=config), config)
    pipeline.enable("console", pixels=False)
    assert pipeline.poll(clock.now()) == []
    assert pipeline.latest is not None and pipeline.latest[1] is None  # the viewer's frame, no detection
    assert pipeline.latest_jpeg is None and pipeline.frames == 0
    pipeline.enable("recording", max_rate_hz=2.0, lines=False)
    clock.advance(0.1)
    readings = pipeline.poll(clock.now())
    assert len(readings) == 1 and pipeline.latest[1] is None  # the recording's picture; the detector stayed idle


def test_the_recording_keeps_the_cameras_own_jpeg(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import base64

    from beastbt.cli import main
    from beastbt.recording.reader import read_recording
    made = capture_reads(monkeypatch, SimMjpegCamera, "read_jpeg")
    code = main(["run", str(REPO / "missions" / "patrol.yaml"), "--robot", str(mjpeg_profile(tmp_path)), "--sim",
                 "--max-time", "3 s", "--runs-dir", str(tmp_path / "runs"), "--record-images", "2"])
    assert code == 1  # stopped by --max-time, as asked
    [folder] = list((tmp_path / "runs").iterdir())
    images = read_recording(folder / "run.mcap").messages.get("/camera/image", [])
    assert len(images) == 7
    assert all(base64.b64decode(m["data"]) in made for _, m in images)  # as the camera gave them, not re-encoded


def test_the_simulated_camera_renders_only_while_a_vision_step_runs(tmp_path: Path) -> None:
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    mission = tmp_path / "m.yaml"
    mission.write_text(f"mission: follow_then_wait\nworld: {REPO / 'worlds' / 'line_track.yaml'}\nsteps:\n"
                       "  - follow_line: {speed: 0.12 m/s, until: {distance: 0.3 m}}\n  - wait: 10 s\n",
                       encoding="utf-8")
    with contextlib.redirect_stdout(io.StringIO()):
        prepared = prepare(str(mission), RunOptions(record=False))
    summary = execute(prepared, out=io.StringIO())
    assert summary["status"] == "success"
    rendered = prepared.run.io.sim_camera.frames_rendered
    fps = prepared.run.io.camera.config.fps
    # Frames for the follow_line step only (the run minus its 10 s wait), none while it waited.
    assert 0 < rendered <= fps * (summary["sim_time_s"] - 10.0) + 5
    assert not prepared.run.io.camera.enabled


def test_a_pi_camera_with_format_mjpeg_hands_over_the_hardware_encoders_jpeg(monkeypatch: pytest.MonkeyPatch) -> None:
    """picamera2 is on a Pi only: a stand-in with its API checks the glue (MJPEGEncoder into an output we read)."""
    import sys
    import types

    from beastbt.devices.camera import Picamera2Capture
    calls: list[Any] = []

    class FakePicamera2:
        def create_video_configuration(self, main: dict, **kw: Any) -> dict:
            return {"main": main, **kw}

        def configure(self, config: dict) -> None:
            calls.append(("configure", config["main"]["format"]))

        def start_recording(self, encoder: Any, output: Any) -> None:
            calls.append(("start_recording", type(encoder).__name__))
            self.output = output.fileoutput

        def stop_recording(self) -> None:
            calls.append(("stop_recording",))

        def close(self) -> None:
            calls.append(("close",))

    camera = FakePicamera2()
    fake = types.ModuleType("picamera2")
    fake.Picamera2 = lambda: camera  # type: ignore[attr-defined]
    encoders = types.ModuleType("picamera2.encoders")
    encoders.MJPEGEncoder = type("MJPEGEncoder", (), {})  # type: ignore[attr-defined]
    outputs = types.ModuleType("picamera2.outputs")
    outputs.FileOutput = lambda f: types.SimpleNamespace(fileoutput=f)  # type: ignore[attr-defined]
    for name, module in (("picamera2", fake), ("picamera2.encoders", encoders), ("picamera2.outputs", outputs)):
        monkeypatch.setitem(sys.modules, name, module)
    frames = jpegs(2, 320, 240)
    capture = Picamera2Capture(CameraConfig(format="mjpeg", fps=30.0))
    assert calls == [("configure", "YUV420"), ("start_recording", "MJPEGEncoder")] and capture.compressed
    assert capture.read_jpeg() == (False, None)  # nothing encoded yet: no frame, after two frame periods
    camera.output.write(frames[0])
    camera.output.write(frames[1])
    assert capture.read_jpeg() == (True, frames[1])  # the newest, untouched
    assert capture.read_jpeg() == (False, None)  # not the same frame twice
    capture.release()
    assert calls[-2:] == [("stop_recording",), ("close",)]
