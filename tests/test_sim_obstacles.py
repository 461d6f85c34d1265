"""Obstacles and contact in the simulator: the world's ``obstacles:``, the swept contact, and the truth it leaves.

The geometry the tests check against is computed here by hand (a point's
distance to a segment, a circle, a box), not with the simulator's own code.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from beastbt.core.errors import InvalidInput
from beastbt.sim.contact import CLEAR_AFTER_M, ContactWorld
from beastbt.sim.dynamics import DiffDriveSim, DriveModel, Wall
from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle, Person
from beastbt.sim.truth import RobotTruth
from beastbt.sim.world import load_world
from beastbt.testing import MissionHarness

ROOT = Path(__file__).resolve().parents[1]
RADIUS_M = 0.15  # robots/sim.yaml's footprint


# -- hand geometry ------------------------------------------------------------------
def segment_distance(px: float, py: float, x1: float, y1: float, x2: float, y2: float) -> float:
    """Distance from a point to a segment (m), by projection."""
    dx, dy = x2 - x1, y2 - y1
    t = max(0.0, min(1.0, ((px - x1) * dx + (py - y1) * dy) / (dx * dx + dy * dy)))
    return math.hypot(px - x1 - t * dx, py - y1 - t * dy)


def gap_to(px: float, py: float, thing, radius_m: float = RADIUS_M) -> float:
    """Gap between a footprint circle at (px, py) and a wall, cylinder or box (m); negative when the centre is in a box."""
    if isinstance(thing, Wall):
        return segment_distance(px, py, thing.x1, thing.y1, thing.x2, thing.y2) - radius_m
    if isinstance(thing, CylinderObstacle):
        return math.hypot(px - thing.x, py - thing.y) - thing.radius_m - radius_m
    corners = thing.corners()
    edges = min(segment_distance(px, py, *a, *b) for a, b in zip(corners, corners[1:] + corners[:1]))
    c, s = math.cos(thing.yaw), math.sin(thing.yaw)
    lx, ly = (px - thing.x) * c + (py - thing.y) * s, -(px - thing.x) * s + (py - thing.y) * c
    inside = abs(lx) < thing.length_m / 2 and abs(ly) < thing.width_m / 2
    return (-edges if inside else edges) - radius_m


def drive_sim(walls=(), obstacles=(), x=0.0, y=0.0, top_mps=0.5) -> DiffDriveSim:
    """A noiseless, instantly responding robot of RADIUS_M at (x, y) facing east."""
    model = DriveModel(track_width_m=0.17, max_wheel_speed_mps=top_mps, max_wheel_accel_mps2=1e9,
                       motor_time_constant_s=0.0, slip_sigma=0.0, slip_bias=0.0, footprint_radius_m=RADIUS_M)
    return DiffDriveSim(model, RobotTruth(x=x, y=y), np.random.default_rng(0), walls=list(walls),
                        contact=ContactWorld(walls, list(obstacles), RADIUS_M))


def write_world(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "w.yaml"
    path.write_text(text)
    return path


# -- the world file -----------------------------------------------------------------
def test_obstacles_load_with_units_and_defaults(tmp_path):
    world = load_world(write_world(tmp_path, """world: w
obstacles:
  - {shape: box, x: 4.0, y: 0.2, size_m: [40 cm, 0.6], yaw_deg: 90}
  - {shape: cylinder, x: 6.0, y: -0.3, radius_m: 15 cm}
  - {shape: person, speed_mps: 3.6 km/h, path: [[9.0, 0.0], [2.0, 0.0]], start_s: 1 min}
