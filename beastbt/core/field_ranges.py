"""The range each field of the input schemas allows, in words, to say what a refused number should have been.

``lat: .nan`` is refused by the YAML loader before any schema is applied; this
module lets its message say "'lat' is a number from -90 to 90" by looking the
field's name up in every schema of ``schemas/`` (only when all uses of the
name agree). It reads the schema files itself so that the YAML loader can use
it without importing the schema checker, which reads files through the loader.
"""

from __future__ import annotations

import json
from functools import lru_cache
from typing import Any, Optional

from beastbt.core.resources import data_dir
from beastbt.core.units import KINDS


def _range_words(node: dict, defs: dict) -> Optional[str]:
    """What range a schema property allows, in words ("a number from -90 to 90"); "" for a number without one; None
    for a property that is no number (text, a mapping)."""
    ref = str(node.get("$ref", ""))
    if ref.startswith("#/$defs/") and ref.rsplit("/", 1)[-1] not in KINDS and isinstance(defs.get(ref[8:]), dict):
        node = {**defs[ref[8:]], **{k: v for k, v in node.items() if k != "$ref"}}
    if "anyOf" in node and "type" not in node:
        said = [w for w in (_range_words(b, defs) if isinstance(b, dict) else None for b in node["anyOf"]) if w]
        constants = [f"'{b['const']}'" for b in node["anyOf"] if isinstance(b, dict) and "const" in b]
        return " or ".join(said + constants) if said else None
    low = node.get("minimum", node.get("exclusiveMinimum"))
    high = node.get("maximum", node.get("exclusiveMaximum"))
    whole = "a whole number" if node.get("type") == "integer" else "a number"
    if low is not None and high is not None:
        return f"{whole} from {_num(low)} to {_num(high)}"
    if "x-unit-max" in node:
        return f"an angle from -{node['x-unit-max']} to {node['x-unit-max']}"
    kind = node.get("x-unit-kind") or (ref.rsplit("/", 1)[-1] if ref.startswith("#/$defs/") else None)
    if kind in KINDS:
        return f"a {kind.replace('_', ' ')} (e.g. '{KINDS[kind].example}') of at most {KINDS[kind].max_said}"
    types = node.get("type")
    types = types if isinstance(types, list) else [types]
    if "number" not in types and "integer" not in types:
        return None
    if low is not None:
        return f"{whole} of at least {_num(low)}"
    if high is not None:
        return f"{whole} of at most {_num(high)}"
    return ""


@lru_cache(maxsize=None)
def _field_ranges() -> dict[str, frozenset[str]]:
    """Every numeric property name of the input schemas, with the ranges its occurrences allow ("" for none)."""
    out: dict[str, set[str]] = {}

    def walk(node: Any, defs: dict) -> None:
        if isinstance(node, dict):
            props = node.get("properties")
            if isinstance(props, dict):
                for key, sub in props.items():
                    words = _range_words(sub, defs) if isinstance(sub, dict) else None
                    if words is not None:
                        out.setdefault(key, set()).add(words)
            for value in node.values():
                walk(value, defs)
        elif isinstance(node, list):
            for value in node:
                walk(value, defs)

    root = data_dir("schemas")
    for entry in sorted(list(root.glob("*.json")) + list(root.glob("parts/*.json"))):
        if entry.name != "summary.schema.json":  # what a run writes, not what a user does
            schema = json.loads(entry.read_text(encoding="utf-8"))
            walk(schema, schema.get("$defs") or {})
    return {k: frozenset(v) for k, v in out.items()}


def field_range(key: str) -> Optional[str]:
    """The range a field named ``key`` allows wherever the schemas use it (``lat`` -> "a number from -90 to 90"),
    or None when they say none or do not agree; used to word a refused number (``lat: .nan``)."""
    words = _field_ranges().get(key, frozenset())
    return next(iter(words)) if len(words) == 1 and "" not in words else None


def _num(value: Any) -> str:
    """A schema bound as a person writes it (1000000, not 1e+06)."""
    return str(int(value)) if isinstance(value, (int, float)) and float(value).is_integer() else f"{value:g}"


__all__ = ["field_range"]
