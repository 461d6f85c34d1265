"""The mission steps ``go_to``, ``route`` and ``return_home``, compiled to :class:`GoTo` leaves.

Node names read like the mission: ``go_to b (within 3 m)``,
``route a -> b -> c``, ``return_home (within 2 m)``. A place's tolerance is
the step's ``tolerance`` when given, else the place's own, else the robot's
``navigation.default_tolerance_m`` (2 m). On a robot without a GPS these
steps compile to a leaf that fails at once, saying so.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Mapping, Optional

import py_trees

from beastbt.behaviours.flow import RepeatTimes
from beastbt.behaviours.navigation import (DrivenPath, GoTo, NavConfig, RetracePath, RouteLegs, Target, home_target,
                                           place_target)
from beastbt.behaviours.operator import NotAvailable
from beastbt.mission.compile import Compiler, StepBuilder
from beastbt.mission import steps as st
from beastbt.mission.model import HOME

Behaviour = py_trees.behaviour.Behaviour

_DEFAULT_TOLERANCE_M = NavConfig().default_tolerance_m


def _options(s: st.NavOptions) -> dict:
    """speed_mps, gps_timeout_s, stuck_after_s, blocked_after_s and recovery_tries of a navigation step (None when
    not given)."""
    return {"speed_mps": s.speed_mps, "gps_timeout_s": s.gps_timeout_s, "stuck_after_s": s.stuck_after_s,
            "blocked_after_s": s.blocked_after_s, "recovery_tries": s.recovery_tries}


def _within(tolerance_m: Optional[float]) -> str:
    shown = tolerance_m if tolerance_m is not None else _DEFAULT_TOLERANCE_M
    return f"(within {shown:g} m)"


def _on_map(c: Compiler, name: str) -> bool:
    """Whether going to place ``name`` is driving on the mission's map: a mission with ``map:``, and the place is
    on the map (``home`` on a mission with a map is where it started on the map)."""
    if getattr(c.mission, "map_grid", None) is None:
        return False
    return name == HOME or c.mission.places[name].on_map


def _map_go_to(c: Compiler, name: str, step_tolerance_m: Optional[float], options: dict,
               label: str = "go_to") -> Behaviour:
    """A :class:`MapGoTo` leaf for a place on the map (``home``: where the mission started on the map)."""
    from beastbt.behaviours.map_navigation import (MapGoTo, map_home_target, map_place_target, map_planner,
                                                   mission_map_start)
    m = c.mission
    planner = map_planner(c.ctx, m.map_grid, mission_map_start(m))
    if name == HOME:
        target, tolerance = map_home_target(planner), step_tolerance_m
    else:
        place = m.places[name]
        target = map_place_target(place.x, place.y)
        tolerance = step_tolerance_m if step_tolerance_m is not None else place.tolerance_m
    shown = f"(within {tolerance:g} m)" if tolerance is not None else "(on the map)"
    title = f"{label} {shown}" if name == HOME and label == "return_home" else f"{label} {name} {shown}"
    return MapGoTo(title, c.ctx, name, target, planner, tolerance, **options)


def _go_to_place(c: Compiler, name: str, step_tolerance_m: Optional[float], options: dict,
                 label: str = "go_to") -> Behaviour:
    """A GoTo leaf for a named place (``home`` included); a MapGoTo for a place on the mission's map."""
    if _on_map(c, name):
        return _map_go_to(c, name, step_tolerance_m, options, label)
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


def build_go_to(c: Compiler, s: st.Step) -> Behaviour:
    """``go_to: gate`` or ``go_to: {place: gate | lat:, lon:, tolerance:, speed:, gps_timeout:, stuck_after:,
    blocked_after:}``."""
    if isinstance(s, st.GoToPlace):
        return _go_to_place(c, s.place, s.tolerance_m, _options(s))
    assert isinstance(s, st.GoToPoint)
    label = f"{s.lat_deg:.6f}, {s.lon_deg:.6f}"
    if "gps" not in c.ctx.capabilities:
        return NotAvailable(f"go_to {label}", c.ctx, "this robot has no GPS")
    return GoTo(f"go_to {label} {_within(s.tolerance_m)}", c.ctx, label, place_target(s.lat_deg, s.lon_deg),
                s.tolerance_m, **_options(s))


def build_route(c: Compiler, s: st.Route) -> Behaviour:
    """``route: {places: [a, b, c], loops: 2 | forever, ...}``: go_to each place in order, loops times."""
    name = "route " + " -> ".join(s.places)
    legs = [_go_to_place(c, p, s.tolerance_m, _options(s)) for p in s.places]
    body: Behaviour
    if s.resume == "nearest" and all(isinstance(leg, GoTo) for leg in legs):
        body = RouteLegs(name if s.loops == 1 else "pass", c.ctx, legs, s.resume)  # type: ignore[arg-type]
    else:
        body = py_trees.composites.Sequence(name=name if s.loops == 1 else "pass", memory=True, children=legs)
    if s.loops == 1:
        return body
    label = "forever" if s.loops < 0 else f"{s.loops} times"
    return RepeatTimes(f"{name} ({label})", body, s.loops)


def build_return_home(c: Compiler, s: st.ReturnHome) -> Behaviour:
    """``return_home`` or ``return_home: {tolerance:, speed:, gps_timeout:, stuck_after:, blocked_after:}``; on a
    mission with a map, a planned path to where it started on the map (``along: path`` plans too)."""
    if _on_map(c, HOME):
        return _map_go_to(c, HOME, s.tolerance_m, _options(s), "return_home")
    if "gps" not in c.ctx.capabilities:
        return NotAvailable("return_home", c.ctx, "this robot has no GPS")
    if s.along == "path":
        path = c.ctx.services.driven_path
        if path is None:
            path = c.ctx.services.driven_path = DrivenPath()

        def leg(target: Target) -> GoTo:
            return GoTo(f"back along the path {_within(s.tolerance_m)}", c.ctx, "path", target, s.tolerance_m,
                        **_options(s))
        return RetracePath("return_home along the path driven", leg, path, home_target(c.ctx))
    return GoTo(f"return_home {_within(s.tolerance_m)}", c.ctx, HOME, home_target(c.ctx), s.tolerance_m, **_options(s))


__all__ = ["build_go_to", "build_route", "build_return_home"]


NAVIGATION_STEPS: Mapping[str, StepBuilder] = MappingProxyType({
    "go_to": build_go_to,
    "route": build_route,
    "return_home": build_return_home,
})
"""The steps the navigation part adds to the language."""
