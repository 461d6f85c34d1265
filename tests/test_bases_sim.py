"""Every base adapter's wire output pinned against its protocol; CAN, PWM and Waveshare profiles on the simulator;
real profiles that cannot open a device stop before moving."""

from __future__ import annotations

import io
import json
import os
import signal
from pathlib import Path

import can
import pytest
from conftest import REPO

from beastbt import cli
from beastbt.actuation.can_base import CanBase, CanBaseConfig
from beastbt.actuation.pwm_base import PwmBase, PwmBaseConfig
from beastbt.actuation.watchdog import AdapterWatchdog
from beastbt.blackboard.types import VelocityCommand as V
from beastbt.devices.pca9685 import Pca9685
from beastbt.devices.waveshare_base import WaveshareBase
from beastbt.mission.model import load_mission
from beastbt.core.clock import SimClock
from beastbt.core.events import EventLog
from beastbt.assembly import assemble
from beastbt.parts.joystick import attach_joystick
from beastbt.parts.teleop import TeleopPart
from beastbt.robot.part import REAL
from beastbt.robot.profile import load_profile
from beastbt.robot.robot_io import RobotIO
from beastbt.assembly import prepare
from beastbt.run.session import RunOptions, execute
from beastbt.sim.i2c_bus import SimI2CBus
from beastbt.sim.pca9685_emulator import SimPca9685
from beastbt.sim.serial_port import SimSerialPort
from beastbt.testing import MissionHarness

ROBOTS = REPO / "robots"
SEQUENCE = [V(0.2, 0.0), V(0.0, 0.1), V(-0.1, 0.5)]
"""A known command sequence, sent after start and followed by an e-stop and close."""


def play(base) -> None:
    base.start(0.0)
    for i, cmd in enumerate(SEQUENCE):
        base.send_velocity(cmd, 0.05 * (i + 1))
    base.emergency_stop(0.2)
    base.close()


# -- pinned protocols -----------------------------------------------------------------------

def test_waveshare_bytes_for_a_known_sequence():
    written = bytearray()
    play(WaveshareBase(SimSerialPort(on_write=written.extend)))
    assert bytes(written).decode().splitlines() == [
        '{"T":143,"cmd":0}',                      # echo off
        '{"T":900,"main":3,"module":2}', '{"T":4,"cmd":2}',  # UGV Beast with its gimbal (as ugv_rpi sends)
        '{"T":136,"cmd":500}',                    # the base's own heartbeat: 0.5 s
        '{"T":142,"cmd":50}', '{"T":131,"cmd":1}',  # feedback every 50 ms, continuously
        '{"T":1,"L":0.0,"R":0.0}',                # arms the heartbeat
        '{"T":1,"L":0.2,"R":0.2}',                # wheel speeds, m/s: they reset the heartbeat (T:13 would not)
        '{"T":1,"L":-0.0141,"R":0.0141}',         # 0.1 rad/s in place raised to 0.2 rad/s, 0.141 m track
        '{"T":1,"L":-0.1353,"R":-0.0648}',
        '{"T":1,"L":0.0,"R":0.0}', '{"T":135}',   # e-stop: zero speed, gimbal stopped; torque kept
        '{"T":1,"L":0.0,"R":0.0}',                # close: a final stop
    ]


def test_can_frames_for_a_known_sequence():
    channel = f"beastbt-test-pin-{os.getpid()}"
    sniffer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    cfg = CanBaseConfig(interface="virtual", channel=channel)  # HARDWARE.md: 0x100, int16 LE, 0.01 rad/s, r = 0.04 m
    play(CanBase(can.Bus(interface="virtual", channel=channel, receive_own_messages=False), cfg))
    frames = []
    while (m := sniffer.recv(timeout=0)) is not None:
        frames.append((m.arbitration_id, m.is_extended_id, bytes(m.data).hex(" ")))
    sniffer.shutdown()
    assert frames == [
        (0x100, False, "00 00 00 00"),   # start: from a known stop
        (0x100, False, "f4 01 f4 01"),   # 0.2 m/s both: 5 rad/s = 500 = 0x01f4
        (0x100, False, "e7 ff 19 00"),   # turn 0.1 rad/s on a 0.2 m track: -/+0.01 m/s = -/+25
        (0x100, False, "89 fe 83 ff"),   # -0.15 m/s = -375, -0.05 m/s = -125
        (0x100, False, "00 00 00 00"),   # e-stop: zero (the example protocol has no stop frame)
        (0x100, False, "00 00 00 00"),   # close
    ]


