"""Live tuning: the profile's knobs a run lets an operator change while it runs, each bound to the object that uses it.

A knob is named by its place in the robot profile (``limits.max_speed_mps``,
``line_follower.curve_slowdown_m``, ``collision_monitor.slow.ratio``) and
takes its title, unit, range and default from the profile's schema
(``schemas/robot.schema.json`` and ``schemas/parts/*.json``: ``title``,
``default``, ``minimum``/``maximum``/``exclusiveMinimum``, ``x-knob-unit``).
Where the schema sets no top (a speed, a weight), :data:`KNOBS` gives the
slider one: the speed limits never go above the profile's own value (the
console may slow a robot, never make it faster than its profile allows).

:class:`TuningRegistry` holds the run's knobs (only those whose object the
run has: no LiDAR, no collision monitor knobs) and sets them on the tick
thread, where :class:`~beastbt.live.console_control.ConsoleControls` carries
out the console's ``tune`` control: the new value is in force from the next
tick. A value outside the knob's range is refused with the range. Every
change is an event (``tuning``) and, being a console control, an operator
input on ``/operator/input`` (so ``beastbt replay`` makes it again at the
same tick); both are in the recording and on Foxglove's live connection.

:func:`save_profile_text` writes the changed values back into the profile's
text with ruamel.yaml's round trip (comments, key order and layout kept, as the
studio's edits do); :meth:`TuningRegistry.reset` throws the changes away.

Nothing here reads a clock: the tick thread's ``now_s`` is passed in.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Optional, Union

from beastbt.actuation.gate import tightest
from beastbt.core.schema_defaults import schema_document

PROFILE = "profile"
"""A knob's ceiling that is the profile's own value when the run started (the speed limits)."""

UNIT_WORDS = {"metres": "m", "seconds": "s", "metres per second": "m/s", "radians per second": "rad/s",
              "degrees per second": "deg/s", "degrees": "deg", "radians": "rad", "hertz": "Hz", "volts": "V"}
"""A schema's ``x-knob-unit`` as the slider shows it."""

GROUPS = {"limits": "always", "collision_monitor": "always (a LiDAR)",
          "line_follower": "follow_line", "local_planner": "go_to, route, return_home (a LiDAR)",
          "navigation": "go_to, route, return_home", "localisation": "a mission on a saved map"}
"""Each group of knobs and when the console shows its sliders (the steps that use it)."""


@dataclass(frozen=True)
class KnobSpec:
    """One tunable knob: its profile path, group, the live object it binds to (``holder(run)``, None when the run
    has none), how its value is read from it (``read(holder)``, in the knob's unit) and set (``write(run, holder,
    value)``), and the slider's top when the schema gives none (a number, or :data:`PROFILE`), and its step."""

    name: str
    group: str
    holder: Callable[[Any], Any]
    read: Callable[[Any], float]
    write: Callable[[Any, Any, float], None]
    ceiling: Union[float, str, None] = None
    step: Optional[float] = None


# -- the bindings -------------------------------------------------------------------------------------------------

def _run(run: Any) -> Any:
    return run


def _set_speed(run: Any, _: Any, value: float) -> None:
    limit = tightest(run.mission.speed_limit_mps, value)
    run.gate.limits.max_speed_mps = limit
    run.ctx.speed_limit_mps = limit  # the steps cap their speed to it (follow_line each tick)
    navigator = run.ctx.services.local_navigator
    if navigator is not None:
        navigator.planner.limits = dataclasses.replace(navigator.planner.limits, max_speed_mps=value)


def _set_turn_rate(run: Any, _: Any, value_dps: float) -> None:
    limit = tightest(run.mission.turn_rate_limit_rps, math.radians(value_dps))
    run.gate.limits.max_turn_rate_rps = limit
    run.ctx.turn_rate_limit_rps = limit  # navigation and follow_line read it each tick


