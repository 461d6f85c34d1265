"""A recorded run as a ROS 2 bag: the recording's standard channels as ROS 2 messages, CDR in MCAP.

``beastbt export RUN --ros2 out.mcap`` reads the run's ``run.mcap`` (JSON
messages, :mod:`beastbt.recording.reader`) and writes an MCAP file in
rosbag2's layout: profile ``ros2``, each channel's schema the ``ros2msg``
definition of its type (:mod:`beastbt.ros2.msgdefs`), each message CDR
(:mod:`beastbt.ros2.cdr`). ``ros2 bag play``, rviz2 and Foxglove read it.

Channels, from the recording's (docs/ros2.md):

====================  ==========================  ====================================
recording             bag                         type
====================  ==========================  ====================================
/odom                 /odom                       nav_msgs/msg/Odometry
/tf                   /tf                         tf2_msgs/msg/TFMessage
/scan                 /scan                       sensor_msgs/msg/LaserScan
/gps/fix              /fix                        sensor_msgs/msg/NavSatFix
/sensors/imu          /imu/data                   sensor_msgs/msg/Imu
/sensors/battery      /battery                    sensor_msgs/msg/BatteryState
/camera/image         /camera/image/compressed    sensor_msgs/msg/CompressedImage
/map                  /map                        nav_msgs/msg/OccupancyGrid
/path                 /plan                       nav_msgs/msg/Path (map)
/plan                 /plan                       nav_msgs/msg/Path (GPS way round, odom)
====================  ==========================  ====================================

Stamps are the recording's Unix epoch nanoseconds (log time and header alike).
The bag's ``/plan`` carries both of the recording's lines merged in time
order (a run has one or the other in practice): the map planner's path
(``/path``) and the way round a GPS go_to follows (``/plan``); a line taken
off is an empty Path in the frame of the line it takes off, as the link
publishes it live (:mod:`beastbt.ros2.topics`).
"""

from __future__ import annotations

import base64
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from beastbt.ros2 import cdr
from beastbt.ros2.msgdefs import DEFINITIONS


def _fox_ns(t: dict) -> int:
    return int(t["sec"]) * 1_000_000_000 + int(t["nsec"])


def _xyz(v: dict) -> tuple[float, float, float]:
    return float(v["x"]), float(v["y"]), float(v["z"])


def _quat(q: dict) -> tuple[float, float, float, float]:
    return float(q["x"]), float(q["y"]), float(q["z"]), float(q["w"])


def odom_of(m: dict, offset_ns: int) -> bytes:
    """``/odom`` (a ``foxglove.Odometry``) as ``nav_msgs/Odometry``."""
    return cdr.encode_odometry(_fox_ns(m["timestamp"]), m["frame_id"], m["body_frame_id"],
                               _xyz(m["pose"]["position"]), _quat(m["pose"]["orientation"]),
                               _xyz(m["linear_velocity"]), _xyz(m["angular_velocity"]), m["pose_covariance"],
                               m["velocity_covariance"])


def tf_of(m: dict, offset_ns: int) -> bytes:
    """``/tf`` (``foxglove.FrameTransforms``) as ``tf2_msgs/TFMessage``."""
    return cdr.encode_tf([cdr.Transform(_fox_ns(t["timestamp"]), t["parent_frame_id"], t["child_frame_id"],
                                        _xyz(t["translation"]), _quat(t["rotation"])) for t in m["transforms"]])


def scan_of(m: dict, offset_ns: int) -> bytes:
    """``/scan`` (``foxglove.LaserScan`` with beastbt's fields) as ``sensor_msgs/LaserScan``: range 0 (no
    return in the recording) as +inf."""
    ranges = np.asarray(m["ranges"], dtype=np.float32)
    ranges = np.where(ranges > 0.0, ranges, np.float32(np.inf))
    n = len(ranges)
    start, end = float(m["start_angle"]), float(m["end_angle"])
    rate = float(m.get("scan_rate_hz") or 0.0)
    scan_time = 1.0 / rate if rate > 0 else 0.0
    return cdr.encode_laser_scan(_fox_ns(m["timestamp"]), m["frame_id"], start, end,
                                 (end - start) / (n - 1) if n > 1 else 0.0, scan_time / n if n else 0.0, scan_time,
                                 0.02, 12.0, ranges, np.asarray(m["intensities"], dtype=np.float32))


