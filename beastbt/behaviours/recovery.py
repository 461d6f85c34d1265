"""Recoveries: what go_to, route and return_home try before they give up, in Nav2's order.

When a navigation step on a robot with a LiDAR would fail as stuck or
blocked, it runs one recovery instead and then tries again, as Nav2's
``RecoveryNode`` with its ``RoundRobin`` of recoveries does: the first
failure clears the costmaps around the robot, the second backs up, the third
spins in place, the fourth waits, and round again, until the step's
``tries`` are used up; then the step fails with the reason it had.

* **clear** (Nav2's ``ClearCostmapAroundRobot`` on both costmaps): the local
  costmap and the marks of the global costmap within ``clear_radius_m`` of
  the robot are forgotten (what the LiDAR still sees comes back at the next
  scan);
* **back_up** (``BackUp``): reverse ``backup_distance_m`` at
  ``backup_speed_mps``, only while the LiDAR sees the box behind the robot
  free (the footprint's width, the distance still to go plus
  ``backup_clearance_m``); with something behind it is skipped, said so;
* **spin** (``Spin``): turn in place by ``spin_angle_deg`` at
  ``spin_rate_dps``, toward the side where the LiDAR sees more room;
* **wait** (``Wait``): stand still for ``wait_s`` (a person may pass).

Every recovery ends after ``time_allowance_s`` at most (Nav2's
``time_allowance``). The collision monitor stays in charge: a recovery's
command goes through the mux, the monitor and the gate like any other. Each
recovery is a ``recovery`` event and counts in the summary's
``recoveries``. Nothing here reads a clock but the step's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional, Protocol

from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults

ORDER = ("clear", "back_up", "spin", "wait")
"""The recoveries in the order they are tried (round robin)."""

RECOVERY_LOG = "recoveries"
"""The key of the run's :class:`RecoveryLog` in ``ctx.services.plugins``."""

RECOVERY_CONFIG = "recovery"
"""The key of the profile's :class:`RecoveryConfig` in ``ctx.services.plugins``."""


