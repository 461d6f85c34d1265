"""JSON Schema validation with answers a person can act on.

The schemas in ``schemas/`` are the contract (and what editors use through the
``# yaml-language-server: $schema=`` comment). jsonschema finds every error;
this module turns each into a :class:`Problem` at the right line and column,
naming what was expected and, for a misspelt word, the closest valid one. For
the ``anyOf`` of steps and conditions it picks the branch the author meant
(from the step's keyword) instead of listing every alternative.
"""

from __future__ import annotations

import copy
import math
import re
from functools import lru_cache
from typing import Any, Iterable, Optional

import jsonschema
from referencing import Registry, Resource
from referencing.jsonschema import DRAFT202012

from beastbt.core.errors import Position, Problem, did_you_mean, value_in_words
from beastbt.core.resources import data_dir
from beastbt.core.schema_defaults import schema_document
from beastbt.core.units import DECIMAL_COMMA, KINDS, UNIT_TO_KIND, UnitError, parse_quantity
from beastbt.core.yaml_source import SourceDoc

_TYPE_WORDS = {
    "object": "a mapping (key: value)", "array": "a list", "string": "text", "number": "a number",
    "integer": "a whole number", "boolean": "true or false", "null": "nothing",
}


@lru_cache(maxsize=None)
def _schema_texts() -> dict[str, dict]:
    # Parsed through schema_document: the config dataclasses' defaults have read several of these files already.
    root = data_dir("schemas")
    out: dict[str, dict] = {}
    for entry in root.iterdir():
        if entry.name.endswith(".json"):
            out[entry.name] = schema_document(entry.name)
    parts = root / "parts"
    if parts.is_dir():
        for entry in parts.iterdir():
            if entry.name.endswith(".json"):
                out["parts/" + entry.name] = schema_document("parts/" + entry.name)
    return out


def load_schema(name: str) -> dict:
    """Return the schema ``name`` (e.g. ``mission.schema.json``) as a dict."""
    return _schema_texts()[name]


_BASE_URI = "https://beastbt.dev/schemas/"


@lru_cache(maxsize=None)
def _registry() -> Registry:
    # Without their "$schema": jsonschema would validate a referenced part with the plain Draft 2020-12 class that
    # names, not with the extended one (the range keywords below); every schema here is 2020-12.
    resources_ = [(_BASE_URI + key, Resource.from_contents(_without_dialect(doc), default_specification=DRAFT202012))
                  for key, doc in _schema_texts().items()]
    return Registry().with_resources(resources_)


def _unit_in_range(validator: Any, kind: Any, instance: Any, schema: dict) -> Iterable[jsonschema.ValidationError]:
    """The ``x-unit-kind`` keyword: a value of the right form ('3 m', or a bare number where one is allowed) must also
    be finite and within what its kind can mean (``1e400 m``, ``1e308 deg`` and ``.nan`` are refused here)."""
    if kind not in KINDS or isinstance(instance, bool):
        return
    types = schema.get("type")
    types = types if isinstance(types, list) else [types]
    if isinstance(instance, (int, float)):
        if "number" not in types and "integer" not in types:
            return  # the type check says what is wrong
    elif not (isinstance(instance, str) and re.search(schema.get("pattern", ""), instance)):
        return  # not of the form: the pattern check says it
    try:
        parse_quantity(instance, kind)
    except UnitError as exc:
        yield jsonschema.ValidationError(str(exc))


def _unit_max(validator: Any, most: Any, instance: Any, schema: dict) -> Iterable[jsonschema.ValidationError]:
    """The ``x-unit-max`` keyword (``"360 deg"``): a field's own bound, tighter than its kind's, either way."""
    kind = UNIT_TO_KIND.get(str(most).split()[-1])
    if kind is None or isinstance(instance, bool) or not isinstance(instance, (str, int, float)):
        return
    try:
        value, bound = parse_quantity(instance, kind), parse_quantity(most, kind)
    except UnitError:
        return  # the form or the kind's range is reported by x-unit-kind
    if abs(value) > bound:
        yield jsonschema.ValidationError(f"expected {kind.replace('_', ' ')} from -{most} to {most}, got '{instance}'")


