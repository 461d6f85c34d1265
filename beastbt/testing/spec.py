"""A mission test file (``*.test.yaml``) loaded and checked: every error names its file, line and column.

The contract is ``schemas/test.schema.json``; here the file is read with
positions (:func:`~beastbt.core.yaml_source.load_yaml`), checked against the
schema (:func:`~beastbt.core.schema_check.schema_problems`, as ``beastbt
validate`` checks a mission), then against its mission: the places an event
waits for, the questions answered, the fences named and the steps
substituted must all be the mission's, else the error is at that line, with
the names the mission has. Times are seconds, distances metres, speeds m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

from beastbt.core.errors import InvalidInput, Problem, did_you_mean
from beastbt.core.units import UnitError, parse_quantity
from beastbt.core.yaml_source import SourceDoc, load_yaml

SCHEMA = "test.schema.json"
SUFFIX = ".test.yaml"
"""What a mission test file's name ends with (``beastbt test`` and pytest find them by it)."""

DEFAULT_SEEDS = 1
DEFAULT_MAX_TIME_S = 600.0
"""A test's run ends (stopped) after this much mission time unless its ``max_time:`` says otherwise, s."""
DEFAULT_FOR_S = {"gps_lost": 10.0, "gps_jump": 10.0, "lidar_silent": 2.0, "pause": 5.0}
"""How long a fault lasts when its event gives no ``for:``, s."""
DEFAULT_NEAR_M = 2.0
DEFAULT_PERSON_SPEED_MPS = 0.8
BATTERY_EMPTY_V, BATTERY_FULL_V = 9.9, 12.6
"""A 3-cell LiPo at 0 % and 100 % (3.3 V and 4.2 V a cell): what ``battery: 21 %`` is a share of, V."""
HAPPENINGS = ("gps", "lidar", "battery", "person", "operator", "estop")
"""The keys of an event that say what happens (exactly one per event)."""


@dataclass(frozen=True)
class Trigger:
    """When an event fires: at mission time ``at_s`` (s), or the first time the robot is within ``within_m`` (m)
    of the mission's place ``near``."""

    at_s: Optional[float] = None
    near: Optional[str] = None
    within_m: float = DEFAULT_NEAR_M

    def words(self) -> str:
        """The trigger as a person says it."""
        if self.at_s is not None:
            return f"at {self.at_s:g} s"
        return f"near {self.near} within {self.within_m:g} m"


@dataclass(frozen=True)
class Fault:
    """What happens: ``kind`` (gps_lost, gps_jump, lidar_silent, battery, person, pause, abort, estop), its SI
    parameters (``jump_m``; ``battery_v``; ``from_xy``, ``to_xy`` m, ``speed_mps``, ``gives_way``) and for how long
    (``for_s``, s; 0 when it does not last)."""

    kind: str
    params: dict = field(default_factory=dict)
    for_s: float = 0.0

    def words(self) -> str:
        """The fault as a person says it."""
        p = self.params
        lasting = f" for {self.for_s:g} s" if self.for_s else ""
        return {
            "gps_lost": f"GPS lost{lasting}",
            "gps_jump": f"GPS jumps {p.get('jump_m', 0):g} m{lasting}",
            "lidar_silent": f"LiDAR silent{lasting}",
            "battery": f"battery set to {p.get('battery_v', 0):.2f} V",
            "person": f"person walks from {list(p.get('from_xy', ()))} to {list(p.get('to_xy', ()))}",
            "pause": f"operator pauses{lasting}",
            "abort": "operator aborts",
            "estop": "e-stop",
        }.get(self.kind, self.kind)


@dataclass(frozen=True)
class TestEvent:
    """One event of a test: its trigger and its fault; ``index`` its place in ``events:``."""

    __test__ = False  # not a pytest test class, whatever its name
    trigger: Trigger
    fault: Fault
    index: int = 0


