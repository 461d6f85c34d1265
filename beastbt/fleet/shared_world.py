"""Simulated robots in one world: each publishes its true pose, the station relays them, each adds the others.

A simulated robot on the fleet puts its true pose in its state (the ``sim``
field: ``{world, x, y, yaw, radius_m}``, the world's name, metres and radians in
the world's frame, its footprint's radius). Robots do not hear each other (they
are peers of the station's router that do not gossip, and the access control
lets a robot read no other robot's keys), so the station relays: every
:data:`RELAY_PERIOD_S` it puts on ``beastbt/fleet/sim/poses`` the poses of the
simulated robots it has heard within :data:`~beastbt.sim.obstacles.OTHERS_MAX_AGE_S`:
``{"robots": [{name, world, x, y, yaw, radius_m, age_s}]}`` (``age_s``: how long
ago the station heard it, s, so that no clock is shared). Each simulated robot
takes those of its own world but itself into its
:class:`~beastbt.sim.obstacles.OtherRobots`, which its simulator reads between
ticks: its LiDAR sees them and its robot can touch them. A pose that is not
heard again within a second is dropped (a robot that went, or a station that did).
"""

from __future__ import annotations

import json
import math
from typing import Any, Optional

from beastbt.fleet import keys
from beastbt.sim.obstacles import OTHERS_MAX_AGE_S, OtherRobot

RELAY_PERIOD_S = 0.175
"""How often the station puts the simulated robots' poses (wall s): the robots' own state rate."""
RADIUS_MAX_M = 5.0
"""The largest footprint radius taken from the fleet (m): anything larger is not a small ground robot's."""
WORLD_NAME_MAX = 200
"""The longest world name taken from the fleet (characters)."""


def sim_field(sim: Any) -> dict:
    """The ``sim`` field of a simulated robot's state: its world's name, true pose (m, rad) and footprint radius (m)."""
    t = sim.truth
    return {"world": str(sim.world.name), "x": round(t.x, 3), "y": round(t.y, 3), "yaw": round(t.yaw, 4),
            "radius_m": float(sim.drive.model.footprint_radius_m)}


def start_field(profile: Any, world_file: str) -> dict:
    """The ``sim`` field of ``profile``'s simulated robot standing at the start of ``world_file`` (before its first
    run); InvalidInput when the world is not a valid one."""
    from beastbt.sim.robot import build_simulator
    from beastbt.sim.world import load_world
    return sim_field(build_simulator(profile, load_world(world_file), 0))


def check_sim_field(value: Any) -> Optional[dict]:
    """A ``sim`` field as the fleet takes it (finite numbers, a radius in (0, :data:`RADIUS_MAX_M`]), or None."""
    if not isinstance(value, dict):
        return None
    world = value.get("world")
    if not isinstance(world, str) or not world or len(world) > WORLD_NAME_MAX:
        return None
    try:
        x, y, yaw, radius = (float(value[k]) for k in ("x", "y", "yaw", "radius_m"))
    except (KeyError, TypeError, ValueError):
        return None
    if not all(math.isfinite(v) for v in (x, y, yaw, radius)) or not 0.0 < radius <= RADIUS_MAX_M:
        return None
    return {"world": world, "x": x, "y": y, "yaw": yaw, "radius_m": radius}


def poses_payload(robots: list[tuple[str, dict, float]]) -> str:
    """What the station puts on ``beastbt/fleet/sim/poses``: each ``(name, sim field, age_s)``."""
    return json.dumps({"robots": [{"name": name, **sim, "age_s": round(age_s, 3)} for name, sim, age_s in robots]},
                      separators=(",", ":"))


def others_of(raw: bytes, own_name: str, world: Optional[str]) -> list[tuple[OtherRobot, float]]:
    """The other robots of ``world`` in a relayed payload (not ``own_name``, nor anything malformed or older than
    :data:`~beastbt.sim.obstacles.OTHERS_MAX_AGE_S`), each with its age (s)."""
    if world is None:
        return []
    try:
        value = json.loads(bytes(raw))
    except (ValueError, UnicodeDecodeError, RecursionError):
        return []
    items = value.get("robots") if isinstance(value, dict) else None
    out = []
    for item in items if isinstance(items, list) else []:
        if not isinstance(item, dict):
            continue
        name, sim, age = item.get("name"), check_sim_field(item), item.get("age_s", 0.0)
        if (sim is None or not isinstance(name, str) or keys.name_problem(name) is not None or name == own_name
                or sim["world"] != world or not isinstance(age, (int, float)) or not 0.0 <= age <= OTHERS_MAX_AGE_S):
            continue
        out.append((OtherRobot(name, sim["x"], sim["y"], sim["yaw"], sim["radius_m"]), float(age)))
    return out


__all__ = ["sim_field", "start_field", "check_sim_field", "poses_payload", "others_of", "RELAY_PERIOD_S",
           "RADIUS_MAX_M"]
