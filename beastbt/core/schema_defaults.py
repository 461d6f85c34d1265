"""One source of defaults: a config dataclass takes its field defaults from its JSON Schema.

Every knob of a robot profile, a world or the recording has its default
stated once, as the ``default`` of its property in ``schemas/`` (where
editors show it, and where ``docs/`` and the tests read it). A config
dataclass names its schema with :func:`schema_defaults`, applied under
``@dataclass``::

    @dataclass
    @schema_defaults("parts/watchdog.schema.json")
    class WatchdogConfig:
        timeout_s: float
        \"\"\"Seconds without a fresh command before the watchdog sends zero itself.\"\"\"

and its fields get their defaults from there when the module is imported
(``WatchdogConfig()`` works as before; ``dataclasses.fields`` shows the
schema's values). A field whose property has no ``default`` is an error at
import, naming the schema and the field, unless the class says why in
``computed`` (a value computed in code, a nested config with its own schema,
a constant). A list for a field annotated as a tuple becomes a tuple; other
lists and mappings become fresh copies per instance (a ``default_factory``);
``convert`` turns a JSON value into the field's Python form (a mapping with
integer keys).
"""

from __future__ import annotations

import copy
import dataclasses
import json
from functools import lru_cache
from typing import Any, Callable, Mapping, Optional, TypeVar

from beastbt.core.resources import data_dir

T = TypeVar("T")


@lru_cache(maxsize=None)
def schema_document(name: str) -> dict:
    """The schema ``name`` (``parts/watchdog.schema.json``) as a dict, read once per process."""
    node: Any = data_dir("schemas")
    for part in name.split("/"):
        node = node / part
    return json.loads(node.read_text(encoding="utf-8"))


def schema_properties(ref: str) -> dict[str, dict]:
    """The ``properties`` of ``ref``: a schema name, optionally with a JSON pointer to an object schema
    (``x.json#/properties/m``) or straight to its properties (``x.json#/properties``)."""
    name, _, pointer = ref.partition("#")
    node: Any = schema_document(name)
    parts = [p for p in pointer.split("/") if p]
    for part in parts:
        node = node[int(part)] if isinstance(node, list) else node[part]
    return node if parts and parts[-1] == "properties" else node.get("properties", {})


def schema_default(ref: str, field_name: str) -> Any:
    """The ``default`` of property ``field_name`` in ``ref``; KeyError when it states none."""
    prop = schema_properties(ref).get(field_name)
    if prop is None or "default" not in prop:
        raise KeyError(f"{ref} states no default for '{field_name}'")
    return prop["default"]


def _tupled(value: Any) -> Any:
    return tuple(_tupled(v) for v in value) if isinstance(value, list) else value


def schema_defaults(ref: str, computed: Optional[Mapping[str, str]] = None,
                    convert: Optional[Mapping[str, Callable[[Any], Any]]] = None,
                    required: tuple[str, ...] = ()) -> Callable[[type[T]], type[T]]:
    """Class decorator (under ``@dataclass``): every annotated field's default is its property's ``default`` in ``ref``.

    ``computed``: fields whose default stays in code, each with the reason
    (they must then have one in the class). ``convert``: field -> function
    from the JSON value to the field's value. ``required``: fields the author
    must always give (the schema requires them and states no default).
    """
    computed = dict(computed or {})
    convert = dict(convert or {})

    def apply(cls: type[T]) -> type[T]:
        props = schema_properties(ref)
        for name, annotation in cls.__dict__.get("__annotations__", {}).items():
            if name.startswith("_") or name.isupper() or "ClassVar" in str(annotation):
                continue  # class constants, not fields
            if name in required:
                if name in cls.__dict__ or "default" in props.get(name, {}):
                    raise TypeError(f"{cls.__name__}.{name}: marked required, but a default is stated")
                continue
            if name in computed:
                if name not in cls.__dict__:
                    raise TypeError(f"{cls.__name__}.{name}: marked computed ({computed[name]}) but has no default")
                continue
            prop = props.get(name)
            if prop is None or "default" not in prop:
                raise TypeError(f"{cls.__name__}.{name}: {ref} states no default for '{name}'; add one there "
                                f"(or list the field in computed= with the reason)")
            if name in cls.__dict__:
                raise TypeError(f"{cls.__name__}.{name}: the default is stated in the code and in {ref}; "
                                f"keep only the schema's")
            value = prop["default"]
            if name in convert:
                value = convert[name](value)
            elif isinstance(value, list) and str(annotation).replace("Optional[", "").lower().startswith("tuple"):
                value = _tupled(value)  # JSON has lists; a tuple field stays a (hashable, shared) tuple
            if isinstance(value, (list, dict)):
                setattr(cls, name, dataclasses.field(default_factory=lambda v=value: copy.deepcopy(v)))
            else:
                setattr(cls, name, value)
        cls.__schema__ = ref  # type: ignore[attr-defined]
        return cls

    return apply


__all__ = ["schema_defaults", "schema_default", "schema_properties", "schema_document"]