def test_pwm_register_writes_for_a_known_sequence():
    bus = SimI2CBus()
    chip = SimPca9685()
    bus.attach(0x40, chip)
    play(PwmBase(Pca9685(bus), PwmBaseConfig()))  # ESCs on channels 0/1, 50 Hz, 0.5 m/s at full pulse

    def esc(off: int) -> list[tuple[int, int]]:
        # ON = 0, OFF = count; 4 registers per channel from 0x06 (ch0) and 0x0a (ch1), one block write each.
        return [(0, 0), (0, 0), (off & 0xFF, 0), (off >> 8, 0)]

    def pair(left: int, right: int) -> list[tuple[int, int]]:
        return [(0x06 + i, v) for i, (v, _) in enumerate(esc(left))] + [(0x0A + i, v) for i, (v, _) in enumerate(esc(right))]

    # Counts = round(pulse * 25 MHz / (prescale + 1)) with prescale round(25e6 / (4096 * 50)) - 1 = 121.
    assert chip.writes == (
        [(0x01, 0x04), (0x00, 0x11), (0xFE, 121), (0x00, 0x01), (0x00, 0xA1)]  # OUTDRV, sleep, prescale, wake, restart|AI
        + pair(307, 307)   # neutral 1.5 ms
        + pair(348, 348)   # 0.2 m/s = 40 %: 1.7 ms
        + pair(305, 309)   # -/+0.01 m/s: 1.49 / 1.51 ms
        + pair(277, 297)   # -0.15 / -0.05 m/s: 1.35 / 1.45 ms
        + pair(307, 307)   # e-stop: neutral
        + pair(307, 307)   # close: neutral
    )


# -- profiles on the simulator --------------------------------------------------------------

MISSION = """
mission: t
steps:
  - drive: {distance: 1 m, speed: 0.2 m/s}
  - turn: {angle: 90 deg}
"""


def test_can_profile_on_the_simulator_drives_through_the_virtual_bus():
    h = MissionHarness.from_yaml(MISSION, robot=str(ROBOTS / "diy_can.yaml"))
    controller = h.run.io.can_controller
    assert isinstance(h.run.io.base, AdapterWatchdog) and isinstance(h.run.io.base.inner, CanBase)
    assert h.run.io.esp32 is None
    assert h.run_to_end(30) == "success"
    assert controller.commands_received >= h.run.ticks
    odo = h.blackboard("odometry")
    assert 0.5 * (odo.left_m + odo.right_m) == pytest.approx(1.0, abs=0.05)
    assert h.run.io.base.inner.feedback_frames > 0 and h.run.io.base.inner.error_frames == 0
    assert abs(h.truth.x - 1.0) < 0.15 and h.truth.yaw == pytest.approx(1.5708, abs=0.1)
    assert "pwm_servos" in h.run.io.capabilities and h.run.io.servo_names() == {"pan", "tilt"}
    h.run.io.close()


