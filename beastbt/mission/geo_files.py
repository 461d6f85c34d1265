"""Places and routes from the files people plan with (mission language v2).

Named places: GPX waypoints (``wpt``), KML ``Placemark`` points, GeoJSON
``Point`` features with a ``name``. Routes: a GPX route (``rte``) or track
(``trk``), a KML ``LineString``, a GeoJSON ``LineString``, a QGroundControl
``.plan`` (its ``NAV_WAYPOINT`` items), a Mission Planner ``.waypoints``
(``QGC WPL 110``). GPX is read with gpxpy; KML with the standard library's
XML parser; the rest are JSON or text. A file that cannot be read is a
:class:`GeoFileError` naming the line where the format has lines; what
beastbt cannot do (altitudes, other mission commands) is listed in
``ignored`` so that the loader can warn once.

Every file is bounded before it is parsed (issue 38: a 78 MB GPX of 2 million
points was still validating after 120 s): at most :data:`MAX_GEO_FILE_BYTES`
on disk, checked with ``stat`` before reading, and at most
:data:`MAX_GEO_POINTS` points, counted while streaming through the XML with
expat (GPX, KML) or over the text (GeoJSON, .plan, .waypoints) before the
points are built. A JSON file's lists and objects are bounded in number and
depth on its text too, before the JSON reader builds (or recurses into) them.
"""

from __future__ import annotations

import json
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Optional

if TYPE_CHECKING:
    from beastbt.core.file_refs import FileRefs

MAX_GEO_FILE_BYTES = 16 << 20
"""The largest route, places or fence file read, in bytes (16 MiB): ten thousand GPX track points with times and
elevations take about 2 MB."""
MAX_GEO_POINTS = 10_000
"""The most points a route, places or fence file may hold (each becomes a place of the mission and a go_to): a
real route has hundreds, a recorded track at 1 s a few thousand an hour."""
MAX_JSON_DEPTH = 64
"""How deep a GeoJSON or .plan file may nest lists and objects: GeoJSON needs 6 levels (a MultiPolygon's
coordinates in a feature of a collection)."""
THIN_HINT = ("thin it to at most {max:,} points first (GPSBabel: gpsbabel -i gpx -f IN -x simplify,count=1000 "
             "-o gpx -F OUT), or split the route into several files")
"""The hint of a file with too many points."""
MAX_XML_ELEMENTS = 20 * MAX_GEO_POINTS
"""The most elements a GPX or KML file may hold (each a node of the tree gpxpy or ElementTree builds): a GPX track
point with its time, elevation and a sports watch's extensions is some ten."""
_XML_CHUNK_BYTES = 1 << 16
"""How much of an XML file expat is given at a time while its points are counted."""

NAV_WAYPOINT = 16
"""MAVLink MAV_CMD_NAV_WAYPOINT: the only mission item a ground robot's route takes from a .plan or .waypoints."""
KML_NS = "{http://www.opengis.net/kml/2.2}"


class GeoFileError(ValueError):
    """A places or route file that cannot be read: ``line`` (1-based) where the format has lines, else None;
    ``column`` (1-based) where known, ``hint`` what to do when there is more to say than 'fix the file'."""

    def __init__(self, message: str, line: Optional[int] = None, column: int = 1,
                 hint: Optional[str] = None) -> None:
        super().__init__(message)
        self.line = line
        self.column = column
        self.hint = hint


def _too_many_points(what: str, line: Optional[int], column: int = 1) -> GeoFileError:
    return GeoFileError(f"more than {MAX_GEO_POINTS:,} {what}: a route, places or fence file holds at most "
                        f"{MAX_GEO_POINTS:,} points", line, column, THIN_HINT.format(max=MAX_GEO_POINTS))


