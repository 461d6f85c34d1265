"""Values with units, as mission authors write them: ``3 m``, ``500 ms``, ``0.2 m/s``, ``90 deg``.

Every value is converted to SI (metres, seconds, m/s, radians, rad/s, hertz,
volts, fraction 0-1). A bare number is accepted only where the language says
so (distances, durations, speeds, frequencies, voltages, fractions); angles and
turn rates must carry their unit. Errors are :class:`UnitError` with a message
that names the kind that was expected.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Union

_NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?"
_VALUE = re.compile(rf"^\s*({_NUMBER})\s*([A-Za-z%/°][A-Za-z%/°0-9]*)?\s*$")


@dataclass(frozen=True)
class UnitKind:
    """A kind of quantity: its name, its SI unit, the units it accepts and their factors."""

    name: str
    si_unit: str
    factors: dict
    bare_allowed: bool
    example: str


KINDS: dict[str, UnitKind] = {
    "distance": UnitKind("distance", "m", {"m": 1.0, "cm": 0.01, "mm": 0.001, "km": 1000.0}, True, "3 m"),
    "duration": UnitKind(
        "duration", "s", {"s": 1.0, "ms": 0.001, "min": 60.0, "h": 3600.0}, True, "2 s"
    ),
    "speed": UnitKind(
        "speed", "m/s", {"m/s": 1.0, "cm/s": 0.01, "mm/s": 0.001, "km/h": 1.0 / 3.6}, True, "0.2 m/s"
    ),
    "angle": UnitKind("angle", "rad", {"deg": math.pi / 180.0, "°": math.pi / 180.0, "rad": 1.0}, False, "90 deg"),
    "turn_rate": UnitKind(
        "turn_rate", "rad/s", {"deg/s": math.pi / 180.0, "rad/s": 1.0}, False, "45 deg/s"
    ),
    "frequency": UnitKind("frequency", "Hz", {"Hz": 1.0, "hz": 1.0, "kHz": 1000.0}, True, "20 Hz"),
    "voltage": UnitKind("voltage", "V", {"V": 1.0, "mV": 0.001}, True, "11.1 V"),
    "fraction": UnitKind("fraction", "", {"%": 0.01}, True, "20 %"),
    "pulse": UnitKind("pulse", "s", {"ms": 0.001, "us": 1e-6, "µs": 1e-6, "s": 1.0}, False, "1.5 ms"),
}

_UNIT_TO_KIND: dict[str, str] = {}
for _kind in KINDS.values():
    for _unit in _kind.factors:
        _UNIT_TO_KIND.setdefault(_unit, _kind.name)


UNIT_SYNONYMS: dict[str, str] = {
    "meter": "m", "meters": "m", "metre": "m", "metres": "m", "mtr": "m",
    "centimeter": "cm", "centimeters": "cm", "centimetre": "cm", "centimetres": "cm",
    "millimeter": "mm", "millimeters": "mm", "millimetre": "mm", "millimetres": "mm",
    "kilometer": "km", "kilometers": "km", "kilometre": "km", "kilometres": "km",
    "sec": "s", "secs": "s", "second": "s", "seconds": "s",
    "msec": "ms", "millisecond": "ms", "milliseconds": "ms",
    "minute": "min", "minutes": "min", "mins": "min", "m": "min",
    "hour": "h", "hours": "h", "hr": "h", "hrs": "h",
    "mps": "m/s", "m/sec": "m/s", "kmh": "km/h", "kph": "km/h", "km/hr": "km/h",
    "degree": "deg", "degrees": "deg", "degs": "deg", "radian": "rad", "radians": "rad",
    "dps": "deg/s", "deg/sec": "deg/s", "degrees/s": "deg/s", "rad/sec": "rad/s",
    "hertz": "Hz", "khz": "kHz", "volt": "V", "volts": "V", "v": "V", "millivolt": "mV",
    "percent": "%", "pct": "%",
}
"""Units authors write for the ones the language knows: a did-you-mean, never accepted silently."""
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d+,\d+")


class UnitError(ValueError):
    """A value could not be read as the expected kind of quantity."""


def _describe(kind: UnitKind) -> str:
    units = ", ".join(k for k in kind.factors if k != "°")
    name = kind.name.replace("_", " ")
    article = "an" if name[0] in "aeiou" else "a"
    return f"{article} {name} such as '{kind.example}' (units: {units})"


def parse_quantity(value: Union[str, int, float], kind: str) -> float:
    """Read ``value`` as a quantity of ``kind`` and return it in SI units.

    ``kind`` is one of :data:`KINDS` (distance, duration, speed, angle,
    turn_rate, frequency, voltage, fraction, pulse). Raises :class:`UnitError`
    naming what was expected.
    """
    k = KINDS[kind]
    if isinstance(value, bool):
        raise UnitError(f"expected {_describe(k)}, got {value!r}")
    if isinstance(value, (int, float)):
        if not k.bare_allowed:
            raise UnitError(f"{kind.replace('_', ' ')} needs a unit: write '{value} {k.example.split()[1]}', not a bare number")
        v = float(value)
        if kind == "fraction" and not 0.0 <= v <= 1.0:
            raise UnitError(f"a bare fraction must be between 0 and 1 (or write a percentage like '20 %'), got {value}")
        return v
    if not isinstance(value, str):
        raise UnitError(f"expected {_describe(k)}, got {type(value).__name__}")
    m = _VALUE.match(value)
    if not m:
        if _DECIMAL_COMMA.match(value):
            fixed = value.replace(",", ".", 1)
            raise UnitError(f"'{value}' has a decimal comma: write '{fixed.strip()}' (a point, not a comma)")
        raise UnitError(f"expected {_describe(k)}, got '{value}'")
    number, unit = float(m.group(1)), m.group(2)
    if unit is None:
        return parse_quantity(number, kind)
    if unit in k.factors:
        return number * k.factors[unit]
    other = _UNIT_TO_KIND.get(unit)
    if other is not None:
        raise UnitError(f"expected {_describe(k)}, got '{value}', which is a {other.replace('_', ' ')}")
    meant = UNIT_SYNONYMS.get(unit) or UNIT_SYNONYMS.get(unit.lower())
    if meant is None or meant not in k.factors:
        from beastbt.core.errors import closest
        meant = closest(unit, [u for u in k.factors if u != "°"])
    if meant in k.factors:
        raise UnitError(f"unknown unit '{unit}' in '{value}'; did you mean '{m.group(1)} {meant}'? "
                        f"Expected {_describe(k)}")
    raise UnitError(f"unknown unit '{unit}' in '{value}': expected {_describe(k)}")


def parse_duration(value: Union[str, int, float]) -> float:
    """Read a duration (``2 s``, ``500 ms``, ``5 min``) and return seconds."""
    return parse_quantity(value, "duration")


def parse_count(value: Union[str, int]) -> int:
    """Read a count: a positive whole number, or ``forever`` (returned as -1)."""
    if value == "forever":
        return -1
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise UnitError(f"expected a whole number of at least 1 or 'forever', got {value!r}")
    return value


def format_quantity(si_value: float, kind: str) -> str:
    """Write an SI value back the way an author would read it (``3 m``, ``90 deg``, ``0.15 m/s``)."""
    if kind == "angle":
        return f"{math.degrees(si_value):g} deg"
    if kind == "turn_rate":
        return f"{math.degrees(si_value):g} deg/s"
    if kind == "fraction":
        return f"{si_value * 100:g} %"
    if kind == "pulse":
        return f"{si_value * 1000:g} ms"
    return f"{si_value:g} {KINDS[kind].si_unit}"
