"""A run killed hard leaves a recording that opens up to its last complete chunk.

The real thing: ``beastbt run --speed realtime`` in a subprocess, SIGKILL
after a couple of seconds, then the file is read with the ``mcap`` library.
Killing the run alone leaves its writer process to close the file properly.
Then, deterministically: a complete recording cut at many byte offsets always
reads as a prefix of the whole.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from mcap.reader import NonSeekingReader, make_reader

from beastbt.recording.reader import read_recording
from beastbt.replay import replay
from recording_support import PATROL, REPO, record_run


def _ticks_readable(path) -> int:
    try:
        return len(read_recording(path, topics=["/cmd/gate"]).topic("/cmd/gate"))
    except Exception:
        return 0


def _start_realtime_patrol(tmp_path) -> tuple[subprocess.Popen, "os.PathLike"]:
    """``beastbt run`` in real time, in its own process group, once a second of ticks (a chunk) is on disk."""
    runs = tmp_path / "runs"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt.cli", "run", str(PATROL), "--speed", "realtime",
                             "--runs-dir", str(runs)], cwd=tmp_path, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    # Wait (on the wall clock: this run is real time) until a second of ticks (a chunk) is on disk.
    deadline = time.monotonic() + 60.0
    path = None
    while time.monotonic() < deadline and proc.poll() is None:
        found = list(runs.glob("*/run.mcap")) if runs.exists() else []
        if found and _ticks_readable(found[0]) >= 20:
            path = found[0]
            break
        time.sleep(0.2)
    if path is None:
        _kill_group(proc)
    assert proc.poll() is None, proc.stderr.read().decode()
    assert path is not None, "the recording never reached a second of ticks"
    time.sleep(0.3)  # kill in the middle of writing, not just after a flush
    return proc, path


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=30)


def _check_what_was_kept(path, rec) -> None:
    ticks = [m["tick"] for m in rec.topic("/cmd/gate")]
    assert len(ticks) >= 20 and ticks == list(range(len(ticks)))  # every tick up to the cut, none missing
    assert rec.info["mission"] == "corridor_patrol" and rec.text("mission.yaml")
    for topic in ("/sensors/odometry", "/estimate/fused", "/truth", "/cmd/mission", "/tree", "/events"):
        assert rec.topic(topic), topic
    # And what was kept replays.
    result = replay(str(path.parent))
    assert result.identical and result.ticks == len(ticks)


def test_sigkill_of_everything_leaves_a_file_that_opens_up_to_its_last_complete_chunk(tmp_path):
    # A power cut, or the OOM killer taking the run and its writer process: the file just stops.
    proc, path = _start_realtime_patrol(tmp_path)
    try:
        os.killpg(proc.pid, signal.SIGKILL)  # the run and its writer process, at once
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            _kill_group(proc)
    assert proc.returncode == -signal.SIGKILL
    assert not (path.parent / "summary.json").exists()

    rec = read_recording(path)
    assert not rec.complete
    _check_what_was_kept(path, rec)
    # mcap's own linear reader gets the same messages before it meets the cut.
    count = 0
    with open(path, "rb") as f:
        try:
            for _ in NonSeekingReader(f).iter_messages(log_time_order=False):
                count += 1
        except Exception:
            pass  # the last, incomplete record
    assert count == rec.message_count()


def test_sigkill_of_the_run_alone_leaves_a_closed_file_that_says_it_was_cut(tmp_path):
    # The run's process dies (SIGKILL, a crash in C code): its writer process sees the pipe end, writes
    # what it had and closes the file properly, marked as cut, with no run summary.
    proc, path = _start_realtime_patrol(tmp_path)
    try:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and not read_recording(path, topics=[]).complete:
            time.sleep(0.1)  # the writer closes the file on its own, moments later
    finally:
        _kill_group(proc)
    assert proc.returncode == -signal.SIGKILL
    assert not (path.parent / "summary.json").exists()

    rec = read_recording(path)
    assert rec.complete and rec.summary is None
    assert "ended without finishing" in rec.metadata["beastbt.cut"]["reason"]
    _check_what_was_kept(path, rec)
    with open(path, "rb") as f:  # a proper MCAP file now: the seeking reader reads its summary section
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == rec.message_count()


def test_a_recording_cut_anywhere_reads_as_a_prefix(tmp_path):
    folder, _ = record_run(PATROL, tmp_path, seed=2, max_time_s=8.0, recording={"chunk_interval_s": 0.4})
    data = (folder / "run.mcap").read_bytes()
    whole = read_recording(folder / "run.mcap", keep_order=True)
    assert whole.complete
    full = [(t, ts, m) for t, ts, m in whole.order]
    seen_counts = set()
    for frac in (0.02, 0.1, 0.25, 0.33, 0.5, 0.61, 0.75, 0.9, 0.97, 0.999):
        cut = tmp_path / f"cut{frac}.mcap"
        cut.write_bytes(data[: int(len(data) * frac)])
        part = read_recording(cut, keep_order=True)
        assert not part.complete and part.stopped_because
        assert part.order == full[: len(part.order)]
        assert part.info == whole.info
        seen_counts.add(len(part.order))
    assert len(seen_counts) >= 6  # small chunks: each cut keeps a different amount
