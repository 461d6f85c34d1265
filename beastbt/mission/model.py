"""The mission model: a validated mission with every value in SI units and its source position.

:func:`load_mission` reads a mission file (or text), checks it against
``schemas/mission.schema.json``, then checks what a schema cannot: values that
must be positive, references to tasks and places, tasks that call themselves.
Every problem found is collected and raised together as
:class:`~beastbt.core.errors.InvalidInput`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Collection, Optional, Union

from beastbt.mission.fences import Fence
from beastbt.mission.geo_files import resolve_geo_files
from beastbt.mission.task_params import expand_task_parameters
from beastbt.core.errors import InvalidInput, Problem, did_you_mean
from beastbt.core.file_refs import CLI, MAP, WORLD, FileRefs, RefusedFile
from beastbt.core.schema_check import load_schema, schema_problems
from beastbt.core.schema_defaults import schema_default
from beastbt.mission import steps as st
from beastbt.mission.external_steps import ExternalStep, load_external_steps, step_keywords_in, with_external_steps
from beastbt.core.units import parse_count, parse_quantity
from beastbt.core.values import Value
from beastbt.core.yaml_source import MAX_NESTING, PathKey, SourceDoc, load_yaml

HOME = "home"
"""The reserved place name for where the mission started (its first good GPS fix)."""

STEP_KEYWORDS = (
    "drive", "turn", "wait", "stop", "go_to", "route", "return_home", "follow_line", "look", "servo",
    "snapshot", "say", "teleop", "repeat", "do", "first_of", "retry", "timeout", "parallel", "if", "while",
    "wait_until", "until", "abort_if", "ask", "photo", "alert", "dock", "undock", "track", "ros2_goals",
)


def mission_default(pointer: str, name: str) -> Any:
    """The default the mission schema states for property ``name`` at JSON ``pointer`` (``/properties``)."""
    return schema_default(f"mission.schema.json#{pointer}", name)


@dataclass(eq=False, repr=False)  # frozen, compared and printed by core.values.Value
class Place(Value):
    """A named place: a GPS place (``lat``, ``lon``: WGS84 degrees) or a place on the mission's map (``x``, ``y``:
    metres in the map frame, ``yaw`` rad or None), and an arrival tolerance in metres."""

    name: str
    lat: Optional[float]
    lon: Optional[float]
    tolerance_m: Optional[float] = None
    x: Optional[float] = None
    y: Optional[float] = None
    yaw: Optional[float] = None

    @property
    def on_map(self) -> bool:
        """Whether the place is in the map frame (x, y) rather than GPS (lat, lon)."""
        return self.x is not None


@dataclass(eq=False, repr=False)  # frozen, compared and printed by core.values.Value
class RawStep(Value):
    """One step as written, for the loader's own checks: its keyword, its raw value, where it sits."""

    kind: str
    value: Any
    path: PathKey


@dataclass(eq=False, repr=False)  # frozen, compared and printed by core.values.Value
class Failsafe(Value):
    """A failsafe: ``kind`` (gps_lost, battery_low, geofence, keepout, localization_lost), its SI parameters and its
    action."""

    kind: str
    then: str
    params: dict
    path: PathKey


@dataclass
class Mission:
    """A mission that passed every check, ready to compile.

    Durations in seconds, speeds in m/s, angles in radians, rates in hertz.
    """

    name: str
    file: str
    doc: SourceDoc
    description: str = ""
    world: Optional[Path] = None
    rate_hz: float = field(default_factory=lambda: parse_quantity(mission_default("/properties", "rate"), "frequency"))
    speed_limit_mps: Optional[float] = None
    turn_rate_limit_rps: Optional[float] = None
    accel_limit_mps2: Optional[float] = None
    places: dict[str, Place] = field(default_factory=dict)
    fences: dict[str, Fence] = field(default_factory=dict)
    """Named polygons to keep in or out of (``fences:``)."""
    tasks: dict[str, tuple[st.Step, ...]] = field(default_factory=dict)
    task_variants: dict[tuple[str, tuple], tuple[st.Step, ...]] = field(default_factory=dict)
    """(task, arguments of a ``do: {task, ...}``) -> that task's steps with those values."""
    """Each task's steps, by name (``do: name`` runs them)."""
    steps: tuple[st.Step, ...] = ()
    on_failure: str = field(default_factory=lambda: mission_default("/properties", "on_failure"))
    teleop_override: bool = field(default_factory=lambda: mission_default("/properties", "teleop"))
    teleop_on_release: str = field(
        default_factory=lambda: mission_default("/properties/teleop/anyOf/1/properties", "on_release"))
    failsafes: list[Failsafe] = field(default_factory=list)
    load_warnings: list[Problem] = field(default_factory=list)
    """Warnings found while reading it (what a route or places file carries that beastbt ignores)."""
    warnings: list[Problem] = field(default_factory=list)
    """What is valid but probably not meant (:mod:`beastbt.mission.warnings`): it runs, unless ``--strict``."""
    external_steps: dict[str, ExternalStep] = field(default_factory=dict)
    """Steps of installed packages the mission uses (``beastbt.steps`` entry points), by keyword."""
    map_file: Optional[Path] = None
    """The saved map to localise on (``map:``), resolved against the mission's folder."""
    refs: FileRefs = CLI
    world_refused: Optional[Problem] = None
    """Why ``world:`` cannot be read (at its line), or None: said when the world is loaded, so that a run given
    another world (``--world``) is not stopped by it; the refused file is never opened."""
    """Where the files it names may be read from (:mod:`beastbt.core.file_refs`): its world's ``map:`` too."""
    map_grid: Optional[Any] = None
    """That map, read (a :class:`beastbt.mapping.occupancy_map.OccupancyMap`), or None without ``map:``."""
    map_start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The start pose on the map (x m, y m, yaw rad; ``start:``): by default the map frame's origin."""
    map_start_place: Optional[str] = None
    """The place ``start:`` named, if it named one (resolved by whoever knows map-frame places)."""
    initial_uncertainty_xy_m: float = field(default_factory=lambda: parse_quantity(mission_default(
        "/properties/initial_uncertainty/properties", "xy"), "distance"))
    """Standard deviation of the start position on the map, each axis (m)."""
    initial_uncertainty_yaw_rad: float = field(default_factory=lambda: parse_quantity(mission_default(
        "/properties/initial_uncertainty/properties", "yaw"), "angle"))
    """Standard deviation of the start heading on the map (rad)."""


