"""Building configuration dataclasses from plain dicts (a robot profile's YAML).

Used by the ``from_dict`` class methods of the device and actuator configs
(PCA9685, servos, PWM base, CAN base, joystick, teleop). It rejects a
misspelt knob with a clear ``ValueError`` that names the closest valid one,
checks each value against the field's type (an ``int`` is accepted for a
``float``; a ``bool`` is never accepted as a number), and leaves range checks
to each dataclass's ``__post_init__``.
"""

from __future__ import annotations

import math

import dataclasses
import typing
from collections.abc import Mapping
from typing import Any, Optional, TypeVar

from beastbt.core.errors import value_in_words

T = TypeVar("T")


def _type_ok(value: Any, hint: Any) -> bool:
    """True when ``value`` fits the type annotation ``hint`` (the few shapes configs use)."""
    origin = typing.get_origin(hint)
    if origin is typing.Union:
        return any(_type_ok(value, arg) for arg in typing.get_args(hint))
    if origin is typing.Literal:
        return value in typing.get_args(hint)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is str:
        return isinstance(value, str)
    return True  # anything fancier is checked by the dataclass itself


def _describe(hint: Any) -> str:
    """A short human name for a type annotation, for error messages."""
    origin = typing.get_origin(hint)
    if origin is typing.Union:
        return " or ".join(_describe(a) for a in typing.get_args(hint))
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(hint))
    if hint is type(None):
        return "null"
    return getattr(hint, "__name__", str(hint))


def _coerce(value: Any, hint: Any) -> Any:
    """Turn an ``int`` into a ``float`` where the field is a float (YAML writes ``1`` for ``1.0``)."""
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    origin = typing.get_origin(hint)
    if origin is typing.Union:
        args = typing.get_args(hint)
        if float in args and int not in args and isinstance(value, int) and not isinstance(value, bool):
            return float(value)
    return value


def dataclass_from_dict(cls: type[T], data: Any, what: str) -> T:
    """Build the dataclass ``cls`` from the mapping ``data``.

    ``what`` names the config in error messages (``"can_base"``). Raises
    ``ValueError`` for a non-mapping, an unknown key (with a suggestion), a
    value of the wrong type, or whatever ``cls.__post_init__`` rejects.
    """
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ValueError(f"{what}: expected a mapping of settings, got {value_in_words(data)}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key not in fields:
            import difflib  # only for a misspelt key

            close = difflib.get_close_matches(str(key), list(fields), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ValueError(f"{what}: unknown key '{key}'{hint} (known keys: {', '.join(sorted(fields))})")
        hint_t = hints.get(key, Any)
        if not _type_ok(value, hint_t):
            raise ValueError(f"{what}.{key}: expected {_describe(hint_t)}, got {value!r}")
        kwargs[key] = _coerce(value, hint_t)
    try:
        return cls(**kwargs)
    except ValueError as exc:
        text = str(exc)
        raise ValueError(text if text.startswith(what) else f"{what}: {text}") from None


def check_config_keys(data: Any, cls: type, what: str) -> None:
    """Refuse a non-mapping or keys that are not fields of the dataclass ``cls``; ``what`` names the config.

    Raises ``ValueError`` ("{what} config must be a mapping ..." or "unknown {what} config key(s): ...").
    """
    if not isinstance(data, dict):
        raise ValueError(f"{what} config must be a mapping, got {value_in_words(data)}")
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"unknown {what} config key(s): {', '.join(map(str, unknown))} "
                         f"(known: {', '.join(sorted(known))})")


def require_number(name: str, value: Any, *, minimum: Optional[float] = None, positive: bool = False) -> float:
    """``value`` as a float, or a ValueError naming ``name`` when it is not a finite number in range."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if positive and value <= 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if minimum is not None and value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value!r}")
    return float(value)
