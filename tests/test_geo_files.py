"""Places and routes from GPX, KML, GeoJSON, QGroundControl .plan and Mission Planner .waypoints (language v2)."""

from __future__ import annotations

import json

import pytest

from beastbt.core.errors import InvalidInput
from beastbt.mission.model import load_mission
from beastbt.testing import MissionHarness
from conftest import REPO

A, B, C = (40.41690, -3.70380), (40.41700, -3.70350), (40.41680, -3.70330)
GPX = f"""<?xml version="1.0" encoding="UTF-8"?>
<gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1">
  <wpt lat="{A[0]}" lon="{A[1]}"><name>Gate A</name></wpt>
  <wpt lat="{B[0]}" lon="{B[1]}"><name>b</name></wpt>
  <trk><trkseg><trkpt lat="{A[0]}" lon="{A[1]}"><ele>650</ele></trkpt><trkpt lat="{B[0]}" lon="{B[1]}"/>
  <trkpt lat="{C[0]}" lon="{C[1]}"/></trkseg></trk>
</gpx>
"""
KML = f"""<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2"><Document>
  <Placemark><name>Gate A</name><Point><coordinates>{A[1]},{A[0]},0</coordinates></Point></Placemark>
  <Placemark><name>path</name><LineString><coordinates>{A[1]},{A[0]} {B[1]},{B[0]} {C[1]},{C[0]}</coordinates>
  </LineString></Placemark>
</Document></kml>
"""
GEOJSON = json.dumps({"type": "FeatureCollection", "features": [
    {"type": "Feature", "properties": {"name": "Gate A"}, "geometry": {"type": "Point", "coordinates": [A[1], A[0]]}},
    {"type": "Feature", "properties": {}, "geometry": {"type": "LineString",
                                                        "coordinates": [[A[1], A[0]], [B[1], B[0]], [C[1], C[0]]]}}]})
PLAN = json.dumps({"fileType": "Plan", "mission": {"items": [
    {"command": 22, "params": [0, 0, 0, 0, A[0], A[1], 10]},  # takeoff: not for a ground robot
    {"command": 16, "params": [0, 0, 0, 0, A[0], A[1], 0]}, {"command": 16, "params": [0, 0, 0, 0, B[0], B[1], 0]},
    {"command": 16, "params": [0, 0, 0, 0, C[0], C[1], 0]}]}})
WAYPOINTS = "QGC WPL 110\n" + "\n".join(
    "\t".join(map(str, [i, 1 if i == 0 else 0, 3, cmd, 0, 0, 0, 0, lat, lon, 0, 1]))
    for i, (cmd, (lat, lon)) in enumerate([(16, A), (16, A), (16, B), (21, C), (16, C)])) + "\n"


def mission(tmp_path, name: str, content: str, steps: str, places: bool = False):
    (tmp_path / name).write_text(content, encoding="utf-8")
    text = (f"mission: files\nworld: {REPO / 'worlds' / 'campus.yaml'}\n"
            + (f"places: {{file: {name}}}\n" if places else "") + "steps:\n" + steps)
    path = tmp_path / "m.yaml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("name, content, points", [
    ("path.gpx", GPX, 3), ("path.kml", KML, 3), ("path.geojson", GEOJSON, 3), ("path.plan", PLAN, 3),
    ("path.waypoints", WAYPOINTS, 3)])
def test_a_route_file_becomes_the_route(tmp_path, name, content, points):
    m = load_mission(mission(tmp_path, name, content, f"  - route: {{file: {name}, speed: 0.3 m/s}}\n"))
    route = m.steps[0]
    assert len(route.places) == points and route.speed_mps == pytest.approx(0.3)
    first = m.places[route.places[0]]
    assert (first.lat, first.lon) == pytest.approx(A) and (m.places[route.places[-1]].lat,
                                                            m.places[route.places[-1]].lon) == pytest.approx(C)
    ignored = [w.message for w in m.warnings if "ignored" in w.message]
    assert bool(ignored) is (name in ("path.gpx", "path.plan", "path.waypoints"))  # altitudes or other commands


@pytest.mark.parametrize("name, content", [("p.gpx", GPX), ("p.kml", KML), ("p.geojson", GEOJSON)])
def test_named_places_from_a_file(tmp_path, name, content):
    m = load_mission(mission(tmp_path, name, content, "  - go_to: Gate_A\n", places=True))
    assert (m.places["Gate_A"].lat, m.places["Gate_A"].lon) == pytest.approx(A)


def test_a_route_from_a_file_runs_on_the_simulator(tmp_path):
    path = mission(tmp_path, "path.plan", PLAN, "  - route: {file: path.plan}\n")
    h = MissionHarness.from_file(path, seed=1)
    assert h.run_to_end(600) == "success"
    assert [w["reached"] for w in h.summary()["waypoints"]] == [True, True, True]


@pytest.mark.parametrize("name, content, line, says", [
    ("bad.gpx", "<gpx><wpt lat='1' lon='2'>\n<name>x</wpt>\n</gpx>", 2, "not valid GPX"),
    ("bad.waypoints", "QGC WPL 110\n0\t1\t3\t16\n", 2, "12 fields"),
    ("bad.waypoints", "hello\n", 1, "QGC WPL 110"),
    ("bad.kml", "<kml><Document>\n<Placemark>\n</kml>", 3, "not valid KML"),
])
def test_a_bad_file_is_named_with_its_line(tmp_path, name, content, line, says):
    path = mission(tmp_path, name, content, f"  - route: {{file: {name}}}\n")
    with pytest.raises(InvalidInput) as info:
        load_mission(path)
    text = info.value.format()
    assert f"{tmp_path / name}:{line}:1: error:" in text and says in text, text
    assert "m.yaml:4:" in text and f"the route file {name} cannot be read" in text


def test_a_missing_file_and_an_unknown_format(tmp_path):
    for name, says in (("none.gpx", "does not exist"), ("x.csv", "'.csv' files are not read")):
        path = tmp_path / "m.yaml"
        if name == "x.csv":
            (tmp_path / name).write_text("1,2\n")
        path.write_text(f"mission: t\nsteps:\n  - route: {{file: {name}}}\n")
        with pytest.raises(InvalidInput, match=says):
            load_mission(path)


def test_a_missing_route_file_is_one_error_not_an_unknown_place_too(tmp_path):
    (tmp_path / "survey.gpx").write_text(
        "<gpx><wpt lat='40.4169' lon='-3.7038'><name>gate</name></wpt></gpx>\n", encoding="utf-8")
    path = tmp_path / "m.yaml"
    path.write_text("mission: t\nplaces: {file: survey.gpx}\nsteps:\n  - route: {file: missing.gpx}\n  - go_to: gate\n")
    with pytest.raises(InvalidInput) as info:
        load_mission(path)
    problems = info.value.problems
    assert len(problems) == 1, info.value.format()
    assert "the route file missing.gpx cannot be read" in problems[0].message
    assert "unknown place" not in info.value.format() and "gate" not in info.value.format()
