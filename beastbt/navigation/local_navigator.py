"""One run's local navigation: the rolling costmap fed with scans, and the DWA planner on it.

:class:`LocalNavigator` is what ``go_to`` (and so ``route`` and
``return_home``) is handed on a robot with a LiDAR. Each tick of a
navigation step it is given the newest :class:`LaserScan` and the
dead-reckoned pose (``pose_odom``): a scan it has not seen yet goes into the
costmap, placed with the odom pose at the scan's stamp (interpolated from the
poses it was given), each beam turned back by the turn after its own time
(:meth:`LocalNavigator.deskewed`), and the grid is rebuilt round the robot; the
global costmap (GPS go_to) takes it only when the robot turned slowly over its
revolution (:data:`STEADY_TURN_RATE_RPS`), since its marks last; the same scan
goes to the person tracker (:mod:`beastbt.navigation.people`), whose walking
persons the planner passes on ``local_planner.pass_side``. Robots that do
not navigate never call it and pay nothing. Nothing here reads a clock.
"""

from __future__ import annotations

import dataclasses
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

SCAN_LATENCY_S = 0.05
"""How long before its stamp a scan's last beam was measured (s): the driver reads a revolution's last bytes at the
next tick (up to 0.05 s later at 20 Hz), and the emulated LiDAR casts each half revolution with the pose at the
half's start. On the simulator, the marks of walls seen while turning in place lie nearest the walls with 0.05 to
0.075 s (0 leaves walls 1.5-2 m away smeared by up to 10 cm even deskewed)."""

STEADY_TURN_RATE_RPS = 0.35
"""A scan taken while the robot turned faster than this (rad/s) does not go to the global costmap
(:attr:`LocalNavigator.fresh_steady`): de-skewed or not, where its beams lie is a degree or two off (the odometry's
heading drifts in a turn in place; the emulated LiDAR casts each half revolution at one heading), 5-10 cm at 2 m,
enough to close a tight gap's mouth with marks that stay (docs/navigation.md, Tight gaps). The local costmap, rebuilt
from the newest scans, takes every scan."""

DESKEW_KNOTS = 5
"""The odom yaw is looked up at this many times over a revolution to turn its beams (:meth:`LocalNavigator.deskewed`)."""


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
        self.fresh_steady: Optional[tuple[LaserScan, tuple[float, float, float]]] = None
        """:attr:`fresh` de-skewed (:meth:`deskewed`), when the robot turned no faster than
        :data:`STEADY_TURN_RATE_RPS` over its revolution; else None. The global costmap, whose marks last, is fed
        these only."""
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

    def turn_rate_rps(self, scan: LaserScan) -> float:
        """How fast (rad/s, unsigned) the robot turned, by odometry, over ``scan``'s revolution; 0 when unknown."""
        period = scan.scan_time_s
        if not (math.isfinite(period) and 0.0 < period < POSE_HISTORY_S / 2.0):
            return 0.0
        end = scan.stamp_s - SCAN_LATENCY_S
        a, b = self.pose_at(end - period), self.pose_at(end)
        if a is None or b is None:
            return 0.0
        return abs(wrap(b[2] - a[2])) / period

    def deskewed(self, scan: LaserScan, end: tuple[float, float, float]) -> LaserScan:
        """``scan`` with each beam's angle turned by how far the robot turned from the beam's own time to the scan's
        stamp (where the scan is placed, at the odom pose ``end``: x m, y m, yaw rad); the scan itself when the robot
        did not turn.

        The beams of a revolution come in order over ``scan_time_s``, up to :data:`SCAN_LATENCY_S` before the
        stamp: a robot turning in place at 1 rad/s turns 6 degrees in a 10 Hz revolution, and a wall 1.5 m away
        placed whole at the stamp's pose is smeared by up to 15 cm, across a tight gap's mouth (docs/navigation.md,
        Tight gaps). The robot's travel over the revolution (3 cm at 0.3 m/s) is left: it moves every beam alike."""
        period = scan.scan_time_s
        n = len(scan.angles_rad)
        if not (math.isfinite(period) and 0.0 < period < POSE_HISTORY_S / 2.0) or n == 0:
            return scan
        # The odom yaw at a few times over the revolution (the poses come every tick), between them linear.
        first = scan.stamp_s - SCAN_LATENCY_S - period
        knots = np.linspace(first, scan.stamp_s - SCAN_LATENCY_S, DESKEW_KNOTS)
        yaws = []
        for t in knots:
            at = self.pose_at(float(t))
            if at is None:
                return scan
            yaws.append(at[2])
        yaws = np.unwrap(np.array(yaws))
        behind = wrap(end[2] - float(yaws[-1])) + (float(yaws[-1]) - yaws)  # yet to turn, from each knot to the end
        if float(np.abs(behind).max()) < 1e-6:
            return scan
        times = first + period * (np.arange(n) + 0.5) / n
        angles = np.asarray(scan.angles_rad, dtype=float) - np.interp(times, knots, behind)
        return dataclasses.replace(scan, angles_rad=(angles + math.pi) % (2.0 * math.pi) - math.pi)

    def observe(self, scan: Optional[LaserScan], pose: Optional[FusedPose], now_s: float) -> Optional[LocalCostmap]:
        """Take this tick's scan and odom pose; the costmap (rebuilt when the scan is new), or None without a fresh
        scan (none yet, or older than ``local_planner.scan_timeout_s``)."""
        self.fresh = None
        self.fresh_steady = None
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
            fixed = self.deskewed(scan, at)
            self.costmap.add_scan(scan.stamp_s, base_points_xy(fixed, m), at, (m.x_m, m.y_m))
            self.costmap.build(scan.stamp_s, (pose.x, pose.y))
            self.scans_used += 1
            if self.planner.config.step_aside:
                self.people.update(scan, m, self.pose_at)  # it places each blob at its own time itself
                scan = self.people.without_walkers(scan)  # their trail is not marked on the global costmap
            self.fresh = (scan, at)
            if self.turn_rate_rps(scan) <= STEADY_TURN_RATE_RPS:
                # The de-skewed angles, with the walkers' beams taken out (the same beams, in the same order).
                steady = scan if fixed.angles_rad is scan.angles_rad else dataclasses.replace(
                    scan, angles_rad=fixed.angles_rad)
                self.fresh_steady = (steady, at)
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
