"""Joystick override of a running mission, tick by tick, with scripted joysticks read by the real driver."""

from __future__ import annotations

import pytest

from beastbt.testing import MissionHarness

DRIVE = """
mission: t
steps:
  - drive: {distance: 2 m, speed: 0.2 m/s}
"""

WAIT = """
mission: t
steps:
  - wait: 10 s
"""


def harness(text: str, events: list | None = None) -> MissionHarness:
    extras = {} if events is None else {"joystick": events}
    return MissionHarness.from_yaml(text, **extras)


def tick_to(h: MissionHarness, t_s: float) -> None:
    """Tick until the tick at ``t_s`` has run (the clock then reads t_s + dt)."""
    while h.now_s < t_s - 1e-9:
        h.tick()
    h.tick()


def record_at(h: MissionHarness, t_s: float):
    return next(r for r in h.records if abs(r.now_s - t_s) < 1e-6)


def test_no_motion_without_enable():
    # Sticks at full deflection, turbo pressed, but never the deadman.
    h = harness(WAIT, [{"at": "0.5 s", "linear": 1.0, "angular": -1.0}, {"at": "1 s", "press": "turbo"}])
    h.tick_until(lambda h: h.now_s >= 3.0)
    assert h.blackboard("joystick").axes["linear"] == pytest.approx(1.0)
    assert all(r.cmd_gate.is_zero() for r in h.records)
    assert all(r.mux_source == "mission" for r in h.records[1:])
    assert not h.blackboard("teleop_active")
    assert all(c["L"] == 0 and c["R"] == 0 for c in h.wire if c.get("T") == 1)


def test_sticks_without_enable_leave_the_mission_untouched():
    alone = harness(DRIVE)
    alone.run_to_end(30)
    stirred = harness(DRIVE, [{"at": "0.5 s", "linear": -1.0}, {"at": "2 s", "angular": 1.0}])
    stirred.run_to_end(30)
    assert stirred.result == alone.result == "success"
    assert [r.cmd_gate for r in stirred.records] == [r.cmd_gate for r in alone.records]


def test_motion_within_one_tick_of_enable_and_the_mission_pauses():
    h = harness(DRIVE, [{"at": "1 s", "linear": -1.0}, {"at": "2 s", "press": "enable"}])
    tick_to(h, 1.95)
    assert h.records[-1].mux_source == "mission" and h.records[-1].cmd_gate.linear_mps > 0
    n_wire = len(h.wire)
    tick_to(h, 2.0)  # the tick at which the button went down
    rec = record_at(h, 2.0)
    assert rec.mux_source == "teleop"
    assert rec.cmd_mux.linear_mps == pytest.approx(-0.5)  # full reverse at the default 0.5 m/s scale
    assert rec.cmd_gate.linear_mps < record_at(h, 1.95).cmd_gate.linear_mps  # already braking towards reverse
    assert h.blackboard("teleop_active") is True
    assert h.run.paused_by == "teleop"
    assert h.status_of("drive 2 m at 0.2 m/s") == "RUNNING"
    sent = h.wire[n_wire]
    assert sent["T"] == 1 and (sent["L"] + sent["R"]) / 2 == pytest.approx(rec.cmd_gate.linear_mps, abs=1e-4)
    # From rest the first teleop tick already moves: enable with deflection -> motion the same tick.
    h2 = harness(WAIT, [{"at": "1 s", "linear": 0.6}, {"at": "2 s", "press": "enable"}])
    tick_to(h2, 1.95)
    assert h2.records[-1].cmd_gate.is_zero()
    tick_to(h2, 2.0)
    assert record_at(h2, 2.0).cmd_gate.linear_mps > 0
    assert any(e.kind == "teleop" and "takes over" in e.text for e in h2.events)


