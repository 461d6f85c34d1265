"""``beastbt replay`` of runs an operator took part in: answers, pauses, the console's stick, e-stop, a joystick.

What comes from outside the tree (an ``--answer``, the console's controls, a
typed answer) is recorded on ``/operator/input`` at the tick it counted in,
and replay carries it out again there, through the same code: such a run
replays identically, and ``beastbt replay`` says so and exits 0.
"""

from __future__ import annotations

import io
import json
import os
import time
from pathlib import Path

import jsonschema
import pytest

from beastbt.cli import main
from beastbt.recording.reader import read_recording
from beastbt.recording.schemas import CHANNELS
from beastbt.replay import NOT_REPLAYED, ReplayResult, replay
from console_support import ConsoleRun
from recording_support import record_run

ASK_THEN_DRIVE = """mission: ask_then_drive
steps:
  - ask: {id: door, question: "Is the door open?"}
    then:
      - drive: {distance: 0.3 m, speed: 0.2 m/s}
    else:
      - say: "staying"
"""
"""Answered yes, the robot drives; waiting for the answer, it stands: a replay without the answer never drives."""

CONSOLE_MISSION = """mission: console_everything
steps:
  - ask: {id: door, question: "Is the door open?"}
    then:
      - drive: {distance: 0.2 m, speed: 0.2 m/s}
  - ask: {id: done, question: "Done driving by hand?"}
  - drive: {distance: 0.1 m, speed: 0.2 m/s}
"""
"""Two questions: the operator answers the first, then pauses, resumes and drives before answering the second."""


