"""What the studio shows of a text that is not saved yet: its problems, its compiled tree, what its map draws.

Each function takes the studio's folder, the text, the relative path the text
is (or will be) saved at (so ``world:`` and geo files resolve from its
folder), and a robot profile, and answers the JSON of docs/studio.md. The
checks are beastbt's own (the same as ``beastbt validate`` prints): nothing
here judges a mission by other rules. Every file a text or a request names
(``world:``, ``map:``, route files, the robot) is read only inside the
studio's folder, or among the shipped ones by name (:func:`studio_refs`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any, Optional

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.core.file_refs import MAP, ROBOT, WORLD, FileRefs, RefusedFile, shipped_names
from beastbt.studio.files import FileRefused, StudioFolder, kind_of

UNSAVED_NAME = "untitled.yaml"
"""The name a text without a path is checked under (in the studio's folder)."""
DEFAULT_ROBOT = "sim"
"""The robot a mission is checked and compiled for when the page names none (``beastbt run``'s default)."""


def where(folder: StudioFolder, path: Optional[str]) -> tuple[Path, str]:
    """(the real path a text at ``path`` would have, the name its problems carry); refused outside the folder."""
    if not path:
        return folder.root / UNSAVED_NAME, UNSAVED_NAME
    return folder.resolve(path, must_exist=False), path


def robot_names(folder: StudioFolder) -> list[str]:
    """The robots the page can choose: the bundled profiles by name, then the folder's robot files by path."""
    from beastbt.core.resources import data_dir
    names = sorted(p.name[:-5] for p in data_dir("robots").iterdir() if p.name.endswith(".yaml"))
    return names + [f["path"] for f in folder.list() if f["kind"] == "robot"]


def studio_refs(folder: StudioFolder) -> FileRefs:
    """Where the files a text names may be read from in the studio: inside its folder, or shipped ones by name."""
    return FileRefs.inside(folder.root, "the studio's folder")


def robot_argument(folder: StudioFolder, robot: Optional[str]) -> str:
    """What ``load_profile`` takes for the page's robot: a bundled name as is, a folder file by its real path.

    Anything else is refused (:class:`FileRefused`, 400/403/404) before a byte of it is read: a path outside the
    folder (``/etc/passwd``), a device (``/dev/zero``), a folder (``x.yaml/.``), a file over the profile's cap.
    The message names the robot as the request wrote it.
    """
    if not robot:
        return DEFAULT_ROBOT
    if not isinstance(robot, str):
        raise FileRefused(400, "'robot' is a robot profile's name or the path of a robot file in the folder")
    if robot in shipped_names(ROBOT):
        return robot
    try:
        refs = FileRefs.inside(folder.root, "the studio's folder", "the studio's folder")
        return str(refs.locate(robot, folder.root, ROBOT))
    except RefusedFile as exc:
        status = 404 if "does not exist" in exc.message or exc.message.startswith("no ") else 400
        if any(word in exc.message for word in ("absolute path", "climbs out", "leads out")):
            status = 403
        raise FileRefused(status, f"'robot': {exc.message} ({exc.hint})") from None


def problem_json(p: Problem, name: str, lines: list[str]) -> dict:
    """A problem as the API gives it: severity, line, column, end, message, hint; ``file`` when it is in another."""
    line, column = max(1, p.position.line), max(1, p.position.column)
    out: dict[str, Any] = {"severity": p.severity, "line": line, "column": column, "message": p.message}
    end = _token_end(lines, line, column)
    if end is not None:
        out["end_line"], out["end_column"] = line, end
    if p.hint:
        out["hint"] = p.hint
    if p.file != name:
        out["file"] = p.file
    return out


def _token_end(lines: list[str], line: int, column: int) -> Optional[int]:
    """The column just after the word (key, scalar or quoted text) that starts at ``line:column``."""
    if not 1 <= line <= len(lines):
        return None
    text = lines[line - 1]
    i = column - 1
    if i >= len(text):
        return None
    if text[i] in "\"'":
        close = text.find(text[i], i + 1)
        return (close + 2) if close > 0 else len(text) + 1
    j = i
    while j < len(text) and text[j] not in ",]}#" and not (text[j] == ":" and (j + 1 == len(text) or
                                                                                  text[j + 1] == " ")):
        j += 1
    while j > i and text[j - 1] == " ":
        j -= 1
    return j + 1 if j > i else None


def _sorted(problems: list[Problem], name: str) -> list[Problem]:
    """Once each: the text's own first (errors, then warnings, by position), then those in other files."""
    unique = {(p.file, p.position, p.message, p.severity): p for p in problems}
    return sorted(unique.values(), key=lambda p: (p.file != name, p.file, p.severity != "error", p.position,
                                                  p.message))


def check(folder: StudioFolder, text: str, path: Optional[str], robot: Optional[str]) -> tuple[Any, list[Problem]]:
    """(the loaded mission or None, every problem of the text) as ``beastbt validate --robot ROBOT`` finds them."""
    from beastbt.validate import for_robot, internal_error, mission_with_world
    real, name = where(folder, path)
    kind = kind_of(text)
    try:
        if kind in ("world", "robot") or _is_list(text):
            return None, _check_by_file(real, name, text, kind)
        if kind == "test":
            return None, _check_test(real, name, text)
        from beastbt.mission.model import load_mission
        mission = load_mission(real, text=text, display_name=name, refs=studio_refs(folder))
        found = mission_with_world(mission)
        if not any(p.severity == "error" for p in found):
            found = found + for_robot(mission, robot_argument(folder, robot))
        return mission, found
    except InvalidInput as exc:
        return None, exc.problems
    except FileRefused:
        raise
    except Exception as exc:  # noqa: BLE001 - a slip of ours must not end in a traceback for a user's text
        return None, [internal_error(name, exc)]


def _check_test(real: Path, name: str, text: str) -> list[Problem]:
    """A mission test's problems as ``beastbt validate`` finds them: its schema's, then its mission's (at their own
    lines in the mission's file), read from where it will be saved so that ``mission:`` resolves."""
    from beastbt.core.schema_check import schema_problems
    from beastbt.core.yaml_source import load_yaml
    from beastbt.testing.spec import SCHEMA, _checked
    try:
        doc = load_yaml(real, text=text, display_name=name)
        problems = schema_problems(doc, SCHEMA, "mission test")
        if problems:
            return problems
        _checked(doc, real, None)
    except InvalidInput as exc:
        return exc.problems
    return []


def _is_list(text: str) -> bool:
    """Whether the text's first line of content is a list item: a joystick script (``--joystick FILE``)."""
    for line in text.splitlines():
        stripped = line.strip()
        if stripped and not stripped.startswith("#") and stripped != "---":
            return stripped.startswith("- ") or stripped == "-"
    return False


def _check_by_file(real: Path, name: str, text: str, kind: str) -> list[Problem]:
    """A world, robot or joystick script text, checked as ``beastbt validate`` checks a file (written to a private
    temporary file: these files name no other file)."""
    from beastbt.validate import validate_file
    with tempfile.TemporaryDirectory(prefix="beastbt-studio-") as tmp:
        fake = Path(tmp) / (Path(name).name if name.endswith((".yaml", ".yml")) else "file.yaml")
        fake.write_text(text, encoding="utf-8")
        found = validate_file(str(fake))
        return [Problem(name if p.file in (str(fake), fake.name) else p.file, p.position, p.message, p.hint,
                        p.severity) for p in found]


def validate_text(folder: StudioFolder, text: str, path: Optional[str] = None, robot: Optional[str] = None) -> dict:
    """``POST /api/validate``: ``{problems: [...]}`` sorted errors first, then by position."""
    _, name = where(folder, path)
    _, problems = check(folder, text, path, robot)
    lines = text.splitlines()
    return {"problems": [problem_json(p, name, lines) for p in _sorted(problems, name)]}


def tree_of(folder: StudioFolder, text: str, path: Optional[str] = None, robot: Optional[str] = None) -> dict:
    """``POST /api/tree``: the compiled tree, ``{nodes, edges, root, problems}``, each node at its step's line.

    Node ids are the console's (:func:`beastbt.run.tree_ids.tree_layout`): ``"0"`` the root, ``"0.1"`` its second
    child. A node the compiler made inside a step (the ``go_to`` of a route) carries that step's position.
    """
    from beastbt.assembly import compile_for_profile
    from beastbt.robot.profile import load_profile
    from beastbt.run.tree_ids import tree_layout
    _, name = where(folder, path)
    mission, problems = check(folder, text, path, robot)
    lines = text.splitlines()
    answer: dict[str, Any] = {"nodes": [], "edges": [], "root": None,
                              "problems": [problem_json(p, name, lines) for p in _sorted(problems, name)]}
    if mission is None:
        return answer
    positions: dict[int, Position] = {}

    def seen(step: Any, behaviour: Any) -> None:
        positions.setdefault(id(behaviour), step.at)

    try:
        root = compile_for_profile(mission, load_profile(robot_argument(folder, robot)), on_step=seen)
    except InvalidInput as exc:
        answer["problems"] += [problem_json(p, name, lines) for p in exc.problems]
        return answer
    top = mission.doc.position(("mission",), key=True)
    at: dict[str, Position] = {}
    for n in tree_layout(root):
        here = positions.get(id(n.node)) or (at[n.parent] if n.parent is not None else top)
        at[n.id] = here
        answer["nodes"].append({"id": n.id, "name": n.name, "kind": n.kind, "type": type(n.node).__name__,
                                "line": here.line, "column": here.column})
        if n.parent is not None:
            answer["edges"].append([n.parent, n.id])
    answer["root"] = "0"
    return answer


def _raw_mission(folder: StudioFolder, text: str, path: Optional[str]) -> tuple[Any, list[Problem]]:
    """The text as positioned YAML (for a map of a text that does not load as a mission yet), and its problems."""
    from beastbt.core.yaml_source import load_yaml
    real, name = where(folder, path)
    try:
        return load_yaml(real, text=text, display_name=name), []
    except InvalidInput as exc:
        return None, exc.problems


def _number(value: Any) -> Optional[float]:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def map_of(folder: StudioFolder, text: str, path: Optional[str] = None, robot: Optional[str] = None) -> dict:
    """``POST /api/map``: what the map pane draws (docs/studio.md, Map): places, fences, routes, the world."""
    from beastbt.mission.mission_world import load_mission_world
    from beastbt.sim.world import empty_world
    real, name = where(folder, path)
    if kind_of(text) == "world":
        return _world_map(real, name, text)
    mission, problems = check(folder, text, path, None)
    lines = text.splitlines()
    errors = [p for p in problems if p.severity == "error"]
    answer: dict[str, Any] = {"frame": "gps", "datum": None, "places": [], "fences": [], "routes": [],
                              "problems": [problem_json(p, name, lines) for p in _sorted(errors, name)]}
    world = None
    if mission is not None and mission.world is not None:
        try:
            world = load_mission_world(mission)
        except InvalidInput:
            world = None
    if mission is not None and mission.map_file is not None:
        _map_frame(folder, mission, world, text, path, answer)
        return answer
    frame = (world or empty_world()).frame
    answer["datum"] = {"lat": frame.lat0_deg, "lon": frame.lon0_deg}
    if world is not None:
        answer["world"] = _world_json(world, frame)
    if mission is not None:
        _mission_layers(mission, answer)
    else:
        doc, _ = _raw_mission(folder, text, path)
        if doc is not None and isinstance(doc.data, dict):
            if doc.data.get("map") is not None:
                answer.update(frame="map", datum=None)
                _raw_map_plan(folder, doc, where(folder, path)[0].parent, answer)
                _raw_map_places(doc, answer)
            else:
                _raw_layers(doc, answer)
    return answer


MAP_DECIMALS = 3
"""Decimals (mm) of the map-frame coordinates the map pane is given."""


def _map_frame(folder: StudioFolder, mission: Any, world: Any, text: str, path: Optional[str], answer: dict) -> None:
    """The map pane of a mission on a map (``map:``): everything in the map frame (x forward, y left of where
    mapping began, metres), the occupancy grid as a PNG, the world's plan moved onto it (docs/studio.md, Map)."""
    import math
    from beastbt.estimation.map_localiser import compose, invert
    from beastbt.parts.map_localisation import start_pose
    answer.update(frame="map", datum=None)
    grid = mission.map_grid
    if grid is None:
        from beastbt.mapping.occupancy_map import load_map
        try:
            grid = load_map(mission.map_file, refs=mission.refs)
        except InvalidInput:
            grid = None
    if grid is not None:
        answer["map"] = _grid_json(folder, grid, mission.map_file)
    try:
        # start_pose reads only the mission of a prepared run
        start = start_pose(_MissionOnly(mission))  # type: ignore[arg-type]
    except InvalidInput:
        start = mission.map_start
    answer["start"] = {"x": round(start[0], MAP_DECIMALS), "y": round(start[1], MAP_DECIMALS),
                       "yaw_deg": round(math.degrees(start[2]), 3)}
    if world is not None:
        # the robot starts at the world's start and at the mission's start on the map: that fixes the map frame
        map_from_world = compose(start, invert((world.start_x, world.start_y, world.start_yaw)))
        answer["world"] = _world_in_map(world, map_from_world)
    doc = mission.doc
    raw, _ = _raw_mission(folder, text, path)
    raw_places = raw.data.get("places") if raw is not None and isinstance(raw.data, dict) else None
    places_file = raw_places.get("file") if isinstance(raw_places, dict) and set(raw_places) == {"file"} else None
    for place in mission.places.values():
        item: dict[str, Any] = {"name": place.name, "tolerance_m": place.tolerance_m}
        if place.on_map:
            item.update(x=round(place.x, MAP_DECIMALS), y=round(place.y, MAP_DECIMALS),
                        yaw_deg=None if place.yaw is None else round(math.degrees(place.yaw), 3))
        else:  # a GPS place on a mission with a map: listed, but it has no spot on the map
            item.update(lat=place.lat, lon=place.lon)
        if places_file is not None:
            at = raw.position(("places", "file"))
            item.update(readonly=True, file=str(places_file))
        else:
            at = doc.position(("places", place.name), key=True)
        item.update(line=at.line, column=at.column)
        answer["places"].append(item)
    _map_fences(doc, mission, answer)
    from beastbt.mission import steps as st
    from beastbt.mission.warnings import all_steps
    for step in list(all_steps(mission.steps)) + [s for task in mission.tasks.values() for s in all_steps(task)]:
        if isinstance(step, st.Route):
            known = [mission.places[n] for n in step.places if n in mission.places and mission.places[n].on_map]
            answer["routes"].append({"places": list(step.places), "points": [[p.x, p.y] for p in known],
                                     "loops": step.loops, "line": step.at.line, "column": step.at.column})


class _MissionOnly:
    """What :func:`beastbt.parts.map_localisation.start_pose` reads of a prepared run: its mission."""

    def __init__(self, mission: Any) -> None:
        self.mission = mission


def _grid_json(folder: StudioFolder, grid: Any, file: Any) -> dict:
    """The occupancy grid for drawing: a PNG data URL (map_saver's trinary grey: occupied black, free white,
    unknown grey; top row first) and where it lies in the map frame (metres)."""
    import base64
    import math

    import cv2
    from beastbt.mapping.occupancy_map import map_pixels
    ok, png = cv2.imencode(".png", map_pixels(grid))
    try:
        shown = str(Path(file).resolve().relative_to(folder.root.resolve()))
    except ValueError:
        shown = Path(file).name
    return {"file": shown, "image": "data:image/png;base64," + base64.b64encode(png.tobytes()).decode("ascii")
            if ok else None,
            "origin": {"x": grid.origin_x, "y": grid.origin_y, "yaw_deg": round(math.degrees(grid.origin_yaw), 3)},
            "resolution_m": grid.resolution_m, "cols": grid.cols, "rows": grid.rows,
            "width_m": round(grid.width_m, 6), "height_m": round(grid.height_m, 6),
            "bounds": [[grid.origin_x, grid.origin_y],
                       [round(grid.origin_x + grid.width_m, 6), round(grid.origin_y + grid.height_m, 6)]]}


def _world_in_map(world: Any, map_from_world: tuple[float, float, float]) -> dict:
    """The world's plan (walls, obstacles, floor lines, start) moved into the map frame by ``map_from_world``."""
    import math

    from beastbt.sim.floor import floor_lines
    from beastbt.sim.obstacles import obstacle_outline
    c, s = math.cos(map_from_world[2]), math.sin(map_from_world[2])

    def xy(x: float, y: float) -> list[float]:
        return [round(map_from_world[0] + c * x - s * y, MAP_DECIMALS),
                round(map_from_world[1] + s * x + c * y, MAP_DECIMALS)]

    walls = [xy(w.x1, w.y1) + xy(w.x2, w.y2) for w in world.walls]
    obstacles = []
    for o in map(obstacle_outline, world.obstacles):
        if "corners" in o:
            obstacles.append({"shape": o["shape"], "corners": [xy(*p) for p in o["corners"]]})
        elif "xy" in o:
            obstacles.append({"shape": o["shape"], "xy": xy(*o["xy"]), "radius_m": o["radius_m"]})
        elif "path" in o:
            obstacles.append({"shape": o["shape"], "path": [xy(p[0], p[1]) for p in o["path"]],
                              "radius_m": o["radius_m"]})
    floor = world.section("floor")
    try:
        lines = [{"points": [xy(float(x), float(y)) for x, y in line.points], "closed": line.closed}
                 for line in (floor_lines(floor) if floor else [])]
    except ValueError:
        lines = []
    sx, sy = xy(world.start_x, world.start_y)
    return {"name": world.name, "file": world.file, "walls": walls, "obstacles": obstacles, "lines": lines,
            "start": {"x": sx, "y": sy, "yaw_deg": round(math.degrees(world.start_yaw + map_from_world[2]), 3)},
            "map_from_world": {"x": round(map_from_world[0], 6), "y": round(map_from_world[1], 6),
                               "yaw_deg": round(math.degrees(map_from_world[2]), 6)}}


def _map_fences(doc: Any, mission: Any, answer: dict) -> None:
    """Fences whose corners are places on the map, as ``[[x, y], ...]`` (a lat/lon corner has no spot here)."""
    fences = doc.data.get("fences") if isinstance(doc.data.get("fences"), dict) else {}
    for name, fence in mission.fences.items():
        raw = fences.get(name) if isinstance(fences.get(name), dict) else {}
        corners = raw.get("polygon") or raw.get("points") or []
        polygon = [[mission.places[c].x, mission.places[c].y] for c in corners
                   if isinstance(c, str) and c in mission.places and mission.places[c].on_map]
        if len(polygon) >= 3:
            at = doc.position(("fences", name), key=True)
            answer["fences"].append({"name": name, "keep": fence.keep, "polygon": polygon, "line": at.line,
                                     "column": at.column})


def _raw_map_plan(folder: StudioFolder, doc: Any, base: Path, answer: dict) -> None:
    """The grid and the world's plan of a map mission's text that does not load yet, so that a typo elsewhere does
    not blank the map while it is typed: what of ``map:``, ``world:`` and ``start:`` reads, drawn as when it loads."""
    import math

    from beastbt.core.units import parse_quantity
    from beastbt.estimation.map_localiser import compose, invert
    from beastbt.mapping.occupancy_map import load_map
    from beastbt.sim.world import load_world
    data = doc.data

    refs = studio_refs(folder)

    def file(key: str) -> Optional[Path]:
        try:  # only what the studio may read: the mission's problems say why another is refused
            return refs.locate(data.get(key), base, MAP if key == "map" else WORLD)
        except RefusedFile:
            return None

    try:
        map_file = file("map")
        if map_file is not None:
            answer["map"] = _grid_json(folder, load_map(map_file, refs=refs), map_file)
        start = data.get("start")
        if start is None:
            pose = (0.0, 0.0, 0.0)
        elif isinstance(start, dict) and "x" in start and "y" in start:
            pose = (parse_quantity(start["x"], "distance"), parse_quantity(start["y"], "distance"),
                    parse_quantity(start["yaw"], "angle") if "yaw" in start else 0.0)
        else:
            return  # a start at a named place, or one being typed: the world waits for the mission to load
        answer["start"] = {"x": round(pose[0], MAP_DECIMALS), "y": round(pose[1], MAP_DECIMALS),
                           "yaw_deg": round(math.degrees(pose[2]), 3)}
        world_file = file("world")
        if world_file is not None:
            world = load_world(str(world_file))
            answer["world"] = _world_in_map(world, compose(pose, invert((world.start_x, world.start_y,
                                                                         world.start_yaw))))
    except Exception:  # noqa: BLE001 - a half-typed text draws what it can; its problems say the rest
        return


def _raw_map_places(doc: Any, answer: dict) -> None:
    """The ``{x, y}`` places that can be read of a map mission's text that does not load (units as the language
    writes them: ``3.0 m``)."""
    from beastbt.core.units import parse_quantity
    places = doc.data.get("places") if isinstance(doc.data.get("places"), dict) else {}
    for pname, value in places.items():
        if not isinstance(value, dict) or "x" not in value or "y" not in value:
            continue
        try:
            x, y = parse_quantity(value["x"], "distance"), parse_quantity(value["y"], "distance")
        except Exception:  # noqa: BLE001 - an unreadable number is the problems' business, not the map's
            continue
        at = doc.position(("places", pname), key=True)
        answer["places"].append({"name": str(pname), "x": round(x, MAP_DECIMALS), "y": round(y, MAP_DECIMALS),
                                 "line": at.line, "column": at.column})


def _world_map(real: Path, name: str, text: str) -> dict:
    """The map of a world file's text (unsaved changes included): its plan at its datum, nothing placed."""
    from beastbt.sim.world import empty_world, load_world
    lines = text.splitlines()
    answer: dict[str, Any] = {"frame": "gps", "datum": None, "places": [], "fences": [], "routes": [], "problems": []}
    world = None
    with tempfile.TemporaryDirectory(prefix="beastbt-studio-") as tmp:
        fake = Path(tmp) / (real.name if real.name.endswith((".yaml", ".yml")) else "world.yaml")
        fake.write_text(text, encoding="utf-8")
        try:
            world = load_world(str(fake))
        except InvalidInput as exc:
            answer["problems"] = [problem_json(Problem(name, p.position, p.message, p.hint, p.severity), name, lines)
                                  for p in exc.problems if p.severity == "error"]
    frame = (world or empty_world()).frame
    answer["datum"] = {"lat": frame.lat0_deg, "lon": frame.lon0_deg}
    if world is not None:
        answer["world"] = _world_json(world, frame)
        answer["world"]["file"] = name
    return answer


def _mission_layers(mission: Any, answer: dict) -> None:
    """Places, fences and routes of a loaded mission, each at the position of its key or step."""
    from beastbt.mission import steps as st
    from beastbt.mission.warnings import all_steps
    doc = mission.doc
    for place in mission.places.values():
        at = doc.position(("places", place.name), key=True)
        answer["places"].append({"name": place.name, "lat": place.lat, "lon": place.lon,
                                 "tolerance_m": place.tolerance_m, "line": at.line, "column": at.column})
    for fence in mission.fences.values():
        at = doc.position(("fences", fence.name), key=True)
        answer["fences"].append({"name": fence.name, "keep": fence.keep, "polygon": [list(c) for c in fence.corners],
                                 "line": at.line, "column": at.column})
    for failsafe in mission.failsafes:
        if failsafe.kind == "geofence" and "radius_m" in failsafe.params:
            centre = mission.places.get(failsafe.params.get("center"))
            if centre is not None:
                at = doc.position(failsafe.path, key=True)
                answer["fences"].append({"name": "geofence", "keep": "in", "line": at.line, "column": at.column,
                                         "circle": {"lat": centre.lat, "lon": centre.lon,
                                                    "radius_m": failsafe.params["radius_m"]}})
    steps = list(all_steps(mission.steps)) + [s for task in mission.tasks.values() for s in all_steps(task)]
    for step in steps:
        if isinstance(step, st.Route):
            known = [mission.places[n] for n in step.places if n in mission.places]
            answer["routes"].append({"places": list(step.places), "points": [[p.lat, p.lon] for p in known],
                                     "loops": step.loops, "line": step.at.line, "column": step.at.column})
        elif isinstance(step, st.GoToPoint):
            answer["routes"].append({"places": [], "points": [[step.lat_deg, step.lon_deg]], "loops": 1,
                                     "line": step.at.line, "column": step.at.column})


def _raw_layers(doc: Any, answer: dict) -> None:
    """What can be read of a text that does not load: its ``places:`` with lat/lon, ``fences:`` of corners, routes."""
    data = doc.data
    places = data.get("places") if isinstance(data.get("places"), dict) else {}
    coords: dict[str, tuple[float, float]] = {}
    for pname, value in places.items():
        if isinstance(value, dict) and _number(value.get("lat")) is not None and _number(value.get("lon")) is not None:
            coords[str(pname)] = (float(value["lat"]), float(value["lon"]))
            at = doc.position(("places", pname), key=True)
            answer["places"].append({"name": str(pname), "lat": coords[str(pname)][0], "lon": coords[str(pname)][1],
                                     "line": at.line, "column": at.column})
    fences = data.get("fences") if isinstance(data.get("fences"), dict) else {}
    for fname, value in fences.items():
        corners = value.get("polygon") if isinstance(value, dict) else None
        if not isinstance(corners, list):
            continue
        polygon = []
        for c in corners:
            if isinstance(c, dict) and _number(c.get("lat")) is not None and _number(c.get("lon")) is not None:
                polygon.append([float(c["lat"]), float(c["lon"])])
            elif isinstance(c, str) and c in coords:
                polygon.append(list(coords[c]))
        if len(polygon) >= 3:
            at = doc.position(("fences", fname), key=True)
            answer["fences"].append({"name": str(fname), "keep": "out" if value.get("keep") == "out" else "in",
                                     "polygon": polygon, "line": at.line, "column": at.column})
    steps = data.get("steps") if isinstance(data.get("steps"), list) else []
    for i, step in enumerate(steps):
        route = step.get("route") if isinstance(step, dict) else None
        names = route.get("places") if isinstance(route, dict) else None
        if isinstance(names, list):
            at = doc.position(("steps", i))
            answer["routes"].append({"places": [str(n) for n in names],
                                     "points": [list(coords[n]) for n in names if isinstance(n, str) and n in coords],
                                     "loops": 1, "line": at.line, "column": at.column})


def _world_json(world: Any, frame: Any) -> dict:
    """A world's plan in its frame (metres, x east, y north) and the same in lat/lon for a map (``*_latlon``)."""
    from beastbt.sim.floor import floor_lines
    from beastbt.sim.obstacles import obstacle_outline

    def latlon(x: float, y: float) -> list[float]:
        lat, lon, _ = frame.to_geodetic(x, y, 0.0)
        return [round(lat, 8), round(lon, 8)]

    walls = [[w.x1, w.y1, w.x2, w.y2] for w in world.walls]
    floor = world.section("floor")
    try:
        lines = [{"points": [[round(float(x), 3), round(float(y), 3)] for x, y in line.points], "closed": line.closed}
                 for line in (floor_lines(floor) if floor else [])]
    except ValueError:
        lines = []
    obstacles = [obstacle_outline(o) for o in world.obstacles]
    for o in obstacles:
        if "corners" in o:
            o["corners_latlon"] = [latlon(x, y) for x, y in o["corners"]]
        if "xy" in o:
            o["latlon"] = latlon(*o["xy"])
        if "path" in o:
            o["path_latlon"] = [latlon(p[0], p[1]) for p in o["path"]]
    import math
    return {"name": world.name, "file": world.file, "walls": walls,
            "walls_latlon": [[latlon(x1, y1), latlon(x2, y2)] for x1, y1, x2, y2 in walls],
            "obstacles": obstacles, "lines": lines,
            "lines_latlon": [[latlon(x, y) for x, y in line["points"]] for line in lines],
            "start": {"x": world.start_x, "y": world.start_y, "yaw_deg": round(math.degrees(world.start_yaw), 3),
                      "lat": latlon(world.start_x, world.start_y)[0], "lon": latlon(world.start_x, world.start_y)[1]}}