def _count_xml_points(path: Path, point_tags: frozenset, coordinates: bool) -> None:
    """Stream the XML at ``path`` through expat, counting its points without building them: elements named in
    ``point_tags`` (GPX ``wpt``, ``rtept``, ``trkpt``), or, with ``coordinates``, the ``lon,lat[,alt]`` tuples of
    every KML ``coordinates`` element; GeoFileError at the first point beyond :data:`MAX_GEO_POINTS`, or the first
    element beyond :data:`MAX_XML_ELEMENTS`."""
    import xml.parsers.expat

    parser = xml.parsers.expat.ParserCreate()
    count = 0
    inside = [False]  # inside a <coordinates> element
    in_word = [False]  # the last character data ended inside a tuple (expat may cut text anywhere)

    elements = 0

    def start(name: str, attrs: dict) -> None:
        nonlocal count, elements
        elements += 1
        if elements > MAX_XML_ELEMENTS:  # each becomes an object of the reader's tree: bounded like the points
            raise GeoFileError(f"more than {MAX_XML_ELEMENTS:,} XML elements: a route, places or fence file holds "
                               f"at most {MAX_GEO_POINTS:,} points", parser.CurrentLineNumber,
                               parser.CurrentColumnNumber + 1, THIN_HINT.format(max=MAX_GEO_POINTS))
        local = name.rsplit(":", 1)[-1]
        if coordinates:
            inside[0] = local == "coordinates"
            in_word[0] = False
        elif local in point_tags:
            count += 1
            if count > MAX_GEO_POINTS:
                raise _too_many_points("points (wpt, rtept, trkpt)", parser.CurrentLineNumber,
                                       parser.CurrentColumnNumber + 1)

    def end(name: str) -> None:
        inside[0] = False

    def text(data: str) -> None:
        nonlocal count
        if not inside[0]:
            return
        line, column = parser.CurrentLineNumber, parser.CurrentColumnNumber + 1
        for match in re.finditer(r"\S+", data):
            if match.start() == 0 and in_word[0]:
                continue  # the rest of a tuple the previous piece of text began
            count += 1
            if count > MAX_GEO_POINTS:
                before = data[:match.start()]
                newlines = before.count("\n")
                col = (len(before) - before.rfind("\n")) if newlines else column + len(before)
                raise _too_many_points("coordinates (lon,lat tuples)", line + newlines, col)
        in_word[0] = bool(data) and not data[-1].isspace()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = text
    try:
        with open(path, "rb") as f:
            while True:
                chunk = f.read(_XML_CHUNK_BYTES)
                parser.Parse(chunk, not chunk)
                if not chunk:
                    break
    except xml.parsers.expat.ExpatError:
        return  # the format's own reader says where and why, as before; it too stops there


def _line_column(text: str, index: int) -> tuple[int, int]:
    """The 1-based line and column of ``text[index]``."""
    return text.count("\n", 0, index) + 1, index - (text.rfind("\n", 0, index) + 1) + 1


def _json_shape_problem(text: str, what: str) -> Optional[GeoFileError]:
    """The first place where ``text`` nests lists and objects deeper than :data:`MAX_JSON_DEPTH`, or opens more
    than :data:`MAX_JSON_CONTAINERS` of them (strings skipped); None when it does neither. Looks at most at the
    first :data:`MAX_JSON_CONTAINERS` + 1 of them."""
    depth = opened = 0
    for match in re.finditer(r'"(?:[^"\\]|\\.)*"|[\[\]{}]', text):
        token = match.group()
        if token in "[{":
            depth += 1
            opened += 1
            if depth > MAX_JSON_DEPTH:
                return GeoFileError(f"not valid {what}: lists and objects nested more than {MAX_JSON_DEPTH} deep",
                                    *_line_column(text, match.start()),
                                    "a GeoJSON file nests 6 levels at most: is this the right file?")
            if opened > MAX_JSON_CONTAINERS:
                return GeoFileError(f"more than {MAX_JSON_CONTAINERS:,} lists and objects: a route, places or "
                                    f"fence file holds at most {MAX_GEO_POINTS:,} points",
                                    *_line_column(text, match.start()), THIN_HINT.format(max=MAX_GEO_POINTS))
        elif token in "]}":
            depth -= 1
    return None


MAX_JSON_CONTAINERS = 5 * MAX_GEO_POINTS
"""The most lists and objects a GeoJSON or .plan file may open: a named GeoJSON Point is four (its feature, geometry,
properties and coordinates), so 10,000 places fit."""

_JSON_PAIR = re.compile(r"\[\s*-?[\d.]")
"""The start of a JSON list whose first item is a number: a coordinate pair (or a .plan's params)."""


@dataclass
class GeoPoints:
    """What a file gave: ``points`` as (name or None, lat, lon) and what was ``ignored`` (one line each)."""

    points: list[tuple[Optional[str], float, float]] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)


def _check(lat: float, lon: float, where: str, line: Optional[int] = None) -> tuple[float, float]:
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise GeoFileError(f"{where}: latitude {lat} / longitude {lon} is not on Earth (lat -90..90, lon -180..180)",
                           line)
    return lat, lon


