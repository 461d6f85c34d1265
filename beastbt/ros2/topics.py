"""What a run publishes to ROS 2: its topics, their types, QoS and rates, and the messages made from one tick.

:class:`RunTopics` is a recorder of the run (``run.recorders``): each tick it
gets the tick's :class:`~beastbt.run.runner.TickRecord` and makes, from what
the run has and nothing more, the CDR of the topics it is asked for, handing
each to ``send(name, payload)``; which key, tokens and attachment carry it is
the link's business (:mod:`beastbt.ros2.link`). A sensor the run does not
read is asleep and sends nothing (a LiDAR nobody reads gives no ``/scan``).

Frames follow REP-105 and the recording's (:mod:`beastbt.recording.foxglove`):
``map`` -> ``odom`` -> ``base_link`` -> ``lidar``, ``camera_link`` ->
``camera_optical``, ``gps``, named by the profile's ``frames:``. Stamps are
the clock's time plus the Unix epoch offset the link measured when it
started (in the simulator, ROS time runs at the simulation's pace).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from beastbt.blackboard.types import BatteryState, CameraFrame, GpsFix, ImuSample, LaserScan
from beastbt.ros2 import cdr
from beastbt.ros2.rmw_zenoh import DEFAULT, LATCHED, SENSOR_DATA, Qos


@dataclass(frozen=True)
class TopicSpec:
    """One topic: its ROS name (relative to the namespace), type, QoS and the rate it goes at (for the docs)."""

    name: str
    type_name: str
    qos: Qos
    rate: str


TOPICS: dict[str, TopicSpec] = {
    "odom": TopicSpec("odom", "nav_msgs/msg/Odometry", DEFAULT, "pose rate (20 Hz), 1 Hz standing still"),
    "tf": TopicSpec("tf", "tf2_msgs/msg/TFMessage", DEFAULT, "with /odom"),
    "tf_static": TopicSpec("tf_static", "tf2_msgs/msg/TFMessage", LATCHED, "once (transient local)"),
    "scan": TopicSpec("scan", "sensor_msgs/msg/LaserScan", SENSOR_DATA, "each revolution (LD19 10 Hz)"),
    "map": TopicSpec("map", "nav_msgs/msg/OccupancyGrid", LATCHED, "once, and when the planner marks cells"),
    "fix": TopicSpec("fix", "sensor_msgs/msg/NavSatFix", SENSOR_DATA, "each GNSS epoch (1-10 Hz)"),
    "imu": TopicSpec("imu/data", "sensor_msgs/msg/Imu", SENSOR_DATA, "each sample, at most 50 Hz"),
    "camera": TopicSpec("camera/image/compressed", "sensor_msgs/msg/CompressedImage", SENSOR_DATA,
                        "each frame the run takes that has a JPEG"),
    "battery": TopicSpec("battery", "sensor_msgs/msg/BatteryState", DEFAULT, "1 Hz"),
    "plan": TopicSpec("plan", "nav_msgs/msg/Path", DEFAULT, "each new global plan (map), each new way round (GPS, "
                      "odom); empty when dropped"),
    "diagnostics": TopicSpec("diagnostics", "diagnostic_msgs/msg/DiagnosticArray", DEFAULT, "1 Hz"),
}
"""Every topic beastbt publishes, by the name the profile's ``ros2: topics:`` uses (``tf`` brings ``tf_static``)."""

INPUTS: dict[str, TopicSpec] = {
    "cmd_vel": TopicSpec("cmd_vel", "geometry_msgs/msg/Twist", DEFAULT, "teleop, 0.5 s deadman"),
    "cmd_vel_stamped": TopicSpec("cmd_vel", "geometry_msgs/msg/TwistStamped", DEFAULT, "teleop, 0.5 s deadman"),
    "goal_pose": TopicSpec("goal_pose", "geometry_msgs/msg/PoseStamped", DEFAULT, "a planned go_to"),
    "initialpose": TopicSpec("initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", DEFAULT,
                             "resets the localiser"),
    "estop": TopicSpec("estop", "std_msgs/msg/Bool", DEFAULT, "true latches the e-stop"),
}
"""What beastbt subscribes to (on the same namespace)."""

