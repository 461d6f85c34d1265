"""The ROS 2 messages' CDR bytes, byte for byte those of rosbags' serializer with its Humble and Jazzy type stores.

beastbt writes CDR by hand (beastbt/ros2/cdr.py); rosbags is an independent, pure-Python ROS 2 type system
(rosbags.typesys). Each message is built twice with the same values, once by beastbt and once as a rosbags
message, and the bytes must be equal; decoding rosbags' bytes gives the values back; the RIHS01 hashes beastbt
puts in rmw_zenoh's keys are the ones rosbags computes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.ros2 import cdr

rosbags_typesys = pytest.importorskip("rosbags.typesys")
STORES = {"humble": rosbags_typesys.Stores.ROS2_HUMBLE, "jazzy": rosbags_typesys.Stores.ROS2_JAZZY}


@pytest.fixture(params=sorted(STORES))
def store(request):
    return rosbags_typesys.get_typestore(STORES[request.param])


def _t(store, name):
    return store.types[name]


def header(store, stamp_ns, frame):
    Time, Header = _t(store, "builtin_interfaces/msg/Time"), _t(store, "std_msgs/msg/Header")
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return Header(stamp=Time(sec=sec, nanosec=nsec), frame_id=frame)


def pose(store, p, q):
    g = "geometry_msgs/msg/"
    return _t(store, g + "Pose")(position=_t(store, g + "Point")(x=p[0], y=p[1], z=p[2]),
                                 orientation=_t(store, g + "Quaternion")(x=q[0], y=q[1], z=q[2], w=q[3]))


def vec(store, v):
    return _t(store, "geometry_msgs/msg/Vector3")(x=v[0], y=v[1], z=v[2])


def same(store, ours: bytes, msg, name: str) -> None:
    theirs = bytes(store.serialize_cdr(msg, name))
    assert ours == theirs, f"{name}: {ours.hex()} != {theirs.hex()}"


STAMP = 1_733_520_000_123_456_789
Q = cdr.yaw_quaternion(0.7)


@pytest.mark.parametrize("frames", [("odom", "base_link"), ("o", "b"), ("odom_a", "base_link_xy"), ("odo", "bas")])
def test_odometry(store, frames):  # the frames' lengths make every padding before the numbers
    cov = [float(i) * 0.01 for i in range(36)]
    ours = cdr.encode_odometry(STAMP, frames[0], frames[1], (1.5, -2.25, 0.0), Q, (0.3, 0.0, 0.0), (0.0, 0.0, -0.2),
                               cov, [0.5] * 36)
    g = "geometry_msgs/msg/"
    msg = _t(store, "nav_msgs/msg/Odometry")(
        header=header(store, STAMP, frames[0]), child_frame_id=frames[1],
        pose=_t(store, g + "PoseWithCovariance")(pose=pose(store, (1.5, -2.25, 0.0), Q), covariance=np.array(cov)),
        twist=_t(store, g + "TwistWithCovariance")(
            twist=_t(store, g + "Twist")(linear=vec(store, (0.3, 0, 0)), angular=vec(store, (0, 0, -0.2))),
            covariance=np.full(36, 0.5)))
    same(store, ours, msg, "nav_msgs/msg/Odometry")


@pytest.mark.parametrize("frames", [("map", "odom"), ("odom", "base_link"), ("base_link", "lidar"), ("m", "o"),
                                    ("robot1/map", "robot1/odom_")])
def test_tf(store, frames):
    ts = [cdr.Transform(STAMP, "map", "odom", (0.1, 0.2, 0.0), Q),
          cdr.Transform(STAMP + 5, frames[0], frames[1], (1.0, 2.0, 0.3), cdr.IDENTITY),
          cdr.Transform(STAMP - 5, frames[1], "x" * len(frames[0]), (3.0, 2.0, 1.0), Q)]
    g = "geometry_msgs/msg/"
    msg = _t(store, "tf2_msgs/msg/TFMessage")(transforms=[
        _t(store, g + "TransformStamped")(header=header(store, t.stamp_ns, t.parent), child_frame_id=t.child,
                                          transform=_t(store, g + "Transform")(
                                              translation=vec(store, t.translation),
                                              rotation=_t(store, g + "Quaternion")(x=t.rotation[0], y=t.rotation[1],
                                                                                  z=t.rotation[2], w=t.rotation[3])))
        for t in ts])
    same(store, cdr.encode_tf(ts), msg, "tf2_msgs/msg/TFMessage")
    same(store, cdr.encode_tf([]), _t(store, "tf2_msgs/msg/TFMessage")(transforms=[]), "tf2_msgs/msg/TFMessage")


@pytest.mark.parametrize("frame", ["lidar", "laser", "l", "abc"])  # every padding the frame's length can make
@pytest.mark.parametrize("n", [0, 1, 455])
def test_laser_scan(store, frame, n):
    rng = np.random.default_rng(n)
    ranges = rng.uniform(0.05, 12.0, n).astype(np.float32)
    if n:
        ranges[0] = np.inf
    intens = rng.integers(0, 255, n).astype(np.float32)
    args = (-math.pi, math.pi - 0.0138, 0.0138, 1e-4, 0.1, 0.02, 12.0)
    ours = cdr.encode_laser_scan(STAMP, frame, *args, ranges, intens)
    msg = _t(store, "sensor_msgs/msg/LaserScan")(
        header=header(store, STAMP, frame), angle_min=args[0], angle_max=args[1], angle_increment=args[2],
        time_increment=args[3], scan_time=args[4], range_min=args[5], range_max=args[6], ranges=ranges,
        intensities=intens)
    same(store, ours, msg, "sensor_msgs/msg/LaserScan")


def test_occupancy_grid(store):
    data = np.array([-1, 0, 100, 50, 0, -1], dtype=np.int8)
    ours = cdr.encode_occupancy_grid(STAMP, "map", STAMP - 10, 0.05, 3, 2, (-1.0, -2.0, 0.0), cdr.IDENTITY, data)
    n = "nav_msgs/msg/"
    Time = _t(store, "builtin_interfaces/msg/Time")
    info = _t(store, n + "MapMetaData")(map_load_time=Time(sec=(STAMP - 10) // 10**9, nanosec=(STAMP - 10) % 10**9),
                                        resolution=0.05, width=3, height=2,
                                        origin=pose(store, (-1.0, -2.0, 0.0), cdr.IDENTITY))
    msg = _t(store, n + "OccupancyGrid")(header=header(store, STAMP, "map"), info=info, data=data)
    same(store, ours, msg, "nav_msgs/msg/OccupancyGrid")


@pytest.mark.parametrize("frame", ["gps", "gps_link"])
def test_nav_sat_fix(store, frame):
    cov = [4.0, 0, 0, 0, 4.0, 0, 0, 0, 16.0]
    ours = cdr.encode_nav_sat_fix(STAMP, frame, cdr.STATUS_FIX, cdr.SERVICE_GPS, 48.1, 11.5, 520.25, cov,
                                  cdr.COVARIANCE_APPROXIMATED)
    s = "sensor_msgs/msg/"
    msg = _t(store, s + "NavSatFix")(header=header(store, STAMP, frame),
                                     status=_t(store, s + "NavSatStatus")(status=0, service=1), latitude=48.1,
                                     longitude=11.5, altitude=520.25, position_covariance=np.array(cov),
                                     position_covariance_type=1)
    same(store, ours, msg, "sensor_msgs/msg/NavSatFix")


@pytest.mark.parametrize("frame", ["imu_link", "imu", "i", "base_link", "imu_li"])
def test_imu(store, frame):
    ocov = [-1.0] + [0.0] * 8
    ours = cdr.encode_imu(STAMP, frame, cdr.IDENTITY, ocov, (0.01, -0.02, 0.3), [1e-4] * 9, (0.1, 0.2, 9.81),
                          [1e-2] * 9)
    msg = _t(store, "sensor_msgs/msg/Imu")(
        header=header(store, STAMP, frame),
        orientation=_t(store, "geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.array(ocov), angular_velocity=vec(store, (0.01, -0.02, 0.3)),
        angular_velocity_covariance=np.full(9, 1e-4), linear_acceleration=vec(store, (0.1, 0.2, 9.81)),
        linear_acceleration_covariance=np.full(9, 1e-2))
    same(store, ours, msg, "sensor_msgs/msg/Imu")


@pytest.mark.parametrize("size", [0, 1, 1001])
def test_compressed_image(store, size):
    data = bytes(range(256)) * (size // 256) + bytes(size % 256)
    ours = cdr.encode_compressed_image(STAMP, "camera_optical", "jpeg", data)
    msg = _t(store, "sensor_msgs/msg/CompressedImage")(header=header(store, STAMP, "camera_optical"), format="jpeg",
                                                       data=np.frombuffer(data, dtype=np.uint8))
    same(store, ours, msg, "sensor_msgs/msg/CompressedImage")


def test_battery_state(store):
    ours = cdr.encode_battery_state(STAMP, "base_link", 11.7, percentage=0.8, present=True,
                                    cell_voltage=[3.9, 3.9, 3.9], location="base", serial_number="")
    nan = math.nan
    msg = _t(store, "sensor_msgs/msg/BatteryState")(
        header=header(store, STAMP, "base_link"), voltage=11.7, temperature=nan, current=nan, charge=nan,
        capacity=nan, design_capacity=nan, percentage=0.8, power_supply_status=0, power_supply_health=0,
        power_supply_technology=0, present=True, cell_voltage=np.array([3.9, 3.9, 3.9], dtype=np.float32),
        cell_temperature=np.array([], dtype=np.float32), location="base", serial_number="")
    same(store, ours, msg, "sensor_msgs/msg/BatteryState")


def test_path(store):
    poses = [cdr.PathPose(STAMP, "map", (float(i), 2.0 * i, 0.0), cdr.yaw_quaternion(0.1 * i)) for i in range(4)]
    g = "geometry_msgs/msg/"
    msg = _t(store, "nav_msgs/msg/Path")(header=header(store, STAMP, "map"), poses=[
        _t(store, g + "PoseStamped")(header=header(store, p.stamp_ns, p.frame_id), pose=pose(store, p.position,
                                                                                             p.orientation))
        for p in poses])
    same(store, cdr.encode_path(STAMP, "map", poses), msg, "nav_msgs/msg/Path")


def test_diagnostics(store):
    statuses = [cdr.DiagnosticStatus(cdr.OK, "beastbt: lidar", "ok", "ld19", (("rate_hz", "10.0"), ("x", ""))),
                cdr.DiagnosticStatus(cdr.WARN, "beastbt: battery", "low", "", ())]
    d = "diagnostic_msgs/msg/"
    msg = _t(store, d + "DiagnosticArray")(header=header(store, STAMP, ""), status=[
        _t(store, d + "DiagnosticStatus")(level=s.level, name=s.name, message=s.message, hardware_id=s.hardware_id,
                                          values=[_t(store, d + "KeyValue")(key=k, value=v) for k, v in s.values])
        for s in statuses])
    same(store, cdr.encode_diagnostics(STAMP, statuses), msg, "diagnostic_msgs/msg/DiagnosticArray")


def test_bool(store):
    for value in (True, False):
        same(store, cdr.encode_bool(value), _t(store, "std_msgs/msg/Bool")(data=value), "std_msgs/msg/Bool")
        assert cdr.decode_bool(bytes(store.serialize_cdr(_t(store, "std_msgs/msg/Bool")(data=value),
                                                         "std_msgs/msg/Bool"))) is value


# -- reading what ROS 2 sends --------------------------------------------------------------------------------------

def twist(store, lin, ang):
    return _t(store, "geometry_msgs/msg/Twist")(linear=vec(store, lin), angular=vec(store, ang))


def test_decode_twist(store):
    data = bytes(store.serialize_cdr(twist(store, (0.4, 0.0, 0.0), (0.0, 0.0, -0.5)), "geometry_msgs/msg/Twist"))
    t = cdr.decode_twist(data)
    assert t.linear == (0.4, 0.0, 0.0) and t.angular == (0.0, 0.0, -0.5)


@pytest.mark.parametrize("frame", ["", "base_link", "b"])
def test_decode_twist_stamped(store, frame):
    msg = _t(store, "geometry_msgs/msg/TwistStamped")(header=header(store, STAMP, frame),
                                                      twist=twist(store, (0.25, 0.0, 0.0), (0.0, 0.0, 1.0)))
    t = cdr.decode_twist_stamped(bytes(store.serialize_cdr(msg, "geometry_msgs/msg/TwistStamped")))
    assert (t.linear, t.angular, t.stamp_ns, t.frame_id) == ((0.25, 0.0, 0.0), (0.0, 0.0, 1.0), STAMP, frame)


def test_decode_pose_stamped(store):
    q = cdr.yaw_quaternion(-2.0)
    msg = _t(store, "geometry_msgs/msg/PoseStamped")(header=header(store, STAMP, "map"),
                                                     pose=pose(store, (3.0, -4.5, 0.0), q))
    p = cdr.decode_pose_stamped(bytes(store.serialize_cdr(msg, "geometry_msgs/msg/PoseStamped")))
    assert (p.stamp_ns, p.frame_id, p.position) == (STAMP, "map", (3.0, -4.5, 0.0))
    assert p.yaw == pytest.approx(-2.0)


def test_decode_pose_with_covariance_stamped(store):
    g = "geometry_msgs/msg/"
    cov = np.arange(36, dtype=float)
    msg = _t(store, g + "PoseWithCovarianceStamped")(
        header=header(store, STAMP, "map"),
        pose=_t(store, g + "PoseWithCovariance")(pose=pose(store, (1.0, 2.0, 0.0), cdr.yaw_quaternion(0.5)),
                                                 covariance=cov))
    p = cdr.decode_pose_with_covariance_stamped(bytes(store.serialize_cdr(msg, g + "PoseWithCovarianceStamped")))
    assert p.position == (1.0, 2.0, 0.0) and p.yaw == pytest.approx(0.5) and p.covariance == tuple(cov)


@pytest.mark.parametrize("bad", [b"", b"\x00\x01", b"\x07\x01\x00\x00" + bytes(48), b"\x00\x01\x00\x00" + bytes(47),
                                 b"\x00\x01\x00\x00" + b"\xff" * 48])
def test_bad_bytes_are_a_cdr_error_not_a_crash(bad):
    with pytest.raises(cdr.CdrError):
        cdr.decode_twist(bad)
    with pytest.raises(cdr.CdrError):
        cdr.decode_pose_stamped(bad)


def test_a_string_longer_than_the_message_is_refused():
    with pytest.raises(cdr.CdrError):
        cdr.decode_pose_stamped(b"\x00\x01\x00\x00" + bytes(8) + (10**6).to_bytes(4, "little") + b"map\x00")


def test_big_endian_twist_is_read():
    import struct
    data = b"\x00\x00\x00\x00" + struct.pack(">6d", 0.5, 0, 0, 0, 0, 0.25)
    t = cdr.decode_twist(data)
    assert t.linear[0] == 0.5 and t.angular[2] == 0.25


def test_type_hashes_are_rosbags_rihs01():
    jazzy = rosbags_typesys.get_typestore(STORES["jazzy"])
    for name, typ in cdr.TYPES.items():
        assert typ.rihs01 == jazzy.hash_rihs01(name), name


def test_dds_names():
    assert cdr.TYPES["sensor_msgs/msg/LaserScan"].dds_name == "sensor_msgs::msg::dds_::LaserScan_"
    assert cdr.TYPES["tf2_msgs/msg/TFMessage"].dds_name == "tf2_msgs::msg::dds_::TFMessage_"