def test_pwm_profile_on_the_simulator_teleop_and_servos():
    h = MissionHarness.from_yaml("""
mission: t
steps:
  - look: {pan: 30 deg, tilt: 20 deg}
  - servo: {channel: 1, pulse: 1.6 ms}
  - drive: {time: 2 s, speed: 0.2 m/s}
  - teleop: {for: 2 s}
""", robot=str(ROBOTS / "diy_pwm.yaml"), joystick=[{"at": "3.5 s", "press": "enable"}, {"at": "3.5 s", "angular": 1.0}])
    chip = h.run.io.sim_pca9685
    h.tick_until(lambda h: h.now_s >= 0.3)
    assert h.truth.pan_rad == pytest.approx(0.5236, abs=0.01)   # pan servo on channel 0 turned the camera
    assert h.truth.tilt_rad == pytest.approx(0.3491, abs=0.01)
    assert chip.pulse_s(0) * 1e3 == pytest.approx(1.5 + 30 / 90 * 0.5, abs=0.006)
    assert h.run_to_end(30) == "success"
    assert chip.pulse_s(1) * 1e3 == pytest.approx(1.6, abs=0.006)
    assert h.truth.x > 0.3                 # driven by time, open loop through the ESC pulses
    assert abs(h.truth.yaw) > 0.5          # and turned by the operator
    assert h.blackboard("odometry") is None  # no encoders on this base


def test_beast_profile_on_the_simulator(tmp_path):
    m = tmp_path / "m.yaml"
    m.write_text(MISSION)
    assert cli.main(["run", "--robot", str(ROBOTS / "ugv_beast.yaml"), "--sim", str(m), "--no-record"]) == 0
    assert cli.main(["run", "--robot", str(ROBOTS / "diy_can.yaml"), "--sim", str(m), "--no-record"]) == 0


@pytest.mark.parametrize("robot", ["sim", "diy_can", "diy_pwm"])
def test_the_last_thing_on_the_wire_is_a_stop(tmp_path, robot):
    m = tmp_path / "m.yaml"
    m.write_text("mission: t\nsteps:\n  - drive: {time: 5 s, speed: 0.2 m/s}\n")
    profile = "sim" if robot == "sim" else str(ROBOTS / f"{robot}.yaml")
    p = prepare(str(m), RunOptions(robot=profile, record=False, max_time_s=1.0, simulate=True))
    x = p.run.io
    sniffer = can.Bus(interface="virtual", channel=x.can_channel) if x.can_channel is not None else None
    summary = execute(p, io.StringIO())
    assert summary["status"] == "stopped" and summary["distance_m"] > 0.05
    if robot == "sim":
        assert x.esp32.commands[-1] == {"T": 1, "L": 0.0, "R": 0.0}
    elif robot == "diy_can":
        frames = []
        while (f := sniffer.recv(timeout=0)) is not None:
            frames.append(f)
        sniffer.shutdown()
        assert any(bytes(f.data) != bytes(4) for f in frames if f.arbitration_id == 0x100)
        assert frames[-1].arbitration_id == 0x100 and bytes(frames[-1].data) == bytes(4)
    else:
        chip = x.sim_pca9685
        assert chip.pulse_s(14) * 1e3 == pytest.approx(1.5, abs=0.006)
        assert chip.pulse_s(15) * 1e3 == pytest.approx(1.5, abs=0.006)
        last = chip.writes[-8:]
        assert [r for r, _ in last] == [0x3E, 0x3F, 0x40, 0x41, 0x42, 0x43, 0x44, 0x45]  # channels 14 and 15


# -- real profiles: stop before moving, name the device ----------------------------------------

def variant(tmp_path: Path, name: str, old: str, new: str) -> Path:
    text = (ROBOTS / f"{name}.yaml").read_text()
    assert old in text
    out = tmp_path / f"{name}.yaml"
    out.write_text(text.replace(old, new))
    return out


@pytest.mark.parametrize("name,old,new,expect", [
    ("ugv_beast", "port: /dev/serial0", "port: /dev/beastbt-no-such-port", ["base (Waveshare ESP32)", "/dev/beastbt-no-such-port", "check"]),
    ("diy_can", "channel: can0", "channel: bbtnocan0", ["CAN motor controller", "bbtnocan0", "ip link set bbtnocan0 up"]),
    ("diy_pwm", "bus: 1 ", "bus: 97 ", ["PCA9685", "/dev/i2c-97", "I2C is enabled"]),
])
def test_a_missing_device_stops_the_run_before_moving(tmp_path, capsys, name, old, new, expect):
    profile = variant(tmp_path, name, old, new)
    m = tmp_path / "m.yaml"
    m.write_text(MISSION)
    assert cli.main(["run", "--robot", str(profile), str(m), "--no-record"]) == 2
    err = capsys.readouterr().err
    for word in expect:
        assert word in err


