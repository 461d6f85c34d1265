"""Localisation on the mission's map (``map:``): the particle filter fed each tick, writing ``map_pose``.

Attached by the composition root when the mission has ``map:``. The robot
needs a LiDAR: without one the run is refused (exit 2) before anything moves,
at the mission's ``map:``. The filter is
:class:`~beastbt.estimation.map_localiser.MapLocaliser`, tuned by the
profile's ``localisation:`` section; it starts at the mission's ``start:``
(default: the map frame's origin, where mapping began) spread by
``initial_uncertainty:``.

Each tick, after sensing, the part integrates its own odometry pose, as
robot_localization's odometry-plus-IMU EKF does for AMCL: the travel of the
wheels (``pose_odom``'s step) and the turn of the gyro (the IMU's yaw rate,
once the driver's standstill bias is known and while its samples are fresh;
the wheels' turn otherwise, e.g. on a robot without an IMU). A tracked base
slips most in turns, where its wheels' heading is worst and the gyro's best.
A new scan (``run.latest[LaserScan]``) updates the filter with that pose
at the middle of the scan's revolution (:func:`scan_mid_s`: its points were
measured over it, and matched at its end the heading would lag in turns);
every tick, ``map_pose`` is it carried into the map by the filter's
``map -> odom`` transform, so it moves smoothly between scans and never waits
for one. A LiDAR that goes quiet (no scan for :data:`SCAN_STALE_S`) counts as
no match: the robot is no longer localised after the localiser's
``lost_after_s``. The failsafe ``localization_lost`` and the condition ``localized``
read it.

In the simulator it also measures the pose against the truth: the true pose
is moved into the map frame by the world's start and the mission's start on
the map (the robot started at both), and ``truth.position_error_rms_m`` and
``truth.position_error_max_m`` of the summary are that error (m), in place of
the GPS fusion's (there is no GPS fix indoors). The summary's
``localisation`` says how the filter did.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, Optional

import numpy as np

from beastbt.blackboard import catalogue
from beastbt.blackboard.types import ImuSample, LaserScan, MapPose
from beastbt.core.errors import InvalidInput
from beastbt.devices.lidar_scan import LidarConfig, base_points_xy
from beastbt.estimation.map_localiser import LocaliserConfig, MapLocaliser, Pose2D, compose, invert, scan_mid_s
from beastbt.robot.part import Part
from beastbt.robot.profile import section_config
from beastbt.run.runner import MissionRun
from beastbt.run.session import Prepared

# This module is imported only for a mission with a map (beastbt.assembly), so NumPy and the filter come with it.

LOCALISATION_RNG_STREAM = 0x10CA1
"""Mixed with the run's seed for the filter's own random numbers: the same seed gives the same run, and the
filter draws from no emulator's stream."""

GYRO_STALE_S = 0.2
"""An IMU sample older than this (s) is not used for the turn of a tick: the wheels' turn is."""

SCAN_STALE_S = 0.5
"""Once scans have come, none for this long (five LD19 revolutions) counts as no match at all (s)."""

ODOM_HISTORY_TICKS = 40
"""Ticks of odometry kept to find the pose at a scan's middle (2 s at 20 Hz: a scan is at most a tick or two old)."""

ERRORS_KEPT = 12000
"""Per-tick true errors kept for tests and benchmarks (10 minutes at 20 Hz); the metrics are running sums."""


def start_pose(prepared: Prepared) -> Pose2D:
    """The mission's start on the map: ``start: {x, y, yaw}``, a named place with map coordinates, or the origin."""
    mission = prepared.mission
    name = mission.map_start_place
    if name is None:
        return mission.map_start
    place = mission.places.get(name)
    x, y = getattr(place, "x", None), getattr(place, "y", None)
    if place is None or x is None or y is None:
        raise InvalidInput([mission.doc.problem(("start",), f"'start: {name}' names no place on the map",
                                                "name a place with x and y (places: {name: {x: 1 m, y: 2 m}}), "
                                                "or write start: {x: 1 m, y: 2 m, yaw: 90 deg}")])
    return (float(x), float(y), float(getattr(place, "yaw", None) or 0.0))


