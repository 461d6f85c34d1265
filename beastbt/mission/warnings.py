"""Warnings: what is valid but probably not what the author meant. The mission runs; ``--strict`` refuses it.

From the mission alone (:func:`mission_warnings`): text cut by a ``#``, a
mission without steps, a step faster than the mission's own speed limit,
places far from each other or from the world (latitude and longitude
swapped?). Against its world (:func:`world_warnings`): GPS navigation
indoors, a tag measured by another size than the world's. Against the robot it runs on (:func:`robot_warnings`): a step
faster than the robot's limit, a ``battery_low`` failsafe on a robot that
does not report its battery.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterator, Optional

from beastbt.core.errors import Problem, warning
from beastbt.core.schema_defaults import schema_default
from beastbt.core.units import format_quantity
from beastbt.estimation.geodesy import TYPO_DISTANCE_M, distance_m
from beastbt.behaviours.conditions import sector_width_rad
from beastbt.mission import steps as st
from beastbt.mission.place_neighbours import lonely_places

FAR_PLACE_M = TYPO_DISTANCE_M
"""Places farther apart than this (m) are almost surely a typo, typically latitude and longitude swapped (the
distance beyond which go_to refuses to drive)."""


def all_steps(steps: tuple) -> Iterator[st.Step]:
    """Every step of ``steps``, nested ones included, in document order."""
    for step in steps:
        yield step
        for f in dataclasses.fields(step):
            value = getattr(step, f.name)
            if isinstance(value, tuple) and value and isinstance(value[0], st.Step):
                yield from all_steps(value)


def _value_at(data: Any, path: tuple) -> Any:
    for key in path:
        data = data[key]
    return data


def _every_step(mission: Any) -> Iterator[st.Step]:
    yield from all_steps(tuple(mission.steps))
    for task in mission.tasks.values():
        yield from all_steps(tuple(task))


def _speed_warnings(mission: Any, limit_mps: Optional[float], whose: str) -> list[Problem]:
    out = []
    if limit_mps is None:
        return out
    for step in _every_step(mission):
        speed = getattr(step, "speed_mps", None)
        if speed is not None and abs(speed) > limit_mps + 1e-9:
            out.append(warning(mission.doc.problem(step.path + (step.KEYWORD, "speed"),
                                                   f"speed {format_quantity(speed, 'speed')} is above {whose} "
                                                   f"{format_quantity(limit_mps, 'speed')}: it will be capped",
                                                   f"write a speed up to {format_quantity(limit_mps, 'speed')}")))
    return out


def _place_far_away(place: Any, places: list, world_datum: Optional[tuple[float, float]],
                    lonely: Optional[tuple[float, str]]) -> Optional[tuple[str, str]]:
    """(message, hint) when ``place`` is far from where the mission happens, judged on its own; else None.

    ``lonely`` is (metres, name) of the nearest other place when every other
    place is farther than :data:`FAR_PLACE_M` (from :func:`lonely_places`).

    Where the mission happens is its world's datum, or (no world) the
    simulator's default world. A place far from it that swapping its lat and
    lon would bring near is said to be swapped; one far from a real world's
    datum, or from every one of two or more other places, is said to be far.
    Comparing places pairwise would blame the right place and the swapped one
    alike: with one of two swapped, each is far from the other.
    """
    datum = world_datum
    reference = "the world's datum"
    if datum is None:
        default = schema_default("world.schema.json#/properties", "datum")
        datum = (float(default["lat"]), float(default["lon"]))
        reference = "the simulator's default world (the mission names no world)"
    def looks_swapped(p: Any) -> bool:
        return (distance_m(p.lat, p.lon, *datum) > FAR_PLACE_M and abs(p.lon) <= 90.0
                and distance_m(p.lon, p.lat, *datum) <= FAR_PLACE_M)

    d = distance_m(place.lat, place.lon, *datum)
    swapped = (distance_m(place.lon, place.lat, *datum) if abs(place.lon) <= 90.0 else math.inf)
    hint = (f"lat is north-south (-90..90), lon east-west: check lat: {place.lat:.6f}, lon: {place.lon:.6f}")
    if looks_swapped(place):
        return (f"place '{place.name}' is {d / 1000:.0f} km from {reference}, and {swapped / 1000:.1f} km from it with "
                f"lat and lon swapped: are they swapped?", f"write lat: {place.lon:.6f}, lon: {place.lat:.6f}")
    if d > FAR_PLACE_M and world_datum is not None:
        return f"place '{place.name}' is {d / 1000:.0f} km from {reference}: is it typed right?", hint
    if len(places) >= 3 and lonely is not None:
        nearest, name = lonely
        return (f"place '{place.name}' is {nearest / 1000:.0f} km from the nearest other place ('{name}'), and "
                f"farther from all the others: are its lat and lon swapped?", hint)
    if len(places) == 2 and place is places[1] and lonely is not None and not looks_swapped(places[0]):
        # Two places far apart, neither swapped by the look of it: which one is wrong cannot be told, so say it
        # once, at the second, without blaming it.
        return (f"place '{place.name}' is {lonely[0] / 1000:.0f} km from '{lonely[1]}', the only other place: "
                f"is one of them typed wrong (lat and lon swapped, a digit off)?", hint)
    return None


def _map_place_warnings(mission: Any) -> list[Problem]:
    """A place on the map that lies in an occupied or unknown cell of the mission's map, or off it: go_to there
    would fail (the planner does not drive into walls or where the map has not been)."""
    grid = getattr(mission, "map_grid", None)
    if grid is None:
        return []
    out = []
    for place in mission.places.values():
        if place.x is None:
            continue
        value = grid.value_at(place.x, place.y)
        col, row = grid.to_cells(place.x, place.y)
        where = f"({place.x:g}, {place.y:g}) m"
        if not grid.inside(col, row):
            said = "lies off the map"
        elif grid.occupied()[int(row), int(col)]:
            said = "lies in an occupied cell of the map (a wall or furniture)"
        elif value < 0:
            said = "lies in an unknown cell of the map (where the map has not been)"
        else:
            continue
        out.append(warning(mission.doc.problem(("places", place.name), f"place '{place.name}' {where} {said}: "
                                               "go_to there will fail", "move the place into a free (white) part "
                                               "of the map: beastbt map show MAP --places MISSION draws them")))
    return out


def mission_warnings(mission: Any, world_datum: Optional[tuple[float, float]] = None) -> list[Problem]:
    """What looks wrong in the mission itself; ``world_datum`` (lat, lon) is where its world is, if known."""
    doc = mission.doc
    out: list[Problem] = list(getattr(mission, "load_warnings", []))
    for path, comment in doc.comments_after.items():
        if path and path[-1] in ("say", "description"):
            kept = _value_at(doc.data, path)
            out.append(warning(doc.problem(path, f"the text of '{path[-1]}' stops before '{comment}': YAML reads "
                                                 f"'#' after a space as the start of a comment",
                                           f"put the whole text in quotes: {path[-1]}: \"{kept} {comment}\"")))
    if not mission.steps:
        out.append(warning(doc.problem(("steps",), "the mission has no steps: it succeeds at once, doing nothing",
                                       "add what the robot should do under 'steps:'")))
    out += _speed_warnings(mission, mission.speed_limit_mps, "the mission's limit")
    out += _map_place_warnings(mission)
    places = [p for p in mission.places.values() if p.lat is not None]
    lonely = lonely_places(places, FAR_PLACE_M)  # linear in the places, not pairwise (issue 38)
    for i, place in enumerate(places):
        said = _place_far_away(place, places, world_datum, lonely.get(i))
        if said is not None:
            out.append(warning(doc.problem(("places", place.name), said[0], said[1])))
    for fence in getattr(mission, "fences", {}).values():
        for place in places:
            inside = fence.contains(place.lat, place.lon)
            if inside != (fence.keep == "in"):
                where = "outside the keep-in" if fence.keep == "in" else "inside the keep-out"
                out.append(warning(doc.problem(("places", place.name), f"place '{place.name}' is {where} fence "
                                                                       f"'{fence.name}': going there crosses it",
                                               "move the place, or the fence")))
    out += _sector_warnings(mission)
    return by_position(out)


def _inner(condition: Any) -> tuple:
    """The conditions inside ``not``, ``all`` and ``any``."""
    return getattr(condition, "conditions", None) or ((condition.condition,) if isinstance(condition, st.Not) else ())


def _needs_a_fix(condition: Any) -> bool:
    """True when a condition reads the position on Earth (``near``, ``inside``/``outside`` a fence)."""
    if isinstance(condition, (st.Near, st.InFence)):
        return True
    return any(_needs_a_fix(c) for c in _inner(condition))


def _needs_a_lidar(condition: Any) -> bool:
    """True when a condition reads the LiDAR (``obstacle_within``)."""
    if isinstance(condition, st.ObstacleWithin):
        return True
    return any(_needs_a_lidar(c) for c in _inner(condition))


def _sectors(condition: Any, path: tuple) -> Iterator[tuple[st.ObstacleWithin, tuple]]:
    """Every ``obstacle_within`` with a sector in ``condition`` (written at ``path``), with where it is written."""
    if isinstance(condition, st.ObstacleWithin):
        if condition.sector_rad is not None:
            yield condition, path + ("sector_deg",)
    elif isinstance(condition, st.Not):
        yield from _sectors(condition.condition, path + ("not",))
    elif isinstance(condition, (st.AllOf, st.AnyOf)):
        key = "all" if isinstance(condition, st.AllOf) else "any"
        for i, c in enumerate(condition.conditions):
            yield from _sectors(c, path + (key, i))


def _sector_warnings(mission: Any) -> list[Problem]:
    """A sector written from left to right the long way round (``[30, -30]``: everything but the 60 deg ahead)."""
    out = []
    for step in _every_step(mission):
        condition = getattr(step, "condition", None)
        if condition is None:
            continue
        for c, path in _sectors(condition, step.path + (step.KEYWORD,)):
            start, end = (math.degrees(a) for a in c.sector_rad)
            width = math.degrees(sector_width_rad(*c.sector_rad))
            if end < start and width > 180.0:
                out.append(warning(mission.doc.problem(
                    path, f"sector_deg [{start:g}, {end:g}] runs counterclockwise from {start:g} deg to {end:g} deg: "
                          f"the {width:g} degrees round the back, all but the {360 - width:g} degrees between them",
                    f"for the {360 - width:g} degrees between them write [{end:g}, {start:g}] (0 is straight ahead, "
                    f"positive to the left)")))
    return out


def _on_the_map(mission: Any, step: Any) -> bool:
    """Whether a navigation step drives on the mission's map (a mission with ``map:``, places on the map, home)."""
    if getattr(mission, "map_grid", None) is None:
        return False
    places = mission.places
    if isinstance(step, st.ReturnHome):
        return True
    if isinstance(step, st.GoToPlace):
        return step.place == "home" or (step.place in places and places[step.place].on_map)
    if isinstance(step, st.Route):
        return all(p == "home" or (p in places and places[p].on_map) for p in step.places)
    return False


