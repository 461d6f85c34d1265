"""Live tuning (beastbt.live.tuning): knobs from the profile's schema, bound to the run's live objects.

A change goes through the console's control (``tune``), as the page and the
HTTP API send it: it is in force from the next tick, refused with the range
when out of it, an event and an operator input (``/operator/input``), so the
run's replay makes it again and is identical. Saving writes the changed values
into the profile's file with its comments and layout kept.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import pytest

from beastbt.assembly import prepare
from beastbt.live.console_control import ConsoleControls, Refused
from beastbt.live.tuning import KNOBS, knob_schema, save_profile_text, tuning_of
from beastbt.recording.reader import read_recording
from beastbt.replay import NOT_REPLAYED, replay
from beastbt.robot.part import Part
from beastbt.robot.profile import load_profile
from beastbt.run.session import RunOptions, execute
from beastbt.testing import MissionHarness
from conftest import REPO

LINE = REPO / "missions" / "line_to_intersection.yaml"
"""Follows the tape of the line track at 0.12 m/s: the line follower's knobs are in use from the start."""


def control(controls: ConsoleControls, name: str, body: dict, now_s: float) -> dict:
    """Carry out one console control now, as the console's tick hook does; its answer (raises Refused)."""
    future = controls.submit(name, body)
    controls.apply_pending(now_s)
    return future.result(0)


@pytest.fixture
def line_run():
    h = MissionHarness.from_file(LINE)
    return h, ConsoleControls(h.run, wall=lambda: 0.0)


def test_each_knob_takes_its_title_unit_range_and_default_from_the_profile_schema(line_run):
    h, controls = line_run
    h.tick()
    knobs = {k["name"]: k for k in control(controls, "tuning", {}, h.now_s)["knobs"]}
    speed = knobs["limits.max_speed_mps"]
    assert (speed["title"], speed["unit"], speed["min"], speed["min_exclusive"]) == ("Max speed (m/s)", "m/s", 0, True)
    assert speed["max"] == speed["profile"] == speed["value"] == 0.35  # the profile's own limit is the top
    curve = knobs["line_follower.curve_slowdown_m"]
    assert (curve["unit"], curve["default"], curve["min"], curve["min_exclusive"]) == ("m", 0.2, 0, False)
    assert knobs["collision_monitor.slow.ratio"]["max"] == 1 and knobs["collision_monitor.slow.ratio"]["default"] == 0.3
    assert knobs["collision_monitor.min_points"]["integer"] and knobs["collision_monitor.min_points"]["value"] == 3
    assert knobs["local_planner.goal_dist_scale"]["default"] == 2.0
    assert "localisation.lost_quality" not in knobs  # no saved map, no localiser: nothing to bind it to
    assert knobs["collision_monitor.slow.ratio"]["title"] == "Slow zone ratio"  # a nested knob: its parent names it
    for name, k in knobs.items():  # every one as the schema states it
        prop = knob_schema(name)
        assert k["title"].endswith(prop["title"].lower() if name.count(".") > 1 else prop["title"]), name
        assert k["default"] == prop.get("default"), name
    assert {spec.name.split(".")[0] for spec in KNOBS} >= {"limits", "line_follower", "collision_monitor",
                                                          "local_planner", "navigation", "localisation"}


def test_a_value_outside_its_range_is_refused_with_the_range(line_run):
    h, controls = line_run
    h.tick()
    for name, value, words in (("limits.max_speed_mps", 0.5, "above 0 and at most 0.35 m/s"),
                               ("limits.max_speed_mps", 0, "above 0 and at most 0.35 m/s"),
                               ("collision_monitor.slow.ratio", 1.5, "above 0 and at most 1"),
                               ("collision_monitor.min_points", 2.5, "whole number"),
                               ("line_follower.nope", 1, "the knobs are limits.max_speed_mps")):
        with pytest.raises(Refused) as refused:
            control(controls, "tune", {"name": name, "value": value}, h.now_s)
        assert refused.value.status == 400 and words in str(refused.value), str(refused.value)
    assert h.run.gate.limits.max_speed_mps == 0.35 and h.run.inputs.count == 0  # nothing changed, nothing recorded


