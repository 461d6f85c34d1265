"""What a run happens in, for Foxglove: /scene (a 3D SceneUpdate) and /route (GeoJSON for the map).

Two halves, like the rest of the recording:

* :func:`scene_description` runs once, on the run's side, when the recorder
  is installed: it gathers the mission's places, waypoints, route and fences
  (WGS84 degrees), the world's datum, start, walls, obstacles and line track (world
  metres) and the robot's footprint into a plain dict that goes down the
  pipe as one ``("scene", now_s, description)`` item;
* :class:`SceneView` runs in the writer process and turns it into messages:
  ``foxglove.GeoJSON`` on /route at once, ``foxglove.SceneUpdate`` on /scene
  at once and again whenever the place of the ``map`` frame on Earth changes.

The ``map`` frame is the estimator's local east-north-up frame. The EKF
anchors it at its first good GPS fix (``docs/navigation.md``), not at the
world's datum; so until the run has a fused position on Earth the scene is
drawn with ``map`` at the robot's start in the world (where dead reckoning
starts), and redrawn once a fused position tells where ``map`` really is
(``SceneView.on_pose``). World geometry goes world metres -> WGS84 (through
the world's datum) -> map metres; places go WGS84 -> map metres.
"""

from __future__ import annotations

import json
import math
from typing import Any, Optional

from beastbt.estimation.geodesy import LocalFrame, distance_m
from beastbt.recording.config import FramesConfig
from beastbt.recording.foxglove import color, fox_time, quaternion, vector3

REDRAW_M = 0.5
"""The scene is redrawn when the map frame's origin on Earth moves by more than this (m)."""

_FOREVER = {"sec": 0, "nsec": 0}

# Colours (r, g, b, a in 0-1): what a user should tell apart at a glance.
_WALL = color(0.55, 0.55, 0.6, 0.9)
_TAPE = color(0.05, 0.05, 0.05)
_PLACE = color(0.1, 0.45, 0.95, 0.9)
_WAYPOINT = color(0.95, 0.6, 0.1, 0.9)
_ROUTE = color(0.1, 0.45, 0.95, 0.6)
_KEEP_IN = color(0.1, 0.75, 0.2, 0.9)
_KEEP_OUT = color(0.9, 0.15, 0.1, 0.9)
_FOOTPRINT = color(1.0, 0.85, 0.0, 0.9)
_OBSTACLE = color(0.6, 0.45, 0.3, 0.9)
_PERSON = color(0.75, 0.55, 0.95, 0.8)
_TEXT = color(1.0, 1.0, 1.0)

WALL_HEIGHT_M = 0.4
WALL_THICKNESS_M = 0.05
"""How walls are drawn (the simulator's walls are segments without height or thickness), metres."""
OBSTACLE_HEIGHT_M = 0.5
"""How tall boxes and cylinders are drawn (the simulator's obstacles are 2D footprints), metres."""


# -- the run's side: once, at install ----------------------------------------------------------------


def scene_description(mission: Any, world: Any, footprint_radius_m: Optional[float]) -> dict:
    """Everything /scene and /route draw, as plain JSON-able data (degrees, metres, radians).

    ``mission``: a :class:`~beastbt.mission.model.Mission`; ``world``: a
    :class:`~beastbt.sim.world.World` or None on the robot.
    """
    from beastbt.mission import steps as st
    from beastbt.mission.warnings import all_steps

    # GPS places only: places on a saved map are drawn with the map (/map, /path), not on Earth
    places = {name: {"name": name, "lat": p.lat, "lon": p.lon, "tolerance_m": p.tolerance_m}
              for name, p in mission.places.items() if p.lat is not None}
    route: list[dict] = []
    waypoints: list[dict] = []
    every = list(all_steps(tuple(mission.steps)))
    for task in mission.tasks.values():
        every.extend(all_steps(tuple(task)))
    for step in every:
        if isinstance(step, st.Route):
            route.extend(places[n] for n in step.places if n in places)
        elif isinstance(step, st.GoToPlace) and step.place in places:
            route.append(places[step.place])
        elif isinstance(step, st.GoToPoint):
            point = {"name": f"{step.lat_deg:.6f}, {step.lon_deg:.6f}", "lat": step.lat_deg, "lon": step.lon_deg,
                     "tolerance_m": None}
            waypoints.append(point)
            route.append(point)
    fences = [{"name": name, "keep": f.keep, "corners": [list(c) for c in f.corners]}
              for name, f in mission.fences.items()]
    circles = []
    for fs in mission.failsafes:
        centre = places.get(str(fs.params.get("center"))) if fs.kind == "geofence" else None
        if centre is not None and "radius_m" in fs.params:
            circles.append({"name": f"geofence {fs.params['radius_m']:g} m around {centre['name']}",
                            "lat": centre["lat"], "lon": centre["lon"], "radius_m": fs.params["radius_m"]})
    out: dict = {"places": list(places.values()), "waypoints": waypoints,
                 "route": [[p["lat"], p["lon"]] for p in route], "fences": fences, "circles": circles,
                 "footprint_radius_m": footprint_radius_m, "world": None}
    if world is not None:
        out["world"] = {"name": world.name, "datum": [world.frame.lat0_deg, world.frame.lon0_deg, world.frame.alt0_m],
                        "start": [world.start_x, world.start_y, world.start_yaw],
                        "walls": [[w.x1, w.y1, w.x2, w.y2] for w in world.walls],
                        "obstacles": [_obstacle_data(o) for o in world.obstacles],
                        "lines": _world_lines(world)}
    return out