def _sees_tags(condition: Any, path: tuple) -> Iterator[tuple[st.Sees, tuple]]:
    """Every ``{sees: {tag: ..., within: ...}}`` in ``condition`` (written at ``path``), with where it is written."""
    if isinstance(condition, st.Sees):
        if condition.what == "tag" and condition.within_m is not None:
            yield condition, path + ("sees",)
    elif isinstance(condition, st.Not):
        yield from _sees_tags(condition.condition, path + ("not",))
    elif isinstance(condition, (st.AllOf, st.AnyOf)):
        key = "all" if isinstance(condition, st.AllOf) else "any"
        for i, c in enumerate(condition.conditions):
            yield from _sees_tags(c, path + (key, i))


def _tag_size_warnings(mission: Any, world: Any) -> list[Problem]:
    """A ``dock``, or a ``sees`` a tag ``within`` a distance, that measures a tag of the world by another size than
    the world's: its distances would be off by the ratio (the lab's 30 cm tag taken for 16 cm: docked 23 cm short of
    the goal, with a small error by its own estimate)."""
    from beastbt.mission.vision_steps import DOCK_DEFAULTS
    from beastbt.core.units import parse_quantity
    default_m = parse_quantity(DOCK_DEFAULTS["size"], "distance")
    sizes = {(str(t.get("family", DOCK_DEFAULTS["family"])), int(t["id"])): float(t.get("size_m", default_m))
             for t in world.data.get("tags") or [] if isinstance(t, dict) and "id" in t}
    if not sizes:
        return []
    # a sees without its size measures the tag by the size the last dock at it said: known right when one said it
    docked = {(s.family, s.tag) for s in _every_step(mission)
              if isinstance(s, st.Dock) and abs(s.size_m - sizes.get((s.family, s.tag), s.size_m)) <= 0.05 * s.size_m}
    out = []

    def check(family: str, tag: int, size_m: float, path: tuple, what: str) -> None:
        real = sizes.get((family, tag))
        if real is None or abs(size_m - real) <= 0.05 * real:
            return
        out.append(warning(mission.doc.problem(
            path, f"tag {tag} is {format_quantity(real, 'distance')} in world '{world.name}', but this {what} measures "
                  f"it as a {format_quantity(size_m, 'distance')} tag: it would judge every distance to it at "
                  f"{size_m / real:.2f} times the true one",
            f"write size: {format_quantity(real, 'distance')} (the side of the tag's black square)")))

    for step in _every_step(mission):
        if isinstance(step, st.Dock):
            check(step.family, step.tag, step.size_m, step.path + (step.KEYWORD, "tag"), "dock")
        condition = getattr(step, "condition", None)
        if condition is not None:
            for c, path in _sees_tags(condition, step.path + (step.KEYWORD,)):
                family = c.family or DOCK_DEFAULTS["family"]
                if c.size_m is None and (family, c.tag_id) in docked:
                    continue
                check(family, c.tag_id, default_m if c.size_m is None else c.size_m, path + ("tag",), "sees")
    return out


