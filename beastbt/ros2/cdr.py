"""The ROS 2 messages beastbt speaks, as CDR bytes: written and read by hand, little-endian, with struct and numpy.

A ROS 2 message on the wire (rmw_zenoh, zenoh-bridge-ros2dds, a rosbag2
MCAP with ``cdr`` encoding) is plain CDR (XCDR1, "CDR_LE"): a 4-byte
encapsulation header ``00 01 00 00``, then each field in order, every
primitive aligned to its own size counted from the byte after the header
(padding is zeros), strings as a uint32 length that counts a closing NUL,
the bytes and the NUL, sequences as a uint32 count and the elements, fixed
arrays as their elements alone. The tests check every encoder here byte for
byte against ``rosbags``' ``serialize_cdr`` with its Humble and Jazzy type
stores, and every decoder against its ``serialize_cdr`` output.

Units are ROS's: metres, radians, seconds, m/s, rad/s; stamps are integer
nanoseconds (ROS ``builtin_interfaces/Time``: int32 seconds, uint32 nanoseconds).
Orientations are quaternions ``(x, y, z, w)``.

:data:`TYPES` names each message type as ROS (``sensor_msgs/msg/LaserScan``),
as DDS and rmw_zenoh do (``sensor_msgs::msg::dds_::LaserScan_``) and by its
RIHS01 type hash (REP-2011, Jazzy and later; Humble has none).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Iterable, Optional, Sequence

import numpy as np

HEADER_LE = b"\x00\x01\x00\x00"
"""The encapsulation header of little-endian plain CDR (what every ROS 2 middleware sends on x86 and ARM)."""
HEADER_BE = b"\x00\x00\x00\x00"
"""Big-endian plain CDR: read (a big-endian machine may send it), never written."""

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
IDENTITY: Quat = (0.0, 0.0, 0.0, 1.0)


class CdrError(ValueError):
    """Bytes that are not the CDR of the expected message (short, a bad header, a length beyond the end)."""


@dataclass(frozen=True)
class MessageType:
    """One ROS 2 message type: ``name`` (``pkg/msg/Type``), its DDS name and its RIHS01 hash (Jazzy)."""

    name: str
    rihs01: str

    @property
    def dds_name(self) -> str:
        """``pkg::msg::dds_::Type_``: the name DDS and rmw_zenoh give the type."""
        pkg, kind, typ = self.name.split("/")
        return f"{pkg}::{kind}::dds_::{typ}_"


TYPES: dict[str, MessageType] = {t.name: t for t in (
    MessageType("nav_msgs/msg/Odometry", "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"),
    MessageType("tf2_msgs/msg/TFMessage", "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"),
    MessageType("sensor_msgs/msg/LaserScan",
                "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"),
    MessageType("nav_msgs/msg/OccupancyGrid",
                "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7"),
    MessageType("sensor_msgs/msg/NavSatFix",
                "RIHS01_62223ab3fe210a15976021da7afddc9e200dc9ec75231c1b6a557fc598a65404"),
    MessageType("sensor_msgs/msg/Imu", "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"),
    MessageType("sensor_msgs/msg/CompressedImage",
                "RIHS01_15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a"),
    MessageType("sensor_msgs/msg/BatteryState",
                "RIHS01_4bee5dfce981c98faa6828b868307a0a73f992ed0789f374ee96c8f840e69741"),
    MessageType("nav_msgs/msg/Path", "RIHS01_1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b"),
    MessageType("diagnostic_msgs/msg/DiagnosticArray",
                "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"),
    MessageType("geometry_msgs/msg/Twist", "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"),
    MessageType("geometry_msgs/msg/TwistStamped",
                "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"),
    MessageType("geometry_msgs/msg/PoseStamped",
                "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"),
    MessageType("geometry_msgs/msg/PoseWithCovarianceStamped",
                "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e"),
    MessageType("std_msgs/msg/Bool", "RIHS01_feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9"),
)}
"""Every type beastbt publishes or reads, by ROS name (the hashes: the tests recompute them with rosbags)."""


# -- writing ------------------------------------------------------------------------------------------------------

class CdrWriter:
    """A CDR_LE message being written: the encapsulation header, then fields appended with their alignment."""

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(HEADER_LE)

    def align(self, n: int) -> None:
        """Pad with zeros to a multiple of ``n`` bytes, counted from the byte after the encapsulation header."""
        pad = -(len(self.buf) - 4) % n
        if pad:
            self.buf += b"\x00" * pad

    def pack(self, align: int, fmt: str, *values: object) -> None:
        """Append ``values`` packed little-endian with struct ``fmt`` (no padding inside: the caller lays out
        fields of one size, or sizes that need none), after aligning to ``align``."""
        self.align(align)
        self.buf += struct.pack("<" + fmt, *values)

    def string(self, text: str) -> None:
        """A CDR string: uint32 length counting the NUL, the UTF-8 bytes, the NUL."""
        data = text.encode()
        self.align(4)
        self.buf += struct.pack("<I", len(data) + 1)
        self.buf += data
        self.buf += b"\x00"

    def stamp(self, stamp_ns: int) -> None:
        """A ``builtin_interfaces/Time``: int32 seconds, uint32 nanoseconds (floor division: negative stays right)."""
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        self.pack(4, "iI", sec, nsec)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        """A ``std_msgs/Header``: the stamp and the frame."""
        self.stamp(stamp_ns)
        self.string(frame_id)

    def array(self, values: np.ndarray, dtype: str, count: bool = True) -> None:
        """A sequence (``count``: with its uint32 length) or fixed array of numbers of numpy ``dtype`` (``<f4``,
        ``<f8``, ``i1``, ``u1``), aligned to the element size."""
        arr = np.ascontiguousarray(values, dtype=dtype)
        if count:
            self.align(4)
            self.buf += struct.pack("<I", arr.size)
        if arr.size:
            self.align(arr.itemsize)
            self.buf += arr.tobytes()

    def pose(self, position: Sequence[float], orientation: Sequence[float]) -> None:
        """A ``geometry_msgs/Pose``: point (x, y, z) then quaternion (x, y, z, w), seven float64."""
        self.pack(8, "7d", *position, *orientation)

    def bytes(self) -> bytes:
        """The message."""
        return bytes(self.buf)


def _cov(values: Optional[Iterable[float]], n: int) -> list[float]:
    out = [0.0] * n if values is None else [float(v) for v in values]
    if len(out) != n:
        raise ValueError(f"a covariance of {n} numbers was expected, not {len(out)}")
    return out


_STAMP = struct.Struct("<iI")
_ODOMETRY_NUMBERS = struct.Struct("<7d36d6d36d")
_TRANSFORM_NUMBERS = struct.Struct("<7d")
_IMU_NUMBERS = struct.Struct("<4d9d3d9d3d9d")


@lru_cache(maxsize=256)
def _strings(offset: int, texts: tuple[str, ...], then_align: int) -> bytes:
    """The CDR of ``texts``, strings one after another from byte ``offset`` (counted after the encapsulation
    header), then the zeros that align what follows to ``then_align``. A message's frames are the same message
    after message: made once (the hot encoders below are then a stamp, these bytes and one struct of numbers)."""
    w = CdrWriter()
    w.buf += bytes(offset)
    for text in texts:
        w.string(text)
    w.align(then_align)
    return bytes(w.buf[4 + offset:])


def _stamp(stamp_ns: int) -> bytes:
    return _STAMP.pack(*divmod(int(stamp_ns), 1_000_000_000))


# -- the messages beastbt publishes ------------------------------------------------------------------------------

def encode_odometry(stamp_ns: int, frame_id: str, child_frame_id: str, position: Vec3, orientation: Quat,
                    linear: Vec3 = (0.0, 0.0, 0.0), angular: Vec3 = (0.0, 0.0, 0.0),
                    pose_covariance: Optional[Sequence[float]] = None,
                    twist_covariance: Optional[Sequence[float]] = None) -> bytes:
    """``nav_msgs/msg/Odometry``: the pose of ``child_frame_id`` in ``frame_id`` (m, quaternion) with its 6x6
    covariance (row-major, x y z roll pitch yaw), the velocity in ``child_frame_id`` (m/s, rad/s) with its own."""
    # header (stamp at 0, frame), child frame, then 85 float64 8-aligned: the frames' bytes are cached
    return b"".join((HEADER_LE, _stamp(stamp_ns), _strings(8, (frame_id, child_frame_id), 8),
                     _ODOMETRY_NUMBERS.pack(*position, *orientation, *_cov(pose_covariance, 36), *linear, *angular,
                                            *_cov(twist_covariance, 36))))


@dataclass(frozen=True)
class Transform:
    """One ``geometry_msgs/TransformStamped``: ``child`` placed in ``parent`` at ``stamp_ns`` (m, quaternion)."""

    stamp_ns: int
    parent: str
    child: str
    translation: Vec3 = (0.0, 0.0, 0.0)
    rotation: Quat = IDENTITY


def encode_tf(transforms: Sequence[Transform]) -> bytes:
    """``tf2_msgs/msg/TFMessage``: a list of stamped transforms (``/tf``, ``/tf_static``)."""
    parts = [HEADER_LE, struct.pack("<I", len(transforms))]
    offset = 4  # after the count; each transform's seven float64 end 8-aligned, so its stamp needs no padding
    for t in transforms:
        frames = _strings(offset + 8, (t.parent, t.child), 8)
        parts += (_stamp(t.stamp_ns), frames, _TRANSFORM_NUMBERS.pack(*t.translation, *t.rotation))
        offset += 8 + len(frames) + 56
    return b"".join(parts)


_SCAN_HEAD = struct.Struct("<iII")


def encode_laser_scan(stamp_ns: int, frame_id: str, angle_min: float, angle_max: float, angle_increment: float,
                      time_increment: float, scan_time: float, range_min: float, range_max: float,
                      ranges: np.ndarray, intensities: Optional[np.ndarray] = None) -> bytes:
    """``sensor_msgs/msg/LaserScan``: ``ranges`` (m, float32; inf or NaN for no return) at angles ``angle_min``
    + i ``angle_increment`` (rad, counter-clockwise), ``intensities`` as many or none.

    Written in one go (this runs ten times a second): the header and the seven
    float32 have a fixed layout once the frame's length is known.
    """
    frame = frame_id.encode()
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    r = np.ascontiguousarray(ranges, dtype="<f4")
    i = np.ascontiguousarray(intensities if intensities is not None else (), dtype="<f4")
    head = _SCAN_HEAD.pack(sec, nsec, len(frame) + 1) + frame + b"\x00"
    pad = -len(head) % 4  # header starts at 0 (aligned): floats follow at a multiple of 4
    return b"".join((HEADER_LE, head, b"\x00" * pad,
                     struct.pack("<7fI", angle_min, angle_max, angle_increment, time_increment, scan_time,
                                 range_min, range_max, r.size), r.tobytes(),
                     struct.pack("<I", i.size), i.tobytes()))


def encode_occupancy_grid(stamp_ns: int, frame_id: str, map_load_time_ns: int, resolution_m: float, width: int,
                          height: int, origin_position: Vec3, origin_orientation: Quat, data: np.ndarray) -> bytes:
    """``nav_msgs/msg/OccupancyGrid``: ``data`` int8 row-major from the origin cell (-1 unknown, 0 free to 100
    occupied), ``resolution_m`` metres a cell, the origin the pose of cell (0, 0)'s corner in ``frame_id``."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.stamp(map_load_time_ns)
    w.pack(4, "fII", resolution_m, width, height)
    w.pose(origin_position, origin_orientation)
    w.array(data, "i1")
    return w.bytes()


