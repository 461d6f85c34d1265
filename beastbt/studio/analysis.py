"""What the studio shows of a text that is not saved yet: its problems, its compiled tree, what its map draws.

Each function takes the studio's folder, the text, the relative path the text
is (or will be) saved at (so ``world:`` and geo files resolve from its
folder), and a robot profile, and answers the JSON of docs/studio.md. The
checks are beastbt's own (the same as ``beastbt validate`` prints): nothing
here judges a mission by other rules.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any, Optional

from beastbt.core.errors import InvalidInput, Position, Problem
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


def robot_argument(folder: StudioFolder, robot: Optional[str]) -> str:
    """What ``load_profile`` takes for the page's robot: a bundled name as is, a folder file by its real path."""
    if not robot:
        return DEFAULT_ROBOT
    if robot.endswith((".yaml", ".yml")):
        return str(folder.resolve(robot))
    return robot


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
        from beastbt.mission.model import load_mission
        mission = load_mission(real, text=text, display_name=name)
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
    frame = (world or empty_world()).frame
    answer["datum"] = {"lat": frame.lat0_deg, "lon": frame.lon0_deg}
    if world is not None:
        answer["world"] = _world_json(world, frame)
    if mission is not None:
        _mission_layers(mission, answer)
    else:
        doc, _ = _raw_mission(folder, text, path)
        if doc is not None and isinstance(doc.data, dict):
            _raw_layers(doc, answer)
    return answer


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