def step_of(value: Any, path: PathKey, extra: Collection[str] = ()) -> RawStep:
    """Name the step written at ``path`` (a bare word like ``stop`` or a one-keyword mapping).

    ``extra``: step keywords of installed packages that the mission uses.
    """
    if isinstance(value, str):
        return RawStep(value, None, path)
    for key in value:
        if key in STEP_KEYWORDS or key in extra:
            return RawStep(key, value[key], path)
    raise ValueError(f"not a step: {value!r}")


def steps_of(values: list, path: PathKey, extra: Collection[str] = ()) -> list[RawStep]:
    """The steps of a list at ``path`` (``extra``: step keywords of installed packages)."""
    return [step_of(v, path + (i,), extra) for i, v in enumerate(values)]


MAX_INLINED_VALUES = 50_000
"""Most values (steps, their keys and settings) a mission's tree may have once every ``do:`` is replaced by its task:
about 10,000 steps, far beyond any mission written by hand, compiled in well under a second."""

MAX_ACCEL_MPS2 = 50.0
"""Largest acceleration limit a mission may write, m/s2 (about five times what gravity gives)."""


def _accel(value: Union[str, float]) -> float:
    if isinstance(value, (int, float)):
        return float(value)
    return float(value.strip().split()[0].replace("m/s2", ""))