def test_exactly_one_zero_on_release_then_the_mission_resumes():
    h = harness(DRIVE, [{"at": "0.4 s", "linear": 1.0, "angular": 0.4}, {"at": "0.5 s", "press": "enable"},
                        {"at": "3 s", "release": "enable"}])
    tick_to(h, 2.9)
    x_teleop_start = h.truth.x
    tick_to(h, 3.0)
    release = record_at(h, 3.0)
    assert release.mux_source == "teleop" and release.cmd_mux.is_zero()
    assert h.blackboard("teleop_active") is False
    assert h.run.paused_by is None
    tick_to(h, 3.05)
    assert record_at(h, 3.05).mux_source == "mission"
    teleop_recs = [r for r in h.records if r.mux_source == "teleop"]
    zeros = [r for r in teleop_recs if r.cmd_mux.is_zero()]
    assert len(zeros) == 1 and zeros[0] is teleop_recs[-1]
    assert all(not r.cmd_mux.is_zero() for r in teleop_recs[:-1])
    # The interrupted drive starts afresh where the operator left the robot and covers its 2 m from there.
    start = (h.truth.x, h.truth.y)
    assert h.run_to_end(60) == "success"
    assert any(e.kind == "teleop" and "resumes at drive 2 m" in e.text for e in h.events)
    travelled = ((h.truth.x - start[0]) ** 2 + (h.truth.y - start[1]) ** 2) ** 0.5
    assert travelled == pytest.approx(2.0, abs=0.1)
    assert h.truth.x > x_teleop_start
    assert h.summary()["teleop"]["takeovers"] == 1


def test_release_long_after_the_drive_stalled_does_not_fail_it_as_blocked():
    # 8 s of teleop is longer than the drive's 5 s stuck timer: resuming must not fail it.
    h = harness(DRIVE, [{"at": "0.5 s", "press": "enable"}, {"at": "8.5 s", "release": "enable"}])
    assert h.run_to_end(60) == "success"
    assert not [e for e in h.events if e.kind == "step_failed"]


def test_teleop_false_means_no_override():
    text = DRIVE + "teleop: false\n"
    h = harness(text, [{"at": "0.5 s", "press": "enable"}, {"at": "0.6 s", "linear": -1.0},
                       {"at": "3 s", "release": "enable"}])
    assert h.run_to_end(60) == "success"
    assert all(r.mux_source != "teleop" for r in h.records)
    assert h.run.paused_by is None
    alone = harness(text)
    alone.run_to_end(60)
    assert [r.cmd_gate for r in h.records] == [r.cmd_gate for r in alone.records]


def test_on_release_abort_ends_the_mission_stopped():
    h = harness(DRIVE + "teleop: {on_release: abort}\n",
                [{"at": "1 s", "press": "enable"}, {"at": "2 s", "release": "enable"}])
    tick_to(h, 1.95)
    assert h.result is None and h.run.paused_by == "teleop"
    tick_to(h, 2.0)
    assert h.result == "stopped"
    assert record_at(h, 2.0).cmd_mux.is_zero()
    assert any(e.kind == "teleop" and "on_release: abort" in e.text for e in h.events)


def test_unplugged_pad_counts_as_release():
    h = harness(DRIVE, [{"at": "0.5 s", "press": "enable"}, {"at": "0.5 s", "linear": 1.0},
                        {"at": "1.5 s", "unplug": True}])
    tick_to(h, 1.45)
    assert h.blackboard("teleop_active") is True
    tick_to(h, 1.5)
    assert h.blackboard("teleop_active") is False
    assert record_at(h, 1.5).cmd_mux.is_zero() and record_at(h, 1.5).mux_source == "teleop"
    assert h.blackboard("joystick").connected is False
    assert h.run_to_end(60) == "success"


def test_teleop_active_condition_sees_the_deadman():
    # With teleop: false the mission keeps running and can watch the deadman.
    h = harness("""
mission: t
teleop: false
steps:
  - wait_until: teleop_active
    timeout: 10 s
""", [{"at": "2 s", "press": "enable"}])
    assert h.run_to_end(20) == "success"
    assert h.now_s == pytest.approx(2.05)
    # With teleop: true the tree is paused while enable is held, so it never sees it held;
    # on release the wait starts afresh (and here times out).
    h2 = harness("""
mission: t
steps:
  - wait_until: teleop_active
    timeout: 3 s
""", [{"at": "1 s", "press": "enable"}, {"at": "2 s", "release": "enable"}])
    assert h2.run_to_end(20) == "failure"
    assert h2.now_s == pytest.approx(5.05, abs=0.06)  # 3 s after the release at 2 s


def test_mux_changes_are_events():
    h = harness(WAIT, [{"at": "1 s", "press": "enable"}, {"at": "2 s", "release": "enable"}])
    h.tick_until(lambda h: h.now_s >= 3)
    mux = [e.text for e in h.events if e.kind == "mux"]
    assert mux[0].startswith("mission -> teleop") and mux[1].startswith("teleop -> mission")
