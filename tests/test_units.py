"""Values with units: conversion to SI and the errors for the wrong kind."""

import math

import pytest

from beastbt.core.units import UnitError, format_quantity, parse_count, parse_quantity


@pytest.mark.parametrize("text,kind,si", [
    ("3 m", "distance", 3.0), ("30 cm", "distance", 0.3), ("1.2 km", "distance", 1200.0), (2, "distance", 2.0),
    ("500 ms", "duration", 0.5), ("5 min", "duration", 300.0), ("1 h", "duration", 3600.0),
    ("20 cm/s", "speed", 0.2), ("1.8 km/h", "speed", 0.5), ("90 deg", "angle", math.pi / 2),
    ("1.57 rad", "angle", 1.57), ("45 deg/s", "turn_rate", math.pi / 4), ("20 Hz", "frequency", 20.0),
    ("11.1 V", "voltage", 11.1), ("20 %", "fraction", 0.2), ("1.5 ms", "pulse", 0.0015), ("-3 m", "distance", -3.0),
])
def test_values_convert_to_si(text, kind, si):
    assert parse_quantity(text, kind) == pytest.approx(si)


@pytest.mark.parametrize("text,kind,words", [
    ("3 s", "distance", "which is a duration"), (90, "angle", "needs a unit"), ("3 furlongs", "distance", "unknown unit"),
    ("fast", "speed", "expected a speed"), (1.5, "fraction", "between 0 and 1"), (True, "distance", "expected a distance"),
])
def test_wrong_values_name_the_expected_kind(text, kind, words):
    with pytest.raises(UnitError, match=words):
        parse_quantity(text, kind)


def test_counts_and_formatting():
    assert parse_count("forever") == -1 and parse_count(3) == 3
    with pytest.raises(UnitError):
        parse_count(0)
    assert format_quantity(math.pi, "angle") == "180 deg"
    assert format_quantity(0.15, "speed") == "0.15 m/s"
