"""FloorMap: the simulated floor's raster (what the camera sees) and its truth geometry."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml

from beastbt.sim.floor import FloorMap

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def world() -> dict:
    return yaml.safe_load((REPO / "worlds" / "line_track.yaml").read_text())


@pytest.fixture(scope="module")
def track(world: dict) -> FloorMap:
    return FloorMap.from_dict(world["floor"], np.random.default_rng(0))


def small_floor(paths: list, **extra) -> FloorMap:
    d = {"resolution_m": 0.005, "margin_m": 0.3, "background": {"colour": 190, "texture": 0}, "lines": {"width_m": 0.019, "colour": 20, "paths": paths}}
    d.update(extra)
    return FloorMap.from_dict(d, np.random.default_rng(0))


def grey_at(floor: FloorMap, x: float, y: float) -> int:
    c, r = floor.world_to_raster(x, y)
    return int(floor.image[int(round(r)), int(round(c)), 1])


# --- the sample track ------------------------------------------------------------------
def test_sample_track_junctions_and_ends(track: FloorMap) -> None:
    found = sorted((round(x, 3), round(y, 3), k) for x, y, k in track.junctions())
    assert found == [(2.0, 0.0, "+"), (2.0, 2.5, "+"), (4.0, 1.25, "T")]
    ends = sorted((round(x, 3), round(y, 3)) for x, y in track.line_ends())
    assert ends == [(2.0, -0.6), (2.0, 3.1), (2.8, 1.25)]


def test_sample_track_is_a_closed_loop_of_10_to_20_m(track: FloorMap) -> None:
    loop = track.lines[0]
    assert loop.closed
    segs = loop.segments()
    length = float(np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1).sum())
    assert 10.0 <= length <= 20.0
    assert np.allclose(segs[-1, 1], segs[0, 0])


def test_sample_track_starts_on_the_line_heading_along_it_with_a_junction_ahead(world: dict, track: FloorMap) -> None:
    st = world["start"]
    x, y, yaw = st["x"], st["y"], math.radians(st["yaw_deg"])
    assert track.distance_to_line(x, y) < 0.005
    _, _, heading = track.nearest_on_line(x, y)
    assert abs(math.remainder(heading - yaw, math.pi)) < math.radians(2)
    ahead = [math.hypot(jx - x, jy - y) for jx, jy, _ in track.junctions() if (jx - x) * math.cos(yaw) + (jy - y) * math.sin(yaw) > 0.3]
    assert ahead and min(ahead) < 3.0


def test_sample_world_floor_validates_against_the_schema(world: dict) -> None:
    schema = json.loads((REPO / "schemas" / "parts" / "floor.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(world["floor"])
    bad = dict(world["floor"], backgrund={"colour": 3})
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.Draft202012Validator(schema).validate(bad)
    assert set(world) == {"world", "description", "datum", "gps", "start", "floor"}
    assert world["gps"] == {"sky": "none"}  # an indoor track: the receiver gets no fix


# --- truth geometry -------------------------------------------------------------------
def test_distance_to_line() -> None:
    f = small_floor([{"path": [[0, 0], [2, 0]]}])
    assert f.distance_to_line(1.0, 0.0) == pytest.approx(0.0)
    assert f.distance_to_line(1.0, 0.1) == pytest.approx(0.1)
    assert f.distance_to_line(2.3, 0.4) == pytest.approx(0.5)  # past the end: to the end point
    assert f.distances_to_line(np.array([[1.0, -0.2], [0.0, 0.0]])) == pytest.approx([0.2, 0.0])


def test_arc_points_lie_on_the_circle_and_run_clockwise_when_asked() -> None:
    f = small_floor([{"path": [{"arc": {"center": [1, 1], "radius_m": 0.5, "from_deg": 90, "to_deg": 0}}]}])
    pts = f.lines[0].points
    assert np.allclose(np.hypot(pts[:, 0] - 1, pts[:, 1] - 1), 0.5)
    assert pts[0] == pytest.approx([1.0, 1.5]) and pts[-1] == pytest.approx([1.5, 1.0])
    # the chord never strays more than a millimetre from the circle
    mid = 0.5 * (pts[:-1] + pts[1:])
    assert (0.5 - np.hypot(mid[:, 0] - 1, mid[:, 1] - 1)).max() < 0.001


def test_junction_kinds_and_non_junctions() -> None:
    y = small_floor([{"path": [[0, 0], [1, 0]]}, {"path": [[1, 0], [1.8, 0.55]]}, {"path": [[1, 0], [1.8, -0.55]]}])
    assert [(round(a, 3), round(b, 3), k) for a, b, k in y.junctions()] == [(1.0, 0.0, "Y")]
    joined = small_floor([{"path": [[0, 0], [1, 0]]}, {"path": [[1, 0], [2, 0]]}])  # one path continuing another
    assert joined.junctions() == []
    assert sorted(joined.line_ends()) == [(0.0, 0.0), (2.0, 0.0)]
    corner = small_floor([{"path": [[0, 0], [1, 0], [1, 1]]}])  # an L bend is not a junction
    assert corner.junctions() == []
    crossing_itself = small_floor([{"path": [[0, 0], [2, 0], [2, 1], [1, 1], [1, -1]]}])
    assert [(round(a, 3), round(b, 3), k) for a, b, k in crossing_itself.junctions()] == [(1.0, 0.0, "+")]


# --- raster --------------------------------------------------------------------------------
def test_raster_shows_the_line_at_its_true_width() -> None:
    f = small_floor([{"path": [[0, 0], [2, 0]]}, {"path": [[1.0, -0.5], [1.7, 0.2]]}])
    bg, ink = 190.0, 20.0
    for (x, y, dx, dy) in [(0.5, 0.0, 0.0, 1.0), (1.35, -0.15, -1 / math.sqrt(2), 1 / math.sqrt(2))]:
        # integrate paint coverage across the line
        s = np.arange(-0.05, 0.05, 0.0005)
        cover = [(bg - grey_at(f, x + t * dx, y + t * dy)) / (bg - ink) for t in s]
        width = float(np.sum(cover)) * 0.0005
        assert width == pytest.approx(0.019, abs=0.002)
    assert grey_at(f, 0.5, 0.0) < 40
    assert grey_at(f, 0.5, 0.05) == pytest.approx(190, abs=2)


def test_gaps_erase_paint_but_not_truth() -> None:
    f = small_floor([{"path": [[0, 0], [2, 0]]}], gaps=[{"at": [1.0, 0.0], "length_m": 0.04}])
    assert grey_at(f, 1.0, 0.0) == pytest.approx(190, abs=3)
    assert grey_at(f, 1.03, 0.0) < 40
    assert f.distance_to_line(1.0, 0.0) == 0.0
    assert f.line_ends() == [(0.0, 0.0), (2.0, 0.0)]


def test_shadow_glare_and_lighting_change_brightness() -> None:
    f = small_floor(
        [{"path": [[0, 0], [2, 0]]}],
        shadows=[{"circle": {"center": [0.5, 0.2], "radius_m": 0.1}, "darkness": 0.5, "softness_m": 0.0}],
        glare=[{"center": [1.5, 0.2], "radius_m": 0.1, "strength": 0.2}],
    )
    assert grey_at(f, 0.5, 0.2) == pytest.approx(95, abs=3)
    assert grey_at(f, 1.5, 0.2) == pytest.approx(190 + 0.2 * 255, abs=3)
    g = small_floor([{"path": [[0, 0], [2, 0]]}], lighting={"gradient": {"direction_deg": 0, "min_gain": 0.5, "max_gain": 1.0}})
    assert grey_at(g, -0.25, 0.2) < 110 and grey_at(g, 2.25, 0.2) > 180


def test_colours_and_texture() -> None:
    f = small_floor([{"path": [[0, 0], [1, 0]], "colour": "yellow"}, {"path": [[0, 0.5], [1, 0.5]], "colour": [10, 20, 200]}])
    assert tuple(f.image[tuple(int(round(v)) for v in f.world_to_raster(0.5, 0.0))[::-1]]) == (30, 200, 235)  # BGR
    assert tuple(f.image[tuple(int(round(v)) for v in f.world_to_raster(0.5, 0.5))[::-1]]) == (200, 20, 10)
    d = {"background": {"colour": 150, "texture": 10}, "lines": {"paths": [{"path": [[0, 0], [1, 0]]}]}}
    a = FloorMap.from_dict(d, np.random.default_rng(5)).image
    b = FloorMap.from_dict(d, np.random.default_rng(5)).image
    c = FloorMap.from_dict(d, np.random.default_rng(6)).image
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert 5 < float(a[:50, :50, 0].std()) < 15


# --- rejecting bad floors -------------------------------------------------------------------
@pytest.mark.parametrize(
    "floor, message",
    [
        ({"lines": {"paths": [{"path": [[0, 0], [1, 0]]}]}, "resolutoin_m": 0.01}, "did you mean 'resolution_m'"),
        ({"lines": {"widht_m": 0.02, "paths": []}}, "did you mean 'width_m'"),
        ({"lines": {"paths": [{"path": [[0, 0]]}]}}, "at least two distinct points"),
        ({"lines": {"colour": "blakc", "paths": []}}, "did you mean 'black'"),
        ({"lines": {"paths": [{"path": [[0, 0], {"arc": {"center": [0, 0], "radius_m": 1, "from_deg": 0}}]}]}}, "missing required key 'to_deg'"),
        ({"shadows": [{"darkness": 0.5}]}, "exactly one shape"),
        ({"resolution_m": 0.001, "extent_m": {"x": [0, 100], "y": [0, 100]}}, "resolution_m coarser"),
        ({"lines": {"paths": [{"path": [[0, "a"], [1, 0]]}]}}, "expected a number"),
    ],
)
def test_bad_floors_are_rejected_clearly(floor: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        FloorMap.from_dict(floor)
