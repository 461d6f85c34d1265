"""The mission steps ``go_to``, ``route`` and ``return_home``, compiled to :class:`GoTo` leaves.

Node names read like the mission: ``go_to b (within 3 m)``,
``route a -> b -> c``, ``return_home (within 2 m)``. A place's tolerance is
the step's ``tolerance`` when given, else the place's own, else the robot's
``navigation.default_tolerance_m`` (2 m). On a robot without a GPS these
steps compile to a leaf that fails at once, saying so.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Mapping, Optional

import py_trees

from beastbt.behaviours.flow import RepeatTimes
from beastbt.behaviours.navigation import GoTo, NavConfig, home_target, place_target
from beastbt.behaviours.operator import NotAvailable
from beastbt.mission.compile import Compiler, StepBuilder
from beastbt.mission.model import HOME, Step, parse_count
from beastbt.core.units import parse_quantity

Behaviour = py_trees.behaviour.Behaviour

_DEFAULT_TOLERANCE_M = NavConfig().default_tolerance_m


def _options(v: Any) -> dict:
    """speed_mps, gps_timeout_s and stuck_after_s of a step mapping (None when not given)."""
    v = v if isinstance(v, dict) else {}
    return {
        "speed_mps": parse_quantity(v["speed"], "speed") if "speed" in v else None,
        "gps_timeout_s": parse_quantity(v["gps_timeout"], "duration") if "gps_timeout" in v else None,
        "stuck_after_s": parse_quantity(v["stuck_after"], "duration") if "stuck_after" in v else None,
    }


def _within(tolerance_m: Optional[float]) -> str:
    shown = tolerance_m if tolerance_m is not None else _DEFAULT_TOLERANCE_M
    return f"(within {shown:g} m)"


def _go_to_place(c: Compiler, name: str, step_tolerance_m: Optional[float], options: dict,
                 label: str = "go_to") -> Behaviour:
    """A GoTo leaf for a named place (``home`` included)."""
    if "gps" not in c.ctx.capabilities:
        return NotAvailable(f"{label} {name}", c.ctx, "this robot has no GPS")
    if name == HOME:
        target = home_target(c.ctx)
        tolerance = step_tolerance_m
    else:
        lat, lon, place_tolerance = c.place(name)
        assert lat is not None and lon is not None
        target = place_target(lat, lon)
        tolerance = step_tolerance_m if step_tolerance_m is not None else place_tolerance
    return GoTo(f"{label} {name} {_within(tolerance)}", c.ctx, name, target, tolerance, **options)


def build_go_to(c: Compiler, s: Step) -> Behaviour:
    """``go_to: gate`` or ``go_to: {place: gate | lat:, lon:, tolerance:, speed:, gps_timeout:, stuck_after:}``."""
    v = s.value
    if isinstance(v, str):
        return _go_to_place(c, v, None, _options(None))
    tolerance = parse_quantity(v["tolerance"], "distance") if "tolerance" in v else None
    if "place" in v:
        return _go_to_place(c, v["place"], tolerance, _options(v))
    lat, lon = float(v["lat"]), float(v["lon"])
    label = f"{lat:.6f}, {lon:.6f}"
    if "gps" not in c.ctx.capabilities:
        return NotAvailable(f"go_to {label}", c.ctx, "this robot has no GPS")
    return GoTo(f"go_to {label} {_within(tolerance)}", c.ctx, label, place_target(lat, lon), tolerance, **_options(v))


def build_route(c: Compiler, s: Step) -> Behaviour:
    """``route: {places: [a, b, c], loops: 2 | forever, ...}``: go_to each place in order, loops times."""
    v = s.value
    places = list(v["places"])
    tolerance = parse_quantity(v["tolerance"], "distance") if "tolerance" in v else None
    options = _options(v)
    loops = parse_count(v["loops"]) if "loops" in v else 1
    name = "route " + " -> ".join(places)
    legs = [_go_to_place(c, p, tolerance, options) for p in places]
    body: Behaviour = py_trees.composites.Sequence(name=name if loops == 1 else "pass", memory=True, children=legs)
    if loops == 1:
        return body
    label = "forever" if loops < 0 else f"{loops} times"
    return RepeatTimes(f"{name} ({label})", body, loops)


def build_return_home(c: Compiler, s: Step) -> Behaviour:
    """``return_home`` or ``return_home: {tolerance:, speed:, gps_timeout:, stuck_after:}``."""
    v = s.value if isinstance(s.value, dict) else {}
    tolerance = parse_quantity(v["tolerance"], "distance") if "tolerance" in v else None
    if "gps" not in c.ctx.capabilities:
        return NotAvailable("return_home", c.ctx, "this robot has no GPS")
    return GoTo(f"return_home {_within(tolerance)}", c.ctx, HOME, home_target(c.ctx), tolerance, **_options(v))


__all__ = ["build_go_to", "build_route", "build_return_home"]


NAVIGATION_STEPS: Mapping[str, StepBuilder] = MappingProxyType({
    "go_to": build_go_to,
    "route": build_route,
    "return_home": build_return_home,
})
"""The steps the navigation part adds to the language."""