def world_warnings(mission: Any, world: Any) -> list[Problem]:
    """What cannot work in the mission's world: what needs a GPS fix indoors (a world whose ``gps`` says ``sky: none``),
    and a tag measured by another size than the world gives it.

    GPS navigation steps, conditions on the position on Earth (``near``, a
    fence) and the failsafes that watch the fix or a fence.
    """
    if world is None:
        return []
    if (world.section("gps") or {}).get("sky") != "none":
        return _tag_size_warnings(mission, world)
    doc = mission.doc
    indoors = f"world '{world.name}' is indoors (gps: {{sky: none}}): the robot never gets a GPS fix there"
    hint = ("indoors, drive by distance and turns or follow a line; or run the mission in a world under the open "
            "sky")
    out = []
    for step in _every_step(mission):
        if _on_the_map(mission, step):
            continue  # planned on the mission's map and localised by the LiDAR: no GPS needed
        if isinstance(step, (st.GoToPlace, st.GoToPoint, st.Route, st.ReturnHome)):
            out.append(warning(doc.problem(step.path + (step.KEYWORD,),
                                           f"{indoors}, so this {step.KEYWORD} cannot arrive", hint)))
        elif _needs_a_fix(getattr(step, "condition", None)):
            out.append(warning(doc.problem(step.path + (step.KEYWORD,),
                                           f"{indoors}, so this condition reads a position that is never known", hint)))
    for failsafe in mission.failsafes:
        if failsafe.kind in ("gps_lost", "geofence", "keepout"):
            what = ("a fix that never comes" if failsafe.kind == "gps_lost"
                    else "a position on Earth that is never known")
            out.append(warning(doc.problem(failsafe.path, f"{indoors}: this {failsafe.kind} failsafe watches {what}",
                                           hint, key=True)))
    return out + _tag_size_warnings(mission, world)


