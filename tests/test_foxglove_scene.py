"""/scene and /route: the mission's places, route and fences and the world's walls and tape, for Foxglove.

The scene is drawn in ``map``, the EKF's frame: at the robot's start until a
fused position tells where ``map`` is on Earth, then redrawn there.
"""

from __future__ import annotations

import json

import pytest

from beastbt.estimation.geodesy import LocalFrame
from beastbt.mission.model import load_mission
from beastbt.recording.config import FramesConfig
from beastbt.recording.scene import SceneView, scene_description
from beastbt.sim.world import load_world
from conftest import REPO

CAMPUS = LocalFrame(40.41680, -3.70380)  # worlds/campus.yaml's datum


def _entities(message: dict) -> dict:
    return {e["id"]: e for e in message["entities"]}


def _xy(primitive: dict) -> tuple[float, float]:
    p = primitive["pose"]["position"]
    return p["x"], p["y"]


def test_the_gps_route_places_and_route_in_order_on_the_map_and_in_3d():
    mission = load_mission(REPO / "missions" / "gps_route.yaml")
    d = scene_description(mission, load_world(REPO / "worlds" / "campus.yaml"), 0.15)
    assert [p["name"] for p in d["places"]] == ["a", "b", "c"]
    assert d["route"] == [[40.41690, -3.70380], [40.41700, -3.70350], [40.41680, -3.70330]]
    view = SceneView(json.loads(json.dumps(d)), FramesConfig())  # what crosses the pipe is plain JSON
    geo = json.loads(view.route_message()["geojson"])
    kinds = [(f["properties"]["kind"], f["properties"]["name"]) for f in geo["features"]]
    assert kinds == [("place", "a"), ("place", "b"), ("place", "c"), ("route", "route")]
    assert geo["features"][0]["geometry"]["coordinates"] == [-3.70380, 40.41690]  # GeoJSON is lon, lat
    scene = _entities(view.scene_message(5))
    # The campus start is its datum: place a is about 11 m north of map's origin.
    (ax, ay), (bx, by), _ = [_xy(s) for s in scene["places"]["spheres"]]
    assert ax == pytest.approx(0.0, abs=0.01) and ay == pytest.approx(11.1, abs=0.1)
    assert [t["text"] for t in scene["places"]["texts"]] == ["a", "b", "c"]
    assert len(scene["places"]["lines"]) == 1  # only b states a tolerance: its ring
    assert len(scene["route"]["lines"][0]["points"]) == 3
    foot = scene["footprint"]
    assert foot["frame_id"] == "base_link" and foot["frame_locked"] and foot["lines"][0]["type"] == 1


def test_the_scene_is_redrawn_once_the_estimator_anchors_map_on_earth():
    mission = load_mission(REPO / "missions" / "gps_route.yaml")
    view = SceneView(scene_description(mission, load_world(REPO / "worlds" / "campus.yaml"), 0.15), FramesConfig())
    assert not view.on_pose(0.0, 0.0, None, None, False)  # no position yet
    # The EKF anchored map 2 m east of the datum: the robot at (1, 0) in map is 3 m east of the datum.
    lat, lon, _ = CAMPUS.to_geodetic(3.0, 0.0, 0.0)
    assert view.on_pose(1.0, 0.0, lat, lon, True)
    ax, ay = _xy(_entities(view.scene_message(7))["places"]["spheres"][0])
    assert ax == pytest.approx(-2.0, abs=0.01) and ay == pytest.approx(11.1, abs=0.1)
    assert not view.on_pose(1.5, 0.0, lat, lon, True)  # anchored: the EKF never moves its frame again


def test_corridor_walls_are_cubes_and_the_line_track_is_lines_from_the_robots_start():
    corridor = load_world(REPO / "worlds" / "corridor.yaml")  # starts at (1, 0) facing east
    mission = load_mission(REPO / "missions" / "patrol.yaml")
    scene = _entities(SceneView(scene_description(mission, corridor, 0.15), FramesConfig()).scene_message(1))
    south = scene["walls"]["cubes"][0]  # [0, -1] to [10, -1]
    assert _xy(south) == pytest.approx((4.0, -1.0), abs=0.01)
    assert south["size"]["x"] == pytest.approx(10.0, abs=0.01)
    track = load_world(REPO / "worlds" / "line_track.yaml")  # starts at (0.8, 0)
    d = scene_description(load_mission(REPO / "missions" / "line_to_intersection.yaml"), track, 0.15)
    assert len(d["world"]["lines"]) == 3 and d["world"]["lines"][0]["closed"]
    lines = _entities(SceneView(d, FramesConfig()).scene_message(1))["line_track"]["lines"]
    first = lines[0]["points"][0]  # the loop starts at (0.5, 0)
    assert (first["x"], first["y"]) == pytest.approx((-0.3, 0.0), abs=0.01)
    assert lines[0]["type"] == 1 and lines[0]["thickness"] == pytest.approx(0.019)


def test_fences_and_a_geofence_circle_on_the_map_and_in_3d(tmp_path):
    yard = [CAMPUS.to_geodetic(e, n, 0.0)[:2] for e, n in ((-12, -12), (12, -12), (12, 12), (-12, 12))]
    polygon = ", ".join(f"{{lat: {lat:.8f}, lon: {lon:.8f}}}" for lat, lon in yard)
    path = tmp_path / "fenced.yaml"
    path.write_text(f"mission: fenced\nworld: {REPO / 'worlds' / 'campus.yaml'}\n"
                    "places:\n  gate: {lat: 40.41680, lon: -3.70380}\n"
                    f"fences:\n  pond: {{polygon: [{polygon}], keep: out}}\n"
                    "failsafes:\n  geofence: {center: gate, radius: 30 m, then: stop}\n"
                    "steps:\n  - go_to: {lat: 40.41685, lon: -3.70380}\n")
    d = scene_description(load_mission(path), load_world(REPO / "worlds" / "campus.yaml"), None)
    assert d["fences"][0]["keep"] == "out" and d["circles"][0]["radius_m"] == 30.0
    assert d["waypoints"][0]["lat"] == 40.41685 and d["route"] == [[40.41685, -3.70380]]
    view = SceneView(d, FramesConfig())
    geo = json.loads(view.route_message()["geojson"])
    fences = [f for f in geo["features"] if f["properties"]["kind"] == "fence"]
    assert fences[0]["properties"]["keep"] == "out"
    ring = fences[0]["geometry"]["coordinates"][0]
    assert ring[0] == ring[-1] and len(ring) == 5  # closed
    scene = _entities(view.scene_message(1))
    assert "footprint" not in scene  # no footprint radius given
    pond, circle = scene["fences"]["lines"]
    assert pond["type"] == 1 and pond["color"]["r"] > pond["color"]["g"]  # keep out: red
    xs = [p["x"] for p in circle["points"]]
    assert max(xs) == pytest.approx(30.0, abs=0.1)
    assert scene["waypoints"]["texts"][0]["text"] == "40.416850, -3.703800"
