"""Progress (steps done of planned, ETA) and the terminal's live status line."""

from __future__ import annotations

import io
import subprocess
import sys

import pytest

from beastbt.run.progress import planned, progress_of
from beastbt.run.session import CLEAR_LINE, _console_listener, status_line
from beastbt.testing import MissionHarness
from conftest import REPO

LOOPED = """mission: looped
steps:
  - drive: {distance: 0.3 m}
  - repeat:
      times: 3
      steps:
        - wait: 1 s
        - turn: {angle: 10 deg}
  - say: done
"""


def test_progress_counts_leaf_runs_through_loops_and_gives_an_eta():
    h = MissionHarness.from_yaml(LOOPED)
    assert planned(h.run.root) == 1 + 3 * 2 + 1
    seen = []
    while not h.done:
        h.tick()
        p = progress_of(h.run.root, h.run.mission_time_s)
        seen.append(p.done)
        assert p.total == 8 and 0 <= p.done <= 8
        if 0 < p.done < 8:
            assert p.eta_s is not None and p.eta_s > 0
    assert seen == sorted(seen)  # never goes back
    assert seen[0] == 0 and seen[-1] == 8 and len(set(seen)) >= 6  # steps that end in one tick may share it
    assert h.result == "success"


LONG_STEP = """mission: long_step
steps:
  - wait: 1 s
  - wait: 1 s
  - wait: 1 s
  - wait: 20 s
  - wait: 1 s
  - wait: 1 s
"""


def test_the_eta_does_not_grow_through_one_long_step_among_short_ones():
    h = MissionHarness.from_yaml(LONG_STEP)
    long_step = []  # (mission s, ETA s) while the long wait runs
    while not h.done:
        h.tick()
        p = progress_of(h.run.root, h.run.mission_time_s)
        if p.done == 3:
            long_step.append((h.run.mission_time_s, p.eta_s))
    assert h.result == "success"
    assert long_step[-1][0] - long_step[0][0] > 19.0
    etas = [eta for _, eta in long_step]
    # At its start: three steps left at the pace of the three done (1 s each); then it falls as the wait runs, and
    # holds at the two steps after it (2 s) once the wait has run longer than the pace: it never grows.
    assert etas[0] == pytest.approx(3.0, abs=0.15)
    assert all(later <= earlier + 1e-9 for earlier, later in zip(etas, etas[1:]))
    assert etas[-1] == pytest.approx(2.0, abs=0.15)
    after = progress_of(h.run.root, h.run.mission_time_s)
    assert after.done == 6 and after.eta_s == 0.0 and after.text() == "6/6 steps"


def test_the_eta_credits_the_running_step_and_keeps_the_steps_after_it():
    from beastbt.run.progress import eta_s
    assert eta_s(0, 6, 5.0, 5.0) is None  # no step done: no pace yet
    assert eta_s(3, 6, 3.0, 3.0) == pytest.approx(3.0)  # three left at 1 s each
    assert eta_s(3, 6, 3.5, 3.0) == pytest.approx(2.5)  # half of the running one gone
    assert eta_s(3, 6, 30.0, 3.0) == pytest.approx(2.0)  # it overran: the two after it are left
    assert eta_s(6, 6, 30.0, 29.0) == 0.0


def test_a_loop_without_a_count_has_no_total_and_no_eta():
    h = MissionHarness.from_yaml("mission: f\nsteps:\n  - repeat:\n      times: forever\n      steps:\n"
                                 "        - wait: 1 s\n")
    h.tick(60)
    p = progress_of(h.run.root, h.run.mission_time_s)
    assert p.total is None and p.eta_s is None and p.done >= 2
    assert p.text() == f"{p.done} steps"


def test_the_status_line_fits_the_terminal_and_shows_progress(monkeypatch):
    h = MissionHarness.from_file(REPO / "missions" / "patrol.yaml")
    h.tick(50)
    for columns in (40, 80, 200):
        monkeypatch.setenv("COLUMNS", str(columns))
        line = status_line(h.run)
        assert line.startswith(CLEAR_LINE)
        text = line[len(CLEAR_LINE):]
        assert len(text) <= columns - 1
        assert "/42 steps" in text
    assert "drive 3 m" in status_line(h.run)


def test_events_clear_the_status_line_on_a_terminal_only():
    from beastbt.core.events import Event
    tty, pipe = io.StringIO(), io.StringIO()
    _console_listener(tty, True)(Event(1.0, "say", "hello"))
    _console_listener(pipe, False)(Event(1.0, "say", "hello"))
    assert tty.getvalue().startswith(CLEAR_LINE)
    assert "\r" not in pipe.getvalue() and pipe.getvalue().strip().endswith("say: hello")


def test_a_run_into_a_pipe_writes_no_carriage_returns(tmp_path):
    out = subprocess.run([sys.executable, "-m", "beastbt", "run", str(REPO / "missions" / "patrol.yaml"), "--no-record"],
                         capture_output=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0
    assert b"\r" not in out.stdout and b"\x1b[" not in out.stdout