POSE_PERIOD_S = 0.05
"""/odom and /tf at most this often (s, clock time): 20 Hz, the recording's pose rate."""
STILL_PERIOD_S = 1.0
"""... and while the robot stands still, this often (tf listeners need a fresh transform now and then)."""
IMU_PERIOD_S = 0.02
"""/imu/data at most this often (s): 50 Hz."""
SLOW_PERIOD_S = 1.0
"""/battery and /diagnostics this often (s)."""
BURST_PERIOD_S = 0.1
"""The ticks' messages are made and sent together at most this often (s, clock time): 10 Hz, the LiDAR's pace.
Each burst wakes Zenoh's transmission once, and that wake-up (about 0.1 ms of CPU, a system call on a cold
path), not the messages, is what a link costs the robot; every message keeps the stamp of its own tick and
the rates above, and goes out at most this much later."""
LD19_RANGE_M = (0.02, 12.0)
"""range_min and range_max of a scan when the profile gives none (m): the LD19's."""


def gnss_status(quality: int) -> int:
    """NavSatStatus.status of an NMEA GGA quality: 0 no fix, 2 DGPS/SBAS, 4 and 5 RTK as ground-based
    augmentation, anything else a plain fix."""
    if quality <= 0:
        return cdr.STATUS_NO_FIX
    if quality == 2:
        return cdr.STATUS_SBAS_FIX
    if quality in (4, 5):
        return cdr.STATUS_GBAS_FIX
    return cdr.STATUS_FIX


def scan_message(stamp_ns: int, frame_id: str, scan: LaserScan, range_m: tuple[float, float]) -> bytes:
    """A beastbt scan as ``sensor_msgs/LaserScan``: the measured angles spaced evenly from the first to the last
    (unwrapped, as the recording does; a head turning clockwise gives a negative increment), no return as +inf
    (REP-117), intensities as the model's numbers."""
    from beastbt.recording.foxglove import unwrapped_ends
    n = len(scan.ranges_m)
    start, end = unwrapped_ends(scan.angles_rad)
    inc = (end - start) / (n - 1) if n > 1 else 0.0
    ranges = np.asarray(scan.ranges_m, dtype=np.float32)
    ranges = np.where(np.isfinite(ranges), ranges, np.float32(np.inf))
    scan_time = scan.scan_time_s if math.isfinite(scan.scan_time_s) else 0.0
    return cdr.encode_laser_scan(stamp_ns, frame_id, start, end, inc, scan_time / n if n else 0.0, scan_time,
                                 range_m[0], range_m[1], ranges, np.asarray(scan.intensities, dtype=np.float32))


