"""Simulated worlds: where the world is on Earth, where the robot starts, walls, obstacles and sensor models.

A world is a YAML file checked against ``schemas/world.schema.json``. The
default world (when neither the mission nor the command line names one) is an
empty plain at the world schema's default datum (the bundled worlds' spot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional, Union

from beastbt.core.unit_fields import read_unit_values
from beastbt.estimation.geodesy import LocalFrame
from beastbt.core.errors import InvalidInput
from beastbt.core.schema_check import schema_problems
from beastbt.core.schema_defaults import schema_default
from beastbt.core.yaml_source import SourceDoc, load_yaml
from beastbt.sim.dynamics import Wall
from beastbt.sim.obstacles import Obstacle, obstacle_of


@dataclass
class World:
    """A checked world. Positions in metres in the world's local ENU frame, yaw in radians CCW from east."""

    name: str
    file: Optional[str]
    doc: Optional[SourceDoc]
    frame: LocalFrame
    start_x: float
    start_y: float
    start_yaw: float
    walls: list[Wall]
    obstacles: list[Obstacle]
    """Boxes, cylinders and walking persons (``beastbt.sim.obstacles``), in the world's order."""
    battery_start_v: float
    battery_drain_v_per_s: float
    data: dict

    def section(self, name: str) -> Optional[dict]:
        """A model section (``gps``, ``imu``, ``floor``, ``camera``), or None."""
        value = self.data.get(name)
        return dict(value) if isinstance(value, dict) else None


def _world_default(section: str, name: str) -> Any:
    """The world schema's default for ``name`` (in ``section``; "" for a top-level key)."""
    return schema_default("world.schema.json#/properties" + (f"/{section}" if section else ""), name)


def empty_world() -> World:
    """An empty plain where the world schema's defaults put it (its default datum, the robot at the origin facing
    east)."""
    return world_of({"world": "empty"})


def load_world(path: Union[str, Path]) -> World:
    """Load and check a world file; raise :class:`InvalidInput` with every problem found."""
    doc = load_yaml(path)
    problems = read_unit_values(doc) or schema_problems(doc, "world.schema.json", "world") or _tag_problems(doc)
    if problems:
        raise InvalidInput(problems)
    return world_of(doc.data, doc)


def _tag_problems(doc: SourceDoc) -> list:
    """The world's ``tags:`` whose id their family does not have (checked by the schema otherwise)."""
    from beastbt.vision.tag_families import tag_id_problem
    out = []
    for i, t in enumerate(doc.data.get("tags") or []):
        why = tag_id_problem(str(t.get("family", "apriltag_36h11")), int(t["id"]))
        if why is not None:
            out.append(doc.problem(("tags", i, "id"), f"tags: {why}",
                                   "use an id the family has, or a family with more ids (apriltag_36h11 has 587)"))
    return out


def world_of(d: dict, doc: Optional[SourceDoc] = None) -> World:
    """The :class:`World` of a checked world mapping; what it leaves out takes the world schema's defaults."""
    datum = d.get("datum") or _world_default("", "datum")
    start = d.get("start") or {}
    battery = d.get("battery") or {}
    return World(
        name=d["world"], file=doc.file if doc is not None else None, doc=doc,
        frame=LocalFrame(float(datum["lat"]), float(datum["lon"]), float(datum.get("alt_m", _world_default("datum", "alt_m")))),
        start_x=float(start.get("x", _world_default("start", "x"))),
        start_y=float(start.get("y", _world_default("start", "y"))),
        start_yaw=math.radians(float(start.get("yaw_deg", _world_default("start", "yaw_deg")))),
        walls=[Wall(*map(float, w)) for w in d.get("walls") or []],
        obstacles=[obstacle_of(o) for o in d.get("obstacles") or []],
        battery_start_v=float(battery.get("start_v", _world_default("battery", "start_v"))),
        battery_drain_v_per_s=float(battery.get("drain_v_per_s", _world_default("battery", "drain_v_per_s"))),
        data=d,
    )
