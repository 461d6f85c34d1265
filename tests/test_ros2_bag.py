"""``beastbt export RUN --ros2 out.mcap``: a recorded run as a ROS 2 bag, read back by rosbags' reader.

A short simulated patrol is recorded (with every sensor and a few camera images), exported through the CLI,
and read back with rosbags' ``AnyReader`` (rosbag2 MCAP, ``ros2msg`` schemas, CDR) and with
mcap-ros2-support's decoder: every message is there, decodes, and carries what the recording had.
"""

from __future__ import annotations

import base64
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from beastbt.ros2 import bag, cdr
from beastbt.ros2.msgdefs import DEFINITIONS
from conftest import REPO

typesys = pytest.importorskip("rosbags.typesys")
highlevel = pytest.importorskip("rosbags.highlevel")


def beastbt(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([sys.executable, "-m", "beastbt", *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bag")
    run = beastbt("run", str(REPO / "missions" / "patrol.yaml"), "--max-time", "8 s", "--no-record", "--record",
                  "run.mcap", "--record-sensors", "--record-images", "2", cwd=tmp)
    assert run.returncode in (0, 1), run.stderr
    out = beastbt("export", "run.mcap", "--ros2", "out.mcap", cwd=tmp)
    assert out.returncode == 0, out.stderr
    from beastbt.recording.reader import read_recording
    rec = read_recording(tmp / "run.mcap", topics=list(bag.CHANNELS))
    with highlevel.AnyReader([tmp / "out.mcap"]) as reader:
        msgs: dict[str, list] = {}
        for conn, t_ns, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append((t_ns, reader.deserialize(raw, conn.msgtype), conn.msgtype))
    return {"rec": rec, "msgs": msgs, "path": tmp / "out.mcap", "stdout": out.stdout}


def test_every_recorded_message_is_in_the_bag(exported):
    rec, msgs = exported["rec"], exported["msgs"]
    expected = {bag.CHANNELS[topic][0]: len(items) for topic, items in rec.messages.items()}
    for topic in ("/odom", "/tf", "/scan", "/imu/data", "/battery", "/camera/image/compressed"):
        assert expected.get(topic), f"the recording has no {topic}"
    assert {topic: len(items) for topic, items in msgs.items()} == expected
    for topic, items in msgs.items():
        assert {typ for _, _, typ in items} == {bag.CHANNELS[[k for k, v in bag.CHANNELS.items()
                                                               if v[0] == topic][0]][1]}


def test_the_bag_holds_the_recordings_values(exported):
    rec, msgs = exported["rec"], exported["msgs"]
    offset = rec.log_time_offset_ns
    (t0, o0), (t_bag, odom, _) = rec.messages["/odom"][0], msgs["/odom"][0]
    assert t_bag == t0 + offset  # log time: Unix ns
    assert odom.pose.pose.position.x == o0["pose"]["position"]["x"]
    assert odom.header.stamp.sec * 10**9 + odom.header.stamp.nanosec == o0["timestamp"]["sec"] * 10**9 + \
        o0["timestamp"]["nsec"]
    scan_json, scan = rec.messages["/scan"][-1][1], msgs["/scan"][-1][1]
    ranges = np.asarray(scan_json["ranges"], dtype=np.float32)
    assert np.array_equal(scan.ranges, np.where(ranges > 0, ranges, np.inf).astype(np.float32))
    assert scan.angle_min == pytest.approx(scan_json["start_angle"], abs=1e-6)
    image_json, image = rec.messages["/camera/image"][0][1], msgs["/camera/image/compressed"][0][1]
    assert bytes(image.data) == base64.b64decode(image_json["data"])  # the JPEG as recorded, not encoded again
    assert bytes(image.data[:2]) == b"\xff\xd8"
    imu_json, imu = rec.messages["/sensors/imu"][0][1], msgs["/imu/data"][0][1]
    assert (imu.angular_velocity.z, imu.linear_acceleration.z) == (imu_json["gyro_rps"][2], imu_json["accel_mps2"][2])
    battery_json, battery = rec.messages["/sensors/battery"][0][1], msgs["/battery"][0][1]
    assert battery.voltage == pytest.approx(battery_json["voltage_v"], rel=1e-6) and math.isnan(battery.current)
    tf = msgs["/tf"][0][1]
    assert [t.child_frame_id for t in tf.transforms][:2] == ["odom", "base_link"]


def test_mcap_ros2_support_decodes_it_too(exported):
    decoder = pytest.importorskip("mcap_ros2.decoder")
    from mcap.reader import make_reader
    n = 0
    with open(exported["path"], "rb") as f:
        reader = make_reader(f, decoder_factories=[decoder.DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            n += 1
    assert n == sum(len(v) for v in exported["msgs"].values())


def test_message_definitions_are_rosbags_jazzy_ones():
    jazzy = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    for name, text in DEFINITIONS.items():
        assert text == jazzy.generate_msgdef(name, ros_version=2)[0], name


def test_map_and_path_convert_as_the_recording_writes_them():
    from beastbt.mapping.occupancy_map import OccupancyMap
    from beastbt.recording.map_views import map_grid, path_update
    from beastbt.blackboard.types import GlobalPlan
    jazzy = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    data = np.array([[0, 100, -1], [0, 0, 100]], dtype=np.int8)
    grid = OccupancyMap(data, 0.05, -1.0, -2.0, 0.0)
    t = 1_733_520_000_000_000_000
    m = jazzy.deserialize_cdr(bag.map_of(map_grid(t, "map", grid), 0), "nav_msgs/msg/OccupancyGrid")
    assert (m.info.width, m.info.height, m.info.resolution) == (3, 2, pytest.approx(0.05))
    assert list(m.data) == [0, 100, -1, 0, 0, 100] and m.info.origin.position.x == -1.0
    plan = GlobalPlan(1.0, np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 1.0]]), "door", 2.2)
    p = jazzy.deserialize_cdr(bag.path_of(path_update(t, "map", plan), 0), "nav_msgs/msg/Path")
    assert [(q.pose.position.x, q.pose.position.y) for q in p.poses] == [(0.0, 0.0), (1.0, 0.5), (2.0, 1.0)]
    gone = jazzy.deserialize_cdr(bag.path_of(path_update(t, "map", None), 0), "nav_msgs/msg/Path")
    assert list(gone.poses) == []


def test_export_of_a_missing_run_says_so(tmp_path):
    r = beastbt("export", "no-such-run", "--ros2", "out.mcap", cwd=tmp_path)
    assert r.returncode == 2 and "no-such-run" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out.mcap").exists()
