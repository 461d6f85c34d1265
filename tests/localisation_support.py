"""Test support for localisation on a map: the office world's truth map, in the map frame, saved for missions."""

from __future__ import annotations

import math
from pathlib import Path

from beastbt.estimation.map_localiser import compose, invert
from beastbt.mapping.occupancy_map import FREE, OccupancyMap, empty_map, save_map
from beastbt.mapping.rasterise import mark_outlines
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle
from beastbt.sim.world import World, load_world
from conftest import REPO

OFFICE = REPO / "worlds" / "office.yaml"

TOUR = """\
  - drive: {distance: 1.5 m}
  - turn: {angle: 180 deg}
  - drive: {distance: 3 m}
  - turn: {angle: 90 deg}
  - drive: {distance: 1 m}
  - turn: {angle: 90 deg}
  - drive: {distance: 1.5 m}
"""
"""A tour of the office world's office and corridor (the steps of a mission): drives, a U-turn and two turns."""


def truth_map(world: World, map_start: tuple[float, float, float] = (0.0, 0.0, 0.0),
              resolution_m: float = 0.05, margin_m: float = 0.5) -> OccupancyMap:
    """The world's walls and obstacles drawn into a map whose frame puts the world's start at ``map_start``
    (as a map built from there would), every other cell free."""
    map_from_world = compose(map_start, invert((world.start_x, world.start_y, world.start_yaw)))

    def moved(x: float, y: float) -> tuple[float, float]:
        p = compose(map_from_world, (x, y, 0.0))
        return p[0], p[1]

    segments = []
    for w in world.walls:
        segments.append((*moved(w.x1, w.y1), *moved(w.x2, w.y2)))
    circles = []
    for o in world.obstacles:
        if isinstance(o, BoxObstacle):
            corners = [moved(x, y) for x, y in o.corners()]
            segments += [(*corners[i], *corners[(i + 1) % 4]) for i in range(4)]
        elif isinstance(o, CylinderObstacle):
            circles.append((*moved(o.x, o.y), o.radius_m))
    xs = [v for s in segments for v in (s[0], s[2])]
    ys = [v for s in segments for v in (s[1], s[3])]
    # Whole metres of the world fall on cell centres, so that a wall is drawn centred in its cells and the map
    # has no half-cell bias (a wall on a cell boundary would be drawn on one side of it).
    x0 = (math.floor((min(xs) - margin_m) / resolution_m) - 0.5) * resolution_m
    y0 = (math.floor((min(ys) - margin_m) / resolution_m) - 0.5) * resolution_m
    grid = empty_map(max(xs) + margin_m - x0, max(ys) + margin_m - y0, resolution_m, x0, y0, fill=FREE)
    return mark_outlines(grid, segments, circles)


def office_map_file(folder: Path, map_start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Path:
    """The office world's truth map saved in map_server format in ``folder``; the YAML's path."""
    yaml_path, _ = save_map(truth_map(load_world(OFFICE), map_start), folder / "office_map.yaml")
    return yaml_path


def mission_text(name: str, steps: str, extra: str = "", world: Path = OFFICE) -> str:
    """A mission on the office world and its map (``office_map.yaml`` beside it)."""
    return (f"mission: {name}\nworld: {world}\nmap: office_map.yaml\n{extra}steps:\n{steps}")


__all__ = ["truth_map", "office_map_file", "mission_text", "OFFICE"]
