"""The rolling local costmap: scan points marked lethal and inflated, in the odom frame, like Nav2's local costmap.

:class:`RollingCostmap` keeps the points of the scans of the last
``observation_persistence_s`` (moved to the ``odom`` frame with the
dead-reckoned pose at each scan's time) and, on every new scan, rebuilds a
square grid of ``width_m`` centred on the robot:

* **obstacle layer**: each cell holding a point is :data:`COST_LETHAL` (254);
  points nearer than ``obstacle_min_range_m`` or farther than
  ``obstacle_max_range_m`` from the LiDAR are left out;
* **inflation layer**: with ``d`` the distance (m) from a cell's centre to the
  nearest lethal cell's centre (``cv2.distanceTransform`` with its 5x5 mask:
  within 2 % of the Euclidean distance, several times quicker than the exact
  one when the window is full of points),
  cells with ``d`` up to the inscribed radius (the footprint radius plus
  ``footprint_padding_m``) are :data:`COST_INSCRIBED` (253), those up to
  ``inflation_radius_m`` get ``252 * exp(-cost_scaling_factor * (d -
  inscribed))`` as in Nav2's ``inflation_layer``, and the rest
  :data:`COST_FREE` (0). With ``narrow`` (a profile whose
  ``local_planner.narrow_speed_mps`` is above 0), the cells of the padding
  band farther than the footprint radius itself are :data:`COST_NARROW` (252,
  passable, the costliest) instead in and round a gap (obstacles within reach
  on two opposite sides; not in a band along one wall): the local planner
  drives them slowly (docs/navigation.md, Tight gaps).

Decay for moving things is the rebuild itself: a point lives for
``observation_persistence_s`` (Nav2's ``observation_persistence``), so a
person who walked away is gone from the map within that time. Since the
window is rebuilt from what the LiDAR sees now, cells are never unknown
(Nav2 with ``track_unknown_space: false``). Nothing here reads a clock:
times are the scans' stamps.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Optional

import cv2
import numpy as np

from beastbt.blackboard.types import COST_FREE, COST_INSCRIBED, COST_LETHAL, LocalCostmap
from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults

COST_NARROW = COST_INSCRIBED - 1
"""A cell within the padding but farther than the footprint radius from an obstacle, with ``narrow``: passable, the
costliest (an inflated cell is at most 251); the global planner's narrow cost too."""

LUT_STEPS_PER_CELL = 8
"""The inflation cost is looked up at this many distances per cell (a distance is rounded down to 1/8 cell), fewer
when the inflation reaches farther than 254 / 8 cells (the lookup is a 256-entry ``cv2.LUT``)."""


@dataclass(frozen=True)
@schema_defaults("parts/local_costmap.schema.json")
class LocalCostmapConfig:
    """The profile's ``local_costmap:`` section (Nav2's local costmap knobs), metres and seconds."""

    width_m: float
    """Side of the square rolling window (m)."""
    resolution_m: float
    """Side of a cell (m)."""
    obstacle_min_range_m: float
    """Points nearer the LiDAR are left out (m)."""
    obstacle_max_range_m: float
    """Points farther from the LiDAR are left out (m)."""
    observation_persistence_s: float
    """How long a scan's points stay (s)."""
    footprint_padding_m: float
    """Added to the footprint radius for the inscribed cost (m)."""
    inflation_radius_m: float
    """Cells this close to an obstacle get an inflated cost (m)."""
    cost_scaling_factor: float
    """How fast the inflated cost falls off beyond the inscribed radius (1/m)."""

    def __post_init__(self) -> None:
        for name in ("width_m", "resolution_m", "obstacle_max_range_m", "inflation_radius_m", "cost_scaling_factor"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"local_costmap: '{name}' must be > 0, got {getattr(self, name)}")
        for name in ("obstacle_min_range_m", "observation_persistence_s", "footprint_padding_m"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"local_costmap: '{name}' must be >= 0, got {getattr(self, name)}")
        if self.width_m / self.resolution_m > 2000:
            raise ValueError(f"local_costmap: width_m / resolution_m is {self.width_m / self.resolution_m:.0f} cells "
                             f"a side: at most 2000")

    @classmethod
    def from_dict(cls, d: Any) -> "LocalCostmapConfig":
        """Build from a profile's ``local_costmap:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "local_costmap")


def lut_steps(config: LocalCostmapConfig, inscribed_m: float) -> int:
    """Steps per cell of the inflation lookup: :data:`LUT_STEPS_PER_CELL`, fewer for a far-reaching inflation."""
    reach_cells = max(config.inflation_radius_m, inscribed_m) / config.resolution_m
    return max(1, min(LUT_STEPS_PER_CELL, int(254 // (reach_cells + 1))))


def inflation_lut(config: LocalCostmapConfig, inscribed_m: float, narrow_from_m: Optional[float] = None
                  ) -> np.ndarray:
    """Cost (uint8, 256 entries) by distance to the nearest lethal cell, indexed by the distance in
    1 / :func:`lut_steps` cells (255: that far or farther).

    254 at 0, 253 up to ``inscribed_m`` (:data:`COST_NARROW` beyond ``narrow_from_m``, the footprint radius, when
    given), Nav2's exponential decay up to ``inflation_radius_m``, 0 beyond.
    """
    res = config.resolution_m
    steps = lut_steps(config, inscribed_m)
    d = np.arange(256) * (res / steps)
    cost = np.where(d <= config.inflation_radius_m,
                    (COST_INSCRIBED - 1) * np.exp(-config.cost_scaling_factor * (d - inscribed_m)), COST_FREE)
    cost = np.where(d <= inscribed_m, COST_INSCRIBED, np.floor(cost))
    if narrow_from_m is not None:
        cost = np.where((d <= inscribed_m) & (d > narrow_from_m + 1e-9), COST_NARROW, cost)
    cost[0] = COST_LETHAL
    cost[-1] = COST_FREE
    if config.inflation_radius_m >= d[-1] and inscribed_m < d[-1]:
        raise ValueError("local_costmap: inflation_radius_m reaches too many cells for the lookup")
    return cost.astype(np.uint8)


def odom_points(points_base: np.ndarray, pose_xy_yaw: tuple[float, float, float]) -> np.ndarray:
    """Points (n, 2) in base_link moved to the odom frame by the robot's pose there (x m, y m, yaw rad)."""
    x, y, yaw = pose_xy_yaw
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty_like(points_base)
    out[:, 0] = x + c * points_base[:, 0] - s * points_base[:, 1]
    out[:, 1] = y + s * points_base[:, 0] + c * points_base[:, 1]
    return out


