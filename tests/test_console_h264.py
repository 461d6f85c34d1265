"""H.264 in the console's video (issue 26, item 1): the hardware encoder when there is one, JPEG elsewhere; a
camera's own H.264 passed to the viewers untouched; a new viewer starts at a keyframe; a page that says nothing
gets JPEG as before."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from console_support import capture_reads, run_with_console
from beastbt.live.console_video import H264_DELTA, H264_KEY, HEADER, ConsoleVideo, VideoConfig
from beastbt.devices.h264 import (HARDWARE_DEVICE, HARDWARE_ENCODER, ParameterSets, avc1_codec, encoder_available,
                               is_keyframe, nal_units, resolve_codec, split_access_units)

REPO = Path(__file__).resolve().parent.parent
av = pytest.importorskip("av", reason="PyAV is not installed (pip install -e '.[video]')")
SOFTWARE = next((name for name in ("libx264", "libopenh264") if encoder_available(name)[0]), None)
needs_software = pytest.mark.skipif(SOFTWARE is None, reason="this PyAV wheel has no software H.264 encoder")


def picture(i: int, width: int = 320, height: int = 240) -> np.ndarray:
    """A frame with a bar that moves (so that every delta unit differs)."""
    image = np.full((height, width, 3), 150, np.uint8)
    x = (12 * i) % (width - 20)
    image[:, x:x + 20] = (30, 60, 200)
    return image


def encoded_stream(n: int, gop: int = 5) -> list[bytes]:
    """``n`` access units from the software encoder, a keyframe every ``gop`` (as a camera's encoder gives them)."""
    from beastbt.devices.h264 import H264Encoder
    encoder = H264Encoder(SOFTWARE or "libx264", 500_000, 10.0)
    units = []
    for i in range(n):
        if i % gop == 0 and i:
            encoder.request_keyframe()
        units += [unit for unit, _ in encoder.encode(picture(i))]
    encoder.close()
    return units


def video(**config: Any) -> ConsoleVideo:
    clock = [0.0]

    def wall() -> float:
        clock[0] += 0.001
        return clock[0]
    return ConsoleVideo(VideoConfig(**config), wall, lambda: 1_700_000_000.0, lambda: ["running"])


def take(feed: Any, count: int = 50) -> list[bytes]:
    out = []
    for _ in range(count):
        message = feed.next_message(0.0)
        if message is not None:
            out.append(message)
    return out


def payload(message: bytes) -> tuple[int, bytes]:
    _, _, quality, overlay_length = HEADER.unpack_from(message)
    return quality, message[HEADER.size + overlay_length:]


# -- which codec ----------------------------------------------------------------------------------------------

@pytest.mark.skipif(os.path.exists(HARDWARE_DEVICE), reason=f"this machine has {HARDWARE_DEVICE}")
def test_auto_is_jpeg_on_a_machine_without_the_hardware_encoder() -> None:
    ok, why = encoder_available(HARDWARE_ENCODER)
    assert not ok and HARDWARE_DEVICE in why
    assert resolve_codec("auto") == ("jpeg", why)
    assert resolve_codec("jpeg")[0] == "jpeg"
    with pytest.raises(ValueError, match="h264 needs the H.264 encoder h264_v4l2m2m"):
        resolve_codec("h264")
    v = video().start()
    try:
        assert v.codec == "jpeg" and not v.h264_active
    finally:
        v.close()


@needs_software
def test_auto_is_h264_where_the_encoder_opens() -> None:
    # The rule itself, with the software encoder standing in for the hardware one (never a default).
    assert resolve_codec("auto", SOFTWARE) == ("h264", f"{SOFTWARE} is present")


@pytest.mark.skipif(os.path.exists(HARDWARE_DEVICE), reason=f"this machine has {HARDWARE_DEVICE}")
def test_h264_asked_for_without_the_encoder_stops_the_run_at_its_key(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture) -> None:
    from beastbt.cli import main
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    profile = tmp_path / "robot.yaml"
    profile.write_text(text.replace("  device: sim\n", "  device: sim\n  console_codec: h264\n"), encoding="utf-8")
    line = profile.read_text(encoding="utf-8").splitlines().index("  console_codec: h264") + 1
    code = main(["run", str(REPO / "missions" / "patrol.yaml"), "--robot", str(profile), "--sim", "--console", "0",
                 "--max-time", "1 s", "--runs-dir", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{profile}:{line}:" in err and "console_codec" in err and "/dev/video11" in err
    assert "Traceback" not in err


# -- Annex B --------------------------------------------------------------------------------------------------

@needs_software
def test_an_h264_stream_splits_into_the_encoders_access_units() -> None:
    units = encoded_stream(12, gop=5)
    assert split_access_units(b"".join(units)) == units
    assert [is_keyframe(u) for u in units] == [i % 5 == 0 for i in range(12)]
    codec = avc1_codec(units[0])
    assert codec is not None and codec.startswith("avc1.") and len(codec) == 11
    assert avc1_codec(units[1]) is None  # a delta unit has no SPS


def test_a_keyframe_without_parameter_sets_gets_the_last_ones() -> None:
    sps, pps, idr, slice_ = b"\x67\x42\xc0\x1e\xaa", b"\x68\xce\x3c\x80", b"\x65\x88\x84", b"\x41\x9a\x02"
    sets = ParameterSets()
    first = b"\x00\x00\x00\x01" + sps + b"\x00\x00\x00\x01" + pps + b"\x00\x00\x00\x01" + idr
    assert sets.complete(first) == first
    assert sets.complete(b"\x00\x00\x01" + slice_) == b"\x00\x00\x01" + slice_  # a delta unit: as it came
    later = sets.complete(b"\x00\x00\x00\x01" + idr)
    assert nal_units(later) == [sps, pps, idr]


# -- the viewers ----------------------------------------------------------------------------------------------

@needs_software
def test_a_cameras_h264_reaches_an_h264_viewer_byte_identical_from_a_keyframe(tmp_path: Path) -> None:
    from beastbt.devices.camera import H264Replay
    stream = tmp_path / "camera.h264"
    stream.write_bytes(b"".join(encoded_stream(15, gop=5)))
    replay = H264Replay.from_file(str(stream))
    v = video()
    first = v.feed()
    first.hello(json.dumps({"accept": ["h264", "jpeg"]}))
    sent, got = [], []
    for i in range(12):
        ok, unit = replay.read_h264()
        assert ok
        sent.append(unit)
        v.pass_h264(unit, is_keyframe(unit), None, None, 0.25, 1_700_000_000.0 + i / 10)
        got += take(first, 2)
        if i == 7:  # a second viewer joins: it starts at the newest keyframe the console still holds (unit 5)
            later = v.feed()
            later.hello(json.dumps({"accept": ["h264", "jpeg"]}))
    got_later = take(later)
    v.close()
    expected = [(H264_KEY if i % 5 == 0 else H264_DELTA, sent[i]) for i in range(12)]
    assert [payload(m) for m in got] == expected
    assert [payload(m) for m in got_later] == expected[5:]


@needs_software
def test_a_viewer_over_its_budget_waits_for_the_next_keyframe_and_asks_for_one() -> None:
    v = video(codec="h264", h264_encoder=SOFTWARE, fps=10.0)
    v.codec = resolve_codec("h264", SOFTWARE)[0]  # no thread: frames are handed in here, one by one
    feed = v.feed()
    feed.hello(json.dumps({"accept": ["h264", "jpeg"]}))
    got: list[bytes] = []
    for i in range(6):
        v._send((picture(i), None, None, 0.25, 1_700_000_000.0), i + 1)  # noqa: SLF001 - the video thread's step
        if i == 2:
            feed.guard.budget_bytes = 0  # the next unit does not fit: the ones after it would not decode
        if i == 3:
            feed.guard.budget_bytes = 1e9
        got += take(feed, 3)
    kinds = [payload(m)[0] for m in got]
    assert kinds[0] == H264_KEY  # the first frame a viewer gets decodes alone
    assert kinds.count(H264_KEY) == 2 and kinds[kinds.index(H264_KEY, 1) - 1] == H264_DELTA
    assert feed.skipped >= 1 and len(got) < 6  # what it missed was skipped, then a keyframe was made for it


@needs_software
def test_a_page_that_says_nothing_gets_jpeg_and_one_that_decodes_h264_gets_h264() -> None:
    v = video(codec="h264", h264_encoder=SOFTWARE, fps=10.0)
    v.codec = resolve_codec("h264", SOFTWARE)[0]  # no thread: frames are handed in here, one by one
    old_page, new_page = v.feed(), v.feed()
    new_page.hello('{"accept": ["h264", "jpeg"]}')
    for i in range(3):
        v._send((picture(i), None, None, 0.25, 1_700_000_000.0), i + 1)  # noqa: SLF001
    old = take(old_page, 3)
    new = take(new_page, 5)
    assert old and all(payload(m)[1][:2] == b"\xff\xd8" and 20 <= payload(m)[0] <= 90 for m in old)
    assert [payload(m)[0] for m in new] == [H264_KEY, H264_DELTA, H264_DELTA]
    assert v.frames_h264 == 3 and v.frames_encoded >= 1
    new_page.hello('{"accept": ["jpeg"], "why": "no WebCodecs"}')  # the page found it cannot decode after all
    v._send((picture(3), None, None, 0.25, 1_700_000_000.0), 4)  # noqa: SLF001
    assert new_page.codec == "jpeg" and new_page.why_not_h264 == "no WebCodecs"
    assert payload(take(new_page, 1)[0])[1][:2] == b"\xff\xd8"


# -- end to end: the simulator's fake H.264 camera through the run and the console's process ---------------------

@needs_software
def test_the_fake_h264_cameras_units_arrive_at_api_video_byte_identical(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    from beastbt.devices.camera import EncodingH264Camera
    made = capture_reads(monkeypatch, EncodingH264Camera, "read_h264")
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    profile = tmp_path / "robot.yaml"
    profile.write_text(text.replace("  device: sim\n", "  device: sim\n  format: h264\n"), encoding="utf-8")

    def h264_units(messages: list) -> list[tuple[int, bytes]]:
        return [payload(m) for m in messages if payload(m)[0] in (H264_KEY, H264_DELTA)]

    def two_keyframes(messages: list) -> bool:
        return sum(q == H264_KEY for q, _ in h264_units(messages)) >= 2

    # The run lasts until the viewer has had two keyframes (a second of the camera's 15 units a second, a keyframe
    # a second, from the first keyframe on), however long a loaded machine takes to start the camera, the encoder
    # and the console's process: not a fixed two seconds of mission that a slow start may spend before the first.
    prepared, messages = run_with_console(tmp_path, profile, "mission: m\nsteps:\n  - wait: 60 s\n", "realtime",
                                          True, accept=["h264", "jpeg"], max_time_s=90.0, until=two_keyframes)
    units = h264_units(messages)
    assert len(units) >= 16 and two_keyframes(messages)  # a whole group of pictures and the next keyframe
    assert units[0][0] == H264_KEY and all((q == H264_KEY) == is_keyframe(u) for q, u in units)
    start = made.index(units[0][1])
    assert [u for _, u in units] == made[start:start + len(units)]  # every unit, in order, as the camera gave it
    assert prepared.run.io.camera.decoded == 0  # nothing decoded in the run for the console


# -- the camera driver with an H.264 camera -----------------------------------------------------------------------

@needs_software
def test_the_driver_hands_over_units_untouched_and_decodes_only_in_order(tmp_path: Path) -> None:
    from beastbt.core.clock import SimClock
    from beastbt.devices.camera import Camera, CameraConfig, open_video_capture
    units = encoded_stream(8, gop=4)
    path = tmp_path / "camera.h264"
    path.write_bytes(b"".join(units))
    config = CameraConfig(device=str(path), fps=10.0)
    clock = SimClock()
    camera = Camera(lambda: open_video_capture(config), clock, config=config)
    frames = []
    for _ in range(3):
        frames.append(camera.poll(pixels=False))
        clock.advance(0.1)
    assert camera.h264 and [f.h264 for f in frames] == units[:3] and all(f.image is None for f in frames)
    assert camera.decode(frames[2]) is None  # units 0 and 1 were never decoded: no right picture for unit 2
    assert camera.read_errors == 1
    later = []
    for _ in range(3):  # units 3, 4 (a keyframe), 5: from here on every unit is decoded as it is read
        later.append(camera.poll(pixels=False))
        clock.advance(0.1)
    assert later[0].image is None and later[1].image is not None and later[2].image is not None
    assert later[2].image.shape == (240, 320, 3) and later[2].h264 == units[5]
    assert camera.decode(later[2]) is later[2]  # already decoded


def test_a_pi_camera_with_format_h264_hands_over_the_hardware_encoders_units(monkeypatch: pytest.MonkeyPatch) -> None:
    """picamera2 is on a Pi only: a stand-in with its API checks the glue (H264Encoder with SPS/PPS on every
    keyframe, into an output that keeps every unit in order)."""
    import sys
    import types

    from beastbt.devices.camera import CameraConfig, Picamera2Capture
    calls: list[Any] = []

    class FakePicamera2:
        def create_video_configuration(self, main: dict, **kw: Any) -> dict:
            return {"main": main, **kw}

        def configure(self, config: dict) -> None:
            calls.append(("configure", config["main"]["format"]))

        def start_recording(self, encoder: Any, output: Any) -> None:
            calls.append(("start_recording", type(encoder).__name__, encoder.kw))
            self.output = output.fileoutput

        def stop_recording(self) -> None:
            calls.append(("stop_recording",))

        def close(self) -> None:
            calls.append(("close",))

    class H264Encoder:
        def __init__(self, **kw: Any) -> None:
            self.kw = kw

    camera = FakePicamera2()
    fake = types.ModuleType("picamera2")
    fake.Picamera2 = lambda: camera  # type: ignore[attr-defined]
    encoders = types.ModuleType("picamera2.encoders")
    encoders.H264Encoder = H264Encoder  # type: ignore[attr-defined]
    outputs = types.ModuleType("picamera2.outputs")
    outputs.FileOutput = lambda f: types.SimpleNamespace(fileoutput=f)  # type: ignore[attr-defined]
    for name, module in (("picamera2", fake), ("picamera2.encoders", encoders), ("picamera2.outputs", outputs)):
        monkeypatch.setitem(sys.modules, name, module)
    capture = Picamera2Capture(CameraConfig(format="h264", fps=30.0))
    assert calls[0] == ("configure", "YUV420") and calls[1][:2] == ("start_recording", "H264Encoder")
    assert calls[1][2]["repeat"] is True and calls[1][2]["iperiod"] == 30  # SPS/PPS with a keyframe every second
    assert capture.compressed and capture.read_h264() == (False, None)  # nothing encoded yet
    units = [b"\x00\x00\x00\x01\x67unit%d" % i for i in range(3)]
    for unit in units:
        camera.output.write(unit)
    assert [capture.read_h264() for _ in range(3)] == [(True, u) for u in units]  # every one, in order, untouched
    assert capture.read_h264() == (False, None)
    capture.release()
    assert calls[-2:] == [("stop_recording",), ("close",)]


@needs_software
def test_vision_on_an_h264_camera_gets_every_frame_it_asks_for(tmp_path: Path) -> None:
    from beastbt.core.clock import SimClock
    from beastbt.devices.camera import Camera, CameraConfig, H264Replay
    from beastbt.vision.camera_pipeline import CameraPipeline
    units = encoded_stream(10, gop=10)
    clock = SimClock()
    config = CameraConfig(fps=10.0)
    pipeline = CameraPipeline(lambda: Camera(lambda: H264Replay(units), clock, config=config), config, detect=False)
    pipeline.enable("console", pixels=False)
    pipeline.enable("recording", max_rate_hz=5.0, lines=False)
    got = []
    for _ in range(10):
        got += pipeline.poll(clock.now())
        clock.advance(0.1)
    assert len(got) == 5 and all(f.image is not None for f in got)  # the recording's 5 a second, each decoded
    assert pipeline.camera.read_errors == 0
    assert [f.h264 for f in pipeline.h264_units] == units  # and every unit for the console, untouched


@needs_software
def test_after_a_unit_lost_on_the_way_the_console_sends_nothing_until_the_next_keyframe() -> None:
    units = encoded_stream(10, gop=5)
    v = video()
    feed = v.feed()
    feed.hello('{"accept": ["h264"]}')
    got: list[bytes] = []
    for seq, unit in enumerate(units, 1):
        if seq == 3:
            continue  # dropped between the run and the console's process (the pipe was full)
        v.pass_h264(unit, is_keyframe(unit), None, None, 0.25, 1_700_000_000.0, camera_seq=seq)
        got += [payload(m)[1] for m in take(feed, 2)]
    v.close()
    assert got == units[:2] + units[5:] and v.units_dropped == 2  # units 4 and 5 (seq) needed the lost one


def test_format_h264_on_the_simulator_without_a_software_encoder_stops_at_its_key(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    import beastbt.devices.h264 as h264
    from beastbt.cli import main
    monkeypatch.setattr(h264, "software_encoder", lambda: None)  # a PyAV wheel without libx264 or libopenh264
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    profile = tmp_path / "robot.yaml"
    profile.write_text(text.replace("  device: sim\n", "  device: sim\n  format: h264\n"), encoding="utf-8")
    line = profile.read_text(encoding="utf-8").splitlines().index("  format: h264") + 1
    code = main(["run", str(REPO / "missions" / "patrol.yaml"), "--robot", str(profile), "--sim",
                 "--max-time", "1 s", "--runs-dir", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert code == 2 and f"{profile}:{line}:" in err and "software H.264 encoder" in err and "Traceback" not in err