STATUS_NO_FIX, STATUS_FIX, STATUS_SBAS_FIX, STATUS_GBAS_FIX = -1, 0, 1, 2
"""``sensor_msgs/NavSatStatus.status``."""
SERVICE_GPS = 1
"""``sensor_msgs/NavSatStatus.service``: GPS."""
COVARIANCE_APPROXIMATED = 1
"""``sensor_msgs/NavSatFix.position_covariance_type``: approximated (from the HDOP)."""


def encode_nav_sat_fix(stamp_ns: int, frame_id: str, status: int, service: int, latitude_deg: float,
                       longitude_deg: float, altitude_m: float, covariance: Optional[Sequence[float]] = None,
                       covariance_type: int = 0) -> bytes:
    """``sensor_msgs/msg/NavSatFix``: WGS84 degrees, altitude (m), the ENU position covariance (m^2, 3x3)."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.pack(1, "b", status)
    w.pack(2, "H", service)
    w.pack(8, "3d9dB", latitude_deg, longitude_deg, altitude_m, *_cov(covariance, 9), covariance_type)
    return w.bytes()


def encode_imu(stamp_ns: int, frame_id: str, orientation: Quat, orientation_covariance: Optional[Sequence[float]],
               angular_velocity: Vec3, angular_velocity_covariance: Optional[Sequence[float]],
               linear_acceleration: Vec3, linear_acceleration_covariance: Optional[Sequence[float]]) -> bytes:
    """``sensor_msgs/msg/Imu``: orientation (a covariance starting with -1 says there is none), angular velocity
    (rad/s), linear acceleration (m/s^2, gravity included), each with its 3x3 covariance."""
    return b"".join((HEADER_LE, _stamp(stamp_ns), _strings(8, (frame_id,), 8),
                     _IMU_NUMBERS.pack(*orientation, *_cov(orientation_covariance, 9), *angular_velocity,
                                       *_cov(angular_velocity_covariance, 9), *linear_acceleration,
                                       *_cov(linear_acceleration_covariance, 9))))


def encode_compressed_image(stamp_ns: int, frame_id: str, image_format: str, data: bytes) -> bytes:
    """``sensor_msgs/msg/CompressedImage``: ``data`` as given (a JPEG passes through untouched), ``image_format``
    ``jpeg`` or ``png``."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.string(image_format)
    w.pack(4, "I", len(data))
    w.buf += data
    return w.bytes()


