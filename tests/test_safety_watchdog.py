"""The adapter-side watchdog: zero within 0.5 s of the last fresh command, a stop as the last word."""

from __future__ import annotations

import threading

import pytest

from beastbt.actuation.watchdog import AdapterWatchdog, WatchdogConfig
from beastbt.blackboard.types import VelocityCommand as V
from beastbt.core.clock import SimClock
from beastbt.testing import MissionHarness


class FakeBase:
    """Records what reaches the 'wire'."""

    name = "fake"

    def __init__(self) -> None:
        self.sent: list[tuple] = []

    def start(self, now_s: float) -> None:
        self.sent.append(("start",))

    def send_velocity(self, cmd: V, now_s: float) -> None:
        self.sent.append(("v", cmd.linear_mps, cmd.angular_rps, round(now_s, 6)))

    def emergency_stop(self, now_s: float) -> None:
        self.sent.append(("estop", round(now_s, 6)))

    def poll(self, now_s: float) -> list:
        return []

    def close(self) -> None:
        self.sent.append(("close",))


def rig(**cfg):
    clock = SimClock()
    base = FakeBase()
    events: list = []
    dog = AdapterWatchdog(base, clock, WatchdogConfig(**cfg), lambda k, t: events.append((k, t)))
    return clock, base, dog, events


def drive_loop(clock: SimClock, dog: AdapterWatchdog, until_s: float, v: float = 0.3) -> None:
    """A healthy 20 Hz loop: a fresh command each tick, the watchdog checked at 100 Hz in between."""
    while clock.now() < until_s - 1e-9:
        dog.send_velocity(V(v, 0.0, clock.now()), clock.now())
        for _ in range(5):
            clock.advance(0.01)
            assert dog.check(clock.now()) is None


def test_zero_within_the_timeout_of_a_frozen_loop_and_only_once():
    clock, base, dog, events = rig()
    drive_loop(clock, dog, 1.0)
    last_fresh = clock.now() - 0.05
    assert all(s[1] == 0.3 for s in base.sent)
    fired = []
    while clock.now() < 3.0:  # the loop is frozen: nothing but the watchdog's checks
        clock.advance(0.01)
        if dog.check(clock.now()) == "zero":
            fired.append(clock.now())
    assert len(fired) == 1
    assert 0.45 - 1e-9 <= fired[0] - last_fresh <= 0.46
    assert base.sent[-1][:3] == ("v", 0.0, 0.0)
    assert dog.trips == 1 and events and "no fresh command" in events[-1][1]


def test_fresh_commands_rearm_it():
    clock, base, dog, events = rig()
    drive_loop(clock, dog, 0.5)
    clock.advance(1.0)
    assert dog.check(clock.now()) == "zero"
    drive_loop(clock, dog, 2.0)
    assert base.sent[-1][1] == 0.3
    assert any("fresh commands again" in t for _, t in events)
    clock.advance(0.5)
    assert dog.check(clock.now()) == "zero" and dog.trips == 2


def test_a_stale_command_goes_out_as_zero():
    clock, base, dog, _ = rig()
    clock.advance(2.0)
    dog.send_velocity(V(0.3, 0.2, stamp_s=1.0), 2.0)
    assert base.sent[-1][:3] == ("v", 0.0, 0.0) and dog.stale_commands == 1
    assert dog.last_fresh_s is None


def test_estop_latch_refuses_motion_until_reset():
    clock, base, dog, _ = rig()
    dog.send_velocity(V(0.3, 0.0, 0.0), 0.0)
    dog.emergency_stop(0.0)
    for t in (0.05, 0.1, 5.0):
        clock.set(t)
        dog.send_velocity(V(0.3, 0.5, t), t)
        assert base.sent[-1][:3] == ("v", 0.0, 0.0)
    assert base.sent.count(("estop", 0.0)) == 1 and dog.blocked_by_estop == 3
    dog.reset_estop()
    dog.send_velocity(V(0.3, 0.0, 5.0), 5.0)
    assert base.sent[-1][1] == 0.3


def test_api_latch_sends_the_base_stop_itself_when_the_loop_does_not():
    clock, base, dog, events = rig(estop_grace_s=0.1)
    dog.latch_estop("remote button")
    clock.advance(0.05)
    assert dog.check(clock.now()) is None  # the loop still has time to do it
    clock.advance(0.06)
    assert dog.check(clock.now()) == "estop"
    clock.advance(1.0)
    assert dog.check(clock.now()) is None
    assert [s for s in base.sent if s[0] == "estop"] == [("estop", 0.11)]


def test_close_makes_the_stop_the_last_thing_sent():
    clock, base, dog, _ = rig()
    dog.start(0.0)
    drive_loop(clock, dog, 0.3)
    dog.close()
    dog.send_velocity(V(0.3, 0.0, clock.now()), clock.now())
    clock.advance(1.0)
    assert dog.check(clock.now()) is None
    assert base.sent[-1] == ("close",)
    dog.close()
    assert base.sent.count(("close",)) == 1


def test_the_thread_checks_on_its_own_with_an_injected_clock_and_sleeper():
    clock, base, dog, _ = rig(check_period_s=0.02)
    dog.send_velocity(V(0.3, 0.0, 0.0), 0.0)
    finished = threading.Event()
    naps: list[float] = []

    def sleeper(dt: float) -> None:
        # Simulated time passes only while the watchdog sleeps: deterministic, whatever the machine.
        naps.append(dt)
        clock.advance(dt)
        if clock.now() >= 1.0 - 1e-9:
            dog.stop_thread()
            finished.set()

    dog.start_thread(sleeper)
    assert finished.wait(30)
    zeros = [s for s in base.sent if s[0] == "v" and s[1] == 0.0]
    assert len(zeros) == 1 and 0.45 <= zeros[0][3] <= 0.47
    assert set(naps) == {0.02}


def test_disabled_watchdog_passes_commands_through():
    clock, base, dog, _ = rig(enabled=False)
    dog.send_velocity(V(0.3, 0.0, 0.0), 0.0)
    clock.advance(5.0)
    assert dog.check(clock.now()) is None and base.sent == [("v", 0.3, 0.0, 0.0)]


def test_config_rejects_unknown_and_bad_values():
    with pytest.raises(ValueError, match="timeout_sec"):
        WatchdogConfig.from_dict({"timeout_sec": 1})
    with pytest.raises(ValueError, match="positive"):
        WatchdogConfig.from_dict({"timeout_s": 0})
    assert WatchdogConfig.from_dict({"timeout_s": 0.3}).timeout_s == 0.3


def test_frozen_tick_loop_in_a_simulated_run_stops_the_robot():
    h = MissionHarness.from_yaml("""
mission: t
steps:
  - drive: {distance: 5 m, speed: 0.3 m/s}
""")
    h.tick_until(lambda h: h.now_s >= 2.0)
    last_tick_s = h.records[-1].now_s
    esp32 = h.run.io.esp32
    assert esp32.commands[-1]["L"] > 0.25 and h.truth.v_mps > 0.25
    zero_at = None
    for _ in range(100):  # one second of a frozen loop: the simulator and the watchdog go on
        h.clock.advance(0.01)
        h.run.io.sim.advance(h.now_s)
        if zero_at is None and esp32.commands[-1] == {"T": 1, "L": 0.0, "R": 0.0}:
            zero_at = h.now_s
    assert zero_at is not None and zero_at - last_tick_s <= 0.5
    assert h.truth.v_mps < 0.01  # the motors' lag decays to a stop
    assert h.run.io.base.trips == 1
    assert any(e.kind == "watchdog" for e in h.events)
