"""Every flow construct of the language, tick by tick, success and failure paths."""

from __future__ import annotations

import pytest

from beastbt.testing import MissionHarness


def mission(body: str, extra: str = "") -> MissionHarness:
    return MissionHarness.from_yaml(f"mission: t\n{extra}steps:\n{body}")


def test_a_list_stops_at_the_first_failure():
    h = mission("  - say: one\n  - servo: {name: nope, angle: 1 deg}\n  - say: three\n")
    assert h.run_to_end(5) == "failure"
    assert [e.text for e in h.events if e.kind == "say"] == ["one"]


def test_repeat_runs_the_steps_n_times():
    h = mission("  - repeat: {times: 3, steps: [say: hi, wait: 100 ms]}\n")
    assert h.run_to_end(5) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["hi"] * 3


def test_repeat_fails_when_a_pass_fails():
    h = mission("  - repeat: {times: 3, steps: [say: hi, servo: {name: nope, angle: 1 deg}]}\n")
    assert h.run_to_end(5) == "failure"
    assert len([e for e in h.events if e.kind == "say"]) == 1


def test_repeat_forever_keeps_going():
    h = mission("  - repeat: {times: forever, steps: [wait: 100 ms]}\n")
    h.tick(200)
    assert not h.done
    assert h.status_of("repeat forever") == "RUNNING"


def test_do_runs_the_named_task():
    h = mission("  - do: greet\n  - do: greet\n", "tasks:\n  greet: [say: hello]\n")
    assert h.run_to_end(5) == "success"
    assert len([e for e in h.events if e.kind == "say"]) == 2
    assert len(h.nodes("do greet")) == 2


def test_first_of_tries_alternatives_until_one_succeeds():
    h = mission("  - first_of:\n      - [servo: {name: nope, angle: 1 deg}]\n      - [say: plan B]\n      - [say: plan C]\n")
    assert h.run_to_end(5) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["plan B"]


def test_first_of_fails_when_all_fail():
    h = mission("  - first_of: [[servo: {name: a, angle: 1 deg}], [servo: {name: b, angle: 1 deg}]]\n")
    assert h.run_to_end(5) == "failure"


def test_retry_makes_up_to_n_attempts_in_all():
    h = mission("  - retry: {times: 3, steps: [say: try, servo: {name: nope, angle: 1 deg}]}\n")
    assert h.run_to_end(5) == "failure"
    assert len([e for e in h.events if e.kind == "say"]) == 3


def test_retry_stops_at_the_first_success():
    h = mission("  - retry: {times: 3, steps: [say: try]}\n")
    assert h.run_to_end(5) == "success"
    assert len([e for e in h.events if e.kind == "say"]) == 1


def test_timeout_fails_steps_that_take_too_long():
    h = mission("  - timeout: {after: 1 s, steps: [wait: 5 s]}\n")
    assert h.run_to_end(10) == "failure"
    assert h.now_s == pytest.approx(1.0, abs=0.1)


def test_timeout_passes_steps_that_finish_in_time():
    h = mission("  - timeout: {after: 2 s, steps: [wait: 500 ms]}\n")
    assert h.run_to_end(10) == "success"


def test_parallel_all_waits_for_every_branch():
    h = mission("  - parallel: {steps: [wait: 1 s, look: {pan: 30 deg, settle: 200 ms}]}\n")
    h.tick(8)
    assert h.status_of("look pan 30 deg") == "SUCCESS"
    assert not h.done
    assert h.run_to_end(5) == "success"
    assert h.now_s == pytest.approx(1.0, abs=0.1)


def test_parallel_any_ends_with_the_first_success():
    h = mission("  - parallel: {succeed_on: any, steps: [wait: 5 s, wait: 500 ms]}\n")
    assert h.run_to_end(10) == "success"
    assert h.now_s == pytest.approx(0.5, abs=0.1)


def test_parallel_fails_when_a_branch_fails():
    h = mission("  - parallel: {steps: [wait: 5 s, servo: {name: nope, angle: 1 deg}]}\n")
    assert h.run_to_end(10) == "failure"


def test_if_chooses_once_when_reached():
    h = mission("  - wait: 1 s\n  - if: {elapsed: 500 ms}\n    then: [say: late]\n    else: [say: early]\n")
    assert h.run_to_end(5) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["late"]


def test_if_takes_else_and_does_not_fall_through_on_failure():
    h = mission("  - if: {elapsed: 1 h}\n    then: [say: then]\n    else: [say: else]\n")
    assert h.run_to_end(5) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["else"]
    h2 = mission("  - if: {not: {elapsed: 1 h}}\n    then: [servo: {name: nope, angle: 1 deg}]\n    else: [say: else]\n")
    assert h2.run_to_end(5) == "failure"
    assert not [e for e in h2.events if e.kind == "say"]


def test_if_without_else_succeeds_when_false():
    h = mission("  - if: teleop_active\n    then: [say: x]\n")
    assert h.run_to_end(5) == "success"


def test_while_checks_before_each_pass():
    h = mission("  - while: {not: {elapsed: 1 s}}\n    steps: [say: pass, wait: 300 ms]\n")
    assert h.run_to_end(10) == "success"
    # A pass ends on the tick its wait ends and the next starts on the following tick:
    # passes start at 0, 0.35 and 0.7 s; at 1.05 s the condition is false.
    assert [round(e.time_s, 2) for e in h.events if e.kind == "say"] == [0.0, 0.35, 0.7]
    h2 = mission("  - while: teleop_active\n    steps: [say: never]\n")
    assert h2.run_to_end(5) == "success"
    assert not [e for e in h2.events if e.kind == "say"]


def test_while_fails_when_a_pass_fails():
    h = mission("  - while: {not: {elapsed: 1 h}}\n    steps: [servo: {name: nope, angle: 1 deg}]\n")
    assert h.run_to_end(5) == "failure"


def test_wait_until_holds_still_then_succeeds():
    h = mission("  - wait_until: {elapsed: 2 s}\n")
    assert h.run_to_end(10) == "success"
    assert h.now_s == pytest.approx(2.0, abs=0.1)
    assert all(c.is_zero() for c in h.sent)


def test_wait_until_fails_after_its_timeout():
    h = mission("  - wait_until: {battery_below: 1 V}\n    timeout: 1 s\n")
    assert h.run_to_end(10) == "failure"
    assert any("did not hold within 1 s" in e.text for e in h.events)


def test_conditions_all_any_battery():
    h = mission("  - wait: 500 ms\n  - if: {all: [{elapsed: 0 s}, {any: [line_seen, {battery_below: 20 V}]}]}\n    then: [say: 'yes']\n")
    assert h.run_to_end(5) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["yes"]


def test_node_names_read_like_the_mission():
    h = mission("  - repeat: {times: 2, steps: [drive: {distance: 3 m, speed: 0.15 m/s}, turn: {angle: 90 deg}]}\n"
                "  - timeout: {after: 1 min, steps: [wait: 2 s]}\n")
    names = {n.name for n in h.root.iterate()}
    assert {"mission t", "repeat 2 times", "drive 3 m at 0.15 m/s", "turn 90 deg", "timeout 60 s", "wait 2 s"} <= names