class RollingCostmap:
    """A rolling costmap around the robot from scan points; see the module docstring.

    ``footprint_radius_m`` is the robot's circle (m). :meth:`add_scan` takes
    one scan's points (base_link, and the robot's odom pose at the scan's
    time); :meth:`build` makes the grid round a position. :attr:`points_odom`
    are the points it holds now.
    """

    def __init__(self, config: LocalCostmapConfig, footprint_radius_m: float, narrow: bool = False) -> None:
        self.config = config
        self.inscribed_m = footprint_radius_m + config.footprint_padding_m
        self.cells = int(round(config.width_m / config.resolution_m))
        # Narrow: clear of the footprint (the global costmap has judged the gap on its fine grid).
        narrow_from = footprint_radius_m if narrow else None
        self._lut = inflation_lut(config, self.inscribed_m, narrow_from)
        self._narrow_reach = int(math.ceil(2.0 * self.inscribed_m / config.resolution_m)) + 1 if narrow else 0
        self._lut_scale = float(lut_steps(config, self.inscribed_m))
        self._reach_cells = int(math.ceil(max(config.inflation_radius_m, self.inscribed_m) / config.resolution_m)) + 1
        self._scans: deque[tuple[float, np.ndarray]] = deque()
        self._free = np.full((self.cells, self.cells), 255, np.uint8)
        self.points_odom = np.zeros((0, 2))
        self.latest: Optional[LocalCostmap] = None

    def add_scan(self, stamp_s: float, points_base: np.ndarray, pose_xy_yaw: tuple[float, float, float],
                 lidar_xy: tuple[float, float] = (0.0, 0.0)) -> None:
        """Keep a scan's points ((n, 2) base_link, m) seen from the pose (odom x m, y m, yaw rad) at ``stamp_s``.

        Points outside [obstacle_min_range_m, obstacle_max_range_m] of the LiDAR
        (at ``lidar_xy`` in base_link) are left out; scans older than
        ``observation_persistence_s`` before this one are forgotten.
        """
        cfg = self.config
        r = np.hypot(points_base[:, 0] - lidar_xy[0], points_base[:, 1] - lidar_xy[1])
        keep = (r <= cfg.obstacle_max_range_m) & (r >= cfg.obstacle_min_range_m)
        self._scans.append((stamp_s, odom_points(points_base[keep], pose_xy_yaw)))
        while self._scans and self._scans[0][0] < stamp_s - cfg.observation_persistence_s - 1e-9:
            self._scans.popleft()
        if len(self._scans) == 1:
            self.points_odom = self._scans[0][1]
        else:
            self.points_odom = np.concatenate([p for _, p in self._scans])

    def clear(self) -> None:
        """Forget every point (a new start)."""
        self._scans.clear()
        self.points_odom = np.zeros((0, 2))
        self.latest = None

    def build(self, stamp_s: float, centre_xy: tuple[float, float]) -> LocalCostmap:
        """The grid of ``width_m`` round ``centre_xy`` (odom, m), its origin on a multiple of the resolution."""
        res = self.config.resolution_m
        n = self.cells
        ox = math.floor(centre_xy[0] / res - n / 2) * res
        oy = math.floor(centre_xy[1] / res - n / 2) * res
        cost = np.zeros((n, n), np.uint8)
        pts = self.points_odom
        if len(pts):
            ix = ((pts[:, 0] - ox) * (1.0 / res)).astype(np.intp)  # truncation is floor here: only >= 0 is kept
            iy = ((pts[:, 1] - oy) * (1.0 / res)).astype(np.intp)
            inside = (ix >= 0) & (ix < n) & (iy >= 0) & (iy < n) & (pts[:, 0] >= ox) & (pts[:, 1] >= oy)
            ix, iy = ix[inside], iy[inside]
            if len(ix):
                # Only cells within the inflation's reach of a point can cost anything: the distance transform
                # runs on the box round the points (the whole window in a room, a corner of it on a lawn).
                m = self._reach_cells
                x0, x1 = max(0, int(ix.min()) - m), min(n, int(ix.max()) + m + 1)
                y0, y1 = max(0, int(iy.min()) - m), min(n, int(iy.max()) + m + 1)
                grid = self._free[y0:y1, x0:x1].copy()
                grid[iy - y0, ix - x0] = 0
                # Distance (cells) from each cell to the nearest marked one, then the cost by lookup: the distance
                # in 1/steps cells, saturated at 255 (convertScaleAbs rounds: less half a step, it floors),
                # through a 256-entry cv2.LUT.
                dist = cv2.distanceTransform(grid, cv2.DIST_L2, cv2.DIST_MASK_5)
                idx = cv2.convertScaleAbs(dist, alpha=self._lut_scale, beta=-0.5)
                cost[y0:y1, x0:x1] = cv2.LUT(idx, self._lut)
                if self._narrow_reach:
                    # Narrow only in and round a gap (obstacles on two opposite sides, its mouth within reach of
                    # them): along one wall the padding stays impassable, as without narrow cells, so a robot is
                    # not slowed beside every wall.
                    box = cost[y0:y1, x0:x1]
                    k = self._narrow_reach
                    gap = between_obstacles(box == COST_LETHAL, k).astype(np.uint8)
                    near_gap = cv2.dilate(gap, np.ones((2 * k + 1, 2 * k + 1), np.uint8)).astype(bool)
                    box[(box == COST_NARROW) & ~near_gap] = COST_INSCRIBED
        self.latest = LocalCostmap(stamp_s, ox, oy, res, cost)
        return self.latest


