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
