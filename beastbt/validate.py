"""``beastbt validate``: check files without running anything.

A file is checked as a mission, a robot profile, a world or a mission test according to its
first key (``mission:``, ``robot:``, ``world:``, ``test:``), and a file whose top level
is a list (of ``{at: ...}`` events) as a joystick script (``--joystick FILE``); anything else is
checked as a mission, whose errors then say what a mission needs. A
mission's world file is checked with it: its problems are reported in the
world file, and at the mission's ``world:`` line. Warnings (valid, but
probably not meant) come with the errors; ``--strict`` counts them as errors.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.core.yaml_source import load_yaml


FILE_KEYS = frozenset({"mission", "steps", "robot", "world"})
"""First keys of the files that are mappings: a top-level list holding them is not a joystick script."""


def validate_file(path: str, robot: Optional[str] = None) -> list[Problem]:
    """Every problem in the file at ``path``, errors and warnings (an empty list when it is clean).

    With ``robot`` (a profile's name or file), a mission is also checked for
    that robot, as ``beastbt run --robot`` would: its top speed, its devices
    (battery, joystick, LiDAR, odometry) against what the mission uses.
    Without it, its speeds are checked against the default robot's top speed
    (``sim``, what ``beastbt run`` uses).
    """
    from beastbt.mission.model import load_mission
    from beastbt.robot.profile import load_profile
    from beastbt.sim.world import load_world
    try:
        from beastbt.sim.joystick_limits import list_file_problem
        too_big = list_file_problem(path)  # a list (a joystick script?) beyond its bounds: refused before it is read
        if too_big is not None:
            return [too_big]
        doc = load_yaml(path, require_mapping=False)
        if isinstance(doc.data, list) and not any(isinstance(e, dict) and set(e) & FILE_KEYS for e in doc.data):
            # Only a joystick script is a list of events at its top level; a list of a mission's keys is a
            # mission written with a '-' too many, and its error says so.
            from beastbt.devices.joystick import JoystickMapping
            from beastbt.parts.sim_joystick import load_joystick_script
            load_joystick_script(path, JoystickMapping())
            return []
        first = next(iter(doc.data), None) if isinstance(doc.data, dict) else None
        if first == "robot":
            load_profile(path)
        elif first == "test":  # a mission test file (docs/testing.md), checked with its mission
            from beastbt.testing.spec import load_test
            load_test(path)
        elif first == "world":
            load_world(path)
        else:
            mission = load_mission(path)
            found = mission_with_world(mission)
            if not any(p.severity == "error" for p in found):
                found = found + (for_robot(mission, robot) if robot is not None else
                                 speeds_for_default_robot(mission))
            return found
    except InvalidInput as exc:
        return exc.problems
    except Exception as exc:  # noqa: BLE001 - a slip of ours must not end in a traceback for a user's file
        return [internal_error(path, exc)]
    return []


def for_robot(mission, robot: str) -> list[Problem]:  # type: ignore[no-untyped-def]
    """The warnings of running ``mission`` on ``robot`` (a profile's name or file); its problems if it is invalid."""
    from beastbt.assembly import run_warnings
    from beastbt.robot.hardware import DeviceUnavailable
    from beastbt.robot.part import REAL
    from beastbt.robot.profile import load_profile
    try:
        profile = load_profile(robot)
        said = {(p.file, p.position, p.message) for p in mission.warnings}
        return [p for p in run_warnings(mission, profile, None, REAL) if (p.file, p.position, p.message) not in said]
    except InvalidInput as exc:
        return exc.problems
    except DeviceUnavailable as exc:
        return [Problem(robot, Position(), str(exc))]


DEFAULT_ROBOT = "sim"
"""The robot ``beastbt run`` uses without ``--robot``: its top speed is checked without ``--robot`` too."""


def speeds_for_default_robot(mission) -> list[Problem]:  # type: ignore[no-untyped-def]
    """The speeds above the top speed of the robot ``beastbt run`` uses by default (``sim``), as warnings.

    Only the profile is read (no part, no device module): ``beastbt validate`` stays quick.
    """
    from beastbt.mission.warnings import speed_warnings
    from beastbt.robot.profile import load_profile
    try:
        profile = load_profile(DEFAULT_ROBOT)
    except InvalidInput:
        return []  # the bundled profile is checked by its own tests; a mission is not blamed for it
    said = {(p.file, p.position, p.message) for p in mission.warnings}
    return [p for p in speed_warnings(mission, profile.max_speed_mps, profile.name)
            if (p.file, p.position, p.message) not in said]


def internal_error(path: str, exc: BaseException) -> Problem:
    """A problem saying that checking ``path`` failed inside beastbt (a bug), in place of a traceback."""
    import traceback
    frame = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" at {Path(frame.filename).name}:{frame.lineno}" if frame is not None else ""
    return Problem(path, Position(1, 1),
                   f"internal error while checking this file: {type(exc).__name__}: {str(exc)[:200]}{where}",
                   "this is a bug in beastbt, not necessarily in the file: please report it with the file attached")


def mission_with_world(mission) -> list[Problem]:  # type: ignore[no-untyped-def]
    """The mission's warnings, with its world file checked and its places checked against the world's datum."""
    from beastbt.mission.mission_world import load_mission_world
    from beastbt.mission.warnings import by_position, mission_warnings, world_warnings
    if mission.world is None:
        return list(mission.warnings)
    try:
        world = load_mission_world(mission)
    except InvalidInput as exc:
        return exc.problems
    frame = world.frame
    return by_position(mission_warnings(mission, (frame.lat0_deg, frame.lon0_deg)) + world_warnings(mission, world))
