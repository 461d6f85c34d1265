"""A full disk: the recording stops with an event, the mission goes on, the summary is kept.

The real thing where the machine allows it (root: a 2 MB tmpfs mounted for
the test, as CI does): ``beastbt run`` through the CLI with its run folder on
it. Everywhere: the writer with a file whose writes fail with ENOSPC after a
given size, beside a second file that has room.
"""

from __future__ import annotations

import errno
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import NonSeekingReader, make_reader

from beastbt.recording.config import RecordingConfig
from beastbt.recording.reader import read_recording
from beastbt.recording.recorder import low_space_warnings
from beastbt.recording.writer import RunFileWriter
from beastbt.run.run_folder import RunFolder
from recording_support import CAMERA_MISSION, PATROL, REPO, record_run

SMALL_DISK_BYTES = 2 << 20


def _mounted(mount_point: Path, options: str):
    """Mount a tmpfs with ``options`` on ``mount_point`` for the test (skip where mounting is not allowed)."""
    mount_point.mkdir()
    if not sys.platform.startswith("linux"):
        pytest.skip("mounting a small tmpfs needs Linux; the fault-injection tests cover the writer")
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(mount_point)],
                              capture_output=True, text=True)
    except OSError as exc:
        pytest.skip(f"no mount command here ({exc}); the fault-injection tests cover the writer")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here (needs root: {done.stderr.strip() or done.returncode}); "
                    f"the fault-injection tests cover the writer")
    try:
        yield mount_point
    finally:
        subprocess.run(["umount", "-l", str(mount_point)], check=False)


@pytest.fixture
def small_disk(tmp_path):
    """A 2 MB file system (tmpfs) mounted on a folder for this test."""
    yield from _mounted(tmp_path / "small_disk", f"size={SMALL_DISK_BYTES}")


@pytest.fixture
def no_inodes_disk(tmp_path):
    """A file system with room for 2 more files or folders (tmpfs, nr_inodes): no run folder can be made."""
    yield from _mounted(tmp_path / "no_inodes", f"size={SMALL_DISK_BYTES},nr_inodes=4")


def _fill(folder: Path) -> None:
    """Fill the file system of ``folder`` to the last byte."""
    block = b"\0" * 65536
    with open(folder / "filler", "wb", buffering=0) as f:
        try:
            while True:
                f.write(block)
        except OSError as exc:
            assert exc.errno == errno.ENOSPC
    small = b"\0" * 512
    with open(folder / "filler2", "wb", buffering=0) as f:
        try:
            while True:
                f.write(small)
        except OSError:
            pass


