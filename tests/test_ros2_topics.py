"""What a run publishes, message by message: each topic's bytes decode with rosbags to the values the run had.

The run is assembled (office_rooms: the office map, the sim robot with its LiDAR and camera) but not run; one
tick's record is handed to the ROS 2 topics with known readings and poses, and every message sent is decoded
by rosbags' Humble and Jazzy type stores and compared with what went in.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.blackboard.types import (BatteryState, CameraFrame, FusedPose, GpsFix, ImuSample, LaserScan,
                                      VelocityCommand)
from beastbt.ros2.topics import TOPICS, RunTopics
from beastbt.run.runner import TickRecord
from conftest import REPO

typesys = pytest.importorskip("rosbags.typesys")
OFFSET_S = 1_700_000_000.0
JPEG = b"\xff\xd8\xff\xe0" + bytes(range(256)) * 3 + b"\xff\xd9"


@pytest.fixture(scope="module")
def sent():
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions
    prepared = prepare(str(REPO / "missions" / "office_rooms.yaml"), RunOptions(record=False))
    out: list[tuple[str, bytes]] = []
    try:
        topics = RunTopics(prepared.run, prepared.profile, frozenset(TOPICS) - {"tf_static"},
                           lambda name, payload: out.append((name, payload)), OFFSET_S)
        topics.start(0.0)
        angles = np.linspace(-math.pi, math.pi, 450, endpoint=False)
        ranges = np.linspace(0.5, 5.0, 450)
        ranges[7] = np.nan
        readings = [
            LaserScan(0.98, angles, ranges, np.full(450, 200.0), 10.0, "ld19"),
            ImuSample(0.99, (0.01, -0.02, 0.3), (0.1, 0.2, 9.81)),
            GpsFix(0.97, 48.1, 11.5, 520.0, quality=2, time_utc="120000.00",
                   covariance_enu=((4.0, 0, 0), (0, 4.0, 0), (0, 0, 16.0))),
            BatteryState(0.95, 11.8),
            CameraFrame(0.96, np.zeros((4, 4, 3), dtype=np.uint8), 3, jpeg=JPEG),
        ]
        odom = FusedPose(1.0, 1.5, -0.5, 0.4, speed_mps=0.2, yaw_rate_rps=0.1,
                         covariance=((0.01, 0.0, 0.0), (0.0, 0.02, 0.0), (0.0, 0.0, 0.003)))
        pose = FusedPose(1.0, 11.5, 9.5, 0.4)
        zero = VelocityCommand()
        topics.on_tick(TickRecord(20, 1.0, readings, odom, pose, zero, zero, zero, "mission", []))
        yield {"out": out, "prepared": prepared, "readings": readings, "odom": odom}
    finally:
        prepared.abandon()


@pytest.fixture(params=["ROS2_HUMBLE", "ROS2_JAZZY"])
def store(request):
    return typesys.get_typestore(getattr(typesys.Stores, request.param))


def one(sent, store, name):
    found = [p for n, p in sent["out"] if n == name]
    assert found, f"no {name}: {[n for n, _ in sent['out']]}"
    return store.deserialize_cdr(found[-1], TOPICS[name].type_name)


def stamp(msg):
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_scan(sent, store):
    m = one(sent, store, "scan")
    scan = sent["readings"][0]
    assert m.header.frame_id == "lidar" and stamp(m) == pytest.approx(OFFSET_S + 0.98, abs=1e-6)
    assert len(m.ranges) == 450 and math.isinf(m.ranges[7])  # no return: +inf (REP-117)
    assert np.allclose(np.delete(m.ranges, 7), np.delete(scan.ranges_m, 7).astype(np.float32))
    assert m.angle_min == pytest.approx(-math.pi, abs=1e-6)
    assert m.angle_min + 449 * m.angle_increment == pytest.approx(m.angle_max, abs=1e-5)
    assert m.scan_time == pytest.approx(0.1) and list(m.intensities[:3]) == [200.0] * 3


def test_imu(sent, store):
    m = one(sent, store, "imu")
    assert (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z) == (0.01, -0.02, 0.3)
    assert m.linear_acceleration.z == 9.81 and m.orientation_covariance[0] == -1.0


def test_fix(sent, store):
    m = one(sent, store, "fix")
    assert (m.latitude, m.longitude, m.altitude) == (48.1, 11.5, 520.0)
    assert m.status.status == 1  # NMEA quality 2 (DGPS): SBAS fix
    assert list(m.position_covariance) == [4.0, 0, 0, 0, 4.0, 0, 0, 0, 16.0] and m.position_covariance_type == 1


def test_battery(sent, store):
    m = one(sent, store, "battery")
    assert m.voltage == pytest.approx(11.8) and math.isnan(m.percentage) and m.present


def test_camera_jpeg_passes_through(sent, store):
    m = one(sent, store, "camera")
    assert m.format == "jpeg" and bytes(m.data) == JPEG and m.header.frame_id == "camera_optical"


def test_odom_and_tf(sent, store):
    m = one(sent, store, "odom")
    odom = sent["odom"]
    assert (m.pose.pose.position.x, m.pose.pose.position.y) == (1.5, -0.5)
    assert 2 * math.atan2(m.pose.pose.orientation.z, m.pose.pose.orientation.w) == pytest.approx(0.4)
    assert (m.twist.twist.linear.x, m.twist.twist.angular.z) == (0.2, 0.1)
    assert (m.pose.covariance[0], m.pose.covariance[7], m.pose.covariance[35]) == (0.01, 0.02, 0.003)
    tf = one(sent, store, "tf")
    (map_odom, odom_base) = tf.transforms
    assert (map_odom.header.frame_id, map_odom.child_frame_id) == ("map", "odom")
    assert (odom_base.transform.translation.x, odom_base.transform.translation.y) == (odom.x, odom.y)


def test_tf_static(sent, store):
    m = one(sent, store, "tf_static")
    children = {t.child_frame_id: t for t in m.transforms}
    assert {"gps", "lidar", "camera_link", "camera_optical"} <= set(children)
    assert children["lidar"].transform.translation.z == pytest.approx(0.12)  # robots/sim.yaml


def test_map_is_the_missions_map(sent, store):
    m = one(sent, store, "map")
    grid = sent["prepared"].mission.map_grid
    rows, cols = np.asarray(grid.data).shape
    assert (m.info.width, m.info.height) == (cols, rows)
    assert m.info.resolution == pytest.approx(grid.resolution_m)
    assert np.array_equal(np.asarray(m.data, dtype=np.int8), np.asarray(grid.data, dtype=np.int8).ravel())
    assert (m.info.origin.position.x, m.info.origin.position.y) == (grid.origin_x, grid.origin_y)


def test_diagnostics(sent, store):
    m = one(sent, store, "diagnostics")
    run = m.status[0]
    assert run.name == "beastbt: run" and dict((kv.key, kv.value) for kv in run.values)["mission"] == "office_rooms"