class RunTopics:
    """The topics of one run (see the module docstring): ``enabled`` names from :data:`TOPICS`, ``send(name,
    payload)`` puts one message, ``epoch_offset_s`` turns clock seconds into Unix seconds."""

    def __init__(self, run: Any, profile: Any, enabled: frozenset, send: Callable[[str, bytes], None],
                 epoch_offset_s: float, wanted: Callable[[str], bool] = lambda name: True) -> None:
        from beastbt.recording.config import FramesConfig
        from beastbt.robot.profile import section_config
        self.run = run
        self.enabled = enabled
        self.send = send
        self.wanted = wanted
        """Whether anyone subscribes to a topic now (the link's Zenoh matching status): no one, no encoding."""
        self.offset_s = epoch_offset_s
        self.frames = section_config(profile, "frames", FramesConfig)
        self.lidar = None
        self.range_m = LD19_RANGE_M
        if profile.section("lidar") is not None:
            from beastbt.devices.lidar_scan import LidarConfig
            config = section_config(profile, "lidar", LidarConfig)
            self.lidar = config.mounting
            if config.range_m is not None:
                self.range_m = (float(config.range_m[0]), float(config.range_m[1]))
        self.camera = None
        if profile.section("camera") is not None:
            from beastbt.devices.camera import CameraConfig
            self.camera = CameraConfig.from_dict(profile.section("camera")).mounting
        self._pose_s = -math.inf
        self._pose_key: Any = None
        self._imu_s = -math.inf
        self._slow_s = -math.inf
        self._battery: Optional[BatteryState] = None
        self._epochs: Any = None
        self._maps: Any = None
        self._way: Any = None
        """The GPS way round last published on /plan (the navigator's own object; None: none, or an empty Path)."""
        self._pending: list = []
        self._burst_s = -math.inf
        self.sent = 0

    def ns(self, t_s: float) -> int:
        """Clock seconds as ROS time (Unix ns)."""
        return int(round((t_s + self.offset_s) * 1e9))

    def _put(self, name: str, payload: bytes) -> None:
        self.sent += 1
        self.send(name, payload)

    # -- once ----------------------------------------------------------------------------------------------------
    def static_transforms(self, now_s: float) -> bytes:
        """``/tf_static``: base_link -> lidar, gps, camera_link (at gimbal rest) -> camera_optical."""
        f, t = self.frames, self.ns(now_s)
        out = [cdr.Transform(t, f.base_link, f.gps)]
        if self.lidar is not None:
            m = self.lidar
            out.append(cdr.Transform(t, f.base_link, "lidar", (float(m.x_m), float(m.y_m), float(m.z_m)),
                                     cdr.yaw_quaternion(math.radians(float(m.yaw_deg)))))
        if self.camera is not None:
            c = self.camera
            pitch = math.radians(float(c.pitch_deg))
            out.append(cdr.Transform(t, f.base_link, f.camera_link,
                                     (float(getattr(c, "x_offset_m", 0.0)), float(getattr(c, "y_offset_m", 0.0)),
                                      float(c.height_m)), (0.0, math.sin(0.5 * pitch), 0.0, math.cos(0.5 * pitch))))
            out.append(cdr.Transform(t, f.camera_link, f.camera_optical, (0.0, 0.0, 0.0), (-0.5, 0.5, -0.5, 0.5)))
        return cdr.encode_tf(out)

    def start(self, now_s: float) -> None:
        """What goes once, at the start: ``/tf_static``."""
        if "tf" in self.enabled:
            self._put("tf_static", self.static_transforms(now_s))

    # -- every tick ----------------------------------------------------------------------------------------------
    def on_tick(self, rec: Any) -> None:
        """``run.recorders`` callable: keep this tick, and make and send the messages of the ticks kept once a
        burst is due (:data:`BURST_PERIOD_S`)."""
        self._pending.append(rec)
        if rec.now_s - self._burst_s >= BURST_PERIOD_S - 1e-9:
            self.flush()

    def flush(self) -> None:
        """Make and send the messages of the ticks kept, one burst (also when the link closes)."""
        pending, self._pending = self._pending, []
        if not pending:
            return
        for rec in pending:
            self._tick(rec)
        now_s = pending[-1].now_s
        self._burst_s = now_s
        if "map" in self.enabled or "plan" in self.enabled:
            self._map_and_plan(now_s)

    def _tick(self, rec: Any) -> None:
        """The messages of one tick (its readings, poses and the 1 Hz topics), each as its tick had it."""
        now_s = rec.now_s
        enabled = self.enabled
        wanted = self.wanted
        for r in rec.readings:
            cls = r.__class__
            if cls is LaserScan:
                if "scan" in enabled and wanted("scan"):
                    self._put("scan", scan_message(self.ns(r.stamp_s), "lidar", r, self.range_m))
            elif cls is ImuSample:
                if "imu" in enabled and r.stamp_s - self._imu_s >= IMU_PERIOD_S - 1e-9 and wanted("imu"):
                    self._imu_s = r.stamp_s
                    self._put("imu", cdr.encode_imu(self.ns(r.stamp_s), self.frames.base_link, cdr.IDENTITY,
                                                    [-1.0] + [0.0] * 8, r.gyro_rps, None, r.accel_mps2, None))
            elif cls is CameraFrame:
                if "camera" in enabled and r.jpeg is not None and wanted("camera"):  # passed through, never encoded
                    self._put("camera", cdr.encode_compressed_image(self.ns(r.stamp_s), self.frames.camera_optical,
                                                                    "jpeg", r.jpeg))
            elif cls is BatteryState:
                self._battery = r
        if "fix" in enabled:
            fixes = [r for r in rec.readings if r.__class__ is GpsFix]
            if fixes:
                self._fixes(fixes)
        if (rec.pose_odom is not None or rec.pose is not None) and (wanted("odom") or wanted("tf")):
            self._poses(now_s, rec.pose_odom, rec.pose)
        if now_s - self._slow_s >= SLOW_PERIOD_S - 1e-9:
            self._slow_s = now_s
            self._slow(now_s, rec)

    def _fixes(self, fixes: list) -> None:
        if self._epochs is None:
            from beastbt.recording.foxglove import EpochFixes
            self._epochs = EpochFixes()
        for fix in self._epochs.take(fixes):
            if not self.wanted("fix"):
                continue
            cov = [float(v) for row in fix.covariance_enu for v in row]
            self._put("fix", cdr.encode_nav_sat_fix(self.ns(fix.stamp_s), self.frames.gps, gnss_status(fix.quality),
                                                    cdr.SERVICE_GPS, fix.lat, fix.lon,
                                                    fix.alt_msl if fix.alt_msl is not None else math.nan, cov,
                                                    cdr.COVARIANCE_APPROXIMATED))

    def _poses(self, now_s: float, odom: Any, pose: Any) -> None:
        since = now_s - self._pose_s
        if since < POSE_PERIOD_S - 1e-9:
            return
        body = odom if odom is not None else pose
        key = (body.x, body.y, body.yaw)
        if key == self._pose_key and since < STILL_PERIOD_S - 1e-9:
            return
        self._pose_s, self._pose_key = now_s, key
        f, t = self.frames, self.ns(now_s)
        if "odom" in self.enabled and self.wanted("odom"):
            cov = [0.0] * 36
            for i, a in enumerate((0, 1, 5)):  # x, y, rotation about z in the 6x6
                for j, b in enumerate((0, 1, 5)):
                    cov[6 * a + b] = float(body.covariance[i][j])
            self._put("odom", cdr.encode_odometry(t, f.odom, f.base_link, (body.x, body.y, 0.0),
                                                  cdr.yaw_quaternion(body.yaw), (body.speed_mps, 0.0, 0.0),
                                                  (0.0, 0.0, body.yaw_rate_rps), cov))
        if "tf" in self.enabled and self.wanted("tf"):
            self._put("tf", cdr.encode_tf([self._map_to_odom(t, pose, odom),
                                           cdr.Transform(t, f.odom, f.base_link, (body.x, body.y, 0.0),
                                                         cdr.yaw_quaternion(body.yaw))]))

    def _map_to_odom(self, t: int, pose: Any, odom: Any) -> cdr.Transform:
        f = self.frames
        loc = self.run.ctx.services.plugins.get("map_localiser")
        if loc is not None and odom is not None:
            x, y, yaw = loc.map_from_odom  # on a saved map: AMCL's map -> odom, so the map and the robot line up
        elif pose is not None and odom is not None:
            from beastbt.recording.foxglove import map_to_odom
            x, y, yaw = map_to_odom(pose, odom)
        else:
            x = y = yaw = 0.0
        return cdr.Transform(t, f.map, f.odom, (float(x), float(y), 0.0), cdr.yaw_quaternion(float(yaw)))

    def _slow(self, now_s: float, rec: Any) -> None:
        t = self.ns(now_s)
        battery = self._battery
        if "battery" in self.enabled and battery is not None and self.wanted("battery"):
            self._put("battery", cdr.encode_battery_state(t, self.frames.base_link, battery.voltage_v))
        if "diagnostics" in self.enabled and self.wanted("diagnostics"):
            run = self.run
            estop = bool(run.mux.estop_latched)
            statuses = [cdr.DiagnosticStatus(
                cdr.ERROR if estop else cdr.OK, "beastbt: run",
                "e-stop latched" if estop else ("paused" if run.paused_by else "running"), "beastbt",
                (("mission", str(run.mission.name)), ("step", str(run.current_step())),
                 ("mux_source", str(rec.mux_source)), ("paused_by", str(run.paused_by or ""))))]
            if battery is not None:
                statuses.append(cdr.DiagnosticStatus(cdr.OK, "beastbt: battery", f"{battery.voltage_v:.2f} V", "base",
                                                     (("voltage_v", f"{battery.voltage_v:.3f}"),)))
            self._put("diagnostics", cdr.encode_diagnostics(t, statuses))

    def _map_and_plan(self, now_s: float) -> None:
        if self._maps is None:
            from beastbt.recording.map_views import MapSampler
            self._maps = MapSampler(self.run)
        changed = self._maps.sample(now_s)
        t = self.ns(now_s)
        if "map" in changed and "map" in self.enabled:
            grid, lethal = changed["map"]
            self._put("map", map_message(t, self.frames.map, grid, lethal))
        if "path" in changed and "plan" in self.enabled and self.wanted("plan"):
            plan = changed["path"]
            self._put("plan", path_message(t, self.frames.map, None if plan is None else plan.points_xy))
        if "plan" in self.enabled:
            self._gps_way(t)

    def _gps_way(self, t: int) -> None:
        """``/plan`` of a GPS go_to (odom): the way round it follows each time it changes, an empty Path when it is
        dropped, as the recording's ``/plan`` (the way is the global navigator's ``following``, read, not planned
        again). Nothing while no one subscribes: a subscriber that comes later gets the way followed then."""
        from beastbt.recording.global_views import gps_navigator
        g = gps_navigator(self.run)
        if g is None:
            return
        way = g.following
        if way is self._way or not self.wanted("plan"):
            return
        self._way = way
        self._put("plan", path_message(t, self.frames.odom, None if way is None else way.points))


