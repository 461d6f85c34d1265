"""Hardware in the loop without hardware: the real CLI against the Waveshare firmware emulated on a pty.

``beastbt run --robot PROFILE`` opens the profile's ``base.port``, here the
slave of a pseudo-terminal whose other end is the emulated ESP32 running
either firmware (:mod:`fake_waveshare`), in real time. The joystick is a
FIFO carrying Linux ``js_event`` records. What a Beast owner relies on:
the start-up sequence, the base's own heartbeat stopping the robot when
beastbt is killed, the joystick e-stop without any torque release, and a
2 m drive that the base's own odometry agrees with.
"""

from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from conftest import REPO
from fake_waveshare import FakeWaveshare

HEARTBEAT_S = 0.5
"""base.heartbeat_s of the profile under test (the schema's default)."""


def beast_profile(tmp_path: Path, port: str, firmware: str, joystick: str | None = None) -> Path:
    """robots/ugv_beast.yaml with only its base (on ``port``, running ``firmware``) and maybe a joystick."""
    data = yaml.safe_load((REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8"))
    for section in ("gps", "imu", "camera", "lidar", "joystick", "servos"):
        data.pop(section, None)
    data["base"].update(port=port, firmware=firmware)
    if joystick is not None:
        data["joystick"] = {"device": joystick}
    path = tmp_path / f"beast_{firmware}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def start_run(tmp_path: Path, mission_text: str, profile: Path) -> subprocess.Popen:
    mission = tmp_path / "mission.yaml"
    mission.write_text(mission_text, encoding="utf-8")
    return subprocess.Popen([sys.executable, "-m", "beastbt", "run", str(mission), "--robot", str(profile),
                             "--no-record", "--summary", str(tmp_path / "summary.json")],
                            cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(REPO)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for(predicate, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return False


@pytest.mark.parametrize("firmware, told", [("ros", "auto"), ("general", "auto"), ("general", "general")])
def test_start_up_sequence_and_firmware_detection(tmp_path, firmware, told):
    with FakeWaveshare(firmware) as fake:
        proc = start_run(tmp_path, "mission: still\nsteps:\n  - wait: 0.3 s\n", beast_profile(tmp_path, fake.port, told))
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        sent = [c for _, c in fake.received]
    assert sent[:7] == [{"T": 143, "cmd": 0}, {"T": 900, "main": 3, "module": 2}, {"T": 4, "cmd": 2},
                        {"T": 136, "cmd": 500}, {"T": 142, "cmd": 50}, {"T": 131, "cmd": 1},
                        {"T": 1, "L": 0.0, "R": 0.0}]
    assert not [c for c in sent if c.get("T") in (0, 13)], "no T:0 (torque release), no T:13 (no heartbeat)"
    assert sent[-1] == {"T": 1, "L": 0.0, "R": 0.0}
    events = json.loads((tmp_path / "summary.json").read_text())["events"]
    detected = [e["text"] for e in events if e["kind"] == "base_firmware"]
    assert detected == ([] if told != "auto" else [f"base: firmware ugv_base_{firmware} detected: " + detected[0].split(": ", 2)[2]])
    if told == "auto":
        assert f"ugv_base_{firmware}" in detected[0]


@pytest.mark.parametrize("firmware", ["ros", "general"])
def test_kill_9_while_driving_the_base_stops_itself_within_its_heartbeat(tmp_path, firmware):
    with FakeWaveshare(firmware) as fake:
        proc = start_run(tmp_path, "mission: far\nsteps:\n  - drive: {distance: 20 m, speed: 0.3 m/s}\n",
                         beast_profile(tmp_path, fake.port, firmware))
        try:
            assert wait_for(lambda: fake.moving_since() is not None, 30.0), proc.stderr.read() if proc.poll() else ""
            time.sleep(0.5)
            assert fake.drive.truth.v_mps > 0.1
            killed_at = time.monotonic()
            proc.send_signal(signal.SIGKILL)  # no watchdog, no atexit, no close: only the base's heartbeat is left
            proc.wait(timeout=10)
            assert wait_for(lambda: fake.stopped_at(killed_at) is not None, 3.0), "the base kept driving"
            stop = fake.stopped_at(killed_at) - killed_at
        finally:
            if proc.poll() is None:
                proc.kill()
    assert stop <= HEARTBEAT_S + 0.2, stop


def test_joystick_estop_stops_within_half_a_second_and_keeps_servo_torque(tmp_path):
    fifo = tmp_path / "js0"
    os.mkfifo(fifo)
    writer = os.open(fifo, os.O_RDWR | os.O_NONBLOCK)  # held open: the driver never sees an unplugged pad
    try:
        with FakeWaveshare("ros") as fake:
            proc = start_run(tmp_path, "mission: far\nsteps:\n  - drive: {distance: 20 m, speed: 0.3 m/s}\n",
                             beast_profile(tmp_path, fake.port, "ros", joystick=str(fifo)))
            try:
                assert wait_for(lambda: fake.moving_since() is not None, 30.0)
                time.sleep(0.5)
                pressed_at = time.monotonic()
                estop_button = 1  # ugv_beast.yaml's default mapping: B / circle
                os.write(writer, struct.pack("<IhBB", 1000, 1, 0x01, estop_button))
                assert wait_for(lambda: fake.stopped_at(pressed_at) is not None, 2.0)
                stop = fake.stopped_at(pressed_at) - pressed_at
                out, err = proc.communicate(timeout=30)
            finally:
                if proc.poll() is None:
                    proc.kill()
            sent = [c for _, c in fake.received]
    finally:
        os.close(writer)
    assert stop <= 0.5, stop
    assert proc.returncode == 1 and "emergency stop" in out, (out, err)
    assert {"T": 135} in sent  # the gimbal stopped where it is...
    assert {"T": 0} not in sent and {"T": 210, "cmd": 0} not in sent  # ...and never limp
    assert fake.esp32.gimbal.torque_on


@pytest.mark.parametrize("firmware", ["ros", "general"])
def test_a_2_m_drive_ends_within_10_percent_by_the_bases_odometry(tmp_path, firmware):
    with FakeWaveshare(firmware) as fake:
        proc = start_run(tmp_path, "mission: two\nsteps:\n  - drive: {distance: 2 m, speed: 0.35 m/s}\n",
                         beast_profile(tmp_path, fake.port, firmware))
        out, err = proc.communicate(timeout=60)
        time.sleep(0.3)  # let the tracks come to rest
        left, right = fake.odometry_m()
    assert proc.returncode == 0, err
    assert (left + right) / 2 == pytest.approx(2.0, rel=0.10)
