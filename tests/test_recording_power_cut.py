"""A power cut: the recording of a run killed hard is read by MCAP's own readers, and ``beastbt recover``
rewrites any cut file (even one torn in the middle of a record) as a whole MCAP file.

The real thing: ``beastbt run --speed realtime`` in its own process group,
SIGKILL of the whole group once chunks are on disk, then ``mcap.reader``'s
seeking and linear readers on the file as it is, and on what ``beastbt
recover`` makes of it. Then, deterministically: the writer's file after
each chunk, and a recorded file cut at many byte offsets.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from mcap.reader import NonSeekingReader, make_reader

from beastbt.recording.config import RecordingConfig
from beastbt.recording.reader import read_recording
from beastbt.recording.recover import RECOVERED_METADATA, recover
from beastbt.recording.writer import RunFileWriter
from recording_support import PATROL, REPO, record_run


def _official(path: Path) -> list[tuple[str, int, bytes]]:
    """Every message of ``path`` by mcap's seeking reader (what ``make_reader`` gives for a file): topic, log
    time, data, in file order; raises when the reader cannot read the file."""
    with open(path, "rb") as f:
        return [(ch.topic, m.log_time, m.data) for _, ch, m in make_reader(f).iter_messages(log_time_order=False)]


def _official_linear(path: Path) -> int:
    with open(path, "rb") as f:
        return sum(1 for _ in NonSeekingReader(f).iter_messages())


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "beastbt.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


def _ticks_on_disk(path: Path) -> int:
    try:
        return len(read_recording(path, topics=["/cmd/gate"]).topic("/cmd/gate"))
    except Exception:
        return 0


def test_a_sigkill_of_the_whole_run_leaves_a_file_mcaps_readers_read_and_recover_makes_it_whole(tmp_path):
    runs = tmp_path / "runs"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt.cli", "run", str(PATROL), "--speed", "realtime",
                             "--runs-dir", str(runs)], cwd=tmp_path, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60.0
        path = None
        while time.monotonic() < deadline and proc.poll() is None:
            found = list(runs.glob("*/run.mcap")) if runs.exists() else []
            if found and _ticks_on_disk(found[0]) >= 40:  # two chunks (1 s each at 20 Hz) on disk
                path = found[0]
                break
            time.sleep(0.1)
        assert proc.poll() is None, proc.stderr.read().decode()
        assert path is not None, "the recording never reached two chunks"
        time.sleep(0.45)  # in the middle of the next chunk, not just after a write
        os.killpg(proc.pid, signal.SIGKILL)  # the run and its writer process at once: a power cut
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    folder = path.parent
    assert not (folder / "summary.json").exists()

    # As it is: both of mcap's readers read the file to its end, every message our own reader finds.
    on_disk = read_recording(path, keep_order=True)
    # At least the 40 ticks' odometry and three commands each (poses go at 10 Hz, the LiDAR at its own rate).
    assert not on_disk.complete and on_disk.message_count() >= 40 * 4
    as_cut = _official(path)
    assert len(as_cut) == on_disk.message_count() == _official_linear(path)

    cut_bytes = path.read_bytes()
    # Recovered: a whole file (summary section, statistics) holding the same messages, and a summary.
    done = _cli("recover", str(folder), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert f"{len(as_cut)} messages kept" in done.stdout and "rebuilt" in done.stdout
    assert (folder / "run.mcap.cut").read_bytes() == cut_bytes  # the cut file kept as it was
    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert stats.message_count == len(as_cut)
    assert sorted(_official(path)) == sorted(as_cut)
    rec = read_recording(path)
    assert rec.complete and rec.metadata[RECOVERED_METADATA]["from"] == "run.mcap.cut"
    assert rec.info == on_disk.info and rec.text("mission.yaml") == on_disk.text("mission.yaml")
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    ticks = len(on_disk.topic("/cmd/gate"))
    assert summary["status"] == "stopped" and summary["mission"] == "corridor_patrol"
    assert summary["ticks"] == ticks and abs(summary["sim_time_s"] - (ticks - 1) * 0.05) < 1e-6
    kinds = [e["kind"] for e in summary["events"]]
    # As in a summary of a run that ended well: what the assembly said (which parts sleep), then the start.
    assert set(kinds[:kinds.index("mission_start")]) <= {"asleep"} and summary["recovered"]["from"] == "run.mcap.cut"
    assert "mission_start" in (folder / "events.log").read_text(encoding="utf-8")
    listed = _cli("runs", "--runs-dir", str(runs), cwd=tmp_path)
    assert "cut short (stopped, recovered)" in listed.stdout
    again = _cli("recover", str(folder), cwd=tmp_path)
    assert again.returncode == 0 and "nothing to recover" in again.stdout


def test_after_every_chunk_the_writers_file_is_a_valid_mcap_file(tmp_path):
    # What a SIGKILL right after any flush leaves: copy the file then, and read the copy with mcap's readers.
    path = tmp_path / "run.mcap"
    w = RunFileWriter([path], RecordingConfig.from_dict({"compression": "zstd"}), {"mission": "chunks"}, [])
    copies = []
    for i in range(300):
        w.write(("event", i * 0.05, "say", f"event {i}"))
        if i % 25 == 24:
            w.flush()
            copy = tmp_path / f"at{i}.mcap"
            shutil.copyfile(path, copy)
            copies.append((copy, w.messages))
    w.finish()
    for copy, messages in copies:
        got = _official(copy)
        assert len(got) == messages == _official_linear(copy)
        texts = [json.loads(d)["text"] for topic, _, d in got if topic == "/events"]
        assert texts == [f"event {i}" for i in range(len(texts))] and len(texts) == messages // 2
        rec = read_recording(copy)
        assert not rec.complete and "last complete chunk" in rec.stopped_because
    assert read_recording(path).complete and len(_official(path)) == w.messages == 600


def test_a_recording_cut_at_any_byte_recovers_to_a_valid_file_holding_its_whole_chunks(tmp_path):
    folder, _ = record_run(PATROL, tmp_path / "runs", seed=2, max_time_s=6.0, recording={"chunk_interval_s": 0.3})
    data = (folder / "run.mcap").read_bytes()
    whole = _official(folder / "run.mcap")
    offsets = sorted({int(len(data) * k / 37) + j for k in range(1, 37) for j in (0, 3)} | {9, 40, 500})
    kept_counts = set()
    for n, offset in enumerate(offsets):
        cut = tmp_path / f"cut{n}.mcap"
        cut.write_bytes(data[:offset])  # torn anywhere: in a chunk, a message index, a length field
        prefix = read_recording(cut).message_count()
        r = recover(cut)
        assert not r.complete and r.backup == cut.with_name(cut.name + ".cut") and r.backup.stat().st_size == offset
        got = _official(cut)  # the seeking reader: footer, summary section, chunk indexes
        assert len(got) == r.messages == prefix
        assert sorted(got) == sorted(whole[: len(got)])  # the first messages of the whole run, none altered
        kept_counts.add(len(got))
    assert len(kept_counts) >= 12  # cuts at different places keep different amounts
    assert max(kept_counts) >= 0.9 * len(whole)
