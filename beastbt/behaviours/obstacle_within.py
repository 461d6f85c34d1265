"""The ``obstacle_within`` condition: does the LiDAR see something within a gap of the robot's footprint?

``{obstacle_within: 0.5 m, sector_deg: [-30, 30]}`` holds when at least
``min_points`` returns of the latest scan (the collision monitor's
``min_points``, 3 by default, so one stray return does not count) lie at most
0.5 m from the footprint, within the sector. Distances are the free space
between the footprint (a circle of the profile's footprint radius round
base_link, as the collision monitor and the simulator's contact use) and a
return: |p| - radius for a return at p in base_link, the same gap as the
summary's ``truth.min_clearance_m``. The scan is moved from the LiDAR's frame to
base_link with ``lidar.mounting`` by the collision monitor's own transform
(:func:`~beastbt.devices.lidar_scan.base_points_xy`).

The sector is in base_link, degrees: 0 straight ahead, positive to the left
(counterclockwise seen from above); it runs counterclockwise from its first
angle to its second, so ``[-30, 30]`` is the 60 degrees ahead and
``[150, -150]`` the 60 degrees behind.

Without a fresh scan (none yet, or the latest older than the collision
monitor's ``source_timeout_s``, 0.3 s by default) the answer is *unknown*:
the test returns None, which never holds, and ``not`` of unknown is unknown
too (``all``/``any`` follow Kleene's three-valued logic), so neither
``wait_until: {obstacle_within: ...}`` nor ``wait_until: {not: {obstacle_within: ...}}``
is ever satisfied by a silent LiDAR. One event says so per silent spell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

from beastbt.actuation.collision_monitor import DEFAULT_FOOTPRINT_RADIUS_M, CollisionMonitorConfig
from beastbt.behaviours.conditions import sector_width_rad
from beastbt.behaviours.context import MissionContext
from beastbt.blackboard.types import LaserScan
from beastbt.devices.lidar_scan import STARTUP_GRACE_S, LidarMounting, base_points_xy

EVENT_KIND = "obstacle_within"


@dataclass(frozen=True)
class ObstacleSensing:
    """What the obstacle conditions need of the robot: where its LiDAR sits, its footprint, and the collision
    monitor's rules for a scan (how old it may be, s; how many returns make an obstacle).

    Set by the LiDAR part (``RunServices.obstacle_sensing``) from the profile's ``lidar.mounting``,
    ``geometry.footprint_radius_m`` and ``collision_monitor``; the defaults are those of a profile that states none.
    """

    mounting: LidarMounting = field(default_factory=LidarMounting)
    footprint_radius_m: float = DEFAULT_FOOTPRINT_RADIUS_M
    """The footprint's radius round base_link, m."""
    max_age_s: float = field(default_factory=lambda: CollisionMonitorConfig().source_timeout_s)
    """A scan older than this does not count, s (the collision monitor's ``source_timeout_s``)."""
    min_points: int = field(default_factory=lambda: CollisionMonitorConfig().min_points)
    """Fewest returns that make an obstacle (the collision monitor's ``min_points``)."""


@dataclass
class _ScanView:
    """One scan as the conditions see it: each return's gap to the footprint (m) and bearing (rad) in base_link."""

    scan: LaserScan
    gaps_m: np.ndarray
    bearings_rad: np.ndarray