NAN = math.nan
POWER_SUPPLY_STATUS_UNKNOWN = 0
POWER_SUPPLY_HEALTH_UNKNOWN = 0
POWER_SUPPLY_TECHNOLOGY_UNKNOWN = 0


def encode_battery_state(stamp_ns: int, frame_id: str, voltage_v: float, temperature_c: float = NAN,
                         current_a: float = NAN, charge_ah: float = NAN, capacity_ah: float = NAN,
                         design_capacity_ah: float = NAN, percentage: float = NAN,
                         power_supply_status: int = POWER_SUPPLY_STATUS_UNKNOWN,
                         power_supply_health: int = POWER_SUPPLY_HEALTH_UNKNOWN,
                         power_supply_technology: int = POWER_SUPPLY_TECHNOLOGY_UNKNOWN, present: bool = True,
                         cell_voltage: Sequence[float] = (), cell_temperature: Sequence[float] = (),
                         location: str = "", serial_number: str = "") -> bytes:
    """``sensor_msgs/msg/BatteryState``: NaN for what is not measured (as the message says), ``percentage`` 0-1."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.pack(4, "7f4B", voltage_v, temperature_c, current_a, charge_ah, capacity_ah, design_capacity_ah, percentage,
           power_supply_status, power_supply_health, power_supply_technology, bool(present))
    w.array(np.asarray(cell_voltage, dtype=float), "<f4")
    w.array(np.asarray(cell_temperature, dtype=float), "<f4")
    w.string(location)
    w.string(serial_number)
    return w.bytes()


@dataclass(frozen=True)
class PathPose:
    """One ``geometry_msgs/PoseStamped`` of a path: (x, y, z) metres and a quaternion in ``frame_id``."""

    stamp_ns: int
    frame_id: str
    position: Vec3
    orientation: Quat = IDENTITY


def encode_path(stamp_ns: int, frame_id: str, poses: Sequence[PathPose]) -> bytes:
    """``nav_msgs/msg/Path``: the poses in order (``/plan``)."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.pack(4, "I", len(poses))
    for p in poses:
        w.header(p.stamp_ns, p.frame_id)
        w.pose(p.position, p.orientation)
    return w.bytes()