"""))
    box, post, person = world.obstacles
    assert box == BoxObstacle(4.0, 0.2, 0.4, 0.6, math.pi / 2)
    assert post == CylinderObstacle(6.0, -0.3, pytest.approx(0.15))
    assert person.speed_mps == pytest.approx(1.0) and person.start_s == 60.0
    assert person.radius_m == 0.25 and person.loop is False  # the schema's defaults


@pytest.mark.parametrize("item, where, says", [
    ("{shape: box, x: 4.0, y: 0.2, size_m: [0.4, -0.6]}", "3:48", "size_m"),
    ("{shape: cylindre, x: 6.0, y: -0.3, radius_m: 0.15}", "3:13", "did you mean 'cylinder'"),
    ("{shape: person, radius_m: 0.25, speed: 0.8, path: [[9.0, 0.0], [2.0, 0.0]]}", "3:37", "speed_mps"),
    ("{shape: cylinder, x: 6.0, y: -0.3}", "3:5", "radius_m"),
    ("{shape: person, path: [[9.0, 0.0], [2.0]]}", "3:40", "at least 2"),
    ("{shape: person, path: [[1, 1]], start_s: soon}", "3:46", "start_s"),
    ("{x: 1, y: 2}", "3:5", "shape"),
])
def test_a_bad_obstacle_is_reported_at_its_place(tmp_path, item, where, says):
    path = write_world(tmp_path, f"world: w\nobstacles:\n  - {item}\n")
    with pytest.raises(InvalidInput) as err:
        load_world(path)
    text = "\n".join(p.format() for p in err.value.problems)
    assert f"{path}:{where}: error: " in text and says in text, text


# -- persons ------------------------------------------------------------------------
def test_a_person_waits_walks_the_path_once_and_stands_at_its_end():
    p = Person(radius_m=0.25, speed_mps=0.8, path=((9.0, 0.0), (2.0, 0.0), (2.0, 2.0)), start_s=5.0)
    assert p.position_at(0.0) == p.position_at(5.0) == (9.0, 0.0)
    assert p.position_at(10.0) == pytest.approx((5.0, 0.0))           # 4 m along the first leg
    assert p.position_at(5.0 + 8.0 / 0.8) == pytest.approx((2.0, 1.0))  # round the corner: 7 m + 1 m
    assert p.position_at(1000.0) == (2.0, 2.0)


def test_a_looping_person_goes_back_and_forth_on_an_open_path_and_around_a_closed_one():
    line = Person(radius_m=0.2, speed_mps=1.0, path=((0.0, 0.0), (4.0, 0.0)), loop=True)
    assert [line.position_at(t)[0] for t in (1.0, 5.0, 7.0, 9.0, 13.0)] == pytest.approx([1.0, 3.0, 1.0, 1.0, 3.0])
    square = Person(radius_m=0.2, speed_mps=1.0, path=((0, 0), (1, 0), (1, 1), (0, 1), (0, 0)), loop=True)
    assert square.closed
    assert square.position_at(4.5) == pytest.approx((0.5, 0.0))  # around again, same direction
    assert square.position_at(5.5) == pytest.approx((1.0, 0.5))


def test_a_person_who_does_not_give_way_stops_at_contact_and_walks_on_when_the_robot_has_gone():
    person = Person(radius_m=0.25, speed_mps=1.0, path=((3.0, 0.0), (-3.0, 0.0)), gives_way=False)
    sim = drive_sim(obstacles=[person])
    for _ in range(400):  # 4 s: the person would be at -1 m if nothing stood in its way
        sim.step(0.01)
    px, py = sim.contact.person_xy[0]
    assert px == pytest.approx(RADIUS_M + 0.25, abs=1e-6) and py == 0.0  # touching, not through
    assert sim.contact.collisions == 1 and sim.contact.min_clearance_m == pytest.approx(0.0, abs=1e-9)
    sim.truth.y = 1.0  # the robot is lifted out of the way
    for _ in range(100):
        sim.step(0.01)
    assert sim.contact.person_xy[0][0] == pytest.approx(px - 1.0, abs=1e-6)  # on at its own pace, no catching up


# -- contact ------------------------------------------------------------------------
@pytest.mark.parametrize("top_mps, dt_s", [(0.5, 0.01), (0.5, 1.0), (40.0, 0.01), (400.0, 0.1)])
def test_no_speed_or_time_step_tunnels_through_a_thin_wall_or_a_post(top_mps, dt_s):
    for thing, stop_x in ((Wall(2.25, -1.0, 2.25, 1.0), 2.25 - RADIUS_M),
                          (CylinderObstacle(2.25, 0.0, 0.02), 2.25 - 0.02 - RADIUS_M),
                          (BoxObstacle(2.25, 0.0, 0.01, 1.0, 0.0), 2.245 - RADIUS_M)):
        sim = drive_sim(walls=[thing] if isinstance(thing, Wall) else [],
                        obstacles=[] if isinstance(thing, Wall) else [thing], top_mps=top_mps)
        sim.set_body_targets(top_mps, 0.0)
        for _ in range(int(20 / dt_s) if top_mps < 1 else 50):
            sim.step(dt_s)
        assert sim.truth.x == pytest.approx(stop_x, abs=1e-9), thing
        assert sim.blocked and sim.contact.collisions == 1


def test_at_contact_the_drive_stalls_but_the_robot_turns_and_backs_away():
    sim = drive_sim(walls=[Wall(1.0, -1.0, 1.0, 1.0)])
    sim.set_body_targets(0.3, 0.0)
    for _ in range(500):
        sim.step(0.01)
    left_m = sim.truth.left_m
    assert sim.truth.x == pytest.approx(1.0 - RADIUS_M) and sim.blocked
    for _ in range(100):  # pushing on: the encoders do not count the stalled drive
        sim.step(0.01)
    assert sim.truth.left_m == pytest.approx(left_m)
    sim.set_body_targets(0.0, 1.0)
    for _ in range(100):
        sim.step(0.01)
    assert sim.truth.yaw == pytest.approx(1.0, abs=0.02) and sim.truth.x == pytest.approx(1.0 - RADIUS_M)
    sim.set_body_targets(-0.3, 0.0)
    for _ in range(100):
        sim.step(0.01)
    assert sim.truth.x < 1.0 - RADIUS_M - 0.1


def test_collisions_count_episodes_not_ticks_with_hysteresis():
    sim = drive_sim(walls=[Wall(1.0, -1.0, 1.0, 1.0)])

    def drive(v_mps: float, seconds: float) -> None:
        sim.set_body_targets(v_mps, 0.0)
        for _ in range(round(seconds / 0.01)):
            sim.step(0.01)

    drive(0.3, 4.0)                         # into the wall and pushing for a while: one
    drive(-0.1, 0.1)                        # back 1 cm: within the hysteresis, still the same contact
    assert 0.0 < 1.0 - RADIUS_M - sim.truth.x < CLEAR_AFTER_M
    drive(0.3, 1.0)
    assert sim.contact.collisions == 1
    drive(-0.3, 1.0)                        # well clear
    drive(0.3, 2.0)                         # and into it again: two
    assert sim.contact.collisions == 2
    drive(-0.3, 1.0)
    assert sim.contact.collisions == 2 and not sim.contact.in_contact


def test_clearance_against_hand_computed_geometry():
    box = BoxObstacle(1.0, 0.0, 0.2, 1.0, math.pi / 2)  # turned: x from 0.5 to 1.5 m, y from -0.1 to 0.1 m
    world = ContactWorld([Wall(-3.0, 2.0, 3.0, 2.0)], [box, CylinderObstacle(0.0, -1.0, 0.1)], RADIUS_M)
    assert world.clearance(0.0, -0.5) == pytest.approx(0.5 - 0.1 - RADIUS_M)  # the post, 0.5 m south
    assert world.clearance(1.0, 0.5) == pytest.approx(0.4 - RADIUS_M)          # over the box's long side
    assert world.clearance(1.0, 0.0) == pytest.approx(-0.1 - RADIUS_M)         # inside the box
    assert world.clearance(-2.0, 1.7) == pytest.approx(0.3 - RADIUS_M)         # under the wall
    assert world.clearance(1.7, -0.2) == pytest.approx(math.hypot(0.2, 0.1) - RADIUS_M)  # the box's corner
    assert ContactWorld([], [], RADIUS_M).clearance(0.0, 0.0) == math.inf


def test_min_clearance_of_a_drive_past_a_post_and_a_box_is_the_hand_computed_gap():
    post, box = CylinderObstacle(2.0, 0.6, 0.1), BoxObstacle(3.0, -0.8, 0.4, 0.4, math.radians(45))
    sim = drive_sim(obstacles=[post, box])
    sim.set_body_targets(0.5, 0.0)
    for _ in range(1000):
        sim.step(0.01)
    assert sim.truth.x > 4.0 and sim.contact.collisions == 0
    box_gap = 0.8 - 0.2 * math.sqrt(2) - RADIUS_M  # its corner points at the path
    assert sim.contact.min_clearance_m == pytest.approx(min(0.6 - 0.1 - RADIUS_M, box_gap), abs=1e-6)


# -- whole runs ---------------------------------------------------------------------
def run_checking_every_tick(h: MissionHarness, things: list, timeout_s: float) -> float:
    """Tick to the end; assert the footprint is never inside anything; return the least gap seen (m)."""
    least = math.inf
    while not h.done and h.now_s < timeout_s:
        h.tick()
        t = h.truth
        persons = [CylinderObstacle(float(x), float(y), p.radius_m)
                   for p, (x, y) in zip(h.run.io.sim.drive.contact.persons, h.run.io.sim.drive.contact.person_xy)]
        gap = min(gap_to(t.x, t.y, thing) for thing in things + persons)
        assert gap > -1e-9, (h.now_s, t.x, t.y)
        least = min(least, gap)
    return least


def robot_without_lidar(tmp_path: Path) -> str:
    """robots/sim.yaml without its LiDAR, so no collision monitor: what contact itself does."""
    data = yaml.safe_load((ROOT / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    data.pop("lidar", None)
    path = tmp_path / "robot_without_lidar.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return str(path)


def test_a_20_m_drive_in_the_10_m_corridor_stops_at_the_end_wall_with_one_collision(tmp_path):
    world = load_world(ROOT / "worlds" / "corridor.yaml")
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - drive: {distance: 20 m, stuck_after: 2 s}\n",
                                 world=str(ROOT / "worlds" / "corridor.yaml"), robot=robot_without_lidar(tmp_path))
    least = run_checking_every_tick(h, list(world.walls), 120.0)
    assert h.result == "failure"  # blocked: without a collision monitor it touches the wall
    assert h.truth.x == pytest.approx(10.0 - RADIUS_M, abs=1e-6) and h.truth.v_mps == 0.0
    truth = h.summary()["truth"]
    assert truth["collisions"] == 1 and truth["min_clearance_m"] == 0.0 and truth["blocked"]
    assert least == pytest.approx(0.0, abs=1e-6)


def test_a_run_among_boxes_posts_and_a_person_never_enters_any(tmp_path):
    (tmp_path / "w.yaml").write_text("""world: w
