"""The recording's two halves apart: the wire between them, the writer process, and the recorder when the
writer fails. (The channels of whole runs are in test_recording_channels.py.)"""

from __future__ import annotations

import dataclasses
import io
import os
import signal
import time

import numpy as np
import pytest

from beastbt.blackboard.types import FusedPose, GpsFix, ImuSample, ServoCommand, VelocityCommand
from beastbt.core.events import Event
from beastbt.recording.recorder import McapRecorder, RecordingConfig
from beastbt.recording.reader import read_recording
from beastbt.recording.wire import Frame, ItemDecoder, ItemEncoder
from beastbt.recording.writer import CUT_REASON, reading_sources, serve


@dataclasses.dataclass(frozen=True, slots=True)
class Slotted:
    stamp_s: float
    value: float


def _tick(k: int, readings: list) -> tuple:
    t = 0.05 * k
    pose = FusedPose(t, 1.0 + k, 2.0, 0.1, covariance=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.1)))
    cmd = VelocityCommand(0.2, 0.0, t, "mission")
    return ("tick", k, t, readings, None, pose, cmd, cmd, cmd, "mission", [("drive", "RUNNING", "", "0")], None,
            (True, (("base", len(readings)),)))


def _round_trip(items: list[tuple], chunk: int = 7) -> list[tuple]:
    """Encode in two batches, feed the bytes to a decoder a few at a time (as a pipe may deliver them)."""
    enc, dec = ItemEncoder(), ItemDecoder()
    data = enc.encode(items[:1]) + enc.encode(items[1:])
    out: list[tuple] = []
    for i in range(0, len(data), chunk):
        out.extend(dec.feed(data[i:i + chunk]))
    assert dec.pending_bytes == 0
    return out


def test_the_wire_gives_back_equal_items_of_the_same_types():
    gps = GpsFix(0.1, 40.0, -3.0, 650.0, 1, 8, 0.9, None, None, "120000.00")
    imu = ImuSample(0.1, (0.0, 0.0, np.float64(0.01)), (0.0, 0.0, 9.81))  # a numpy scalar stays one
    image = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    items = [("event", 0.0, "say", "hello"),
             _tick(1, [gps, imu, Frame(0.1, 4, 3, 2, image), Frame(0.15, 5, 3, 2, None)]),
             ("servo", 0.2, ServoCommand("pan", 0.5, stamp_s=0.2)),
             ("flag", 2, 0.1, "imu_driver", "bias_ready", True)]
    back = _round_trip(items)
    assert back[0] == items[0] and back[2] == items[2] and back[3] == items[3]
    tick = back[1]
    assert tick[:3] == items[1][:3] and tick[5:] == items[1][5:]
    got_gps, got_imu, frame, bare = tick[3]
    assert got_gps == gps and type(got_gps) is GpsFix
    assert type(got_imu.gyro_rps[2]) is np.float64 and got_imu == imu
    assert type(frame) is Frame and np.array_equal(frame.image, image) and bare.image is None


def test_classes_the_writer_cannot_import_and_slotted_ones_still_arrive():
    @dataclasses.dataclass(frozen=True)
    class Thermometer:  # defined in a function: no importable name
        stamp_s: float
        temperature_c: float

    local, slotted = _round_trip([_tick(1, [Thermometer(0.05, 21.5)]), _tick(2, [Slotted(0.1, 3.0)])])
    stand_in = local[3][0]
    assert type(stand_in).__name__ == "Thermometer" and dataclasses.asdict(stand_in) == {
        "stamp_s": 0.05, "temperature_c": 21.5}
    assert slotted[3][0] == Slotted(0.1, 3.0)  # no __dict__: the batch went as a plain pickle


def test_reading_sources_follow_the_polls_and_admit_the_untagged_base():
    assert reading_sources(True, (("base", 2), ("gps", 1)), 3) == ["base", "base", "gps"]
    assert reading_sources(False, (("gps", 1),), 3) == ["base", "base", "gps"]  # the base polls first
    assert reading_sources(True, (("gps", 1),), 3) is None  # they do not add up
    assert reading_sources(True, (), 2) is None


def _serve(tmp_path, items: list[tuple], cut_after: int = 0) -> tuple[list[dict], int]:
    enc = ItemEncoder()
    data = enc.encode(items)
    if cut_after:
        data = data[:cut_after]
    replies: list[dict] = []
    code = serve(io.BytesIO(data).read, replies.append)
    return replies, code


def _open(tmp_path, name: str = "w.mcap") -> tuple:
    return ("open", [str(tmp_path / name)], dataclasses.asdict(RecordingConfig()), {"mission": "m"}, [])


