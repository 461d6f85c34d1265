"""Asking the operator (mission language v2): the robot stands still until yes or no comes from a channel."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from beastbt.testing import MissionHarness
from conftest import REPO

DOOR = """mission: door_check
steps:
  - ask:
      id: door
      question: Is the door open?
      timeout: 5 s
      default: no
    then:
      - drive: {distance: 1 m}
    else:
      - say: "door closed, staying"
"""


def asked(h: MissionHarness) -> list[tuple[str, str]]:
    return [(e.kind, e.text) for e in h.events if e.kind in ("ask", "answer", "say")]


@pytest.mark.parametrize("answers, moved, who", [({"door": "yes"}, True, "script"), ({"door": "no"}, False, "script"),
                                                 (None, False, "timeout")])
def test_the_answer_chooses_the_branch_and_says_who_gave_it(answers, moved, who):
    h = MissionHarness.from_yaml(DOOR, answers=answers)
    assert h.run_to_end(60) == "success"
    assert (h.summary()["distance_m"] > 0.9) is moved
    choice = "yes" if moved else "no"
    assert ("answer", f"door: {choice} (by {who})") in asked(h)
    if who == "timeout":
        assert h.now_s >= 5.0


def test_without_a_timeout_it_waits_standing_still_then_an_answer_lets_it_go():
    h = MissionHarness.from_yaml("mission: q\nsteps:\n  - ask: {id: go, question: \"Drive?\"}\n"
                                 "    then: [drive: {distance: 0.5 m}]\n")
    h.tick_until(lambda h: h.now_s >= 30.0)
    assert h.result is None and h.summary()["distance_m"] == 0.0
    assert all(r.cmd_gate.is_zero() for r in h.records)
    assert h.run.ctx.services.questions.current().text == "Drive?"
    assert h.run.ctx.services.questions.answer("go", "y", "console")
    assert h.run_to_end(60) == "success" and h.summary()["distance_m"] > 0.4


def test_a_timeout_without_a_default_fails_and_answered_is_a_condition():
    h = MissionHarness.from_yaml("mission: q\nsteps:\n  - ask: {id: a, question: \"Ok?\", timeout: 2 s}\n")
    assert h.run_to_end(30) == "failure"
    later = MissionHarness.from_yaml("mission: q\nsteps:\n  - ask: {id: a, question: \"Ok?\"}\n"
                                     "  - if: {answered: a, is: yes}\n    then: [say: \"yes\"]\n    else: [say: nope]\n",
                                     answers={"a": "yes"})
    assert later.run_to_end(30) == "success" and ("say", "yes") in asked(later)


def test_answers_from_the_command_line(tmp_path):
    path = tmp_path / "door.yaml"
    path.write_text(DOOR)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run([sys.executable, "-m", "beastbt", "run", str(path), "--no-record", "--answer", "door=yes"],
                          capture_output=True, text=True, timeout=60, env=env)
    assert done.returncode == 0 and "answer: door: yes (by script)" in done.stdout
    bad = subprocess.run([sys.executable, "-m", "beastbt", "run", str(path), "--answer", "door=maybe"],
                         capture_output=True, text=True, timeout=60, env=env)
    assert bad.returncode == 2 and "is not ID=yes or ID=no" in bad.stderr


def test_the_docs_example_runs_by_its_timeout():
    import re
    doc = (REPO / "docs" / "mission-language.md").read_text(encoding="utf-8")
    text = re.search(r"```yaml\n(mission: door_check.*?)```", doc, re.S).group(1)
    h = MissionHarness.from_yaml(text)
    assert h.run_to_end(60) == "success" and ("say", "door closed, staying") in asked(h)


def test_an_answer_to_no_question_is_refused_and_an_unanswerable_question_says_how_to_answer(tmp_path):
    path = tmp_path / "door.yaml"
    path.write_text(DOOR.replace("timeout: 5 s", "timeout: 30 s"))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    typo = subprocess.run([sys.executable, "-m", "beastbt", "run", str(path), "--no-record", "--answer", "dor=yes"],
                          capture_output=True, text=True, timeout=60, env=env, stdin=subprocess.DEVNULL)
    assert typo.returncode == 2
    assert "no question 'dor'" in typo.stderr and "did you mean 'door'?" in typo.stderr
    assert "mission" not in typo.stdout  # refused before anything ran
    # No console, stdin not a terminal, no --answer: the run says at once that nobody can answer, and how.
    alone = subprocess.run([sys.executable, "-m", "beastbt", "run", str(path), "--no-record"],
                           capture_output=True, text=True, timeout=60, env=env, stdin=subprocess.DEVNULL)
    line = next(x for x in alone.stdout.splitlines() if "nobody can answer" in x)
    assert line.startswith("[    0.") and "--answer door=yes" in line and "--console" in line
    assert "answer: door: no (by timeout)" in alone.stdout