def _run_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    if args[0] == "run":
        # These runs are about a disk that really fills: the simulator's profile with the runs' free-space
        # floor off (the floor, which stops a recording before the disk is full, is tests/test_runs_retention.py's).
        profile = cwd / "sim_no_floor.yaml"
        profile.write_text((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8") + "\nruns: {min_free_mb: 0}\n",
                           encoding="utf-8")
        args = (*args, "--robot", str(profile), "--sim")
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "beastbt.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


def _messages_by_official_reader(path: Path) -> int:
    with open(path, "rb") as f:
        return sum(1 for _ in make_reader(f).iter_messages(log_time_order=False))


def test_a_disk_that_fills_during_the_run_stops_the_recording_with_an_event_and_the_mission_succeeds(
        small_disk, tmp_path):
    summary_path = tmp_path / "summary.json"  # on another file system: it is written whole
    done = _run_cli("run", str(PATROL), "--runs-dir", str(small_disk / "runs"), "--summary", str(summary_path),
                    cwd=tmp_path)
    assert done.returncode == 0, done.stderr  # the patrol succeeds: the exit status is the mission's
    assert "Traceback" not in done.stderr + done.stdout
    out = done.stdout
    # Warned at the start (2 MB is below the 50 MB default), told at once when the disk filled, before the end.
    assert re.search(r"\] recording: only [12]\.\d MB free at .*min_free_mb: 50 MB", out)
    stopped = [line for line in out.splitlines() if "recording: stopped: disk full at" in line]
    assert len(stopped) == 1 and "the mission goes on" in stopped[0]
    # At full speed the writer may lag the loop by the whole patrol: told by the end of the run at the latest.
    assert out.index(stopped[0]) < out.index("run recorded in")

    summary = json.loads(summary_path.read_text(encoding="utf-8"))
    assert summary["status"] == "success"
    assert [e for e in summary["events"] if e["kind"] == "recording" and "disk full" in e["text"]]
    recording = summary["recording"]
    assert "disk full" in recording["error"] and recording["dropped"] > 0 and recording["messages"] > 1000

    # The file keeps what was flushed before the disk filled, exactly, readable by mcap's own readers.
    folder = next((small_disk / "runs").iterdir())
    mcap = folder / "run.mcap"
    assert _messages_by_official_reader(mcap) == recording["messages"]
    with open(mcap, "rb") as f:
        assert sum(1 for _ in NonSeekingReader(f).iter_messages()) == recording["messages"]
    rec = read_recording(mcap, topics=[])
    assert not rec.complete and "last complete chunk" in rec.stopped_because


def test_a_disk_full_from_the_start_prints_the_summary_and_runs_says_why_there_is_none(small_disk, tmp_path):
    runs = small_disk / "runs"
    runs.mkdir()
    _fill(small_disk)
    # In real time, as on the robot: the first chunk (1 s) does not fit, and the run says so within a second.
    done = _run_cli("run", str(PATROL), "--runs-dir", str(runs), "--speed", "realtime", "--max-time", "3 s",
                    cwd=tmp_path)
    assert done.returncode == 1, done.stderr  # the mission's status: stopped at max time
    assert "Traceback" not in done.stderr + done.stdout
    [told] = re.findall(r"\[\s*([0-9.]+) s\] recording: stopped: disk full at", done.stdout)
    assert 1.0 <= float(told) <= 2.5
    assert "summary.json: the disk is full" in done.stderr
    # Written nowhere: the summary is on the terminal, whole.
    head = "the run summary (written nowhere else):\n"
    assert head in done.stdout
    text = done.stdout.split(head, 1)[1]
    summary, _ = json.JSONDecoder().raw_decode(text)
    assert summary["status"] == "stopped" and summary["mission"] == "corridor_patrol"
    assert 60 <= summary["ticks"] <= 61 and summary["recording"]["messages"] == 0
    assert [e for e in summary["events"] if e["kind"] == "recording" and "disk full" in e["text"]]

    listed = _run_cli("runs", "--runs-dir", str(runs), cwd=tmp_path)
    assert listed.returncode == 0
    assert "no summary (disk full?)" in listed.stdout and "unreadable" not in listed.stdout


class _FullAfter:
    """``os.pwrite`` for one file descriptor as on a disk with ``room`` bytes: a short write, then ENOSPC."""

    def __init__(self, fd: int, room: int, real=os.pwrite) -> None:
        self.fd, self.room, self.real = fd, room, real

    def __call__(self, fd: int, data, offset: int) -> int:
        if fd != self.fd:
            return self.real(fd, data, offset)
        fits = max(0, self.room - offset)
        if fits == 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self.real(fd, bytes(data)[:fits], offset)


def _items(n_ticks: int) -> list:
    """Events and servo items made up to look like a run's (ticks need the run's objects)."""
    from beastbt.blackboard.types import ServoCommand
    items = []
    for i in range(n_ticks):
        items.append(("event", i * 0.05, "say", f"tick {i} " + "x" * 200))
        items.append(("servo", i * 0.05, ServoCommand(name="pan", angle_rad=0.01 * i, stamp_s=i * 0.05)))
    return items


def test_the_writer_on_a_file_that_fills_keeps_it_valid_and_goes_on_with_the_other(tmp_path, monkeypatch):
    summary = {"mission": "disk_full_demo", "status": "success"}
    full, roomy = tmp_path / "full" / "run.mcap", tmp_path / "roomy" / "run.mcap"
    info = {"mission": "disk_full_demo"}
    cfg = RecordingConfig.from_dict({"chunk_interval_s": 0.5, "compression": "none"})
    w = RunFileWriter([full, roomy], cfg, info, [])
    fd = w._stream._files[0].fd
    monkeypatch.setattr(os, "pwrite", _FullAfter(fd, room=250_000))
    from beastbt.recording.wire import ItemEncoder, ItemDecoder  # the items cross the pipe as the run sends them
    decoded = list(ItemDecoder().feed(ItemEncoder().encode(_items(400))))
    for item in decoded:
        w.write(item)
        if item[0] == "servo" and item[2].angle_rad * 100 % 10 < 1e-6:
            w.flush()  # every 10 ticks, as the chunk interval would
    assert len(w.notices) == 1 and f"disk full at {full} (" in w.notices[0]
    assert f"still recording to {roomy}; the mission goes on" in w.notices[0]
    w.finish({"beastbt.summary": {"json": json.dumps(summary)}})

    # The full one: valid up to its last flush, which the official readers read to its end.
    kept = _messages_by_official_reader(full)
    assert 0 < kept < w.messages and full.stat().st_size <= 250_000
    rec = read_recording(full)
    assert not rec.complete and rec.message_count() == kept
    texts = [m["text"] for m in rec.topic("/events")]
    assert texts == [f"tick {i} " + "x" * 200 for i in range(len(texts))]  # the first ones, in order
    # The roomy one: every message, closed properly with the summary.
    whole = read_recording(roomy)
    assert whole.complete and whole.summary == summary
    assert len(whole.topic("/events")) == 400 and len(whole.topic("/cmd/servo")) == 400
    assert _messages_by_official_reader(roomy) == whole.message_count() == w.messages


def test_free_space_below_the_threshold_is_warned_about(tmp_path):
    path = tmp_path / "runs" / "x" / "run.mcap"
    path.parent.mkdir(parents=True)
    assert low_space_warnings([path], 0.0) == []
    free_mb = __import__("shutil").disk_usage(tmp_path).free / 1e6
    [warning] = low_space_warnings([path, path.with_name("other.mcap")], free_mb * 10)  # one per folder
    assert str(path.parent) in warning and "MB free" in warning and "the mission goes on" in warning
    assert RecordingConfig().min_free_mb == 50


def test_a_run_folder_on_a_full_disk_says_what_it_could_not_write(small_disk):
    runs = small_disk / "runs"
    folder = RunFolder(runs / "a_run")
    folder.path.mkdir(parents=True)
    _fill(small_disk)
    summary = {"mission": "m", "status": "success", "events": [{"time_s": 1.0, "kind": "say", "text": "hi" * 5000}]}
    problems = folder.finish(summary)
    assert any("summary.json: the disk is full" in p for p in problems)
    assert (folder.path / "summary.json").read_bytes() == b""  # empty, never half a document


def test_a_run_whose_folder_cannot_be_made_does_not_start_and_says_what_to_do(no_inodes_disk, tmp_path):
    runs = no_inodes_disk / "runs"
    runs.mkdir()
    for name in ("a", "b", "c"):  # use up the inodes that are left
        try:
            (no_inodes_disk / name).touch()
        except OSError:
            break
    done = _run_cli("run", str(PATROL), "--runs-dir", str(runs), cwd=tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "cannot make the run folder" in done.stderr and "--no-record" in done.stderr
    assert "mission corridor_patrol" not in done.stdout  # nothing ran


def test_a_snapshot_on_a_full_disk_is_an_event_and_the_mission_succeeds(small_disk):
    runs = small_disk / "runs"
    runs.mkdir()
    mission = small_disk.parent / "camera.yaml"
    mission.write_text(CAMERA_MISSION.replace("WORLD", str(REPO / "worlds" / "line_track.yaml")), encoding="utf-8")
    _fill(small_disk)
    _, summary = record_run(mission, runs, seed=4)
    assert summary["status"] == "success"
    snapshots = [e["text"] for e in summary["events"] if e["kind"] == "snapshot"]
    assert len(snapshots) == 1 and snapshots[0].startswith("tape: not saved (")
    assert not list(runs.glob("*/tape*.jpg"))
