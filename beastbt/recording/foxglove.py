"""The Foxglove views of a run: the messages of the ``foxglove.*`` channels, built in the writer process.

Each function here turns what one tick recorded (readings, estimates, servo
angles) into a message of one of Foxglove's well-known types, as the JSON
that the type's official schema (``foxglove_schemas/``) describes. They run
in the recording's writer process (:mod:`beastbt.recording.writer`), never
on the tick loop. Every message's ``timestamp`` is its log time (Unix epoch
nanoseconds, see :data:`beastbt.recording.schemas.OFFSET_KEY`).

Frames follow REP-105: ``map`` (the estimator's local east-north-up frame,
metres) -> ``odom`` (dead reckoning, continuous) -> ``base_link`` (x forward,
y left, z up, on the floor under the robot centre) -> ``camera_link`` (the
camera on its gimbal) -> ``camera_optical`` (z forward, x right, y down). The
names come from the robot profile's ``frames:`` (:class:`FramesConfig`). A
LiDAR adds ``base_link`` -> ``lidar`` (:data:`LIDAR_FRAME`, the profile's
``lidar.mounting``), the frame of ``/scan``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Optional, Sequence

import numpy as np

from beastbt.blackboard.types import FusedPose, GpsFix
from beastbt.recording.config import FramesConfig

_IDENTITY = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}

OPTICAL_FROM_LINK = {"x": -0.5, "y": 0.5, "z": -0.5, "w": 0.5}
"""Rotation of the optical frame (z forward, x right, y down) in camera_link (x forward, y left, z up)."""


LIDAR_FRAME = "lidar"
"""The LiDAR's frame: x at its 0 degree mark, z up; placed on base_link by the profile's ``lidar.mounting``."""


def fox_time(t_ns: int) -> dict:
    """Unix epoch nanoseconds as a Foxglove ``time`` (``sec``, ``nsec``)."""
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def quaternion(roll_rad: float = 0.0, pitch_rad: float = 0.0, yaw_rad: float = 0.0) -> dict:
    """A ``foxglove.Quaternion`` from roll about x, then pitch about y, then yaw about z (rad, ZYX order)."""
    cr, sr = math.cos(0.5 * roll_rad), math.sin(0.5 * roll_rad)
    cp, sp = math.cos(0.5 * pitch_rad), math.sin(0.5 * pitch_rad)
    cy, sy = math.cos(0.5 * yaw_rad), math.sin(0.5 * yaw_rad)
    return {"x": sr * cp * cy - cr * sp * sy, "y": cr * sp * cy + sr * cp * sy,
            "z": cr * cp * sy - sr * sp * cy, "w": cr * cp * cy + sr * sp * sy}


def color(r: float, g: float, b: float, a: float = 1.0) -> dict:
    """A ``foxglove.Color``: red, green, blue and opacity, each 0-1."""
    return {"r": r, "g": g, "b": b, "a": a}


def vector3(x: float, y: float, z: float) -> dict:
    """A ``foxglove.Vector3`` (metres, or m/s, rad/s by context)."""
    return {"x": x, "y": y, "z": z}


def planar_pose(x: float, y: float, yaw: float) -> dict:
    """A ``foxglove.Pose`` on the floor: (x, y) metres, yaw rad counter-clockwise about z."""
    return {"position": vector3(x, y, 0.0), "orientation": quaternion(yaw_rad=yaw)}


def pose_in_frame(p: FusedPose, t_ns: int, frame_id: str) -> dict:
    """An estimate as a ``foxglove.PoseInFrame`` in ``frame_id`` (planar: x, y metres, yaw about z)."""
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "pose": planar_pose(p.x, p.y, p.yaw)}


# -- GPS ---------------------------------------------------------------------------------------------


def merge_fixes(earlier: GpsFix, later: GpsFix) -> GpsFix:
    """One fix from two sentences of the same epoch (GGA then RMC): the later's values, the earlier's where
    the later has none (RMC has no altitude or satellites, GGA no speed or course)."""
    fields = {}
    for f in dataclasses.fields(GpsFix):
        value = getattr(later, f.name)
        fields[f.name] = value if value is not None else getattr(earlier, f.name)
    sentences = [s for s in (earlier.sentence, later.sentence) if s]
    fields["sentence"] = "+".join(dict.fromkeys("+".join(sentences).split("+")))
    return GpsFix(**fields)


class EpochFixes:
    """One fix per GNSS epoch out of a tick's GPS readings (GGA and RMC of one epoch merged).

    A receiver sends two or three position sentences per epoch (GGA, RMC,
    GLL) with the same UTC time; Foxglove's map would draw each as a fix. The
    fixes of one epoch that arrive in one tick are merged (:func:`merge_fixes`);
    a fix of an epoch already passed on in an earlier tick is dropped. A fix
    without a UTC time (no date yet) belongs to the epoch of the fix after it
    in the same tick.
    """

    def __init__(self) -> None:
        self._last_epoch: Optional[str] = None

    def take(self, fixes: Sequence[GpsFix]) -> list[GpsFix]:
        """The tick's fixes, one per epoch not seen before, oldest first."""
        out: list[GpsFix] = []
        for fix in fixes:
            if fix.time_utc is not None and fix.time_utc == self._last_epoch:
                if out and out[-1].time_utc is None:
                    out.pop()  # a dateless sentence of that same epoch
                continue  # the rest of an epoch already published in an earlier tick
            if out and (out[-1].time_utc == fix.time_utc or out[-1].time_utc is None):
                out[-1] = merge_fixes(out[-1], fix)
            else:
                out.append(fix)
        if out:
            self._last_epoch = out[-1].time_utc
        return out