OK, WARN, ERROR, STALE = 0, 1, 2, 3
"""``diagnostic_msgs/DiagnosticStatus.level``."""


@dataclass(frozen=True)
class DiagnosticStatus:
    """One ``diagnostic_msgs/DiagnosticStatus``: ``level`` (:data:`OK`...), names, and ``values`` (key, value)."""

    level: int
    name: str
    message: str
    hardware_id: str = ""
    values: tuple[tuple[str, str], ...] = field(default_factory=tuple)


def encode_diagnostics(stamp_ns: int, statuses: Sequence[DiagnosticStatus], frame_id: str = "") -> bytes:
    """``diagnostic_msgs/msg/DiagnosticArray`` (``/diagnostics``)."""
    w = CdrWriter()
    w.header(stamp_ns, frame_id)
    w.pack(4, "I", len(statuses))
    for s in statuses:
        w.pack(1, "B", s.level)
        w.string(s.name)
        w.string(s.message)
        w.string(s.hardware_id)
        w.pack(4, "I", len(s.values))
        for key, value in s.values:
            w.string(key)
            w.string(value)
    return w.bytes()


def encode_bool(value: bool) -> bytes:
    """``std_msgs/msg/Bool``."""
    return HEADER_LE + (b"\x01" if value else b"\x00")


