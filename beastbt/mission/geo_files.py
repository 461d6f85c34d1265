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
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Optional

if TYPE_CHECKING:
    from beastbt.core.file_refs import FileRefs

NAV_WAYPOINT = 16
"""MAVLink MAV_CMD_NAV_WAYPOINT: the only mission item a ground robot's route takes from a .plan or .waypoints."""
KML_NS = "{http://www.opengis.net/kml/2.2}"


class GeoFileError(ValueError):
    """A places or route file that cannot be read: ``line`` (1-based) where the format has lines, else None."""

    def __init__(self, message: str, line: Optional[int] = None) -> None:
        super().__init__(message)
        self.line = line


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
    """The JSON document at ``path``; GeoFileError at its line when it is not JSON."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise GeoFileError(f"not valid {what} (JSON): {exc.msg}", exc.lineno) from None


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
            out.points.append((None, *_check(lat, lon, "a .waypoints waypoint", number)))
        else:
            others.add(command)
    if others:
        out.ignored.append(f"mission commands other than NAV_WAYPOINT ({', '.join(map(str, sorted(others)))})")
    return out


READERS = {".gpx": _gpx, ".kml": _kml, ".geojson": _geojson, ".json": _geojson, ".plan": _plan,
           ".waypoints": _waypoints}
"""File suffix -> reader."""


def read_points(path: Path, want: str) -> GeoPoints:
    """The named places (``want="places"``) or the route points (``"route"``) of the file at ``path``."""
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise GeoFileError(f"'{path.suffix}' files are not read: use .gpx, .kml, .geojson, .plan or .waypoints")
    try:
        got = reader(path, want)
    except FileNotFoundError:
        raise GeoFileError(f"{path} does not exist (paths are relative to the mission file)") from None
    except OSError as exc:
        raise GeoFileError(f"cannot read {path}: {exc.strerror or exc}") from None
    except GeoFileError:
        raise
    except (ValueError, OverflowError, TypeError, KeyError, IndexError, AttributeError) as exc:
        # A coordinate that is no number, a 400-digit one (float() overflows), a 5000-digit one (int() refuses).
        raise GeoFileError(f"cannot read the points of {path.name}: {str(exc)[:200]}") from None
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
                                                f"cannot be read: {exc}", "fix the file, or point 'file:' at another"))
            if exc.line is not None:
                errors.append(Problem(str(path), Position(exc.line, 1), str(exc)))
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


__all__ = ["UNREADABLE_ROUTE", "read_points", "resolve_geo_files", "GeoFileError", "GeoPoints", "READERS"]