def _gpx(path: Path, want: str) -> GeoPoints:
    import gpxpy
    import gpxpy.gpx
    _count_xml_points(path, frozenset(("wpt", "rtept", "trkpt")), coordinates=False)
    try:
        gpx = gpxpy.parse(path.read_text(encoding="utf-8"))
    except gpxpy.gpx.GPXXMLSyntaxException as exc:
        match = re.search(r"line (\d+)", str(exc))
        raise GeoFileError(f"not valid GPX: {exc}", int(match.group(1)) if match else None) from None
    except gpxpy.gpx.GPXException as exc:
        raise GeoFileError(f"not valid GPX: {exc}") from None
    out = GeoPoints()
    if want == "places":
        pts = [(w.name, w.latitude, w.longitude, w.elevation) for w in gpx.waypoints]
    else:
        pts = [(None, p.latitude, p.longitude, p.elevation) for r in gpx.routes for p in r.points]
        if not pts:
            pts = [(None, p.latitude, p.longitude, p.elevation) for t in gpx.tracks for s in t.segments
                   for p in s.points]
    for name, lat, lon, ele in pts:
        out.points.append((name, *_check(lat, lon, "a GPX point")))
    if any(p[3] is not None for p in pts):
        out.ignored.append("altitudes (a ground robot drives on the ground)")
    return out


def _kml(path: Path, want: str) -> GeoPoints:
    import xml.etree.ElementTree as ET  # only for a mission with a KML file: it costs every start-up otherwise

    _count_xml_points(path, frozenset(), coordinates=True)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise GeoFileError(f"not valid KML (XML): {exc}", exc.position[0]) from None
    out = GeoPoints()
    altitudes = False
    for placemark in root.iter(f"{KML_NS}Placemark"):
        name = placemark.findtext(f"{KML_NS}name")
        if want == "places":
            coords = placemark.findtext(f"{KML_NS}Point/{KML_NS}coordinates")
        elif want == "polygon":
            coords = placemark.findtext(f".//{KML_NS}Polygon/{KML_NS}outerBoundaryIs/{KML_NS}LinearRing/"
                                        f"{KML_NS}coordinates")
        else:
            coords = placemark.findtext(f".//{KML_NS}LineString/{KML_NS}coordinates")
        if not coords:
            continue
        for triple in coords.split():
            parts = triple.split(",")
            try:
                lon, lat = float(parts[0]), float(parts[1])
            except (ValueError, IndexError):
                raise GeoFileError(f"KML coordinates '{triple}' are not lon,lat[,alt]") from None
            altitudes |= len(parts) > 2 and float(parts[2] or 0) != 0.0
            out.points.append((name if want == "places" else None, *_check(lat, lon, "a KML point")))
        if want in ("route", "polygon") and out.points:
            break  # the first LineString (or Polygon) is the one
    if altitudes:
        out.ignored.append("altitudes (a ground robot drives on the ground)")
    return out


def _json(path: Path, what: str) -> object:
    """The JSON document at ``path``; GeoFileError at its line when it is not JSON, nests beyond
    :data:`MAX_JSON_DEPTH`, or holds more than :data:`MAX_GEO_POINTS` lists that start with a number (counted
    on the text, before the lists are built)."""
    text = path.read_text(encoding="utf-8")
    for i, match in enumerate(_JSON_PAIR.finditer(text)):
        if i == MAX_GEO_POINTS:
            raise _too_many_points("coordinate lists", *_line_column(text, match.start()))
    # Every list and object costs memory once parsed (an empty list 56 bytes) and a level of the JSON reader's
    # recursion (200,000 levels: a RecursionError): their number and depth are bounded on the text first.
    problem = _json_shape_problem(text, what)
    if problem is not None:
        raise problem
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise GeoFileError(f"not valid {what} (JSON): {exc.msg}", exc.lineno, exc.colno) from None