@dataclass(frozen=True)
class Substitution:
    """A step whose result is forced: the step's name (``go_to bench``), ``result`` (success/failure) after
    ``after_s`` (s)."""

    step: str
    result: str
    after_s: float = 0.0


@dataclass(frozen=True)
class Bound:
    """A bound on a number of the summary: ``op`` (<=, >=, <, >, ==) and ``value`` (SI); ``text`` as written."""

    op: str
    value: float
    text: str

    def holds(self, seen: float) -> bool:
        """Whether ``seen`` is within the bound."""
        v = self.value
        return {"<=": seen <= v + 1e-9, ">=": seen >= v - 1e-9, "<": seen < v, ">": seen > v,
                "==": abs(seen - v) <= 1e-9}[self.op]


@dataclass
class Expectations:
    """What every run of a test must show, read from its summary (None or empty: not checked)."""

    status: Optional[str] = None
    reached: list[str] = field(default_factory=list)
    collisions: Optional[Bound] = None
    min_clearance: Optional[Bound] = None
    time: Optional[Bound] = None
    never_in: list[str] = field(default_factory=list)
    asked: list[str] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)


@dataclass
class MissionTest:
    """A checked test file: its name (``test:``), file, mission, world, robot, seeds, max time (s), answers,
    events, substitutions and expectations. Paths are resolved from the test file's folder."""

    name: str
    file: Path
    mission: Path
    world: Optional[Path]
    robot: str
    seeds: list[int]
    max_time_s: float
    answers: dict[str, str]
    events: list[TestEvent]
    substitutions: list[Substitution]
    expect: Expectations
    doc: Optional[SourceDoc] = None


def find_tests(paths: list[Union[str, Path]]) -> list[Path]:
    """Every ``*.test.yaml`` under ``paths`` (files given by name count whatever they end with), sorted, once; hidden
    folders and ``node_modules`` are not searched."""
    import os
    found: list[Path] = []
    for p in map(Path, paths):
        if not p.is_dir():
            found.append(p)
            continue
        for folder, dirs, files in os.walk(p):
            # Not into hidden folders (.git, .venv) nor node_modules: a project's tests are not there.
            dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d != "node_modules")
            found.extend(Path(folder) / f for f in sorted(files) if f.endswith(SUFFIX))
    seen: set[Path] = set()
    out = []
    for p in found:
        key = p.resolve()
        if key not in seen:
            seen.add(key)
            out.append(p)
    return out


def load_test(path: Union[str, Path], seeds: Optional[int] = None) -> MissionTest:
    """Read and check the test file at ``path``; raise :class:`InvalidInput` with every problem, positioned.

    ``seeds``: run seeds 1..N instead of the file's ``seeds:`` (``beastbt test --seeds N``).
    """
    from beastbt.core.schema_check import schema_problems
    doc = load_yaml(path)
    problems = schema_problems(doc, SCHEMA, "mission test")
    if problems:
        raise InvalidInput(problems)
    return _checked(doc, Path(path), seeds)


def faults_from(events: Optional[list] = None, substitute: Optional[dict] = None, places: Optional[Any] = None,
                name: str = "<harness>") -> tuple[list[TestEvent], list[Substitution]]:
    """Events and substitutions written as in a test file (``[{at: 30 s, gps: lost}]``, ``{"go_to a": {result:
    failure}}``), checked by the same schema and code; raise :class:`InvalidInput` naming ``name`` and the entry.
    ``places``: the mission's places a ``when: {near: ...}`` may name (None: not checked here)."""
    from beastbt.core.schema_check import schema_problems
    data: dict[str, Any] = {"test": name, "mission": name}
    if events:
        data["events"] = list(events)
    if substitute:
        data["substitute"] = dict(substitute)
    doc = SourceDoc(file=name, data=data)
    problems = schema_problems(doc, SCHEMA, "mission test")
    if problems:
        raise InvalidInput(problems)
    checked: list[TestEvent] = []
    for i, raw in enumerate(data.get("events") or []):
        event, said = _event(doc, i, raw, None if places is None else set(places) | {"home"})
        problems.extend(said)
        if event is not None:
            checked.append(event)
    subs = [Substitution(str(step), str(spec["result"]),
                         _si(doc, ("substitute", step, "after"), spec.get("after", 0), "duration"))
            for step, spec in (data.get("substitute") or {}).items()]
    if problems:
        raise InvalidInput(problems)
    return checked, subs


