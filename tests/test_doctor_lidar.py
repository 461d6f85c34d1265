"""``beastbt doctor``'s LiDAR check against the fake LD19 and the fake RPLIDAR A1 on pseudo-terminals."""

from __future__ import annotations

import os
import time
import tty
from pathlib import Path

import yaml

from beastbt.core.clock import WallClock
from beastbt.robot.doctor import FAIL, OK, WARN, DoctorContext, check_lidar, serial_ports
from beastbt.robot.profile import load_profile
from conftest import REPO
from fake_ld19 import FakeLd19
from fake_rplidar import FakeRplidar
from test_doctor import lines, run_doctor


def lidar_profile(tmp_path: Path, **lidar) -> Path:
    """robots/ugv_beast.yaml without its other devices, with ``lidar:``."""
    data = yaml.safe_load((REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8"))
    for name in ("gps", "imu", "camera", "joystick", "servos"):
        data.pop(name, None)
    data["lidar"] = lidar
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def check(tmp_path: Path, **lidar) -> list:
    profile = load_profile(lidar_profile(tmp_path, **lidar))
    return list(check_lidar(DoctorContext(profile, WallClock())))


def test_an_ld19_reports_packets_rate_and_points(tmp_path):
    with FakeLd19(rate_hz=10.0) as fake:
        [finding] = check(tmp_path, type="ld19", port=fake.port)
    assert finding.level == OK, finding.line()
    assert "0 CRC failures" in finding.text and "10.0 Hz" in finding.text
    points = int(finding.text.split(" points per scan")[0].rsplit(" ", 1)[1])
    assert 420 <= points <= 480


def test_a_noisy_ld19_line_is_a_warning(tmp_path):
    with FakeLd19() as fake:
        fake.bad_crc_next = 400  # about a second of bad packets, then good ones
        [finding] = check(tmp_path, type="ld19", port=fake.port)
    assert finding.level == WARN and "% bad" in finding.text and "noisy line" in finding.fix, finding.line()
    # Some went out before the port was open.
    assert int(finding.text.split(" CRC failures")[0].rsplit(" ", 1)[1]) >= 300


def test_an_ld19_that_does_not_spin_up_fails_with_the_fix(tmp_path):
    with FakeLd19(rate_hz=2.0) as fake:
        [finding] = check(tmp_path, type="ld19", port=fake.port)
    assert finding.level == FAIL and "not at speed" in finding.text and "supply" in finding.fix


def test_an_rplidar_reports_health_model_firmware_and_scans(tmp_path):
    with FakeRplidar() as fake:
        findings = check(tmp_path, type="rplidar_a1", port=fake.port)
        time.sleep(0.05)  # the fake's loop reads the STOP
        assert not fake.scanning and fake.requests[-1] == 0x25  # stopped after the check
    about, figures = findings
    assert about.level == OK and "A1M8, firmware 1.29, hardware 7" in about.text and "health good" in about.text
    assert figures.level == OK and "0 check-bit failures" in figures.text and " Hz" in figures.text


def test_an_rplidar_with_a_health_warning_is_a_warning(tmp_path):
    with FakeRplidar(health=(1, 0x0042)) as fake:
        findings = check(tmp_path, type="rplidar_a1", port=fake.port)
    assert findings[0].level == WARN and "warning (code 0x0042)" in findings[0].text


def test_a_port_with_nothing_behind_fails(tmp_path):
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        [finding] = check(tmp_path, type="rplidar_a1", port=os.ttyname(slave))
    finally:
        os.close(master)
        os.close(slave)
    assert finding.level == FAIL and "no answer to GET_HEALTH" in finding.text and finding.fix


def test_the_cli_prints_the_lidar_line_and_lists_its_port(tmp_path):
    profile = lidar_profile(tmp_path, type="ld19", port=str(tmp_path / "no-ttyUSB0"))
    assert ("lidar", str(tmp_path / "no-ttyUSB0")) in serial_ports(load_profile(profile))
    done = run_doctor(profile)
    assert done.returncode == 1
    [line] = lines(done.stdout, "lidar")  # the missing port, said once
    assert line.startswith("FAIL") and "does not exist" in line and "Fix:" in line


def test_the_shipped_beast_profile_has_waveshares_lidar_and_doctor_checks_it(tmp_path):
    """robots/ugv_beast.yaml as shipped carries the kit's LD19 (only its port is pointed at the fake here), so
    ``doctor`` checks it and the collision monitor protects the Beast."""
    data = yaml.safe_load((REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8"))
    assert data["lidar"]["type"] == "ld19" and data["lidar"]["port"] == "/dev/ttyACM0"
    assert data["lidar"]["mounting"]["yaw_deg"] == 90  # ugv_beast.urdf turns base_lidar_link by +pi/2
    assert load_profile("ugv_beast").section("lidar")["port"] == "/dev/ttyACM0"  # the shipped copy, by name
    with FakeLd19(rate_hz=10.0) as fake:
        [finding] = check(tmp_path, **dict(data["lidar"], port=fake.port))
    assert finding.level == OK and "10.0 Hz" in finding.text, finding.line()
