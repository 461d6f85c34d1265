"""``ros2: {format: bridge}``: what zenoh-bridge-ros2dds on a Humble laptop sees, played by a plain Zenoh peer.

The robot (namespace /robot1) puts each topic's raw CDR on the bridge's key (``robot1/scan``), with no
attachment, announces it with the bridge's liveliness tokens, and takes ``robot1/cmd_vel`` (a Twist, told from a
TwistStamped by its size: the bridge's key carries no type) and ``robot1/estop``.
"""

from __future__ import annotations

import json
import struct
import os
import subprocess
import sys
import threading
import time

import pytest

from beastbt.ros2 import bridge, cdr, rmw_zenoh as rz
from conftest import REPO
from fleet_support import free_port, wait_for
from ros2_support import peer_with_tokens

zenoh = pytest.importorskip("zenoh")
typesys = pytest.importorskip("rosbags.typesys")

MISSION = "mission: stand_by\nsteps:\n  - wait: 60 s\n"


def _peer(port: int):
    return peer_with_tokens(port, key="@/*/@ros2_lv/**")  # what a bridge 1.x subscribes to (liveliness_mgt.rs:30)


def test_the_bridge_format_out_and_in(tmp_path):
    profile = tmp_path / "robot.yaml"
    profile.write_text((REPO / "robots" / "sim.yaml").read_text() +
                       "\nros2:\n  format: bridge\n  namespace: /robot1\n  topics: [odom, tf, scan]\n")
    (tmp_path / "m.yaml").write_text(MISSION)
    port = free_port()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "run", "m.yaml", "--robot", str(profile), "--sim",
                             "--speed", "realtime", "--max-time", "60 s", "--no-record", "--summary", "s.json",
                             "--ros2", f"tcp/127.0.0.1:{port}"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen: list[tuple[str, bytes, object]] = []
    lock = threading.Lock()
    s = None
    try:
        s, tokens = wait_for(lambda: _peer(port), 60, "the robot's bridge tokens")

        def take(sample) -> None:
            with lock:
                seen.append((str(sample.key_expr), sample.payload.to_bytes(), sample.attachment))
        s.declare_subscriber("**", take)
        wait_for(lambda: any(k == "robot1/scan" for k, _, _ in list(seen)), 30, "robot1/scan")
        humble = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
        for _ in range(15):  # 1.5 s of a Twist at 0.2 m/s, as DDS sends it through the bridge: raw CDR
            s.put("robot1/cmd_vel", cdr.HEADER_LE + struct.pack("<6d", 0.2, 0, 0, 0, 0, 0))
            time.sleep(0.1)
        time.sleep(1.0)
        s.put("robot1/estop", cdr.encode_bool(True))
        out = proc.communicate(timeout=60)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        if s is not None:
            s.close()
    zid = tokens[0].split("/")[1]  # @/<zid>/@ros2_lv/...
    assert bridge.plugin_token(zid) in tokens
    assert bridge.endpoint_token(zid, "MP", "robot1/scan", "sensor_msgs/msg/LaserScan", rz.SENSOR_DATA) in tokens
    assert bridge.endpoint_token(zid, "MS", "robot1/cmd_vel", "geometry_msgs/msg/Twist", rz.DEFAULT) in tokens
    keys = {k for k, _, _ in seen}
    assert {"robot1/scan", "robot1/odom", "robot1/tf"} <= keys and not any(k.startswith("robot1/imu") for k in keys)
    for key, payload, attachment in seen:
        if key == "robot1/scan":
            assert attachment is None  # the bridge carries none
            assert humble.deserialize_cdr(payload, "sensor_msgs/msg/LaserScan").header.frame_id == "lidar"
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["status"] == "stopped" and summary["distance_m"] > 0.1, out[-1500:]
