"""Simulated persons around the robot: they keep their distance, wait, step around on the side with room, rejoin
their path, and wait when there is no room.

The robot is a footprint of RADIUS_M placed by hand (``ContactWorld.advance_persons`` is what the physics step
calls before the robot moves); the distances checked are computed here from the positions, not taken from the
model's own bookkeeping.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from beastbt.core.schema_defaults import schema_default
from beastbt.sim.contact import ContactWorld
from beastbt.sim.dynamics import DiffDriveSim, DriveModel, Wall
from beastbt.sim.obstacles import BoxObstacle, Person
from beastbt.sim.truth import RobotTruth
from beastbt.sim.world import load_world

RADIUS_M = 0.15  # robots/sim.yaml's footprint
DT_S = 0.01     # the simulator's physics step


def person_gap(world: ContactWorld, robot: tuple[float, float], i: int = 0) -> float:
    """Gap between person ``i`` and the footprint at ``robot`` (m)."""
    px, py = world.person_xy[i]
    return math.hypot(px - robot[0], py - robot[1]) - world.persons[i].radius_m - RADIUS_M


def walk(world: ContactWorld, robot: tuple[float, float], seconds: float, t0_s: float = 0.0) -> list:
    """Step the persons for ``seconds`` around a robot standing at ``robot``; returns (t, x, y, gap) per step."""
    trace = []
    for k in range(1, round(seconds / DT_S) + 1):
        t = t0_s + k * DT_S
        world.advance_persons(t, DT_S, *robot)
        x, y = world.person_xy[0]
        trace.append((t, float(x), float(y), person_gap(world, robot)))
    return trace


def walls_distance(walls: list, x: float, y: float) -> float:
    """Distance from a point to the nearest wall segment (m), by projection."""
    best = math.inf
    for w in walls:
        dx, dy = w.x2 - w.x1, w.y2 - w.y1
        t = max(0.0, min(1.0, ((x - w.x1) * dx + (y - w.y1) * dy) / (dx * dx + dy * dy)))
        best = min(best, math.hypot(x - w.x1 - t * dx, y - w.y1 - t * dy))
    return best


WEST = Person(radius_m=0.25, speed_mps=1.0, path=((4.0, 0.0), (-4.0, 0.0)))  # walks west along y = 0


def test_the_defaults_are_the_schemas():
    p = WEST
    assert p.gives_way is schema_default("world.schema.json#/$defs/person_obstacle", "gives_way") is True
    assert p.keeps_m == schema_default("world.schema.json#/$defs/person_obstacle", "keeps_m") == 0.3
    assert p.patience_s == schema_default("world.schema.json#/$defs/person_obstacle", "patience_s") == 1.5


def test_keeps_m_patience_s_and_gives_way_load_with_units(tmp_path):
    path = tmp_path / "w.yaml"
    path.write_text("world: w\nobstacles:\n  - {shape: person, path: [[0, 0], [1, 0]], keeps_m: 50 cm, "
                    "patience_s: 1 min, gives_way: false}\n  - {shape: person, path: [[0, 0], [1, 0]]}\n")
    shy, plain = load_world(path).obstacles
    assert (shy.keeps_m, shy.patience_s, shy.gives_way) == (pytest.approx(0.5), 60.0, False)
    assert (plain.keeps_m, plain.patience_s, plain.gives_way) == (0.3, 1.5, True)


def test_a_person_stops_keeps_m_from_a_robot_in_its_way_and_waits_its_patience():
    person = Person(radius_m=0.25, speed_mps=1.0, path=((4.0, 0.0), (-4.0, 0.0)), patience_s=2.0)
    world = ContactWorld([], [person], RADIUS_M)
    trace = walk(world, (0.0, 0.0), 6.0)
    stop_x = 0.25 + RADIUS_M + 0.3
    arrived = next(t for t, x, _, _ in trace if x <= stop_x + 1e-9)
    assert arrived == pytest.approx((4.0 - stop_x) / 1.0, abs=DT_S)  # it walked at its pace until then
    standing = [(x, y, gap) for t, x, y, gap in trace if arrived <= t < arrived + 2.0 - DT_S]
    assert all(x == pytest.approx(stop_x, abs=1e-9) and y == 0.0 for x, y, _ in standing)  # waits there
    assert min(gap for _, _, _, gap in trace) == pytest.approx(0.3, abs=1e-9)  # never nearer than keeps_m
    moved_off = next(t for t, _, y, _ in trace if y != 0.0)
    assert moved_off == pytest.approx(arrived + 2.0, abs=2 * DT_S)  # steps around once its patience is spent


@pytest.mark.parametrize("robot_y, side", [(0.0, 1.0), (0.1, -1.0), (-0.1, 1.0)])
def test_it_steps_around_on_the_nearer_side_passes_keeps_m_away_and_rejoins_its_path(robot_y, side):
    """Robot on the path: the person's right (north, walking west); off the path: the other side, the shorter step."""
    world = ContactWorld([], [WEST], RADIUS_M)
    trace = walk(world, (0.0, robot_y), 12.0)
    assert min(gap for *_, gap in trace) >= 0.3 - 1e-9  # never nearer than its personal distance
    ys = [y for _, _, y, _ in trace]
    assert max(ys, key=abs) * side > 0 and all(y * side >= -1e-12 for y in ys)  # one side only
    assert abs(max(ys, key=abs) - robot_y) == pytest.approx(0.25 + RADIUS_M + 0.3 + 0.02, abs=1e-9)  # the pass
    assert trace[-1][1:3] == (-4.0, 0.0)  # back on its path and at its end
    beside = [x for _, x, y, _ in trace if abs(y) > 0.5]
    assert min(beside) < 0.0 < max(beside)  # it walked past the robot, not back the way it came


