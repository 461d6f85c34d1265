"""Mission steps from other packages: the ``beastbt.steps`` entry points, loaded by keyword when a mission uses one.

A package adds a step by naming, in its ``pyproject.toml``::

    [project.entry-points."beastbt.steps"]
    blink = "beastbt_blinker:BlinkStep"

an object (a class is instantiated) with ``schema``, the JSON Schema of the
step's value (what the author writes after ``blink:``), and
``build(compiler, step)``, which returns the py_trees behaviour of one such
step (``step.value`` is the value as written, already validated against
``schema``; ``compiler.ctx`` is the run's context and services). Nothing is
loaded unless a mission uses a keyword the language does not know; a core
keyword cannot be taken by a package. See ``docs/extending.md``.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Callable, Collection, Iterable, Mapping

from beastbt.core.values import Value

STEP_ENTRY_POINTS = "beastbt.steps"
"""Entry-point group of steps from other packages: ``keyword = "package.module:StepClass"``."""


@dataclass(eq=False, repr=False)  # frozen, compared and printed by core.values.Value
class ExternalStep(Value):
    """A step keyword provided by an installed package: its value's schema and its builder."""

    keyword: str
    schema: Mapping[str, Any]
    build: Callable[[Any, Any], Any]
    """``build(compiler, step) -> py_trees Behaviour``."""
    provider: str
    """The entry point's target (``package.module:Name``), for messages."""


def step_keywords_in(data: Any, known: Collection[str]) -> set[str]:
    """Keywords written where a step goes (a one-key mapping in a list) that are not in ``known``."""
    found: set[str] = set()

    def walk(node: Any, in_list: bool) -> None:
        if isinstance(node, dict):
            if in_list and node:
                first = next(iter(node))
                if isinstance(first, str) and first not in known:
                    found.add(first)
            for value in node.values():
                walk(value, False)
        elif isinstance(node, list):
            for item in node:
                walk(item, True)

    walk(data, False)
    return found


def load_external_steps(keywords: Iterable[str], core: Collection[str]) -> dict[str, ExternalStep]:
    """The installed steps among ``keywords`` (others are left for the schema to report as unknown)."""
    wanted = set(keywords) - set(core)
    if not wanted:
        return {}
    from importlib import metadata  # only for a mission with a keyword the core lacks: it costs milliseconds

    out: dict[str, ExternalStep] = {}
    for ep in metadata.entry_points(group=STEP_ENTRY_POINTS):
        if ep.name in wanted and ep.name not in out:
            obj = ep.load()
            plugin = obj() if isinstance(obj, type) else obj
            schema, build = getattr(plugin, "schema", None), getattr(plugin, "build", None)
            if not isinstance(schema, Mapping) or not callable(build):
                raise TypeError(f"step '{ep.name}' ({ep.value}) needs a 'schema' mapping and a 'build(compiler, step)'")
            out[ep.name] = ExternalStep(ep.name, schema, build, ep.value)
    return out


def with_external_steps(mission_schema: Mapping[str, Any], steps: Mapping[str, ExternalStep]) -> dict[str, Any]:
    """The mission schema with one more step alternative per external step (``{keyword: value-schema}``)."""
    schema = copy.deepcopy(dict(mission_schema))
    branches = schema["$defs"]["step"]["anyOf"]
    for keyword, step in steps.items():
        branches.append({"type": "object", "additionalProperties": False, "required": [keyword],
                         "properties": {keyword: dict(step.schema)},
                         "description": str(step.schema.get("description", f"'{keyword}' from {step.provider}"))})
    return schema


__all__ = ["ExternalStep", "STEP_ENTRY_POINTS", "step_keywords_in", "load_external_steps", "with_external_steps"]
