"""Ctrl-C during a run: a zero command is sent, the run ends 'stopped' with exit status 1."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import REPO


def test_ctrl_c_stops_the_robot_and_exits_1(tmp_path):
    summary = tmp_path / "s.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "beastbt.cli", "run", str(REPO / "missions" / "patrol.yaml"), "--speed", "realtime",
         "--summary", str(summary), "--runs-dir", str(tmp_path / "runs")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(REPO)})
    # Wait (bounded) until the run is under way: its recording has data once the loop ticks (the run folder appears
    # earlier, while the simulator is still being built: a Ctrl-C then abandons a run that never started, and under
    # load one second after the folder appeared was not always enough). The patrol takes minutes in real time.
    deadline = time.monotonic() + 60

    def ticking() -> bool:
        return any(f.stat().st_size > 0 for f in (tmp_path / "runs").glob("*/run.mcap"))

    while not ticking() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=max(5.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    assert proc.returncode == 1, err.decode()
    s = json.loads(summary.read_text())
    assert s["status"] == "stopped"
    assert any("interrupted" in e["text"] for e in s["events"])
    assert 0 < s["sim_time_s"] < 30


def test_interrupt_and_internal_errors_leave_a_stop_on_the_wire(tmp_path):
    import io

    import pytest

    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute

    for exc in (KeyboardInterrupt(), RuntimeError("a bug in a behaviour")):
        p = prepare(str(REPO / "missions" / "patrol.yaml"), RunOptions(record=False))
        original = p.run.tick
        calls = {"n": 0}

        def tick(exc=exc):
            calls["n"] += 1
            if calls["n"] == 60:
                raise exc
            return original()

        p.run.tick = tick
        esp32 = p.run.io.esp32
        if isinstance(exc, KeyboardInterrupt):
            s = execute(p, io.StringIO())
            assert s["status"] == "stopped"
        else:
            with pytest.raises(RuntimeError):
                execute(p, io.StringIO())
            assert p.run.status == "failure"
        moving = [c for c in esp32.commands if c.get("T") == 1 and c["L"] != 0]
        assert moving, "the robot was driving before the interruption"
        assert esp32.commands[-1] == {"T": 1, "L": 0.0, "R": 0.0}


def test_ctrl_c_while_the_robot_is_being_built_is_said_and_exits_1(monkeypatch, capsys):
    """Ctrl-C before the mission started (the robot still being built: a real base's serial port, the simulator's
    textures) ends 'beastbt run' with 1 and says so on standard error (it used to end silently)."""
    import beastbt.assembly
    from beastbt.cli import main

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(beastbt.assembly, "prepare", interrupted)
    status = main(["run", str(REPO / "missions" / "patrol.yaml"), "--no-record"])
    assert status == 1
    err = capsys.readouterr().err
    assert "beastbt run: interrupted while the robot was being built" in err and "nothing moved" in err, err
