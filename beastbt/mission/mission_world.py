"""The world a mission names (``world:``), loaded with its problems shown at the mission's line too."""

from __future__ import annotations

from beastbt.core.errors import InvalidInput
from beastbt.sim.world import World, load_world


def load_mission_world(mission: "object") -> World:
    """Load ``mission.world`` (located, checked and capped by the mission's file policy when it was loaded:
    :mod:`beastbt.core.file_refs`); InvalidInput with the world file's problems and one at the mission's
    ``world:`` line, naming the world as the mission wrote it."""
    refused = getattr(mission, "world_refused", None)
    if refused is not None:  # not found, or not to be read here: it is never opened
        raise InvalidInput([refused])
    try:
        return load_world(str(mission.world))  # type: ignore[attr-defined]
    except InvalidInput as exc:
        doc = mission.doc  # type: ignore[attr-defined]
        written = doc.data.get("world") if isinstance(doc.data, dict) else None
        here = doc.problem(("world",), f"the world file {written or mission.world} has problems "  # type: ignore
                                       f"(listed with its own lines)",
                           "fix the world file, or point 'world:' at another")
        raise InvalidInput([here] + exc.problems) from None


__all__ = ["load_mission_world"]