def between_obstacles(lethal: np.ndarray, reach: int) -> np.ndarray:
    """Cells with a lethal cell within ``reach`` cells on two opposite sides (left and right, above and below, or
    across either diagonal), looking along a line one cell thick to either side: the cells of a gap, not of a band
    along one wall. The thickness is for a wall at a slant to the grid (at 20-30 degrees, say): a line of cells
    from the middle of its gap may pass beside the wall's cells on one side without meeting one."""
    rows, cols = lethal.shape
    thick = cv2.dilate(lethal.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    pad = np.zeros((rows + 2 * reach, cols + 2 * reach), bool)
    pad[reach:-reach, reach:-reach] = thick

    def seen(dr: int, dc: int) -> np.ndarray:
        out = np.zeros((rows, cols), bool)
        for j in range(1, reach + 1):
            out |= pad[reach + j * dr:reach + j * dr + rows, reach + j * dc:reach + j * dc + cols]
        return out

    out = np.zeros((rows, cols), bool)
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        out |= seen(dr, dc) & seen(-dr, -dc)
    return out


def cost_at(costmap: LocalCostmap, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The cost of the cells holding the odom points (``x``, ``y`` arrays, m); 0 outside the window."""
    res = costmap.resolution_m
    rows, cols = costmap.cost.shape
    ix = np.floor((x - costmap.origin_x_m) / res).astype(np.intp)
    iy = np.floor((y - costmap.origin_y_m) / res).astype(np.intp)
    inside = (ix >= 0) & (ix < cols) & (iy >= 0) & (iy < rows)
    out = np.zeros(np.shape(x), np.uint8)
    out[inside] = costmap.cost[iy[inside], ix[inside]]
    return out


__all__ = ["LocalCostmapConfig", "RollingCostmap", "inflation_lut", "odom_points", "cost_at", "LUT_STEPS_PER_CELL",
           "COST_NARROW", "between_obstacles"]
