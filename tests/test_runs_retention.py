"""A disk that never fills: runs prune the oldest finished runs by the profile's ``runs:``, never the running one
nor one marked ``keep``; every prune is logged; a recording stops cleanly at the free-space floor and the mission
goes on (on a real 50 MB tmpfs where the machine allows mounting one, as CI does)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from beastbt.run.retention import (KEEP_MARKER, PRUNE_LOG, RunsPolicy, free_bytes, hold_running_lock, is_running,
                                   prune_runs)
from conftest import REPO

MB = 1_000_000


def fake_run(runs: Path, name: str, size_bytes: int, summary: bool = True) -> Path:
    """A finished run folder of about ``size_bytes``: a summary and a run.mcap of that size."""
    folder = runs / name
    folder.mkdir(parents=True)
    if summary:
        (folder / "summary.json").write_text(json.dumps({"mission": name, "status": "success"}), encoding="utf-8")
    with open(folder / "run.mcap", "wb") as f:
        f.write(os.urandom(size_bytes))
    return folder


def beastbt(*args: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout, env=dict(os.environ, PYTHONPATH=str(REPO)))


def test_keep_n_prunes_the_oldest_finished_runs_and_logs_each(tmp_path):
    runs = tmp_path / "runs"
    names = [f"20260101T0000{i:02d}Z_patrol" for i in range(6)]
    for name in names:
        fake_run(runs, name, 1000)
    said: list[str] = []
    pruned = prune_runs(runs, RunsPolicy(keep=2, min_free_mb=0), log=said.append)
    assert [p.name for p in pruned] == names[:4]
    assert sorted(p.name for p in runs.iterdir() if p.is_dir()) == names[4:]
    log = (runs / PRUNE_LOG).read_text().splitlines()
    assert len(log) == 4 and all("more than the newest 2 runs" in line for line in log)
    assert names[0] in log[0] and len(said) == 4


def test_the_size_cap_prunes_oldest_first_until_it_holds(tmp_path):
    runs = tmp_path / "runs"
    for i in range(5):
        fake_run(runs, f"20260101T0000{i:02d}Z_r", 300_000)
    pruned = prune_runs(runs, RunsPolicy(max_total_mb=1.0, min_free_mb=0))
    assert [p.name for p in pruned] == ["20260101T000000Z_r", "20260101T000001Z_r"]
    assert sum(f.stat().st_size for f in runs.rglob("*") if f.is_file() and f.name != PRUNE_LOG) <= 1 * MB


def test_a_running_run_and_a_kept_run_are_never_pruned(tmp_path):
    runs = tmp_path / "runs"
    oldest = fake_run(runs, "20260101T000000Z_kept", 1000)
    running = fake_run(runs, "20260101T000001Z_running", 1000, summary=False)
    dead = fake_run(runs, "20260101T000002Z_died", 1000, summary=False)  # no summary, lock free: finished
    newest = fake_run(runs, "20260101T000003Z_new", 1000)
    done = beastbt("runs", "keep", oldest.name, "--runs-dir", str(runs), "--why", "the inspector's run", cwd=tmp_path)
    assert done.returncode == 0 and "never pruned" in done.stdout
    assert (oldest / KEEP_MARKER).read_text().strip() == "the inspector's run"
    fd = hold_running_lock(running)
    try:
        assert is_running(running) and not is_running(dead)
        listed = beastbt("runs", "--runs-dir", str(runs), cwd=tmp_path).stdout
        assert "running" in listed and "[kept]" in listed
        pruned = prune_runs(runs, RunsPolicy(keep=1, min_free_mb=0))
    finally:
        os.close(fd)
    assert [p.name for p in pruned] == [dead.name]
    assert oldest.exists() and running.exists() and newest.exists()
    beastbt("runs", "unkeep", oldest.name, "--runs-dir", str(runs), cwd=tmp_path)
    assert [p.name for p in prune_runs(runs, RunsPolicy(keep=1, min_free_mb=0))] == [oldest.name, running.name]


def test_runs_prune_dry_run_deletes_nothing_and_an_unknown_run_is_refused(tmp_path):
    runs = tmp_path / "runs"
    for i in range(3):
        fake_run(runs, f"20260101T0000{i:02d}Z_r", 1000)
    done = beastbt("runs", "prune", "--keep", "1", "--dry-run", "--runs-dir", str(runs), cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.count("would prune") == 2
    assert len([p for p in runs.iterdir() if p.is_dir()]) == 3
    done = beastbt("runs", "keep", "no_such_run", "--runs-dir", str(runs), cwd=tmp_path)
    assert done.returncode == 2 and "no such run" in done.stderr


def test_a_run_prunes_with_keep_runs_and_says_so_as_an_event(tmp_path):
    runs = tmp_path / "runs"
    for i in range(4):
        fake_run(runs, f"20200101T0000{i:02d}Z_old", 1000)
    done = beastbt("run", str(REPO / "missions" / "patrol.yaml"), "--runs-dir", str(runs), "--keep-runs", "2",
                   "--max-time", "5 s", "--summary", str(tmp_path / "s.json"), cwd=tmp_path)
    assert done.returncode == 1, done.stderr  # stopped at max time
    events = json.loads((tmp_path / "s.json").read_text())["events"]
    [pruned] = [e for e in events if e["kind"] == "runs_pruned"]
    assert "pruned 2 old run(s)" in pruned["text"]  # of 4 finished, the newest 2 stay; the running one aside
    left = sorted(p.name for p in runs.iterdir() if p.is_dir())
    assert left[:2] == ["20200101T000002Z_old", "20200101T000003Z_old"] and left[2].endswith("_corridor_patrol")


@pytest.fixture
def disk_50mb(tmp_path):
    """A 50 MB tmpfs mounted for the test (skipped where mounting is not allowed; CI runs as root)."""
    mount_point = tmp_path / "disk"
    mount_point.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=50m", "tmpfs", str(mount_point)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        if os.environ.get("CI"):
            pytest.fail(f"CI runs as root and must mount a tmpfs: {done.stderr}")
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield mount_point
    finally:
        subprocess.run(["umount", "-l", str(mount_point)], check=False)


def test_a_two_hour_patrol_on_a_full_50mb_disk_keeps_working_keeps_marked_runs_and_10mb_free(disk_50mb, tmp_path):
    runs = disk_50mb / "runs"
    # Runs that filled the disk: 1 MB ones, the oldest two marked keep, and one still running (locked).
    made = []
    while free_bytes(disk_50mb) > 1.2 * MB:
        made.append(fake_run(runs, f"20260101T{len(made):06d}Z_patrol", MB))
    kept = made[:2]
    for folder in kept:
        (folder / KEEP_MARKER).write_text("")
    running = made[5]
    fd = hold_running_lock(running)
    # The simulator's robot, lighter for a 2-hour test (20 Hz physics, no LiDAR, camera or servos), its runs kept
    # 10 MB free; a patrol of 3 m legs at 4 Hz.
    profile = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    for section in ("lidar", "camera", "servos"):
        profile.pop(section, None)
    profile["sim"]["physics_rate_hz"] = 20
    profile["runs"] = {"min_free_mb": 10}
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(profile, sort_keys=False), encoding="utf-8")
    (tmp_path / "patrol.yaml").write_text(
        f"mission: long_patrol\nworld: {REPO / 'worlds' / 'campus.yaml'}\nrate: 4 Hz\nsteps:\n"
        "  - repeat:\n      times: 1000\n      steps:\n"
        "        - drive: {distance: 3 m, speed: 0.2 m/s}\n        - turn: {angle: 90 deg}\n", encoding="utf-8")
    try:
        done = beastbt("run", "patrol.yaml", "--robot", "robot.yaml", "--sim", "--runs-dir", str(runs),
                       "--max-time", "2 h", "--summary", str(tmp_path / "s.json"), cwd=tmp_path, timeout=900)
    finally:
        os.close(fd)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["sim_time_s"] >= 7199 and summary["status"] == "stopped", done.stdout[-2000:]  # max time: 2 h
    assert "max time" in summary["events"][-1]["text"] and summary["distance_m"] > 1000
    assert not [e for e in summary["events"] if e["kind"] == "step_failed"]
    pruned = [e for e in summary["events"] if e["kind"] == "runs_pruned"]
    assert len(pruned) == 1 and "less than 10 MB free" in pruned[0]["text"]
    floor = [e for e in summary["events"] if e["kind"] == "recording" and "free-space floor" in e["text"]]
    assert len(floor) == 1 and "the mission goes on" in floor[0]["text"]
    assert all(folder.exists() for folder in kept) and running.exists()
    assert free_bytes(disk_50mb) >= 10 * MB
    assert (runs / PRUNE_LOG).read_text().count("pruned") == len(made) - len(list(runs.glob("20260101T*")))
    this_run = [p for p in runs.iterdir() if p.name.endswith("_long_patrol")]
    assert len(this_run) == 1 and (this_run[0] / "summary.json").stat().st_size > 0