def test_the_writer_answers_stop_and_finish_and_closes_a_cut_run_properly(tmp_path):
    ticks = [_tick(k, [GpsFix(0.05 * k, 40.0, -3.0, 650.0, 1, 8, 0.9, None, None, "")]) for k in range(30)]
    replies, code = _serve(tmp_path, [_open(tmp_path)] + ticks + [("stop",), ("finish", '{"status": "success"}')])
    assert code == 0 and len(replies) == 2 and replies[0]["messages"] == replies[1]["messages"] > 0
    whole = read_recording(tmp_path / "w.mcap")
    assert whole.complete and whole.summary == {"status": "success"} and "beastbt.cut" not in whole.metadata
    assert [m["tick"] for m in whole.topic("/cmd/gate")] == list(range(30))
    # The run's process died: the pipe ends without stop or finish. The file is still closed properly.
    replies, code = _serve(tmp_path, [_open(tmp_path, "cut.mcap")] + ticks)
    cut = read_recording(tmp_path / "cut.mcap")
    assert code == 1 and replies == [] and cut.complete and cut.summary is None
    assert cut.metadata["beastbt.cut"]["reason"] == CUT_REASON and len(cut.topic("/cmd/gate")) == 30


def test_the_writer_reports_a_file_it_cannot_open(tmp_path):
    blocked = tmp_path / "a_file"
    blocked.write_text("not a folder")
    bad_open = ("open", [str(blocked / "run.mcap")], dataclasses.asdict(RecordingConfig()), {}, [])
    replies, code = _serve(tmp_path, [bad_open, _tick(0, []), ("stop",), ("finish", None)])
    assert code == 1 and "could not open the recording" in replies[-1]["error"]
    # The tick's would-be messages: fused pose twice (beastbt and Foxglove), /tf, mission, mux, gate, tree.
    assert replies[-1]["messages"] == 0 and replies[-1]["dropped"] == 7


def test_a_writer_process_that_dies_loses_messages_but_never_the_run(tmp_path):
    rec = McapRecorder([tmp_path / "x.mcap"], RecordingConfig(send_interval_s=0.0, overflow="drop"))
    rec.on_event(Event(0.0, "say", "before"))
    rec.start()
    deadline = time.monotonic() + 20
    while not (tmp_path / "x.mcap").exists() and time.monotonic() < deadline:
        time.sleep(0.02)  # the writer has opened the file
    os.kill(rec._proc.pid, signal.SIGKILL)
    rec._proc.wait()
    for k in range(20):  # the loop goes on; each item is counted, none raises
        rec.on_event(Event(0.1 * k, "say", f"after {k}"))
    rec.finish({"status": "success"})
    assert rec.error and "writer" in rec.error
    assert rec.dropped >= 2 * 19  # /events and /log of (nearly) every event after the kill


def test_the_recording_config_rejects_a_negative_send_interval():
    with pytest.raises(ValueError, match="send_interval_s"):
        RecordingConfig(send_interval_s=-1.0)


def test_a_writer_process_that_cannot_start_leaves_the_run_whole(tmp_path, monkeypatch):
    import sys

    from recording_support import PATROL, record_run
    monkeypatch.setattr(sys, "executable", str(tmp_path / "no-python-here"))
    folder, summary = record_run(PATROL, tmp_path / "runs", seed=1, max_time_s=3.0)
    assert summary["status"] == "stopped" and summary["ticks"] == 61  # the run went its whole way
    assert "could not start the writer process" in summary["recording"]["error"]
    assert summary["recording"]["messages"] == 0 and summary["recording"]["dropped"] > 61 * 5
    assert (folder / "summary.json").exists() and (folder / "events.log").exists()


def test_messages_are_strict_json_even_when_a_value_is_not_a_number():
    import json

    from beastbt.recording.writer import encode_json
    text = encode_json({"x": float("nan"), "cov": [[1.0, float("inf")], [np.float64("-inf"), 2.0]],
                        "text": "NaN is kept in a string", "n": 3})
    # Foxglove parses JSON the way browsers do: no NaN, no Infinity.
    assert json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in {text!r}")) == {
        "x": None, "cov": [[1.0, None], [None, 2.0]], "text": "NaN is kept in a string", "n": 3}
    assert encode_json({"x": 1.5}) == b'{"x":1.5}'


