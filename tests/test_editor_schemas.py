"""The schemas as editors use them: every ``$ref`` resolves to a shipped file (no remote address).

Editors with the YAML language server (VS Code YAML, Neovim, ...) read a
schema through the file's first-line comment and resolve its ``$ref`` against
the schema's own location, unless the schema states an ``$id``, which turns
``parts/x.schema.json`` into a web address that does not exist.
"""

from __future__ import annotations

import json
from typing import Any, Iterator

import pytest

from beastbt.core.resources import data_dir

SCHEMA_DIR = data_dir("schemas")


def schema_names() -> list[str]:
    names = [e.name for e in SCHEMA_DIR.iterdir() if e.name.endswith(".json")]
    names += ["parts/" + e.name for e in (SCHEMA_DIR / "parts").iterdir() if e.name.endswith(".json")]
    return sorted(names)


SCHEMAS = schema_names()


def load(name: str) -> dict:
    node: Any = SCHEMA_DIR
    for part in name.split("/"):
        node = node / part
    return json.loads(node.read_text(encoding="utf-8"))


def walk(node: Any, pointer: str = "") -> Iterator[tuple[str, Any]]:
    """(JSON pointer, node) for every node of a schema."""
    yield pointer, node
    if isinstance(node, dict):
        for key, value in node.items():
            yield from walk(value, f"{pointer}/{key}")
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from walk(value, f"{pointer}/{i}")


def follow(name: str, pointer: str) -> Any:
    node: Any = load(name)
    for part in filter(None, pointer.split("/")):
        node = node[int(part)] if isinstance(node, list) else node[part.replace("~1", "/").replace("~0", "~")]
    return node


def target_of(name: str, ref: str) -> tuple[str, str]:
    """The schema name and JSON pointer ``ref`` (written in schema ``name``) points to."""
    file, _, pointer = ref.partition("#")
    if not file:
        return name, pointer
    folder = name.rsplit("/", 1)[0] + "/" if "/" in name else ""
    parts: list[str] = []
    for part in (folder + file).split("/"):
        if part == "..":
            parts.pop()
        elif part not in ("", "."):
            parts.append(part)
    return "/".join(parts), pointer


@pytest.mark.parametrize("name", SCHEMAS)
def test_no_schema_states_an_id_that_would_send_its_refs_to_the_web(name):
    ids = [pointer for pointer, node in walk(load(name)) if isinstance(node, dict) and "$id" in node]
    assert not ids, f"{name}: $id at {ids}: editors would fetch the parts/ schemas from that address"


@pytest.mark.parametrize("name", SCHEMAS)
def test_every_ref_resolves_to_a_shipped_schema(name):
    for pointer, node in walk(load(name)):
        if not (isinstance(node, dict) and isinstance(node.get("$ref"), str)):
            continue
        ref = node["$ref"]
        assert "://" not in ref, f"{name}#{pointer}: {ref} is a remote address"
        target, fragment = target_of(name, ref)
        assert target in SCHEMAS, f"{name}#{pointer}: {ref} names no shipped schema"
        try:
            follow(target, fragment)
        except (KeyError, IndexError, ValueError):
            pytest.fail(f"{name}#{pointer}: {ref}: no such place in {target}")


# -- values with units: a pattern and words an editor shows ----------------------------------------------------

def unit_nodes(name: str) -> Iterator[tuple[str, dict, str]]:
    """(pointer, node, unit kind) for every schema node that takes a value with a unit."""
    from beastbt.core.unit_fields import SUFFIX_UNITS
    defs = load(name).get("$defs", {})
    for pointer, node in walk(load(name)):
        if not isinstance(node, dict):
            continue
        if "x-unit-kind" in node:
            yield pointer, node, node["x-unit-kind"]
        for key, prop in (node.get("properties") or {}).items():
            suffix = next((s for s in sorted(SUFFIX_UNITS, key=len, reverse=True) if key.endswith(s)), None)
            if suffix is None or "_per_" in key or name in ("mission.schema.json", "summary.schema.json") \
                    or not isinstance(prop, dict):
                continue
            ref = prop.get("$ref") or (prop.get("items") or {}).get("$ref", "")
            assert prop.get("type") != "number" and (prop.get("items") or {}).get("type") != "number", \
                f"{name}#{pointer}/properties/{key}: a number knob with a unit in its name takes '500 ms' too: " \
                f"refer to a unit in $defs"
            if ref.startswith("#/$defs/") and "pattern" in defs[ref.rsplit("/", 1)[1]]:
                yield f"{pointer}/properties/{key}", defs[ref.rsplit("/", 1)[1]], SUFFIX_UNITS[suffix][0]


def test_values_with_units_have_a_pattern_and_say_what_they_expect():
    import re
    from beastbt.core.units import KINDS
    seen = set()
    for name in SCHEMAS:
        for pointer, node, kind in unit_nodes(name):
            seen.add(kind)
            where = f"{name}#{pointer}"
            message = node.get("patternErrorMessage", "")
            assert f"{kind.replace('_', ' ')} such as '" in message, f"{where}: {message!r}"
            assert node.get("errorMessage") == message, where
            if kind not in KINDS:
                continue
            for unit in KINDS[kind].factors:
                assert re.match(node["pattern"], f"1.5 {unit}"), f"{where}: '1.5 {unit}' does not match"
            assert not re.match(node["pattern"], "3 meters"), where
            assert f"such as '{KINDS[kind].example}'" in message, f"{where}: {message!r}"
    assert {"distance", "duration", "speed", "angle", "turn_rate", "frequency", "voltage"} <= seen


def test_a_profile_knob_named_with_its_unit_takes_a_value_with_a_unit_in_the_schema_too():
    """``timeout_s: 500 ms`` is read by beastbt (unit_fields), so the schema editors use must not call it wrong."""
    from beastbt.core.schema_check import validator_for
    watchdog = validator_for("parts/watchdog.schema.json")
    assert watchdog.is_valid({"timeout_s": "400 ms"}) and watchdog.is_valid({"timeout_s": 0.4})
    assert not watchdog.is_valid({"timeout_s": "400 meters"})
    robot = load("robot.schema.json")
    assert robot["properties"]["limits"]["properties"]["max_speed_mps"]["$ref"] == "#/$defs/metres_per_second"