start: {x: 0, y: 0, yaw_deg: 0}
walls: [[-1, -1.5, 8, -1.5], [-1, 1.5, 8, 1.5]]
obstacles:
  - {shape: box, x: 2.0, y: 0.4, size_m: [0.3, 0.5], yaw_deg: 30}
  - {shape: cylinder, x: 4.0, y: -0.9, radius_m: 0.1}
  - {shape: person, radius_m: 0.25, speed_mps: 0.6, path: [[5.0, 0.0], [-0.8, 0.0]], gives_way: false}
""")
    world = load_world(tmp_path / "w.yaml")
    h = MissionHarness.from_yaml("""mission: t
steps:
  - wait: 10 s                                   # the person walks into the standing robot and stops
  - turn: {angle: -90 deg}
  - drive: {distance: 1 m, speed: 0.3 m/s}       # away south; the person walks on behind
  - turn: {angle: 90 deg}
  - drive: {distance: 5 m, speed: 0.3 m/s, stuck_after: 1 s}   # east, into the post
on_failure: stop
""", world=str(tmp_path / "w.yaml"), base_dir=tmp_path, robot=robot_without_lidar(tmp_path))
    least = run_checking_every_tick(h, list(world.walls) + [o for o in world.obstacles if not isinstance(o, Person)],
                                    90.0)
    truth = h.summary()["truth"]
    assert truth["collisions"] == 2 and least == pytest.approx(0.0, abs=1e-6)  # the person, then the post
    assert h.truth.x == pytest.approx(4.0 - math.sqrt((0.25) ** 2 - (h.truth.y + 0.9) ** 2), abs=1e-6)
    assert h.run.io.sim.drive.contact.person_xy[0] == pytest.approx((-0.8, 0.0))  # it walked on to its end


def test_an_empty_world_has_no_clearance_and_no_collisions():
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - drive: {distance: 0.3 m}\n")
    assert h.run_to_end(30) == "success"
    truth = h.summary()["truth"]
    assert truth["collisions"] == 0 and truth["min_clearance_m"] is None


# -- what people see ----------------------------------------------------------------
def test_the_scene_draws_boxes_cylinders_and_persons_and_validates_against_foxglove():
    import json

    import jsonschema

    from beastbt.live.console_state import MapFrame, map_layers
    from beastbt.mission.model import load_mission
    from beastbt.recording.config import FramesConfig
    from beastbt.recording.scene import SceneView, scene_description

    world = load_world(ROOT / "worlds" / "corridor_person.yaml")
    world.obstacles += [BoxObstacle(4.0, 0.5, 0.4, 0.6, 0.3), CylinderObstacle(6.0, -0.3, 0.15)]
    mission = load_mission(ROOT / "missions" / "patrol.yaml")
    view = SceneView(json.loads(json.dumps(scene_description(mission, world, RADIUS_M))), FramesConfig())
    message = view.scene_message(5)
    schema = json.loads((ROOT / "tests" / "data" / "foxglove" / "SceneUpdate.json").read_text(encoding="utf-8"))
    jsonschema.validate(json.loads(json.dumps(message)), schema)
    drawn = {e["id"]: e for e in message["entities"]}["obstacles"]
    start = world.start_x, world.start_y  # map sits at the robot's start until a fused position says otherwise
    (box,) = drawn["cubes"]
    assert box["pose"]["position"]["x"] == pytest.approx(4.0 - start[0], abs=1e-3)
    assert (box["size"]["x"], box["size"]["y"]) == (0.4, 0.6)
    (post,) = drawn["cylinders"]  # the person is drawn where it walks, on /sim/persons (tests/test_obstacle_views.py)
    assert post["size"]["x"] == pytest.approx(0.3) and len(drawn["lines"]) == 1         # the person's path
    assert drawn["lines"][0]["points"][0]["x"] == pytest.approx(9.5 - start[0], abs=1e-3)  # from where it sets off

    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - wait: 1 s\n", world=str(ROOT / "worlds" / "campus_obstacles.yaml"))
    world = h.prepared.world
    layers = map_layers(h.run, world, MapFrame(h.run, world))  # the console's map
    assert [o["shape"] for o in layers["obstacles"]] == [
        "box" if isinstance(o, BoxObstacle) else "cylinder" for o in world.obstacles]
    assert layers["obstacles"][0]["corners"][0] == pytest.approx(list(world.obstacles[0].corners()[0]), abs=1e-3)
    assert layers["obstacles"][1]["xy"] == [world.obstacles[1].x, world.obstacles[1].y]


def test_the_worlds_doc_example_is_a_valid_world(tmp_path):
    import re
    doc = (ROOT / "docs" / "worlds.md").read_text(encoding="utf-8")
    (block,) = [b for b in re.findall(r"```yaml\n(.*?)```", doc, re.S) if "world.schema.json" in b]
    world = load_world(write_world(tmp_path, block))
    assert [type(o).__name__ for o in world.obstacles] == ["BoxObstacle", "CylinderObstacle", "Person"]


@pytest.mark.parametrize("count", [3, 60])  # a small world (plain floats) and a large one (NumPy)
def test_clearance_agrees_with_the_hand_geometry_in_small_and_large_worlds(count):
    rng = np.random.default_rng(count)
    walls = [Wall(*map(float, rng.uniform(-10, 10, 4))) for _ in range(count)]
    things = [BoxObstacle(*map(float, rng.uniform(-10, 10, 2)), *map(float, rng.uniform(0.1, 2, 2)),
                          float(rng.uniform(-3, 3))) for _ in range(count)]
    things += [CylinderObstacle(*map(float, rng.uniform(-10, 10, 2)), float(rng.uniform(0.05, 1))) for _ in range(count)]
    world = ContactWorld(walls, things, RADIUS_M)
    assert world._small == (count < 5)
    for x, y in rng.uniform(-11, 11, (200, 2)):
        want = min(gap_to(x, y, t) for t in walls + things)
        assert world.clearance(x, y) == pytest.approx(want, abs=1e-9)


@pytest.mark.parametrize("count", [3, 12])  # plain floats (9 things) and NumPy (36)
def test_the_swept_test_stops_where_a_fine_walk_along_the_move_first_touches(count):
    rng = np.random.default_rng(100 + count)
    walls = [Wall(*map(float, rng.uniform(-6, 6, 4))) for _ in range(count)]
    things = [BoxObstacle(*map(float, rng.uniform(-6, 6, 2)), *map(float, rng.uniform(0.1, 1, 2)),
                          float(rng.uniform(-3, 3))) for _ in range(count)]
    things += [CylinderObstacle(*map(float, rng.uniform(-6, 6, 2)), float(rng.uniform(0.05, 0.5))) for _ in range(count)]
    world = ContactWorld(walls, things, RADIUS_M)
    met = 0
    for _ in range(100):
        x0, y0 = rng.uniform(-7, 7, 2)
        if min(gap_to(x0, y0, t) for t in walls + things) <= 0.0:
            continue  # starts touching or inside: not this test's case
        x1, y1 = x0 + rng.uniform(-4, 4), y0 + rng.uniform(-4, 4)
        world._ref = None
        s = world.free_fraction(x0, y0, x1, y1)
        fine = np.linspace(0.0, 1.0, 2001)
        reach = math.hypot(x1 - x0, y1 - y0)
        near = [t for t in walls + things if gap_to(x0, y0, t) <= reach]  # the rest is out of the move's reach
        gaps = [min((gap_to(x0 + f * (x1 - x0), y0 + f * (y1 - y0), t) for t in near), default=math.inf) for f in fine]
        inside = [f for f, g in zip(fine, gaps) if g < -1e-9]
        if inside:
            met += 1
            assert inside[0] - 1 / 2000 <= s <= inside[0]
        else:
            assert s == 1.0 or min(gaps) < 1e-3  # free, or it grazes something within the walk's resolution
    assert met >= 10  # the moves did meet things


def test_with_the_default_lidar_the_20_m_drive_in_the_corridor_stops_before_the_wall_without_touching():
    """The issue's scenario on robots/sim.yaml (LD19 and the collision monitor): stopped short, no contact."""
    world = load_world(ROOT / "worlds" / "corridor.yaml")
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - drive: {distance: 20 m, speed: 0.3 m/s, stuck_after: 2 s}\n",
                                 world=str(ROOT / "worlds" / "corridor.yaml"))
    least = run_checking_every_tick(h, list(world.walls), 120.0)
    truth = h.summary()["truth"]
    assert truth["collisions"] == 0 and truth["min_clearance_m"] > 0.02 and least > 0.02
    assert h.truth.x > 9.0 and abs(h.truth.v_mps) < 1e-6  # it drove the corridor's length, then stopped short
    assert any(e.kind == "collision_monitor" and "stop" in e.text for e in h.events)
