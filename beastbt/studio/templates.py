"""New missions from templates: patrol, GPS route, line, teleop; each one validates as it comes.

A template is a short mission with comments that say what to change. One that
runs in a simulated world names it (``world:``): the folder's own world of that
name by its path relative to where the new file will be saved, else the world
shipped with beastbt by its bare name (``world: corridor``), which resolves
wherever the file goes (docs/mission-language.md).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple, Optional

from beastbt.studio.files import StudioFolder


class Template(NamedTuple):
    """One template: its title and description for the page, its world file (if any) and its text."""

    title: str
    description: str
    world: Optional[str]
    text: str
    """The mission, with ``{world}`` where the world's path goes and ``{name}`` the mission's name."""


TEMPLATES: dict[str, Template] = {
    "patrol": Template(
        "Patrol", "Drive back and forth along a corridor, looking both ways at each end.", "corridor.yaml",
        """\
# A patrol: drive along, look around, turn back; three times.
# Change the distance to the length of your corridor.
mission: {name}
description: Patrol the corridor and look both ways at each end.
world: {world}   # the simulated world used by "Try it"
limits: {{speed: 0.3 m/s}}

tasks:
  look_around:
    - look: {{pan: -45 deg}}
    - wait: 2 s
    - look: {{pan: 45 deg}}
    - wait: 2 s
    - look: {{pan: 0 deg}}

steps:
  - repeat:
      times: 3
      steps:
        - drive: {{distance: 3 m, speed: 0.15 m/s}}
        - do: look_around
        - turn: {{angle: 180 deg}}
""" ),
    "gps_route": Template(
        "GPS route", "Visit places in order by GPS: add places on the map, then make a route through them.",
        "campus.yaml",
        """\
# A route by GPS. On the map: "Add place" and click to add places,
# then "Make route" and click them in order: the route is added to the steps.
mission: {name}
description: Visit the places in order by GPS.
world: {world}   # the simulated world used by "Try it"
limits: {{speed: 0.5 m/s}}

steps:
  - say: "Starting the route"

# Stop and wait when the GPS fix is lost; carry on when it is back.
failsafes:
  gps_lost: {{after: 3 s, then: hold}}
""" ),
    "line": Template(
        "Follow a line", "Follow the line seen by the camera to the next junction, then turn onto the new branch.",
        "line_track.yaml",
        """\
# Follow a line on the floor with the camera.
mission: {name}
description: Follow the line to the junction, take a picture and turn.
world: {world}   # the simulated world used by "Try it": it has a line
limits: {{speed: 0.2 m/s}}

steps:
  - follow_line: {{speed: 0.12 m/s, until: intersection}}
  - stop
  - snapshot: {{name: junction}}
  - turn: {{angle: 90 deg}}
  - follow_line: {{speed: 0.12 m/s, until: {{distance: 2 m}}}}
""" ),
    "teleop": Template(
        "Drive by hand", "The robot is the operator's: drive it with the joystick until the enable button is "
                         "released.", None,
        """\
# Drive by hand: the robot follows the joystick while the enable (deadman)
# button is held, and the mission ends when it is released.
mission: {name}
description: Drive the robot by hand with the joystick.
limits: {{speed: 0.5 m/s}}

steps:
  - say: "Hold the enable button and drive"
  - teleop: {{until: released}}
""" ),
}
"""The templates by name (``POST /api/templates/<name>``)."""


def world_path(folder: StudioFolder, mission_path: Optional[str], world_file: str) -> str:
    """The ``world:`` value that reaches ``world_file`` from a mission saved at ``mission_path``: the folder's own
    world by its relative path, else the shipped world's bare name (never a path into beastbt's install)."""
    here = (folder.root / mission_path).parent if mission_path else folder.root
    mine = [f["path"] for f in folder.list() if f["kind"] == "world" and Path(f["path"]).name == world_file]
    if not mine:
        return Path(world_file).stem  # 'world: corridor': looked up beside the file, then among the shipped worlds
    target = folder.root / sorted(mine, key=lambda p: (p.count("/"), p))[0]
    try:
        return Path(os.path.relpath(target, here)).as_posix()
    except ValueError:  # another drive (Windows): no relative path
        return target.as_posix()


def mission_name(path: Optional[str], template: str) -> str:
    """The ``mission:`` name for a new file: its file name made a name (letters, digits, _ and -)."""
    stem = Path(path).stem if path else f"my_{template}"
    name = "".join(c if c.isalnum() or c in "_-" else "_" for c in stem).strip("_-") or f"my_{template}"
    return name if name[0].isalpha() else f"m_{name}"


def template_text(folder: StudioFolder, name: str, body: dict) -> str:
    """The text of a new mission from template ``name`` (``body``: ``{path?}``, where it will be saved)."""
    template = TEMPLATES[name]
    path = body.get("path") if isinstance(body.get("path"), str) else None
    if path:
        folder.resolve(path, must_exist=False)  # refused outside the folder, as the save would be
    world = world_path(folder, path, template.world) if template.world else ""
    return template.text.format(name=mission_name(path, name), world=world)


__all__ = ["TEMPLATES", "Template", "template_text"]
