"""``beastbt serve --ros2``: rviz2's "2D Goal Pose" on /goal_pose sends the robot to a planned goal on the office map.

A simulated robot serves (on the office world, its profile's ``ros2: map:`` the office map) with no station
up; a plain Zenoh peer waits for the robot's /goal_pose subscription token, as rviz2 would see it through
rmw_zenoh, and publishes one PoseStamped in the map frame. The goal becomes a mission with a planned go_to,
run as a station's mission is (recorded, every safety part): its summary says it reached the goal.
"""

from __future__ import annotations

import glob
import json
import os
import subprocess
import sys

import pytest

from beastbt.ros2 import rmw_zenoh as rz
from conftest import REPO
from fleet_support import free_port, wait_for
from ros2_support import peer_with_tokens

zenoh = pytest.importorskip("zenoh")
typesys = pytest.importorskip("rosbags.typesys")


def _peer_seeing_goal_subscription(port: int):
    found = peer_with_tokens(port, lambda tokens: any(
        "/MS/" in t and "%goal_pose/geometry_msgs::msg::dds_::PoseStamped_/" in t for t in tokens))
    return None if found is None else found[0]


def test_goal_pose_becomes_a_planned_go_to_on_the_office_map(tmp_path):
    profile = tmp_path / "robot.yaml"
    profile.write_text((REPO / "robots" / "sim.yaml").read_text() +
                       f"\nros2:\n  map: {REPO / 'maps' / 'office.yaml'}\n")
    fleet_port, ros_port = free_port(), free_port()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "serve", "--sim", "--robot", str(profile), "--world",
                             str(REPO / "worlds" / "office.yaml"), "--speed", "max", "--fleet",
                             f"tcp/127.0.0.1:{fleet_port}", "--insecure-loopback", "--ros2",
                             f"tcp/127.0.0.1:{ros_port}", "--runs-dir", str(tmp_path / "runs")],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    s = None
    try:
        s = wait_for(lambda: _peer_seeing_goal_subscription(ros_port), 90, "serve's /goal_pose subscription")
        store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
        t, g = store.types, "geometry_msgs/msg/"
        goal = t[g + "PoseStamped"](
            header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="map"),
            pose=t[g + "Pose"](position=t[g + "Point"](x=3.0, y=5.5, z=0.0),
                               orientation=t[g + "Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
        s.put(rz.topic_key(0, "/goal_pose", g + "PoseStamped"), bytes(store.serialize_cdr(goal, g + "PoseStamped")),
              attachment=rz.attachment(1, 0, bytes(16)))
        found = wait_for(lambda: glob.glob(str(tmp_path / "runs" / "*ros2_goal*" / "summary.json")), 300,
                         "the goal's run to end")
    finally:
        if s is not None:
            s.close()
        proc.terminate()
        out = proc.communicate(timeout=60)[0]
    summary = json.loads(open(found[0]).read())
    assert summary["status"] == "success", out[-2000:]
    (waypoint,) = summary["map_waypoints"]
    assert (waypoint["name"], waypoint["x"], waypoint["y"], waypoint["reached"]) == ("goal", 3.0, 5.5, True)
    assert waypoint["arrival_error_m"] < 0.5  # measured from the true pose, in the map frame
    assert waypoint["path_m"] > 5.0  # planned through the office's and the kitchen's doors, not straight
