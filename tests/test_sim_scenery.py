"""The simulated camera draws the world around the floor: ground texture, sky, walls, obstacles and persons."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from beastbt.parts.camera import PLAIN_FLOOR, build_floor, persons_xy
from beastbt.sim.camera_emulator import CameraEffects, SimCamera
from beastbt.sim.dynamics import Wall
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle, Person
from beastbt.sim.scenery import (SKIRTING_M, Scenery, TEXTURE_TILE_PX, WALL_HEIGHT_M, ground_canvas, ground_texture)
from beastbt.sim.world import load_world
from beastbt.testing import MissionHarness
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.line_detector import LineDetector, LineDetectorConfig
from conftest import REPO

GEOM = CameraGeometry(width_px=320, height_px=240, hfov_deg=62.2, height_m=0.2, pitch_deg=40.0, x_offset_m=0.1)
LEVEL = math.radians(40.0)  # gimbal tilt that brings the optical axis level
F = GEOM.focal_px
CX, CY = (GEOM.width_px - 1) / 2.0, (GEOM.height_px - 1) / 2.0


def camera(scenery: Scenery, effects: CameraEffects | None = None) -> SimCamera:
    return SimCamera(build_floor(PLAIN_FLOOR, 1), GEOM, np.random.default_rng(2), effects or CameraEffects.none(),
                     scenery)


def grey_column(img: np.ndarray, u: int) -> np.ndarray:
    return img[:, u].astype(float).mean(axis=1)


def neutral(img_row: np.ndarray) -> np.ndarray:
    """Columns whose colour is grey (the cylinders' paint), not green grass nor blue sky."""
    px = img_row.astype(int)
    return (np.abs(px[:, 0] - px[:, 2]) < 15) & (np.abs(px[:, 1] - px[:, 2]) < 15) & (px.max(axis=1) < 200)


# --- walls -------------------------------------------------------------------------------
WALL_AHEAD = Scenery.of_world([Wall(2.0, -3.0, 2.0, 3.0)], [], has_floor=False, seed=4)


def test_a_wall_ahead_is_a_band_across_the_image_at_the_rows_its_distance_gives():
    cam = camera(WALL_AHEAD)
    img = cam.render(1.0, 0.0, 0.0, tilt_rad=LEVEL)
    d = 2.0 - (1.0 + GEOM.x_offset_m)  # the camera is 0.9 m from the wall
    foot = CY + F * GEOM.height_m / d  # where the wall meets the floor
    skirting_top = CY + F * (GEOM.height_m - SKIRTING_M) / d
    assert CY - F * (WALL_HEIGHT_M - GEOM.height_m) / d < 0  # the wall's top is above the image
    for u in (20, 160, 300):
        col = grey_column(img, u)
        dark = np.nonzero(col < 140)[0]  # the skirting board; floor tiles and the wall are lighter
        assert abs(dark.max() - foot) <= 2 and abs(dark.min() - skirting_top) <= 2
        wall = col[: int(skirting_top) - 2]
        assert wall.std() < 3 and abs(wall.mean() - col[int(foot) + 10:].mean()) > 10  # one flat paint, not floor
    # turned away, the same camera sees the floor and the ceiling: no skirting anywhere
    away = cam.render(1.0, 0.0, math.pi, tilt_rad=LEVEL)
    assert grey_column(away, 160).min() > 140
    # with the camera at its mounting (40 deg down), a wall 0.9 m away is beyond the top of the view...
    assert grey_column(cam.render(1.0, 0.0, 0.0), 160).min() > 140
    # ... and one 0.4 m away is in it, at the row its foot projects to
    near = grey_column(cam.render(1.5, 0.0, 0.0), 160)
    foot_px = GEOM.ground_to_pixel(0.5, 0.0)
    assert foot_px is not None and abs(np.nonzero(near < 140)[0].max() - foot_px[1]) <= 2


def test_walls_hide_what_stands_behind_them_and_the_order_does_not_matter():
    post = CylinderObstacle(4.0, 0.0, 0.2)
    for walls in ([Wall(2.0, -3.0, 2.0, 3.0)], [Wall(2.0, 3.0, 2.0, -3.0)]):
        hidden = camera(Scenery.of_world(walls, [post], False, 4)).render(1.0, 0.0, 0.0, tilt_rad=LEVEL)
        assert not neutral(hidden[int(CY) - 5]).any()
    seen = camera(Scenery.of_world([], [post], False, 4)).render(1.0, 0.0, 0.0, tilt_rad=LEVEL)
    assert neutral(seen[int(CY) - 5]).sum() > 5


# --- obstacles and persons ---------------------------------------------------------------------
def test_a_post_appears_at_its_bearing_and_its_width():
    cam = camera(Scenery.of_world([], [CylinderObstacle(4.1, 1.0, 0.15)], False, 4))
    img = cam.render(0.0, 0.0, 0.0, tilt_rad=LEVEL)
    cols = np.nonzero(neutral(img[int(CY) - 10]))[0]
    d = 4.1 - GEOM.x_offset_m
    expected_u = CX - F * 1.0 / d  # left of the centre: positive y is to the left
    assert abs(cols.mean() - expected_u) <= 2
    assert abs(len(cols) - F * 2 * 0.15 / d) <= 3
    # the robot turned 20 deg left sees it 20 deg further right
    img = cam.render(0.0, 0.0, math.radians(20.0), tilt_rad=LEVEL)
    cols = np.nonzero(neutral(img[int(CY) - 10]))[0]
    bearing = math.atan2(1.0, 4.1) - math.radians(20.0)
    assert abs(cols.mean() - (CX - F * math.tan(bearing))) <= 4


def test_a_box_stands_as_tall_as_a_bench_and_blocks_the_sky():
    bench = BoxObstacle(3.1, 0.0, 0.5, 1.5, 0.0)
    img = camera(Scenery.of_world([], [bench], False, 4)).render(0.0, 0.0, 0.0, tilt_rad=LEVEL)
    col = img[:, int(CX)].astype(int)
    d = 3.1 - 0.25 - GEOM.x_offset_m  # the near face
    top = CY - F * (0.5 - GEOM.height_m) / d
    box_rows = np.nonzero((col[:, 2] > col[:, 0] + 40))[0]  # the brown paint: red well above blue
    assert abs(box_rows.min() - top) <= 2
    assert col[: int(top) - 3, 0].min() > col[: int(top) - 3, 2].min()  # above it: blue sky


def test_persons_are_drawn_where_the_caller_says_they_are():
    walker = Person(radius_m=0.25, speed_mps=1.0, path=((5.0, 0.0), (5.0, 3.0)))
    cam = camera(Scenery.of_world([], [walker], False, 4))
    shirt_row = int(CY - F * (1.2 - GEOM.height_m) / 4.9)

    def shirt_cols(img: np.ndarray) -> np.ndarray:
        px = img[shirt_row].astype(int)
        return np.nonzero((px[:, 2] > 80) & (px[:, 2] > 2 * px[:, 1]))[0]  # red, lit or in shade

    assert len(shirt_cols(cam.render(0.0, 0.0, 0.0, tilt_rad=LEVEL))) == 0  # nobody said where: nobody drawn
    for y in (0.0, -0.8):
        cols = shirt_cols(cam.render(0.0, 0.0, 0.0, tilt_rad=LEVEL, persons_xy=[(5.0, y)]))
        bearing, half = math.atan2(y, 4.9), math.asin(0.25 / math.hypot(4.9, y))  # the outline's tangents
        edges = CX - F * np.tan([bearing + half, bearing - half])
        assert abs(cols.min() - edges[0]) <= 2 and abs(cols.max() - edges[1]) <= 2


# --- ground and sky ------------------------------------------------------------------------
def test_the_ground_texture_is_seamless_and_deterministic_for_a_seed():
    for kind in ("grass", "tiles"):
        tex = ground_texture.__wrapped__(kind, 5)
        assert tex.shape == (TEXTURE_TILE_PX, TEXTURE_TILE_PX, 3)
        assert np.array_equal(tex, ground_texture.__wrapped__(kind, 5))
        assert not np.array_equal(tex, ground_texture.__wrapped__(kind, 6))
        t = tex.astype(float)
        if kind == "grass":  # the right edge continues into the left, the bottom into the top
            assert np.abs(t[:, 0] - t[:, -1]).mean() < 3 * np.abs(np.diff(t, axis=1)).mean() + 1
            assert np.abs(t[0] - t[-1]).mean() < 3 * np.abs(np.diff(t, axis=0)).mean() + 1
        else:  # joints every 0.5 m, the first on the tile's edge: repeated, they stay 0.5 m apart
            joints = np.nonzero(t.mean(axis=(0, 2)) < 0.95 * np.median(t.mean(axis=(0, 2))))[0]
            assert joints.tolist() == list(range(0, TEXTURE_TILE_PX, 50))
    grass, tiles = ground_texture("grass", 5).reshape(-1, 3).mean(0), ground_texture("tiles", 5).reshape(-1, 3).mean(0)
    assert grass[1] > grass[0] + 30 and grass[1] > grass[2] + 20  # green
    assert abs(tiles[0] - tiles[2]) < 40 and tiles.mean() > 150  # light, nearly neutral
    canvas = ground_canvas("grass", 5, 0)
    assert np.array_equal(canvas[:TEXTURE_TILE_PX, TEXTURE_TILE_PX:2 * TEXTURE_TILE_PX], ground_texture("grass", 5))


def test_the_ground_moves_with_the_robot_and_repeats_every_tile():
    cam = camera(Scenery(ground="grass", seed=3))
    a = cam.render(1.0, 2.0, 0.3).astype(int)
    assert np.abs(a - cam.render(1.2, 2.0, 0.3).astype(int)).mean() > 2  # 20 cm on: another patch of grass
    period = TEXTURE_TILE_PX * 0.01
    assert np.abs(a - cam.render(1.0 + period, 2.0 - 3 * period, 0.3).astype(int)).max() <= 1


def test_sky_above_the_horizon_outdoors_ceiling_indoors():
    up = math.radians(60.0)  # 20 deg above level
    sky = camera(Scenery(ground="grass", seed=3)).render(0.0, 0.0, 0.0, tilt_rad=up)
    horizon = int(GEOM.with_pan_tilt(0.0, up).horizon_v)
    top = sky[: horizon - 2].reshape(-1, 3).astype(int)
    assert (top[:, 0] > top[:, 2] + 20).all()  # blue
    assert sky[0, 160, 0] < sky[horizon - 3, 160, 0] or sky[0, 160, 2] < sky[horizon - 3, 160, 2]  # deeper upward
    below = sky[horizon + 10:].reshape(-1, 3).astype(int)
    assert (below[:, 1] > below[:, 0]).mean() > 0.95  # grass
    ceiling = camera(Scenery(ground="tiles", seed=3)).render(0.0, 0.0, 0.0, tilt_rad=up)
    assert ceiling[: horizon - 2].min() > 200


def test_the_scenery_of_a_world_follows_its_walls_and_floor():
    corridor = load_world(REPO / "worlds" / "corridor.yaml")
    s = Scenery.of_world(corridor.walls, corridor.obstacles, False, 1)
    assert s.ground == "tiles" and len(s.walls) == 4
    campus = load_world(REPO / "worlds" / "campus_obstacles.yaml")
    s = Scenery.of_world(campus.walls, campus.obstacles, False, 1)
    assert s.ground == "grass" and len(s.obstacles) == len(campus.obstacles)
    assert Scenery.of_world([], [], True, 1).empty  # a world with floor: and nothing else draws as before
    assert pickle.loads(pickle.dumps(s)) == s  # it crosses to the console's process


# --- the line detector ------------------------------------------------------------------------
@pytest.mark.parametrize("world", ["corridor.yaml", "campus_obstacles.yaml"])
def test_the_line_detector_sees_no_line_on_the_ground_nor_on_walls(world: str):
    w = load_world(REPO / "worlds" / world)
    det = LineDetector(LineDetectorConfig(), GEOM)
    rng = np.random.default_rng(8)
    for seed in (1, 2):
        cam = camera(Scenery.of_world(w.walls, w.obstacles, False, seed), CameraEffects())
        for i in range(40):
            if w.walls:  # anywhere in the corridor, walls in view or not
                x, y = rng.uniform(0.3, 9.7), rng.uniform(-0.75, 0.75)
            else:  # around the obstacles: within a metre of each
                o = w.obstacles[i % len(w.obstacles)]
                x, y = o.x + rng.uniform(-1.0, 1.0), o.y + rng.uniform(-1.0, 1.0)
            img = cam.render(x, y, rng.uniform(-math.pi, math.pi), 0.1)
            assert not det.detect(img, 0.1 * i).seen
            assert (det.line_mask(img) > 0).sum() < 20  # not even specks of tape


def test_a_world_with_a_floor_renders_exactly_as_without_scenery():
    w = load_world(REPO / "worlds" / "line_track.yaml")
    floor = build_floor(w.section("floor"), 3)
    scenery = Scenery.of_world(w.walls, w.obstacles, True, 3)
    plain = SimCamera(floor, GEOM, np.random.default_rng(2), CameraEffects())
    drawn = SimCamera(floor, GEOM, np.random.default_rng(2), CameraEffects(), scenery)
    for pose in ((0.5, 0.0, 0.0), (1.5, 0.2, 1.0)):
        assert np.array_equal(plain.render(*pose, tilt_rad=0.3), drawn.render(*pose, tilt_rad=0.3))


# --- in a run ---------------------------------------------------------------------------------
def test_a_run_in_the_corridor_draws_the_walking_person_where_the_simulator_has_it():
    h = MissionHarness.from_yaml(f"mission: t\nworld: {REPO / 'worlds' / 'corridor_person.yaml'}\nsteps:\n"
                                 "  - look: {tilt: 40 deg}\n  - wait: 20 s\n", seed=3)
    h.run.io.camera.enable("test")
    h.tick_until(lambda h: h.now_s >= 8.0, 200)
    where = persons_xy(h.run.io.sim)
    assert where is not None and len(where) == 1
    sim_camera = h.run.io.sim_camera
    assert sim_camera is not None and sim_camera.scenery is not None and sim_camera.scenery.ground == "tiles"
    t = h.truth
    assert abs(t.tilt_rad - LEVEL) < 0.02
    ok, img = sim_camera.read()
    assert ok
    px, py = where[0]
    d = px - (t.x + GEOM.x_offset_m)
    assert d > 1.0  # still ahead
    row = int(CY - F * (1.2 - GEOM.height_m) / d)
    cols = np.nonzero((img[row, :, 2].astype(int) > 80) & (img[row, :, 2] > 2 * img[row, :, 1].astype(int)))[0]
    assert abs(cols.mean() - (CX - F * (py - t.y) / d)) <= 3
    # the console's own viewer camera gets the same scenery
    from beastbt.live.console_process import _viewer_camera
    spec = pickle.loads(pickle.dumps(h.run.io.viewer_camera))
    viewer = _viewer_camera(spec)
    assert viewer.scenery == sim_camera.scenery
