"""Broken missions: each kind of mistake is rejected with exit 2 at the right line and column,
and none of them starts the simulator."""

from __future__ import annotations

import pytest

from beastbt import cli

OK_HEAD = "mission: t\nsteps:\n"

# (id, text, line, column, words the message must contain)
CASES = [
    ("yaml_syntax", "mission: t\nsteps: [drive: {distance: 3 m}\n", 2, 31, "the '[' at line 2 column 8 is never closed"),
    ("tab_indent", "mission: t\nsteps:\n\t- wait: 2 s\n", 3, 1, "tab character"),
    # Where the author must type: after the word that lacks its colon, at the quote or brace left open.
    ("step_missing_colon", OK_HEAD + "  - drive {distance: 1 m}\n", 3, 10, "missing ':' after 'drive'"),
    ("key_missing_colon", OK_HEAD + "  - drive:\n      distance 3 m\n      speed: 0.2 m/s\n", 4, 15,
     "missing ':' after 'distance'"),
    ("unclosed_quote", OK_HEAD + '  - say: "hello\n  - wait: 1 s\n', 3, 10, "never closed"),
    ("unclosed_brace", OK_HEAD + "  - drive: {distance: 1 m\n  - wait: 1 s\n", 3, 26, "the '{' at line 3 column 12"),
    ("until_mapping", OK_HEAD + "  - follow_line: {until: {meters: 3}}\n", 3, 26, "until: {distance: 3 m}"),
    ("turn_both", OK_HEAD + "  - turn: {angle: 90 deg, heading: 10 deg}\n", 3, 27, "either 'angle' or 'heading'"),
    ("times_infinite", OK_HEAD + "  - repeat: {times: infinite, steps: [wait: 1 s]}\n", 3, 21, "times: forever"),
    ("if_without_then", OK_HEAD + "  - if: gps_fix\n", 3, 5, "'if' needs 'then:'"),
    ("duplicate_key", "mission: t\nmission: u\nsteps: [stop]\n", 2, 1, "duplicate key 'mission'"),
    ("empty_file", "", 1, 1, "empty"),
    ("top_not_mapping", "- mission: t\n- steps: []\n", 1, 1, "top level must be a mapping"),
    ("unknown_top_key", "mission: t\nstpes: [stop]\nsteps: [stop]\n", 2, 1, "unknown key 'stpes'"),
    ("unknown_step", OK_HEAD + "  - folow_line: {until: intersection}\n", 3, 5, "did you mean 'follow_line'"),
    ("unknown_bare_step", OK_HEAD + "  - stpo\n", 3, 5, "unknown step 'stpo'; did you mean 'stop'"),
    ("unknown_step_key", OK_HEAD + "  - drive: {distance: 3 m, sped: 0.2 m/s}\n", 3, 28, "unknown key 'sped'"),
    ("wrong_type", OK_HEAD + "  - repeat: {times: three, steps: [stop]}\n", 3, 21, "times"),
    ("wrong_unit_kind", OK_HEAD + "  - drive: {distance: 3 s}\n", 3, 23, "expected a distance"),
    ("angle_without_unit", OK_HEAD + "  - turn: {angle: 90}\n", 3, 19, "angle needs a unit"),
    ("negative_speed", OK_HEAD + "  - drive: {distance: 3 m, speed: -0.2 m/s}\n", 3, 35, "speed must be greater than zero"),
    ("zero_speed", OK_HEAD + "  - follow_line: {speed: 0 m/s, until: line_end}\n", 3, 26, "speed must be greater than zero"),
    ("unknown_task", OK_HEAD + "  - do: look_arund\n", 3, 9, "unknown task 'look_arund'"),
    ("unknown_place", "mission: t\nplaces:\n  gate: {lat: 1, lon: 2}\nsteps:\n  - go_to: gat\n", 5, 12, "unknown place 'gat'; did you mean 'gate'"),
    ("self_calling_task", "mission: t\ntasks:\n  a:\n    - wait: 1 s\n    - do: a\nsteps: [do: a]\n", 5, 11, "task 'a' calls itself"),
    ("mutual_recursion", "mission: t\ntasks:\n  a: [do: b]\n  b: [do: a]\nsteps: [do: a]\n", 3, 11, "calls itself"),
    ("missing_mission", "steps: [stop]\n", 1, 1, "missing 'mission'"),
    ("missing_steps", "mission: t\n", 1, 1, "missing 'steps'"),
    ("bad_rate", "mission: t\nrate: 500 Hz\nsteps: [stop]\n", 2, 7, "1 to 100 Hz"),
    ("bad_name", "mission: my mission\nsteps: [stop]\n", 1, 10, "not a valid name"),
    ("unknown_condition", OK_HEAD + "  - wait_until: intersectoin\n", 3, 17, "unknown condition 'intersectoin'"),
    # a mapping where a word (none) is also allowed: the mapping's own keys are explained, not "a mapping is not allowed"
    ("recovery_misspelt", OK_HEAD + "  - go_to: {lat: 40.4, lon: -3.7, recovery: {tris: 3}}\n", 3, 46,
     "unknown key 'tris' in 'recovery'; did you mean 'tries'"),
]