def _file_at(doc: SourceDoc, key: str, base: Path) -> Optional[Path]:
    value = doc.data.get(key)
    if value is None:
        return None
    target = Path(value) if Path(value).is_absolute() else base / value
    if not target.is_file():
        raise InvalidInput([doc.problem((key,), f"{key}: no file '{value}' (looked for {target})",
                                        "paths are relative to the folder of the test file")])
    return target


def _si(doc: SourceDoc, path: tuple, value: Any, kind: str) -> float:
    try:
        return parse_quantity(value, kind)
    except UnitError as exc:
        raise InvalidInput([doc.problem(path, str(exc))]) from None


CMP_DEFAULT = {"collisions": "==", "min_clearance": ">=", "time": "<="}
CMP_KIND = {"collisions": None, "min_clearance": "distance", "time": "duration"}


def _bound(doc: SourceDoc, key: str) -> Optional[Bound]:
    raw = (doc.data.get("expect") or {}).get(key)
    if raw is None:
        return None
    text = str(raw).strip()
    op = next((o for o in ("<=", ">=", "==", "<", ">") if text.startswith(o)), CMP_DEFAULT[key])
    rest = text[len(op):].strip() if text.startswith(op) else text
    kind = CMP_KIND[key]
    if kind is None:
        try:
            value = float(int(rest))
        except ValueError:
            raise InvalidInput([doc.problem(("expect", key), f"'{text}' is not a whole-number bound",
                                            "write a count such as 0, or a bound such as '<= 1'")]) from None
    else:
        value = _si(doc, ("expect", key), rest, kind)
    return Bound(op, value, text)