@pytest.mark.skipif(os.path.exists("/dev/serial0"), reason="this machine has the Beast's serial port")
def test_the_beast_profile_names_its_base_port_here(tmp_path, capsys):
    m = tmp_path / "m.yaml"
    m.write_text(MISSION)
    assert cli.main(["run", "--robot", str(ROBOTS / "ugv_beast.yaml"), str(m), "--no-record"]) == 2
    assert "/dev/serial0" in capsys.readouterr().err


class FakeBase:
    name = "fake"

    def __init__(self) -> None:
        self.sent: list = []

    def start(self, now_s: float) -> None:
        self.sent.append("start")

    def send_velocity(self, cmd: V, now_s: float) -> None:
        self.sent.append((cmd.linear_mps, cmd.angular_rps))

    def emergency_stop(self, now_s: float) -> None:
        self.sent.append("estop")

    def poll(self, now_s: float) -> list:
        return []

    def close(self) -> None:
        self.sent.append("close")


def test_missing_joystick_is_an_event_and_the_teleop_step_says_no_joystick(tmp_path):
    profile = load_profile(variant(tmp_path, "ugv_beast", "device: /dev/input/js0", "device: /dev/input/beastbt-js-none"))
    clock = SimClock()
    events = EventLog(clock)
    robot = RobotIO(base=FakeBase())
    attach_joystick(profile, robot, clock, events)
    ev = events.last("joystick_unavailable")
    assert ev is not None and "/dev/input/beastbt-js-none" in ev.text and "'input' group" in ev.text
    assert robot.sensors["joystick"](0.0)[0].connected is False
    mission = load_mission(str(tmp_path / "m.yaml"), text="mission: t\nsteps:\n  - teleop: {for: 5 s}\n")
    run = assemble(mission, profile, RunOptions(record=False), REAL, io=robot, clock=clock, parts=[TeleopPart()]).run
    events = run.events
    assert run.tick() == "failure"
    said = events.last("step_failed").text
    assert "no joystick: plug in the gamepad" in said and "--console" in said and "--joystick" not in said


def test_real_mode_runs_the_watchdog_thread_and_ends_with_a_stop(tmp_path, monkeypatch):
    base = FakeBase()
    monkeypatch.setattr("beastbt.parts.can_base.open_can_base", lambda profile, clock, events: RobotIO(base=base))
    profile = tmp_path / "real.yaml"
    profile.write_text("""
robot: real_can
geometry: {track_width_m: 0.25}
limits: {max_speed_mps: 0.5, max_turn_rate_dps: 90}
base: {type: can}
joystick: {device: /dev/input/beastbt-js-none}
""")
    m = tmp_path / "m.yaml"
    m.write_text("mission: t\nsteps:\n  - drive: {time: 0.3 s, speed: 0.1 m/s}\n")
    js = tmp_path / "js.yaml"
    js.write_text("- {at: 1 s, press: enable}\n")
    with pytest.raises(Exception, match="simulator only"):
        prepare(str(m), RunOptions(robot=str(profile), record=False, joystick_script=str(js)))
    assert base.sent[-1] == "close"  # a run that fails to assemble releases what it opened
    base.sent.clear()
    before = signal.getsignal(signal.SIGTERM)
    p = prepare(str(m), RunOptions(robot=str(profile), record=False))
    dog = p.run.io.base
    assert isinstance(dog, AdapterWatchdog) and dog.running
    summary = execute(p, io.StringIO())
    assert summary["status"] == "success"
    assert not dog.running
    assert base.sent[0] == "start" and base.sent[-1] == "close"
    assert any(s != "start" and s != "close" and s[0] > 0 for s in base.sent)
    assert signal.getsignal(signal.SIGTERM) is before
    assert json.dumps(summary["teleop"])