def test_a_lower_speed_limit_is_in_force_at_the_next_tick(line_run):
    h, controls = line_run
    assert h.tick_until(lambda h: h.run.last_sent.linear_mps > 0.11, 20)
    answer = control(controls, "tune", {"name": "limits.max_speed_mps", "value": 0.06}, h.now_s)
    assert answer == {"name": "limits.max_speed_mps", "value": 0.06, "was": 0.35}
    changed_at = h.now_s
    h.tick()
    assert h.records[-1].cmd_mission.linear_mps <= 0.06  # the follower asks for no more at the next tick
    assert h.run.last_sent.linear_mps < 0.11  # and the gate is bringing the wheels down, at its deceleration
    assert h.tick_until(lambda h: h.run.last_sent.linear_mps <= 0.06 + 1e-9, 1.0)
    assert h.now_s - changed_at <= 0.2
    assert any(e.kind == "tuning" and "limits.max_speed_mps: 0.35 -> 0.06 m/s" in e.text for e in h.run.events.events)
    assert control(controls, "tune_reset", {}, h.now_s) == {"reset": ["limits.max_speed_mps"]}
    h.tick()
    assert h.run.gate.limits.max_speed_mps == 0.35 and h.records[-1].cmd_mission.linear_mps == 0.12


def test_the_followers_speed_is_read_at_each_tick():
    """A step that gives no speed follows at ``line_follower.default_speed_mps``: tuned, the next tick uses it."""
    h = MissionHarness.from_yaml(f"mission: line_default\nworld: {REPO / 'worlds' / 'line_track.yaml'}\nsteps:\n"
                                 f"  - follow_line: {{until: {{distance: 2 m}}}}\n")
    controls = ConsoleControls(h.run, wall=lambda: 0.0)
    assert h.tick_until(lambda h: h.records and h.records[-1].cmd_mission is not None
                        and h.records[-1].cmd_mission.linear_mps > 0.1, 20)
    assert control(controls, "tune", {"name": "line_follower.default_speed_mps", "value": 0.05}, h.now_s)["was"] == 0.12
    h.tick()
    assert 0 < h.records[-1].cmd_mission.linear_mps <= 0.05


def test_the_planner_and_monitor_knobs_reach_their_objects(line_run):
    h, controls = line_run
    h.tick()
    control(controls, "tune", {"name": "collision_monitor.slow.ratio", "value": 0.5}, h.now_s)
    control(controls, "tune", {"name": "local_planner.obstacle_scale", "value": 3.0}, h.now_s)
    control(controls, "tune", {"name": "limits.max_turn_rate_dps", "value": 60}, h.now_s)
    assert h.run.collision_monitor.config.slow.ratio == 0.5
    navigator = h.run.ctx.services.local_navigator
    assert navigator.planner.config.obstacle_scale == navigator.planner_config.obstacle_scale == 3.0
    assert math.isclose(h.run.gate.limits.max_turn_rate_rps, math.radians(60))
    h.tick(30)
    line = tuning_of(h.run).state()["line"]  # the line follower's error, for the page's plot
    assert line["seen"] and abs(line["offset_m"]) < 0.05 and line["t"] > 0
    assert tuning_of(h.run).changes() == {"collision_monitor.slow.ratio": 0.5, "local_planner.obstacle_scale": 3.0,
                                          "limits.max_turn_rate_dps": 60.0}