def location_fix(fix: GpsFix, t_ns: int, frame_id: str) -> dict:
    """A fix as a ``foxglove.LocationFix`` with its HDOP covariance (ENU, m^2, row-major), type APPROXIMATED.

    The covariance is the NMEA driver's ``covariance_enu``: per horizontal axis
    ``(HDOP x UERE)^2`` with the UERE of the fix's quality from the profile's
    ``gps.base_error_m`` (by default 4 m for a plain GPS fix, 0.1 m DGPS, 0.02 m
    RTK fixed; ``beastbt.devices.nmea_gps.DEFAULT_BASE_ERROR_M``), the vertical
    ``vertical_error_factor`` times the horizontal sigma. The estimator fuses
    the same numbers, so the map shows the uncertainty the EKF was told.
    """
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "latitude": fix.lat, "longitude": fix.lon,
            "altitude": fix.alt_msl if fix.alt_msl is not None else 0.0,
            "position_covariance": [float(v) for row in fix.covariance_enu for v in row],
            "position_covariance_type": 1}


def fused_location_fix(pose: FusedPose, t_ns: int, frame_id: str, altitude_m: float,
                       up_variance_m2: float) -> Optional[dict]:
    """The EKF's fused position as a ``foxglove.LocationFix``, or None while it has no place on Earth.

    Horizontal covariance: the EKF's (x, y) block (east, north, m^2). The EKF is
    planar: altitude and its variance are the latest GPS fix's (``altitude_m``,
    ``up_variance_m2``), so the covariance is APPROXIMATED.
    """
    if not pose.position_valid or pose.lat is None or pose.lon is None:
        return None
    c = pose.covariance
    cov = [float(c[0][0]), float(c[0][1]), 0.0, float(c[1][0]), float(c[1][1]), 0.0, 0.0, 0.0,
           float(up_variance_m2)]
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "latitude": pose.lat, "longitude": pose.lon,
            "altitude": altitude_m, "position_covariance": cov, "position_covariance_type": 1}


# -- frames ------------------------------------------------------------------------------------------


def _transform(t_ns: int, parent: str, child: str, translation: dict, rotation: dict) -> dict:
    return {"timestamp": fox_time(t_ns), "parent_frame_id": parent, "child_frame_id": child,
            "translation": translation, "rotation": rotation}


def map_to_odom(pose: FusedPose, odom: FusedPose) -> tuple[float, float, float]:
    """The map -> odom transform (x, y metres, yaw rad) that puts the odometry pose onto the fused one.

    T_map_odom = T_map_base * inverse(T_odom_base): what the GPS corrected of the dead reckoning.
    """
    yaw = pose.yaw - odom.yaw
    c, s = math.cos(yaw), math.sin(yaw)
    return pose.x - (c * odom.x - s * odom.y), pose.y - (s * odom.x + c * odom.y), yaw


@dataclasses.dataclass(frozen=True)
class CameraMount:
    """Where the camera sits on base_link at gimbal pan 0, tilt 0 (metres, degrees down positive)."""

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.2
    pitch_deg: float = 0.0


