"""Fences (mission language v2): polygons kept in or out of, as failsafes and conditions, from places or files."""

from __future__ import annotations

import json

import pytest

from beastbt.core.errors import InvalidInput
from beastbt.estimation.geodesy import LocalFrame
from beastbt.mission.fences import Fence
from beastbt.mission.model import load_mission
from beastbt.testing import MissionHarness
from conftest import REPO

DATUM = LocalFrame(40.41680, -3.70380)  # worlds/campus.yaml


def corners(*east_north: tuple[float, float]) -> list[tuple[float, float]]:
    return [DATUM.to_geodetic(e, n, 0.0)[:2] for e, n in east_north]


def flow(points: list[tuple[float, float]]) -> str:
    return "[" + ", ".join(f"{{lat: {lat:.8f}, lon: {lon:.8f}}}" for lat, lon in points) + "]"


def test_inside_crossed_and_margin_in_metres():
    square = Fence("sq", corners((-5, -5), (5, -5), (5, 5), (-5, 5)))
    lat, lon = DATUM.to_geodetic(4.5, 0, 0)[:2]
    assert square.contains(lat, lon) and not square.crossed(lat, lon) and square.crossed(lat, lon, margin_m=1.0)
    out = DATUM.to_geodetic(6, 0, 0)[:2]
    assert not square.contains(*out) and square.crossed(*out)
    pond = Fence("pond", square.corners, keep="out")
    assert pond.crossed(lat, lon) and not pond.crossed(*out) and pond.crossed(*out, margin_m=1.5)
    assert Fence("bow", corners((0, 0), (5, 5), (5, 0), (0, 5))).valid_problem() is not None  # edges cross


def mission(fences: str, failsafes: str, steps: str) -> MissionHarness:
    return MissionHarness.from_yaml(f"mission: fenced\nworld: campus.yaml\nfences:\n{fences}failsafes:\n{failsafes}"
                                    f"steps:\n{steps}", base_dir=REPO / "worlds", seed=1)


def test_the_geofence_stops_the_robot_before_it_leaves_the_yard():
    yard = flow(corners((-12, -12), (12, -12), (12, 12), (-12, 12)))
    h = mission(f"  yard: {{polygon: {yard}}}\n", "  geofence: {fence: yard, margin: 2 m, then: stop}\n",
                "  - wait: 5 s\n  - drive: {distance: 25 m, speed: 0.4 m/s}\n")
    assert h.run_to_end(200) == "failure"
    assert any(e.kind == "failsafe" and "geofence triggered" in e.text for e in h.events)
    assert 6.0 < max(abs(h.truth.x), abs(h.truth.y)) < 12.5  # stopped near the fence, not 25 m out


def test_keepout_and_the_inside_outside_conditions(tmp_path):
    pond = flow(corners((-12, 8), (12, 8), (12, 14), (-12, 14)))  # a band across the way north
    h = mission(f"  pond: {{polygon: {pond}, keep: out}}\n", "  keepout: {fence: pond, margin: 1 m, then: stop}\n",
                "  - wait: 5 s\n  - if: {outside: pond}\n    then: [say: dry]\n"
                "  - drive: {distance: 20 m, speed: 0.4 m/s}\n")
    assert h.run_to_end(200) == "failure"
    assert any(e.kind == "say" and e.text == "dry" for e in h.events)
    assert any(e.kind == "failsafe" and "keepout triggered" in e.text for e in h.events)
    assert 4.0 < h.truth.y < 8.0


@pytest.mark.parametrize("name, content", [
    ("site.geojson", json.dumps({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {},
        "geometry": {"type": "Polygon", "coordinates": [[[lon, lat] for lat, lon in
                                                         corners((-9, -9), (9, -9), (9, 9), (-9, 9), (-9, -9))]]}}]})),
    ("site.kml", '<kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><Polygon><outerBoundaryIs><LinearRing>'
                 "<coordinates>" + " ".join(f"{lon},{lat},0" for lat, lon in corners((-9, -9), (9, -9), (9, 9), (-9, 9)))
                 + "</coordinates></LinearRing></outerBoundaryIs></Polygon></Placemark></kml>"),
])
def test_a_fence_from_a_file(tmp_path, name, content):
    (tmp_path / name).write_text(content)
    (tmp_path / "m.yaml").write_text(f"mission: f\nfences:\n  site: {{file: {name}}}\nplaces:\n  out: "
                                     f"{flow(corners((30, 0)))[1:-1]}\nsteps: [wait: 1 s]\n")
    m = load_mission(tmp_path / "m.yaml")
    assert len(m.fences["site"].corners) == 4 and m.fences["site"].contains(DATUM.lat0_deg, DATUM.lon0_deg)
    assert any("outside the keep-in fence 'site'" in w.message for w in m.warnings)


@pytest.mark.parametrize("fences, failsafe, says", [
    ("  yard: {polygon: [{lat: 40.4168, lon: -3.7038}, {lat: 40.4169, lon: -3.7038}]}\n", "", "needs at least 3 items, has 2"),
    ("  bow: {polygon: " + flow(corners((0, 0), (5, 5), (5, 0), (0, 5))) + "}\n", "", "not a simple polygon"),
    ("  yard: {polygon: " + flow(corners((0, 0), (5, 0), (5, 5))) + "}\n",
     "failsafes:\n  geofence: {fence: yrad, then: stop}\n", "unknown fence 'yrad'; did you mean 'yard'?"),
])
def test_bad_fences_are_errors_with_positions(tmp_path, fences, failsafe, says):
    (tmp_path / "m.yaml").write_text(f"mission: f\nfences:\n{fences}{failsafe}steps: [wait: 1 s]\n")
    with pytest.raises(InvalidInput) as info:
        load_mission(tmp_path / "m.yaml")
    assert says in info.value.format() and "m.yaml:" in info.value.format()
