"""The ``lidar:`` profile section and its part: opened on the robot, emulated on --sim (asleep when unread)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import yaml

from beastbt.assembly import parts_for
from beastbt.core.clock import WallClock
from beastbt.core.errors import InvalidInput
from beastbt.core.events import EventLog
from beastbt.robot.hardware import DeviceUnavailable
from beastbt.robot.profile import load_profile
from beastbt.robot.robot_io import RobotIO
from beastbt.run.session import RunOptions
from beastbt.testing import MissionHarness
from conftest import REPO
from fake_ld19 import FakeLd19

MISSION = "mission: t\nsteps:\n  - drive: {distance: 0.3 m, speed: 0.2 m/s}\n"


def profile_with(tmp_path: Path, base: str, **lidar) -> Path:
    data = yaml.safe_load((REPO / "robots" / f"{base}.yaml").read_text(encoding="utf-8"))
    if lidar:
        data["lidar"] = lidar
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def test_a_sim_profile_with_a_lidar_runs_and_the_unread_lidar_sleeps(tmp_path):
    robot = profile_with(tmp_path, "sim", type="rplidar_a1", port="/dev/ttyUSB0")
    data = yaml.safe_load(robot.read_text(encoding="utf-8"))
    data["collision_monitor"] = {"enabled": False}  # else the monitor reads every scan
    robot.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    h = MissionHarness.from_yaml(MISSION, robot=str(robot))
    assert h.run_to_end(timeout_s=60) == "success"
    notes = [e for e in h.events if "asleep" in str(e)]
    assert len(notes) == 1 and "lidar" in str(notes[0])
    from beastbt.sim.lidar_emulator import LidarEmulator
    io = h.prepared.run.io
    assert "lidar" not in io.sensors  # neither polled...
    assert not [u for u in io.sim.emulators if isinstance(getattr(u, "__self__", None), LidarEmulator)]  # ...nor cast


def test_a_profile_without_a_lidar_gets_no_lidar_part():
    # diy_pwm carries the lidar: section commented out; the Beast carries Waveshare's kit (issue 36)
    assert "lidar" not in [p.name for p in parts_for(load_profile("diy_pwm"), RunOptions())]
    assert "lidar" in [p.name for p in parts_for(load_profile("ugv_beast"), RunOptions())]
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    assert data["lidar"]["type"] == "ld19"  # the simulator carries Waveshare's kit LiDAR
    assert "lidar" in [p.name for p in parts_for(load_profile("sim"), RunOptions())]


def test_a_profile_with_a_lidar_gets_the_part(tmp_path):
    profile = load_profile(profile_with(tmp_path, "ugv_beast", type="rplidar_a1"))
    assert "lidar" in [p.name for p in parts_for(profile, RunOptions())]


def test_on_the_robot_the_part_opens_the_driver_and_polls_scans(tmp_path):
    from beastbt.parts.lidar import attach_real_lidar
    with FakeLd19() as fake:
        profile = load_profile(profile_with(tmp_path, "ugv_beast", type="ld19", port=fake.port,
                                            mounting={"x_m": 0.05, "yaw_deg": 180}, ignore_deg=[[150, -150]]))
        clock = WallClock()
        io = RobotIO(base=None)  # type: ignore[arg-type]
        driver = attach_real_lidar(profile, io, clock, EventLog(clock))
        assert driver is not None and "lidar" in io.capabilities
        scans: list = []
        end = time.monotonic() + 3.0
        while time.monotonic() < end and not scans:
            scans += io.sensors["lidar"](clock.now())
            time.sleep(0.01)
        for close in io.closers:
            close()
    assert scans and scans[0].model == "ld19" and 420 <= len(scans[0]) <= 480
    assert driver.config.mounting.yaw_deg == 180 and not driver.port_open


def test_a_missing_port_stops_the_start_with_what_to_check(tmp_path):
    from beastbt.parts.lidar import attach_real_lidar
    profile = load_profile(profile_with(tmp_path, "ugv_beast", type="ld19", port=str(tmp_path / "ttyUSB9")))
    clock = WallClock()
    with pytest.raises(DeviceUnavailable) as err:
        attach_real_lidar(profile, RobotIO(base=None), clock, EventLog(clock))  # type: ignore[arg-type]
    assert "ttyUSB9" in str(err.value) and "dialout" in str(err.value)


@pytest.mark.parametrize("lidar, words", [
    ({"type": "ld20"}, "ld19"),
    ({"type": "ld19", "range": [0.1, 8]}, "range"),
    ({"type": "ld19", "mounting": {"yaw": 90}}, "yaw"),
    ({"port": "/dev/ttyUSB0"}, "type"),
])
def test_a_bad_lidar_section_is_a_positioned_error(tmp_path, lidar, words):
    with pytest.raises(InvalidInput) as err:
        load_profile(profile_with(tmp_path, "ugv_beast", **lidar))
    text = str(err.value)
    assert "robot.yaml:" in text and words in text


def test_the_sim_run_no_longer_warns_that_the_lidar_is_not_simulated(tmp_path):
    from beastbt.assembly import prepare
    mission = tmp_path / "m.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    robot = profile_with(tmp_path, "sim", type="rplidar_a1")
    p = prepare(str(mission), RunOptions(robot=str(robot), simulate=True, record=False))
    assert not [w for w in p.warnings if "LiDAR" in w.format() or "lidar" in w.format()]
    p.abandon()


def test_the_knobs_take_units(tmp_path):
    from beastbt.devices.lidar_scan import LidarConfig
    from beastbt.robot.profile import section_config
    profile = load_profile(profile_with(tmp_path, "ugv_beast", type="ld19", stale_after_s="300 ms",
                                        range_m=["5 cm", "8 m"], ignore_deg=[["170 deg", "-170 deg"]],
                                        mounting={"x_m": "12 cm", "yaw_deg": "90 deg"}, min_rate_hz="6 Hz"))
    config = section_config(profile, "lidar", LidarConfig)
    assert config.stale_after_s == pytest.approx(0.3) and config.limits_m == pytest.approx((0.05, 8.0))
    assert config.ignore_deg == [[pytest.approx(170.0), pytest.approx(-170.0)]]
    assert config.mounting.x_m == pytest.approx(0.12) and config.mounting.yaw_deg == pytest.approx(90.0)
    assert config.spinning_below_hz == pytest.approx(6.0) and config.port_baud == 230400