def frame_transforms(t_ns: int, frames: FramesConfig, pose: Optional[FusedPose], odom: Optional[FusedPose],
                     mount: Optional[CameraMount], pan_rad: float, tilt_rad: float,
                     lidar: Optional[dict] = None,
                     map_from_odom: Optional[tuple[float, float, float]] = None) -> dict:
    """A tick's ``foxglove.FrameTransforms``: map -> odom -> base_link -> camera_link -> camera_optical, and
    base_link -> gps.

    ``pose``: the fused estimate (map); ``odom``: the dead-reckoning estimate
    (odom); without it map -> odom is the identity and base_link hangs from
    odom at the fused pose. ``pan_rad`` (left positive) and ``tilt_rad`` (up
    positive): the gimbal's last commanded angles. Without a camera
    (``mount`` None) the tree ends at base_link. ``lidar``: the profile's
    ``lidar.mounting`` (``x_m``, ``y_m``, ``z_m``, ``yaw_deg``), which adds base_link -> lidar.
    ``map_from_odom``: on a saved map, the localiser's map -> odom (x, y metres, yaw rad), as AMCL publishes it;
    it takes the place of the fused estimate's, so the map, the planned path and the robot line up.
    """
    out = []
    body = odom if odom is not None else pose
    if map_from_odom is not None and odom is not None:
        x, y, yaw = map_from_odom
        out.append(_transform(t_ns, frames.map, frames.odom, vector3(x, y, 0.0), quaternion(yaw_rad=yaw)))
    elif pose is not None and odom is not None:
        x, y, yaw = map_to_odom(pose, odom)
        out.append(_transform(t_ns, frames.map, frames.odom, vector3(x, y, 0.0), quaternion(yaw_rad=yaw)))
    else:
        out.append(_transform(t_ns, frames.map, frames.odom, vector3(0.0, 0.0, 0.0), dict(_IDENTITY)))
    if body is not None:
        out.append(_transform(t_ns, frames.odom, frames.base_link, vector3(body.x, body.y, 0.0),
                              quaternion(yaw_rad=body.yaw)))
        # The GPS antenna, taken at the robot centre (the profile does not say where it sits): its fixes
        # then have a place in the tree.
        out.append(_transform(t_ns, frames.base_link, frames.gps, vector3(0.0, 0.0, 0.0), dict(_IDENTITY)))
        if lidar is not None:
            out.append(_transform(t_ns, frames.base_link, LIDAR_FRAME,
                                  vector3(float(lidar["x_m"]), float(lidar["y_m"]), float(lidar["z_m"])),
                                  quaternion(yaw_rad=math.radians(float(lidar["yaw_deg"])))))
        if mount is not None:
            # Pitch down is a positive rotation about y (x tips towards -z); tilting up lowers it.
            pitch = math.radians(mount.pitch_deg) - tilt_rad
            out.append(_transform(t_ns, frames.base_link, frames.camera_link,
                                  vector3(mount.x_m, mount.y_m, mount.z_m),
                                  _compose(quaternion(yaw_rad=pan_rad), quaternion(pitch_rad=pitch))))
            out.append(_transform(t_ns, frames.camera_link, frames.camera_optical, vector3(0.0, 0.0, 0.0),
                                  dict(OPTICAL_FROM_LINK)))
    return {"transforms": out}


def _compose(a: dict, b: dict) -> dict:
    """Quaternion product a * b (rotate by b, then by a)."""
    return {"w": a["w"] * b["w"] - a["x"] * b["x"] - a["y"] * b["y"] - a["z"] * b["z"],
            "x": a["w"] * b["x"] + a["x"] * b["w"] + a["y"] * b["z"] - a["z"] * b["y"],
            "y": a["w"] * b["y"] - a["x"] * b["z"] + a["y"] * b["w"] + a["z"] * b["x"],
            "z": a["w"] * b["z"] + a["x"] * b["y"] - a["y"] * b["x"] + a["z"] * b["w"]}


def odometry(t_ns: int, frames: FramesConfig, odom: FusedPose) -> dict:
    """The dead-reckoning estimate as a ``foxglove.Odometry`` of base_link in odom.

    Pose covariance: the estimate's (x, y, yaw) block at (x, y, rotation about
    z) of the 6x6; velocities in base_link (forward m/s, yaw rate rad/s), their
    covariance unknown (zero).
    """
    cov = [0.0] * 36
    index = (0, 1, 5)  # x, y, rotation about z in the 6x6
    for i, a in enumerate(index):
        for j, b in enumerate(index):
            cov[6 * a + b] = float(odom.covariance[i][j])
    return {"timestamp": fox_time(t_ns), "frame_id": frames.odom, "body_frame_id": frames.base_link,
            "pose": planar_pose(odom.x, odom.y, odom.yaw),
            "linear_velocity": vector3(odom.speed_mps, 0.0, 0.0),
            "angular_velocity": vector3(0.0, 0.0, odom.yaw_rate_rps),
            "pose_covariance": cov, "velocity_covariance": [0.0] * 36}


