"""Mistakes a user can type or write get a clear error, exit 2, and no traceback; nothing starts (issue 15)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

PATROL = str(REPO / "missions" / "patrol.yaml")


def beastbt(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, timeout=120,
                          cwd=cwd, env=dict(os.environ, PYTHONPATH=str(REPO)))


def nested(levels: int) -> str:
    text, indent = "mission: deep\nsteps:\n", "  "
    for _ in range(levels):
        text += f"{indent}- repeat:\n{indent}    times: 1\n{indent}    steps:\n"
        indent += "      "
    return text + f"{indent}- wait: 1 s\n"


@pytest.mark.parametrize("levels", [80, 400])
def test_a_mission_nested_too_deeply_is_refused_with_its_position(tmp_path, levels):
    path = tmp_path / "deep.yaml"
    path.write_text(nested(levels))
    done = beastbt("validate", str(path))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"{path}:" in done.stderr and "nested too deeply" in done.stderr and "tasks:" in done.stderr


def test_a_mission_nested_within_the_limit_runs(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text(nested(25))
    done = beastbt("run", str(path), "--no-record")
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("args, says", [
    (["tree", PATROL, "--dot", "/nonexistent-folder/tree.dot"], "the folder /nonexistent-folder does not exist"),
    (["run", PATROL, "--no-record", "--summary", "/nonexistent-folder/s.json"], "the folder /nonexistent-folder"),
    (["run", PATROL, "--no-record", "--record", "/nonexistent-folder/r.mcap"], "the folder /nonexistent-folder"),
    (["run", PATROL, "--record-images", "-1"], "is negative"),
    (["run", PATROL, "--seed", "-5"], "is negative"),
    (["run", PATROL, "--max-time", "0"], "not a positive duration"),
    (["run", PATROL, "--max-time", "-5 s"], "not a positive duration"),
    (["run", PATROL, "--stream-quality", "0"], "JPEG quality 1-100"),
])
def test_bad_options_exit_2_before_anything_starts(tmp_path, args, says):
    done = beastbt(*args, cwd=tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert says in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "runs").exists() and "mission_start" not in done.stdout


def test_runs_dir_that_is_a_file(tmp_path):
    (tmp_path / "runs").write_text("not a folder")
    done = beastbt("run", PATROL, "--runs-dir", str(tmp_path / "runs"), cwd=tmp_path)
    assert done.returncode == 2 and "is a file, not a folder" in done.stderr and "Traceback" not in done.stderr


def test_yaml_merge_keys_work(tmp_path):
    path = tmp_path / "merge.yaml"
    path.write_text("mission: merged\nsteps:\n  - drive: &slow {distance: 1 m, speed: 0.1 m/s}\n"
                    "  - drive:\n      <<: *slow\n      distance: 0.5 m\n")
    done = beastbt("run", str(path), "--no-record", "--summary", str(tmp_path / "s.json"))
    assert done.returncode == 0, done.stderr
    import json
    assert json.loads((tmp_path / "s.json").read_text())["distance_m"] == pytest.approx(1.5, abs=0.1)
    twice = tmp_path / "twice.yaml"
    twice.write_text("mission: t\nsteps:\n  - drive: {distance: 1 m, distance: 2 m}\n")
    done = beastbt("validate", str(twice))
    assert done.returncode == 2 and "duplicate key 'distance'" in done.stderr


def test_a_mission_named_with_accents_runs_and_its_folder_is_time_and_mission_as_the_readme_says(tmp_path):
    import re
    path = tmp_path / "tour.yaml"
    path.write_text("mission: café_straße\nsteps:\n  - wait: 1 s\n")
    done = beastbt("run", str(path), "--runs-dir", str(tmp_path / "runs"))
    assert done.returncode == 0, done.stderr
    [folder] = (tmp_path / "runs").iterdir()
    assert re.fullmatch(r"\d{8}T\d{6}Z_café_straße", folder.name), folder.name
    assert "runs/<UTC time>_<mission>/" in (REPO / "README.md").read_text(encoding="utf-8")
    long = "a_mission_whose_name_goes_on_and_on_" * 4
    path.write_text(f"mission: {long}\nsteps:\n  - wait: 1 s\n")
    assert beastbt("run", str(path), "--runs-dir", str(tmp_path / "runs")).returncode == 0
    listed = beastbt("runs", "--runs-dir", str(tmp_path / "runs")).stdout.splitlines()
    assert listed[0].split() == ["RUN", "MISSION", "OUTCOME", "TIME", "DISTANCE", "RECORDING"]
    outcome = listed[0].index("OUTCOME")
    assert all(line[outcome:].startswith("success") for line in listed[1:]), listed  # columns line up
    assert all(len(line) < 160 for line in listed)


def test_joystick_script_on_a_real_robot_says_why_before_opening_anything(tmp_path):
    done = beastbt("run", PATROL, "--robot", str(REPO / "robots" / "ugv_beast.yaml"), "--joystick",
                   str(REPO / "missions" / "joystick" / "teleop_demo.yaml"), cwd=tmp_path)
    assert done.returncode == 2 and "simulator only" in done.stderr and "--sim" in done.stderr
    assert "serial0" not in done.stderr  # not the base's error: the real reason


def test_a_missing_device_is_said_in_words_not_errno(tmp_path):
    done = beastbt("run", PATROL, "--robot", str(REPO / "robots" / "ugv_beast.yaml"), cwd=tmp_path)
    assert done.returncode == 2 and "it does not exist" in done.stderr and "Errno" not in done.stderr


def test_on_failure_hold_says_what_it_waits_for(tmp_path):
    path = tmp_path / "hold.yaml"
    path.write_text("mission: t\non_failure: hold\nsteps:\n  - follow_line: {until: intersection}\n")
    done = beastbt("run", str(path), "--no-record", "--max-time", "5 s")
    assert done.returncode == 1
    assert "on_failure: hold: the robot stands still and waits for the run to be ended: Ctrl-C" in done.stdout


def test_a_snapshot_without_a_run_folder_goes_to_a_temporary_folder_and_says_where(tmp_path):
    path = tmp_path / "snap.yaml"
    path.write_text(f"mission: t\nworld: {REPO / 'worlds' / 'line_track.yaml'}\nsteps:\n  - wait: 0.5 s\n"
                    f"  - snapshot: {{name: start}}\n")
    done = beastbt("run", str(path), "--no-record")
    assert done.returncode == 0, done.stderr
    saved = [line.split("saved ", 1)[1] for line in done.stdout.splitlines() if "snapshot: start: saved" in line]
    assert saved and Path(saved[0]).is_file() and Path(saved[0]).stat().st_size > 1000


def test_profiles_and_worlds_take_values_with_units(tmp_path):
    text = (REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8")
    text = text.replace("  track_width_m: 0.17 ", "  track_width_m: 17 cm ").replace(
        "  physics_rate_hz: 100", "  physics_rate_hz: 100 Hz").replace("  timeout_s: 0.45 ", "  timeout_s: 450 ms ")
    path = tmp_path / "robot.yaml"
    path.write_text(text, encoding="utf-8")
    from beastbt.robot.profile import load_profile
    profile = load_profile(path)
    assert profile.track_width_m == pytest.approx(0.17) and profile.section("sim")["physics_rate_hz"] == 100.0
    assert profile.section("watchdog")["timeout_s"] == pytest.approx(0.45)
    path.write_text(text.replace("17 cm", "17 meter"), encoding="utf-8")
    done = beastbt("validate", str(path))
    assert done.returncode == 2 and "did you mean '17 m'?" in done.stderr and "robot.yaml:" in done.stderr
    world = tmp_path / "world.yaml"
    world.write_text((REPO / "worlds" / "corridor.yaml").read_text(encoding="utf-8")
                     .replace("start_v: 12.3", "start_v: 12300 mV").replace("alt_m: 650", "alt_m: 0.65 km"))
    from beastbt.sim.world import load_world
    loaded = load_world(world)
    assert loaded.battery_start_v == pytest.approx(12.3) and loaded.frame.alt0_m == pytest.approx(650.0)


def wait_for_ticks(notify: socket.socket, proc: subprocess.Popen, ticks: int, timeout_s: float = 120.0) -> None:
    """Read the run's sd_notify datagrams (``notify``, bound where ``NOTIFY_SOCKET`` points) until it said
    ``READY=1`` (sent once the loop has taken over SIGTERM) and then fed the watchdog ``ticks`` times (one a tick)."""
    import time
    notify.settimeout(0.5)
    ready, fed = False, 0
    deadline = time.monotonic() + timeout_s
    while not (ready and fed >= ticks):
        assert time.monotonic() < deadline and proc.poll() is None, f"the run never ticked: ready {ready}, {fed} ticks"
        try:
            lines = notify.recv(4096).decode().split("\n")
        except socket.timeout:
            continue
        ready = ready or "READY=1" in lines
        if ready and "WATCHDOG=1" in lines:
            fed += 1


def test_sigterm_to_a_simulated_run_gives_its_summary_and_a_readable_recording(tmp_path):
    import signal
    notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    notify.bind(str(tmp_path / "notify"))
    env = dict(os.environ, PYTHONPATH=str(REPO), NOTIFY_SOCKET=str(tmp_path / "notify"))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "run", PATROL, "--speed", "realtime", "--runs-dir",
                             str(tmp_path / "runs")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tmp_path, env=env)
    # Signal once the loop runs (systemd's READY=1, said after SIGTERM is taken over), then a second of ticks
    # (a watchdog keep-alive each), not after a fixed time: a loaded machine may still be building the run then,
    # and SIGTERM's default action would kill it without a summary.
    try:
        wait_for_ticks(notify, proc, 20)
    except BaseException:
        proc.kill()
        proc.communicate()
        raise
    finally:
        notify.close()
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 1 and "Traceback" not in err
    assert "interrupted (SIGTERM)" in out and "run recorded in" in out, out
    [folder] = (tmp_path / "runs").iterdir()
    report = beastbt("report", str(folder), "--out", str(tmp_path / "report"))
    assert report.returncode == 0 and "file complete" in report.stdout, report.stdout + report.stderr
    assert (tmp_path / "report" / "report.html").is_file()


def test_validate_explain_gives_every_step_its_help_from_the_schema():
    from beastbt.mission.explain import explain_step, steps_and_help
    from beastbt.mission.model import STEP_KEYWORDS
    steps = steps_and_help()
    assert set(STEP_KEYWORDS) <= set(steps)
    for keyword, (description, _, _) in steps.items():
        assert description, keyword
        assert explain_step(keyword).startswith(f"{keyword}: {description}")
    drive = beastbt("validate", "--explain", "drive")
    assert drive.returncode == 0 and "distance (required, a distance)" in drive.stdout and "time (required" in drive.stdout
    assert "with then:" in beastbt("validate", "--explain", "if").stdout
    wrong = beastbt("validate", "--explain", "folow_line")
    assert wrong.returncode == 2 and "did you mean 'follow_line'?" in wrong.stderr


def test_output_that_is_not_a_terminal_has_no_carriage_returns(tmp_path):
    done = beastbt("run", PATROL, "--no-record", cwd=tmp_path)
    assert done.returncode == 0 and "\r" not in done.stdout and "\x1b" not in done.stdout
    assert done.stdout.startswith("[  176.0 s] mission_end: success")
    # The end is said once: the headline carries its reason, at the same time as the event printed live.
    assert done.stdout.count("mission_end") == 1
    assert "mission corridor_patrol: SUCCESS (all steps done)\n  time 176.0 s" in done.stdout


def test_a_failed_run_says_its_end_once_with_the_failure_recapped(tmp_path):
    (tmp_path / "m.yaml").write_text("mission: blocked\nworld: corridor.yaml\nsteps:\n  - drive: {distance: 20 m}\n")
    done = beastbt("run", str(tmp_path / "m.yaml"), "--no-record", "--robot", str(REPO / "robots" / "ugv_beast.yaml"),
                   "--sim", "--world", str(REPO / "worlds" / "corridor.yaml"), cwd=tmp_path)
    assert done.returncode == 1
    assert done.stdout.count("mission_end") == 1, done.stdout
    live = next(line for line in done.stdout.splitlines() if "mission_end" in line)
    headline = next(line for line in done.stdout.splitlines() if line.startswith("mission blocked: FAILURE ("))
    when = float(live.split("]")[0].strip("[ s"))
    assert f"  time {when:.1f} s" in done.stdout and live.split("failure: ")[1] in headline
    assert done.stdout.count("step_failed") == 2  # live, and recapped under the headline


@pytest.mark.parametrize("args, says", [
    (["validate", "/tmp"], "this is a folder, not a file"),
    (["validate", sys.executable], "this is not a text file"),
    (["run", PATROL, "--robot", "ugv_beats"], "no robot profile called 'ugv_beats'; did you mean 'ugv_beast'?"),
])
def test_wrong_files_are_named_in_words(tmp_path, args, says):
    done = beastbt(*args, cwd=tmp_path)
    assert done.returncode == 2 and says in done.stderr and "Errno" not in done.stderr and "Traceback" not in done.stderr


def test_a_fault_of_beastbt_itself_is_one_clear_line_and_a_file_not_a_traceback(monkeypatch, tmp_path, capsys):
    """An unexpected exception in a command: exit 1, the command and the fault named, the traceback in a file."""
    import beastbt.commands.runs as runs_command
    from beastbt import cli

    def broken(args):
        raise RuntimeError("something beastbt did not foresee")

    monkeypatch.setattr(runs_command, "command", broken)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.delenv("BEASTBT_TRACEBACK", raising=False)
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", None)
    assert cli.main(["runs", "--runs-dir", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "internal error in 'runs': RuntimeError: something beastbt did not foresee" in err
    kept = list(tmp_path.glob("beastbt-runs-crash-*.txt"))
    assert len(kept) == 1 and str(kept[0]) in err
    assert "Traceback" in kept[0].read_text() and "broken" in kept[0].read_text()


def test_messages_read_as_sentences_an_option_has_no_line_and_a_file_has_no_a_route(tmp_path):
    import socket
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        done = beastbt("run", PATROL, "--console", str(port), "--no-record")
    assert done.returncode == 2
    assert f"beastbt: --console: error: cannot listen on 127.0.0.1:{port}" in done.stderr and ":1:1:" not in done.stderr
    (tmp_path / "wptonly.gpx").write_text("<gpx><wpt lat='40.4' lon='-3.7'><name>a</name></wpt></gpx>\n")
    (tmp_path / "m.yaml").write_text("mission: t\nsteps:\n  - route: {file: wptonly.gpx}\n")
    said = beastbt("validate", str(tmp_path / "m.yaml")).stderr
    assert "wptonly.gpx has no route (GPX rte/trk" in said and "no a " not in said
    (tmp_path / "robot.yaml").write_text("robot: x\nbogus: 1\n")
    layout = beastbt("foxglove-layout", "--robot", str(tmp_path / "robot.yaml"))
    assert layout.returncode == 2 and "robot.yaml:2:1: error: unknown key 'bogus'" in layout.stderr
    assert "foxglove-layout: error:" not in layout.stderr  # said once, positioned, not wrapped in a second 'error:'