def _checked(doc: SourceDoc, path: Path, seeds_override: Optional[int]) -> MissionTest:
    from beastbt.mission.model import load_mission
    d = doc.data
    base = path.parent
    mission_path = _file_at(doc, "mission", base)
    assert mission_path is not None  # required by the schema
    world = _file_at(doc, "world", base)
    robot = str(d.get("robot", "sim"))
    if robot != "sim":
        beside = Path(robot) if Path(robot).is_absolute() else base / robot
        robot = str(beside) if beside.is_file() else robot  # else a bundled profile's name (ugv_beast)
        from beastbt.robot.profile import load_profile
        try:
            load_profile(robot)
        except InvalidInput as exc:
            if Path(robot).is_file():
                raise  # the profile's own problems, at their lines in it
            raise InvalidInput([doc.problem(("robot",), p.message, p.hint) for p in exc.problems]) from None
    mission = load_mission(str(mission_path))  # its own errors, at its own lines
    problems: list[Problem] = []

    raw_seeds = d.get("seeds", DEFAULT_SEEDS)
    if seeds_override is not None:
        seed_list = list(range(1, seeds_override + 1))
    elif isinstance(raw_seeds, list):
        seed_list = [int(s) for s in raw_seeds]
    else:
        seed_list = list(range(1, int(raw_seeds) + 1))
    max_time_s = _si(doc, ("max_time",), d["max_time"], "duration") if "max_time" in d else DEFAULT_MAX_TIME_S
    if max_time_s <= 0:
        problems.append(doc.problem(("max_time",), "max_time must be more than 0", "e.g. max_time: 10 min"))

    from beastbt.behaviours.ask import choice_of
    from beastbt.commands.run import question_ids
    asked_ids = question_ids(mission)
    answers: dict[str, str] = {}
    for qid, value in (d.get("answers") or {}).items():
        if qid not in asked_ids:
            problems.append(doc.problem(("answers", qid), f"the mission asks no question '{qid}'",
                                        _choices(qid, asked_ids, "its questions", "it has no 'ask:' step"), key=True))
        answers[str(qid)] = choice_of(value) or "no"

    places = set(mission.places) | {"home"}
    events: list[TestEvent] = []
    for i, raw in enumerate(d.get("events") or []):
        event, said = _event(doc, i, raw, places)
        problems.extend(said)
        if event is not None:
            events.append(event)

    for event in events:
        place = mission.places.get(event.trigger.near) if event.trigger.near else None
        if place is not None and place.lat is None:
            problems.append(doc.problem(("events", event.index, "when", "near"),
                                        f"'{event.trigger.near}' is a place on the mission's map, which the test cannot "
                                        f"find in the world", "wait for a GPS place (lat, lon), or use 'at: TIME'"))
    substitutions = [Substitution(str(name), str(spec["result"]),
                                  _si(doc, ("substitute", name, "after"), spec.get("after", 0), "duration"))
                     for name, spec in (d.get("substitute") or {}).items()]
    problems.extend(_unknown_steps(doc, mission, robot, [s.step for s in substitutions]))

    e = d.get("expect") or {}
    expect = Expectations(status=e.get("status"), reached=[str(x) for x in e.get("reached") or []],
                          collisions=_bound(doc, "collisions"), min_clearance=_bound(doc, "min_clearance"),
                          time=_bound(doc, "time"), never_in=[str(x) for x in e.get("never_in") or []],
                          asked=[str(x) for x in e.get("asked") or []],
                          events=[dict(x) for x in e.get("events") or []])
    for i, name in enumerate(expect.reached):
        if name not in places:
            problems.append(doc.problem(("expect", "reached", i), f"the mission has no place '{name}'",
                                        _choices(name, sorted(places), "its places", "it has no places")))
    for i, name in enumerate(expect.never_in):
        if name not in mission.fences:
            problems.append(doc.problem(("expect", "never_in", i), f"the mission has no fence '{name}'",
                                        _choices(name, sorted(mission.fences), "its fences", "it has no 'fences:'")))
    for i, qid in enumerate(expect.asked):
        if qid not in asked_ids:
            problems.append(doc.problem(("expect", "asked", i), f"the mission asks no question '{qid}'",
                                        _choices(qid, asked_ids, "its questions", "it has no 'ask:' step")))
    if problems:
        raise InvalidInput(problems)
    return MissionTest(str(d["test"]), path, mission_path, world, robot, seed_list, max_time_s, answers, events,
                       substitutions, expect, doc)


def _choices(word: str, names: list[str], what: str, none: str) -> str:
    if not names:
        return f"the mission names none: {none}"
    return f"{what}: {', '.join(names)}{did_you_mean(word, names)}"


