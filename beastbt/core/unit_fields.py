"""Values with units in robot profiles and world files: ``rate_hz: 20 Hz``, ``timeout_s: 500 ms``, ``pan_min_deg: -1 rad``.

A profile or world field names its unit in its suffix (``_m``, ``_s``,
``_hz``, ``_mps``, ``_deg``...), and a bare number is in that unit. A
string with a unit is accepted too, with the same unit kinds as missions,
and converted to the field's unit before the file is checked; a wrong unit
is an error at the value's line and column.
"""

from __future__ import annotations

import math
from typing import Any

from beastbt.core.errors import Problem
from beastbt.core.units import UnitError, parse_quantity
from beastbt.core.yaml_source import PathKey, SourceDoc

SUFFIX_UNITS: dict[str, tuple[str, float]] = {
    "_m": ("distance", 1.0),
    "_s": ("duration", 1.0),
    "_ms": ("duration", 1000.0),
    "_hz": ("frequency", 1.0),
    "_mps": ("speed", 1.0),
    "_deg": ("angle", 180.0 / math.pi),
    "_rad": ("angle", 1.0),
    "_dps": ("turn_rate", 180.0 / math.pi),
    "_rps": ("turn_rate", 1.0),
    "_v": ("voltage", 1.0),
}
"""Field-name suffix -> (unit kind, factor from SI to the field's unit)."""


def _kind_of(key: str) -> tuple[str, float] | None:
    if "_per_" in key:
        return None  # a rate of something (drain_v_per_s, jump_rate_per_s): its own unit
    for suffix in sorted(SUFFIX_UNITS, key=len, reverse=True):
        if key.endswith(suffix):
            return SUFFIX_UNITS[suffix]
    return None


def read_unit_values(doc: SourceDoc) -> list[Problem]:
    """Turn every string with a unit under a unit-suffixed key of ``doc`` into a number of that field's unit.

    Modifies ``doc.data`` in place; returns the values that could not be read.
    """
    problems: list[Problem] = []

    def convert(value: Any, path: PathKey, kind: str, factor: float) -> Any:
        if isinstance(value, str):
            try:
                return parse_quantity(value, kind) * factor
            except UnitError as exc:
                problems.append(doc.problem(path, f"'{path[-1] if isinstance(path[-1], str) else path[-2]}': {exc}"))
                return value
        if isinstance(value, list):
            return [convert(v, path + (i,), kind, factor) for i, v in enumerate(value)]
        return value

    def walk(node: Any, path: PathKey) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                found = _kind_of(str(key))
                if found is not None and isinstance(value, (str, list)):
                    node[key] = convert(value, path + (key,), *found)
                else:
                    walk(value, path + (key,))
        elif isinstance(node, list):
            for i, item in enumerate(node):
                walk(item, path + (i,))

    walk(doc.data, ())
    return problems


__all__ = ["read_unit_values", "SUFFIX_UNITS"]