def laser_scan(t_ns: int, scan: Any, source: Optional[str] = None) -> dict:
    """A :class:`~beastbt.blackboard.types.LaserScan` as a ``foxglove.LaserScan`` in the :data:`LIDAR_FRAME`.

    Foxglove spaces the points evenly from ``start_angle`` to ``end_angle``:
    these are the first and last measured angles (radians counterclockwise,
    unwrapped in the order measured: a head turning clockwise gives an end
    below the start), exact for the even steps of the LD19 and close for
    the A1's. No return (NaN, which JSON cannot carry) is written as range 0.
    Ranges are kept to 0.01 mm, intensities as the models' integers (LD19 0-255, A1 quality 0-63): about 6 kB
    per LD19 revolution before compression. Besides Foxglove's fields (the schema allows more, Foxglove
    ignores them) it carries what a replay needs to rebuild the reading (:func:`scan_of`): ``stamp_s``,
    ``scan_rate_hz``, ``model`` and ``source`` (the sensor that gave it).
    """
    start, end = unwrapped_ends(scan.angles_rad)
    ranges = np.asarray(scan.ranges_m, dtype=float)
    ranges = np.where(np.isfinite(ranges), ranges, 0.0)
    # The arrays go to JSON as they are (orjson writes numpy arrays itself, the same text as their lists, in
    # half the time): ranges rounded to 0.01 mm, intensities as integers.
    return {"timestamp": fox_time(t_ns), "frame_id": LIDAR_FRAME, "pose": planar_pose(0.0, 0.0, 0.0),
            "start_angle": start, "end_angle": end, "ranges": np.round(ranges, 5),
            "intensities": np.rint(np.asarray(scan.intensities, dtype=float)).astype(np.int64),
            "stamp_s": float(scan.stamp_s), "scan_rate_hz": float(scan.scan_rate_hz), "model": str(scan.model),
            "source": source}


def unwrapped_ends(angles: Any) -> tuple[float, float]:
    """The first and last of ``np.unwrap(angles)`` (radians; 0, 0 when empty), the same floats, bit for bit.

    A scan's angles wrap once or twice a revolution: this adds up only the
    corrections at the jumps, in the order ``np.unwrap`` adds them all (the
    others are zeros, which change no sum), instead of building the whole
    unwrapped array (8 us of the writer's time a scan).
    """
    p = np.asarray(angles, dtype=float)
    if len(p) < 2:
        return (float(p[0]), float(p[0])) if len(p) else (0.0, 0.0)
    dd = p[1:] - p[:-1]
    jumps = dd[~(np.abs(dd) < math.pi)]  # np.unwrap's corrections are zero where |step| < pi (NaN kept)
    if not len(jumps):
        return float(p[0]), float(p[-1] + 0.0)
    ddmod = np.mod(jumps + math.pi, 2.0 * math.pi) - math.pi
    np.copyto(ddmod, math.pi, where=(ddmod == -math.pi) & (jumps > 0))
    return float(p[0]), float(p[-1] + np.cumsum(ddmod - jumps)[-1])


def scan_of(m: dict) -> Any:
    """The :class:`~beastbt.blackboard.types.LaserScan` of a ``/scan`` message (:func:`laser_scan`): the angles
    spaced evenly from start to end (as Foxglove draws them), range 0 as no return (NaN)."""
    from beastbt.blackboard.types import LaserScan
    ranges = np.asarray(m["ranges"], dtype=float)
    ranges[ranges <= 0.0] = np.nan
    angles = (np.linspace(m["start_angle"], m["end_angle"], len(ranges)) + math.pi) % (2.0 * math.pi) - math.pi
    return LaserScan(float(m["stamp_s"]), angles, ranges, np.asarray(m["intensities"], dtype=float),
                     float(m["scan_rate_hz"]), str(m["model"]))


# -- camera ------------------------------------------------------------------------------------------


def camera_calibration(t_ns: int, frame_id: str, geometry: Any) -> dict:
    """A ``foxglove.CameraCalibration`` of a :class:`~beastbt.vision.camera_model.CameraGeometry` (pixels).

    The pinhole model beastbt uses: no distortion (``plumb_bob`` with zero
    coefficients), no rectification, P = [K | 0].
    """
    k = geometry.camera_matrix
    fx, fy, cx, cy = float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2])
    return {"timestamp": fox_time(t_ns), "frame_id": frame_id, "width": int(geometry.width_px),
            "height": int(geometry.height_px), "distortion_model": "plumb_bob", "D": [0.0] * 5,
            "K": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "P": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]}