def test_arrays_cross_the_wire_as_raw_bytes_with_their_dtype_shape_and_values():
    from beastbt.blackboard.types import LaserScan
    angles = np.linspace(0.0, -3.0, 5)
    ranges = np.array([1.0, np.nan, 2.5, np.inf, 0.001])
    scan = LaserScan(0.1, angles, ranges, np.arange(5, dtype=np.uint8), 10.0, "ld19")
    pixels = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)[:, ::2]  # not contiguous: sent as its values
    enc = ItemEncoder()
    flat = enc._flatten(_tick(1, [scan]))
    assert len(flat[3][0]) == 3 and flat[3][0][1]["ranges_m"] is None  # raw bytes, not numpy's pickling
    back = _round_trip([_tick(1, [scan, Frame(0.1, 4, 2, 2, pixels), Frame(0.15, 5, 2, 2, None)])])[0][3]
    got, frame, bare = back
    assert type(got) is LaserScan and got.stamp_s == 0.1 and got.model == "ld19" and got.scan_rate_hz == 10.0
    for mine, theirs in ((angles, got.angles_rad), (ranges, got.ranges_m), (scan.intensities, got.intensities),
                         (pixels, frame.image)):
        assert theirs.dtype == mine.dtype and theirs.shape == mine.shape
        assert np.array_equal(theirs, mine, equal_nan=True)
    assert bare.image is None and bare.seq == 5


def test_the_faster_mcap_message_writer_writes_the_same_bytes_as_mcaps_own():
    from mcap.writer import CompressionType, Writer

    from beastbt.recording.writer import mcap_writer_class

    def write(cls: type, chunk_size: int) -> bytes:
        out = io.BytesIO()
        w = cls(out, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        w.start(profile="beastbt", library="test")
        sid = w.register_schema(name="s", encoding="jsonschema", data=b"{}")
        channels = [w.register_channel(topic=f"/c{i}", message_encoding="json", schema_id=sid) for i in range(3)]
        for k in range(300):
            # out of order now and then (a late event), several channels, sizes that close chunks midway
            t = 1_000_000 * k - (5_000_000 if k % 37 == 5 else 0)
            w.add_message(channel_id=channels[k % 3], log_time=t, data=b'{"k":%d}' % k + b" " * (k % 50),
                          publish_time=t + 1, sequence=k)
            if k == 150:
                w.flush()
        w.finish()
        return out.getvalue()

    fast = mcap_writer_class()
    assert fast(io.BytesIO(), chunk_size=1000)._fast  # the fast path is the one compared (not mcap's fallback)
    for chunk_size in (1 << 20, 2000):
        assert write(fast, chunk_size) == write(Writer, chunk_size)


def _reference_scan_json(scan) -> bytes:
    """/scan as it was written before the writer skipped np.unwrap and the lists: the reference text."""
    from beastbt.recording import foxglove as fx
    from beastbt.recording.writer import encode_json
    angles = np.unwrap(np.asarray(scan.angles_rad, dtype=float))
    ranges = np.nan_to_num(np.asarray(scan.ranges_m, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
    n = len(angles)
    return encode_json({"timestamp": fx.fox_time(7), "frame_id": fx.LIDAR_FRAME, "pose": fx.planar_pose(0.0, 0.0, 0.0),
                        "start_angle": float(angles[0]) if n else 0.0, "end_angle": float(angles[-1]) if n else 0.0,
                        "ranges": np.round(ranges, 5).tolist(),
                        "intensities": np.rint(np.asarray(scan.intensities, dtype=float)).astype(int).tolist(),
                        "stamp_s": float(scan.stamp_s), "scan_rate_hz": float(scan.scan_rate_hz),
                        "model": str(scan.model), "source": "lidar"})


def test_the_scan_message_is_the_same_text_as_np_unwrap_and_lists_give():
    from beastbt.blackboard.types import LaserScan
    from beastbt.recording import foxglove as fx
    from beastbt.recording.writer import encode_json
    rng = np.random.default_rng(3)
    cases = []
    for k in range(40):  # LD19-like revolutions (clockwise, wrapping at -pi) and A1-like ones, jittered
        n = int(rng.integers(2, 500))
        step = rng.choice([-1.0, 1.0]) * 2 * np.pi / n * rng.uniform(0.9, 1.1)
        raw = rng.uniform(-np.pi, np.pi) + step * np.arange(n) + rng.normal(0.0, 1e-3, n)
        cases.append((raw + np.pi) % (2 * np.pi) - np.pi)
    cases += [np.array([]), np.array([-0.0]), np.array([0.5, -0.0]), np.array([-np.pi, np.pi, -np.pi]),
              np.array([3.0, -3.0, 3.0, -3.0]), np.array([0.1, np.nan, 0.3]), np.array([np.pi, 0.0]),
              np.array([1.0, 1.0 + np.pi, 1.0]), np.linspace(0, 6, 7, dtype=np.float32)]
    for angles in cases:
        n = len(angles)
        ranges = rng.uniform(0.02, 12.0, n).round(3)
        ranges[rng.random(n) < 0.1] = np.nan
        if n > 2:
            ranges[1], ranges[2] = np.inf, -np.inf
        scan = LaserScan(1.5, angles, ranges, rng.integers(0, 256, n).astype(float), 10.0, "ld19")
        assert encode_json(fx.laser_scan(7, scan, "lidar")) == _reference_scan_json(scan), angles
