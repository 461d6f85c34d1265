"""Where home is: the fused start position, once the estimator has settled (``return_home``, ``near: home``, fences).

The first raw GPS fix is a poor home: a single fix is metres off (a cold
start's first fixes more), and ``return_home`` then "arrives" that far from
where the robot started. :class:`HomeFinder` waits until the estimator has
*settled* and sets home to where it then believes the robot *started*:

* settled: the fused position is valid, at least :data:`HOME_MIN_FIXES` GPS
  epochs have been seen since the first fix, and the fused position's
  standard deviation (the square root of the larger eigenvalue of its
  east-north covariance, metres) is at most :data:`HOME_MAX_SIGMA_M`;
* the start: the fused position then, less the wheels' travel since the
  first tick (turned into the world by the fused heading; while the robot has
  not moved more than :data:`STILL_M`, no heading is needed);
* when the estimator has not settled :data:`HOME_WAIT_S` seconds after the
  first fix, home is set all the same from what it has, and says so;
* a robot without an estimator (nothing fuses its GPS) takes the first fix,
  as before, and says so.

How home was set goes to the ``home`` event and the summary's ``home``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional, Sequence

HOME_MIN_FIXES = 10
"""GPS epochs (distinct fixes, one a second on the MTK3339) seen before home may be set."""
HOME_MAX_SIGMA_M = 1.5
"""Largest standard deviation of the fused position (m) at which the estimator counts as settled."""
HOME_WAIT_S = 30.0
"""Seconds after the first fix after which home is set even if the estimator has not settled."""
STILL_M = 0.2
"""Wheel travel from the start (m) below which the start is where the robot is (no heading needed)."""
EARTH_RADIUS_M = 6_378_137.0


@dataclass(frozen=True)
class Home:
    """Home as set: ``lat``/``lon`` degrees; ``how`` (``fused_start``: the settled fused start position,
    ``fused_start_unsettled``: the same after :data:`HOME_WAIT_S` without settling, ``first_fix``: no estimator);
    ``set_at_s`` clock seconds from the first tick; ``fixes`` GPS epochs seen; ``sigma_m`` the fused position's
    standard deviation then (m, None for a fix); ``moved_m`` the wheel travel from the start subtracted (m)."""

    lat: float
    lon: float
    how: str
    set_at_s: float
    fixes: int
    sigma_m: Optional[float]
    moved_m: float

    def text(self) -> str:
        """One line for the ``home`` event and the terminal summary."""
        where = f"{self.lat:.6f}, {self.lon:.6f}"
        if self.how == "first_fix":
            return f"home set at the first GPS fix {where} (no estimator fuses the GPS on this robot)"
        settled = ("once the estimate settled" if self.how == "fused_start"
                   else f"without the estimate settling within {HOME_WAIT_S:g} s")
        back = f", {self.moved_m:.1f} m of wheel travel back" if self.moved_m >= STILL_M else ""
        return (f"home set at the fused start position {where}, at {self.set_at_s:.1f} s {settled} "
                f"({self.fixes} GPS fixes, position sigma {self.sigma_m:.2f} m{back})")

    def as_dict(self) -> dict:
        """The summary's ``home`` (schemas/summary.schema.json)."""
        return {"lat": round(self.lat, 8), "lon": round(self.lon, 8), "how": self.how,
                "set_at_s": round(self.set_at_s, 3), "fixes": self.fixes,
                "sigma_m": None if self.sigma_m is None else round(self.sigma_m, 3), "moved_m": round(self.moved_m, 3)}


def home_line(home: dict) -> str:
    """The terminal summary's line for the summary's ``home`` (how it was set, in words)."""
    how = home.get("how")
    if how == "first_fix":
        return "  home: the first GPS fix (no estimator fuses the GPS on this robot)"
    settled = "once the estimate settled" if how == "fused_start" else f"NOT settled after {HOME_WAIT_S:g} s"
    sigma = home.get("sigma_m")
    return (f"  home: the fused start position, set at {home.get('set_at_s', 0.0):.1f} s {settled} "
            f"({home.get('fixes')} GPS fixes, position sigma "
            + (f"{sigma:.2f} m)" if sigma is not None else "unknown)"))


