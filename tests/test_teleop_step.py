"""The teleop step, on_failure: teleop, failsafes handing over, and the Teleop-only example mission."""

from __future__ import annotations

import io
import json

import pytest
from conftest import REPO

from beastbt import cli
from beastbt.assembly import prepare
from beastbt.run.session import RunOptions, execute
from beastbt.testing import MissionHarness

HAND = """
mission: t
steps:
  - teleop: {until: released}
  - say: "back to the mission"
"""


def test_teleop_step_without_a_joystick_fails_no_joystick():
    h = MissionHarness.from_yaml(HAND)
    assert h.tick() == "failure"
    said = h.node("teleop until released").feedback_message
    assert said.startswith("no joystick: on the simulator") and "--joystick FILE" in said and "--console" in said


def test_with_an_operator_console_the_teleop_step_waits_for_its_stick_instead_of_failing():
    h = MissionHarness.from_yaml(HAND)
    h.run.ctx.services.teleop.remote_attached = True  # what the console does when it serves the run
    for _ in range(20):
        h.tick()
    assert h.run.status is None and h.status_of("teleop until released") == "RUNNING"
    assert "waiting for the operator" in h.node("teleop until released").feedback_message


def test_until_released_waits_for_the_operator_then_succeeds_on_release():
    h = MissionHarness.from_yaml(HAND + "teleop: false\n", joystick=[
        {"at": "1 s", "linear": 1.0}, {"at": "2 s", "press": "enable"}, {"at": "4 s", "release": "enable"}])
    h.tick_until(lambda h: h.now_s >= 1.9)
    assert h.status_of("teleop until released") == "RUNNING"
    assert all(r.cmd_gate.is_zero() for r in h.records)  # sticks alone do not drive
    assert "waiting for the operator" in h.node("teleop until released").feedback_message
    h.tick_until(lambda h: h.now_s >= 2.05)
    # teleop: false, yet inside the step the operator drives, and the mission is not paused.
    assert h.records[-1].mux_source == "teleop" and h.records[-1].cmd_gate.linear_mps > 0
    assert h.run.paused_by is None
    h.tick_until(lambda h: h.now_s >= 3.95)
    assert h.status_of("teleop until released") == "RUNNING"
    assert h.truth.x > 0.3
    h.tick_until(lambda h: h.now_s >= 4.05)  # the release tick
    assert h.status_of("teleop until released") == "SUCCESS"
    assert h.records[-1].cmd_mux.is_zero()
    assert h.run_to_end(5) == "success"
    assert any(e.kind == "say" for e in h.events)


def test_teleop_for_a_time():
    h = MissionHarness.from_yaml("""
mission: t
steps:
  - teleop: {for: 3 s}
""", joystick=[{"at": "0.5 s", "press": "enable"}, {"at": "0.5 s", "angular": 1.0}])
    assert h.tick_until(lambda h: h.done, 10)
    assert h.result == "success"
    assert h.now_s == pytest.approx(3.05, abs=0.06)
    assert h.truth.yaw > 0.5  # the operator turned it left in the meantime
    assert h.blackboard("teleop_active") is True  # still held when the step ended


def test_on_failure_teleop_hands_over_until_the_run_ends(tmp_path):
    mission = tmp_path / "m.yaml"
    mission.write_text("""
mission: failing
steps:
  - servo: {name: gripper, angle: 10 deg}
on_failure: teleop
""")
    script = tmp_path / "js.yaml"
    script.write_text("""
- {at: 2 s, linear: 1.0}
- {at: 3 s, press: enable}
- {at: 5 s, release: enable}
""")
    p = prepare(str(mission), RunOptions(record=False, max_time_s=8.0, simulate=True, joystick_script=str(script)))
    records: list = []
    p.run.recorders.append(records.append)
    summary = execute(p, io.StringIO())
    assert summary["status"] == "stopped"  # ended by the max time, as the operator would end it
    texts = [(e["kind"], e["text"]) for e in summary["events"]]
    assert any(k == "on_failure" and "teleop" in t for k, t in texts)
    assert any(k == "teleop" and "until the run is ended" in t for k, t in texts)
    before = [r for r in records if r.now_s < 2.99]  # (the clock sums 0.05 s steps: 3.0 is 2.9999...)
    assert all(r.cmd_gate.is_zero() for r in before)
    held = [r for r in records if 2.99 <= r.now_s < 4.99]
    assert held and all(r.mux_source == "teleop" for r in held) and held[-1].cmd_gate.linear_mps > 0.2
    after = [r for r in records if r.now_s >= 5.09]
    assert after and all(r.mux_source != "teleop" for r in after)
    assert p.run.paused_by == "on_failure teleop"  # released: the robot stays stopped, the mission does not resume
    assert summary["truth"]["final_pose"]["x"] > 0.4


