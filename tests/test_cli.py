"""The ``beastbt`` command as a user meets it: the overview, --version, did-you-mean, python -m, start-up imports."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from beastbt import cli
from conftest import REPO

PATROL = REPO / "missions" / "patrol.yaml"
HEAVY = ("scipy", "filterpy", "cv2", "matplotlib", "mcap", "can", "serial")
"""What the quick commands must not import (each costs from tens to hundreds of milliseconds)."""


def beastbt(*args: str, cwd: Path = REPO, **kw) -> subprocess.CompletedProcess:
    """``python -m beastbt ARGS`` in a subprocess."""
    return subprocess.run([sys.executable, "-m", "beastbt", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=120, **kw)


def test_beastbt_alone_prints_the_overview_and_exits_2(capsys):
    assert cli.main([]) == 2
    out = capsys.readouterr().out
    for name in cli.COMMANDS:
        assert name in out
    assert "--version" in out


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"beastbt {cli.version()}"
    assert cli.version()[0].isdigit()


@pytest.mark.parametrize("argv, words", [
    (["rnu", "m.yaml"], "unknown command 'rnu'; did you mean 'run'?"),
    (["valdate", "m.yaml"], "did you mean 'validate'?"),
    (["fly", "m.yaml"], "the commands are: run, validate"),
    (["run", "m.yaml", "--seeed", "3"], "unknown option '--seeed'; did you mean '--seed'?"),
    (["run", "m.yaml", "--strem", "8080"], "unknown option '--strem'; did you mean '--stream'?"),
    (["tree", "m.yaml", "--robbot", "sim"], "did you mean '--robot'?"),
])
def test_mistakes_get_a_did_you_mean_and_exit_2_before_anything_starts(argv, words, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        code = cli.main(argv)
        raise SystemExit(code)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert words in err, err
    assert len([line for line in err.splitlines() if "error:" in line]) == 1
    assert not (tmp_path / "runs").exists()  # nothing started


@pytest.mark.parametrize("argv", [
    ["run", str(PATROL), "--speed", "fast"],
    ["run", str(PATROL), "--max-time", "ten"],
    ["run", str(PATROL), "--stream", "camera"],
    ["run", str(PATROL), "--stream", "8080", "--stream-size", "big"],
    ["run", str(PATROL), "--seed", "one"],
])
def test_bad_option_values_exit_2_before_anything_starts(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    try:
        code = cli.main(argv)
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    assert "error" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_python_m_beastbt_is_the_same_command(tmp_path):
    summary = tmp_path / "s.json"
    run = beastbt("run", str(PATROL), "--seed", "1", "--no-record", "--summary", str(summary), "--max-time", "20 s")
    assert run.returncode == 1, run.stderr  # max time reached: stopped
    assert json.loads(summary.read_text())["status"] == "stopped"
    assert beastbt("--version").stdout.strip() == f"beastbt {cli.version()}"
    assert "did you mean 'run'" in beastbt("rnu").stderr
    # Options that parts of beastbt used to register at import time are there too.
    assert "--stream" in beastbt("run", "--help").stdout and "--joystick" in beastbt("run", "--help").stdout


def test_tree_into_a_closed_pipe_is_not_an_error():
    proc = subprocess.Popen(f"{sys.executable} -m beastbt tree {PATROL} | head -1", shell=True, cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = proc.communicate(timeout=60)
    assert out.startswith("{-} mission corridor_patrol")
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_tree_of_a_real_robot_profile_needs_no_hardware(capsys):
    assert cli.main(["tree", str(REPO / "missions" / "gps_route.yaml"), "--robot", str(REPO / "robots" / "ugv_beast.yaml")]) == 0
    out = capsys.readouterr().out
    assert "--> go_to a" in out and "return_home" in out
    assert cli.main(["tree", str(REPO / "missions" / "gps_route.yaml"), "--robot", str(REPO / "robots" / "diy_can.yaml")]) == 0
    assert "not available" not in capsys.readouterr().out  # the leaf's name is the step's; it fails when ticked


@pytest.mark.parametrize("args", [
    ("--help",),
    ("run", "--help"),
    ("validate", str(PATROL)),
    ("tree", str(PATROL)),
    ("tree", str(REPO / "missions" / "line_to_intersection.yaml"), "--robot", str(REPO / "robots" / "ugv_beast.yaml")),
    ("runs", "--runs-dir", "RUNS"),
], ids=lambda a: " ".join(a[:2]))
def test_quick_commands_import_nothing_heavy(args, tmp_path):
    args = tuple(str(tmp_path) if a == "RUNS" else a for a in args)
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "beastbt", *args], cwd=REPO,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    imported = {line.rsplit("|", 1)[1].strip().split(".")[0] for line in out.stderr.splitlines()
                if line.startswith("import time:") and "|" in line}
    assert "beastbt" in imported
    assert not imported & set(HEAVY), f"{' '.join(args)} imports {sorted(imported & set(HEAVY))}"


def _run_imports(mission: Path) -> set[str]:
    """The top-level modules a ``run MISSION --no-record --max-time 1 s`` imports."""
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "beastbt", "run", str(mission), "--no-record",
                          "--max-time", "1 s"], cwd=REPO, capture_output=True, text=True, timeout=120)
    return {line.rsplit("|", 1)[1].strip().split(".")[0] for line in out.stderr.splitlines() if "|" in line}


def test_the_run_command_does_import_the_parts_it_needs(tmp_path):
    # The other side of the check above: a run opens the default sim robot's devices (pyserial), and loads the
    # EKF (filterpy, SciPy) when something reads the fused pose (gps_route's go_to), but not when it sleeps (patrol);
    # patrol has no go_to either, so the local planner's graph search (SciPy) is not loaded for its LiDAR.
    patrol = _run_imports(PATROL)
    assert "serial" in patrol and not {"filterpy", "scipy"} & patrol
    assert "filterpy" in _run_imports(REPO / "missions" / "gps_route.yaml")
