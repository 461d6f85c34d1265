"""Below the tree: the command mux and the safety gate, independent of any mission."""

from __future__ import annotations

import math

import pytest

from beastbt.actuation.gate import GateLimits, SafetyGate
from beastbt.actuation.mux import CommandMux
from beastbt.blackboard.types import VelocityCommand as V


def gate(**kw) -> SafetyGate:
    limits = dict(max_speed_mps=0.3, max_turn_rate_rps=1.0, max_accel_mps2=1.0, max_angular_accel_rps2=10.0,
                  command_timeout_s=0.5)
    limits.update(kw)
    return SafetyGate(GateLimits(**limits))


def test_gate_clamps_speed_and_turn_rate():
    g = gate(max_accel_mps2=100.0, max_angular_accel_rps2=100.0)
    out = g.filter(V(5.0, -9.0, 0.0), 0.0)
    assert out.linear_mps == pytest.approx(0.3) and out.angular_rps == pytest.approx(-1.0)


def test_gate_limits_acceleration_per_tick():
    g = gate()
    g.filter(V(0.0, 0.0, 0.0), 0.0)
    out = g.filter(V(0.3, 0.0, 0.05), 0.05)
    assert out.linear_mps == pytest.approx(0.05)
    out = g.filter(V(0.3, 0.0, 0.10), 0.10)
    assert out.linear_mps == pytest.approx(0.10)


def test_watchdog_zeroes_a_stale_command_within_the_timeout():
    g = gate(max_accel_mps2=100.0)
    cmd = V(0.2, 0.5, 0.0)
    t = 0.0
    while t <= 0.5:
        out = g.filter(cmd, t)
        assert not out.is_zero()
        t = round(t + 0.05, 3)
    out = g.filter(cmd, 0.55)
    assert out.is_zero() and g.watchdog_tripped


def test_mux_priorities_timeouts_and_estop_latch():
    m = CommandMux()
    m.submit("mission", V(0.2, 0, 0.0, "mission"), 0.0)
    assert m.select(0.0).linear_mps == 0.2 and m.source == "mission"
    m.submit("teleop", V(-0.1, 0, 0.1, "teleop"), 0.1)
    assert m.select(0.1).linear_mps == -0.1 and m.source == "teleop"
    # Teleop stops sending: after its timeout the mission wins again.
    m.submit("mission", V(0.2, 0, 0.7, "mission"), 0.7)
    assert m.select(0.7).source == "mission"
    m.latch_estop("button")
    for t in (0.8, 5.0, 100.0):
        m.submit("mission", V(0.2, 0, t, "mission"), t)
        assert m.select(t).is_zero() and m.source == "estop"
    m.reset_estop()
    assert m.select(100.0).source == "mission"


def test_mux_with_nothing_fresh_is_zero():
    m = CommandMux()
    m.submit("mission", V(0.2, 0, 0.0), 0.0)
    assert m.select(0.6).is_zero() and m.source == "none"


def test_estop_during_a_mission_stops_it_with_status_stopped():
    from beastbt.testing import MissionHarness
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - drive: {distance: 5 m, speed: 0.2 m/s}\n")
    h.tick(20)
    assert h.last_sent.linear_mps > 0
    h.run.mux.latch_estop("test")
    assert h.tick() == "stopped"
    assert h.last_sent.is_zero()
    stop = h.wire.index({"T": 1, "L": 0.0, "R": 0.0}, -3)
    assert h.wire[stop + 1] == {"T": 135}  # zero wheel speed and the gimbal stopped where it is...
    assert {"T": 0} not in h.wire and {"T": 210, "cmd": 0} not in h.wire  # ...with no servo torque released
    assert h.wire[-1] == {"T": 1, "L": 0.0, "R": 0.0}
