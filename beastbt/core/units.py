"""Values with units, as mission authors write them: ``3 m``, ``500 ms``, ``0.2 m/s``, ``90 deg``.

Every value is converted to SI (metres, seconds, m/s, radians, rad/s, hertz,
volts, fraction 0-1). A bare number is accepted only where the language says
so (distances, durations, speeds, frequencies, voltages, fractions); angles and
turn rates must carry their unit. Errors are :class:`UnitError` with a message
that names the kind that was expected.

Every value must be finite and, whatever its field, within the magnitude its
kind can mean (:attr:`UnitKind.max_si`: at most 1000 km, a week, 50 m/s, ten
full turns...); a field's own range (a latitude, a pan) is checked where the
field is. So no ``inf``, ``nan`` or ``1e308 deg`` ever reaches a behaviour.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Union

from beastbt.core.errors import value_in_words

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
    max_si: float = math.inf
    """Largest magnitude (in the SI unit) a value of this kind can mean anywhere in beastbt."""
    max_said: str = ""
    """:attr:`max_si` as an author would write it, for messages."""


KINDS: dict[str, UnitKind] = {
    "distance": UnitKind("distance", "m", {"m": 1.0, "cm": 0.01, "mm": 0.001, "km": 1000.0}, True, "3 m",
                         1e6, "1000 km"),
    "duration": UnitKind(
        "duration", "s", {"s": 1.0, "ms": 0.001, "min": 60.0, "h": 3600.0}, True, "2 s", 7 * 24 * 3600.0,
        "a week (168 h)"
    ),
    "speed": UnitKind(
        "speed", "m/s", {"m/s": 1.0, "cm/s": 0.01, "mm/s": 0.001, "km/h": 1.0 / 3.6}, True, "0.2 m/s",
        50.0, "50 m/s (180 km/h)"
    ),
    "angle": UnitKind("angle", "rad", {"deg": math.pi / 180.0, "°": math.pi / 180.0, "rad": 1.0}, False, "90 deg",
                      math.radians(3600.0), "3600 deg (ten full turns)"),
    "turn_rate": UnitKind(
        "turn_rate", "rad/s", {"deg/s": math.pi / 180.0, "rad/s": 1.0}, False, "45 deg/s", math.radians(3600.0),
        "3600 deg/s"
    ),
    "frequency": UnitKind("frequency", "Hz", {"Hz": 1.0, "hz": 1.0, "kHz": 1000.0}, True, "20 Hz", 1e9,
                          "1000000 kHz (1 GHz)"),
    "voltage": UnitKind("voltage", "V", {"V": 1.0, "mV": 0.001}, True, "11.1 V", 1000.0, "1000 V"),
    "fraction": UnitKind("fraction", "", {"%": 0.01}, True, "20 %", 10.0, "1000 %"),
    "pulse": UnitKind("pulse", "s", {"ms": 0.001, "us": 1e-6, "µs": 1e-6, "s": 1.0}, False, "1.5 ms", 1.0, "1 s"),
}
"""The kinds of quantity, with the units each accepts and the largest magnitude it can mean (documented in
docs/mission-language.md, 'Limits', and in the schemas' unit definitions)."""

MAX_COUNT = 1_000_000
"""Most times a ``repeat``, ``retry`` or ``route`` may run (``forever`` is the word for without end)."""

_UNIT_TO_KIND: dict[str, str] = {}
for _kind in KINDS.values():
    for _unit in _kind.factors:
        _UNIT_TO_KIND.setdefault(_unit, _kind.name)
UNIT_TO_KIND = _UNIT_TO_KIND
"""Each unit's kind (``"deg"`` -> ``"angle"``; a unit two kinds share, such as ``ms``, goes to the first)."""


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
DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d+,\d+")
"""A text that starts like a number written with a decimal comma (``0,5 m``, ``40,4169``)."""


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
            raise UnitError(f"{kind.replace('_', ' ')} needs a unit: write '{_number_text(value)} "
                            f"{k.example.split()[1]}', not a bare number")
        if kind == "fraction" and not 0.0 <= value <= 1.0:  # compared before float(): NaN and huge ints fail here
            raise UnitError(f"a bare fraction must be between 0 and 1 (or write a percentage like '20 %'), "
                            f"got {_number_text(value)}")
        return _within(value, 1.0, k, _number_text(value))
    if not isinstance(value, str):
        raise UnitError(f"expected {_describe(k)}, got {value_in_words(value)}")
    m = _VALUE.match(value)
    if not m:
        if DECIMAL_COMMA.match(value):
            fixed = value.replace(",", ".", 1)
            raise UnitError(f"'{value}' has a decimal comma: write '{fixed.strip()}' (a point, not a comma)")
        raise UnitError(f"expected {_describe(k)}, got '{value}'")
    number, unit = float(m.group(1)), m.group(2)
    if unit is None:
        if not math.isfinite(number) and k.bare_allowed:  # '1e400': say what was written, not 'inf'
            raise UnitError(f"expected {_describe(k)}, a finite number, got '{value.strip()}'")
        return parse_quantity(number, kind)
    if unit in k.factors:
        text = value.strip()
        return _within(number, k.factors[unit], k, f"'{text}'" if len(text) <= 24 else
                       f"'{text[:10]}...{text[-8:]}' ({len(m.group(1))} characters of number)")
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


def _number_text(value: Union[int, float]) -> str:
    """A number as a message shows it (a huge whole number by its size, not its 400 digits)."""
    if isinstance(value, int) and abs(value) >= 10 ** 16:
        digits = len(str(abs(value))) if abs(value) < 10 ** 4000 else "4000-plus"  # str() refuses beyond 4300
        return f"{'minus ' if value < 0 else ''}a {digits}-digit number"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _within(number: Union[int, float], factor: float, k: UnitKind, written: str) -> float:
    """``number`` times ``factor`` (SI), if finite and within what ``k`` can mean; else a :class:`UnitError`."""
    try:
        si = float(number) * factor
    except OverflowError:  # an int beyond what a float holds
        si = math.inf
    if not math.isfinite(si) and not isinstance(number, int):
        raise UnitError(f"expected {_describe(k)}, a finite number, got {written}")
    if abs(si) > k.max_si:
        raise UnitError(f"expected {_describe(k)} of at most {k.max_said} in size, got {written}")
    return si


def parse_duration(value: Union[str, int, float]) -> float:
    """Read a duration (``2 s``, ``500 ms``, ``5 min``) and return seconds."""
    return parse_quantity(value, "duration")


def parse_count(value: Union[str, int]) -> int:
    """Read a count: a positive whole number, or ``forever`` (returned as -1)."""
    if value == "forever":
        return -1
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise UnitError(f"expected a whole number of at least 1 or 'forever', got {value!r}")
    if value > MAX_COUNT:
        raise UnitError(f"expected a whole number from 1 to {MAX_COUNT:,} or 'forever', got {_number_text(value)}")
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