def fix_of(m: dict, offset_ns: int) -> bytes:
    """``/gps/fix`` (``foxglove.LocationFix``) as ``sensor_msgs/NavSatFix`` (a GPS fix, covariance approximated)."""
    return cdr.encode_nav_sat_fix(_fox_ns(m["timestamp"]), m["frame_id"], cdr.STATUS_FIX, cdr.SERVICE_GPS,
                                  float(m["latitude"]), float(m["longitude"]), float(m["altitude"]),
                                  m["position_covariance"], int(m.get("position_covariance_type", 1)))


def imu_of(m: dict, offset_ns: int, frame_id: str = "base_link") -> bytes:
    """``/sensors/imu`` as ``sensor_msgs/Imu`` (no orientation: its covariance starts with -1)."""
    return cdr.encode_imu(int(round(float(m["stamp_s"]) * 1e9)) + offset_ns, frame_id, cdr.IDENTITY,
                          [-1.0] + [0.0] * 8, tuple(m["gyro_rps"]), None, tuple(m["accel_mps2"]), None)


def battery_of(m: dict, offset_ns: int, frame_id: str = "base_link") -> bytes:
    """``/sensors/battery`` as ``sensor_msgs/BatteryState`` (the voltage; NaN for what is not measured)."""
    return cdr.encode_battery_state(int(round(float(m["stamp_s"]) * 1e9)) + offset_ns, frame_id,
                                    float(m["voltage_v"]))


def image_of(m: dict, offset_ns: int) -> bytes:
    """``/camera/image`` (``foxglove.CompressedImage``) as ``sensor_msgs/CompressedImage``, the JPEG as recorded."""
    return cdr.encode_compressed_image(_fox_ns(m["timestamp"]), m["frame_id"], m["format"],
                                       base64.b64decode(m["data"]))


def map_of(m: dict, offset_ns: int) -> bytes:
    """``/map`` (a ``foxglove.Grid`` of int8 occupancy) as ``nav_msgs/OccupancyGrid``."""
    data = np.frombuffer(base64.b64decode(m["data"]), dtype=np.int8)
    cols = int(m["column_count"])
    t = _fox_ns(m["timestamp"])
    return cdr.encode_occupancy_grid(t, m["frame_id"], t, float(m["cell_size"]["x"]), cols,
                                     len(data) // cols if cols else 0, _xyz(m["pose"]["position"]),
                                     _quat(m["pose"]["orientation"]), data)


def path_of(m: dict, offset_ns: int, deleted_frame: str = "map") -> Optional[bytes]:
    """``/path`` or ``/plan`` (a ``foxglove.SceneUpdate`` line) as ``nav_msgs/Path``; a deletion as an empty path in
    ``deleted_frame`` (a deletion names no frame: the frame of the line it takes off)."""
    entities = m.get("entities") or []
    if entities:
        e = entities[0]
        t, frame = _fox_ns(e["timestamp"]), e["frame_id"]
        points = e["lines"][0]["points"] if e.get("lines") else []
        return cdr.encode_path(t, frame, [cdr.PathPose(t, frame, (float(p["x"]), float(p["y"]), 0.0))
                                          for p in points])
    deletions = m.get("deletions") or []
    if deletions:
        return cdr.encode_path(_fox_ns(deletions[0]["timestamp"]), deleted_frame, [])
    return None


def gps_plan_of(m: dict, offset_ns: int, deleted_frame: str = "odom") -> Optional[bytes]:
    """``/plan`` (the way round a GPS go_to follows, a ``foxglove.SceneUpdate`` line in odom) as ``nav_msgs/Path``;
    a deletion as an empty path in ``deleted_frame``."""
    return path_of(m, offset_ns, deleted_frame)