def test_a_run_with_a_speed_change_replays_identically(tmp_path):
    """The change is an operator input at the tick it was made in: the replay makes it there again. Without that
    input the replay differs (the change did act)."""
    p = prepare(str(LINE), RunOptions(seed=1, runs_dir=str(tmp_path / "runs"), max_time_s=12.0))
    run = p.run
    controls = ConsoleControls(run, wall=lambda: 0.0)
    changes = {60: ("limits.max_speed_mps", 0.07), 120: ("line_follower.curve_slowdown_m", 0.5),
               160: ("limits.max_speed_mps", 0.3)}

    def operator(r, now_s):  # where the console's hook is: after the parts' own hooks
        if r.ticks in changes:
            name, value = changes[r.ticks]
            controls.submit("tune", {"name": name, "value": value})
        controls.apply_pending(now_s)
    at = next((i for i, hook in enumerate(run.hooks) if not isinstance(getattr(hook, "__self__", None), Part)),
              len(run.hooks))
    run.hooks.insert(at, operator)
    summary = execute(p, io.StringIO())
    folder = p.folder.path
    inputs = read_recording(folder / "run.mcap").topic("/operator/input")
    assert [(m["tick"], m["control"], m["body"]["name"]) for m in inputs] == [
        (60, "tune", "limits.max_speed_mps"), (120, "tune", "line_follower.curve_slowdown_m"),
        (160, "tune", "limits.max_speed_mps")]
    assert sum(e["kind"] == "tuning" for e in summary["events"]) == 3
    result = replay(str(folder))
    assert result.identical and result.ticks == summary["ticks"], result.differences[:3]
    import beastbt.replay as replay_module
    original = replay_module.NOT_REPLAYED
    replay_module.NOT_REPLAYED = NOT_REPLAYED + ("/operator/input",)
    try:
        assert replay(str(folder)).differing_ticks > 0
    finally:
        replay_module.NOT_REPLAYED = original


SIM_PROFILE = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")


def test_saving_writes_the_changed_values_and_keeps_every_comment(tmp_path):
    values = {"limits.max_speed_mps": 0.2, "collision_monitor.slow.ratio": 0.45, "line_follower.curve_slowdown_m": 0.3,
              "collision_monitor.min_points": 4}
    new = save_profile_text(SIM_PROFILE, values, frozenset({"collision_monitor.min_points"}))
    old_lines, new_lines = SIM_PROFILE.splitlines(), new.splitlines()
    comments = [line for line in old_lines if "#" in line]
    kept = [line for line in new_lines if "#" in line]
    assert len(kept) == len(comments)
    changed = [(a, b) for a, b in zip(old_lines, new_lines) if a != b]
    assert changed[0] == ("  max_speed_mps: 0.35        # the Beast's top speed is about 0.35 m/s",
                          "  max_speed_mps: 0.2         # the Beast's top speed is about 0.35 m/s")
    path = tmp_path / "robot.yaml"
    path.write_text(new, encoding="utf-8")
    profile = load_profile(path)  # still a valid profile, with the values in it
    assert profile.max_speed_mps == 0.2
    assert profile.data["collision_monitor"]["slow"]["ratio"] == 0.45
    assert profile.data["collision_monitor"]["min_points"] == 4
    assert profile.data["line_follower"]["curve_slowdown_m"] == 0.3
    assert save_profile_text(SIM_PROFILE, {}) == SIM_PROFILE  # nothing changed: byte for byte


def test_save_through_the_console_controls_writes_the_profile_and_moves_the_reset_point(tmp_path):
    from beastbt.live.tuning import save_through
    robot = tmp_path / "robot.yaml"
    robot.write_text(SIM_PROFILE, encoding="utf-8")
    h = MissionHarness.from_file(LINE, robot=str(robot))
    controls = ConsoleControls(h.run, wall=lambda: 0.0)
    h.tick()
    control(controls, "tune", {"name": "limits.max_speed_mps", "value": 0.25}, h.now_s)

    class Ticking:  # the tick thread answers the controls save_through waits for
        def submit(self, name, body):
            future = controls.submit(name, body)
            controls.apply_pending(h.now_s)
            return future
    answer = save_through(Ticking(), 1.0)
    assert answer["saved"] == ["limits.max_speed_mps"] and answer["profile_file"] == str(robot)
    assert "  max_speed_mps: 0.25        # the Beast's top speed is about 0.35 m/s" in robot.read_text()
    assert control(controls, "tune_reset", {}, h.now_s) == {"reset": []}  # the saved value is the profile's now
    assert h.run.gate.limits.max_speed_mps == 0.25