class _SemanticChecker:
    """Checks the rules a schema cannot express, collecting positioned problems."""

    POSITIVE = {"speed": "speed", "rate": "turn_rate", "tolerance": "distance", "within": "distance",
                "radius": "distance", "after": "duration", "time": "duration", "for": "duration",
                "stuck_after": "duration", "gps_timeout": "duration", "lost_after": "duration",
                "blocked_after": "duration"}

    def __init__(self, doc: SourceDoc) -> None:
        self.doc = doc
        self.data = doc.data
        self.problems: list[Problem] = []
        self.places = set((self.data.get("places") or {}).keys()) | {HOME}
        self.tasks = self.data.get("tasks") or {}

    def error(self, path: PathKey, message: str, hint: Optional[str] = None, key: bool = False) -> None:
        self.problems.append(self.doc.problem(path, message, hint, key=key))

    def run(self) -> list[Problem]:
        d = self.data
        if "rate" in d:
            hz = parse_quantity(d["rate"], "frequency")
            if not 1.0 <= hz <= 100.0:
                self.error(("rate",), f"rate {hz:g} Hz is out of range: the tree is ticked at 1 to 100 Hz", "20 Hz is usual")
        for key, kind in (("speed", "speed"), ("turn_rate", "turn_rate")):
            if key in (d.get("limits") or {}):
                self.positive(("limits", key), kind)
        if "acceleration" in (d.get("limits") or {}):
            accel = _accel(d["limits"]["acceleration"])
            if accel <= 0:
                self.error(("limits", "acceleration"), "acceleration limit must be greater than zero")
            elif not accel <= MAX_ACCEL_MPS2:  # also NaN and inf ('1e400 m/s2')
                self.error(("limits", "acceleration"), f"'acceleration': expected an acceleration of at most "
                           f"{MAX_ACCEL_MPS2:g} m/s2, got {d['limits']['acceleration']!r}",
                           "a small robot accelerates at about 0.5 m/s2")
        for name, task in self.tasks.items():
            if isinstance(task, dict):
                self.walk_steps(task.get("steps") or [], ("tasks", name, "steps"))
            else:
                self.walk_steps(task, ("tasks", name))
        self.walk_steps(d.get("steps") or [], ("steps",))
        if not self.check_recursion():
            self.check_inlined_size()
        for kind, spec in (d.get("failsafes") or {}).items():
            path = ("failsafes", kind)
            for k in spec:
                if k in self.POSITIVE:
                    self.positive(path + (k,), self.POSITIVE[k])
            if kind == "geofence" and "center" in spec:
                self.place_ref(path + ("center",), spec["center"])
            if kind in ("geofence", "keepout") and "fence" in spec:
                self.fence_ref(path + ("fence",), spec["fence"])
            if "margin" in spec:
                self.positive(path + ("margin",), "distance", allow_zero=True)
        map_places = self.check_place_frames()
        for name, fence in (d.get("fences") or {}).items():
            for i, corner in enumerate(fence.get("polygon") or []):
                if isinstance(corner, str):
                    self.place_ref(("fences", name, "polygon", i), corner)
                    if corner in map_places:
                        self.error(("fences", name, "polygon", i), f"fence corner '{corner}' is a place on the map "
                                   "(x, y): a fence's corners are GPS places", "give the corners as {lat, lon}")
            if kind == "battery_low":
                self.positive(path + ("below",), "voltage")
        return self.problems

    def run_guarded(self) -> list[Problem]:
        """Like :meth:`run`, but tolerant of a document the schema rejected (checks what it can)."""
        if not isinstance(self.data, dict):
            return []
        if not isinstance(self.data.get("places") or {}, dict) or not isinstance(self.tasks, dict):
            self.places, self.tasks = {HOME}, {}
        try:
            return self.run()
        except (KeyError, TypeError, ValueError, AttributeError, IndexError):
            return self.problems

    def positive(self, path: PathKey, kind: str, allow_zero: bool = False) -> None:
        value = self.get(path)
        try:
            si = parse_quantity(value, kind)
        except ValueError:
            return  # a malformed value is the schema's to report

        if si < 0 or (si == 0 and not allow_zero):
            word = "zero or negative" if not allow_zero else "negative"
            self.error(path, f"{path[-1]} must be greater than zero, got {value!r} ({word})",
                       f"write a positive {kind.replace('_', ' ')} such as "
                       + {"speed": "'0.2 m/s'", "turn_rate": "'45 deg/s'", "distance": "'2 m'", "duration": "'2 s'",
                          "voltage": "'11 V'"}.get(kind, "1"))

    def get(self, path: PathKey) -> Any:
        node = self.data
        for part in path:
            node = node[part]
        return node

    def check_place_frames(self) -> set[str]:
        """One mission, one frame: GPS places (lat, lon) or places on the map (x, y), and these only with ``map:``.
        The names of the places on the map."""
        places = self.data.get("places") or {}
        if not isinstance(places, dict):
            return set()
        on_map = [n for n, p in places.items() if isinstance(p, dict) and "x" in p]
        gps = [n for n, p in places.items() if isinstance(p, dict) and "lat" in p]
        if on_map and gps:
            first_map, first_gps = on_map[0], gps[0]
            later = first_map if list(places).index(first_map) > list(places).index(first_gps) else first_gps
            kinds = {first_map: "a place on the map (x, y)", first_gps: "a GPS place (lat, lon)"}
            other = first_gps if later == first_map else first_map
            self.error(("places", later), f"'{later}' is {kinds[later]} but '{other}' is {kinds[other]}: one "
                       "mission's places are all in one frame", "indoors on a map write x and y; outdoors with GPS "
                       "write lat and lon", key=True)
        elif on_map and "map" not in self.data:
            self.error(("places", on_map[0]), f"'{on_map[0]}' is a place on a map (x, y), but the mission has no "
                       "'map:'", "add map: ../maps/NAME.yaml (a map_server YAML) at the top of the mission",
                       key=True)
        center = ((self.data.get("failsafes") or {}).get("geofence") or {})
        if isinstance(center, dict) and center.get("center") in on_map:
            self.error(("failsafes", "geofence", "center"), f"'{center['center']}' is a place on the map: a "
                       "geofence's centre is a GPS place", "give the fence's centre as a GPS place")
        return set(on_map)

    def place_ref(self, path: PathKey, name: str) -> None:
        from beastbt.mission.geo_files import UNREADABLE_ROUTE
        if name not in self.places and name != UNREADABLE_ROUTE:
            known = sorted(self.places - {HOME})
            self.error(path, f"unknown place '{name}'{did_you_mean(name, self.places)}",
                       f"places are defined under 'places:' ({', '.join(known) or 'none yet'}); 'home' is where the mission started")

    def walk_steps(self, steps: Any, path: PathKey) -> None:
        if not isinstance(steps, list):
            return
        for i, raw in enumerate(steps):
            try:
                self.check_step(step_of(raw, path + (i,)))
            except (KeyError, TypeError, ValueError, AttributeError, IndexError):
                # The schema has already reported what is malformed here; these checks
                # only add what it cannot see, so a step it rejected is skipped.
                continue

    def check_step(self, s: RawStep) -> None:
        p = s.path + (s.kind,)
        v = s.value
        if s.kind == "drive":
            if "speed" in v:
                self.positive(p + ("speed",), "speed")
            if "distance" in v and parse_quantity(v["distance"], "distance") == 0:
                self.error(p + ("distance",), "drive distance is zero", "write how far to drive, e.g. '3 m' (negative drives backwards)")
            if "time" in v:
                self.positive(p + ("time",), "duration")
            if "stuck_after" in v:
                self.positive(p + ("stuck_after",), "duration")
        elif s.kind == "turn":
            if "rate" in v:
                self.positive(p + ("rate",), "turn_rate")
            if "heading" in v:
                h = math.degrees(parse_quantity(v["heading"], "angle"))
                if not 0 <= h <= 360:
                    self.error(p + ("heading",), f"heading {h:g} deg is out of range: a compass heading is 0 to 360 deg",
                               "0 deg is north, 90 deg east")
        elif s.kind == "wait":
            self.positive(p, "duration", allow_zero=True)
        elif s.kind in ("go_to", "route", "return_home"):
            if isinstance(v, str):
                self.place_ref(p, v)
            elif isinstance(v, dict):
                for k in ("speed", "tolerance", "gps_timeout", "stuck_after", "blocked_after"):
                    if k in v:
                        self.positive(p + (k,), self.POSITIVE[k])
                if s.kind == "go_to":
                    if "place" in v:
                        self.place_ref(p + ("place",), v["place"])
                        if "lat" in v or "lon" in v:
                            self.error(p, "go_to takes either a place or lat/lon, not both")
                    elif not ("lat" in v and "lon" in v):
                        self.error(p, "go_to needs a place name, or both 'lat' and 'lon'",
                                   "write 'go_to: gate' or 'go_to: {lat: 40.4168, lon: -3.7038}'")
                for j, name in enumerate(v.get("places", [])):
                    self.place_ref(p + ("places", j), name)
                if s.kind == "route" and "at_each" in v:
                    self.walk_steps(v["at_each"], p + ("at_each",))
        elif s.kind == "follow_line":
            for k in ("speed", "lost_after"):
                if k in v:
                    self.positive(p + (k,), self.POSITIVE[k])
            until = v.get("until")
            if isinstance(until, dict):
                k = next(iter(until))
                self.positive(p + ("until", k), "distance" if k == "distance" else "duration")
        elif s.kind in ("look", "servo") and isinstance(v, dict) and "settle" in v:
            self.positive(p + ("settle",), "duration", allow_zero=True)
        elif s.kind == "teleop" and "for" in v:
            self.positive(p + ("for",), "duration")
        elif s.kind == "do":
            if isinstance(v, dict):
                p, v = p + ("task",), v.get("task")
            if v not in self.tasks:
                self.error(p, f"unknown task '{v}'{did_you_mean(str(v), self.tasks)}",
                           f"tasks are defined under 'tasks:' ({', '.join(sorted(self.tasks)) or 'none yet'})")
        elif s.kind in ("repeat", "retry"):
            self.walk_steps(v["steps"], p + ("steps",))
        elif s.kind == "timeout":
            self.positive(p + ("after",), "duration")
            self.walk_steps(v["steps"], p + ("steps",))
        elif s.kind == "parallel":
            self.walk_steps(v["steps"], p + ("steps",))
        elif s.kind == "first_of":
            for j, alt in enumerate(v):
                self.walk_steps(alt, p + (j,))
        elif s.kind == "if":
            self.check_condition(v, p)
            raw = self.get(s.path)
            self.walk_steps(raw["then"], s.path + ("then",))
            if "else" in raw:
                self.walk_steps(raw["else"], s.path + ("else",))
        elif s.kind == "while":
            self.check_condition(v, p)
            self.walk_steps(self.get(s.path)["steps"], s.path + ("steps",))
        elif s.kind == "ask":
            raw = self.get(s.path)
            if "timeout" in v:
                self.positive(p + ("timeout",), "duration")
            for branch in ("then", "else"):
                if branch in raw:
                    self.walk_steps(raw[branch], s.path + (branch,))
        elif s.kind in ("until", "abort_if"):
            self.check_condition(v, p)
            self.walk_steps(self.get(s.path)["steps"], s.path + ("steps",))
        elif s.kind == "wait_until":
            self.check_condition(v, p)
            if "timeout" in self.get(s.path):
                self.positive(s.path + ("timeout",), "duration")
        elif s.kind == "track" and isinstance(v, dict):
            from beastbt.mission.vision_steps import check_sees
            for where, message, hint in check_sees({"colour": v.get("colour")}):
                self.error(p + where, message, hint)
            if "for" in v:
                self.positive(p + ("for",), "duration")
        elif s.kind in ("dock", "undock") and isinstance(v, dict):
            from beastbt.mission.vision_steps import check_tag
            for where, message, hint in check_tag(v):
                self.error(p + where, message, hint)
            for k in ("distance", "size", "speed"):
                if k in v:
                    self.positive(p + (k,), self.POSITIVE.get(k, "distance"))
        elif s.kind == "ros2_goals" and isinstance(v, dict):
            for k in ("for", "tolerance", "speed"):
                if k in v:
                    self.positive(p + (k,), self.POSITIVE[k])
            if "until" in v:
                self.check_condition(v["until"], p + ("until",))

    def fence_ref(self, path: PathKey, name: Any) -> None:
        fences = self.data.get("fences") or {}
        if name not in fences:
            self.error(path, f"unknown fence '{name}'{did_you_mean(str(name), list(fences))}",
                       f"fences are defined under 'fences:' ({', '.join(sorted(fences)) or 'none yet'})")

    def check_condition(self, c: Any, path: PathKey) -> None:
        if isinstance(c, dict):
            for word in ("inside", "outside"):
                if word in c:
                    self.fence_ref(path + (word,), c[word])
            if "near" in c:
                self.place_ref(path + ("near",), c["near"])
                if "within" in c:
                    self.positive(path + ("within",), "distance")
            if "battery_below" in c:
                self.positive(path + ("battery_below",), "voltage")
            if "distance_travelled" in c:
                self.positive(path + ("distance_travelled",), "distance")
            if "time_in_block" in c:
                self.positive(path + ("time_in_block",), "duration")
            if "obstacle_within" in c:
                self.positive(path + ("obstacle_within",), "distance")
                self.check_sector(c.get("sector_deg"), path + ("sector_deg",))
            if "sees" in c:
                from beastbt.mission.vision_steps import check_sees
                for where, message, hint in check_sees(c["sees"]):
                    self.error(path + ("sees",) + where, message, hint)
            if "not" in c:
                self.check_condition(c["not"], path + ("not",))
            for key in ("all", "any"):
                for j, sub in enumerate(c.get(key, [])):
                    self.check_condition(sub, path + (key, j))

    def check_sector(self, sector: Any, path: PathKey) -> None:
        """An ``obstacle_within`` sector [from, to] that is not empty (from == to)."""
        if not isinstance(sector, list) or len(sector) != 2:
            return  # absent, or the schema's to report
        try:
            start, end = sector_angle(sector[0]), sector_angle(sector[1])
        except (ValueError, TypeError):
            return  # a malformed angle is the schema's to report
        if abs(start - end) < 1e-12:
            self.error(path, f"'sector_deg' [{sector[0]}, {sector[1]}] is empty: it starts and ends at the same angle",
                       "write [from, to], counterclockwise from 'from' to 'to' (0 ahead, positive to the left), "
                       "e.g. [-30, 30] for the 60 degrees ahead; leave sector_deg out to look all around")

    def task_calls(self, steps: list, path: PathKey) -> list[tuple[str, PathKey]]:
        """Every (task, position) that a step list calls with ``do``, at any depth."""
        out: list[tuple[str, PathKey]] = []

        def visit(node: Any, p: PathKey) -> None:
            if isinstance(node, dict):
                for k, val in node.items():
                    if k == "do" and isinstance(val, str):
                        out.append((val, p + ("do",)))
                    elif k == "do" and isinstance(val, dict) and isinstance(val.get("task"), str):
                        out.append((val["task"], p + ("do", "task")))
                    else:
                        visit(val, p + (k,))
            elif isinstance(node, list):
                for j, item in enumerate(node):
                    visit(item, p + (j,))

        visit(steps, path)
        return out

    def check_inlined_size(self) -> None:
        """Refuse a mission whose tree, with every ``do:`` replaced by its task (as the compiler builds it), would be
        too deep for Python (tasks calling tasks a thousand deep) or too big: more than :data:`MAX_INLINED_VALUES`
        values (tasks that call tasks ten times, six deep, are 10^6 steps). Called once there is no recursion."""
        def body(name: str) -> Any:
            task = self.tasks.get(name)
            return task.get("steps") if isinstance(task, dict) else task

        def callee(key: Any, val: Any) -> Optional[str]:
            if key == "do" and isinstance(val, str):
                return val
            task = val.get("task") if key == "do" and isinstance(val, dict) else None
            return task if isinstance(task, str) else None

        depth: dict[str, int] = {}
        size: dict[str, int] = {}

        def measure(node: Any) -> tuple[int, int]:
            """(levels of lists and mappings, values) of ``node`` with its calls inlined; recursion bounded by the
            file's own nesting (MAX_NESTING), the tasks' by the tables above."""
            if isinstance(node, list):
                parts = [measure(item) for item in node]
                return 1 + max((d for d, _ in parts), default=0), min(MAX_INLINED_VALUES + 1, sum(n for _, n in parts))
            if not isinstance(node, dict):
                return 0, 1
            deepest, total = 0, 1
            for key, val in node.items():
                name = callee(key, val)
                d, n = (depth.get(name, 0), size.get(name, 0)) if name is not None else measure(val)
                deepest, total = max(deepest, d), min(MAX_INLINED_VALUES + 1, total + n)
            return 1 + deepest, total

        # Each task after the tasks it calls (no recursion here, checked before), without Python's recursion.
        calls = {name: [c for c, _ in self.task_calls(body(name), ())] for name in self.tasks}
        done: set[str] = set()
        for start in self.tasks:
            stack = [(start, False)]
            while stack:
                name, ready = stack.pop()
                if name in done or name not in self.tasks:
                    continue
                if ready:
                    depth[name], size[name] = measure(body(name))
                    done.add(name)
                else:
                    stack.append((name, True))
                    stack.extend((c, False) for c in calls[name] if c not in done)
        steps = self.data.get("steps")
        total = 0
        for i, step in enumerate(steps if isinstance(steps, list) else []):
            d, n = measure(step)
            total += n
            if d + 2 > MAX_NESTING or total > MAX_INLINED_VALUES:
                # At the call that copies in the most (the deepest, for a depth).
                called = self.task_calls(step, ("steps", i))
                key = (lambda c: depth.get(c[0], 0)) if d + 2 > MAX_NESTING else (lambda c: size.get(c[0], 0))
                where = max(called, key=key)[1] if called else ("steps", i)
                if d + 2 > MAX_NESTING:
                    self.error(where, f"with its tasks copied in wherever 'do:' runs them, this step nests more than "
                                      f"{MAX_NESTING} levels of lists and mappings (tasks calling tasks too deep)",
                               "call tasks from fewer levels of other tasks: write the steps of a short task out "
                               "where it is called")
                else:
                    self.error(where, f"with its tasks copied in wherever 'do:' runs them, this mission would have "
                                      f"more than {MAX_INLINED_VALUES:,} values in its tree (a task bomb?)",
                               "each 'do:' copies the task into the tree: to run steps many times use "
                               "'repeat: {times: N}', not tasks that call tasks many times over")
                return

    def check_recursion(self) -> bool:
        calls = {name: self.task_calls(steps.get("steps") or [] if isinstance(steps, dict) else steps, ("tasks", name))
                 for name, steps in self.tasks.items()}
        reported: set[str] = set()
        for start in self.tasks:
            stack = [(start, [start])]
            seen: set[str] = set()
            while stack:
                task, chain = stack.pop()
                for callee, pos in calls.get(task, []):
                    if callee == start and start not in reported:
                        reported.add(start)
                        cycle = " -> ".join(chain + [callee])
                        self.error(pos, f"task '{start}' calls itself ({cycle})",
                                   "a task may not run itself, directly or through other tasks; use 'repeat' to run steps again")
                    elif callee in calls and callee not in seen:
                        seen.add(callee)
                        stack.append((callee, chain + [callee]))
        return bool(reported)


