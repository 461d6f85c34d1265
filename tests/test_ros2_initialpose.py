"""``/initialpose`` (rviz2's "2D Pose Estimate") starts the map localiser again around the pose it gives.

A mission on the office map, ticked by the harness with ``--ros2`` on; a plain Zenoh peer publishes a
PoseWithCovarianceStamped 1.5 m from where the robot is (rmw_zenoh's key, Jazzy's type hash). From the next tick
the pose on the map is there, and the run's events say so; a PoseStamped on /initialpose's key is refused as
bytes of the wrong type, never a crash.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from beastbt.ros2 import rmw_zenoh as rz
from beastbt.testing import MissionHarness
from conftest import REPO
from fleet_support import free_port, wait_for

zenoh = pytest.importorskip("zenoh")
typesys = pytest.importorskip("rosbags.typesys")

MISSION = """mission: stand_on_the_map
world: ../worlds/office.yaml
map: ../maps/office.yaml
steps:
  - wait: 60 s
"""


def test_initialpose_resets_the_localiser():
    port = free_port()
    h = MissionHarness.from_yaml(MISSION, base_dir=REPO / "missions", ros2={"listen": f"tcp/127.0.0.1:{port}"})
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    s = zenoh.open(conf)
    try:
        h.tick(20)
        before = h.blackboard("map_pose")
        assert math.hypot(before.x, before.y) < 0.2  # at the map's origin, where the mission starts
        wait_for(lambda: [r for r in s.liveliness().get("@ros2_lv/**", timeout=1.0)
                          if r.ok is not None and "%initialpose/" in str(r.ok.key_expr)], 30, "the subscription")
        store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
        t, g = store.types, "geometry_msgs/msg/"
        cov = [0.0] * 36
        cov[0] = cov[7] = 0.05 ** 2
        cov[35] = 0.05 ** 2
        msg = t[g + "PoseWithCovarianceStamped"](
            header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="map"),
            pose=t[g + "PoseWithCovariance"](pose=t[g + "Pose"](
                position=t[g + "Point"](x=1.5, y=0.0, z=0.0),
                orientation=t[g + "Quaternion"](x=0.0, y=0.0, z=math.sin(0.25), w=math.cos(0.25))),
                covariance=np.array(cov)))
        key = rz.topic_key(0, "/initialpose", g + "PoseWithCovarianceStamped")
        s.put(key, bytes(store.serialize_cdr(msg, g + "PoseWithCovarianceStamped")))
        s.put(key, b"\x00\x01\x00\x00" + bytes(10))  # too short: an event, not a crash

        def reset() -> bool:
            h.tick()
            time.sleep(0.005)
            return any("ROS 2 /initialpose: localising again" in e.text for e in h.events)
        wait_for(reset, 30, "the reset")
        h.tick(2)
        after = h.blackboard("map_pose")
        assert math.hypot(after.x - 1.5, after.y) < 0.3 and abs(after.yaw - 0.5) < 0.2
        wait_for(lambda: h.tick() is None and any("not understood" in e.text for e in h.events), 30, "the bad one")
    finally:
        s.close()
        h.prepared.abandon()