KNOB_UNITS: dict[str, tuple[str, float]] = {
    "metres": ("distance", 1.0), "seconds": ("duration", 1.0), "milliseconds": ("duration", 0.001),
    "hertz": ("frequency", 1.0), "metres per second": ("speed", 1.0), "degrees": ("angle", math.pi / 180.0),
    "radians": ("angle", 1.0), "degrees per second": ("turn_rate", math.pi / 180.0),
    "radians per second": ("turn_rate", 1.0), "volts": ("voltage", 1.0),
}
"""A profile or world knob's unit (``x-knob-unit``) -> (its kind, factor from the knob's unit to SI)."""


def _knob_in_range(validator: Any, unit: Any, instance: Any, schema: dict) -> Iterable[jsonschema.ValidationError]:
    """The ``x-knob-unit`` keyword: a knob's bare number (or a text already converted to one) must be finite and
    within what its kind can mean (a ``timeout_s`` of at most a week, a ``track_width_m`` of at most 1000 km)."""
    if unit not in KNOB_UNITS or isinstance(instance, bool) or not isinstance(instance, (int, float)):
        return
    kind, factor = KNOB_UNITS[unit]
    most = KINDS[kind].max_si / factor
    if not math.isfinite(float(instance)) or abs(instance) > most:
        yield jsonschema.ValidationError(f"{instance:g} {unit} is out of range: at most {_num(round(most, 6))} "
                                         f"{unit} either way ({KINDS[kind].max_said})")


def _num(value: Any) -> str:
    """A schema bound as a person writes it (1000000, not 1e+06)."""
    return str(int(value)) if isinstance(value, (int, float)) and float(value).is_integer() else f"{value:g}"


_Validator = jsonschema.validators.extend(jsonschema.Draft202012Validator,
                                          {"x-unit-kind": _unit_in_range, "x-unit-max": _unit_max,
                                           "x-knob-unit": _knob_in_range})


def validator_of(schema: dict, name: str) -> jsonschema.Draft202012Validator:
    """A validator for ``schema`` (the schema ``name``, possibly extended); relative ``$ref`` resolve. It also checks
    that values with units are finite and within their kind's range (``x-unit-kind``)."""
    schema = _without_dialect(schema)
    schema.setdefault("$id", _BASE_URI + name)
    return _Validator(schema, registry=_registry())


def _without_dialect(schema: dict) -> dict:
    """A copy of ``schema`` without its ``$schema`` key (see :func:`_registry`)."""
    return {k: v for k, v in schema.items() if k != "$schema"}


@lru_cache(maxsize=None)
def validator_for(name: str) -> jsonschema.Draft202012Validator:
    """A cached validator for schema ``name``; relative ``$ref`` to ``parts/*.json`` resolve."""
    return validator_of(load_schema(name), name)


EXCLUSIVE_KEYS = (
    ("angle", "heading", "angle: turn by that much (positive: left); heading: turn to that compass heading"),
    ("distance", "time", "distance: drive that far; time: drive for that long"),
)
"""Keys that choose between forms of a step: written together, the author gets this, not 'unknown key'."""

_WHAT_IT_IS = {"then": ": the steps to run when the condition holds", "steps": ": the steps to run",
               "else": ": the steps to run when the condition does not hold"}


def _what_it_is(key: str) -> str:
    return _WHAT_IT_IS.get(key, "")


def _step_keyword(instance: Any, schema: dict) -> Optional[str]:
    """The step a mapping is (its first required key, when that key is written), or None."""
    required = schema.get("required") or []
    if isinstance(instance, dict) and required and required[0] in instance:
        return str(required[0])
    return None


@lru_cache(maxsize=None)
def _step_words() -> frozenset:
    """The mission's step keywords (``drive``, ``wait``...), the first required key of each step's form."""
    forms = load_schema("mission.schema.json").get("$defs", {}).get("step", {}).get("anyOf", [])
    return frozenset(str(b["required"][0]) for b in forms if isinstance(b, dict) and b.get("required"))