class ScanWatch:
    """The latest scan for the obstacle conditions of one mission, and the events about its absence.

    The scan is moved to base_link once per scan, whatever the number of
    conditions; :meth:`view` gives None when there is no fresh scan and says
    so once per silent spell (before the first scan, only after the LiDAR's
    spin-up grace of 3 s), then once more when scans are back.
    """

    def __init__(self, ctx: MissionContext) -> None:
        self.ctx = ctx
        self._view: Optional[_ScanView] = None
        self._silent_said = False
        self._first_look_s: Optional[float] = None

    @property
    def sensing(self) -> ObstacleSensing:
        """The robot's LiDAR geometry and the scan rules (the defaults when no LiDAR part set them)."""
        given = getattr(self.ctx.services, "obstacle_sensing", None)
        return given if isinstance(given, ObstacleSensing) else ObstacleSensing()

    def view(self, scan: Optional[LaserScan]) -> Optional[_ScanView]:
        """``scan`` (the blackboard's latest) in base_link, or None when it is missing or too old."""
        now = self.ctx.now()
        if self._first_look_s is None:
            self._first_look_s = now
        sensing = self.sensing
        if scan is None or now - scan.stamp_s > sensing.max_age_s:
            self._say_silent(scan, now, sensing)
            return None
        if self._silent_said:
            self._silent_said = False
            self.ctx.events.add(EVENT_KIND, "obstacle_within: LiDAR scans are back: obstacle conditions are checked "
                                            "again")
        if self._view is None or self._view.scan is not scan:
            pts = base_points_xy(scan, sensing.mounting)
            self._view = _ScanView(scan, np.hypot(pts[:, 0], pts[:, 1]) - sensing.footprint_radius_m,
                                   np.arctan2(pts[:, 1], pts[:, 0]))
        return self._view

    def _say_silent(self, scan: Optional[LaserScan], now: float, sensing: ObstacleSensing) -> None:
        if self._silent_said:
            return
        if scan is None:
            assert self._first_look_s is not None
            if now - self._first_look_s < STARTUP_GRACE_S:
                return  # a LiDAR spinning up: not worth an event yet
            why = f"no LiDAR scan in {now - self._first_look_s:.1f} s"
        else:
            why = f"no LiDAR scan for {now - scan.stamp_s:.2f} s (older than {sensing.max_age_s:g} s)"
        self._silent_said = True
        self.ctx.events.add(EVENT_KIND, f"obstacle_within: {why}: obstacle conditions do not hold (nor does "
                                        f"their 'not') until scans return")


class ObstacleTest:
    """The test of one ``obstacle_within``: True, False, or None (unknown: no fresh scan).

    ``gap_m``: free space from the footprint, m; ``sector_rad``: (from, to) in
    base_link, rad, counterclockwise from ``from``, or None for all around.
    After a test that found returns within the gap, :attr:`nearest` is the
    closest one's (gap m, bearing rad) and :attr:`count` how many there were.
    """

    def __init__(self, gap_m: float, sector_rad: Optional[tuple[float, float]], watch: ScanWatch) -> None:
        self.gap_m = gap_m
        self.sector = None if sector_rad is None else (sector_rad[0], sector_width_rad(*sector_rad))
        self.watch = watch
        self.nearest: Optional[tuple[float, float]] = None
        self.count = 0
        self._judged: Optional[tuple[_ScanView, bool]] = None  # the last scan judged and its answer

    def __call__(self, reader: Any) -> Optional[bool]:
        view = self.watch.view(reader.get("scan"))
        if view is None:
            self.nearest, self.count, self._judged = None, 0, None
            return None
        if self._judged is not None and self._judged[0] is view:
            return self._judged[1]  # a 20 Hz tree sees each 10 Hz scan twice: judged once
        answer = self._judge(view)
        self._judged = (view, answer)
        return answer

    def _judge(self, view: _ScanView) -> bool:
        mask = view.gaps_m <= self.gap_m
        if self.sector is not None:
            start, width = self.sector
            mask &= np.mod(view.bearings_rad - start, 2.0 * math.pi) <= width + 1e-9
        self.count = int(np.count_nonzero(mask))
        if self.count == 0:
            self.nearest = None
            return False
        i = int(np.argmin(np.where(mask, view.gaps_m, np.inf)))
        self.nearest = (float(view.gaps_m[i]), float(view.bearings_rad[i]))
        return self.count >= self.watch.sensing.min_points

    def detail(self) -> str:
        """Where the nearest return within the gap was at the last test: ' (nearest 0.42 m at 12 deg)', or ''."""
        if self.nearest is None:
            return ""
        gap, bearing = self.nearest
        return f" (nearest {gap:.2f} m at {math.degrees(bearing):.0f} deg, {self.count} returns)"


def sector_words(sector_rad: Optional[tuple[float, float]]) -> str:
    """The sector as the mission says it: ' in sector [-30, 30] deg', or '' for all around."""
    if sector_rad is None:
        return ""
    a, b = (f"{math.degrees(x):.4g}" for x in sector_rad)
    return f" in sector [{a}, {b}] deg"


__all__ = ["ObstacleSensing", "ObstacleTest", "ScanWatch", "sector_words"]
