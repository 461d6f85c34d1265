"""One run's local navigation: the rolling costmap fed with scans, and the DWA planner on it.

:class:`LocalNavigator` is what ``go_to`` (and so ``route`` and
``return_home``) is handed on a robot with a LiDAR. Each tick of a
navigation step it is given the newest :class:`LaserScan` and the
dead-reckoned pose (``pose_odom``): a scan it has not seen yet goes into the
costmap, placed with the odom pose at the scan's stamp (interpolated from the
poses it was given), and the grid is rebuilt round the robot; the same scan
goes to the person tracker (:mod:`beastbt.navigation.people`), whose walking
persons the planner passes on ``local_planner.pass_side``. Robots that do
not navigate never call it and pay nothing. Nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Optional

import numpy as np

from beastbt.blackboard.types import FusedPose, LaserScan, LocalCostmap
from beastbt.devices.lidar_scan import LidarMounting, base_points_xy
from beastbt.navigation.global_navigator import GlobalNavigator
from beastbt.navigation.local_costmap import LocalCostmapConfig, RollingCostmap
from beastbt.navigation.local_planner import Limits, LocalPlannerConfig
from beastbt.navigation.people import PassingPlanner, PersonTracker

POSE_HISTORY_S = 1.0
"""Odom poses kept to place a scan at its own time (s)."""


def wrap(angle: float) -> float:
    """An angle in [-pi, pi) (rad)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class LocalNavigator:
    """The costmap and planner of one run; ``mounting`` places the LiDAR on the robot (base_link)."""

    def __init__(self, costmap: LocalCostmapConfig, planner: LocalPlannerConfig, footprint_radius_m: float,
                 mounting: LidarMounting, limits: Limits) -> None:
        self.costmap_config = costmap
        self.planner_config = planner
        self.footprint_radius_m = footprint_radius_m
        self.mounting = mounting
        self.costmap = RollingCostmap(costmap, footprint_radius_m, narrow=planner.narrow_speed_mps > 0.0)
        self.people = PersonTracker(planner.person_min_speed_mps, planner.person_max_range_m)
        """The walking persons the scans show (fed by :meth:`observe`)."""
        self.planner = PassingPlanner(planner, limits, self.people, footprint_radius_m)
        self._poses: deque[tuple[float, float, float, float]] = deque()
        self._last_scan: Optional[LaserScan] = None
        self.scans_used = 0
        """Scans put into the costmap so far."""
        self.fresh: Optional[tuple[LaserScan, tuple[float, float, float]]] = None
        """The scan :meth:`observe` took this call (without the returns of walking persons), with the odom pose
        (x m, y m, yaw rad) at its stamp; None when it brought no new scan (the global costmap is fed from here)."""
        self.global_nav: Optional[GlobalNavigator] = None
        """The rolling global costmap and planner of GPS go_to (:mod:`beastbt.navigation.global_navigator`)."""

    # -- poses and scans --------------------------------------------------------------
    def _remember(self, pose: FusedPose) -> None:
        poses = self._poses
        if not poses or pose.stamp_s > poses[-1][0]:
            poses.append((pose.stamp_s, pose.x, pose.y, pose.yaw))
        while len(poses) > 2 and poses[0][0] < pose.stamp_s - POSE_HISTORY_S:
            poses.popleft()

    def pose_at(self, t: float) -> Optional[tuple[float, float, float]]:
        """The odom pose (x m, y m, yaw rad) at time ``t`` (s), interpolated; the nearest one outside the history."""
        poses = self._poses
        if not poses:
            return None
        if t <= poses[0][0]:
            return poses[0][1:]
        for i in range(len(poses) - 1, 0, -1):
            t1 = poses[i][0]
            if t1 <= t:
                if i == len(poses) - 1:
                    return poses[i][1:]
                break
            t0 = poses[i - 1][0]
            if t0 <= t:
                a = (t - t0) / (t1 - t0)
                p0, p1 = poses[i - 1], poses[i]
                return (p0[1] + a * (p1[1] - p0[1]), p0[2] + a * (p1[2] - p0[2]),
                        wrap(p0[3] + a * wrap(p1[3] - p0[3])))
        return poses[-1][1:]

    def observe(self, scan: Optional[LaserScan], pose: Optional[FusedPose], now_s: float) -> Optional[LocalCostmap]:
        """Take this tick's scan and odom pose; the costmap (rebuilt when the scan is new), or None without a fresh
        scan (none yet, or older than ``local_planner.scan_timeout_s``)."""
        self.fresh = None
        if pose is None:
            return None
        self._remember(pose)
        if scan is None or now_s - scan.stamp_s > self.planner_config.scan_timeout_s:
            return None
        if scan is not self._last_scan:
            self._last_scan = scan
            at = self.pose_at(scan.stamp_s)
            assert at is not None
            m = self.mounting
            self.costmap.add_scan(scan.stamp_s, base_points_xy(scan, m), at, (m.x_m, m.y_m))
            self.costmap.build(scan.stamp_s, (pose.x, pose.y))
            self.scans_used += 1
            if self.planner.config.step_aside:
                self.people.update(scan, m, self.pose_at)
                scan = self.people.without_walkers(scan)  # their trail is not marked on the global costmap
            self.fresh = (scan, at)
        return self.costmap.latest

    def nearest_obstacle(self, pose: FusedPose, toward_rad: Optional[float] = None,
                         sector_rad: float = math.radians(60.0)) -> Optional[tuple[float, float]]:
        """The nearest point of the costmap to the robot: (distance m from the robot's centre, bearing rad CCW
        from its heading). With ``toward_rad`` (a bearing, rad) the nearest within ``sector_rad`` of it when there
        is one there. None when the costmap holds no point."""
        pts = self.costmap.points_odom
        if len(pts) == 0:
            return None
        dx, dy = pts[:, 0] - pose.x, pts[:, 1] - pose.y
        d = np.hypot(dx, dy)
        bearing = np.arctan2(dy, dx) - pose.yaw
        bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi
        if toward_rad is not None:
            off = np.abs((bearing - toward_rad + math.pi) % (2.0 * math.pi) - math.pi)
            in_sector = off <= sector_rad
            if in_sector.any():
                d = np.where(in_sector, d, np.inf)
        i = int(np.argmin(d))
        return float(d[i]), float(bearing[i])


def describe_obstacle(distance_m: float, bearing_rad: float) -> str:
    """``obstacle 0.6 m ahead, 15 deg to the left`` (bearing CCW from the heading, rad; distance m)."""
    deg = math.degrees(bearing_rad)
    side = "left" if deg > 0 else "right"
    if abs(deg) < 5.0:
        where = "ahead"
    elif abs(deg) <= 90.0:
        where = f"ahead, {abs(deg):.0f} deg to the {side}"
    elif abs(deg) >= 175.0:
        where = "behind"
    else:
        where = f"{abs(deg):.0f} deg to the {side}"
    return f"obstacle {distance_m:.1f} m {where}"


__all__ = ["LocalNavigator", "describe_obstacle", "POSE_HISTORY_S"]