def _where(path: tuple) -> str:
    for part in reversed(path):
        if isinstance(part, str):
            return f" in '{part}'"
    return ""


def _touches(err: jsonschema.ValidationError, subtree: tuple) -> bool:
    """True when ``err`` is at or under ``subtree``, or is a choice (oneOf, anyOf) above it that failed for something
    at or under it: a step's oneOf says that a step is wrong at the step, not at the key inside it that is."""
    path = tuple(err.absolute_path)
    if path[:len(subtree)] == subtree:
        return True
    if subtree[:len(path)] == path and err.validator in ("oneOf", "anyOf"):
        return any(_touches(sub, subtree) for sub in err.context or ())
    return False


class _Explainer:
    def __init__(self, doc: SourceDoc, what: str,
                 validator: Optional[jsonschema.Draft202012Validator] = None) -> None:
        self.doc = doc
        self.what = what
        self.validator = validator
        self.reindented: dict[tuple, Problem] = {}
        """Mappings whose unknown keys are a matter of indentation: path -> the one problem that says so."""

    def problems(self, errors: Iterable[jsonschema.ValidationError]) -> list[Problem]:
        out: list[Problem] = []
        for err in errors:
            out.extend(self.explain(err))
        return out

    # -- helpers --------------------------------------------------------
    def at(self, path: tuple, message: str, hint: Optional[str] = None, key: bool = False) -> Problem:
        return self.doc.problem(path, message, hint, key=key)

    def explain(self, err: jsonschema.ValidationError) -> list[Problem]:
        path = tuple(err.absolute_path)
        schema = err.schema if isinstance(err.schema, dict) else {}
        v = err.validator
        if "x-unit-kind" in schema and v in ("anyOf", "oneOf", "type", "pattern", "x-unit-kind"):
            return [self.unit_problem(path, err.instance, schema["x-unit-kind"], schema.get("patternErrorMessage"),
                                      ranged=v == "x-unit-kind", schema_comment=schema.get("$comment"))]
        if v == "x-knob-unit":
            said = str(schema.get("patternErrorMessage", "")).removeprefix("Expected ").rstrip(".")
            return [self.at(path, f"{_where(path).replace(' in ', '', 1)}: {err.message}".lstrip(": "),
                            f"write {said}" if said else None)]
        if v == "x-unit-max":
            label = f"'{path[-1]}': " if path and isinstance(path[-1], str) else ""
            return [self.at(path, f"{label}{err.message}", self.describe(schema))]
        if "x-knob-unit" in schema and v == "type":
            # a profile or world knob named with its unit (timeout_s), whose texts ('500 ms') were read before this
            said = str(schema.get("patternErrorMessage", "")).removeprefix("Expected ").rstrip(".")
            return [self.at(path, f"expected a number{_where(path)}, got {value_in_words(err.instance)}",
                            f"write {said}" if said else None)]
        if v in ("anyOf", "oneOf"):
            return self.explain_alternatives(err, path, schema)
        if v == "additionalProperties":
            return self.unknown_keys(err, path, schema)
        if v == "required":
            missing = err.message.split("'")[1] if "'" in err.message else err.message
            step = _step_keyword(err.instance, schema) if path else None
            if step is not None and step != missing:
                return [self.at(path, f"'{step}' needs '{missing}:'{_what_it_is(missing)}",
                                self.required_hint(missing, schema) or f"add '{missing}:' under '{step}'")]
            return [self.at(path, f"missing '{missing}'{_where(path)}", self.required_hint(missing, schema))]
        if v == "type":
            expected = schema.get("type")
            words = " or ".join(_TYPE_WORDS.get(t, t) for t in (expected if isinstance(expected, list) else [expected]))
            hint = self.describe(schema)
            if isinstance(err.instance, bool) and "string" in (expected if isinstance(expected, list) else [expected]):
                hint = "YAML reads yes, no, on, off, true and false as true/false: put the text in quotes"
            if path and path[-1] in ("times", "loops") and isinstance(err.instance, str):
                return [self.at(path, f"'{path[-1]}' is a whole number or 'forever', got '{err.instance}'",
                                f"write '{path[-1]}: forever' to repeat without end, or a number such as "
                                f"'{path[-1]}: 3'")]
            if isinstance(err.instance, str) and "number" in words and DECIMAL_COMMA.match(err.instance):
                fixed = err.instance.strip().replace(",", ".", 1)
                return [self.at(path, f"'{err.instance}'{_where(path)} has a decimal comma",
                                f"write {fixed} (a point, not a comma), without quotes")]
            return [self.at(path, f"expected {words}{_where(path)}, got {value_in_words(err.instance)}", hint)]
        if v in ("enum", "const") and path and path[-1] == "until" and isinstance(err.instance, dict):
            choices = schema.get("enum", [schema.get("const")])
            amount = next(iter(err.instance), "")
            value = err.instance.get(amount, 3) if amount else 3
            number = value if isinstance(value, (int, float)) else str(value).split()[0] if str(value).split() else 3
            return [self.at(path, f"'until' takes {', '.join(map(str, choices))}, {{distance: ...}} or {{time: ...}}; "
                                  f"'{amount}' is not one of them",
                            f"to stop after a distance write until: {{distance: {number} m}}; after a time, "
                            f"until: {{time: 10 s}}")]
        if v in ("enum", "const"):
            choices = schema.get("enum", [schema.get("const")])
            word = err.instance if isinstance(err.instance, str) else None
            msg = f"{value_in_words(err.instance)} is not allowed{_where(path)}: expected one of {', '.join(map(str, choices))}"
            if word:
                msg += did_you_mean(word, [str(c) for c in choices])
            return [self.at(path, msg)]
        if v == "pattern":
            return [self.at(path, f"{value_in_words(err.instance)} is not a valid name{_where(path)}",
                            "names use letters (of any alphabet), digits, _ and -, and start with a letter")]
        if v == "propertyNames":
            return [self.at(path + (err.instance,), f"'{err.instance}' is not a valid name{_where(path)}",
                            "names use letters (of any alphabet), digits, _ and -, and start with a letter", key=True)]
        if v in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
            bound = {"minimum": "at least", "maximum": "at most", "exclusiveMinimum": "more than",
                     "exclusiveMaximum": "less than"}[v]
            return [self.at(path, f"{err.instance} is out of range{_where(path)}: must be {bound} {err.validator_value}",
                            self.describe(schema))]
        if v == "minItems" and isinstance(err.instance, list) and err.instance:
            return [self.at(path, f"{_where(path).strip().replace('in ', '', 1) or 'this'} needs at least "
                                  f"{err.validator_value} items, has {len(err.instance)}", self.describe(schema))]
        if v == "maxItems" and isinstance(err.instance, list):
            what = _where(path).strip().replace('in ', '', 1) or 'this'
            most = err.validator_value
            takes = f"exactly {most}" if schema.get("minItems") == most else f"at most {most}"
            return [self.at(path, f"{what} takes {takes} items, has {len(err.instance)}", self.describe(schema))]
        if v in ("minItems", "minProperties"):
            return [self.at(path, f"{_where(path).strip() or 'this'} is empty".replace("in ", "", 1), self.describe(schema))]
        return [self.at(path, err.message, self.describe(schema))]

    def describe(self, schema: dict) -> Optional[str]:
        desc = schema.get("description")
        return desc if desc else None

    def required_hint(self, missing: str, schema: dict) -> Optional[str]:
        props = schema.get("properties", {}).get(missing, {})
        if self.what == "mission" and missing == "mission":
            return "start the file with 'mission: <a name>'"
        if self.what == "mission" and missing == "steps":
            return "add 'steps:' followed by the list of what the robot does"
        return props.get("description") if isinstance(props, dict) else None

    def unit_problem(self, path: tuple, value: Any, kind: str, expected: Optional[str] = None, ranged: bool = False,
                     schema_comment: Optional[str] = None) -> Problem:
        try:
            parse_quantity(value, kind)
            message = f"{value_in_words(value)} is not a valid {kind.replace('_', ' ')}"
        except UnitError as exc:
            message = str(exc)
        except KeyError:  # a kind the unit parser does not read (acceleration): the schema's own words
            said = (expected or f"Expected a valid {kind.replace('_', ' ')}").split(";")[0].rstrip(".")
            message = f"{said[0].lower()}{said[1:]}, got {value_in_words(value)}"
        label = f"'{path[-1]}': " if path and isinstance(path[-1], str) else ""
        # The hint says what the kind is, its range included (the definition's comment).
        return self.at(path, f"{label}{message}", schema_comment)

    def unknown_keys(self, err: jsonschema.ValidationError, path: tuple, schema: dict) -> list[Problem]:
        inst = err.instance
        for a, b, words in EXCLUSIVE_KEYS:
            if isinstance(inst, dict) and a in inst and b in inst:
                return [self.at(path + (b,), f"'{path[-1] if path else 'this'}' takes either '{a}' or '{b}', not both",
                                words, key=True)]
        allowed = list(schema.get("properties", {}))
        extras = [k for k in err.instance if k not in allowed] if isinstance(err.instance, dict) else []
        out = []
        required = schema.get("required") or []
        where = _where(path)
        if required and path and isinstance(path[-1], int) and self.what == "mission" and required[0] in _step_words():
            where = f" in the '{required[0]}' step"
        if extras and isinstance(inst, dict):
            indent = self.indentation(path, inst, extras)
            if indent is not None:
                self.reindented[path] = indent
                return [indent]
        for key in extras:
            msg = f"unknown key '{key}'{where}{did_you_mean(key, allowed)}"
            out.append(self.at(path + (key,), msg, f"allowed here: {', '.join(allowed)}", key=True))
        return out

    # -- keys at the wrong indentation -----------------------------------------------------------------------
    def _fits_with(self, path: tuple, changed: Any, subtree: tuple) -> bool:
        """True when the document with ``changed`` at ``path`` has no problem left at or under ``subtree``."""
        if self.validator is None:
            return False
        data = copy.deepcopy(self.doc.data)
        if path:
            node = data
            for part in path[:-1]:
                node = node[part]
            node[path[-1]] = changed
        else:
            data = changed
        return not any(_touches(e, subtree) for e in self.validator.iter_errors(data))

    def indentation(self, path: tuple, inst: dict, extras: list) -> Optional[Problem]:
        """A problem saying "indent it" when the unknown ``extras`` of the mapping at ``path`` would be right one
        level deeper (under one of their siblings) or one level shallower (beside the mapping's own key)."""
        keys = ", ".join(f"'{k}'" for k in extras)
        them = "it" if len(extras) == 1 else "them"
        first = self.doc.position(path + (extras[0],), key=True)
        if any(self.doc.position(path + (k,), key=True).line == first.line for k in inst if k not in extras):
            return None  # beside a sibling on one line: a flow mapping ({tag: 3, qr: x}), where indentation says nothing
        for owner, value in inst.items():
            if owner in extras or not (isinstance(value, dict) or value is None):
                continue
            moved = {k: v for k, v in inst.items() if k not in extras}
            moved[owner] = {**(value or {}), **{k: inst[k] for k in extras}}
            if self._fits_with(path, moved, path):
                inner = [self.doc.position(path + (owner, k), key=True) for k in (value or {})]
                owner_at = self.doc.position(path + (owner,), key=True)
                column = inner[0].column if inner else owner_at.column + 2
                spaces = column - first.column
                how = (f"{spaces} more space{'s' if spaces != 1 else ''}, to line up with "
                       f"'{next(iter(value))}:' on line {inner[0].line}" if inner and spaces > 0
                       else "further than it, e.g. 2 more spaces")
                return self.at(path + (extras[0],), f"{keys} belong{'s' if len(extras) == 1 else ''} under "
                                                    f"'{owner}:' (line {owner_at.line}): indent {them} {how}",
                               "in YAML the indentation says what belongs to what", key=True)
        if len(path) >= 2 and isinstance(path[-1], str):
            parent_path = path[:-1]
            parent = self.doc.data
            for part in parent_path:
                parent = parent[part]
            if isinstance(parent, dict) and not any(k in parent for k in extras):
                here = dict(parent)
                here[path[-1]] = {k: v for k, v in inst.items() if k not in extras}
                here.update({k: inst[k] for k in extras})
                if self._fits_with(parent_path, here, parent_path):
                    beside = self.doc.position(path, key=True)
                    spaces = first.column - beside.column
                    how = f"{spaces} fewer space{'s' if spaces != 1 else ''}, " if spaces > 0 else ""
                    return self.at(path + (extras[0],), f"{keys} belong{'s' if len(extras) == 1 else ''} beside "
                                                        f"'{path[-1]}:', not under it: indent {them} {how}to line "
                                                        f"up with '{path[-1]}:' on line {beside.line}",
                                   "in YAML the indentation says what belongs to what", key=True)
        return None

    def explain_alternatives(self, err: jsonschema.ValidationError, path: tuple, schema: dict) -> list[Problem]:
        branches = schema.get(err.validator, [])
        kind = schema.get("x-kind")
        inst = err.instance
        by_branch: dict[int, list[jsonschema.ValidationError]] = {}
        for sub in err.context or []:
            by_branch.setdefault(sub.relative_schema_path[0], []).append(sub)
        if kind in ("step", "condition"):
            return self.explain_keyword_choice(err, path, branches, by_branch, kind)
        # A word or one of several mappings, each named by its own key (sees: motion, {tag: 3}, {qr: ...}): a mapping
        # with none of those keys is a misspelt key, not a wrong word (the word's branch has the fewest errors).
        forms = [b for b in branches if isinstance(b, dict) and b.get("type") == "object" and b.get("required")]
        words = [str(b["const"]) for b in branches if isinstance(b, dict) and "const" in b]
        if (len(forms) >= 2 and words and len(forms) + len(words) == len(branches) and isinstance(inst, str)
                and inst not in words):  # a word that is none of them: say the mappings it could have been too
            return [self.at(path, f"{value_in_words(inst)} is not allowed{_where(path)}: expected one of "
                                  f"{', '.join(words)}{did_you_mean(inst, words)}",
                            "or a mapping: " + ", ".join(f"{{{b['required'][0]}: ...}}" for b in forms))]
        if (len(forms) >= 2 and words and len(forms) + len(words) == len(branches) and isinstance(inst, dict) and inst
                and path and isinstance(path[-1], str)):
            keys = [str(b["required"][0]) for b in forms]
            first = str(next(iter(inst)))
            written = [k for k in keys if k in inst]
            if not any(set(b.get("properties", {})) & set(inst) for b in forms):
                return [self.at(path + (first,), f"unknown key '{first}'{_where(path)}{did_you_mean(first, keys)}",
                                f"allowed here: {', '.join(keys)}; or, instead of a mapping, {' or '.join(words)}",
                                key=True)]
            if len(written) >= 2:  # two forms in one mapping ({sees: {tag: 3, qr: x}})
                a, b = written[:2]
                return [self.at(path + (b,), f"'{path[-1]}' takes one of {', '.join(keys)}, not both '{a}' and '{b}'",
                                f"for both, write all: [{{{path[-1]}: {{{a}: ...}}}}, {{{path[-1]}: {{{b}: ...}}}}]",
                                key=True)]
        chosen = self.pick_branch(inst, branches, by_branch)
        if chosen is not None and chosen in by_branch:
            return self.problems(by_branch[chosen])
        alts = "; or ".join(filter(None, (self.describe(b) or "" for b in branches)))
        return [self.at(path, f"{value_in_words(inst)} does not fit{_where(path)}", alts or self.describe(schema))]

    @staticmethod
    def pick_branch(inst: Any, branches: list, by_branch: dict) -> Optional[int]:
        def type_ok(b: dict) -> bool:
            t = b.get("type")
            if "$ref" in b or t is None:
                return True
            return {"object": isinstance(inst, dict), "array": isinstance(inst, list), "string": isinstance(inst, str)}.get(t, True)
        candidates = [i for i, b in enumerate(branches) if isinstance(b, dict) and type_ok(b)]
        if isinstance(inst, (dict, list)):
            # a mapping where one shape of mapping or a word (none) is allowed means that shape: explain its keys,
            # not "a mapping is not allowed" (where several shapes are, the words' explanation lists them all)
            shaped = [i for i in candidates if "const" not in branches[i] and "enum" not in branches[i]]
            if len(shaped) == 1:
                candidates = shaped
        if isinstance(inst, dict):
            keyed = [i for i in candidates if set(branches[i].get("required", [])) <= set(inst) and branches[i].get("required")]
            if keyed:
                candidates = keyed
            else:
                overlap = [(len(set(branches[i].get("properties", {})) & set(inst)), i) for i in candidates]
                if overlap and max(overlap)[0] > 0:
                    best = max(overlap)[0]
                    candidates = [i for n, i in overlap if n == best]
        if not candidates:
            return None
        return min(candidates, key=lambda i: len(by_branch.get(i, [])))

    def explain_keyword_choice(self, err, path, branches, by_branch, kind) -> list[Problem]:
        inst = err.instance
        words: list[str] = []
        keyed: dict[str, int] = {}
        for i, b in enumerate(branches):
            if "const" in b:
                words.append(b["const"])
            for w in b.get("enum", []):
                words.append(w)
            if b.get("required"):
                keyed[b["required"][0]] = i
                words.append(b["required"][0])
        label = "step" if kind == "step" else "condition"
        listing = ", ".join(dict.fromkeys(words))
        if isinstance(inst, str):
            hint = f"the {label}s are: {listing}"
            if inst in keyed:
                return [self.at(path, f"'{inst}' needs a value here (write '{inst}: ...')", self.describe(branches[keyed[inst]]))]
            return [self.at(path, f"unknown {label} '{inst}'{did_you_mean(inst, words)}", hint)]
        if isinstance(inst, dict):
            present = [k for k in inst if k in keyed]
            if not present:
                first = next(iter(inst), "")
                if not first:
                    return [self.at(path, f"empty {label}", f"the {label}s are: {listing}")]
                head = str(first).replace("{", " ").replace("[", " ").split()
                if head and head[0] in words and head[0] != str(first):
                    at = self.doc.position(path + (first,), key=True)
                    return [Problem(self.doc.file, Position(at.line, at.column + len(head[0])),
                                    f"missing ':' after '{head[0]}'",
                                    f"write '{head[0]}: ' (with a space after the colon) before its settings")]
                return [self.at(path + (first,), f"unknown {label} '{first}'{did_you_mean(str(first), words)}",
                                f"the {label}s are: {listing}", key=True)]
            if len(present) > 1 and not all(k in ("then", "else", "steps", "timeout") for k in present[1:]):
                return [self.at(path + (present[1],), f"one {label} per list item: found both '{present[0]}' and '{present[1]}'",
                                "start each step with its own '- '", key=True)]
            return self.problems(by_branch.get(keyed[present[0]], [])) or [
                self.at(path, f"invalid '{present[0]}' {label}", self.describe(branches[keyed[present[0]]]))]
        return [self.at(path, f"expected a {label}, got {value_in_words(inst)}", f"the {label}s are: {listing}")]


def schema_problems(doc: SourceDoc, schema_name: str, what: str, schema: Optional[dict] = None) -> list[Problem]:
    """Validate ``doc`` against ``schema_name`` (or ``schema``, an extension of it); every problem, explained."""
    validator = validator_for(schema_name) if schema is None else validator_of(schema, schema_name)
    explainer = _Explainer(doc, what, validator)
    problems = explainer.problems(validator.iter_errors(doc.data))
    if not explainer.reindented:
        return problems
    # A key at the wrong indentation upsets its mapping in several ways (a step without its steps, a keyword
    # with nothing under it): once "indent it" is said, the rest about that mapping is noise.
    inside: set = set()
    for path in explainer.reindented:
        n = len(path)
        inside |= {(doc.file, pos) for p, pos in doc.positions.items() if p[:n] == path}
        inside |= {(doc.file, pos) for p, pos in doc.key_positions.items() if p[:n] == path}
    said = set(map(id, explainer.reindented.values()))
    return [p for p in problems if id(p) in said or (p.file, p.position) not in inside]