def _attr(path: str) -> tuple[Callable[[Any], float], Callable[[Any, Any, float], None]]:
    """read/write of a mutable config's (nested) attribute, ``slow.ratio``."""
    *parents, last = path.split(".")

    def owner(holder: Any) -> Any:
        for p in parents:
            holder = getattr(holder, p)
        return holder

    def read(holder: Any) -> float:
        return getattr(owner(holder), last)

    def write(run: Any, holder: Any, value: float) -> None:
        setattr(owner(holder), last, value)
    return read, write


def _frozen(field_name: str, put: Callable[[Any, Any, Any], None]) -> tuple[Callable[[Any], float],
                                                                           Callable[[Any, Any, float], None]]:
    """read/write of a frozen config's field: a copy with the new value, put where its users read it each tick."""

    def read(config: Any) -> float:
        return getattr(config, field_name)

    def write(run: Any, config: Any, value: float) -> None:
        put(run, config, dataclasses.replace(config, **{field_name: value}))
    return read, write


def _put_planner(run: Any, old: Any, new: Any) -> None:
    navigator = run.ctx.services.local_navigator
    navigator.planner_config = navigator.planner.config = new


def _planner_config(run: Any) -> Any:
    navigator = run.ctx.services.local_navigator
    return navigator.planner.config if navigator is not None else None


def _put_nav(run: Any, old: Any, new: Any) -> None:
    run.ctx.services.navigation = new
    for node in run.root.iterate():  # the navigation steps keep the config they started with: give them the new one
        if getattr(node, "nav", None) is old:
            node.nav = new


def _localiser_config(run: Any) -> Any:
    localiser = run.ctx.services.plugins.get("map_localiser")
    return localiser.config if localiser is not None else None


def _put_localiser(run: Any, old: Any, new: Any) -> None:
    if not new.lost_quality <= new.found_quality:
        from beastbt.live.refusal import Refused
        raise Refused(400, f"localisation.lost_quality ({new.lost_quality:g}) must not be above found_quality "
                           f"({new.found_quality:g})")
    run.ctx.services.plugins["map_localiser"].config = new


def _line_follower(run: Any) -> Any:
    return run.ctx.services.line_follower


def _monitor_config(run: Any) -> Any:
    monitor = run.collision_monitor
    return monitor.config if monitor is not None else None


def _spec(name: str, group: str, holder: Callable[[Any], Any], rw: tuple, ceiling: Union[float, str, None] = None,
          step: Optional[float] = None) -> KnobSpec:
    return KnobSpec(name, group, holder, rw[0], rw[1], ceiling, step)


