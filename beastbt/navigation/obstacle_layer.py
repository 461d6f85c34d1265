"""An obstacle layer with memory: LiDAR returns marked in a grid, cleared only when a later beam passes through them.

This is Nav2's obstacle layer (``marking`` and ``clearing`` on one
observation source) for the global costmap of ``go_to``, ``route`` and
``return_home``: unlike the local costmap, which is rebuilt from the last
``observation_persistence_s`` of scans, a cell once marked stays marked
until the LiDAR sees *through* it. A fence the robot drove past a minute ago
is still there when it plans the way round; a person who walked away is gone
as soon as a beam passes where they stood.

:class:`ObstacleLayer` is a boolean grid (row 0 the southernmost, ``origin``
the lower-left corner of cell (0, 0), metres in the grid's frame: ``odom`` on
GPS, ``map`` on a saved map). Each scan, seen from the LiDAR's pose in that
frame, does two things, clearing first and marking second (as Nav2 does, so
that what the scan hits stays marked):

* **clearing** (ray tracing): a marked cell within ``raytrace_max_range_m``
  of the LiDAR is cleared when the beam nearest its bearing went farther than
  the cell (its range more than a cell beyond the cell's centre), or, with
  ``clear_on_no_return``, returned nothing (nothing within the LiDAR's range:
  open space, Nav2's ``inf_is_valid``; on GPS a lone beam with no return
  between two that returned is a dropout, and clears nothing). Only marked cells can need clearing,
  so the layer projects those into the scan instead of walking every beam
  across the grid: the same cells are cleared as by walking each beam with
  Bresenham's line up to its end, at the cost of one ``searchsorted`` per
  marked cell in range, whatever the number of beams;
* **marking**: every return between ``obstacle_min_range_m`` and
  ``obstacle_max_range_m`` of the LiDAR marks its cell.

:meth:`ObstacleLayer.recentre` rolls the grid with the robot (a rolling
window, as Nav2's ``rolling_window: true``): cells that leave the window are
forgotten, cells that enter it are free. :meth:`ObstacleLayer.clear_around`
forgets the marks within a radius (the recovery ``clear the costmaps``).
``version`` counts the changes, so that a costmap built from the layer knows
when it must be built again. With ``fine``, the layer also keeps the marks on a
grid of cells :data:`FINE` times smaller (:attr:`ObstacleLayer.fine`, marked by
the same returns, cleared with the cells holding them, and each on its own by
the same rule in a cell that stays marked: a wall's end stays, a stray mark
beside it in a gap goes), so that a costmap of
0.1 m cells can tell a gap the robot fits through from one 8 cm narrower
(docs/navigation.md, Tight gaps). Nothing here reads a clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from beastbt.core.config import dataclass_from_dict
from beastbt.core.schema_defaults import schema_defaults


@dataclass(frozen=True)
@schema_defaults("parts/global_costmap.schema.json")
class GlobalCostmapConfig:
    """The profile's ``global_costmap:`` section: the obstacle layer with memory and, on GPS, its rolling window.
    Metres and seconds."""

    enabled: bool
    """Whether go_to keeps the global costmap and plans on it (false: the straight line and the local costmap)."""
    width_m: float
    """Side of the square rolling window in the odom frame on GPS missions (m); on a map the map's extent."""
    resolution_m: float
    """Side of a cell of the rolling window on GPS (m); on a map the map's own resolution is used."""
    obstacle_min_range_m: float
    """Returns nearer the LiDAR do not mark (m)."""
    obstacle_max_range_m: float
    """Returns farther than this do not mark (m)."""
    raytrace_max_range_m: float
    """Marked cells farther than this from the LiDAR are not cleared (m)."""
    clear_on_no_return: bool
    """A beam with no return clears the marked cells along it up to raytrace_max_range_m (Nav2's inf_is_valid)."""
    replan_period_s: float
    """A GPS go_to whose way is blocked plans again this often (s)."""
    recentre_m: float
    """The rolling window moves to centre on the robot once it is this far from the window's centre (m)."""

    def __post_init__(self) -> None:
        for name in ("width_m", "resolution_m", "obstacle_max_range_m", "raytrace_max_range_m", "replan_period_s",
                     "recentre_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"global_costmap: '{name}' must be > 0, got {getattr(self, name)}")
        if not self.obstacle_min_range_m >= 0.0:
            raise ValueError(f"global_costmap: 'obstacle_min_range_m' must be >= 0, got {self.obstacle_min_range_m}")
        if self.width_m / self.resolution_m > 2000:
            raise ValueError(f"global_costmap: width_m / resolution_m is {self.width_m / self.resolution_m:.0f} cells "
                             f"a side: at most 2000")
        if self.recentre_m > self.width_m / 4.0:
            raise ValueError(f"global_costmap: 'recentre_m' ({self.recentre_m:g} m) must be at most a quarter of "
                             f"width_m ({self.width_m / 4.0:g} m)")

    @classmethod
    def from_dict(cls, d: Any) -> "GlobalCostmapConfig":
        """Build from a profile's ``global_costmap:`` mapping; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "global_costmap")


FINE = 4
"""With ``fine``, a cell's side holds this many cells of the fine grid (2.5 cm for 0.1 m cells)."""

CONNECT_MAX_M = 1.0
"""Neighbouring returns (adjacent beams) at most this far apart mark the cells between them too (m)."""

GRAZING_COT = 1.0 / math.tan(math.radians(10.0))
"""A beam clears a marked cell only when it ends beyond it by a cell plus the cell's distance times the beam spacing
times this: a surface seen at more than 10 deg from the beam is not cleared by the beams that hit it."""


def wrap(a: np.ndarray) -> np.ndarray:
    """Angles (rad) into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class ObstacleLayer:
    """Marks with memory and ray-traced clearing on a ``rows`` x ``cols`` grid of ``resolution_m`` cells whose
    lower-left corner is at (``origin_x``, ``origin_y``) (m); see the module docstring."""

    def __init__(self, config: GlobalCostmapConfig, rows: int, cols: int, resolution_m: float, origin_x: float,
                 origin_y: float, fine: bool = False, dropouts_clear: bool = True) -> None:
        self.config = config
        self.resolution_m = resolution_m
        self.origin_x = origin_x
        self.origin_y = origin_y
        self.marked = np.zeros((rows, cols), bool)
        self.fine: Optional[np.ndarray] = np.zeros((FINE * rows, FINE * cols), bool) if fine else None
        """With ``fine``: the marks on a grid of cells FINE times smaller ((FINE rows, FINE cols), the same origin),
        each inside a marked cell; else None."""
        self.dropouts_clear = dropouts_clear
        """Whether a lone beam with no return between two that returned clears (with ``clear_on_no_return``), as
        open space; False on GPS (a dropout along a fence seen from its gap cleared metres of it). On a map, the
        dropouts are left to clear: in a room nearly every beam returns, and they clear marks placed a little off."""
        self.unmarkable: Optional[np.ndarray] = None
        """Cells a return never marks (on a map: the map's own walls and a band round them, so that a few cm of
        localisation error does not thicken the walls and narrow the doors); None: every cell."""
        self.version = 0
        """Incremented whenever a cell is marked or cleared, or the window moves."""
        self.cleared_total = 0
        """Cells cleared by ray tracing so far."""

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return self.marked.shape  # type: ignore[return-value]

    @property
    def centre(self) -> tuple[float, float]:
        """The window's centre (m)."""
        rows, cols = self.marked.shape
        return self.origin_x + cols * self.resolution_m / 2.0, self.origin_y + rows * self.resolution_m / 2.0

    def cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside) of points (m) in the grid's frame."""
        res = self.resolution_m
        col = np.floor((np.asarray(x) - self.origin_x) / res).astype(np.intp)
        row = np.floor((np.asarray(y) - self.origin_y) / res).astype(np.intp)
        rows, cols = self.marked.shape
        return row, col, (row >= 0) & (row < rows) & (col >= 0) & (col < cols)

    # -- a scan ------------------------------------------------------------------------------------------
    def update(self, lidar_pose: tuple[float, float, float], angles_rad: np.ndarray, ranges_m: np.ndarray) -> int:
        """Clear then mark with one scan: its beams' ``angles_rad`` (in the LiDAR's frame) and ``ranges_m`` (NaN:
        no return), seen from ``lidar_pose`` (x m, y m, yaw rad of the LiDAR in the grid's frame). The number of
        cells cleared."""
        if len(angles_rad) < 2:
            return 0
        # The beams by angle, once for both passes (a LiDAR's revolution may start anywhere).
        a, r, spacing = _by_angle(angles_rad, ranges_m)
        cleared = self._clear(lidar_pose, a, r, spacing)
        self._mark(lidar_pose, a, r, spacing)
        return cleared

    def seen_through(self, lidar_pose: tuple[float, float, float], angles_rad: np.ndarray, ranges_m: np.ndarray,
                     x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Which points (``x``, ``y``, m in the grid's frame) one scan (as :meth:`update` takes it) saw through: the
        beam toward each went a fine cell and the grazing margin past it, or returned nothing."""
        if len(angles_rad) < 2:
            return np.zeros(len(x), bool)
        a, r, spacing = _by_angle(angles_rad, ranges_m)
        return self._seen_through(lidar_pose, a, r, spacing, np.asarray(x, dtype=float), np.asarray(y, dtype=float),
                                  self.resolution_m / FINE)

    def _clear(self, pose: tuple[float, float, float], a: np.ndarray, r: np.ndarray, spacing: float) -> int:
        cfg, res = self.config, self.resolution_m
        lx, ly, lyaw = pose
        reach = cfg.raytrace_max_range_m
        # Only the marked cells in the box the beams can reach.
        r0, c0, _ = self.cells(np.array([lx - reach]), np.array([ly - reach]))
        r1, c1, _ = self.cells(np.array([lx + reach]), np.array([ly + reach]))
        rows, cols = self.marked.shape
        r0, r1 = max(0, int(r0[0])), min(rows, int(r1[0]) + 1)
        c0, c1 = max(0, int(c0[0])), min(cols, int(c1[0]) + 1)
        if r0 >= r1 or c0 >= c1:
            return 0
        rr, cc = np.nonzero(self.marked[r0:r1, c0:c1])
        if rr.size == 0:
            return 0
        rr += r0
        cc += c0
        clear = self._seen_through(pose, a, r, spacing, self.origin_x + (cc + 0.5) * res,
                                   self.origin_y + (rr + 0.5) * res, res)
        n = int(np.count_nonzero(clear))
        if n:
            self.marked[rr[clear], cc[clear]] = False
            self._clear_fine(rr[clear], cc[clear])
            self.version += 1
            self.cleared_total += n
        if self.fine is not None and n < rr.size:
            n += self._clear_fine_marks(pose, a, r, spacing, rr[~clear], cc[~clear])
        return n

    def _seen_through(self, pose: tuple[float, float, float], a: np.ndarray, r: np.ndarray, spacing: float,
                      x: np.ndarray, y: np.ndarray, size_m: float, open_only: bool = False) -> np.ndarray:
        """Which cells of side ``size_m`` centred at (``x``, ``y``) (m) the beams (angles ``a`` sorted, ranges
        ``r``, ``spacing`` rad apart) from the LiDAR at ``pose`` saw through: the beam nearest each cell's bearing
        passed through it and went past it by a cell and the grazing margin (not with ``open_only``), or returned
        nothing (with ``clear_on_no_return``; not a lone beam between two returns, a dropout)."""
        cfg = self.config
        lx, ly, lyaw = pose
        dx, dy = x - lx, y - ly
        dist = np.hypot(dx, dy)
        near = dist <= cfg.raytrace_max_range_m
        out = np.zeros(len(x), bool)
        if not near.any():
            return out
        dx, dy, dist = dx[near], dy[near], dist[near]
        bearing = wrap(np.arctan2(dy, dx) - lyaw)
        # The beam nearest each cell's bearing (the beams wrap round at +-pi).
        i = np.searchsorted(a, bearing) % len(a)
        j = (i - 1) % len(a)
        di = np.abs(wrap(a[i] - bearing))
        dj = np.abs(wrap(a[j] - bearing))
        k = np.where(di <= dj, i, j)
        off = np.minimum(di, dj)
        # A beam clears a cell it passes through: within half the cell's angular size of the cell's centre, or
        # within the spacing of the beams (a sparse scan still clears what lies between its beams' ends).
        through = off <= np.maximum(0.5 * size_m / np.maximum(dist, size_m), 0.6 * spacing)
        beam = r[k]
        # A lone beam with no return between two that returned is a dropout (the LD19 loses about 1 % of its
        # points), not open space: along a fence seen from beside it, it would clear metres of the fence's cells.
        n = len(a)
        lone = np.zeros(n, bool)
        if n > 2 and not self.dropouts_clear:
            lone = (~np.isfinite(r) & np.isfinite(np.roll(r, 1)) & np.isfinite(np.roll(r, -1))
                    & (np.abs(wrap(np.roll(a, 1) - a)) <= 2.0 * spacing)
                    & (np.abs(wrap(np.roll(a, -1) - a)) <= 2.0 * spacing))
        no_return = ~np.isfinite(beam) & ~lone[k]
        valid = np.isfinite(beam) & (beam >= cfg.obstacle_min_range_m)
        # Past the cell by a cell, and by more where the beams are far apart: a beam that grazes a wall hits it a
        # little farther along than the cell it passes (by dist * spacing / tan(angle)); it must not clear the wall.
        went_past = valid & (beam > dist + size_m + dist * spacing * GRAZING_COT) & (not open_only)
        if cfg.clear_on_no_return:
            went_past |= no_return
        out[near] = through & went_past
        return out

    def _clear_fine_marks(self, pose: tuple[float, float, float], a: np.ndarray, r: np.ndarray, spacing: float,
                          row: np.ndarray, col: np.ndarray) -> int:
        """Clear the fine marks of the cells (``row``, ``col``) that the beams saw through, each on its own, and the
        cells left with none; the number of cells cleared.

        A cell at a gap's edge holds the wall's end, which the beams hit, and it stays marked; but a mark placed a
        few cm into the gap (a scan placed with a heading a degree off, as the odometry drifts in a turn) must go
        once a beam passes through it into open space, or the gap measures narrower than it is, for as long as the
        cell is seen."""
        fine = self.fine
        assert fine is not None
        step = self.resolution_m / FINE
        boxes = fine.reshape(fine.shape[0] // FINE, FINE, fine.shape[1] // FINE, FINE)[row, :, col, :]
        k, fr, fc = np.nonzero(boxes)
        if k.size == 0:
            return 0
        frow, fcol = FINE * row[k] + fr, FINE * col[k] + fc
        # Only by beams into open space (no return): a beam that hit something beyond a fine cell may have met, on
        # the slant, the very wall the cell holds (a fence seen from its gap), and the fine cell says no more.
        clear = self._seen_through(pose, a, r, spacing, self.origin_x + (fcol + 0.5) * step,
                                   self.origin_y + (frow + 0.5) * step, step, open_only=True)
        if not clear.any():
            return 0
        fine[frow[clear], fcol[clear]] = False
        self.version += 1
        emptied = ~fine.reshape(fine.shape[0] // FINE, FINE, fine.shape[1] // FINE, FINE)[row, :, col, :].any(
            axis=(1, 2))
        n = int(np.count_nonzero(emptied))
        if n:
            self.marked[row[emptied], col[emptied]] = False
            self.cleared_total += n
        return n

    def _mark(self, pose: tuple[float, float, float], a: np.ndarray, r: np.ndarray, spacing: float) -> None:
        cfg = self.config
        ok = np.isfinite(r) & (r >= cfg.obstacle_min_range_m) & (r <= cfg.obstacle_max_range_m)
        if not ok.any():
            return
        lx, ly, lyaw = pose
        x = lx + np.where(ok, r, 0.0) * np.cos(a + lyaw)
        y = ly + np.where(ok, r, 0.0) * np.sin(a + lyaw)
        # Neighbouring returns less than CONNECT_MAX_M apart are one surface: the cells between them are marked too.
        # A wall seen at a grazing angle is hit only every r * spacing / sin(angle) (0.9 m at 7 m and 8 deg with
        # a 1 deg LiDAR), and a planner would take the holes between its hits for gaps.
        pair = ok[:-1] & ok[1:] & (np.diff(a) <= 2.0 * spacing)
        gap = np.hypot(np.diff(x), np.diff(y))
        pair &= gap <= CONNECT_MAX_M
        i = np.flatnonzero(pair)
        if i.size:
            t = np.linspace(0.0, 1.0, max(2, int(math.ceil(CONNECT_MAX_M / (0.5 * self.resolution_m)))))[None, 1:-1]
            x = np.concatenate((x[ok], (x[i, None] + t * (x[i + 1] - x[i])[:, None]).ravel()))
            y = np.concatenate((y[ok], (y[i, None] + t * (y[i + 1] - y[i])[:, None]).ravel()))
        else:
            x, y = x[ok], y[ok]
        row, col, inside = self.cells(x, y)
        row, col = row[inside], col[inside]
        if self.unmarkable is not None and row.size:
            keep = ~self.unmarkable[row, col]
            row, col = row[keep], col[keep]
            x, y = x[inside][keep], y[inside][keep]
        else:
            x, y = x[inside], y[inside]
        if row.size and not self.marked[row, col].all():
            self.marked[row, col] = True
            self.version += 1
        if self.fine is not None and row.size:
            frow, fcol = self._fine_cells(x, y, row, col)
            if not self.fine[frow, fcol].all():
                self.fine[frow, fcol] = True
                self.version += 1

    def _fine_cells(self, x: np.ndarray, y: np.ndarray, row: np.ndarray, col: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) on the fine grid of points (m) inside the cells (row, col) (kept inside them, whatever the
        rounding)."""
        step = self.resolution_m / FINE
        frow = np.clip(np.floor((y - self.origin_y) / step).astype(np.intp), FINE * row, FINE * row + FINE - 1)
        fcol = np.clip(np.floor((x - self.origin_x) / step).astype(np.intp), FINE * col, FINE * col + FINE - 1)
        return frow, fcol

    def _clear_fine(self, row: np.ndarray, col: np.ndarray) -> None:
        """Clear the fine cells of the cells (row, col)."""
        if self.fine is None:
            return
        for dr in range(FINE):
            for dc in range(FINE):
                self.fine[FINE * row + dr, FINE * col + dc] = False

    # -- the window ----------------------------------------------------------------------------------------
    def recentre(self, x: float, y: float) -> bool:
        """Move the window to centre on (x, y) (m) once that is ``recentre_m`` from its centre, by whole cells:
        marks that stay inside keep their place in the frame, the rest are forgotten. True when it moved."""
        cx, cy = self.centre
        if max(abs(x - cx), abs(y - cy)) < self.config.recentre_m:
            return False
        res = self.resolution_m
        rows, cols = self.marked.shape
        new_ox = math.floor(x / res - cols / 2) * res
        new_oy = math.floor(y / res - rows / 2) * res
        self.move_to(new_ox, new_oy)
        return True

    def move_to(self, origin_x: float, origin_y: float) -> None:
        """Put the window's lower-left corner at (origin_x, origin_y) (m, on the cell grid), keeping the marks."""
        res = self.resolution_m
        sc = int(round((origin_x - self.origin_x) / res))
        sr = int(round((origin_y - self.origin_y) / res))
        rows, cols = self.marked.shape
        self.marked = _shifted(self.marked, sr, sc)
        if self.fine is not None:
            self.fine = _shifted(self.fine, FINE * sr, FINE * sc)
        self.origin_x += sc * res
        self.origin_y += sr * res
        self.version += 1

    def clear_around(self, x: float, y: float, radius_m: float) -> int:
        """Forget the marks within ``radius_m`` of (x, y) (m); the number of cells cleared."""
        res = self.resolution_m
        rows, cols = self.marked.shape
        row, col, _ = self.cells(np.array([x]), np.array([y]))
        k = int(math.ceil(radius_m / res)) + 1
        r0, r1 = max(0, int(row[0]) - k), min(rows, int(row[0]) + k + 1)
        c0, c1 = max(0, int(col[0]) - k), min(cols, int(col[0]) + k + 1)
        if r0 >= r1 or c0 >= c1:
            return 0
        yy = self.origin_y + (np.arange(r0, r1) + 0.5) * res - y
        xx = self.origin_x + (np.arange(c0, c1) + 0.5) * res - x
        inside = (yy[:, None] ** 2 + xx[None, :] ** 2) <= radius_m ** 2
        box = self.marked[r0:r1, c0:c1]
        n = int(np.count_nonzero(box & inside))
        if n:
            box[inside] = False
            self.version += 1
            if self.fine is not None:
                self.fine[FINE * r0:FINE * r1, FINE * c0:FINE * c1] &= np.repeat(np.repeat(box, FINE, axis=0), FINE,
                                                                                  axis=1)
        return n

    def forget(self) -> int:
        """Forget every mark (Nav2's ClearEntireCostmap); the number of cells that were marked."""
        n = int(np.count_nonzero(self.marked))
        if n:
            self.marked[:] = False
            if self.fine is not None:
                self.fine[:] = False
            self.version += 1
        return n

    def mark_points(self, x: np.ndarray, y: np.ndarray) -> int:
        """Mark the cells holding points (m) (what stopped the robot, on a map); the number newly marked."""
        row, col, inside = self.cells(x, y)
        row, col = row[inside], col[inside]
        new = int(np.count_nonzero(~self.marked[row, col]))
        if new:
            self.marked[row, col] = True
            self.version += 1
        if self.fine is not None and row.size:
            x, y = np.asarray(x, dtype=float)[inside], np.asarray(y, dtype=float)[inside]
            frow, fcol = self._fine_cells(x, y, row, col)
            if not self.fine[frow, fcol].all():
                self.fine[frow, fcol] = True
                self.version += 1
        return new


def _by_angle(angles_rad: np.ndarray, ranges_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """A scan's beams sorted by angle: (angles rad, ranges m, the median spacing between beams, rad)."""
    order = np.argsort(angles_rad)
    a = angles_rad[order]
    return a, ranges_m[order], float(np.median(np.diff(a)))


def _shifted(grid: np.ndarray, sr: int, sc: int) -> np.ndarray:
    """``grid`` moved by ``sr`` rows and ``sc`` columns toward the origin (what leaves it is forgotten, what enters
    is False)."""
    rows, cols = grid.shape
    moved = np.zeros_like(grid)
    if abs(sr) < rows and abs(sc) < cols:
        src = grid[max(0, sr):rows + min(0, sr), max(0, sc):cols + min(0, sc)]
        moved[max(0, -sr):rows + min(0, -sr), max(0, -sc):cols + min(0, -sc)] = src
    return moved


__all__ = ["GlobalCostmapConfig", "ObstacleLayer", "FINE"]
