"""Simulated worlds: where the world is on Earth, where the robot starts, walls and sensor models.

A world is a YAML file checked against ``schemas/world.schema.json``. The
default world (when neither the mission nor the command line names one) is an
empty plain at latitude 0, longitude 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

from beastbt.estimation.geodesy import LocalFrame
from beastbt.core.errors import InvalidInput
from beastbt.core.schema_check import schema_problems
from beastbt.core.yaml_source import SourceDoc, load_yaml
from beastbt.sim.dynamics import Wall


@dataclass
class World:
    """A checked world. Positions in metres in the world's local ENU frame, yaw in radians CCW from east."""

    name: str
    file: Optional[str] = None
    doc: Optional[SourceDoc] = None
    frame: LocalFrame = field(default_factory=lambda: LocalFrame(0.0, 0.0, 0.0))
    start_x: float = 0.0
    start_y: float = 0.0
    start_yaw: float = 0.0
    walls: list[Wall] = field(default_factory=list)
    battery_start_v: float = 12.3
    battery_drain_v_per_s: float = 0.0002
    data: dict = field(default_factory=dict)

    def section(self, name: str) -> Optional[dict]:
        """A model section (``gps``, ``imu``, ``floor``, ``camera``), or None."""
        value = self.data.get(name)
        return dict(value) if isinstance(value, dict) else None


def empty_world() -> World:
    """An empty plain at 0 deg N, 0 deg E, the robot at the origin facing east."""
    return World(name="empty")


def load_world(path: Union[str, Path]) -> World:
    """Load and check a world file; raise :class:`InvalidInput` with every problem found."""
    doc = load_yaml(path)
    problems = schema_problems(doc, "world.schema.json", "world")
    if problems:
        raise InvalidInput(problems)
    d = doc.data
    datum = d.get("datum") or {"lat": 0.0, "lon": 0.0}
    start = d.get("start") or {}
    battery = d.get("battery") or {}
    return World(
        name=d["world"], file=doc.file, doc=doc,
        frame=LocalFrame(float(datum["lat"]), float(datum["lon"]), float(datum.get("alt_m", 0.0))),
        start_x=float(start.get("x", 0.0)), start_y=float(start.get("y", 0.0)),
        start_yaw=math.radians(float(start.get("yaw_deg", 0.0))),
        walls=[Wall(*map(float, w)) for w in d.get("walls") or []],
        battery_start_v=float(battery.get("start_v", 12.3)),
        battery_drain_v_per_s=float(battery.get("drain_v_per_s", 0.0002)),
        data=d,
    )