def _geojson(path: Path, want: str) -> GeoPoints:
    data = _json(path, "GeoJSON")
    features = data.get("features", [data]) if isinstance(data, dict) else []
    out = GeoPoints()
    for feature in features:
        geometry = feature.get("geometry") or {} if isinstance(feature, dict) else {}
        kind, coords = geometry.get("type"), geometry.get("coordinates")
        if want == "places" and kind == "Point":
            name = (feature.get("properties") or {}).get("name")
            if name:
                out.points.append((str(name), *_check(float(coords[1]), float(coords[0]), "a GeoJSON Point")))
        elif want == "route" and kind == "LineString":
            for c in coords:
                out.points.append((None, *_check(float(c[1]), float(c[0]), "a GeoJSON LineString point")))
            break
        elif want == "polygon" and kind in ("Polygon", "MultiPolygon"):
            ring = coords[0] if kind == "Polygon" else coords[0][0]
            for c in ring:
                out.points.append((None, *_check(float(c[1]), float(c[0]), "a GeoJSON Polygon corner")))
            break
    return out


def _plan(path: Path, want: str) -> GeoPoints:
    data = _json(path, "QGroundControl .plan")
    items = ((data.get("mission") or {}).get("items") or []) if isinstance(data, dict) else []
    out = GeoPoints()
    others: set[int] = set()
    for item in items:
        if item.get("command") == NAV_WAYPOINT:
            params = item.get("params") or []
            out.points.append((None, *_check(float(params[4]), float(params[5]), "a .plan waypoint")))
        elif "command" in item:
            others.add(int(item["command"]))
    if others:
        out.ignored.append(f"mission commands other than NAV_WAYPOINT ({', '.join(map(str, sorted(others)))})")
    if out.points:
        out.ignored.append("altitudes (a ground robot drives on the ground)")
    return out


def _waypoints(path: Path, want: str) -> GeoPoints:
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines or not lines[0].startswith("QGC WPL 110"):
        raise GeoFileError("not a Mission Planner .waypoints file: the first line must be 'QGC WPL 110'", 1)
    out = GeoPoints()
    others: set[int] = set()
    for number, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        if len(fields) < 12:
            raise GeoFileError(f"a .waypoints line has 12 fields, this one {len(fields)}", number)
        try:
            index, command, lat, lon = int(fields[0]), int(fields[3]), float(fields[8]), float(fields[9])
        except ValueError:
            raise GeoFileError("a .waypoints line's fields must be numbers", number) from None
        if index == 0:
            continue  # the home position, not a point to visit
        if command == NAV_WAYPOINT:
            if len(out.points) == MAX_GEO_POINTS:
                raise _too_many_points("waypoints", number)
            out.points.append((None, *_check(lat, lon, "a .waypoints waypoint", number)))
        else:
            others.add(command)
    if others:
        out.ignored.append(f"mission commands other than NAV_WAYPOINT ({', '.join(map(str, sorted(others)))})")
    return out


def _check_size(path: Path) -> None:
    """GeoFileError for what is no regular file, or a file over :data:`MAX_GEO_FILE_BYTES`, before reading it."""
    info = path.stat()
    if not stat.S_ISREG(info.st_mode):
        raise GeoFileError(f"{path.name} is not a regular file (a folder, a device or a pipe?)", None, 1,
                           "name a GPX, KML, GeoJSON, .plan or .waypoints file")
    if info.st_size > MAX_GEO_FILE_BYTES:
        raise GeoFileError(f"{path.name} is {info.st_size / (1 << 20):,.1f} MB: a route, places or fence file is "
                           f"read up to {MAX_GEO_FILE_BYTES >> 20} MB", None, 1,
                           THIN_HINT.format(max=MAX_GEO_POINTS))


READERS = {".gpx": _gpx, ".kml": _kml, ".geojson": _geojson, ".json": _geojson, ".plan": _plan,
           ".waypoints": _waypoints}
"""File suffix -> reader."""