KNOBS: tuple[KnobSpec, ...] = (
    KnobSpec("limits.max_speed_mps", "limits", _run, lambda run: run.profile.max_speed_mps, _set_speed, PROFILE, 0.01),
    KnobSpec("limits.max_turn_rate_dps", "limits", _run,
             lambda run: round(math.degrees(run.profile.max_turn_rate_rps), 6),
             _set_turn_rate, PROFILE, 1.0),
    _spec("line_follower.default_speed_mps", "line_follower", _line_follower, _attr("default_speed_mps"), 1.0, 0.01),
    _spec("line_follower.max_turn_rate_rps", "line_follower", _line_follower, _attr("max_turn_rate_rps"), 6.0, 0.05),
    _spec("line_follower.curve_slowdown_m", "line_follower", _line_follower, _attr("curve_slowdown_m"), 2.0, 0.01),
    _spec("line_follower.min_speed_fraction", "line_follower", _line_follower, _attr("min_speed_fraction"),
          step=0.01),
    _spec("line_follower.lost_speed_fraction", "line_follower", _line_follower, _attr("lost_speed_fraction"),
          step=0.01),
    _spec("collision_monitor.slow.ratio", "collision_monitor", _monitor_config, _attr("slow.ratio"), step=0.01),
    _spec("collision_monitor.min_points", "collision_monitor", _monitor_config, _attr("min_points"), 50, 1),
    _spec("local_planner.path_align_scale", "local_planner", _planner_config,
          _frozen("path_align_scale", _put_planner), 10.0, 0.1),
    _spec("local_planner.goal_dist_scale", "local_planner", _planner_config,
          _frozen("goal_dist_scale", _put_planner), 10.0, 0.1),
    _spec("local_planner.obstacle_scale", "local_planner", _planner_config,
          _frozen("obstacle_scale", _put_planner), 10.0, 0.1),
    _spec("navigation.default_blocked_after_s", "navigation", lambda run: run.ctx.services.navigation,
          _frozen("default_blocked_after_s", _put_nav), 120.0, 1.0),
    _spec("navigation.replan_cross_track_m", "navigation", lambda run: run.ctx.services.navigation,
          _frozen("replan_cross_track_m", _put_nav), 20.0, 0.1),
    _spec("localisation.lost_quality", "localisation", _localiser_config,
          _frozen("lost_quality", _put_localiser), step=0.01),
    _spec("localisation.found_quality", "localisation", _localiser_config,
          _frozen("found_quality", _put_localiser), step=0.01),
    _spec("localisation.lost_after_s", "localisation", _localiser_config,
          _frozen("lost_after_s", _put_localiser), 10.0, 0.1),
)
"""Every knob live tuning knows, in the order the console shows them."""


# -- the schema's word on a knob ------------------------------------------------------------------------------------

def knob_schema(name: str) -> dict:
    """The schema property of the profile knob ``name`` (dotted path), its ``$ref`` folded in (own keys win)."""
    section, *rest = name.split(".")
    robot = schema_document("robot.schema.json")
    prop = robot["properties"][section]
    document = robot
    if "$ref" in prop and not prop["$ref"].startswith("#"):
        document = schema_document(prop["$ref"])
        prop = document
    for key in rest:
        prop = prop["properties"][key]
    ref = prop.get("$ref")
    if ref is not None and ref.startswith("#/"):
        target: Any = document
        for part in ref[2:].split("/"):
            target = target[part]
        prop = {**target, **prop}
    return prop


@dataclass
class Knob:
    """One knob of this run: the schema's title, unit, range (``minimum`` inclusive, or above
    ``exclusive_minimum``; ``maximum`` inclusive) and default, the profile's value when the run started (what a
    reset goes back to), and the value in force."""

    spec: KnobSpec
    holder: Any
    title: str
    unit: str
    minimum: Optional[float]
    exclusive_minimum: Optional[float]
    maximum: float
    default: Optional[float]
    integer: bool
    profile: float
    value: float

    @property
    def name(self) -> str:
        return self.spec.name

    def range_text(self) -> str:
        """The range as a person reads it: ``above 0 and at most 0.35 m/s``."""
        unit = f" {self.unit}" if self.unit else ""
        low = (f"above {self.exclusive_minimum:g}" if self.exclusive_minimum is not None
               else f"from {self.minimum:g}" if self.minimum is not None else "")
        high = f"at most {self.maximum:g}" if low.startswith("above") else f"to {self.maximum:g}"
        return f"{low} {'and ' if low.startswith('above') else ''}{high}{unit}".strip()

    def as_dict(self) -> dict:
        """The knob as ``GET /api/tuning`` gives it."""
        step = self.spec.step if self.spec.step is not None else (1 if self.integer else 0.01)
        low = self.minimum if self.minimum is not None else self.exclusive_minimum
        return {"name": self.name, "group": self.spec.group, "title": self.title, "unit": self.unit,
                "value": self.value, "default": self.default, "profile": self.profile,
                "min": low, "min_exclusive": self.exclusive_minimum is not None, "max": self.maximum,
                "step": step, "integer": self.integer, "changed": self.value != self.profile,
                "range": self.range_text()}


