"""The console map's obstacle layers (``state.obstacles``), built in-process on a simulator run.

The robot turns left and drives in the corridor with the pacing person; a
hand-made local plan is written on the blackboard in the odom frame (the
planner is another part's). Each layer must land on the map's plan where the
world says it is: scan returns on the walls and the person, the zones round
the robot and turned with it, the plan through the robot's pose, the person
where the simulator has it. The payload stays small.
"""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest
import shapely

from beastbt.assembly import prepare
from beastbt.blackboard import catalogue
from beastbt.blackboard.types import COST_INSCRIBED, COST_LETHAL, COST_UNKNOWN, LocalCostmap, LocalPlan
from beastbt.live.console_state import MAX_COSTMAP_CELLS, MAX_SCAN_POINTS, ConsoleState, MapFrame, obstacle_layers
from beastbt.recording.obstacle_views import STALE_S, board_reader, sim_contact
from beastbt.run.session import RunOptions, execute
from conftest import REPO

MISSION = """mission: turn_and_drive
steps:
  - turn: {angle: 30 deg}
  - drive: {distance: 0.5 m, speed: 0.2 m/s}
  - wait: 9 s
"""
LOOK_AT_S = (3.0, 9.0, 12.0)
"""When the layers are looked at (simulated s): after the turn, while the person walks, near the end."""


@pytest.fixture(scope="module")
def looks(tmp_path_factory):
    """(layers, robot pose on the plan, odom pose, persons, plan written) at each of LOOK_AT_S, and a state."""
    p = prepare(str(tmp_path_factory.mktemp("m") / "m.yaml"),
                RunOptions(seed=3, runs_dir=str(tmp_path_factory.mktemp("runs")), record=False,
                           world=str(REPO / "worlds" / "corridor_person.yaml")), mission_text=MISSION)
    board = catalogue.writer("fake_planner", ("local_plan", "costmap"))
    reader = board_reader()
    seen: list = []
    todo = list(LOOK_AT_S)
    states: list = []

    def hook(run, now_s: float) -> None:
        odo = run.odom
        # A plan 1 m straight ahead of the robot, in odom (as a local planner would write it), until 10 s.
        if now_s <= 10.0:
            ahead = [[odo.x + k * 0.25 * math.cos(odo.yaw), odo.y + k * 0.25 * math.sin(odo.yaw)] for k in range(5)]
            board.local_plan = LocalPlan(now_s, np.array(ahead), 0.2, 0.0, blocked=now_s > 8.0)
            # A 4 m costmap round the robot (5 cm cells): one lethal cell 1 m ahead of it, an inscribed ring of
            # cells round that, an unknown corner (not drawn), and a wall of lethal cells too many to send all.
            cost = np.zeros((80, 80), dtype=np.uint8)
            ox, oy = odo.x - 2.0, odo.y - 2.0
            col = int((odo.x + math.cos(odo.yaw) - ox) / 0.05)
            row = int((odo.y + math.sin(odo.yaw) - oy) / 0.05)
            cost[row - 1:row + 2, col - 1:col + 2] = COST_INSCRIBED
            cost[row, col] = COST_LETHAL
            cost[:10, :10] = COST_UNKNOWN
            if now_s > 8.0:
                cost[70:, :] = COST_LETHAL
            board.costmap = LocalCostmap(now_s, ox, oy, 0.05, cost)
        if todo and now_s >= todo[0] - 1e-9:
            todo.pop(0)
            frame = MapFrame(run, p.world)
            pose = frame.pose()
            seen.append((obstacle_layers(run, frame, reader, now_s, pose), pose,
                         sim_contact(run).person_xy.copy(), now_s))
            if not states:
                states.append(ConsoleState(run, p.world, lambda: 0.0).build())

    p.run.hooks.append(hook)
    execute(p, io.StringIO())
    assert len(seen) == len(LOOK_AT_S)
    return seen, states[0]


def test_scan_returns_land_on_the_walls_and_the_person_of_the_world(looks):
    walls = shapely.MultiLineString([[(0, -1), (10, -1)], [(0, 1), (10, 1)], [(0, -1), (0, 1)], [(10, -1), (10, 1)]])
    for layers, _pose, persons, _t in looks[0]:
        scan = np.array(layers["scan"])
        assert 100 < len(scan) <= MAX_SCAN_POINTS
        person = shapely.Point(*persons[0]).buffer(0.25).exterior
        d = np.minimum(shapely.distance(shapely.points(scan), walls), shapely.distance(shapely.points(scan), person))
        assert np.quantile(d, 0.95) < 0.05  # the LD19's noise and dropouts aside, every return is on something