@pytest.mark.parametrize("robot_yaw, passes_x", [(0.0, -1.0), (math.pi, 1.0), (None, 1.0)])
def test_it_steps_around_behind_where_the_robot_is_going(robot_yaw, passes_x):
    """A person walking north meets a robot standing on its path. Its right (east) wins a tie, unless the robot
    faces east (it is going there): then the person passes west, behind it."""
    north = Person(radius_m=0.25, speed_mps=1.0, path=((0.0, -3.0), (0.0, 3.0)))
    world = ContactWorld([], [north], RADIUS_M)
    xs = []
    for k in range(1, 1201):  # 12 s
        world.advance_persons(k * DT_S, DT_S, 0.0, 0.0, robot_yaw)
        xs.append(float(world.person_xy[0][0]))
        assert person_gap(world, (0.0, 0.0)) >= 0.3 - 1e-9
    side = max(xs, key=abs)
    assert side * passes_x > 0 and abs(side) == pytest.approx(0.25 + RADIUS_M + 0.3 + 0.02, abs=1e-9)
    assert tuple(world.person_xy[0]) == (0.0, 3.0)  # and on to its end


def test_it_steps_around_to_the_side_with_room_between_walls_and_fixed_obstacles():
    walls = [Wall(-5.0, -0.6, 5.0, -0.6), Wall(-5.0, 1.3, 5.0, 1.3)]  # room to the north only
    east = Person(radius_m=0.25, speed_mps=1.0, path=((-4.0, 0.0), (4.0, 0.0)))  # its right is south: no room
    world = ContactWorld(walls, [east], RADIUS_M)
    trace = walk(world, (0.0, 0.0), 12.0)
    assert max(y for _, _, y, _ in trace) > 0.7 and min(y for _, _, y, _ in trace) >= 0.0
    assert min(walls_distance(walls, x, y) for _, x, y, _ in trace) >= 0.25  # never into a wall
    assert trace[-1][1:3] == (4.0, 0.0)
    # A bench on the north side as well: the person cannot pass and waits, keeping its distance.
    bench = BoxObstacle(0.0, 0.9, 2.0, 0.6)
    world = ContactWorld(walls, [east, bench], RADIUS_M)
    trace = walk(world, (0.0, 0.0), 12.0)
    assert all(y == 0.0 for _, _, y, _ in trace) and trace[-1][1] == pytest.approx(-0.7, abs=1e-9)
    assert world.person_waited_s[0] == pytest.approx(12.0 - 3.3, abs=2 * DT_S)  # since it got there, 3.3 m on
    # When the robot goes, it walks on.
    trace = walk(world, (0.0, -5.0), 9.0, t0_s=12.0)
    assert trace[-1][1:3] == (4.0, 0.0)


def test_a_person_following_a_slow_robot_overtakes_it_after_its_patience():
    walls = [Wall(-5.0, -1.0, 12.0, -1.0), Wall(-5.0, 1.0, 12.0, 1.0)]
    east = Person(radius_m=0.25, speed_mps=1.0, path=((-3.0, 0.0), (10.0, 0.0)))
    sim = robot_sim(walls, [east])
    sim.set_body_targets(0.1, 0.0)
    ahead_of_robot, least = [], math.inf
    for _ in range(1500):
        sim.step(DT_S)
        ahead_of_robot.append(sim.contact.person_xy[0][0] - sim.truth.x)
        least = min(least, person_gap(sim.contact, (sim.truth.x, sim.truth.y)))
    assert ahead_of_robot[0] < 0 < ahead_of_robot[-1]  # behind at first, then past it
    assert least >= 0.3 - 0.1 * DT_S - 1e-9  # the robot moving away only ever opens the gap
    assert sim.contact.collisions == 0 and sim.truth.x == pytest.approx(1.5, abs=0.01)  # the robot was never held