CHANNELS: dict[str, tuple[str, str, Callable[[dict, int], Optional[bytes]]]] = {
    "/odom": ("/odom", "nav_msgs/msg/Odometry", odom_of),
    "/tf": ("/tf", "tf2_msgs/msg/TFMessage", tf_of),
    "/scan": ("/scan", "sensor_msgs/msg/LaserScan", scan_of),
    "/gps/fix": ("/fix", "sensor_msgs/msg/NavSatFix", fix_of),
    "/sensors/imu": ("/imu/data", "sensor_msgs/msg/Imu", imu_of),
    "/sensors/battery": ("/battery", "sensor_msgs/msg/BatteryState", battery_of),
    "/camera/image": ("/camera/image/compressed", "sensor_msgs/msg/CompressedImage", image_of),
    "/map": ("/map", "nav_msgs/msg/OccupancyGrid", map_of),
    "/path": ("/plan", "nav_msgs/msg/Path", path_of),
    "/plan": ("/plan", "nav_msgs/msg/Path", gps_plan_of),
}
"""Recording channel -> (bag topic, ROS type, converter). Two channels may share a bag topic (``/plan``)."""
LINES = {"/path": "map", "/plan": "odom"}
"""The channels of SceneUpdate lines, with their frame: a deletion becomes an empty path in the frame of the line it
took off (this frame before any line)."""


def export_ros2(run: Any, out: Path) -> dict[str, int]:
    """Write the run (a run folder or its ``.mcap``) to ``out`` as a ROS 2 MCAP bag; return messages per bag topic.

    FileNotFoundError when there is no recording, OSError when ``out`` cannot be written.
    """
    from mcap.writer import CompressionType, Writer

    from beastbt.recording.reader import find_recording, read_recording
    rec = read_recording(find_recording(run), topics=list(CHANNELS), keep_order=True)
    offset = rec.log_time_offset_ns
    counts: dict[str, int] = {}
    out = Path(out)
    tmp = out.with_name(out.name + ".part")
    with open(tmp, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD if _has_zstd() else CompressionType.NONE)
        writer.start(profile="ros2", library="beastbt")
        schema_ids: dict[str, int] = {}
        channel_ids: dict[str, int] = {}
        line_frames: dict[str, str] = {}  # the frame of each line channel's last line: its deletion's frame
        # In log time order: two channels may feed one bag topic (/path and /plan: /plan), merged by time.
        for topic, t_ns, msg in sorted(rec.order, key=lambda item: item[1]):
            bag_topic, type_name, convert = CHANNELS[topic]
            try:
                if topic in LINES:
                    entities = msg.get("entities") or []
                    if entities:
                        line_frames[topic] = str(entities[0]["frame_id"])
                    data = path_of(msg, offset, line_frames.get(topic, LINES[topic]))
                else:
                    data = convert(msg, offset)
            except (KeyError, TypeError, ValueError, IndexError):
                continue  # a message of an older recording format: left out, counted nowhere
            if data is None:
                continue
            if bag_topic not in channel_ids:
                if type_name not in schema_ids:
                    schema_ids[type_name] = writer.register_schema(type_name, "ros2msg",
                                                                   DEFINITIONS[type_name].encode())
                channel_ids[bag_topic] = writer.register_channel(bag_topic, "cdr", schema_ids[type_name],
                                                                 metadata={"offered_qos_profiles": ""})
            log_ns = t_ns + offset
            counts[bag_topic] = counts.get(bag_topic, 0) + 1
            writer.add_message(channel_ids[bag_topic], log_time=log_ns, data=data, publish_time=log_ns,
                               sequence=counts[bag_topic])
        writer.finish()
    tmp.replace(out)
    return counts


def _has_zstd() -> bool:
    try:
        import zstandard  # noqa: F401
    except ImportError:
        return False
    return True


__all__ = ["export_ros2", "CHANNELS", "LINES", "path_of", "gps_plan_of"]