def path_message(stamp_ns: int, frame_id: str, points: Any) -> bytes:
    """``nav_msgs/Path`` in ``frame_id`` through ``points`` ((n, 2) m, that frame), every pose stamped ``stamp_ns``
    and facing the identity; None: an empty Path (rviz2 clears its line)."""
    pts = [] if points is None else np.asarray(points, dtype=float).tolist()
    return cdr.encode_path(stamp_ns, frame_id, [cdr.PathPose(stamp_ns, frame_id, (float(x), float(y), 0.0))
                                                for x, y in pts])


def map_message(stamp_ns: int, frame_id: str, grid: Any, lethal: Optional[np.ndarray] = None) -> bytes:
    """An :class:`~beastbt.mapping.occupancy_map.OccupancyMap` as ``nav_msgs/OccupancyGrid`` (row 0 at the
    origin, as map_server); ``lethal`` cells the planner marked since are drawn occupied."""
    data = np.ascontiguousarray(grid.data, dtype=np.int8)
    if lethal is not None:
        data = data.copy()
        data[lethal] = 100
    rows, cols = data.shape
    return cdr.encode_occupancy_grid(stamp_ns, frame_id, stamp_ns, float(grid.resolution_m), int(cols), int(rows),
                                     (float(grid.origin_x), float(grid.origin_y), 0.0),
                                     cdr.yaw_quaternion(float(grid.origin_yaw)), data.ravel())


__all__ = ["TOPICS", "INPUTS", "TopicSpec", "RunTopics", "scan_message", "map_message", "path_message", "gnss_status"]