def test_the_station_relays_tuning_to_the_robots_run(tmp_path):
    """A robot's agent answers the station's ``tuning``, ``tune``, ``tune_reset`` and ``tune_save`` (its queryables
    ``beastbt/<name>/cmd/<control>``) through the run's console controls, as the console's page does."""
    pytest.importorskip("zenoh")
    from types import SimpleNamespace

    from beastbt.fleet import keys
    from beastbt.fleet.agent import FleetAgent
    from beastbt.fleet.config import FleetOptions
    assert {"tuning", "tune", "tune_reset", "tune_save"} <= set(keys.CONTROLS)
    robot = tmp_path / "robot.yaml"
    robot.write_text(SIM_PROFILE, encoding="utf-8")
    h = MissionHarness.from_file(LINE, robot=str(robot))
    controls = ConsoleControls(h.run, wall=lambda: 0.0)
    h.tick()

    class Ticking:  # the run's tick thread, answering at once
        def submit(self, name, body):
            future = controls.submit(name, body)
            controls.apply_pending(h.now_s)
            return future
    agent = FleetAgent("beast", FleetOptions("tcp/127.0.0.1:1"))  # not started: its controls are called directly
    agent.link = SimpleNamespace(run=h.run, controls=Ticking())
    ok, listing = agent.control("tuning", b"{}")
    assert ok and "limits.max_speed_mps" in {k["name"] for k in listing["knobs"]}
    assert agent.control("tune", b'{"name": "limits.max_speed_mps", "value": 0.9}') == (
        False, {"status": 400, "error": "limits.max_speed_mps = 0.9 is out of range: above 0 and at most 0.35 m/s"})
    assert agent.control("tune", b'{"name": "limits.max_speed_mps", "value": 0.2}')[0]
    assert h.run.gate.limits.max_speed_mps == 0.2
    ok, saved = agent.control("tune_save", b"{}")
    assert ok and saved["saved"] == ["limits.max_speed_mps"] and "max_speed_mps: 0.2 " in robot.read_text()
    assert agent.control("tune_reset", b"{}") == (True, {"reset": []})


def test_the_consoles_knobs_table_lists_every_knob_with_its_schema_default():
    text = (REPO / "docs" / "console.md").read_text(encoding="utf-8")
    rows = {cells[0].strip("` "): cells for cells in
            (line.strip("|").split("|") for line in text.splitlines() if line.startswith("| `") and "." in line)}
    for spec in KNOBS:
        assert spec.name in rows, f"docs/console.md's knobs table has no {spec.name}"
        default = knob_schema(spec.name).get("default")
        written = rows[spec.name][3].strip()
        assert written == "(the profile's)" if default is None else float(written) == default, spec.name


def test_a_navigation_knob_reaches_the_running_step_and_its_sliders_show_while_it_drives():
    from py_trees.common import Status

    from beastbt.behaviours.navigation import GoTo
    h = MissionHarness.from_file(REPO / "missions" / "gps_route.yaml", seed=1)
    controls = ConsoleControls(h.run, wall=lambda: 0.0)
    driving = lambda h: [n for n in h.run.nodes if isinstance(n, GoTo) and n.status == Status.RUNNING]  # noqa: E731
    assert h.tick_until(lambda h: bool(driving(h)), 30)
    assert {"navigation", "local_planner"} <= set(tuning_of(h.run).active_groups())
    control(controls, "tune", {"name": "navigation.default_blocked_after_s", "value": 45}, h.now_s)
    assert h.run.ctx.services.navigation.default_blocked_after_s == 45.0
    assert all(n.nav.default_blocked_after_s == 45.0 for n in driving(h))  # the step under way reads it next tick
    h.tick()
    assert driving(h) and driving(h)[0].nav.default_blocked_after_s == 45.0


def test_a_profile_installed_inside_the_package_is_not_saved_to(monkeypatch):
    """Installed, ``--robot sim`` is a file inside the package: saving is refused with how to save instead."""
    from beastbt.live import tuning
    h = MissionHarness.from_file(LINE)
    controls = ConsoleControls(h.run, wall=lambda: 0.0)
    h.tick()
    control(controls, "tune", {"name": "limits.max_speed_mps", "value": 0.25}, h.now_s)
    monkeypatch.setattr(h.run.profile, "file", str(Path(tuning.__file__).parent / "robots" / "sim.yaml"))

    class Ticking:
        def submit(self, name, body):
            future = controls.submit(name, body)
            controls.apply_pending(h.now_s)
            return future
    with pytest.raises(Refused) as refused:
        tuning.save_through(Ticking(), 1.0)
    assert refused.value.status == 409 and "--robot my_robot.yaml" in str(refused.value)
    assert tuning_of(h.run).changes() == {"limits.max_speed_mps": 0.25}  # kept: still to be saved elsewhere
