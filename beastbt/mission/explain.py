"""``beastbt validate --explain STEP``: a short help for one step, taken from the mission schema's descriptions."""

from __future__ import annotations

from typing import Any, Optional

from beastbt.core.errors import did_you_mean
from beastbt.core.schema_check import load_schema


def _resolve(node: Any, defs: dict) -> Any:
    if isinstance(node, dict) and "$ref" in node and node["$ref"].startswith("#/$defs/"):
        target = dict(defs[node["$ref"].rsplit("/", 1)[1]])
        target.update({k: v for k, v in node.items() if k != "$ref"})
        return target
    return node


def _forms(node: Any, defs: dict) -> list[dict]:
    node = _resolve(node, defs)
    if isinstance(node, dict) and ("oneOf" in node or "anyOf" in node):
        out: list[dict] = []
        for branch in node.get("oneOf", node.get("anyOf", [])):
            out.extend(_forms(branch, defs))
        return out
    return [node] if isinstance(node, dict) else []


def _value_words(node: dict) -> str:
    if "const" in node:
        return repr(node["const"])
    if "enum" in node:
        return " | ".join(map(str, node["enum"]))
    if "x-unit-kind" in node:
        kind = node["x-unit-kind"].replace("_", " ")
        return f"{'an' if kind[0] in 'aeiou' else 'a'} {kind}"
    kind = node.get("type")
    return {"object": "settings", "array": "a list", "string": "text", "integer": "a whole number",
            "number": "a number", "boolean": "true or false"}.get(kind if isinstance(kind, str) else "", "a value")


def _described(node: dict) -> str:
    """': its description, e.g. its first example' (or less, when the schema states less)."""
    text = node.get("description") or ""
    examples = node.get("examples") or []
    if examples and not isinstance(examples[0], (dict, list)) and str(examples[0]) not in text:
        text = f"{text.rstrip('.')}; e.g. {examples[0]}" if text else f"e.g. {examples[0]}"
    return f": {text}" if text else ""


def steps_and_help() -> dict[str, tuple[str, list[dict], dict]]:
    """Every step keyword -> (its description, the forms its value may take, the keys written beside it)."""
    schema = load_schema("mission.schema.json")
    defs = schema["$defs"]
    out: dict[str, tuple[str, list[dict], dict]] = {}
    for branch in defs["step"]["anyOf"]:
        if "const" in branch:
            out[branch["const"]] = (branch.get("description", ""), [], {})
            continue
        props = branch.get("properties") or {}
        required = branch.get("required") or list(props)[:1]
        if not required or required[0] not in props:
            continue
        keyword = required[0]
        value = props[keyword]
        forms = _forms(value, defs)
        description = branch.get("description") or _resolve(value, defs).get("description") or next(
            (f.get("description") for f in forms if f.get("description")), "")
        beside = {k: _resolve(v, defs) for k, v in props.items() if k != keyword}
        out[keyword] = (description, forms, beside)
    return out


def explain_step(keyword: str) -> Optional[str]:
    """The help text of step ``keyword``, or None when there is no such step."""
    known = steps_and_help()
    if keyword not in known:
        return None
    description, forms, beside = known[keyword]
    schema = load_schema("mission.schema.json")
    defs = schema["$defs"]
    lines = [f"{keyword}: {description}".rstrip(": ")]
    if not forms:
        lines.append(f"  write it alone:  - {keyword}")
    for i, form in enumerate(forms, 1):
        label = f"form {i}" if len(forms) > 1 else "takes"
        props = form.get("properties") or {}
        if not props:
            lines.append(f"  {label}: {_value_words(form)}{_described(form)}")
            continue
        required = set(form.get("required") or [])
        lines.append(f"  {label}:" + (f" {form['description']}" if form.get("description") else ""))
        for name, sub in props.items():
            sub = _resolve(sub, defs)
            need = "required" if name in required else "optional"
            lines.append(f"    {name} ({need}, {_value_words(sub)}){_described(sub)}")
    for name, sub in beside.items():
        lines.append(f"  with {name}: ({_value_words(sub)}){_described(sub)}")
    lines.append("  more: docs/mission-language.md")
    return "\n".join(lines)


def unknown_step_message(keyword: str) -> str:
    """What to say for ``--explain`` of a word that is not a step."""
    steps = list(steps_and_help())
    return f"'{keyword}' is not a step{did_you_mean(keyword, steps)} (the steps are: {', '.join(steps)})"


__all__ = ["explain_step", "steps_and_help", "unknown_step_message"]
