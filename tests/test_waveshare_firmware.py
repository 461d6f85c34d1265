"""The Waveshare emulator follows each firmware's source, and the driver reads both (docs/hardware/waveshare.md)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from beastbt.blackboard.types import BatteryState, ImuSample, VelocityCommand, WheelOdometry
from beastbt.devices.waveshare_base import WaveshareBase, WaveshareConfig
from beastbt.sim.dynamics import DiffDriveSim, DriveModel
from beastbt.sim.serial_port import SimSerialPort
from beastbt.sim.truth import RobotTruth
from beastbt.sim.waveshare_emulator import SimWaveshareBase


def board(firmware: str, **kw) -> SimWaveshareBase:
    model = DriveModel(track_width_m=0.141, max_wheel_speed_mps=1.0, max_wheel_accel_mps2=100.0,
                       motor_time_constant_s=0.0, slip_sigma=0.0, slip_bias=0.0, footprint_radius_m=0.1)
    return SimWaveshareBase(DiffDriveSim(model, RobotTruth(), np.random.default_rng(0)),
                            np.random.default_rng(1), firmware=firmware, **kw)


def send(esp32: SimWaveshareBase, *commands: dict) -> None:
    for c in commands:
        esp32.port.write(json.dumps(c).encode() + b"\n")


def run_for(esp32: SimWaveshareBase, seconds: float, dt: float = 0.01) -> None:
    for _ in range(int(round(seconds / dt))):
        esp32.drive.step(dt)
        esp32.update(esp32.now_s + dt, dt)


def lines(esp32: SimWaveshareBase) -> list[dict]:
    data = esp32.port.read(esp32.port.in_waiting)
    return [json.loads(x) for x in data.splitlines() if x.strip()]


# -- the heartbeat --------------------------------------------------------------------------------

@pytest.mark.parametrize("firmware, resets", [("ros", False), ("general", True)])
def test_t13_resets_the_heartbeat_only_on_the_general_firmware(firmware, resets):
    esp32 = board(firmware)
    send(esp32, {"T": 900, "main": 3, "module": 0}, {"T": 136, "cmd": 500})
    run_for(esp32, 1.0)  # the boot-time heartbeat has fired (no command yet): its one stop is spent
    send(esp32, {"T": 13, "X": 0.3, "Z": 0.0})
    run_for(esp32, 2.0)
    moving = esp32.drive.target_left_mps != 0.0
    assert moving is not resets  # ros: still driving 2 s after the last T:13; general: stopped after 0.5 s


@pytest.mark.parametrize("firmware", ["ros", "general"])
def test_t1_resets_the_heartbeat_on_both_and_the_base_stops_once_it_lapses(firmware):
    esp32 = board(firmware)
    send(esp32, {"T": 900, "main": 3, "module": 0}, {"T": 136, "cmd": 500})
    send(esp32, {"T": 1, "L": 0.3, "R": 0.3})
    run_for(esp32, 0.45)
    assert esp32.drive.target_left_mps == pytest.approx(0.3)
    run_for(esp32, 0.1)
    assert esp32.drive.target_left_mps == 0.0 and esp32.heartbeat_stops >= 1


# -- T:0, torque, limits --------------------------------------------------------------------------

def test_t0_releases_every_servo_on_ros_and_does_nothing_on_general():
    ros, general = board("ros"), board("general")
    for esp32 in (ros, general):
        send(esp32, {"T": 900, "main": 3, "module": 2}, {"T": 1, "L": 0.2, "R": 0.2}, {"T": 0})
    assert ros.drive.target_left_mps == 0.0 and not ros.gimbal.torque_on and ros.estops == 1
    assert general.drive.target_left_mps == pytest.approx(0.2) and general.gimbal.torque_on
    send(ros, {"T": 210, "cmd": 1})
    assert ros.gimbal.torque_on


def test_a_wheel_speed_beyond_2_mps_is_ignored_not_clamped():
    esp32 = board("ros")
    send(esp32, {"T": 900, "main": 3, "module": 0}, {"T": 1, "L": 0.2, "R": 0.2}, {"T": 1, "L": 2.5, "R": 2.5})
    assert esp32.drive.target_left_mps == pytest.approx(0.2) and esp32.ignored_speeds == 1


def test_the_driver_clamps_keeping_the_curvature_and_warns_once():
    events = []
    port = SimSerialPort()
    base = WaveshareBase(port, WaveshareConfig(), lambda kind, text: events.append(kind), track_width_m=0.2)
    assert base.wheel_speeds(VelocityCommand(3.0, 5.0)) == pytest.approx((2.5 * 2.0 / 3.5, 2.0))
    base.wheel_speeds(VelocityCommand(4.0, 0.0))
    assert events == ["base_speed_clamped"]


# -- boot state and odometry ---------------------------------------------------------------------

def test_boot_state_per_firmware():
    ros, general = board("ros"), board("general")
    run_for(ros, 0.2)
    run_for(general, 0.2)
    assert lines(ros) and not lines(general)  # general: feedback off until T:131
    send(general, {"T": 131, "cmd": 1})
    assert lines(general)[0] == {"T": 131, "cmd": 1}  # echo on at boot: the command comes back first
    assert (ros.main_type, general.main_type) == (2, 1)


def test_ros_odometry_is_whole_centimetres_through_the_main_types_wheel():
    esp32 = board("ros")
    esp32.drive.truth.left_m = esp32.drive.truth.right_m = 1.2345
    send(esp32, {"T": 900, "main": 3, "module": 0})
    run_for(esp32, 0.06)
    fb = [x for x in lines(esp32) if x["T"] == 1001][-1]
    assert fb["odl"] == 123 and isinstance(fb["odl"], int)
    assert isinstance(fb["v"], int) and "r" not in fb
    send(esp32, {"T": 900, "main": 2, "module": 0})  # a board left as a UGV Rover: 80 mm wheel, 660 counts
    run_for(esp32, 0.06)
    fb = [x for x in lines(esp32) if x["T"] == 1001][-1]
    assert fb["odl"] == int(1.2345 * (1092 / 660) * (0.08 / 0.0523) * 100)


def test_general_feedback_has_attitude_and_volts_but_no_odometry():
    esp32 = board("general")
    send(esp32, {"T": 143, "cmd": 0}, {"T": 900, "main": 3, "module": 2}, {"T": 131, "cmd": 1})
    run_for(esp32, 0.05)
    fb = [x for x in lines(esp32) if x.get("T") == 1001][-1]
    assert {"L", "R", "r", "p", "y", "temp", "v", "pan", "tilt"} <= set(fb)
    assert "odl" not in fb and "gx" not in fb and isinstance(fb["v"], float) and 10 < fb["v"] < 13


# -- the driver reads both -------------------------------------------------------------------------

def test_the_driver_reads_the_general_firmware_and_integrates_its_wheel_speeds():
    events = []
    port = SimSerialPort()
    base = WaveshareBase(port, WaveshareConfig(), lambda kind, text: events.append((kind, text)))
    out = []
    for i in range(11):  # 0.5 s at 0.2 m/s, 20 Hz
        port.feed(json.dumps({"T": 1001, "L": 0.2, "R": 0.2, "r": 0.0, "p": 0.0, "y": 10.0, "temp": 40.0,
                              "v": 11.87}).encode() + b"\n")
        out += base.poll(0.05 * i)
    assert base.firmware == "general" and events[0][0] == "base_firmware" and "ugv_base_general" in events[0][1]
    odo = [r for r in out if isinstance(r, WheelOdometry)]
    assert odo[-1].left_m == pytest.approx(0.1) and not [r for r in out if isinstance(r, ImuSample)]
    assert [r for r in out if isinstance(r, BatteryState)][-1].voltage_v == pytest.approx(11.87)


def test_the_driver_refines_whole_centimetres_without_drifting_from_them():
    port = SimSerialPort()
    base = WaveshareBase(port, WaveshareConfig(firmware="ros"))
    got = []
    for i in range(40):  # true distance 0.2 m/s * t; the firmware truncates to whole cm
        t = 0.05 * i
        cm = int(0.2 * t * 100)
        port.feed(json.dumps({"T": 1001, "L": 0.2, "R": 0.2, "odl": cm, "odr": cm, "v": 1187}).encode() + b"\n")
        got += [(t, r.left_m) for r in base.poll(t) if isinstance(r, WheelOdometry)]
    assert max(abs(left - 0.2 * t) for t, left in got) < 0.002  # finer than the 1 cm counts
    # A speed that lies (slip) is held within the count: never more than 1 cm from what the encoders say.
    port.feed(json.dumps({"T": 1001, "L": 5.0, "R": 5.0, "odl": 40, "odr": 40, "v": 1187}).encode() + b"\n")
    assert [r for r in base.poll(2.5) if isinstance(r, WheelOdometry)][0].left_m <= 0.41


def test_bus_servo_errors_become_events_without_flooding():
    events = []
    port = SimSerialPort()
    base = WaveshareBase(port, WaveshareConfig(), lambda kind, text: events.append((kind, text)))
    for i in range(100):  # the firmware repeats T:1005 every loop
        port.feed(b'{"T":1005,"id":2,"status":0}\n{"T":1005,"id":1,"status":0}\n')
        base.poll(0.05 * i)
    errors = [text for kind, text in events if kind == "bus_servo_error"]
    assert len(errors) == 2 and "gimbal pan" in errors[0] and "gimbal tilt" in errors[1]
    base.poll(10.0)
    port.feed(b'{"T":1005,"id":2,"status":0}\n')
    base.poll(10.1)
    assert "reports so far" in [text for kind, text in events if kind == "bus_servo_error"][-1]


def test_a_module_without_its_gimbal_reports_t1005_through_the_whole_stack():
    from beastbt.testing import MissionHarness
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - wait: 1 s\n")
    h.run.io.esp32.gimbal_present = False
    h.run_to_end()
    assert any(e.kind == "bus_servo_error" and "gimbal pan" in e.text for e in h.events)
    assert math.isfinite(h.summary()["sim_time_s"])
