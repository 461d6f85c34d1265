"""``beastbt validate``: check files without running anything.

A file is checked as a mission, a robot profile or a world according to its
first key (``mission:``, ``robot:``, ``world:``); anything else is checked as a
mission, whose errors then say what a mission needs.
"""

from __future__ import annotations

from beastbt.core.errors import InvalidInput, Problem
from beastbt.core.yaml_source import load_yaml


def validate_file(path: str) -> list[Problem]:
    """Every problem in the file at ``path`` (an empty list when it is valid)."""
    from beastbt.mission.model import load_mission
    from beastbt.robot.profile import load_profile
    from beastbt.sim.world import load_world
    try:
        doc = load_yaml(path)
        first = next(iter(doc.data), None) if isinstance(doc.data, dict) else None
        if first == "robot":
            load_profile(path)
        elif first == "world":
            load_world(path)
        else:
            load_mission(path)
    except InvalidInput as exc:
        return exc.problems
    return []