def _knob(spec: KnobSpec, run: Any, holder: Any) -> Knob:
    prop = knob_schema(spec.name)
    integer = prop.get("type") == "integer"
    value = spec.read(holder)
    value = int(value) if integer else float(value)
    maximum = prop.get("maximum")
    if maximum is None:
        maximum = value if spec.ceiling == PROFILE else spec.ceiling
    unit = UNIT_WORDS.get(prop.get("x-knob-unit", ""), "")
    if not unit and spec.name.endswith("_dps"):
        unit = "deg/s"
    default = prop.get("default")
    title = str(prop.get("title", spec.name))
    if spec.name.count(".") > 1:  # a nested knob (collision_monitor.slow.ratio): its parent names it too
        title = f"{knob_schema(spec.name.rsplit('.', 1)[0]).get('title', '')} {title.lower()}".strip()
    return Knob(spec, holder, title, unit, prop.get("minimum"),
                prop.get("exclusiveMinimum"), float(maximum), None if default is None else float(default), integer,
                value, value)


# -- the registry ---------------------------------------------------------------------------------------------------

def _refused(status: int, message: str) -> Exception:
    from beastbt.live.refusal import Refused
    return Refused(status, message)


class TuningRegistry:
    """The tunable knobs of one run, bound to its live objects (see the module docstring). Tick thread only."""

    def __init__(self, run: Any) -> None:
        self.run = run
        self.knobs: dict[str, Knob] = {}
        for spec in KNOBS:
            holder = spec.holder(run)
            if holder is not None:
                self.knobs[spec.name] = _knob(spec, run, holder)
        self._board: Any = None
        self.version = 0
        """Changes when the knobs' description changes (a save makes new profile values): the console's page fetches
        the knobs again then. The values themselves come with every state."""

    def listing(self) -> dict:
        """``GET /api/tuning``: ``{knobs: [...], active: [groups], profile_file}``."""
        return {"knobs": [k.as_dict() for k in self.knobs.values()], "active": self.active_groups(),
                "profile_file": getattr(self.run.profile, "file", None), "version": self.version}

    def values(self) -> dict[str, float]:
        """Every knob's value in force, by name."""
        return {name: k.value for name, k in self.knobs.items()}

    def changes(self) -> dict[str, float]:
        """The knobs whose value differs from the profile's, by name."""
        return {name: k.value for name, k in self.knobs.items() if k.value != k.profile}

    def active_groups(self) -> list[str]:
        """The groups of knobs the running steps use (see :data:`GROUPS`): ``limits`` always."""
        from py_trees.common import Status
        groups = ["limits"]
        running = {type(n).__name__ for n in self.run.nodes if n.status == Status.RUNNING}
        present = {k.spec.group for k in self.knobs.values()}
        if "FollowLine" in running:
            groups.append("line_follower")
        if running & {"GoTo", "MapGoTo", "Route", "ReturnHome", "MapRoute"}:
            groups += ["navigation", "local_planner"]
        groups += ["collision_monitor", "localisation"]
        return [g for g in dict.fromkeys(groups) if g in present]

    def check(self, name: Any, value: Any) -> Knob:
        """The knob ``name`` and a value it takes; a 400 that says the range (or the knobs there are) otherwise."""
        knob = self.knobs.get(name) if isinstance(name, str) else None
        if knob is None:
            raise _refused(400, f"no knob {str(name)[:60]!r} on this run: the knobs are {', '.join(self.knobs)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise _refused(400, f"{knob.name} takes a number ({knob.range_text()}), not {str(value)[:40]!r}")
        low_ok = (knob.exclusive_minimum is None or value > knob.exclusive_minimum) and (
            knob.minimum is None or value >= knob.minimum)
        if not low_ok or value > knob.maximum:
            raise _refused(400, f"{knob.name} = {value:g} is out of range: {knob.range_text()}")
        if knob.integer and value != int(value):
            raise _refused(400, f"{knob.name} takes a whole number ({knob.range_text()}), not {value:g}")
        return knob

    def set(self, name: Any, value: Any, now_s: float, who: str = "console") -> dict:
        """Set one knob (tick thread): in force from the next tick; an event says so. Raises Refused (400)."""
        knob = self.check(name, value)
        value = int(value) if knob.integer else float(value)
        old = knob.value
        self._write(knob, value)
        self.run.events.add("tuning", f"{knob.name}: {old:g} -> {value:g}{' ' + knob.unit if knob.unit else ''} "
                                      f"({who})")
        return {"name": knob.name, "value": value, "was": old}

    def _write(self, knob: Knob, value: float) -> None:
        holder = knob.spec.holder(self.run)  # a frozen config is replaced by each change: the one in force now
        knob.spec.write(self.run, holder, value)
        knob.value = value

    def reset(self, now_s: float, who: str = "console") -> dict:
        """Throw the changes away: every knob back to the profile's value. Returns the knobs it set back."""
        undone = {}
        for knob in self.knobs.values():
            if knob.value != knob.profile:
                undone[knob.name] = knob.profile
                self._write(knob, knob.profile)
        if undone:
            self.run.events.add("tuning", f"reset to the profile ({who}): {', '.join(undone)}")
        return {"reset": sorted(undone)}

    def saved(self, values: dict) -> dict:
        """The values were written to the profile's file: they are the profile's now (a reset comes back to them)."""
        for name, value in values.items():
            knob = self.knobs.get(name)
            if knob is not None:
                knob.profile = int(value) if knob.integer else float(value)
        self.version += 1
        self.run.events.add("tuning", f"saved to {getattr(self.run.profile, 'file', 'the profile')}: "
                                      f"{', '.join(f'{k} = {v:g}' for k, v in values.items()) or 'no change'}")
        return {"saved": sorted(values)}

    def line_state(self) -> Optional[dict]:
        """The line follower's error for the page's plot while a line is followed: ``{t, offset_m, seen}``."""
        if "line_follower.default_speed_mps" not in self.knobs:
            return None
        if self._board is None:
            import py_trees

            from beastbt.blackboard import catalogue
            self._board = py_trees.blackboard.Client(name="tuning")
            catalogue.register(self._board, "line")
        from beastbt.blackboard import catalogue
        obs = catalogue.get(self._board, "line")
        if obs is None:
            return None
        return {"t": round(float(obs.stamp_s), 3), "offset_m": round(float(obs.offset_m), 4) if obs.seen else None,
                "seen": bool(obs.seen)}

    def state(self) -> dict:
        """The console state's ``tuning``: ``{version, values, active, changed, line}``."""
        return {"version": self.version, "values": self.values(), "active": self.active_groups(),
                "changed": sorted(self.changes()), "line": self.line_state()}


def tuning_of(run: Any) -> TuningRegistry:
    """The run's tuning registry, built on first use (on the tick thread)."""
    plugins = run.ctx.services.plugins
    registry = plugins.get("tuning")
    if registry is None:
        registry = plugins["tuning"] = TuningRegistry(run)
    return registry


def check_tune_body(body: Any) -> dict:
    """The body of ``POST /api/tuning``: ``{name, value}``, a short knob name and a number (the range is the run's
    to check)."""
    if not isinstance(body, dict) or not isinstance(body.get("name"), str) or len(body["name"]) > 100:
        raise _refused(400, "expected {\"name\": KNOB, \"value\": NUMBER}, e.g. {\"name\": \"limits.max_speed_mps\", "
                            "\"value\": 0.2}")
    value = body.get("value")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _refused(400, f"'value' must be a number, not {str(value)[:40]!r}")
    return {"name": body["name"], "value": value}


# -- saving to the profile ------------------------------------------------------------------------------------------

SAVE_DECIMALS = 4
"""Decimals a saved value is written with."""


def _number(value: float, integer: bool) -> Union[int, float]:
    return int(value) if integer else round(float(value), SAVE_DECIMALS)


def save_profile_text(text: str, values: dict[str, float], integers: frozenset[str] = frozenset()) -> str:
    """``text`` (a robot profile) with each knob of ``values`` (dotted path -> value in the knob's unit) written in,
    with ruamel.yaml's round trip: comments, order and layout kept; a missing section or key is added. Raises
    :class:`~beastbt.core.yaml_round_trip.EditRefused` when the text is not a YAML mapping."""
    from ruamel.yaml.comments import CommentedMap

    from beastbt.core.yaml_round_trip import EditRefused, _dump, _patched, load_round_trip
    crlf = "\r\n" in text
    work = text.replace("\r\n", "\n") if crlf else text
    if not work.endswith("\n"):
        work += "\n"
    y, data, exact = load_round_trip(work)
    baseline = work if exact else _dump(y, data)
    for name, value in values.items():
        *parents, last = name.split(".")
        node = data
        for key in parents:
            child = node.get(key)
            if child is None:
                child = CommentedMap()
                node[key] = child
            if not isinstance(child, dict):
                raise EditRefused(f"'{key}' in the profile is not a mapping: cannot write {name}")
            node = child
        node[last] = _number(value, name in integers)
    new = _dump(y, data)
    if not exact:
        new = _patched(work, baseline, new) or new
    if not text.endswith("\n") and not text.endswith("\r\n") and new.endswith("\n"):
        new = new[:-1]
    return new.replace("\n", "\r\n") if crlf else new


def write_profile(path: str, values: dict[str, float], integers: frozenset[str] = frozenset()) -> None:
    """Write ``values`` into the profile file at ``path`` (:func:`save_profile_text`), atomically (a temporary file
    beside it, then a rename: a power cut leaves the old file or the new one, never half of one)."""
    import os
    from pathlib import Path
    target = Path(path)
    text = target.read_text(encoding="utf-8")
    new = save_profile_text(text, values, integers)
    tmp = target.with_name(f".{target.name}.tuning-tmp")
    tmp.write_text(new, encoding="utf-8")
    os.replace(tmp, target)


def inside_package(path: str) -> bool:
    """Whether ``path`` is one of the files installed inside the beastbt package (a bundled profile)."""
    from pathlib import Path

    import beastbt
    package = Path(beastbt.__file__).resolve().parent
    try:
        Path(path).resolve().relative_to(package)
    except ValueError:
        return False
    return True


def save_through(controls: Any, timeout_s: float) -> dict:
    """``POST /api/tuning/save`` from any thread but the tick thread: take the changes (a control, on the tick
    thread), write them into the profile's file here (the loop never waits for the disk), then tell the run they
    are saved (a control, recorded: a reset after it comes back to them). Raises Refused."""
    snapshot = controls.submit("tune_changes", {}).result(timeout_s)
    values, path, integers = snapshot["changes"], snapshot["profile_file"], frozenset(snapshot["integers"])
    if not values:
        return {"saved": [], "profile_file": path}
    if not path:
        raise _refused(409, "this run's profile has no file to save to")
    if inside_package(path):
        raise _refused(409, f"{path} is the profile installed with beastbt (an upgrade would undo the change): copy "
                            f"it (cp {path} my_robot.yaml), run with --robot my_robot.yaml and save there")
    from beastbt.core.yaml_round_trip import EditRefused
    try:
        write_profile(path, values, integers)
    except (OSError, EditRefused) as exc:
        raise _refused(409, f"could not save to {path}: {exc}") from None
    outcome = controls.submit("tune_saved", {"values": values}).result(timeout_s)
    return {**outcome, "profile_file": path}


__all__ = ["KNOBS", "KnobSpec", "Knob", "TuningRegistry", "tuning_of", "check_tune_body", "knob_schema",
           "save_profile_text", "write_profile", "save_through", "GROUPS", "PROFILE"]
