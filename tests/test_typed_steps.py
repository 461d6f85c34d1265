"""The loader gives typed steps: one frozen dataclass per step, SI units, the source position of each."""

from __future__ import annotations

import dataclasses
import math

import pytest

from beastbt.assembly import BUILTIN_PARTS
from beastbt.core.errors import Position
from beastbt.mission import steps as st
from beastbt.mission.compile import CORE_STEPS
from beastbt.mission.model import load_mission

EVERY_STEP = """\
mission: every_step
places:
  gate: {lat: 40.0001, lon: -3.0002, tolerance: 1.5 m}
  yard: {lat: 40.0003, lon: -3.0001}
tasks:
  peek:
    - look: {pan: -45 deg, tilt: 10 deg, settle: 300 ms}
steps:
  - drive: {distance: 3 m, speed: 15 cm/s, stuck_after: 4 s}
  - drive: {time: 2 s}
  - turn: {angle: 90 deg, rate: 30 deg/s}
  - turn: {heading: 180 deg}
  - wait: 500 ms
  - stop
  - go_to: gate
  - go_to: {lat: 40.0002, lon: -3.0003, tolerance: 2 m, speed: 0.2 m/s, gps_timeout: 5 s}
  - route: {places: [gate, yard], loops: forever}
  - return_home
  - follow_line: {until: {distance: 2 m}, speed: 0.1 m/s, lost_after: 1 s}
  - follow_line: {until: intersection}
  - servo: {name: arm, angle: 30 deg}
  - servo: {channel: 2, pulse: 1.5 ms}
  - snapshot: {name: here}
  - say: "hello # world"
  - teleop: {for: 10 s}
  - repeat: {times: 2, steps: [{do: peek}]}
  - retry: {times: 3, steps: [stop]}
  - timeout: {after: 1 min, steps: [stop]}
  - parallel: {succeed_on: any, steps: [stop, {wait: 1 s}]}
  - first_of: [[stop], [{wait: 2 s}]]
  - if: {battery_below: 11.5 V}
    then: [stop]
    else: [{wait: 1 s}]
  - while: {not: {near: gate, within: 5 m}}
    steps: [stop]
  - wait_until: {any: [intersection, {elapsed: 2 min}, {all: [gps_fix, teleop_active]}]}
    timeout: 30 s
"""


@pytest.fixture(scope="module")
def mission():
    return load_mission("every_step.yaml", text=EVERY_STEP)


def test_each_step_is_its_dataclass_with_si_values(mission):
    s = mission.steps
    assert s[0] == st.DriveDistance(distance_m=3.0, speed_mps=0.15, stuck_after_s=4.0, at=Position(9, 5),
                                    path=("steps", 0))
    assert s[1] == st.DriveTime(duration_s=2.0, speed_mps=None, at=Position(10, 5), path=("steps", 1))
    assert isinstance(s[2], st.TurnBy) and math.isclose(s[2].angle_rad, math.pi / 2)
    assert math.isclose(s[2].rate_rps, math.radians(30))
    assert isinstance(s[3], st.TurnToHeading) and math.isclose(s[3].heading_rad, math.pi) and s[3].rate_rps is None
    assert s[4].duration_s == 0.5 and isinstance(s[5], st.Stop)
    assert s[6] == st.GoToPlace(place="gate", at=Position(15, 5), path=("steps", 6))
    assert isinstance(s[7], st.GoToPoint) and (s[7].lat_deg, s[7].lon_deg, s[7].tolerance_m) == (40.0002, -3.0003, 2.0)
    assert (s[7].speed_mps, s[7].gps_timeout_s, s[7].stuck_after_s) == (0.2, 5.0, None)
    assert s[8].places == ("gate", "yard") and s[8].loops == st.FOREVER
    assert isinstance(s[9], st.ReturnHome) and s[9].tolerance_m is None
    assert (s[10].until, s[10].amount, s[10].speed_mps, s[10].lost_after_s) == ("distance", 2.0, 0.1, 1.0)
    assert (s[11].until, s[11].amount) == ("intersection", None)
    assert isinstance(s[12], st.ServoAngle) and s[12].name == "arm" and math.isclose(s[12].angle_rad, math.pi / 6)
    assert isinstance(s[13], st.ServoPulse) and (s[13].channel, s[13].pulse_s) == (2, 0.0015)
    assert s[14].name == "here" and s[15].text == "hello # world" and s[16].duration_s == 10.0


def test_flow_steps_nest_typed_steps_and_conditions(mission):
    s = mission.steps
    assert s[17].times == 2 and s[17].steps == (st.Do(task="peek", at=Position(26, 32), path=("steps", 17, "repeat", "steps", 0)),)
    assert s[18].times == 3 and isinstance(s[18].steps[0], st.Stop)
    assert s[19].after_s == 60.0 and s[20].succeed_on == "any" and s[20].steps[1].duration_s == 1.0
    assert len(s[21].alternatives) == 2 and s[21].alternatives[1][0].duration_s == 2.0
    assert s[22].condition == st.BatteryBelow(volts=11.5) and s[22].otherwise[0].duration_s == 1.0
    assert s[23].condition == st.Not(condition=st.Near(place="gate", within_m=5.0))
    assert s[24].timeout_s == 30.0
    assert s[24].condition == st.AnyOf(conditions=(st.Flag(word="intersection"), st.Elapsed(duration_s=120.0),
                                                   st.AllOf(conditions=(st.Flag(word="gps_fix"),
                                                                        st.Flag(word="teleop_active")))))
    peek = mission.tasks["peek"][0]
    assert isinstance(peek, st.Look) and math.isclose(peek.pan_rad, -math.pi / 4) and peek.settle_s == 0.3
    assert peek.at == Position(7, 7)


def test_steps_are_frozen(mission):
    with pytest.raises(dataclasses.FrozenInstanceError):
        mission.steps[0].distance_m = 5.0  # type: ignore[misc]
    assert isinstance(mission.steps, tuple) and isinstance(mission.steps[17].steps, tuple)


def test_every_step_class_has_a_builder_in_core_or_a_part():
    keywords = set(CORE_STEPS)
    for entry in BUILTIN_PARTS:
        keywords |= set(entry.load().steps())
    missing = [cls.__name__ for cls in st.CORE_STEP_CLASSES if cls.KEYWORD not in keywords]
    assert not missing, f"step classes without a builder: {missing}"
    assert {cls.KEYWORD for cls in st.CORE_STEP_CLASSES} == keywords  # and no builder without a step class