# -- from what the author wrote to typed steps -------------------------------------------------------------

class _StepReader:
    """Turns the checked YAML of a mission's steps into the typed steps of :mod:`beastbt.mission.steps`."""

    def __init__(self, doc: SourceDoc, external: Collection[str]) -> None:
        self.doc = doc
        self.external = external

    def steps(self, values: list, path: PathKey) -> tuple[st.Step, ...]:
        return tuple(self.step(v, path + (i,)) for i, v in enumerate(values))

    def step(self, raw: Any, path: PathKey) -> st.Step:
        s = step_of(raw, path, self.external)
        v, at = s.value, self.doc.position(path)
        where = {"at": at, "path": path}
        q = parse_quantity

        def opt(key: str, kind: str, mapping: Any = None) -> Optional[float]:
            m = v if mapping is None else mapping
            return q(m[key], kind) if isinstance(m, dict) and key in m else None

        def nav(mapping: Any) -> dict:
            return {"tolerance_m": opt("tolerance", "distance", mapping), "speed_mps": opt("speed", "speed", mapping),
                    "gps_timeout_s": opt("gps_timeout", "duration", mapping),
                    "stuck_after_s": opt("stuck_after", "duration", mapping),
                    "blocked_after_s": opt("blocked_after", "duration", mapping),
                    "recovery_tries": recovery_tries(mapping)}

        def recovery_tries(mapping: Any) -> Optional[int]:
            # recovery: none | {tries: N}; absent: the robot's default
            r = mapping.get("recovery") if isinstance(mapping, dict) else None
            if r is None:
                return None
            return 0 if r == "none" else int(r["tries"])

        k = s.kind
        if k in self.external:
            return st.PluginStep(keyword=k, value=v, **where)
        if k == "drive":
            if "distance" in v:
                return st.DriveDistance(distance_m=q(v["distance"], "distance"), speed_mps=opt("speed", "speed"),
                                        stuck_after_s=opt("stuck_after", "duration"), **where)
            return st.DriveTime(duration_s=q(v["time"], "duration"), speed_mps=opt("speed", "speed"), **where)
        if k == "turn":
            common = {"rate_rps": opt("rate", "turn_rate"), "stuck_after_s": opt("stuck_after", "duration")}
            if "angle" in v:
                return st.TurnBy(angle_rad=q(v["angle"], "angle"), **common, **where)
            return st.TurnToHeading(heading_rad=q(v["heading"], "angle"), **common, **where)
        if k == "wait":
            return st.Wait(duration_s=q(v, "duration"), **where)
        if k == "stop":
            return st.Stop(**where)
        if k == "go_to":
            if isinstance(v, str):
                return st.GoToPlace(place=v, **where)
            if "place" in v:
                return st.GoToPlace(place=v["place"], **nav(v), **where)
            return st.GoToPoint(lat_deg=float(v["lat"]), lon_deg=float(v["lon"]), **nav(v), **where)
        if k == "route":
            loops = v.get("loops", mission_default("/$defs/step/anyOf/6/properties/route/properties", "loops"))
            return st.Route(places=tuple(v["places"]), loops=parse_count(loops), resume=v.get("resume", "current"),
                            at_each=self.steps(v.get("at_each") or [], path + ("route", "at_each")),
                            stop_on_failure=bool(v.get("stop_on_failure", True)), **nav(v), **where)
        if k == "return_home":
            along = v.get("along", "straight") if isinstance(v, dict) else "straight"
            return st.ReturnHome(along=along, **nav(v), **where)
        if k == "follow_line":
            until, amount = v["until"], None
            if isinstance(until, dict):
                until = next(iter(v["until"]))
                amount = q(v["until"][until], "distance" if until == "distance" else "duration")
            return st.FollowLine(until=until, amount=amount, speed_mps=opt("speed", "speed"),
                                 lost_after_s=opt("lost_after", "duration"), **where)
        if k == "look":
            return st.Look(pan_rad=opt("pan", "angle"), tilt_rad=opt("tilt", "angle"), settle_s=opt("settle", "duration"),
                           **where)
        if k == "servo":
            if "name" in v:
                return st.ServoAngle(name=v["name"], angle_rad=q(v["angle"], "angle"), settle_s=opt("settle", "duration"),
                                     **where)
            return st.ServoPulse(channel=int(v["channel"]), pulse_s=q(v["pulse"], "pulse"),
                                 settle_s=opt("settle", "duration"), **where)
        if k == "snapshot":
            return st.Snapshot(name=v["name"], **where)
        if k == "say":
            return st.Say(text=str(v), **where)
        if k == "teleop":
            return st.Teleop(duration_s=opt("for", "duration"), **where)
        if k in ("repeat", "retry"):
            cls = st.Repeat if k == "repeat" else st.Retry
            return cls(times=parse_count(v["times"]), steps=self.steps(v["steps"], path + (k, "steps")), **where)
        if k == "timeout":
            return st.Timeout(after_s=q(v["after"], "duration"), steps=self.steps(v["steps"], path + (k, "steps")),
                              **where)
        if k == "parallel":
            on = v.get("succeed_on", mission_default("/$defs/step/anyOf/19/properties/parallel/properties", "succeed_on"))
            return st.Parallel(succeed_on=on, steps=self.steps(v["steps"], path + (k, "steps")),
                               **where)
        if k == "first_of":
            return st.FirstOf(alternatives=tuple(self.steps(alt, path + (k, i)) for i, alt in enumerate(v)), **where)
        if k == "do":
            if isinstance(v, dict):
                args = tuple(sorted((str(a), b) for a, b in v.items() if a != "task"))
                return st.Do(task=v["task"], args=args, **where)
            return st.Do(task=v, **where)
        if k == "if":
            return st.If(condition=condition_of(v), then=self.steps(raw["then"], path + ("then",)),
                         otherwise=self.steps(raw["else"], path + ("else",)) if "else" in raw else None, **where)
        if k == "while":
            return st.While(condition=condition_of(v), steps=self.steps(raw["steps"], path + ("steps",)), **where)
        if k == "ask":
            from beastbt.behaviours.ask import choice_of
            default = choice_of(v["default"]) if "default" in v else None
            return st.Ask(question_id=str(v.get("id") or f"q{where['at'].line}"), question=str(v["question"]),
                          timeout_s=opt("timeout", "duration", v), default=default,
                          then=self.steps(raw.get("then") or [], path + ("then",)),
                          otherwise=self.steps(raw.get("else") or [], path + ("else",)), **where)
        if k == "until":
            return st.UntilBlock(condition=condition_of(v), steps=self.steps(raw["steps"], path + ("steps",)), **where)
        if k == "abort_if":
            return st.AbortIf(condition=condition_of(v), steps=self.steps(raw["steps"], path + ("steps",)), **where)
        if k == "wait_until":
            return st.WaitUntil(condition=condition_of(v), timeout_s=opt("timeout", "duration", raw), **where)
        if k == "ros2_goals":
            goals = v.get("goals")
            return st.Ros2Goals(goals=None if goals is None else int(goals), duration_s=opt("for", "duration"),
                                until=condition_of(v["until"]) if "until" in v else None,
                                tolerance_m=opt("tolerance", "distance"), speed_mps=opt("speed", "speed"), **where)
        if k in ("photo", "alert", "dock", "undock", "track"):
            from beastbt.mission.vision_steps import vision_step
            return vision_step(k, v, where)
        raise ValueError(f"no typed step for '{k}'")


