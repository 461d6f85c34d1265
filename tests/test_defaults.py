"""One source of defaults: every default of a mission, profile or world is stated once, in its JSON Schema.

The config dataclasses read their defaults from the schemas
(:func:`beastbt.core.schema_defaults.schema_defaults`); a mission knob whose
default is the robot's says where it comes from (``x-default-from``). These
tests fail when the code states a default of its own, when a schema's default
does not fit its own property, and when a schema description or the docs
state a default (or a unit) that the schema does not.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
import pkgutil
import re
from pathlib import Path
from typing import Any, Iterator, Optional

import pytest

import beastbt
from beastbt.core.schema_check import validator_of
from beastbt.core.units import UnitError, parse_quantity
from conftest import REPO

SCHEMAS = sorted(p.relative_to(REPO / "schemas").as_posix() for p in (REPO / "schemas").rglob("*.json"))
DOCS = sorted((REPO / "docs").glob("*.md")) + [REPO / "README.md"]
UNIT_KINDS = {"distance", "duration", "speed", "angle", "turn_rate", "frequency", "voltage", "fraction", "pulse"}


def schema(name: str) -> dict:
    return json.loads((REPO / "schemas" / name).read_text(encoding="utf-8"))


def properties_of(name: str) -> Iterator[tuple[str, str, dict]]:
    """(JSON pointer, property name, property schema) for every property of every object in schema ``name``."""
    def walk(node: Any, pointer: str) -> Iterator[tuple[str, str, dict]]:
        if isinstance(node, dict):
            props = node.get("properties")
            if isinstance(props, dict):
                for key, prop in props.items():
                    if isinstance(prop, dict):
                        yield f"{pointer}/properties/{key}", key, prop
            for key, value in node.items():
                yield from walk(value, f"{pointer}/{key}")
        elif isinstance(node, list):
            for i, value in enumerate(node):
                yield from walk(value, f"{pointer}/{i}")
    yield from walk(schema(name), "")


def resolve(ref: str) -> dict:
    """The schema node at ``file#pointer``."""
    name, _, pointer = ref.partition("#")
    node: Any = schema(name)
    for part in filter(None, pointer.split("/")):
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node


def effective_default(prop: dict) -> Optional[Any]:
    """The property's default, following ``x-default-from`` to the robot's knob; None when it has none."""
    if "default" in prop:
        return prop["default"]
    if "x-default-from" in prop:
        return resolve(prop["x-default-from"]).get("default")
    return None


def unit_kind(prop: dict) -> Optional[str]:
    ref = prop.get("$ref", "")
    kind = ref.rsplit("/", 1)[-1] if ref.startswith("#/$defs/") else prop.get("x-unit-kind")
    return kind if kind in UNIT_KINDS else None


# -- the code states no default of its own ---------------------------------------------------------------------