@dataclass(frozen=True)
@schema_defaults("parts/recovery.schema.json")
class RecoveryConfig:
    """The profile's ``recovery:`` section (Nav2's recovery behaviours' knobs), metres, seconds and degrees."""

    tries: int
    """Recoveries a step may run before it gives up (Nav2's number_of_retries); 0: none."""
    clear_radius_m: float
    """clear: the costmaps are forgotten within this distance of the robot (m)."""
    backup_distance_m: float
    """back_up: how far to reverse (m)."""
    backup_speed_mps: float
    """back_up: how fast (m/s)."""
    backup_clearance_m: float
    """back_up: the room the LiDAR must see free behind the robot beyond the distance still to go (m)."""
    spin_angle_deg: float
    """spin: how far to turn in place (deg)."""
    spin_rate_dps: float
    """spin: how fast (deg/s)."""
    wait_s: float
    """wait: how long to stand still (s)."""
    time_allowance_s: float
    """Any recovery ends after this long (s)."""

    def __post_init__(self) -> None:
        if isinstance(self.tries, bool) or not isinstance(self.tries, int) or not 0 <= self.tries <= 100:
            raise ValueError(f"recovery: 'tries' must be a whole number from 0 to 100, got {self.tries!r}")
        for name in ("clear_radius_m", "backup_distance_m", "backup_speed_mps", "spin_angle_deg", "spin_rate_dps",
                     "time_allowance_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"recovery: '{name}' must be > 0, got {getattr(self, name)}")
        for name in ("backup_clearance_m", "wait_s"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"recovery: '{name}' must be >= 0, got {getattr(self, name)}")

    @classmethod
    def from_dict(cls, d: Any) -> "RecoveryConfig":
        """Build from a profile's ``recovery:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "recovery")


@dataclass
class RecoveryLog:
    """The recoveries a run ran: how many of each kind (the summary's ``recoveries``)."""

    kinds: dict[str, int] = field(default_factory=dict)

    def count(self, kind: str) -> None:
        """One more recovery of ``kind``."""
        self.kinds[kind] = self.kinds.get(kind, 0) + 1

    def summary(self) -> dict:
        """``{count, kinds: {clear: 1, ...}}``."""
        return {"count": sum(self.kinds.values()), "kinds": dict(self.kinds)}


class Host(Protocol):
    """What a recovery needs of the navigation step that runs it (a :class:`~beastbt.behaviours.navigation.GoTo`)."""

    name: str

    def read(self, key: str) -> Any: ...

    def command(self, linear_mps: float, angular_rps: float) -> None: ...

    def clear_costmaps_around(self, radius_m: float) -> int: ...

    def points_base(self) -> Any: ...


class Recoveries:
    """The recoveries of one navigation step: :meth:`begin` one (the next in :data:`ORDER`) when the step would
    fail, :meth:`tick` it until it ends. ``tries`` of them at most (None: the profile's)."""

    def __init__(self, config: RecoveryConfig, tries: int, footprint_radius_m: float,
                 log: Optional[RecoveryLog] = None) -> None:
        self.config = config
        self.tries = tries
        self.footprint_radius_m = footprint_radius_m
        self.log = log
        self.used = 0
        self.kind: Optional[str] = None
        """The recovery running, or None."""
        self.started_s = 0.0
        self.start_odom: Any = None
        self.spin_sign = 1.0
        self.spun_rad = 0.0
        self.last_yaw: Optional[float] = None
        self.what = ""

    @property
    def running(self) -> bool:
        """Whether a recovery is under way."""
        return self.kind is not None

    def left(self) -> int:
        """Recoveries still allowed."""
        return max(0, self.tries - self.used)

    def begin(self, host: Host, events: Any, now: float, reason: str) -> None:
        """Start the next recovery because of ``reason`` (the failure it stands in for)."""
        cfg = self.config
        kind = ORDER[self.used % len(ORDER)]
        self.used += 1
        self.kind = kind
        self.started_s = now
        self.start_odom = host.read("pose_odom")
        self.spun_rad = 0.0
        self.last_yaw = None
        if kind == "clear":
            n = host.clear_costmaps_around(cfg.clear_radius_m)
            self.what = f"clearing the costmaps within {cfg.clear_radius_m:g} m ({n} cells forgotten)"
        elif kind == "back_up":
            self.what = f"backing up {cfg.backup_distance_m:g} m"
        elif kind == "spin":
            self.spin_sign = self._roomier_side(host)
            side = "left" if self.spin_sign > 0 else "right"
            self.what = f"spinning {cfg.spin_angle_deg:g} deg to the {side}"
        else:
            self.what = f"waiting {cfg.wait_s:g} s"
        if self.log is not None:
            self.log.count(kind)
        events.add("recovery", f"{host.name}: recovery {self.used} of {self.tries}: {self.what}, because {reason}")

    def tick(self, host: Host, events: Any, now: float) -> bool:
        """Drive the recovery under way one tick; False once it has ended (the step tries again)."""
        cfg = self.config
        kind = self.kind
        odom = host.read("pose_odom")
        done = False
        if kind is None:
            return False
        if now - self.started_s > cfg.time_allowance_s:
            done = True
        elif kind == "clear":
            done = True
        elif kind == "back_up":
            gone = 0.0
            if odom is not None and self.start_odom is not None:
                gone = math.hypot(odom.x - self.start_odom.x, odom.y - self.start_odom.y)
            if gone >= cfg.backup_distance_m:
                done = True
            elif not self._room_behind(host, cfg.backup_distance_m - gone + cfg.backup_clearance_m):
                if gone < 0.01:
                    events.add("recovery", f"{host.name}: no room behind to back up: skipped")
                done = True
            else:
                host.command(-cfg.backup_speed_mps, 0.0)
        elif kind == "spin":
            # Turned so far: the yaw steps added up (a wrapped difference would stop at 180 deg).
            if odom is not None:
                if self.last_yaw is not None:
                    self.spun_rad += abs(_wrap(odom.yaw - self.last_yaw))
                self.last_yaw = odom.yaw
            if self.spun_rad >= math.radians(cfg.spin_angle_deg) - 1e-3:
                done = True
            else:
                host.command(0.0, self.spin_sign * math.radians(cfg.spin_rate_dps))
        else:
            done = now - self.started_s >= cfg.wait_s
            if not done:
                host.command(0.0, 0.0)
        if done:
            host.command(0.0, 0.0)
            self.kind = None
            return False
        return True

    def _room_behind(self, host: Host, length_m: float) -> bool:
        """Whether the LiDAR sees the box behind the robot free: ``length_m`` beyond its footprint, its width."""
        pts = host.points_base()
        if pts is None:
            return False  # no scan: nothing is known behind, so no backing up
        r = self.footprint_radius_m
        x, y = pts[:, 0], pts[:, 1]
        inside = (x < 0.0) & (x > -(r + length_m)) & (abs(y) < r + 0.03)
        return int(inside.sum()) < 2

    def _roomier_side(self, host: Host) -> float:
        """+1 (left) or -1 (right): the side whose nearest LiDAR return within 2 m is farther."""
        pts = host.points_base()
        if pts is None or len(pts) == 0:
            return 1.0
        import numpy as np

        d = np.hypot(pts[:, 0], pts[:, 1])
        near = d < 2.0
        left = d[near & (pts[:, 1] > 0)]
        right = d[near & (pts[:, 1] < 0)]
        lmin = float(left.min()) if left.size else math.inf
        rmin = float(right.min()) if right.size else math.inf
        return 1.0 if lmin >= rmin else -1.0


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


__all__ = ["RecoveryConfig", "RecoveryLog", "Recoveries", "ORDER", "RECOVERY_LOG", "RECOVERY_CONFIG"]