def robot_sim(walls: list, obstacles: list, seed: int = 0) -> DiffDriveSim:
    """A noiseless robot of RADIUS_M at the origin facing east, responding at once."""
    model = DriveModel(track_width_m=0.17, max_wheel_speed_mps=0.5, max_wheel_accel_mps2=1e9,
                       motor_time_constant_s=0.0, slip_sigma=0.0, slip_bias=0.0, footprint_radius_m=RADIUS_M)
    return DiffDriveSim(model, RobotTruth(), np.random.default_rng(seed), walls=list(walls),
                        contact=ContactWorld(walls, list(obstacles), RADIUS_M))


def test_whatever_the_robot_does_a_person_never_overlaps_it_or_a_wall_and_the_same_run_is_the_same():
    """A robot driving at random in a corridor among pacing persons (it may drive into one: a person never does)."""
    walls = [Wall(-4.0, -1.0, 4.0, -1.0), Wall(-4.0, 1.0, 4.0, 1.0), Wall(-4.0, -1.0, -4.0, 1.0),
             Wall(4.0, -1.0, 4.0, 1.0)]
    persons = [Person(radius_m=0.25, speed_mps=0.8, path=((3.5, 0.3), (-3.5, 0.3)), loop=True),
               Person(radius_m=0.2, speed_mps=1.2, path=((-3.5, -0.4), (3.5, -0.4)), loop=True, patience_s=0.5),
               Person(radius_m=0.25, speed_mps=0.7, path=((1.0, -0.7), (1.0, 0.7)), loop=True, keeps_m=0.5)]

    def run() -> np.ndarray:
        sim = robot_sim(walls, persons)
        rng = np.random.default_rng(3)
        out, stepped_aside = [], set()
        for k in range(6000):  # 60 s
            if k % 100 == 0:
                sim.set_body_targets(float(rng.uniform(-0.3, 0.4)), float(rng.uniform(-1.0, 1.0)))
            sim.step(DT_S)
            for i, p in enumerate(sim.contact.persons):
                x, y = sim.contact.person_xy[i]
                assert math.hypot(x - sim.truth.x, y - sim.truth.y) >= p.radius_m + RADIUS_M - 1e-9, (k, i)
                if sim.contact.person_offset_m[i] != 0.0:  # off its path: clear of the walls
                    stepped_aside.add(i)
                    assert walls_distance(walls, x, y) >= p.radius_m - 1e-9, (k, i)
            out.append(sim.contact.person_xy.copy())
        assert stepped_aside == {0, 1, 2}  # each met the robot and stepped around it at least once
        return np.array(out)

    a = run()
    assert np.array_equal(a, run())  # deterministic: no randomness of its own
    moved = np.abs(np.diff(a, axis=0)).max()
    assert moved <= 1.2 * DT_S * math.sqrt(1 + 0.25) + 1e-9  # no jumps: a sideways step is at walking speed


def test_a_person_who_stands_at_its_end_does_not_move_for_the_robot():
    person = Person(radius_m=0.25, speed_mps=1.0, path=((2.0, 0.0), (0.5, 0.0)))  # ends 0.1 m from the footprint
    world = ContactWorld([], [person], RADIUS_M)
    trace = walk(world, (-3.0, 0.0), 5.0)
    walk(world, (0.0, 0.0), 10.0, t0_s=5.0)  # now the robot comes to it
    assert tuple(world.person_xy[0]) == (0.5, 0.0)


def test_the_corridor_person_world_still_loads_and_gives_way_by_default():
    world = load_world(Path(__file__).resolve().parents[1] / "worlds" / "corridor_person.yaml")
    (person,) = world.obstacles
    assert person.gives_way and person.keeps_m == 0.3 and person.loop


def test_a_person_who_keeps_no_distance_is_refused_in_the_words_of_a_strict_bound(tmp_path):
    import subprocess
    import sys

    from conftest import REPO
    path = tmp_path / "w.yaml"
    path.write_text("world: w\nobstacles:\n  - {shape: person, path: [[0, 0], [1, 0]], keeps_m: 0}\n")
    done = subprocess.run([sys.executable, "-m", "beastbt", "validate", str(path)], capture_output=True, text=True,
                          timeout=60, env={**__import__("os").environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 2
    assert "0 is out of range in 'keeps_m': must be more than 0" in done.stderr  # not "at least 0", which 0 is