def config_classes() -> list[type]:
    """Every dataclass of beastbt that takes its defaults from a schema."""
    found = []
    for info in pkgutil.walk_packages(beastbt.__path__, "beastbt."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for value in vars(module).values():
            if isinstance(value, type) and dataclasses.is_dataclass(value) and "__schema__" in vars(value) \
                    and value.__module__ == module.__name__:
                found.append(value)
    return found


CONFIGS = config_classes()


def test_the_configs_of_every_profile_section_read_their_schema():
    names = {c.__name__ for c in CONFIGS}
    assert {"WatchdogConfig", "ControlParams", "EkfConfig", "NavConfig", "GpsConfig", "ImuConfig", "CameraConfig",
            "LineDetectorConfig", "FollowLineConfig", "TeleopConfig", "CanBaseConfig", "PwmBaseConfig",
            "WaveshareConfig", "RecordingConfig", "StreamConfig", "DriveModel", "GpsNoiseModel", "ImuNoiseModel",
            "CameraEffects", "JoystickMapping", "Pca9685Config", "CameraMounting", "ServoCalibration"} <= names


@pytest.mark.parametrize("cls", CONFIGS, ids=lambda c: c.__name__)
def test_every_field_default_is_the_schemas(cls):
    name, _, pointer = cls.__schema__.partition("#")
    props = resolve(cls.__schema__) if pointer.endswith("/properties") else resolve(cls.__schema__).get("properties",
                                                                                                          {})
    instance_defaults = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            instance_defaults[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            instance_defaults[f.name] = f.default_factory()
    for field_name, value in instance_defaults.items():
        if field_name not in props or "default" not in props[field_name]:
            continue  # a computed field (the decorator requires the class to say why)
        expected = props[field_name]["default"]
        assert json.loads(json.dumps(value, default=list)) == json.loads(json.dumps(expected)) or \
            (isinstance(value, dict) and {str(k): v for k, v in value.items()} == expected), (cls.__name__, field_name)


def test_a_literal_default_in_the_code_is_refused():
    from beastbt.core.schema_defaults import schema_defaults

    with pytest.raises(TypeError, match="stated in the code and in parts/watchdog.schema.json"):
        @dataclasses.dataclass
        @schema_defaults("parts/watchdog.schema.json")
        class Twice:
            timeout_s: float = 0.5
    with pytest.raises(TypeError, match="states no default for 'cadence_s'"):
        @dataclasses.dataclass
        @schema_defaults("parts/watchdog.schema.json")
        class Unknown:
            cadence_s: float


# -- the schemas' defaults are valid, and their descriptions agree ------------------------------------------------

@pytest.mark.parametrize("name", SCHEMAS)
def test_every_default_fits_its_own_property(name):
    for pointer, key, prop in properties_of(name):
        if "default" in prop:
            check = validator_of({"$ref": f"https://beastbt.dev/schemas/{name}#{pointer}"}, "default-check.json")
            errors = [e.message for e in check.iter_errors(prop["default"])]
            assert not errors, f"{name}#{pointer}: default {prop['default']!r}: {errors}"
        if "x-default-from" in prop:
            assert effective_default(prop) is not None, f"{name}#{pointer}: {prop['x-default-from']} has no default"


NUMBER_UNIT = r"(-?\d+(?:\.\d+)?(?:e-?\d+)?)(?:\s*([A-Za-z/°%][A-Za-z/°%^0-9]*))?"
DEFAULT_IN_TEXT = re.compile(r"\(?\bdefault:?\s+" + NUMBER_UNIT)


def same_number(stated: str, value: float) -> bool:
    """``stated`` (as written, e.g. '1.047') rounds ``value`` to its own precision."""
    decimals = len(stated.split(".")[1]) if "." in stated else 0
    return math.isclose(float(stated), value, rel_tol=1e-9) or abs(float(stated) - value) <= 0.5 * 10 ** -decimals


SUFFIX_KINDS = {"_s": ("duration", 1.0), "_m": ("distance", 1.0), "_mps": ("speed", 1.0), "_rps": ("turn_rate", 1.0),
                "_dps": ("turn_rate", math.pi / 180), "_deg": ("angle", math.pi / 180), "_rad": ("angle", 1.0),
                "_hz": ("frequency", 1.0), "_v": ("voltage", 1.0)}
"""A profile knob's unit, from its name's suffix: (unit kind, factor of its value to SI)."""


def knob_unit(prop: dict, key: str) -> Optional[tuple[str, float]]:
    """(kind, factor to SI) of a number knob: from its own name, or from the robot knob it takes its default from."""
    name = prop["x-default-from"].rsplit("/", 1)[-1] if "x-default-from" in prop else key
    return next((v for suffix, v in SUFFIX_KINDS.items() if name.endswith(suffix)), None)


def agrees(stated_number: str, stated_unit: Optional[str], prop: dict, key: str = "") -> bool:
    """The default stated in prose (a number and maybe a unit) is the property's effective default, in its unit."""
    default = effective_default(prop)
    stated_unit = stated_unit or ""
    if isinstance(default, bool) or default is None:
        return False
    if isinstance(default, str):
        kind = unit_kind(prop)
        if kind is None:
            return default.startswith(stated_number)  # a word or an address: as written
        try:
            return math.isclose(parse_quantity(f"{stated_number} {stated_unit}".strip(), kind),
                                parse_quantity(default, kind), rel_tol=1e-9)
        except UnitError:
            return False
    if not isinstance(default, (int, float)):
        return False
    unit = knob_unit(prop, key)
    if stated_unit and unit is not None:  # '5 s', '50 deg': the same quantity in the knob's unit
        try:
            si = parse_quantity(f"{stated_number} {stated_unit}", unit[0])
        except UnitError:
            return False  # a unit of another kind: '5 m' for a time
        return math.isclose(si, float(default) * unit[1], rel_tol=1e-3)
    return same_number(stated_number, float(default))


@pytest.mark.parametrize("name", SCHEMAS)
def test_descriptions_state_the_schemas_own_default(name):
    wrong = []
    for pointer, key, prop in properties_of(name):
        if "properties" in prop:
            continue  # an object's description may name its members' defaults; they are checked themselves
        match = DEFAULT_IN_TEXT.search(prop.get("description", ""))
        if match and not agrees(match.group(1), match.group(2), prop, key):
            wrong.append(f"{name}#{pointer}: the description says default {match.group(1)} {match.group(2)}, "
                         f"the schema {effective_default(prop)!r}")
    assert not wrong, "\n".join(wrong)


# -- the docs state the schemas' defaults ------------------------------------------------------------------------

def knob_index() -> dict[str, list[dict]]:
    """Property name -> its schemas (every schema, every place it appears)."""
    index: dict[str, list[dict]] = {}
    for name in SCHEMAS:
        for _, key, prop in properties_of(name):
            index.setdefault(key, []).append(prop)
    return index


KNOB_THEN_DEFAULT = re.compile(r"`([a-z_]+)`[^`|\n]{0,40}?\(?\bdefault:?\s+" + NUMBER_UNIT)
"""A backticked knob, then within a few words 'default VALUE UNIT' (in a sentence or a table cell)."""
YAML_COMMENTED = re.compile(r"^\s*-?\s*([a-z_]+):[^#\n]*#[^\n]*?\bdefault:?\s+" + NUMBER_UNIT)
"""A line of a YAML example whose comment states the key's default (``rate: 20 Hz  # ... (default 20 Hz)``)."""


def doc_statements(text: str) -> Iterator[tuple[int, str, str, str]]:
    """(line, knob, number, unit) for every default the text states for a named knob."""
    for lineno, line in enumerate(text.splitlines(), 1):
        for m in KNOB_THEN_DEFAULT.finditer(line):
            yield lineno, m.group(1), m.group(2), m.group(3)
        m = YAML_COMMENTED.match(line)
        if m:
            yield lineno, m.group(1), m.group(2), m.group(3)


def wrong_statements(path: Path, text: str, index: dict[str, list[dict]]) -> list[str]:
    out = []
    for lineno, knob, number, unit in doc_statements(text):
        props = index.get(knob)
        if not props:
            continue  # not a knob of any schema (an option of the command line, a word in prose)
        if not any(agrees(number, unit, p, knob) for p in props):
            have = sorted({repr(effective_default(p)) for p in props})
            out.append(f"{path.name}:{lineno}: `{knob}` default {number} {unit}; the schema says {', '.join(have)}")
    return out


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_the_docs_state_the_schemas_defaults(doc):
    wrong = wrong_statements(doc, doc.read_text(encoding="utf-8"), knob_index())
    assert not wrong, "\n".join(wrong)


def test_the_docs_check_finds_a_wrong_default_or_unit():
    index = knob_index()
    assert wrong_statements(Path("x.md"), "- `check_period_s` (default 0.02 s) is fine; `stuck_after` (default 5 s)\n",
                            index) == []
    bad = wrong_statements(Path("x.md"), "The watchdog: `check_period_s` (default 0.05 s).\n"
                                         "| drive | blocked (no progress for `stuck_after`, default 5 m) |\n"
                                         "rate: 10 Hz      # optional (default 10 Hz)\n", index)
    assert len(bad) == 3, bad
    assert "x.md:3: `rate` default 10 Hz" in bad[2]
    assert "x.md:1: `check_period_s` default 0.05 s" in bad[0] and "x.md:2: `stuck_after` default 5 m" in bad[1]