# -- reading what ROS 2 sends ---------------------------------------------------------------------------------------

class CdrReader:
    """A CDR message being read (little- or big-endian, from its encapsulation header); :class:`CdrError` when
    it ends early or is not plain CDR."""

    __slots__ = ("data", "pos", "order")

    def __init__(self, data: bytes) -> None:
        data = bytes(data)
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise CdrError("not plain CDR: the encapsulation header is not 00 00 or 00 01")
        self.data = data
        self.pos = 4
        self.order = "<" if data[1] == 1 else ">"

    def unpack(self, align: int, fmt: str) -> tuple:
        """The values of struct ``fmt`` after aligning to ``align``."""
        self.pos += -(self.pos - 4) % align
        size = struct.calcsize(self.order + fmt)
        if self.pos + size > len(self.data):
            raise CdrError(f"the message ends at byte {len(self.data)}, {size} more were expected at {self.pos}")
        out = struct.unpack_from(self.order + fmt, self.data, self.pos)
        self.pos += size
        return out

    def string(self) -> str:
        """A CDR string (its NUL dropped; bad UTF-8 replaced)."""
        (n,) = self.unpack(4, "I")
        if n > len(self.data) - self.pos:
            raise CdrError(f"a string of {n} bytes does not fit in the {len(self.data) - self.pos} left")
        raw = self.data[self.pos:self.pos + n]
        self.pos += n
        return raw.rstrip(b"\x00").decode("utf-8", "replace")

    def header(self) -> tuple[int, str]:
        """A ``std_msgs/Header``: (stamp ns, frame_id)."""
        sec, nsec = self.unpack(4, "iI")
        return sec * 1_000_000_000 + nsec, self.string()


@dataclass(frozen=True)
class Twist:
    """A ``geometry_msgs/Twist`` (or the twist of a TwistStamped): ``linear`` m/s, ``angular`` rad/s, body frame."""

    linear: Vec3
    angular: Vec3
    stamp_ns: Optional[int] = None
    frame_id: str = ""