DEFAULT_NEAR_WITHIN_M = parse_quantity(mission_default("/$defs/condition/anyOf/2/properties", "within"), "distance")
"""``{near: place}`` without ``within`` means within this many metres (the schema's default)."""


def sector_angle(value: Any) -> float:
    """One end of an ``obstacle_within`` sector in radians: a bare number is degrees, a text has its unit."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return math.radians(float(value))
    return parse_quantity(value, "angle")


def condition_of(raw: Any) -> st.Condition:
    """The typed condition of what the author wrote (already checked by the schema)."""
    if isinstance(raw, str):
        return st.Flag(word=raw)
    if "battery_below" in raw:
        return st.BatteryBelow(volts=parse_quantity(raw["battery_below"], "voltage"))
    if "near" in raw:
        return st.Near(place=raw["near"], within_m=parse_quantity(raw.get("within", DEFAULT_NEAR_WITHIN_M), "distance"))
    if "elapsed" in raw:
        return st.Elapsed(duration_s=parse_quantity(raw["elapsed"], "duration"))
    if "inside" in raw:
        return st.InFence(fence=raw["inside"], inside=True)
    if "outside" in raw:
        return st.InFence(fence=raw["outside"], inside=False)
    if "answered" in raw:
        from beastbt.behaviours.ask import choice_of
        return st.Answered(question_id=str(raw["answered"]), choice=choice_of(raw["is"]) or "yes")
    if "distance_travelled" in raw:
        return st.DistanceTravelled(distance_m=parse_quantity(raw["distance_travelled"], "distance"))
    if "time_in_block" in raw:
        return st.TimeInBlock(duration_s=parse_quantity(raw["time_in_block"], "duration"))
    if "obstacle_within" in raw:
        sector = raw.get("sector_deg")
        ends = None if sector is None else (sector_angle(sector[0]), sector_angle(sector[1]))
        return st.ObstacleWithin(gap_m=parse_quantity(raw["obstacle_within"], "distance"), sector_rad=ends)
    if "sees" in raw:
        from beastbt.mission.vision_steps import sees_of
        return sees_of(raw["sees"])
    if "not" in raw:
        return st.Not(condition=condition_of(raw["not"]))
    if "all" in raw:
        return st.AllOf(conditions=tuple(condition_of(c) for c in raw["all"]))
    return st.AnyOf(conditions=tuple(condition_of(c) for c in raw["any"]))


def _do_steps(mission: "Mission") -> list[st.Do]:
    from beastbt.mission.warnings import all_steps
    everything = list(all_steps(tuple(mission.steps)))
    for steps in mission.tasks.values():
        everything += list(all_steps(tuple(steps)))
    return [s for s in everything if isinstance(s, st.Do)]


def load_mission(path: Union[str, Path], text: Optional[str] = None, display_name: Optional[str] = None,
                 refs: FileRefs = CLI) -> Mission:
    """Load, validate and check a mission; raise :class:`InvalidInput` with every problem found.

    The files it names (``world:``, ``map:``, route and places files) are read where ``refs`` allows: anywhere
    on the command line (the default), inside the studio's folder or the robot's mission folder there.
    """
    doc = load_yaml(path, text=text, display_name=display_name)
    params, param_problems = expand_task_parameters(doc)
    geo_errors, geo_warnings = resolve_geo_files(doc, Path(path).parent if str(path) else Path("."), refs)
    param_problems = param_problems + geo_errors
    # A keyword the language does not know may be a step of an installed package: only those are loaded.
    external = load_external_steps(step_keywords_in(doc.data, STEP_KEYWORDS), STEP_KEYWORDS)
    schema = with_external_steps(load_schema("mission.schema.json"), external) if external else None
    taken = {(p.file, p.position) for p in param_problems}  # a bad $name: said once, not again by the schema
    said = {(p.file, p.position) for p in (doc.problem(path, "") for path in params.said_at_declaration)}
    problems = param_problems + [p for p in schema_problems(doc, "mission.schema.json", "mission", schema)
                                 if (p.file, p.position) not in taken | said]
    problems += [p for p in _SemanticChecker(doc).run_guarded() if (p.file, p.position) not in said]
    if problems:
        raise InvalidInput(problems)
    mission = _build(doc, Path(path), external, refs)
    _load_map(mission, doc)
    bad_fences = [doc.problem(("fences", name), why, "list the corners in order around the area")
                  for name, fence in mission.fences.items() if (why := fence.valid_problem()) is not None]
    if bad_fences:
        raise InvalidInput(bad_fences)
    reader = _StepReader(doc, external)
    for call_args in {(d.task, d.args) for d in _do_steps(mission) if d.args}:
        task, args = call_args
        raw = params.task_steps(task, dict(args))
        if raw is not None:
            mission.task_variants[call_args] = reader.steps(raw, ("tasks", task, "steps"))
    from beastbt.mission.warnings import mission_warnings
    mission.load_warnings = geo_warnings
    mission.warnings = mission_warnings(mission)
    return mission


def _read_map_keys(m: Mission, doc: SourceDoc, base: Path) -> None:
    """``map:``, ``start:`` and ``initial_uncertainty:`` into the mission (the map itself is read by
    :func:`_load_map`)."""
    d = doc.data
    if "map" in d:
        m.map_file = locate(m.refs, doc, ("map",), base, MAP)
    start = d.get("start")
    if isinstance(start, str):
        m.map_start_place = start
    elif isinstance(start, dict):
        yaw = parse_quantity(start["yaw"], "angle") if "yaw" in start else 0.0
        m.map_start = (parse_quantity(start["x"], "distance"), parse_quantity(start["y"], "distance"), yaw)
    spread = d.get("initial_uncertainty") or {}
    if "xy" in spread:
        m.initial_uncertainty_xy_m = parse_quantity(spread["xy"], "distance")
    if "yaw" in spread:
        m.initial_uncertainty_yaw_rad = parse_quantity(spread["yaw"], "angle")


def _load_map(m: Mission, doc: SourceDoc) -> None:
    """Read the mission's ``map:`` (positioned problems: a missing file at ``map:``, a bad one in the map's YAML);
    ``start:`` and ``initial_uncertainty:`` without ``map:`` are refused where they stand."""
    d = doc.data
    if m.map_file is None:
        stray = [doc.problem((key,), f"'{key}' is a pose on a map, but the mission has no 'map:'",
                             "add map: ../maps/NAME.yaml (a map_server YAML), or remove this key", key=True)
                 for key in ("start", "initial_uncertainty") if key in d]
        stray += [doc.problem(f.path, "the failsafe localization_lost watches the localisation on a map, but the "
                              "mission has no 'map:'", "add map: ../maps/NAME.yaml", key=True)
                  for f in m.failsafes if f.kind == "localization_lost"]
        stray += [doc.problem(path, "the condition 'localized' is about the localisation on a map, but the mission "
                              "has no 'map:' (it would never hold)", "add map: ../maps/NAME.yaml")
                  for path in _localized_conditions(d.get("steps"), ("steps",))
                  + _localized_conditions(d.get("tasks"), ("tasks",))]
        if stray:
            raise InvalidInput(stray)
        return
    for key, value in (("xy", m.initial_uncertainty_xy_m), ("yaw", m.initial_uncertainty_yaw_rad)):
        if value < 0:
            raise InvalidInput([doc.problem(("initial_uncertainty", key), "an uncertainty cannot be negative",
                                            "give a standard deviation such as xy: 0.5 m, yaw: 20 deg")])
    if m.map_start_place is not None and m.map_start_place not in m.places:
        raise InvalidInput([doc.problem(("start",), f"'start: {m.map_start_place}' names no place",
                                        "name a place of places: with x and y on the map, or write "
                                        "start: {x: 1 m, y: 2 m, yaw: 90 deg}")])
    read_map(m, doc)


_CONDITION_KEYS = ("if", "while", "wait_until", "until", "abort_if", "not", "all", "any")


def _localized_conditions(node: Any, path: PathKey) -> list[PathKey]:
    """Where the raw steps use the condition word ``localized`` (paths into the document)."""
    found: list[PathKey] = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key in _CONDITION_KEYS and value == "localized":
                found.append(path + (key,))
            else:
                found += _localized_conditions(value, path + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            if value == "localized" and path and path[-1] in ("all", "any"):
                found.append(path + (i,))
            else:
                found += _localized_conditions(value, path + (i,))
    return found


def locate(refs: FileRefs, doc: SourceDoc, key: PathKey, base: Path, kind: Any) -> Path:
    """The file ``doc`` names at ``key`` (a path, or a bare name such as ``campus``), from a file in ``base``,
    where ``refs`` allows it; InvalidInput at that key, naming the path as written, if it is refused."""
    try:
        return refs.locate(_value_at(doc.data, key), base, kind)
    except RefusedFile as exc:
        hint = exc.hint
        if kind is MAP and "does not exist" in exc.message:
            hint += "; build a map with beastbt run MISSION --build-map maps/NAME.yaml"
        raise InvalidInput([doc.problem(key, exc.message, hint)]) from None


def _value_at(data: Any, key: PathKey) -> Any:
    for part in key:
        data = data[part]
    return data


def locate_world_map(m: Mission, world_doc: SourceDoc, world_file: str, refs: Optional[FileRefs] = None) -> None:
    """A mission without ``map:`` of its own takes its world's ``map:`` (relative to the world file, where ``refs``
    allow: by default the mission's), and reads it; InvalidInput at the world's ``map:`` line."""
    m.map_file = locate(refs or m.refs, world_doc, ("map",), Path(world_file).parent, MAP)
    read_map(m, world_doc)


def read_map(m: Mission, doc: SourceDoc) -> None:
    """Read ``m.map_file`` into ``m.map_grid``: a missing file is a problem at ``doc``'s ``map:`` (the mission's,
    or the world's that gave it), a bad one at the line of the map's own YAML."""
    assert m.map_file is not None
    if not m.map_file.is_file():
        raise InvalidInput([doc.problem(("map",), f"the map file {str(m.map_file)!r} does not exist",
                                        "the path is relative to the file that names it; build a map with "
                                        "beastbt run MISSION --build-map maps/NAME.yaml")])
    from beastbt.mapping.occupancy_map import load_map  # OpenCV reads the image: only for a mission with a map
    m.map_grid = load_map(m.map_file, refs=m.refs)


def _build(doc: SourceDoc, path: Path, external: dict[str, ExternalStep], refs: FileRefs = CLI) -> Mission:
    d = doc.data
    limits = d.get("limits") or {}
    base = path.parent if str(path) else Path(".")
    m = Mission(name=d["mission"], file=doc.file, doc=doc, description=d.get("description", ""),
                external_steps=external, refs=refs)
    if "world" in d:
        try:
            m.world = locate(refs, doc, ("world",), base, WORLD)
        except InvalidInput as exc:
            m.world, m.world_refused = Path(str(d["world"])), exc.problems[0]
    _read_map_keys(m, doc, base)
    m.rate_hz = parse_quantity(d.get("rate", mission_default("/properties", "rate")), "frequency")
    if "speed" in limits:
        m.speed_limit_mps = parse_quantity(limits["speed"], "speed")
    if "turn_rate" in limits:
        m.turn_rate_limit_rps = parse_quantity(limits["turn_rate"], "turn_rate")
    if "acceleration" in limits:
        m.accel_limit_mps2 = _accel(limits["acceleration"])
    for name, place in (d.get("places") or {}).items():
        tol = parse_quantity(place["tolerance"], "distance") if "tolerance" in place else None
        if "x" in place:
            yaw = parse_quantity(place["yaw"], "angle") if "yaw" in place else None
            m.places[name] = Place(name, None, None, tol, parse_quantity(place["x"], "distance"),
                                   parse_quantity(place["y"], "distance"), yaw)
        else:
            m.places[name] = Place(name, float(place["lat"]), float(place["lon"]), tol)
    for name, fence in (d.get("fences") or {}).items():
        corners = []
        for corner in fence.get("polygon") or fence.get("points") or []:
            if isinstance(corner, str):
                place = m.places[corner]
                corners.append((place.lat, place.lon))
            else:
                corners.append((float(corner["lat"]), float(corner["lon"])))
        m.fences[name] = Fence(name, corners, fence.get("keep", "in"))
    reader = _StepReader(doc, external)
    for name, steps in (d.get("tasks") or {}).items():
        if isinstance(steps, dict):
            m.tasks[name] = reader.steps(steps["steps"], ("tasks", name, "steps"))
        else:
            m.tasks[name] = reader.steps(steps, ("tasks", name))
    m.steps = reader.steps(d["steps"], ("steps",))
    m.on_failure = d.get("on_failure", mission_default("/properties", "on_failure"))
    teleop = d.get("teleop", mission_default("/properties", "teleop"))
    if isinstance(teleop, dict):
        m.teleop_override = True
        m.teleop_on_release = teleop.get("on_release", mission_default("/properties/teleop/anyOf/1/properties",
                                                                         "on_release"))
    else:
        m.teleop_override = bool(teleop)
    for kind, spec in (d.get("failsafes") or {}).items():
        params: dict[str, Any] = {}
        if kind == "gps_lost":
            after = spec.get("after", mission_default("/properties/failsafes/properties/gps_lost/properties", "after"))
            params["after_s"] = parse_quantity(after, "duration")
        elif kind == "battery_low":
            params["below_v"] = parse_quantity(spec["below"], "voltage")
            hold = spec.get("for", mission_default("/properties/failsafes/properties/battery_low/properties", "for"))
            params["for_s"] = parse_quantity(hold, "duration")
        elif kind in ("geofence", "keepout") and "fence" in spec:
            params["fence"] = spec["fence"]
            params["margin_m"] = parse_quantity(spec.get("margin", "0 m"), "distance")
        elif kind == "localization_lost":
            after = spec.get("after", mission_default("/properties/failsafes/properties/localization_lost/properties",
                                                      "after"))
            params["after_s"] = parse_quantity(after, "duration")
        elif kind == "geofence":
            params["center"] = spec["center"]
            params["radius_m"] = parse_quantity(spec["radius"], "distance")
        m.failsafes.append(Failsafe(kind, spec["then"], params, ("failsafes", kind)))
    return m


__all__ = ["Mission", "Place", "RawStep", "Failsafe", "load_mission", "read_map", "locate", "locate_world_map", "step_of", "steps_of", "condition_of",
           "parse_count", "HOME", "DEFAULT_NEAR_WITHIN_M", "sector_angle"]