def test_on_failure_teleop_without_a_joystick_fails():
    h = MissionHarness.from_yaml("""
mission: t
steps:
  - servo: {name: gripper, angle: 10 deg}
on_failure: teleop
""")
    assert h.tick() == "failure"
    assert any("no joystick" in e.text for e in h.events if e.kind == "teleop")


def test_battery_low_failsafe_on_the_simulated_battery(tmp_path):
    world = tmp_path / "w.yaml"
    world.write_text("world: low\nbattery: {start_v: 11.0, drain_v_per_s: 0.001}\n")
    text = """
mission: t
steps:
  - wait: 60 s
failsafes:
  battery_low: {below: 11.5 V, for: 2 s, then: stop}
"""
    h = MissionHarness.from_yaml(text, world=str(world))
    assert h.run_to_end(30) == "failure"
    assert h.blackboard("battery").voltage_v == pytest.approx(11.0, abs=0.01)
    assert 2.0 <= h.now_s <= 2.3
    assert any(e.kind == "failsafe" and "battery_low" in e.text for e in h.events)
    # A full battery never triggers it.
    world.write_text("world: full\nbattery: {start_v: 12.3}\n")
    h = MissionHarness.from_yaml(text.replace("wait: 60 s", "wait: 5 s"), world=str(world))
    assert h.run_to_end(30) == "success"


def test_battery_low_then_teleop_hands_over(tmp_path):
    world = tmp_path / "w.yaml"
    world.write_text("world: low\nbattery: {start_v: 11.0}\n")
    h = MissionHarness.from_yaml("""
mission: t
steps:
  - drive: {distance: 5 m, speed: 0.2 m/s}
failsafes:
  battery_low: {below: 11.5 V, for: 1 s, then: teleop}
""", world=str(world), joystick=[{"at": "3 s", "press": "enable"}, {"at": "3 s", "linear": -1.0}])
    h.tick_until(lambda h: h.now_s >= 1.5)
    assert h.run.paused_by == "failsafe teleop (battery_low)" and h.result is None
    h.tick_until(lambda h: h.now_s >= 2.9)
    assert h.records[-1].cmd_gate.is_zero()  # handed over: the mission no longer drives
    h.tick_until(lambda h: h.now_s >= 3.5)
    assert h.records[-1].mux_source == "teleop" and h.records[-1].cmd_gate.linear_mps < 0


def test_teleop_example_runs_with_the_example_joystick(tmp_path):
    summary = tmp_path / "s.json"
    code = cli.main(["run", str(REPO / "missions" / "teleop.yaml"), "--joystick",
                     str(REPO / "missions" / "joystick/teleop_demo.yaml"), "--no-record", "--summary", str(summary)])
    s = json.loads(summary.read_text())
    assert code == 0 and s["status"] == "success"
    assert s["sim_time_s"] == pytest.approx(6.5, abs=0.06)  # ends on the release in the script
    assert s["distance_m"] > 1.0
    assert cli.main(["run", str(REPO / "missions" / "teleop.yaml"), "--no-record"]) == 1  # no joystick


def test_bad_joystick_script_is_invalid_input(tmp_path, capsys):
    bad = tmp_path / "js.yaml"
    bad.write_text("- {at: 1 s, press: enable}\n- {at: 2 s, presss: turbo}\n")
    code = cli.main(["run", str(REPO / "missions" / "teleop.yaml"), "--joystick", str(bad), "--no-record"])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{bad}:2:13: error:" in err and "presss" in err and "did you mean 'press'?" in err


def test_a_hold_failsafe_is_restored_after_the_operator_lets_go(tmp_path):
    world = tmp_path / "w.yaml"
    world.write_text("world: low\nbattery: {start_v: 11.0}\n")
    h = MissionHarness.from_yaml("""
mission: t
steps:
  - drive: {distance: 5 m, speed: 0.2 m/s}
failsafes:
  battery_low: {below: 11.5 V, for: 0.5 s, then: hold}
""", world=str(world), joystick=[{"at": "2 s", "linear": 0.5}, {"at": "2 s", "press": "enable"},
                                 {"at": "3 s", "release": "enable"}])
    h.tick_until(lambda h: h.now_s >= 1.5)
    assert h.run.paused_by == "hold (battery_low)"
    h.tick_until(lambda h: h.now_s >= 2.5)
    assert h.run.paused_by == "teleop" and h.records[-1].mux_source == "teleop"  # teleop outranks the hold
    h.tick_until(lambda h: h.now_s >= 3.2)
    assert h.run.paused_by == "hold (battery_low)"  # still low: the hold is back, the mission does not resume
    assert h.records[-1].cmd_mux.is_zero() and h.result is None