def read_points(path: Path, want: str) -> GeoPoints:
    """The named places (``want="places"``) or the route points (``"route"``) of the file at ``path``."""
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise GeoFileError(f"'{path.suffix}' files are not read: use .gpx, .kml, .geojson, .plan or .waypoints")
    try:
        _check_size(path)
        got = reader(path, want)
    except FileNotFoundError:
        raise GeoFileError(f"{path} does not exist (paths are relative to the mission file)") from None
    except OSError as exc:
        raise GeoFileError(f"cannot read {path}: {exc.strerror or exc}") from None
    except GeoFileError:
        raise
    except RecursionError:  # elements nested thousands deep, past the readers' recursion
        raise GeoFileError(f"{path.name} nests its elements too deeply to be read", None, 1,
                           "a route file nests a few levels: is this the right file?") from None
    except (ValueError, OverflowError, TypeError, KeyError, IndexError, AttributeError) as exc:
        # A coordinate that is no number, a 400-digit one (float() overflows), a 5000-digit one (int() refuses).
        raise GeoFileError(f"cannot read the points of {path.name}: {str(exc)[:200]}") from None
    if len(got.points) > MAX_GEO_POINTS:  # what the readers' own counts let through (a .plan's items)
        raise _too_many_points("points", None)
    if want == "polygon" and len(got.points) > 3 and got.points[0][1:] == got.points[-1][1:]:
        got.points.pop()  # a closed ring repeats its first corner
    if not got.points:
        what = {"polygon": "polygon (KML Polygon, GeoJSON Polygon)",
                "places": "named points (GPX wpt, KML Placemark Point, GeoJSON Point with a name)"}.get(
            want, "route (GPX rte/trk, KML or GeoJSON LineString, .plan or .waypoints NAV_WAYPOINTs)")
        raise GeoFileError(f"{path.name} has no {what}")
    return got




def _name(text: str, fallback: str) -> str:
    """A mission name from a file's point name (letters of any alphabet, digits, _ and -; starting with a letter)."""
    cleaned = re.sub(r"[^\w-]+", "_", text.strip()).strip("_")
    if not cleaned or not cleaned[0].isalpha():
        cleaned = f"{fallback}_{cleaned}" if cleaned else fallback
    return cleaned


UNREADABLE_ROUTE = "unreadable_route_file"
"""The place a route whose file cannot be read stands for: the file's own error says what is wrong, so the mission's
check passes over this name instead of adding an "unknown place" error."""


_NAME = re.compile(r"^[^\W\d][\w-]*$")
"""A place name the mission language accepts: a letter first, then letters, digits, _ and -."""

MAP_PLACE_KEYS = ("x", "y", "yaw", "tolerance")
"""What a place on the map may say (the mission schema's map_place)."""


def map_places_file(doc: "SourceDoc", base: Path, relative: str,  # type: ignore[name-defined]  # noqa: F821
                    errors: list, refs: Optional["FileRefs"] = None) -> dict:
    """The named poses of a places YAML (``name: {x: 1 m, y: 2 m, yaw: 90 deg, tolerance: 0.3 m}``, map frame) as
    the mission's ``places:``; problems go to ``errors``, positioned in that file (and at the mission's ``file:``
    when the file cannot be read)."""
    from beastbt.core.errors import InvalidInput, Problem
    from beastbt.core.units import parse_quantity
    from beastbt.core.file_refs import CLI, PLACES, RefusedFile
    from beastbt.core.yaml_source import load_yaml
    try:
        path = (refs or CLI).locate(relative, base, PLACES)
    except RefusedFile as exc:
        if "does not exist" in exc.message:
            errors.append(doc.problem(("places", "file"), f"the places file {relative} does not exist",
                                      "the path is relative to the mission file; a places YAML holds "
                                      "name: {x: 1 m, y: 2 m, yaw: 90 deg} lines"))
        else:
            errors.append(doc.problem(("places", "file"), exc.message, exc.hint))
        return {}
    try:
        places = load_yaml(path)
    except InvalidInput as exc:
        errors.extend(exc.problems)
        return {}
    hint = "each place is name: {x: 1.5 m, y: -2 m} with optional yaw: 90 deg and tolerance: 0.3 m"
    out: dict = {}
    for name, value in places.data.items():
        where = (name,)
        if not isinstance(name, str) or not _NAME.match(name):
            errors.append(places.problem(where, f"place name {name!r} must start with a letter (then letters, digits, "
                                                f"_ and -)", hint,
                                         key=True))
            continue
        if not isinstance(value, dict) or "x" not in value or "y" not in value:
            errors.append(places.problem(where, f"place '{name}' needs x and y (metres on the map)", hint))
            continue
        bad = [k for k in value if k not in MAP_PLACE_KEYS]
        if bad:
            errors.append(places.problem(where + (bad[0],), f"place '{name}': unknown key '{bad[0]}'", hint,
                                         key=True))
            continue
        ok = True
        for key in value:
            kind = "angle" if key == "yaw" else "distance"
            try:
                parse_quantity(value[key], kind)
            except (ValueError, TypeError) as exc:
                example = "an angle such as 90 deg" if kind == "angle" else "a distance such as 2 m"
                errors.append(places.problem(where + (key,), f"place '{name}': '{key}' {exc}", example))
                ok = False
        if ok:
            out[name] = dict(value)
    if not out and not any(isinstance(p, Problem) and p.file == places.file for p in errors):
        errors.append(places.problem((), "the places file names no place", hint))
    return out


