"""``beastbt station --simulate N [--world WORLD]``: N simulated robots on the station's fleet, each at its own start.

Each robot is a ``beastbt serve --sim`` process of its own (``sim-1`` ... ``sim-N``), as a real robot
would be, connected to the station's router. They share the world (``--world``, else an empty plain),
each with its start moved sideways (to the robot's left, :data:`SPACING_M` apart), so that none starts
inside another. Each simulator adds the others as moving obstacles, from the poses the station relays
(:mod:`beastbt.fleet.shared_world`).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from typing import Optional, Sequence

import yaml

SPACING_M = 1.0
"""How far apart the simulated robots start (m), side by side."""


def world_for(index: int, world: Optional[str], folder: Path) -> Path:
    """The world file of robot ``index`` (0-based): ``world`` (or an empty plain) with its start moved sideways."""
    data = yaml.safe_load(Path(world).read_text(encoding="utf-8")) if world else {"world": "plain"}
    start = dict(data.get("start") or {})
    x, y = float(start.get("x", 0.0)), float(start.get("y", 0.0))
    yaw = math.radians(float(start.get("yaw_deg", 0.0)))
    offset = SPACING_M * index
    start.update(x=round(x - math.sin(yaw) * offset, 3), y=round(y + math.cos(yaw) * offset, 3))
    data["start"] = start
    path = folder / f"sim-{index + 1}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def start_robots(count: int, world: Optional[str], endpoint: str, speed: str, folder: Path,
                 runs_dir: str, link: Sequence[str] = ()) -> list[subprocess.Popen]:
    """Start ``count`` ``beastbt serve --sim`` robots on ``endpoint``, joining with the options ``link``
    (``--fleet-config FILE``: the station's keys, or ``--insecure-loopback``); their processes."""
    procs = []
    for i in range(count):
        path = world_for(i, world, folder)
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "beastbt", "serve", "--sim", "--name", f"sim-{i + 1}", "--fleet", endpoint,
             "--world", str(path), "--speed", speed, "--runs-dir", runs_dir, *link],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL))
    return procs


__all__ = ["start_robots", "world_for", "SPACING_M"]