def speed_warnings(mission: Any, max_speed_mps: float, robot: str) -> list[Problem]:
    """The speeds the mission asks for above ``robot``'s top speed (m/s), as warnings: they will be capped."""
    return by_position(_speed_warnings(mission, max_speed_mps, f"the top speed of robot '{robot}'"))


def robot_warnings(mission: Any, max_speed_mps: float, robot: str, has_battery: bool,
                   has_joystick: bool = True, has_lidar: bool = True, has_odometry: bool = True) -> list[Problem]:
    """What looks wrong when the mission runs on this robot."""
    out = list(speed_warnings(mission, max_speed_mps, robot))
    if not has_odometry:
        for step in _every_step(mission):
            if isinstance(step, (st.DriveDistance, st.TurnBy)):
                what = "how far it drove" if isinstance(step, st.DriveDistance) else "how far it turned"
                out.append(warning(mission.doc.problem(
                    step.path + (step.KEYWORD,), f"robot '{robot}' has no odometry (its base reports no wheel "
                                                 f"travel): this {step.KEYWORD} cannot measure {what}, and fails "
                                                 f"as if blocked",
                    "drive for a time instead (drive: {time: 4 s, speed: 0.15 m/s}), or give the base wheel "
                    "encoders")))
    if not has_lidar:
        for step in _every_step(mission):
            if _needs_a_lidar(getattr(step, "condition", None)):
                out.append(warning(mission.doc.problem(
                    step.path + (step.KEYWORD,), f"robot '{robot}' has no LiDAR (no lidar: section): this "
                                                 f"obstacle_within cannot be checked, so this {step.KEYWORD} step "
                                                 f"fails at once", "run it on a robot with a lidar: section "
                                                                   "(robots/sim.yaml has an LD19), or remove the "
                                                                   "condition")))
    if mission.on_failure == "hold" and not has_joystick and "on_failure" in (mission.doc.data or {}):
        out.append(warning(mission.doc.problem(("on_failure",), f"on_failure: hold on robot '{robot}', which has no "
                                                                f"joystick: nothing can clear the hold, the robot "
                                                                f"stands still until the run is ended",
                                               "use on_failure: stop, or give the robot a joystick: section")))
    for failsafe in mission.failsafes:
        if failsafe.kind == "battery_low" and not has_battery:
            out.append(warning(mission.doc.problem(failsafe.path, f"robot '{robot}' does not report its battery: "
                                                                  f"this battery_low failsafe can never trigger",
                                                   "run it on a robot whose base reports the battery (the Waveshare "
                                                   "base does), or remove it", key=True)))
    return by_position(out)


def by_position(problems: list[Problem]) -> list[Problem]:
    """Problems in the order of the file."""
    return sorted(problems, key=lambda p: (p.file, p.position))


__all__ = ["mission_warnings", "robot_warnings", "speed_warnings", "world_warnings", "all_steps", "FAR_PLACE_M"]