def _event(doc: SourceDoc, i: int, raw: dict, places: Optional[set]) -> tuple[Optional[TestEvent], list[Problem]]:
    """One entry of ``events:`` checked: one trigger, one happening, ``for:`` only where something lasts."""
    at = ("events", i)
    triggers = [k for k in ("at", "when") if k in raw]
    happening = [k for k in HAPPENINGS if k in raw]
    if len(triggers) != 1:
        return None, [doc.problem(at, "an event needs one trigger: 'at: TIME' or 'when: {near: PLACE}'" if not triggers
                                  else "an event has one trigger: 'at:' or 'when:', not both",
                                  "e.g. - {at: 30 s, gps: lost, for: 10 s}")]
    if len(happening) != 1:
        return None, [doc.problem(at, "an event needs one thing that happens" if not happening else
                                  f"an event has one thing that happens, not {len(happening)} "
                                  f"({', '.join(happening)}): write one event for each",
                                  f"one of: {', '.join(HAPPENINGS)}")]
    if "at" in raw:
        trigger = Trigger(at_s=_si(doc, at + ("at",), raw["at"], "duration"))
    else:
        near = str(raw["when"]["near"])
        if places is not None and near not in places:
            return None, [doc.problem(at + ("when", "near"), f"the mission has no place '{near}'",
                                      _choices(near, sorted(places), "its places", "it has no places"))]
        within = raw["when"].get("within", DEFAULT_NEAR_M)
        trigger = Trigger(near=near, within_m=_si(doc, at + ("when", "within"), within, "distance"))
    what = happening[0]
    value = raw[what]
    params: dict[str, Any] = {}
    if what == "gps":
        kind = "gps_lost" if value == "lost" else "gps_jump"
        if kind == "gps_jump":
            params["jump_m"] = _si(doc, at + ("gps", "jump"), value["jump"], "distance")
    elif what == "lidar":
        kind = "lidar_silent"
    elif what == "battery":
        text = str(value).strip()
        if text.endswith("%"):
            share = float(text[:-1])
            if not 0 <= share <= 100:
                return None, [doc.problem(at + ("battery",), f"'{text}' is not a charge from 0 % to 100 %")]
            volts = BATTERY_EMPTY_V + share / 100.0 * (BATTERY_FULL_V - BATTERY_EMPTY_V)
        else:
            volts = _si(doc, at + ("battery",), text, "voltage")
        kind, params["battery_v"] = "battery", volts
    elif what == "person":
        kind = "person"
        params = {"from_xy": tuple(float(v) for v in value["from"]), "to_xy": tuple(float(v) for v in value["to"]),
                  "speed_mps": _si(doc, at + ("person", "speed"), value.get("speed", DEFAULT_PERSON_SPEED_MPS),
                                   "speed"),
                  "gives_way": bool(value.get("gives_way", True))}
        if params["speed_mps"] <= 0:
            return None, [doc.problem(at + ("person", "speed"), "a person's speed must be more than 0")]
    elif what == "operator":
        kind = str(value)
    else:
        kind = "estop"
    lasts = kind in DEFAULT_FOR_S
    if "for" in raw and not lasts:
        return None, [doc.problem(at + ("for",), f"'for:' is how long a fault lasts; '{what}: {value}' does not last",
                                  "'for:' goes with gps, lidar and operator: pause", key=True)]
    for_s = _si(doc, at + ("for",), raw["for"], "duration") if "for" in raw else DEFAULT_FOR_S.get(kind, 0.0)
    if lasts and for_s <= 0:
        return None, [doc.problem(at + ("for",), "'for:' must be more than 0")]
    return TestEvent(trigger, Fault(kind, params, for_s), i), []


def _unknown_steps(doc: SourceDoc, mission: Any, robot: str, names: list[str]) -> list[Problem]:
    """Problems for substituted step names that no node of the mission's tree has (the tree of ``beastbt tree``)."""
    if not names:
        return []
    from beastbt.assembly import compile_for_profile
    from beastbt.robot.profile import load_profile
    root = compile_for_profile(mission, load_profile(robot))
    nodes = sorted({n.name for n in root.iterate()})
    out = []
    for name in names:
        if not any(matches(name, node) for node in nodes):
            steps = [n for n in nodes if not n.startswith("mission ")]
            out.append(doc.problem(("substitute", name), f"the mission's tree has no step '{name}'",
                                   f"its steps (beastbt tree): {', '.join(steps)}{did_you_mean(name, steps)}",
                                   key=True))
    return out


def matches(written: str, node_name: str) -> bool:
    """Whether a substitution written ``written`` names the node ``node_name``: the same, or the same before its
    bracket (``go_to bench`` names ``go_to bench (within 2 m)``)."""
    return node_name == written or node_name.startswith(written + " (")


__all__ = ["faults_from", "MissionTest", "TestEvent", "Trigger", "Fault", "Substitution", "Expectations", "Bound", "load_test",
           "find_tests", "matches", "SUFFIX", "SCHEMA"]
