"""``route: {places: [...], at_each: [...], stop_on_failure: false}``: tasks at each place, and going on after one
that fails, as Nav2's waypoint follower does (``PhotoAtWaypoint``, ``WaitAtWaypoint``; ``stop_on_failure``).

Such a route compiles to one ``go_to`` per place (the robot's own ``go_to``, so navigation decides how each
place is reached) followed by the ``at_each`` steps, repeated ``loops`` times. A bare ``photo`` among them is
named after the place (``gate.jpg``; ``gate-2.jpg`` on the second loop). With ``stop_on_failure: false`` a place
that fails (not reached, or a task that fails) is an event of kind ``place_missed`` and the route goes on; it
then succeeds once every place was tried. Its ``resume: nearest`` does not apply (each place is its own step).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import py_trees

from beastbt.behaviours.flow import RepeatTimes
from beastbt.behaviours.operator import NotAvailable
from beastbt.mission import steps as st

if TYPE_CHECKING:
    from beastbt.mission.compile import Behaviour, Compiler


def needs_tasks(s: st.Step) -> bool:
    """True for a route with ``at_each`` steps or ``stop_on_failure: false`` (compiled here, not by navigation)."""
    return isinstance(s, st.Route) and (bool(s.at_each) or not s.stop_on_failure)


def at_place(step: st.Step, place: str) -> st.Step:
    """``step`` as it runs at ``place``: a photo without a name is named after the place."""
    if isinstance(step, st.Photo) and step.name is None:
        return replace(step, name=place)
    return step


def route_with_tasks(c: "Compiler", s: st.Route) -> "Behaviour":
    """The route's places, each reached by the robot's ``go_to`` and followed by the ``at_each`` steps."""
    from beastbt.behaviours.place_tasks import CarryOn
    name = "route " + " -> ".join(s.places) + (" (tasks at each)" if s.at_each else "")
    go_to = c.builders.get("go_to")
    visits = []
    for place in s.places:
        if go_to is None:
            leg: "Behaviour" = NotAvailable(f"go_to {place}", c.ctx, "'route' needs GPS navigation, which this robot "
                                                                     "or version does not provide")
        else:
            leg = go_to(c, st.GoToPlace(place=place, tolerance_m=s.tolerance_m, speed_mps=s.speed_mps,
                                        gps_timeout_s=s.gps_timeout_s, stuck_after_s=s.stuck_after_s,
                                        blocked_after_s=s.blocked_after_s, at=s.at, path=s.path))
        tasks = [c.step(at_place(t, place)) for t in s.at_each]
        visit: "Behaviour" = py_trees.composites.Sequence(name=f"at {place}", memory=True, children=[leg, *tasks])
        if not s.stop_on_failure:
            visit = CarryOn(f"{place}, going on if it fails", visit, c.ctx, place)
        visits.append(visit)
    body = py_trees.composites.Sequence(name=name if s.loops == 1 else "pass", memory=True, children=visits)
    if s.loops == 1:
        return body
    label = "forever" if s.loops < 0 else f"{s.loops} times"
    return RepeatTimes(f"{name} ({label})", body, s.loops)


__all__ = ["needs_tasks", "route_with_tasks", "at_place"]
