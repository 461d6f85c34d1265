"""The fleet's key space on Zenoh: a public contract (docs/fleet.md), every key built and read here.

``<name>`` is a robot's name: letters, digits, ``_`` and ``-`` (at most
:data:`NAME_MAX` characters), so that it is one chunk of a Zenoh key
expression and can never be a wildcard (``*``, ``**``), a separator (``/``)
or a verbatim chunk (``$*``). ``fleet`` is taken by the fleet's own keys.

* ``beastbt/<name>/alive``: the robot's liveliness token (gone when the robot is);
* ``beastbt/<name>/state``: its state, JSON, 5 times a second;
* ``beastbt/<name>/events``: each event of its runs, JSON, as it happens;
* ``beastbt/<name>/photo``: its runs' newest photo, a JPEG of at most 100 kB (the attachment: JSON ``{robot, name,
  time_s}``), as each is taken (:mod:`beastbt.fleet.photos`);
* ``beastbt/<name>/cmd/<control>``: a queryable per control (:data:`CONTROLS`), JSON in, JSON out;
* ``beastbt/<name>/mission``: a queryable that takes a mission (YAML, or a zip with its files);
* ``beastbt/fleet/estop``: a put that e-stops every robot that hears it;
* ``beastbt/fleet/station``: the station's liveliness token (what a supervised mission waits for);
* ``beastbt/fleet/sim/poses``: the simulated robots' true poses, put by the station (each simulator's other robots).
"""

from __future__ import annotations

import re
from typing import Optional

PREFIX = "beastbt"
"""The first chunk of every key of the fleet."""
FLEET = "fleet"
"""The chunk of the fleet's own keys (no robot may be called this)."""
ESTOP_ALL = f"{PREFIX}/{FLEET}/estop"
"""A put here e-stops every robot that hears it, whatever its state, mission or name."""
STATION_ALIVE = f"{PREFIX}/{FLEET}/station"
"""The station's liveliness token."""
SIM_POSES = f"{PREFIX}/{FLEET}/sim/poses"
"""The station puts the simulated robots' true poses here; each simulated robot adds the others to its world."""
ALL_ALIVE = f"{PREFIX}/*/alive"
"""Every robot's liveliness token."""
ALL_STATES = f"{PREFIX}/*/state"
"""Every robot's state."""
ALL_EVENTS = f"{PREFIX}/*/events"
"""Every robot's events."""
ALL_PHOTOS = f"{PREFIX}/*/photo"
"""Every robot's newest photo."""
CONTROLS = ("pause", "resume", "abort", "estop", "estop_reset", "answer", "teleop", "tuning", "tune", "tune_reset",
            "tune_save")
"""The controls a robot answers on ``beastbt/<name>/cmd/<control>`` (those of the operator console; live tuning's
``tuning`` lists the knobs, ``tune`` takes ``{name, value}``, ``tune_reset`` and ``tune_save``)."""
NAME_MAX = 64
"""The longest robot name (characters)."""
_NAME = re.compile(r"[A-Za-z0-9_-]+")


def name_problem(name: str) -> Optional[str]:
    """Why ``name`` cannot be a robot's name (with what a good one looks like), or None when it can."""
    if not isinstance(name, str) or not name:
        return "a robot's name must not be empty"
    if len(name) > NAME_MAX:
        return f"a robot's name has at most {NAME_MAX} characters, not {len(name)}"
    if not _NAME.fullmatch(name):
        return (f"a robot's name is letters, digits, '_' and '-' only (one chunk of a Zenoh key), not {name[:80]!r}: "
                f"e.g. beast-01")
    if name == FLEET:
        return f"'{FLEET}' is taken by the fleet's own keys (beastbt/fleet/...): pick another name"
    return None


def check_name(name: str) -> str:
    """``name`` when it is a valid robot name; ValueError saying why not otherwise."""
    problem = name_problem(name)
    if problem is not None:
        raise ValueError(problem)
    return name


def alive_key(name: str) -> str:
    """The robot's liveliness token."""
    return f"{PREFIX}/{check_name(name)}/alive"


def state_key(name: str) -> str:
    """Where the robot publishes its state."""
    return f"{PREFIX}/{check_name(name)}/state"


def events_key(name: str) -> str:
    """Where the robot publishes its events."""
    return f"{PREFIX}/{check_name(name)}/events"


def photo_key(name: str) -> str:
    """Where the robot puts its runs' newest photo (a JPEG)."""
    return f"{PREFIX}/{check_name(name)}/photo"


def mission_key(name: str) -> str:
    """The robot's mission queryable."""
    return f"{PREFIX}/{check_name(name)}/mission"


def cmd_key(name: str, control: str) -> str:
    """The robot's queryable for ``control`` (one of :data:`CONTROLS`)."""
    if control not in CONTROLS:
        raise ValueError(f"unknown control '{control}': the controls are {', '.join(CONTROLS)}")
    return f"{PREFIX}/{check_name(name)}/cmd/{control}"


def robot_of(key: str) -> Optional[str]:
    """The robot's name in one of its keys (``beastbt/<name>/...``), or None for any other key."""
    parts = str(key).split("/")
    if len(parts) < 3 or parts[0] != PREFIX or name_problem(parts[1]) is not None:
        return None
    return parts[1]


__all__ = ["PREFIX", "ESTOP_ALL", "STATION_ALIVE", "SIM_POSES",
           "ALL_ALIVE", "ALL_STATES", "ALL_EVENTS", "ALL_PHOTOS", "CONTROLS", "NAME_MAX",
           "name_problem", "check_name", "alive_key", "state_key", "events_key", "photo_key", "mission_key", "cmd_key", "robot_of"]