def _obstacle_data(o: Any) -> dict:
    """An obstacle of the world as plain data: its shape and its fields (world metres, yaw in radians)."""
    import dataclasses
    from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle
    shape = "box" if isinstance(o, BoxObstacle) else "cylinder" if isinstance(o, CylinderObstacle) else "person"
    return {"shape": shape, **{k: ([list(p) for p in v] if k == "path" else v) for k, v in dataclasses.asdict(o).items()}}


def _world_lines(world: Any) -> list[dict]:
    """The world's floor lines (centrelines, world metres); none when it has no floor or a bad one."""
    floor = world.section("floor")
    if not floor:
        return []
    from beastbt.sim.floor import floor_lines
    try:
        lines = floor_lines(floor)
    except ValueError:
        return []  # the camera part reports a bad floor; the scene just goes without it
    return [{"points": ln.points.tolist(), "closed": ln.closed, "width_m": ln.width_m} for ln in lines]


# -- the writer's side ---------------------------------------------------------------------------------


def _entity(t_ns: int, frame_id: str, entity_id: str, frame_locked: bool = False, **primitives: list) -> dict:
    """A ``foxglove.SceneEntity`` that lasts until replaced (every primitive list present, most empty)."""
    entity = {"timestamp": fox_time(t_ns), "frame_id": frame_id, "id": entity_id, "lifetime": dict(_FOREVER),
              "frame_locked": frame_locked, "metadata": [], "arrows": [], "cubes": [], "spheres": [],
              "cylinders": [], "lines": [], "triangles": [], "texts": [], "models": []}
    entity.update(primitives)
    return entity


def _pose(x: float, y: float, z: float = 0.0, yaw: float = 0.0) -> dict:
    return {"position": vector3(x, y, z), "orientation": quaternion(yaw_rad=yaw)}


def _cylinder(x: float, y: float, radius_m: float, height_m: float, rgba: dict) -> dict:
    """A ``foxglove.CylinderPrimitive`` standing on the floor at (x, y), metres."""
    return {"pose": _pose(x, y, 0.5 * height_m), "size": vector3(2 * radius_m, 2 * radius_m, height_m),
            "bottom_scale": 1.0, "top_scale": 1.0, "color": rgba}


def _line(points: list[tuple[float, float]], color: dict, thickness_m: float, loop: bool = False,
          z_m: float = 0.002) -> dict:
    """A ``foxglove.LinePrimitive`` on the floor (just above it, so the grid does not hide it)."""
    return {"type": 1 if loop else 0, "pose": _pose(0.0, 0.0), "thickness": thickness_m, "scale_invariant": False,
            "points": [vector3(x, y, z_m) for x, y in points], "color": color, "colors": [], "indices": []}


def _text(x: float, y: float, z: float, text: str) -> dict:
    return {"pose": _pose(x, y, z), "billboard": True, "font_size": 14.0, "scale_invariant": True, "color": _TEXT,
            "text": text}


def _circle(x: float, y: float, radius_m: float, n: int = 48) -> list[tuple[float, float]]:
    return [(x + radius_m * math.cos(2 * math.pi * k / n), y + radius_m * math.sin(2 * math.pi * k / n))
            for k in range(n)]


