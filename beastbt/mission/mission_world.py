"""The world a mission names (``world:``), loaded with its problems shown at the mission's line too."""

from __future__ import annotations

from beastbt.core.errors import InvalidInput
from beastbt.sim.world import World, load_world


def load_mission_world(mission: "object") -> World:
    """Load ``mission.world``; InvalidInput with the world file's problems and one at the mission's ``world:`` line."""
    try:
        return load_world(str(mission.world))  # type: ignore[attr-defined]
    except InvalidInput as exc:
        here = mission.doc.problem(("world",), f"the world file {mission.world} has problems "  # type: ignore[attr-defined]
                                               f"(listed with its own lines)",
                                   "fix the world file, or point 'world:' at another")
        raise InvalidInput([here] + exc.problems) from None


__all__ = ["load_mission_world"]