_LINE_RGBA = color(0.0, 0.86, 0.0)
_TARGET_RGBA = color(1.0, 0.0, 0.0)
_JUNCTION_RGBA = color(1.0, 0.0, 1.0)
_CLEAR = color(0.0, 0.0, 0.0, 0.0)
_CAPTION_BG = color(0.0, 0.0, 0.0, 0.6)
_WHITE = color(1.0, 1.0, 1.0)

LINE_DRAWN_M = 0.4
"""How far either side of the look-ahead point the detected line is drawn, along the line (m)."""


def line_annotations(t_ns: int, obs: Any, geometry: Any, lookahead_m: float) -> dict:
    """What the line detector saw in a frame, as ``foxglove.ImageAnnotations`` on that image (pixels).

    ``obs``: the frame's :class:`~beastbt.blackboard.types.LineObservation`
    (body frame: the line's offset at ``lookahead_m`` and its angle);
    ``geometry``: the camera as the detector saw it (its mounting at gimbal
    pan 0, tilt 0), at the published image's size. Drawn: the detected line
    (straight, through the look-ahead point at the reported angle), the
    look-ahead point the follower steers to (a circle), the intersection
    ahead (a magenta circle) and a caption with the numbers.
    """
    t = fox_time(t_ns)
    w, h = geometry.width_px, geometry.height_px
    points: list[dict] = []
    circles: list[dict] = []

    def pixel(x: float, y: float) -> Optional[dict]:
        uv = geometry.ground_to_pixel(x, y)
        if uv is None or not (-0.5 <= uv[0] <= w - 0.5 and -0.5 <= uv[1] <= h - 0.5):
            return None
        return {"x": uv[0], "y": uv[1]}

    if obs.seen:
        c, s = math.cos(obs.angle_rad), math.sin(obs.angle_rad)
        along = [LINE_DRAWN_M * (k / 10.0 - 1.0) for k in range(21)]
        strip = [p for p in (pixel(lookahead_m + d * c, obs.offset_m + d * s) for d in along) if p is not None]
        if len(strip) >= 2:
            points.append({"timestamp": t, "type": 3, "points": strip, "outline_color": _LINE_RGBA,
                           "outline_colors": [], "fill_color": _CLEAR, "thickness": 3.0})
        target = pixel(lookahead_m, obs.offset_m)
        if target is not None:
            circles.append({"timestamp": t, "position": target, "diameter": 12.0, "thickness": 2.0,
                            "fill_color": _CLEAR, "outline_color": _TARGET_RGBA})
        if obs.intersection and obs.intersection_distance_m is not None:
            d = obs.intersection_distance_m
            junction = pixel(d, obs.offset_m + (d - lookahead_m) * math.tan(obs.angle_rad))
            if junction is not None:
                circles.append({"timestamp": t, "position": junction, "diameter": 18.0, "thickness": 3.0,
                                "fill_color": _CLEAR, "outline_color": _JUNCTION_RGBA})
        caption = f"line {obs.offset_m * 100:+.1f} cm {math.degrees(obs.angle_rad):+.0f} deg"
        if obs.intersection:
            caption += "  junction" + (f" at {obs.intersection_distance_m:.2f} m"
                                       if obs.intersection_distance_m is not None else "")
        if obs.line_end:
            caption += "  end in view"
    else:
        caption = "line: not seen"
    texts = [{"timestamp": t, "position": {"x": 4.0, "y": 14.0}, "text": caption, "font_size": 12.0,
              "text_color": _WHITE, "background_color": _CAPTION_BG}]
    return {"circles": circles, "points": points, "texts": texts}


def camera_mount(mounting: Any) -> Optional[CameraMount]:
    """A :class:`CameraMount` from the ``camera_mounting`` metadata (a dict of the profile's mounting), or None."""
    if not mounting:
        return None
    return CameraMount(x_m=float(mounting.get("x_offset_m", 0.0)), y_m=float(mounting.get("y_offset_m", 0.0)),
                       z_m=float(mounting.get("height_m", 0.2)), pitch_deg=float(mounting.get("pitch_deg", 0.0)))


__all__ = ["fox_time", "quaternion", "color", "vector3", "planar_pose", "pose_in_frame", "merge_fixes", "EpochFixes",
           "location_fix", "fused_location_fix", "camera_calibration", "line_annotations", "map_to_odom", "CameraMount", "frame_transforms", "odometry",
           "camera_mount", "OPTICAL_FROM_LINK", "LIDAR_FRAME", "laser_scan", "scan_of"]