class SceneView:
    """Builds /scene and /route from a :func:`scene_description`, and redraws /scene when ``map`` moves on Earth."""

    def __init__(self, description: dict, frames: FramesConfig) -> None:
        self.d = description
        self.frames = frames
        world = description.get("world")
        self._world_frame = LocalFrame(*world["datum"]) if world else None
        self._origin: Optional[tuple[float, float, float]] = None
        """Where the map frame's origin is on Earth (lat, lon deg, alt m) as last drawn, or None."""
        self._anchored = False
        """The origin came from a fused position (final: the EKF never moves its frame once anchored)."""
        if world is not None:
            # Until the estimator knows better: map starts where the robot starts (dead reckoning's origin).
            sx, sy, _ = world["start"]
            self._origin = self._world_frame.to_geodetic(sx, sy, 0.0)

    # -- /route ------------------------------------------------------------------------------------
    def route_message(self) -> dict:
        """The mission and the world on the map, as a ``foxglove.GeoJSON`` (a FeatureCollection, lon/lat)."""
        features: list[dict] = []

        def feature(kind: str, name: str, geometry: dict, **props: Any) -> None:
            features.append({"type": "Feature", "geometry": geometry,
                             "properties": {"kind": kind, "name": name, **props}})

        for p in self.d["places"]:
            feature("place", p["name"], {"type": "Point", "coordinates": [p["lon"], p["lat"]]},
                    tolerance_m=p["tolerance_m"])
        for p in self.d["waypoints"]:
            feature("waypoint", p["name"], {"type": "Point", "coordinates": [p["lon"], p["lat"]]})
        if len(self.d["route"]) >= 2:
            feature("route", "route", {"type": "LineString", "coordinates": [[lon, lat] for lat, lon in self.d["route"]]})
        for f in self.d["fences"]:
            ring = [[lon, lat] for lat, lon in f["corners"]]
            feature("fence", f["name"], {"type": "Polygon", "coordinates": [ring + ring[:1]]}, keep=f["keep"])
        for c in self.d["circles"]:
            centre = LocalFrame(c["lat"], c["lon"])
            ring = [list(centre.to_geodetic(x, y)[1::-1]) for x, y in _circle(0.0, 0.0, c["radius_m"])]
            feature("fence", c["name"], {"type": "Polygon", "coordinates": [ring + ring[:1]]}, keep="in")
        world = self.d.get("world")
        if world is not None:
            wf = self._world_frame
            for i, (x1, y1, x2, y2) in enumerate(world["walls"]):
                ends = [list(wf.to_geodetic(x1, y1)[1::-1]), list(wf.to_geodetic(x2, y2)[1::-1])]
                feature("wall", f"{world['name']} wall {i + 1}", {"type": "LineString", "coordinates": ends})
            for i, line in enumerate(world["lines"]):
                pts = [list(wf.to_geodetic(x, y)[1::-1]) for x, y in line["points"]]
                if line["closed"]:
                    pts.append(pts[0])
                feature("line", f"{world['name']} line {i + 1}", {"type": "LineString", "coordinates": pts})
        return {"geojson": json.dumps({"type": "FeatureCollection", "features": features}, separators=(",", ":"))}

    # -- /scene ------------------------------------------------------------------------------------
    def on_pose(self, x_m: float, y_m: float, lat: Optional[float], lon: Optional[float], valid: bool) -> bool:
        """A fused pose (map metres and its WGS84 position); True when it moved map's origin enough to redraw."""
        if self._anchored or not valid or lat is None or lon is None:
            return False
        # The origin is the point x m west and y m south of the robot: invert the local projection there.
        origin = LocalFrame(lat, lon).to_geodetic(-x_m, -y_m, 0.0)
        self._anchored = True
        moved = self._origin is None or distance_m(self._origin[0], self._origin[1], origin[0], origin[1]) > REDRAW_M
        self._origin = (origin[0], origin[1], self._origin[2] if self._origin is not None else 0.0)
        return moved

    def world_point(self, x: float, y: float) -> Optional[tuple[float, float]]:
        """A point of the simulated world (world metres) in ``map`` as drawn now; None without a world or origin."""
        world = self.d.get("world")
        if world is None or self._origin is None:
            return None
        lat, lon, _ = self._world_frame.to_geodetic(x, y, 0.0)
        e, n, _ = LocalFrame(*self._origin).to_enu(lat, lon, None)
        return e, n

    def scene_message(self, t_ns: int) -> dict:
        """The ``foxglove.SceneUpdate`` of everything, drawn with map's origin as known now."""
        frames = self.frames
        entities = []
        radius = self.d.get("footprint_radius_m")
        if radius:
            outline = _line(_circle(0.0, 0.0, radius), _FOOTPRINT, 0.01, loop=True)
            nose = _line([(0.0, 0.0), (radius, 0.0)], _FOOTPRINT, 0.01)
            entities.append(_entity(t_ns, frames.base_link, "footprint", frame_locked=True, lines=[outline, nose]))
        if self._origin is None:
            return {"deletions": [], "entities": entities}
        to_map = LocalFrame(*self._origin)

        def geo(lat: float, lon: float) -> tuple[float, float]:
            e, n, _ = to_map.to_enu(lat, lon, None)
            return e, n

        world = self.d.get("world")
        if world is not None:
            wf = self._world_frame

            def world_xy(x: float, y: float) -> tuple[float, float]:
                lat, lon, _ = wf.to_geodetic(x, y, 0.0)
                return geo(lat, lon)

            cubes = []
            for x1, y1, x2, y2 in world["walls"]:
                (a, b), (c, d) = world_xy(x1, y1), world_xy(x2, y2)
                length = math.hypot(c - a, d - b)
                cubes.append({"pose": _pose(0.5 * (a + c), 0.5 * (b + d), 0.5 * WALL_HEIGHT_M, math.atan2(d - b, c - a)),
                              "size": vector3(max(length, WALL_THICKNESS_M), WALL_THICKNESS_M, WALL_HEIGHT_M),
                              "color": _WALL})
            if cubes:
                entities.append(_entity(t_ns, frames.map, "walls", cubes=cubes))
            # Obstacles: boxes and cylinders as they stand; a person as its path (where it is now goes on
            # /sim/persons: the scene is drawn once, it does not follow the person as it walks).
            boxes, posts, paths = [], [], []
            for o in world.get("obstacles", []):
                if o["shape"] == "box":
                    x, y = world_xy(o["x"], o["y"])
                    boxes.append({"pose": _pose(x, y, 0.5 * OBSTACLE_HEIGHT_M, o["yaw"]),
                                  "size": vector3(o["length_m"], o["width_m"], OBSTACLE_HEIGHT_M), "color": _OBSTACLE})
                elif o["shape"] == "cylinder":
                    x, y = world_xy(o["x"], o["y"])
                    posts.append(_cylinder(x, y, o["radius_m"], OBSTACLE_HEIGHT_M, _OBSTACLE))
                elif len(o["path"]) > 1:
                    paths.append(_line([world_xy(px, py) for px, py in o["path"]], _PERSON, 0.03))
            if boxes or posts or paths:
                entities.append(_entity(t_ns, frames.map, "obstacles", cubes=boxes, cylinders=posts, lines=paths))
            lines = [_line([world_xy(x, y) for x, y in ln["points"]], _TAPE, ln["width_m"], loop=ln["closed"])
                     for ln in world["lines"]]
            if lines:
                entities.append(_entity(t_ns, frames.map, "line_track", lines=lines))
        for kind, points, color in (("places", self.d["places"], _PLACE), ("waypoints", self.d["waypoints"], _WAYPOINT)):
            if not points:
                continue
            spheres, texts, rings = [], [], []
            for p in points:
                x, y = geo(p["lat"], p["lon"])
                spheres.append({"pose": _pose(x, y, 0.15), "size": vector3(0.3, 0.3, 0.3), "color": color})
                texts.append(_text(x, y, 0.6, p["name"]))
                if p.get("tolerance_m"):
                    rings.append(_line(_circle(x, y, p["tolerance_m"]), color, 0.03, loop=True))
            entities.append(_entity(t_ns, frames.map, kind, spheres=spheres, texts=texts, lines=rings))
        if len(self.d["route"]) >= 2:
            entities.append(_entity(t_ns, frames.map, "route",
                                    lines=[_line([geo(lat, lon) for lat, lon in self.d["route"]], _ROUTE, 0.05)]))
        fence_lines, fence_texts = [], []
        for f in self.d["fences"]:
            pts = [geo(lat, lon) for lat, lon in f["corners"]]
            fence_lines.append(_line(pts, _KEEP_IN if f["keep"] == "in" else _KEEP_OUT, 0.06, loop=True))
            fence_texts.append(_text(pts[0][0], pts[0][1], 0.5, f"{f['name']} (keep {f['keep']})"))
        for c in self.d["circles"]:
            x, y = geo(c["lat"], c["lon"])
            fence_lines.append(_line(_circle(x, y, c["radius_m"]), _KEEP_IN, 0.06, loop=True))
            fence_texts.append(_text(x + c["radius_m"], y, 0.5, c["name"]))
        if fence_lines:
            entities.append(_entity(t_ns, frames.map, "fences", lines=fence_lines, texts=fence_texts))
        return {"deletions": [], "entities": entities}


__all__ = ["scene_description", "SceneView", "REDRAW_M", "WALL_HEIGHT_M", "WALL_THICKNESS_M", "OBSTACLE_HEIGHT_M"]