def resolve_geo_files(doc: "SourceDoc", base: Path,  # type: ignore[name-defined]  # noqa: F821
                      refs: Optional["FileRefs"] = None) -> tuple[list, list]:
    """Read ``places: {file}`` and every ``route: {file}`` of a mission document into plain places (in ``doc.data``).

    The files are found and opened where ``refs`` allows (default: anywhere, the command line's policy; see
    :mod:`beastbt.core.file_refs`): regular files within the route file's byte cap.

    Returns (errors, warnings) as Problems: errors at the file's line (and at
    the mission's ``file:``), warnings for what a file carries that beastbt
    ignores (once per file).
    """
    from beastbt.core.errors import Position, Problem, warning
    from beastbt.core.yaml_source import values_at_key
    errors: list = []
    warnings: list = []
    data = doc.data if isinstance(doc.data, dict) else {}

    from beastbt.core.file_refs import CLI, ROUTE, RefusedFile

    def load(path_key: tuple, relative: str, want: str) -> Optional[GeoPoints]:
        try:
            path = (refs or CLI).locate(relative, base, ROUTE)
        except RefusedFile as exc:  # missing, outside where it may be, a device, too large: the path as written
            missing = f"the {want} file {relative} cannot be read: it does not exist"
            errors.append(doc.problem(path_key, missing if "does not exist" in exc.message else exc.message,
                                      exc.hint))
            return None
        try:
            got = read_points(path, want)
        except GeoFileError as exc:
            errors.append(doc.problem(path_key, f"the {want if want != 'places' else 'places'} file {relative} "
                                                f"cannot be read: {exc}",
                                      exc.hint or "fix the file, or point 'file:' at another"))
            if exc.line is not None:
                errors.append(Problem(str(path), Position(exc.line, exc.column), str(exc), exc.hint))
            return None
        for what in got.ignored:
            warnings.append(warning(doc.problem(path_key, f"{relative}: ignored {what}")))
        return got

    places = data.get("places")
    if (isinstance(places, dict) and set(places) == {"file"} and isinstance(places["file"], str)
            and Path(places["file"]).suffix.lower() in (".yaml", ".yml")):
        data["places"] = map_places_file(doc, base, places["file"], errors, refs)
    elif isinstance(places, dict) and set(places) == {"file"} and isinstance(places["file"], str):
        got = load(("places", "file"), places["file"], "places")
        data["places"] = {} if got is None else {
            _name(name or f"point_{i + 1}", "place"): {"lat": lat, "lon": lon}
            for i, (name, lat, lon) in enumerate(got.points)}
    fences = data.get("fences")
    for name, fence in (fences.items() if isinstance(fences, dict) else []):
        if isinstance(fence, dict) and isinstance(fence.get("file"), str) and "polygon" not in fence:
            relative = fence.pop("file")
            got = load(("fences", name, "file"), relative, "polygon")
            fence["polygon"] = [{"lat": lat, "lon": lon} for _, lat, lon in got.points] if got else [
                {"lat": 0.0, "lon": 0.0}] * 3
    for path_key, route in values_at_key(data, "route"):
        if not (isinstance(route, dict) and isinstance(route.get("file"), str) and "places" not in route):
            continue
        relative = route.pop("file")
        got = load(path_key + ("file",), relative, "route")
        if got is None:
            route["places"] = [UNREADABLE_ROUTE]
            continue
        stem = _name(Path(relative).stem, "route")
        names = []
        for i, (_, lat, lon) in enumerate(got.points):
            name = f"{stem}_{i + 1}"
            data.setdefault("places", {})
            if isinstance(data["places"], dict):
                data["places"][name] = {"lat": lat, "lon": lon}
            names.append(name)
        route["places"] = names
    return errors, warnings


__all__ = ["UNREADABLE_ROUTE", "read_points", "resolve_geo_files", "GeoFileError", "GeoPoints", "READERS",
           "MAX_GEO_FILE_BYTES", "MAX_GEO_POINTS", "MAX_JSON_DEPTH", "MAX_JSON_CONTAINERS", "MAX_XML_ELEMENTS"]
