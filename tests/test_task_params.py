"""Tasks with parameters (mission language v2): defaults, $name, do: {task, ...}, errors at the line of the use."""

from __future__ import annotations

import pytest

from beastbt.core.errors import InvalidInput
from beastbt.mission.model import load_mission
from beastbt.testing import MissionHarness

TASKS = """mission: params
tasks:
  look_side:
    params: {angle: 45 deg, hold: 2 s}     # the defaults; every parameter needs one
    steps:
      - look: {pan: $angle}
      - wait: $hold
      - look: {pan: 0 deg}
  plain:
    - wait: 1 s
steps:
  - do: look_side                          # the defaults
  - do: {task: look_side, angle: -30 deg}  # one parameter set
  - do: plain
"""


def test_defaults_and_arguments_drive_the_servo_and_the_time():
    h = MissionHarness.from_yaml(TASKS)
    assert h.run_to_end(60) == "success"
    assert h.summary()["servos"]["pan"] == [45.0, 0.0, -30.0, 0.0]
    assert 5.0 <= h.now_s < 8.0  # 2 s + 2 s + 1 s of waits, and the looks settling
    names = [n.name for n in h.run.nodes]
    assert "do look_side" in names and "do look_side (angle: -30 deg)" in names and "look pan -30 deg" in names


@pytest.mark.parametrize("use, line, column, says", [
    ("  - do: {task: look_side, angle: 3 s}\n", 12, 34, "'angle' of task 'look_side' is an angle"),
    ("  - do: {task: look_side, angel: 30 deg}\n", 12, 27, "has no parameter 'angel'; did you mean 'angle'?"),
    ("  - do: {task: plain, hold: 1 s}\n", 12, 23, "task 'plain' takes no parameters"),
    ("  - do: {task: look_sid}\n", 12, 16, "unknown task 'look_sid'; did you mean 'look_side'?"),
])
def test_wrong_calls_are_errors_at_the_line_of_the_use(tmp_path, use, line, column, says):
    path = tmp_path / "m.yaml"
    path.write_text(TASKS.split("steps:\n  - do: look_side")[0] + "steps:\n" + use)
    with pytest.raises(InvalidInput) as info:
        load_mission(path)
    text = info.value.format()
    assert f"m.yaml:{line}:{column}: error:" in text and says in text, text


def test_an_undeclared_name_is_an_error_once_at_its_line(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text(TASKS.replace("- wait: $hold", "- wait: $hodl"))
    with pytest.raises(InvalidInput) as info:
        load_mission(path)
    assert len(info.value.problems) == 1
    assert "m.yaml:7:15: error: '$hodl' is not a parameter of task 'look_side'; did you mean 'hold'?" in \
        info.value.format()


def test_the_docs_example_runs():
    import re
    from conftest import REPO
    doc = (REPO / "docs" / "mission-language.md").read_text(encoding="utf-8")
    text = re.search(r"```yaml\n(mission: look_both_ways.*?)```", doc, re.S).group(1)
    h = MissionHarness.from_yaml(text)
    assert h.run_to_end(60) == "success" and h.summary()["servos"]["pan"] == [45.0, 0.0, -30.0, 0.0]


@pytest.mark.parametrize("declared, column, says", [
    ("{angle: 45 deg, hold}", 29, "parameter 'hold' of task 'look_side' has no default"),
    ("{angle: 45 deg, hold: [1, 2]}", 35, "parameter 'hold' of task 'look_side' has a list as its default"),
])
def test_a_parameter_without_a_default_is_one_error_at_its_declaration_in_words(tmp_path, declared, column, says):
    path = tmp_path / "m.yaml"
    path.write_text("mission: p\ntasks:\n  look_side:\n    params: " + declared + "\n    steps:\n"
                    "      - look: {pan: $angle}\n      - wait: $hold\nsteps:\n  - do: {task: look_side, angle: -30 deg}\n")
    with pytest.raises(InvalidInput) as info:
        load_mission(path)
    text = info.value.format()
    assert len(info.value.problems) == 1, text
    assert f"m.yaml:4:{column}: error: {says}" in text and "every parameter needs a default" in text
    assert "NoneType" not in text and "list'" not in text


def test_a_value_of_the_wrong_shape_is_named_in_words_not_python_types(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("mission: p\nsteps:\n  - wait: {}\n")
    with pytest.raises(InvalidInput) as info:
        load_mission(path)
    assert "dict" not in info.value.format() and "mapping" in info.value.format()