@pytest.fixture
def no_simulator(monkeypatch):
    """Fail the test if anything tries to build the simulated robot."""
    def boom(*a, **k):
        raise AssertionError("the simulator was started for an invalid mission")
    monkeypatch.setattr("beastbt.sim.robot.build_simulator", boom)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_broken_mission_is_rejected_at_its_position(case, write_mission, capsys, no_simulator):
    _, text, line, col, words = case
    path = write_mission(text)
    assert cli.main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:{line}:{col}: error:" in err, err
    assert words in err, err
    assert cli.main(["run", str(path), "--no-record"]) == 2
    assert f"{path}:{line}:{col}: error:" in capsys.readouterr().err


def test_all_problems_of_a_file_are_reported_in_one_run(write_mission, capsys):
    path = write_mission(OK_HEAD + "  - stpo\n  - turn: {angle: 90}\n  - do: nowhere\n")
    assert cli.main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 3
    assert f"{path}:3:5:" in err and f"{path}:4:" in err and f"{path}:5:" in err


def test_errors_carry_a_hint(write_mission, capsys):
    path = write_mission(OK_HEAD + "  - bogus_step\n")
    cli.main(["validate", str(path)])
    err = capsys.readouterr().err
    assert "hint: the steps are:" in err


def test_valid_files_pass_and_missing_file_is_invalid(write_mission, capsys, tmp_path):
    good = write_mission(OK_HEAD + "  - wait: 1 s\n")
    assert cli.main(["validate", str(good)]) == 0
    assert cli.main(["validate", str(tmp_path / "nope.yaml")]) == 2
    assert "file not found" in capsys.readouterr().err


def test_bad_world_is_rejected_before_moving(write_mission, capsys, no_simulator):
    world = write_mission("world: w\nstart: {x: 0, y: 0, yaw: 3}\n", "w.yaml")
    mission = write_mission("mission: t\nworld: w.yaml\nsteps: [stop]\n")
    assert cli.main(["run", str(mission), "--no-record"]) == 2
    err = capsys.readouterr().err
    assert f"{world}:2:" in err and "unknown key 'yaw'" in err and "yaw_deg" in err


@pytest.mark.parametrize("text, where, says", [
    # steps: written at the level of the step, not under repeat: with its times:
    ("  - repeat:\n      times: 3\n    steps:\n      - drive: {distance: 1 m}\n", "5:5",
     "'steps' belongs under 'repeat:' (line 3): indent it 2 more spaces, to line up with 'times:' on line 4"),
    # nothing indented under repeat: at all
    ("  - repeat:\n    times: 3\n    steps:\n      - drive: {distance: 1 m}\n", "4:5",
     "'times', 'steps' belong under 'repeat:' (line 3): indent them further than it"),
    # then: of an ask written inside the ask's own mapping
    ("  - ask:\n      id: door\n      question: Open?\n      then:\n        - drive: {distance: 1 m}\n", "6:7",
     "'then' belongs beside 'ask:', not under it: indent it 2 fewer spaces, to line up with 'ask:' on line 3"),
])
def test_a_key_at_the_wrong_indentation_is_told_to_indent_once(write_mission, capsys, text, where, says):
    path = write_mission("mission: p\nsteps:\n" + text)
    assert cli.main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f":{where}: error: {says}" in err
    assert err.count("error:") == 1, err  # no "unknown key", no "needs 'steps:'" besides


@pytest.mark.parametrize("text, where", [
    ("  - go_to: {lat: 40.4, lon: -3.7, recovery: {tries: 2, wait_s: 3}}\n", "3:56"),
    ("  - go_to:\n      lat: 40.4\n      lon: -3.7\n      recovery:\n        tries: 3\n        wait_s: 2\n", "8:9"),
])
def test_a_key_that_fits_nowhere_is_unknown_not_told_to_indent(write_mission, capsys, text, where):
    """A profile knob under a step's recovery: moved beside 'recovery:' it would be just as wrong (go_to has no
    wait_s), so the author hears that it is unknown here, not to indent it (the step's oneOf hid that)."""
    path = write_mission("mission: p\nsteps:\n" + text)
    assert cli.main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f":{where}: error: unknown key 'wait_s' in 'recovery'" in err, err
    assert "indent" not in err, err