@dataclass(frozen=True)
class PoseStamped:
    """A ``geometry_msgs/PoseStamped`` or ``PoseWithCovarianceStamped``: position (m) and quaternion in
    ``frame_id``; ``covariance`` the 6x6 (row-major) when there was one."""

    stamp_ns: int
    frame_id: str
    position: Vec3
    orientation: Quat
    covariance: Optional[tuple[float, ...]] = None

    @property
    def yaw(self) -> float:
        """The heading (rad, counter-clockwise about z) of the orientation."""
        x, y, z, w = self.orientation
        return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _finite(values: tuple, what: str) -> tuple:
    if not all(math.isfinite(v) for v in values):
        raise CdrError(f"{what} holds a NaN or infinity")
    return values


def decode_twist(data: bytes) -> Twist:
    """A ``geometry_msgs/msg/Twist``; :class:`CdrError` when the bytes are not one (or not finite)."""
    v = _finite(CdrReader(data).unpack(8, "6d"), "the twist")
    return Twist(v[0:3], v[3:6])


def decode_twist_stamped(data: bytes) -> Twist:
    """A ``geometry_msgs/msg/TwistStamped`` (Jazzy's ``/cmd_vel`` in Nav2 and teleop_twist_keyboard stamped)."""
    r = CdrReader(data)
    stamp_ns, frame = r.header()
    v = _finite(r.unpack(8, "6d"), "the twist")
    return Twist(v[0:3], v[3:6], stamp_ns, frame)


def decode_pose_stamped(data: bytes) -> PoseStamped:
    """A ``geometry_msgs/msg/PoseStamped`` (rviz2's "2D Goal Pose" on ``/goal_pose``)."""
    r = CdrReader(data)
    stamp_ns, frame = r.header()
    v = _finite(r.unpack(8, "7d"), "the pose")
    return PoseStamped(stamp_ns, frame, v[0:3], v[3:7])


def decode_pose_with_covariance_stamped(data: bytes) -> PoseStamped:
    """A ``geometry_msgs/msg/PoseWithCovarianceStamped`` (rviz2's "2D Pose Estimate" on ``/initialpose``)."""
    r = CdrReader(data)
    stamp_ns, frame = r.header()
    v = _finite(r.unpack(8, "7d"), "the pose")
    cov = r.unpack(8, "36d")
    return PoseStamped(stamp_ns, frame, v[0:3], v[3:7], cov)


def decode_bool(data: bytes) -> bool:
    """A ``std_msgs/msg/Bool``."""
    (value,) = CdrReader(data).unpack(1, "B")
    return bool(value)


def yaw_quaternion(yaw_rad: float) -> Quat:
    """The quaternion (x, y, z, w) of a rotation by ``yaw_rad`` about z."""
    return (0.0, 0.0, math.sin(0.5 * yaw_rad), math.cos(0.5 * yaw_rad))


__all__ = ["CdrWriter", "CdrReader", "CdrError", "MessageType", "TYPES", "Transform", "PathPose", "DiagnosticStatus",
           "Twist", "PoseStamped", "encode_odometry", "encode_tf", "encode_laser_scan", "encode_occupancy_grid",
           "encode_nav_sat_fix", "encode_imu", "encode_compressed_image", "encode_battery_state", "encode_path",
           "encode_diagnostics", "encode_bool", "decode_twist", "decode_twist_stamped", "decode_pose_stamped",
           "decode_pose_with_covariance_stamped", "decode_bool", "yaw_quaternion", "HEADER_LE", "OK", "WARN",
           "ERROR", "STALE", "STATUS_NO_FIX", "STATUS_FIX", "STATUS_SBAS_FIX", "STATUS_GBAS_FIX", "SERVICE_GPS",
           "COVARIANCE_APPROXIMATED"]
