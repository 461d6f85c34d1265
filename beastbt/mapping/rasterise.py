"""Draw line segments and circles into an :class:`~beastbt.mapping.occupancy_map.OccupancyMap`'s cells.

Used to make a map of what is known exactly (a simulated world's walls and
obstacles, moved into the map frame by the caller), for tests that compare a
built map with the truth, and to mark shapes in a map.
"""

from __future__ import annotations

import math
from typing import Iterable, Sequence

import numpy as np

from beastbt.mapping.occupancy_map import OCCUPIED, OccupancyMap


def segment_points(segments: Sequence[Sequence[float]], spacing_m: float) -> np.ndarray:
    """Points (N, 2) along each segment ``(x1, y1, x2, y2)`` (m), at most ``spacing_m`` apart, ends included."""
    chunks = []
    for x1, y1, x2, y2 in segments:
        n = max(1, int(math.ceil(math.hypot(x2 - x1, y2 - y1) / spacing_m)))
        t = np.linspace(0.0, 1.0, n + 1)
        chunks.append(np.column_stack((x1 + t * (x2 - x1), y1 + t * (y2 - y1))))
    return np.concatenate(chunks) if chunks else np.empty((0, 2))


def circle_points(circles: Iterable[Sequence[float]], spacing_m: float) -> np.ndarray:
    """Points (N, 2) around the outline of each circle ``(x, y, radius)`` (m), at most ``spacing_m`` apart."""
    chunks = []
    for x, y, r in circles:
        n = max(8, int(math.ceil(2 * math.pi * r / spacing_m)))
        a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
        chunks.append(np.column_stack((x + r * np.cos(a), y + r * np.sin(a))))
    return np.concatenate(chunks) if chunks else np.empty((0, 2))


def mark_points(grid: OccupancyMap, points: np.ndarray, value: int = OCCUPIED) -> OccupancyMap:
    """A copy of ``grid`` with the cells holding ``points`` (N, 2; map frame, m) set to ``value``; points off the
    map are left out."""
    data = grid.data.copy()
    if len(points):
        col, row = grid.to_cells(points[:, 0], points[:, 1])
        keep = grid.inside(col, row)
        data[row[keep], col[keep]] = value
    return grid.with_data(data)


def mark_outlines(grid: OccupancyMap, segments: Sequence[Sequence[float]] = (),
                  circles: Iterable[Sequence[float]] = (), value: int = OCCUPIED) -> OccupancyMap:
    """A copy of ``grid`` with every cell that a segment ``(x1, y1, x2, y2)`` or a circle's outline ``(x, y, r)``
    passes through (map frame, m) set to ``value``."""
    spacing = grid.resolution_m / 4.0
    points = np.concatenate((segment_points(segments, spacing), circle_points(circles, spacing)))
    return mark_points(grid, points, value)