def replays_identically(folder: Path, capsys: pytest.CaptureFixture) -> str:
    """Replay ``folder`` with ``beastbt replay``: assert exit 0 and no difference; return what it printed."""
    capsys.readouterr()
    code = main(["replay", str(folder)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "no difference" in out and "still running" not in out, out
    return out


def inputs_of(folder: Path) -> list[dict]:
    """The /operator/input messages of a run, each checked against the channel's schema."""
    messages = read_recording(folder / "run.mcap").topic("/operator/input")
    for m in messages:
        jsonschema.Draft202012Validator(CHANNELS["/operator/input"]).validate(m)
    return messages


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_run_answered_by_answer_replays_identically(tmp_path, capsys):
    folder, summary = record_run(write(tmp_path, "ask.yaml", ASK_THEN_DRIVE), tmp_path / "runs",
                                 answers={"door": "yes"})
    assert summary["status"] == "success" and summary["distance_m"] > 0.25
    out = replays_identically(folder, capsys)
    assert "recorded success, replay success" in out
    result = replay(str(folder))
    assert result.identical and result.ticks == summary["ticks"]


class _TypedLines:
    """A terminal's standard input for the test: a pipe with a line already typed (``select`` works on it)."""

    def __init__(self, text: str) -> None:
        r, w = os.pipe()
        os.write(w, text.encode())
        os.close(w)
        self._file = os.fdopen(r, "r")

    def isatty(self) -> bool:
        return True

    def fileno(self) -> int:
        return self._file.fileno()

    def readline(self) -> str:
        return self._file.readline()

    def close(self) -> None:
        self._file.close()


def test_a_run_answered_at_the_terminal_replays_identically(tmp_path, capsys, monkeypatch):
    stdin = _TypedLines("y\n")
    monkeypatch.setattr("sys.stdin", stdin)
    try:
        folder, summary = record_run(write(tmp_path, "ask.yaml", ASK_THEN_DRIVE), tmp_path / "runs",
                                     status_line=True)
    finally:
        stdin.close()
    assert summary["status"] == "success"
    assert any(e["kind"] == "answer" and "by terminal" in e["text"] for e in summary["events"])
    typed = inputs_of(folder)
    assert [(m["source"], m["control"], m["body"]) for m in typed] == [
        ("terminal", "answer", {"id": "door", "choice": "y"})]
    assert typed[0]["tick"] == 1  # typed before the run started: read after the first tick, counted in the next
    replays_identically(folder, capsys)
    assert without_the_inputs(folder, monkeypatch).replay_status is None  # it would still be waiting


JOYSTICK_TAKEOVER = [{"at": "0.5 s", "press": "enable"}, {"at": "0.6 s", "linear": 0.6, "angular": 0.4},
                     {"at": "1.2 s", "linear": 0, "angular": 0}, {"at": "1.3 s", "release": "enable"}]
"""The operator takes the robot over half-way through the drive, drives a curve, and hands it back."""


def test_a_joystick_take_over_of_an_answered_run_replays_identically(tmp_path, capsys):
    script = write(tmp_path, "js.yaml", json.dumps(JOYSTICK_TAKEOVER))
    folder, summary = record_run(write(tmp_path, "ask.yaml", ASK_THEN_DRIVE), tmp_path / "runs",
                                 answers={"door": "yes"}, joystick_script=str(script))
    assert summary["status"] == "success" and summary["teleop"]["takeovers"] == 1
    assert read_recording(folder / "run.mcap").topic("/cmd/teleop")
    replays_identically(folder, capsys)


@pytest.fixture
def console_run(tmp_path: Path):
    started: list[ConsoleRun] = []

    def start(text: str, *extra: str) -> ConsoleRun:
        run = ConsoleRun(write(tmp_path, "mission.yaml", text), "--runs-dir", str(tmp_path / "runs"),
                         "--speed", "realtime", *extra, cwd=tmp_path)
        started.append(run)
        return run
    yield start
    for run in started:
        run.kill()


def test_a_console_answer_a_pause_and_a_teleop_episode_replay_identically(console_run, tmp_path, capsys, monkeypatch):
    run = console_run(CONSOLE_MISSION)
    run.wait_state(lambda s: s["question"] is not None and s["question"]["id"] == "door", 20)
    assert run.api("/api/answer", {"id": "door", "choice": "yes"})[0] == 200
    run.wait_state(lambda s: s["question"] is not None and s["question"]["id"] == "done", 20)
    assert run.api("/api/pause", {})[0] == 200
    time.sleep(0.3)
    assert run.api("/api/resume", {})[0] == 200
    for _ in range(5):  # drive by hand (the mission pauses meanwhile), then let go of the deadman
        status, answer = run.api("/api/teleop", {"linear": 0.6, "angular": 0.5, "deadman": True})
        assert status == 200 and answer["driving"], answer
        time.sleep(0.1)
    assert run.api("/api/teleop", {"linear": 0.0, "angular": 0.0, "deadman": False})[0] == 200
    time.sleep(0.2)
    for _ in range(3):  # and once more, until the page goes silent: the stick is released by its timeout
        assert run.api("/api/teleop", {"linear": 0.0, "angular": -0.5, "deadman": True})[0] == 200
        time.sleep(0.1)
    time.sleep(0.5)
    run.wait_state(lambda s: s["question"] is not None and s["question"]["id"] == "done", 20)
    assert run.api("/api/answer", {"id": "done", "choice": "yes"})[0] == 200
    code, out, err = run.finish()
    assert code == 0 and "Traceback" not in err, err
    folder = next((tmp_path / "runs").iterdir())
    controls = [m["control"] for m in inputs_of(folder)]
    assert controls[:3] == ["answer", "pause", "resume"] and controls[-1] == "answer"
    assert controls.count("teleop") == 9 and "stick_silent" in controls
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["teleop"]["takeovers"] >= 2  # more when the loaded machine let a message come late
    replays_identically(folder, capsys)
    assert without_the_inputs(folder, monkeypatch).differing_ticks > 0


def without_the_inputs(folder: Path, monkeypatch: pytest.MonkeyPatch) -> ReplayResult:
    """The replay of ``folder`` when /operator/input is not read: the run the tree alone would have made."""
    monkeypatch.setattr("beastbt.replay.NOT_REPLAYED", NOT_REPLAYED + ("/operator/input",))
    return replay(str(folder))


def test_the_consoles_estop_replays_identically(console_run, tmp_path, capsys):
    run = console_run(ASK_THEN_DRIVE, "--answer", "door=yes")
    run.wait_state(lambda s: s["speed_mps"] > 0.05, 20)
    assert run.api("/api/estop", {})[0] == 200
    code, _, _ = run.finish()
    assert code == 1
    folder = next((tmp_path / "runs").iterdir())
    out = replays_identically(folder, capsys)
    assert "recorded stopped, replay stopped" in out
