"""Maps for the map tests: the office world's truth map, made from its walls and furniture.

:func:`office_truth_map` draws ``worlds/office.yaml`` into an occupancy grid in
the map frame (the robot's start pose: x forward, y left, as a map built from
there would have it): walls and the outlines of furniture occupied, boxes and
columns filled, free inside the outer walls, unknown outside. ``maps/office.yaml``
(with ``office.pgm``) is this map saved; ``python tests/map_support.py`` writes
it again (a test checks the two agree).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.mapping.occupancy_map import FREE, OCCUPIED, UNKNOWN, OccupancyMap, empty_map, save_map  # noqa: E402
from beastbt.mapping.rasterise import mark_outlines  # noqa: E402
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle  # noqa: E402
from beastbt.sim.world import World, load_world  # noqa: E402

OFFICE_WORLD = REPO / "worlds" / "office.yaml"
OFFICE_MAP = REPO / "maps" / "office.yaml"
MARGIN_M = 0.5
"""Unknown border round the outer walls (m)."""


def to_map_frame(world: World, x: float, y: float) -> tuple[float, float]:
    """A world point (m) in the map frame: relative to the robot's start pose."""
    c, s = math.cos(world.start_yaw), math.sin(world.start_yaw)
    dx, dy = x - world.start_x, y - world.start_y
    return c * dx + s * dy, -s * dx + c * dy


def truth_map(world: World, resolution_m: float = 0.05) -> OccupancyMap:
    """The world's walls and fixed obstacles as a map in the map frame (only for a world whose start yaw is a
    multiple of 90 deg, so the outer walls stay axis-aligned)."""
    ends = np.array([to_map_frame(world, w.x1, w.y1) for w in world.walls]
                    + [to_map_frame(world, w.x2, w.y2) for w in world.walls])
    lo, hi = ends.min(axis=0), ends.max(axis=0)
    # the origin on a multiple of the resolution, so that cell edges fall on round coordinates
    ox = math.floor((lo[0] - MARGIN_M) / resolution_m) * resolution_m
    oy = math.floor((lo[1] - MARGIN_M) / resolution_m) * resolution_m
    grid = empty_map(hi[0] + MARGIN_M - ox, hi[1] + MARGIN_M - oy, resolution_m, ox, oy, fill=UNKNOWN)
    data = grid.data.copy()
    (c0, c1), (r0, r1) = grid.to_cells([lo[0], hi[0]], [lo[1], hi[1]])
    data[r0:r1 + 1, c0:c1 + 1] = FREE
    for o in world.obstacles:
        if isinstance(o, BoxObstacle):
            corners = np.array([to_map_frame(world, *p) for p in o.corners()])
            col, row = grid.to_cells(corners[:, 0], corners[:, 1])
            cv2.fillPoly(data, [np.column_stack((col, row)).astype(np.int32)], OCCUPIED)
        elif isinstance(o, CylinderObstacle):
            cx, cy = to_map_frame(world, o.x, o.y)
            col, row = grid.to_cells(cx, cy)
            cv2.circle(data, (int(col), int(row)), int(round(o.radius_m / resolution_m)), OCCUPIED, -1)
    grid = grid.with_data(data)
    segments = [(*to_map_frame(world, w.x1, w.y1), *to_map_frame(world, w.x2, w.y2)) for w in world.walls]
    return mark_outlines(grid, segments)


def office_truth_map(resolution_m: float = 0.05) -> OccupancyMap:
    """The office world's truth map (see the module's docstring)."""
    return truth_map(load_world(OFFICE_WORLD), resolution_m)


def office_to_map(x: float, y: float) -> tuple[float, float]:
    """An office world point (m) in the office map's frame."""
    return to_map_frame(load_world(OFFICE_WORLD), x, y)


if __name__ == "__main__":
    yaml_path, image_path = save_map(office_truth_map(), OFFICE_MAP)
    print(f"wrote {yaml_path} and {image_path}")
