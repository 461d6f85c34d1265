"""Tasks with parameters (mission language v2): ``params`` with defaults, ``$name`` in the steps, ``do: {task, ...}``.

Before the mission is checked against its schema, :func:`expand_task_parameters`
checks every parameter use and call, then writes each task's steps with its
defaults in place of the ``$name`` values (so the schema checks a task as it
runs by default), and keeps each call's arguments. :func:`task_steps` gives the
raw steps of a task for one call's arguments, which the loader turns into
typed steps. Rules: every parameter has a default; ``$name`` stands for a
whole value, never part of a text; a parameter keeps the kind of its default
(an angle stays an angle); a wrong kind, an unknown parameter or an
undeclared ``$name`` is an error at the line of the use.
"""

from __future__ import annotations

import copy
from typing import Any, Optional

from beastbt.core.errors import Problem, did_you_mean, value_in_words
from beastbt.core.units import KINDS, UnitError, parse_quantity
from beastbt.core.yaml_source import PathKey, SourceDoc, values_at_key

PARAM_PREFIX = "$"


def kind_of(value: Any) -> str:
    """The kind of a parameter's default: a unit kind (``angle``, ``duration``...), ``number``, ``boolean`` or ``text``."""
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, (int, float)):
        return "number"
    if isinstance(value, str):
        for kind in ("distance", "duration", "speed", "angle", "turn_rate", "frequency", "voltage", "fraction"):
            if not KINDS[kind].bare_allowed or any(value.strip().endswith(u) for u in KINDS[kind].factors):
                try:
                    parse_quantity(value, kind)
                    return kind
                except UnitError:
                    continue
        return "text"
    return "value"


def _fits(value: Any, kind: str) -> bool:
    if kind == "boolean":
        return isinstance(value, bool)
    if kind == "number":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind in ("text", "value"):
        return not isinstance(value, (dict, list))
    try:
        parse_quantity(value, kind)
        return not isinstance(value, bool)
    except UnitError:
        return False


def _substitute(node: Any, values: dict[str, Any]) -> Any:
    if isinstance(node, str) and node.startswith(PARAM_PREFIX) and node[1:] in values:
        return copy.deepcopy(values[node[1:]])
    if isinstance(node, dict):
        return {k: _substitute(v, values) for k, v in node.items()}
    if isinstance(node, list):
        return [_substitute(v, values) for v in node]
    return node


def _references(node: Any, path: PathKey) -> list[tuple[PathKey, str]]:
    out: list[tuple[PathKey, str]] = []
    if isinstance(node, str) and node.startswith(PARAM_PREFIX):
        out.append((path, node[1:]))
    elif isinstance(node, dict):
        for k, v in node.items():
            out.extend(_references(v, path + (k,)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.extend(_references(v, path + (i,)))
    return out


class TaskParameters:
    """The parameterised tasks of one mission: their templates, defaults and kinds, and every call's arguments."""

    def __init__(self) -> None:
        self.templates: dict[str, list] = {}
        self.defaults: dict[str, dict[str, Any]] = {}
        self.kinds: dict[str, dict[str, str]] = {}
        self.calls: dict[PathKey, dict[str, Any]] = {}
        """Path of each ``do:`` with arguments -> the arguments as written."""
        self.said_at_declaration: list[PathKey] = []
        """Uses of a parameter already reported where it is declared (no default): not reported again."""

    def task_steps(self, task: str, args: Optional[dict[str, Any]] = None) -> Optional[list]:
        """The raw steps of ``task`` for a call with ``args`` (defaults for the rest); None for a task without params."""
        if task not in self.templates:
            return None
        return _substitute(self.templates[task], {**self.defaults[task], **(args or {})})


def expand_task_parameters(doc: SourceDoc) -> tuple[TaskParameters, list[Problem]]:
    """Check parameters and calls, and write each parameterised task's steps with its defaults (in ``doc.data``)."""
    params = TaskParameters()
    problems: list[Problem] = []
    data = doc.data if isinstance(doc.data, dict) else {}
    tasks = data.get("tasks") if isinstance(data.get("tasks"), dict) else {}
    for name, task in tasks.items():
        if not (isinstance(task, dict) and isinstance(task.get("params"), dict) and isinstance(task.get("steps"), list)):
            continue
        defaults = task["params"]
        broken: set[str] = set()
        for key, value in list(defaults.items()):
            if value is None or isinstance(value, (dict, list)):
                # The default also gives the parameter its kind: without one, each use would fail on its own
                # with a message about an empty value, far from the mistake. Said once, here, instead.
                what = "has no default" if value is None else f"has {value_in_words(value)} as its default"
                problems.append(doc.problem(("tasks", name, "params", key),
                                            f"parameter '{key}' of task '{name}' {what}",
                                            f"every parameter needs a default, which also gives its kind: "
                                            f"e.g. '{key}: 2 s' or '{key}: 45 deg'", key=value is None))
                del defaults[key]
                broken.add(key)
        params.defaults[name] = dict(defaults)
        params.kinds[name] = {k: kind_of(v) for k, v in defaults.items()}
        params.templates[name] = copy.deepcopy(task["steps"])
        for path, ref in _references(task["steps"], ("tasks", name, "steps")):
            if ref in broken:
                params.said_at_declaration.append(path)
            elif ref not in defaults:
                problems.append(doc.problem(path, f"'${ref}' is not a parameter of task '{name}'"
                                                  f"{did_you_mean(ref, list(defaults))}",
                                            f"its parameters are: {', '.join(defaults) or 'none'}; declare it under "
                                            f"'params:' with a default"))
        task["steps"] = params.task_steps(name)
    for path, call in values_at_key(data, "do"):
        if not isinstance(call, dict):
            continue  # do: NAME, a call without arguments
        task_name = call.get("task")
        if not isinstance(task_name, str) or task_name not in tasks:
            continue  # an unknown task is reported by the loader's own checks
        args = {k: v for k, v in call.items() if k != "task"}
        declared = params.defaults.get(task_name, {})
        for key, value in args.items():
            if key not in declared:
                hint = (f"its parameters are: {', '.join(declared)}" if declared
                        else f"task '{task_name}' takes no parameters")
                problems.append(doc.problem(path + (key,), f"task '{task_name}' has no parameter '{key}'"
                                                           f"{did_you_mean(key, list(declared))}", hint, key=True))
            elif not _fits(value, params.kinds[task_name][key]):
                kind = params.kinds[task_name][key].replace("_", " ")
                problems.append(doc.problem(path + (key,), f"'{key}' of task '{task_name}' is {_article(kind)} {kind} "
                                                           f"(its default is {declared[key]!r}), got {value!r}",
                                            f"write {_article(kind)} {kind} like its default"))
        params.calls[path] = args
    return params, problems


def _article(word: str) -> str:
    return "an" if word[:1] in "aeiou" else "a"


__all__ = ["expand_task_parameters", "TaskParameters", "kind_of"]
