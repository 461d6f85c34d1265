"""TeleopTwistJoy tick by tick: deadman, turbo, exactly one zero command on release."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest

from beastbt.actuation.teleop import TeleopConfig, TeleopTwistJoy
from beastbt.blackboard.types import JoystickState
from beastbt.devices.joystick import JoystickDevice
from beastbt.core.clock import SimClock
from beastbt.sim.joystick_script import ScriptedJoystick

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas" / "parts"


def js(t, linear=0.0, angular=0.0, enable=False, turbo=False, estop=False, connected=True):
    return JoystickState(
        stamp_s=t,
        axes={"linear": linear, "angular": angular},
        buttons={"enable": enable, "turbo": turbo, "estop": estop, "estop_reset": False},
        connected=connected,
    )


def test_no_motion_without_enable():
    t = TeleopTwistJoy()
    for i in range(5):
        assert t.update(js(i * 0.05, linear=1.0, angular=1.0), i * 0.05) is None
        assert not t.active
    assert t.update(None, 0.3) is None


def test_timeline_enable_turbo_release():
    t = TeleopTwistJoy()
    timeline = [
        # (state, expected (linear, angular) or None)
        (js(0.00, linear=0.6), None),
        (js(0.05, linear=0.6, enable=True), (0.3, 0.0)),  # first update with enable + deflection moves
        (js(0.10, linear=0.6, angular=-0.4, enable=True), (0.3, -0.2)),
        (js(0.15, enable=True), (0.0, 0.0)),  # held with sticks centred: still a command each tick
        (js(0.20, linear=1.0, angular=0.5, enable=True, turbo=True), (1.0, 0.5)),
        (js(0.25, linear=1.0, angular=0.5, turbo=True), (0.0, 0.0)),  # released: the one zero
        (js(0.30, linear=1.0, angular=0.5, turbo=True), None),  # turbo alone never drives
        (js(0.35, linear=1.0), None),
    ]
    for state, expected in timeline:
        cmd = t.update(state, state.stamp_s)
        if expected is None:
            assert cmd is None, state
        else:
            assert cmd is not None, state
            assert (cmd.linear_mps, cmd.angular_rps) == pytest.approx(expected)
            assert cmd.source == "teleop" and cmd.stamp_s == state.stamp_s
    assert not t.active


def test_exactly_one_zero_after_release_and_active_flag():
    t = TeleopTwistJoy()
    t.update(js(0.0, linear=0.5, enable=True), 0.0)
    assert t.active
    zero = t.update(js(0.05, linear=0.5), 0.05)
    assert zero is not None and zero.is_zero() and not t.active
    assert [t.update(js(0.1 + i * 0.05, linear=0.5), 0.1 + i * 0.05) for i in range(10)] == [None] * 10


def test_lost_joystick_counts_as_release():
    t = TeleopTwistJoy()
    t.update(js(0.0, linear=0.5, enable=True), 0.0)
    cmd = t.update(js(0.05, linear=0.5, enable=True, connected=False), 0.05)
    assert cmd is not None and cmd.is_zero()
    assert t.update(None, 0.1) is None


def test_custom_scales_and_estop_helper():
    t = TeleopTwistJoy(TeleopConfig(scale_linear_mps=0.2, scale_angular_rps=1.0, scale_linear_turbo_mps=0.4, scale_angular_turbo_rps=2.0))
    cmd = t.update(js(0.0, linear=-0.5, angular=0.5, enable=True), 0.0)
    assert (cmd.linear_mps, cmd.angular_rps) == pytest.approx((-0.1, 0.5))
    cmd = t.update(js(0.0, linear=-0.5, angular=0.5, enable=True, turbo=True), 0.0)
    assert (cmd.linear_mps, cmd.angular_rps) == pytest.approx((-0.2, 1.0))
    assert TeleopTwistJoy.estop_pressed(js(0.0, estop=True))
    assert not TeleopTwistJoy.estop_pressed(js(0.0, estop=True, connected=False))
    assert not TeleopTwistJoy.estop_pressed(None)


def test_nan_axis_is_treated_as_centred():
    t = TeleopTwistJoy()
    cmd = t.update(js(0.0, linear=float("nan"), angular=5.0, enable=True), 0.0)
    assert cmd.linear_mps == 0.0 and cmd.angular_rps == pytest.approx(0.5)  # clamped to full deflection


def test_end_to_end_script_driver_teleop():
    script = ScriptedJoystick.from_yaml(
        """
- {at: 0.5 s, linear: 1.0}
- {at: 1 s, press: enable}
- {at: 2 s, release: enable}
- {at: 3 s, press: enable}
- {at: 3.5 s, unplug: true}
"""
    )
    clock = SimClock()
    device = JoystickDevice(script.opener(), clock, mapping=script.mapping)
    teleop = TeleopTwistJoy()
    cmds = {}
    for i in range(0, 81):
        now = i * 0.05
        clock.set(now)
        script.update(now)
        cmds[round(now, 2)] = teleop.update(device.poll(), now)
    moving = [t for t, c in cmds.items() if c is not None and not c.is_zero()]
    zeros = [t for t, c in cmds.items() if c is not None and c.is_zero()]
    assert moving[0] == 1.0 and cmds[1.0].linear_mps == pytest.approx(0.5, abs=1e-4)
    assert max(t for t in moving if t < 2.5) == pytest.approx(1.95)
    assert zeros == [2.0, 3.5]  # one stop on release, one when the cable went with enable held
    assert all(cmds[t] is None for t in cmds if t > 3.5)


def test_config_from_dict_and_schema_agree():
    schema = json.loads((SCHEMAS / "teleop.schema.json").read_text())
    cfg = TeleopConfig()
    from beastbt.robot.actuator_profile import TELEOP_TWIST_JOY_NAMES  # aliases, resolved by the profile reader
    assert set(schema["properties"]) - set(TELEOP_TWIST_JOY_NAMES) == set(vars(cfg))
    for key, value in vars(cfg).items():
        assert schema["properties"][key]["default"] == value
    jsonschema.validate({"scale_linear_mps": 0.3}, schema)
    assert TeleopConfig.from_dict({"scale_linear_mps": 1}).scale_linear_mps == 1.0
    with pytest.raises(ValueError, match="did you mean 'scale_linear_mps'"):
        TeleopConfig.from_dict({"scale_linear": 0.3})
    with pytest.raises(ValueError, match="zero or positive"):
        TeleopConfig.from_dict({"scale_angular_rps": -1})
