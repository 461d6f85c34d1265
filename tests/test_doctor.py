"""``beastbt doctor``: every device of a profile probed without moving, against fakes and missing devices."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import pytest
import yaml

from beastbt.robot import doctor
from beastbt.robot.doctor import FAIL, OK, WARN, DoctorContext, check_can, check_pi_uart
from beastbt.robot.profile import load_profile
from conftest import REPO
from fake_waveshare import FakeWaveshare

MT3339 = REPO / "tests" / "data" / "nmea" / "mt3339.log"


def profile_file(tmp_path: Path, keep: tuple[str, ...], **sections) -> Path:
    """robots/ugv_beast.yaml with only the device sections in ``keep``, each updated with ``sections``."""
    data = yaml.safe_load((REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8"))
    for name in ("gps", "imu", "camera", "lidar", "joystick", "servos"):
        if name not in keep:
            data.pop(name, None)
    for name, values in sections.items():
        data.setdefault(name, {}).update(values)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def run_doctor(profile: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", "doctor", "--robot", str(profile)], capture_output=True,
                          text=True, timeout=60, env=dict(os.environ, PYTHONPATH=str(REPO)))


def lines(out: str, device: str) -> list[str]:
    return [line for line in out.splitlines() if line[5:].startswith(f"{device}:")]


@pytest.mark.parametrize("firmware", ["ros", "general"])
def test_the_base_answers_with_its_firmware_and_nothing_moves(tmp_path, firmware):
    with FakeWaveshare(firmware) as fake:
        done = run_doctor(profile_file(tmp_path, (), base={"port": fake.port}))
        sent = [c for _, c in fake.received]
    assert done.returncode == 0, done.stdout + done.stderr
    base = lines(done.stdout, "base")
    assert any(line.startswith("OK") and f"ugv_base_{firmware}" in line and "battery" in line for line in base), base
    assert (firmware == "general") == any(line.startswith("WARN") and "odometry" in line for line in base)
    assert not [c for c in sent if c.get("T") in (0, 1, 11, 13, 133, 210)], "the doctor sent a motion command"


def test_a_base_that_does_not_answer_fails_with_a_fix(tmp_path):
    master, slave = os.openpty()  # a port with nothing behind it
    try:
        tty.setraw(slave)
        done = run_doctor(profile_file(tmp_path, (), base={"port": os.ttyname(slave)}))
    finally:
        os.close(master)
        os.close(slave)
    assert done.returncode == 1
    [line] = [line for line in lines(done.stdout, "base") if line.startswith("FAIL")]
    assert "nothing on" in line and "Fix:" in line


def test_missing_devices_each_fail_with_their_fix(tmp_path):
    profile = profile_file(tmp_path, ("gps", "imu", "camera", "joystick"),
                           base={"port": str(tmp_path / "no-serial0")}, gps={"port": str(tmp_path / "no-gps")},
                           imu={"bus": 97}, camera={"device": str(tmp_path / "no-video0"), "backend": "v4l2"},
                           joystick={"device": str(tmp_path / "no-js0")})
    done = run_doctor(profile)
    assert done.returncode == 1
    out = done.stdout
    for device in ("base", "gps", "imu", "camera"):
        found = lines(out, device)
        assert len(found) == 1 and found[0].startswith("FAIL") and "Fix:" in found[0], (device, out)
    assert lines(out, "joystick")[0].startswith("WARN")  # teleop needs it; a mission may not
    assert "failed" in out.splitlines()[-1] and out.splitlines()[-1].endswith(", 1 warning")


def test_a_missing_extra_uart_is_told_to_use_its_overlay_not_raspi_config(tmp_path):
    if Path("/dev/ttyAMA1").exists():
        pytest.skip("this machine has a /dev/ttyAMA1")
    profile = profile_file(tmp_path, ("gps",), base={"port": str(tmp_path / "no-serial0")}, gps={"port": "/dev/ttyAMA1"})
    done = run_doctor(profile)
    (gps,) = lines(done.stdout, "gps")
    assert gps.startswith("FAIL") and "dtoverlay=uart3" in gps and "raspi-config" not in gps, gps
    (base,) = lines(done.stdout, "base")
    assert "raspi-config" in base and "dtoverlay" not in base  # the primary UART: raspi-config does enable it


def test_two_devices_on_one_uart_fail(tmp_path):
    with FakeWaveshare("ros") as fake:
        link = tmp_path / "serial0"
        link.symlink_to(fake.port)  # as /dev/serial0 -> ttyS0 while the GPS is set to /dev/ttyS0
        done = run_doctor(profile_file(tmp_path, ("gps",), base={"port": str(link)}, gps={"port": fake.port}))
    assert done.returncode == 1
    assert any(line.startswith("FAIL") and "same UART as the base's" in line for line in lines(done.stdout, "gps"))


def play_nmea(master: int, text: bytes, stop: threading.Event) -> None:
    """Write a real NMEA capture to the pty, one sentence every 20 ms."""
    for line in text.splitlines(keepends=True):
        if stop.is_set():
            return
        if not line.startswith(b"#"):  # the capture's own header
            os.write(master, line.rstrip(b"\r\n") + b"\r\n")
            time.sleep(0.02)


@pytest.mark.parametrize("capture, level, says", [
    (MT3339.read_bytes(), OK, "talks NMEA at 9600 baud: fix quality 2"),
    (b"\x00\xff\x13garbage at the wrong baud\r\n" * 200, FAIL, "no valid NMEA"),
])
def test_the_gps_talks_at_its_baud_with_fix_and_satellites(tmp_path, capture, level, says):
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    stop = threading.Event()
    feeder = threading.Thread(target=play_nmea, args=(master, capture, stop), daemon=True)
    try:
        profile = load_profile(profile_file(tmp_path, ("gps",), base={"port": str(tmp_path / "none")},
                                            gps={"port": os.ttyname(slave)}))
        feeder.start()
        found = [f for f in doctor.diagnose(profile) if f.device == "gps"]
    finally:
        stop.set()
        feeder.join(timeout=2)
        os.close(master)
        os.close(slave)
    assert found[0].text.endswith("exists") and found[-1].level == level and says in found[-1].text, found
    if level == OK:
        assert found[-1].text.endswith("satellites") and int(found[-1].text.split()[-2]) >= 4


def fake_pi(root: Path, config: str, cmdline: str) -> Path:
    (root / "proc/device-tree").mkdir(parents=True)
    (root / "proc/device-tree/model").write_bytes(b"Raspberry Pi 4 Model B Rev 1.5\0")
    (root / "boot/firmware").mkdir(parents=True)
    (root / "boot/firmware/config.txt").write_text(config)
    (root / "boot/firmware/cmdline.txt").write_text(cmdline)
    return root


def test_on_a_pi_the_uart_must_be_enabled_and_free_of_a_login_console(tmp_path):
    profile = load_profile("ugv_beast")
    bad = fake_pi(tmp_path / "bad", "# enable_uart=1\ndtoverlay=disable-bt\n",
                  "console=serial0,115200 console=tty1 root=PARTUUID=1 rootwait")
    found = list(check_pi_uart(DoctorContext(profile, None, bad)))  # type: ignore[arg-type]
    assert [f.level for f in found] == [FAIL, FAIL]
    assert "enable_uart=1" in found[0].fix and "console=serial0,115200" in found[1].text
    good = fake_pi(tmp_path / "good", "enable_uart=1\ndtoverlay=disable-bt\n", "console=tty1 root=PARTUUID=1")
    assert [f.level for f in check_pi_uart(DoctorContext(profile, None, good))] == [OK, OK]  # type: ignore[arg-type]
    assert list(check_pi_uart(DoctorContext(profile, None, tmp_path / "laptop"))) == []  # type: ignore[arg-type]


@pytest.mark.parametrize("link, level, says", [
    (None, FAIL, "there is no interface can0"),
    ({"up": False, "bitrate": 500000}, FAIL, "can0 is down"),
    ({"up": True, "bitrate": 250000}, FAIL, "runs at 250000 bit/s, the profile says 500000"),
    ({"up": True, "bitrate": 500000}, OK, "can0 is up at 500000 bit/s"),
])
def test_can_is_up_at_the_profiles_bitrate(monkeypatch, link, level, says):
    import beastbt.actuation.can_base as can_base
    monkeypatch.setattr(can_base, "socketcan_link", lambda channel: link)
    [finding] = check_can(DoctorContext(load_profile("diy_can"), None, Path("/")))  # type: ignore[arg-type]
    assert finding.level == level and says in finding.text
    if level == FAIL:
        assert "ip link set can0 up type can bitrate 500000" in finding.fix


def test_the_simulators_profile_has_nothing_to_check():
    done = run_doctor(Path("sim"))
    assert done.returncode == 0 and "simulator" in done.stdout


def test_a_bad_profile_is_invalid_input(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: x\nbase: {type: waveshare_serial, heartbeat_s: -1}\n")
    done = run_doctor(bad)
    assert done.returncode == 2 and "bad.yaml:" in done.stderr and "heartbeat_s" in done.stderr
