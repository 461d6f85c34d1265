"""Hardware in the loop without hardware: the collision monitor between a real LD19 stream and a real base.

``beastbt run --robot PROFILE`` on the wall clock opens the Waveshare base on
a pty (:mod:`fake_waveshare`, its firmware emulated) and the LD19 on another
(:mod:`fake_ld19`, LDRobot's packets of a synthetic room). With a wall 0.3 m
ahead of the LiDAR and a stop zone reaching 0.4 m, a forward drive never gets
a non-zero wheel speed on the wire; with the wall 3 m away the same drive moves.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import REPO
from fake_ld19 import FakeLd19, SyntheticRoom
from fake_waveshare import FakeWaveshare

STOP_ZONE = [[0.4, 0.25], [-0.25, 0.25], [-0.25, -0.25], [0.4, -0.25]]


def profile(tmp_path: Path, base_port: str, lidar_port: str) -> Path:
    data = yaml.safe_load((REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8"))
    for section in ("gps", "imu", "camera", "lidar", "joystick", "servos"):
        data.pop(section, None)
    data["base"].update(port=base_port, firmware="ros")
    data["lidar"] = {"type": "ld19", "port": lidar_port}
    data["collision_monitor"] = {"stop": {"polygon_m": STOP_ZONE}}
    path = tmp_path / "beast_lidar.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


@pytest.mark.parametrize("front_m, moves", [(0.3, False), (3.0, True)])
def test_a_forward_drive_toward_a_wall_gets_zero_on_the_wheels(tmp_path, front_m, moves):
    room = SyntheticRoom(front_m=front_m, back_m=1.0, left_m=1.0, right_m=1.0, pillars=[])
    mission = tmp_path / "mission.yaml"
    mission.write_text("mission: ahead\nsteps:\n  - drive: {distance: 1 m, speed: 0.2 m/s}\n", encoding="utf-8")
    with FakeWaveshare("ros") as base, FakeLd19(room=room) as lidar:
        proc = subprocess.run([sys.executable, "-m", "beastbt", "run", str(mission),
                               "--robot", str(profile(tmp_path, base.port, lidar.port)), "--max-time", "2 s",
                               "--no-record", "--summary", str(tmp_path / "summary.json")],
                              cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(REPO)),
                              capture_output=True, text=True, timeout=60)
        targets = list(base.targets)
    assert proc.returncode in (0, 1, 2), proc.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    texts = [e["text"] for e in summary["events"] if e["kind"] == "collision_monitor"]
    moving = [t for t in targets if t[1] != 0.0 or t[2] != 0.0]
    if moves:
        assert moving and not any("stop" in t for t in texts)
    else:
        assert moving == [], "the wheels were driven toward the wall"
        assert any(t.startswith("collision monitor: stop (mission's command)") for t in texts), texts