class MapLocalisationPart(Part):
    """``map:`` in a mission: the robot's pose on the map (``map_pose``) from its LiDAR and odometry."""

    name = "map_localisation"
    section = "localisation"
    schema = "parts/localisation.schema.json"
    fills = ("map_pose",)
    reads = ("scan", "pose_odom", "imu")
    localiser: Optional[MapLocaliser] = None
    """The particle filter (None until installed)."""

    def install(self, prepared: Prepared) -> None:
        """Refuse a robot without a LiDAR; build the filter at the start pose; hook the tick and the summary."""
        mission, profile, run = prepared.mission, prepared.profile, prepared.run
        if mission.map_grid is None:
            return
        if profile.section("lidar") is None:
            raise InvalidInput([mission.doc.problem(
                ("map",), f"localising on a map needs a LiDAR, and the robot '{profile.name}' has none",
                "use a robot profile with a lidar: section (robots/sim.yaml has an LD19), or remove map:")])
        config: LocaliserConfig = section_config(profile, "localisation", LocaliserConfig)
        self.mounting = section_config(profile, "lidar", LidarConfig).mounting
        self.start = start_pose(prepared)
        rng = np.random.default_rng([int(prepared.options.seed) & 0xFFFFFFFF, LOCALISATION_RNG_STREAM])
        self.localiser = MapLocaliser(mission.map_grid, config, rng)
        self.writer = catalogue.writer("map_localisation", ("map_pose",))
        self._last_scan: Optional[LaserScan] = None
        self._odom: Optional[Pose2D] = None
        """The odometry pose the filter works in: the wheels' travel, the gyro's turn (m, m, rad)."""
        self._last_wheels: Optional[Pose2D] = None
        self._last_tick_s: Optional[float] = None
        self.gyro_ticks = 0
        """Ticks whose turn came from the gyro."""
        tap = run.io.imu_tap
        self._gyro_ready = (tap.ready if tap is not None and tap.ready is not None else (lambda: True))
        self._started = False
        self._prepared = prepared
        world = prepared.world
        self.map_from_world: Optional[Pose2D] = None
        if run.io.sim is not None and world is not None:
            self.map_from_world = compose(self.start, invert((world.start_x, world.start_y, world.start_yaw)))
        self.error_sq_m2 = 0.0
        self.error_n = 0
        self.error_max_m = 0.0
        self.errors: "deque[tuple[float, float]]" = deque(maxlen=ERRORS_KEPT)
        """(clock s, true error m) per tick, the latest :data:`ERRORS_KEPT`."""
        self.covered_3sigma = 0
        """Ticks whose true error lay within 3 standard deviations of the reported covariance (Mahalanobis)."""
        self.lost_ticks = 0
        run.ctx.services.plugins["map_localiser"] = self.localiser  # the recording's views draw its particles
        run.hooks.append(self.on_tick)
        run.summary_contributors.append(self.contribute)

    def on_tick(self, run: MissionRun, now_s: float) -> None:
        """Feed a new scan to the filter, then write ``map_pose`` from this tick's odometry pose."""
        loc = self.localiser
        odom_pose = run.bb.pose_odom
        if loc is None or odom_pose is None:
            return
        odom = self._integrate(run, now_s, (odom_pose.x, odom_pose.y, odom_pose.yaw))
        if not self._started:
            m = self._prepared.mission
            loc.start(self.start, m.initial_uncertainty_xy_m, m.initial_uncertainty_yaw_rad, odom)
            self._started = True
        scan = run.latest.get(LaserScan)
        if scan is not None and scan is not self._last_scan:
            self._last_scan = scan
            loc.update(now_s, base_points_xy(scan, self.mounting), self._odom_at(scan_mid_s(scan)))
        elif self._last_scan is not None and now_s - self._last_scan.stamp_s > SCAN_STALE_S:
            loc.no_scan(now_s)  # a LiDAR gone quiet matches nothing: the robot is soon not localised
        x, y, yaw = loc.map_pose_of(odom)
        mo = loc.map_from_odom
        cov = tuple(tuple(float(v) for v in row) for row in loc.pose_covariance)
        pose = MapPose(now_s, x, y, yaw, cov, loc.match_quality, loc.localized, mo[0], mo[1], mo[2])
        self.writer.map_pose = pose
        run.latest[MapPose] = pose
        if not loc.localized:
            self.lost_ticks += 1
        if self.map_from_world is not None and run.io.sim is not None:
            self._measure(pose, run.io.sim.truth, now_s)

    def _integrate(self, run: MissionRun, now_s: float, wheels: Pose2D) -> Pose2D:
        """This tick's odometry pose: the wheels' step since the last tick, turned by the gyro when it can."""
        if self._odom is None or self._last_wheels is None or self._last_tick_s is None:
            self._odom, self._last_wheels, self._last_tick_s = wheels, wheels, now_s
            self._history: "deque[tuple[float, Pose2D]]" = deque([(now_s, wheels)], maxlen=ODOM_HISTORY_TICKS)
            """(clock s, odometry pose) of the last ticks: a scan is matched at the pose of its middle."""
            return wheels
        dx, dy, dth = compose(invert(self._last_wheels), wheels)
        dt = now_s - self._last_tick_s
        imu = run.latest.get(ImuSample)
        if imu is not None and 0.0 < dt and now_s - imu.stamp_s <= GYRO_STALE_S and self._gyro_ready():
            dth = float(imu.gyro_rps[2]) * dt
            self.gyro_ticks += 1
        self._odom = compose(self._odom, (dx, dy, dth))
        self._last_wheels, self._last_tick_s = wheels, now_s
        self._history.append((now_s, self._odom))
        return self._odom

    def _odom_at(self, t: float) -> Pose2D:
        """The odometry pose at clock time ``t`` (s), interpolated between ticks; the oldest or newest kept outside
        them."""
        h = self._history
        assert self._odom is not None
        if not h or t >= h[-1][0]:
            return self._odom
        if t <= h[0][0]:
            return h[0][1]
        for i in range(len(h) - 1, 0, -1):
            t0, p0 = h[i - 1]
            if t0 <= t:
                t1, p1 = h[i]
                a = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
                step = compose(invert(p0), p1)
                return compose(p0, (a * step[0], a * step[1], a * step[2]))
        return h[0][1]

    def _measure(self, pose: MapPose, truth: Any, now_s: float) -> None:
        """The true error of ``pose`` (m), the truth moved into the map frame by the two starts."""
        assert self.map_from_world is not None
        tx, ty, _ = compose(self.map_from_world, (truth.x, truth.y, truth.yaw))
        dx, dy = pose.x - tx, pose.y - ty
        err = math.hypot(dx, dy)
        self.error_sq_m2 += err * err
        self.error_n += 1
        self.error_max_m = max(self.error_max_m, err)
        self.errors.append((now_s, err))
        # Mahalanobis distance over (x, y), the 2x2 inverse written out: this runs every tick.
        (a, b, _), (_, c, _), _ = pose.covariance
        a, c = a + 1e-6, c + 1e-6  # a collapsed cloud is not a point
        det = a * c - b * b
        if det > 0.0 and (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det <= 9.0:
            self.covered_3sigma += 1  # within 3 sigma: ~99 % of the time for an honest Gaussian

    def contribute(self, run: MissionRun, summary: dict) -> None:
        """``localisation`` (how the filter did) and, in the simulator, the map-frame ``truth`` errors."""
        loc = self.localiser
        if loc is None:
            return
        summary["localisation"] = {
            "updates": loc.updates,
            "particles": loc.config.particles,
            "injected_particles": loc.injected,
            "match_quality": round(loc.match_quality, 3),
            "localized": bool(loc.localized),
            "not_localized_ticks": self.lost_ticks,
            "gyro_ticks": self.gyro_ticks,
        }
        if "truth" in summary and self.map_from_world is not None:
            # how the map frame sits on the world (aligned by the two starts): the report draws the localiser's error
            summary["truth"]["map_from_world"] = [round(float(v), 6) for v in self.map_from_world]
        if "truth" in summary and self.error_n:
            summary["truth"]["position_error_rms_m"] = round(math.sqrt(self.error_sq_m2 / self.error_n), 4)
            summary["truth"]["position_error_max_m"] = round(self.error_max_m, 4)
            summary["truth"]["position_error_within_3sigma_frac"] = round(self.covered_3sigma / self.error_n, 4)


__all__ = ["MapLocalisationPart", "start_pose", "LOCALISATION_RNG_STREAM"]
