"""The emergency stop: joystick button and API, latched below the tree until an explicit reset."""

from __future__ import annotations

import threading

import pytest

from beastbt.run.safety import request_estop, reset_estop
from beastbt.testing import MissionHarness

DRIVE = """
mission: t
steps:
  - drive: {distance: 5 m, speed: 0.25 m/s}
"""


def moving_after(wire: list, index: int) -> list:
    return [c for c in wire[index + 1:] if c.get("T") == 1 and (c["L"] != 0 or c["R"] != 0)]


def lower_stack_tick(h: MissionHarness) -> None:
    """What still runs below the tree once the mission has ended: sense, the teleop hook, mux, gate, base."""
    run = h.run
    h.clock.advance(h.dt_s)
    now = h.now_s
    run.io.sim.advance(now)
    run.sense(now)
    h.run.ctx.services.teleop(run, now)
    out = run.gate.filter(run.mux.select(now), now)
    run.io.base.send_velocity(out, now)


def test_joystick_estop_ends_the_mission_and_sends_the_base_stop_once():
    h = MissionHarness.from_yaml(DRIVE, joystick=[{"at": "2 s", "press": "estop"}])
    h.tick_until(lambda h: h.now_s >= 1.9)
    assert h.truth.v_mps > 0.2
    assert h.tick(3) == "stopped"
    assert h.records[-1].now_s == pytest.approx(2.0)
    assert h.blackboard("estop") is True and h.records[-1].mux_source == "estop"
    wire = h.wire
    stops = [i for i, c in enumerate(wire) if c == {"T": 135}]  # the e-stop: zero wheel speed, then the gimbal stop
    assert len(stops) == 1 and wire[stops[0] - 1] == {"T": 1, "L": 0.0, "R": 0.0}
    assert {"T": 0} not in wire, "T:0 would release every bus servo's torque"
    assert not moving_after(wire, stops[0]), "nothing may move after the e-stop"
    assert any(e.kind == "estop" and "joystick e-stop button" in e.text for e in h.events)
    assert any(e.kind == "mission_end" and "stopped: emergency stop" in e.text for e in h.events)
    assert h.summary()["teleop"]["estop_latched"] is True


def test_estop_latches_until_the_reset_button():
    h = MissionHarness.from_yaml(DRIVE, joystick=[
        {"at": "1 s", "press": "estop"}, {"at": "1.5 s", "release": "estop"},
        {"at": "2 s", "linear": 1.0}, {"at": "2 s", "press": "enable"},   # the operator tries to drive
        {"at": "3 s", "press": "estop_reset"}, {"at": "3.2 s", "release": "estop_reset"}])
    h.tick_until(lambda h: h.done, 5)
    assert h.result == "stopped"
    n = len(h.wire)
    while h.now_s < 2.9:
        lower_stack_tick(h)
        assert h.run.mux.estop_latched and h.run.io.base.estop_latched
    assert not moving_after(h.wire, n - 1), "latched: neither teleop nor anything else moves the robot"
    assert h.run.io.base.blocked_by_estop == 0  # the mux already gives zero; the adapter latch is the backstop
    while h.now_s < 3.5:
        lower_stack_tick(h)
    assert not h.run.mux.estop_latched and not h.run.io.base.estop_latched
    assert moving_after(h.wire, n - 1), "after the reset the operator drives again"
    kinds = [e.text for e in h.events if e.kind == "estop"]
    assert kinds[0].startswith("emergency stop latched") and kinds[-1] == "emergency stop reset: joystick reset button"


def test_reset_is_ignored_while_the_estop_button_is_held():
    h = MissionHarness.from_yaml(DRIVE, joystick=[
        {"at": "1 s", "press": "estop"}, {"at": "1.5 s", "press": "estop_reset"}])
    h.tick_until(lambda h: h.done, 5)
    while h.now_s < 2.5:
        lower_stack_tick(h)
    assert h.run.mux.estop_latched


def test_api_estop_from_another_thread_and_reset():
    h = MissionHarness.from_yaml(DRIVE)
    h.tick_until(lambda h: h.now_s >= 1.0)
    t = threading.Thread(target=request_estop, args=(h.run, "operator console"))
    t.start()
    t.join()
    assert request_estop(h.run, "again") is False  # already latched
    assert h.tick() == "stopped"
    assert [c for c in h.wire if c == {"T": 135}] == [{"T": 135}]
    assert any(e.kind == "estop" and "operator console" in e.text for e in h.events)
    assert reset_estop(h.run, "test") is True
    assert reset_estop(h.run, "test") is False
    assert not h.run.mux.estop_latched and not h.run.io.base.estop_latched


def test_events_from_other_threads_reach_the_listeners_on_the_ticking_thread_only():
    # The console's e-stop, the watchdog, the camera and joystick threads add events while the loop ticks. The
    # listeners (the recorder's queue and pipe among them) are not safe to call from two threads at once: a
    # console e-stop once broke the recorder mid-tick, and the run ended "failed" instead of "stopped".
    h = MissionHarness.from_yaml(DRIVE)
    h.tick_until(lambda h: h.now_s >= 1.0)
    seen: list[tuple[int, str]] = []
    h.run.events.listeners.append(lambda ev: seen.append((threading.get_ident(), ev.kind)))
    chatter = threading.Thread(target=lambda: [h.run.events.add("camera", f"frame {i}") for i in range(200)])
    stop = threading.Thread(target=request_estop, args=(h.run, "operator console"))
    chatter.start()
    stop.start()
    stop.join()
    chatter.join()
    assert seen == [], "nothing is delivered on the threads that added the events"
    assert h.tick() == "stopped"
    assert {thread for thread, _ in seen} == {threading.get_ident()}
    kinds = [kind for _, kind in seen]
    assert kinds.count("camera") == 200 and kinds.count("estop") == 1
    assert kinds.index("estop") < kinds.index("mission_end"), "the e-stop's event comes before the end it caused"
    assert any(e.kind == "mission_end" and "stopped: emergency stop: operator console" in e.text for e in h.events)


def test_api_estop_reaches_the_base_even_with_the_loop_frozen():
    h = MissionHarness.from_yaml(DRIVE)
    h.tick_until(lambda h: h.now_s >= 1.0)
    request_estop(h.run, "remote")
    n = len(h.wire)
    # The loop never ticks again; only the simulator (and so the watchdog) runs on.
    h.clock.advance(0.2)
    h.run.io.sim.advance(h.now_s)
    assert h.wire[n:][:2] == [{"T": 1, "L": 0.0, "R": 0.0}, {"T": 135}]
    assert h.run.io.base.estops_sent == 1