def test_zones_surround_the_robot_and_turn_with_it(looks):
    for layers, (x, y, yaw), _, _ in looks[0]:
        zones = layers["zones"]
        stop, slow = shapely.Polygon(zones["stop"]), shapely.Polygon(zones["slow"])
        assert stop.contains(shapely.Point(x, y)) and slow.contains(stop.buffer(-0.02))
        # The slow zone reaches ahead of the robot: its centre lies along the heading.
        c = slow.centroid
        assert math.atan2(c.y - y, c.x - x) == pytest.approx(yaw, abs=0.05)
        assert zones["action"] in ("none", "slow", "approach", "stop", "silent")
    assert looks[0][0][1][2] == pytest.approx(math.radians(30), abs=0.05)  # the robot did turn


def test_the_plan_goes_from_odom_onto_the_map_through_the_robots_pose(looks):
    (first, (x, y, yaw), _, _), (middle, _, _, _), (late, _, _, t_late) = looks[0]
    plan = np.array(first["plan"])
    assert plan[0] == pytest.approx([x, y], abs=0.02)  # it starts at the robot
    assert plan[-1] == pytest.approx([x + math.cos(yaw), y + math.sin(yaw)], abs=0.02)  # 1 m along its heading
    assert not first["blocked"] and middle["blocked"]
    assert t_late - 10.0 > STALE_S and late["plan"] is None  # the planner stopped: the plan goes away


def test_the_costmap_s_occupied_cells_are_drawn_where_odom_puts_them(looks):
    (first, (x, y, yaw), _, _), (middle, _, _, _), (late, _, _, _) = looks[0]
    cells = np.array(first["costmap"]["cells"])
    assert len(cells) == 9 and first["costmap"]["resolution_m"] == 0.05  # lethal and inscribed; never unknown
    centre = cells.mean(axis=0)
    assert centre == pytest.approx([x + math.cos(yaw), y + math.sin(yaw)], abs=0.05)  # 1 m ahead of the robot
    assert len(middle["costmap"]["cells"]) <= MAX_COSTMAP_CELLS < 10 * 80  # the wall is thinned, not all sent
    assert late["costmap"] is None  # stale: taken off


def test_the_person_is_drawn_where_the_simulator_has_it(looks):
    xs = []
    for layers, _, persons, _ in looks[0]:
        (px, py, r), = layers["persons"]
        assert [px, py] == pytest.approx(persons[0].tolist(), abs=0.01) and r == 0.25
        xs.append(px)
    assert xs[0] > xs[1] > xs[2]  # walking west, toward the robot


def test_the_state_carries_the_layers_in_a_few_kilobytes(looks):
    _, state = looks
    size = len(json.dumps(state["obstacles"]))
    assert state["obstacles"]["scan"] and size < 8000, size


def test_on_a_fused_map_the_plan_starts_at_the_fused_pose_and_runs_along_its_heading(tmp_path):
    # The GPS route navigates by the fused pose: the map is drawn by it, while the plan is in odom (which drifts
    # away from it): the plan must still start at the robot as drawn and leave along its heading.
    p = prepare(str(REPO / "missions" / "gps_route.yaml"),
                RunOptions(seed=1, runs_dir=str(tmp_path), record=False, max_time_s=12.0))
    board = catalogue.writer("fake_planner", ("local_plan",))
    reader = board_reader()
    seen = []

    def hook(run, now_s: float) -> None:
        odo = run.odom
        board.local_plan = LocalPlan(now_s, np.array([[odo.x, odo.y], [odo.x + math.cos(odo.yaw),
                                                                       odo.y + math.sin(odo.yaw)]]))
        if now_s >= 10.0 and not seen:
            frame = MapFrame(run, p.world)
            pose = frame.pose()
            seen.append((frame.fused, pose, (odo.x, odo.y, odo.yaw), obstacle_layers(run, frame, reader, now_s, pose)))

    p.run.hooks.append(hook)
    execute(p, io.StringIO())
    fused, (x, y, yaw), odom, layers = seen[0]
    assert fused and math.hypot(x - odom[0], y - odom[1]) > 0.05  # the two frames do differ here
    start, end = layers["plan"]
    assert start == pytest.approx([x, y], abs=0.02)
    assert end == pytest.approx([x + math.cos(yaw), y + math.sin(yaw)], abs=0.02)