def position_sigma_m(pose: Any) -> float:
    """The fused position's standard deviation (m): the square root of the larger eigenvalue of its 2x2
    east-north covariance."""
    (a, b, _), (c, d, _), _ = pose.covariance
    b = 0.5 * (b + c)
    half_trace = 0.5 * (a + d)
    return math.sqrt(max(half_trace + math.sqrt(max(0.25 * (a - d) ** 2 + b * b, 0.0)), 0.0))


class HomeFinder:
    """Sets home once, from the ticks' fixes, fused pose and odometry (see the module's docstring)."""

    def __init__(self, fused: bool, start_odom: Any = None) -> None:
        self.fused = fused
        """Whether an estimator fuses the GPS (else home is the first fix)."""
        self._epochs: set = set()
        self._first_fix_s: Optional[float] = None
        self._start_odom = start_odom
        """The wheels' pose at the first tick: the start."""
        self._t0: Optional[float] = getattr(start_odom, "stamp_s", None)

    @property
    def had_fix(self) -> bool:
        """True once a GPS fix has been seen (from then on every tick may settle home)."""
        return self._first_fix_s is not None

    def update(self, now_s: float, fixes: Sequence[Any], pose: Any, pose_odom: Any) -> Optional[Home]:
        """Home, the tick it is set (None before): ``fixes`` this tick's GpsFix readings, ``pose`` the fused pose,
        ``pose_odom`` the wheels' pose."""
        if self._t0 is None:
            self._t0 = now_s
        good = [f for f in fixes if getattr(f, "quality", 1)]
        if good and self._first_fix_s is None:
            self._first_fix_s = now_s
        for f in good:
            self._epochs.add(f.time_utc if f.time_utc is not None else f.stamp_s)
        if self._first_fix_s is None:
            return None
        if not self.fused:
            first = good[0]
            return Home(first.lat, first.lon, "first_fix", now_s - self._t0, len(self._epochs), None, 0.0)
        if pose is None or not pose.position_valid or pose.lat is None:
            return None
        sigma = position_sigma_m(pose)
        de, dn, moved = self._travel(pose, pose_odom)
        late = now_s - self._first_fix_s >= HOME_WAIT_S
        settled = len(self._epochs) >= HOME_MIN_FIXES and sigma <= HOME_MAX_SIGMA_M and de is not None
        if not (settled or late):
            return None
        de, dn = (de, dn) if de is not None else (0.0, 0.0)
        lat = pose.lat - math.degrees(dn / EARTH_RADIUS_M)
        lon = pose.lon - math.degrees(de / (EARTH_RADIUS_M * math.cos(math.radians(pose.lat))))
        return Home(lat, lon, "fused_start" if settled else "fused_start_unsettled", now_s - self._t0,
                    len(self._epochs), sigma, moved)

    def _travel(self, pose: Any, pose_odom: Any) -> tuple[Optional[float], Optional[float], float]:
        """(east m, north m) the robot moved since the start, by the wheels turned into the world by the fused
        heading, and the distance (m); east and north None when it moved but the heading is not known yet."""
        start = self._start_odom
        if start is None or pose_odom is None:
            return 0.0, 0.0, 0.0
        dx, dy = pose_odom.x - start.x, pose_odom.y - start.y
        moved = math.hypot(dx, dy)
        if moved < STILL_M:
            return 0.0, 0.0, moved
        if not pose.heading_valid:
            return None, None, moved
        turn = pose.yaw - pose_odom.yaw  # the wheels' frame into the world's
        c, s = math.cos(turn), math.sin(turn)
        return c * dx - s * dy, s * dx + c * dy, moved


__all__ = ["Home", "HomeFinder", "home_line", "position_sigma_m", "HOME_MIN_FIXES", "HOME_MAX_SIGMA_M", "HOME_WAIT_S",
           "STILL_M"]
