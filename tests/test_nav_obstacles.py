"""Navigation that goes round obstacles: the rolling local costmap, the local planner, go_to with a LiDAR.

The costmap and the planner are tested on their own with points placed by
hand; go_to on the simulator with walls in a test field; and the issue's
scenario, the A-B-C route of missions/gps_route.yaml on the campus lawn with
benches, a bike and posts in the way, against the same route on the empty
lawn (simulated time, same seed).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from beastbt.blackboard.types import COST_INSCRIBED, COST_LETHAL
from beastbt.core.errors import InvalidInput
from beastbt.navigation.local_costmap import LocalCostmapConfig, RollingCostmap, cost_at, inflation_lut
from beastbt.navigation.local_navigator import describe_obstacle
from beastbt.navigation.local_planner import DwaPlanner, Limits, LocalPlannerConfig
from beastbt.parts.navigation import local_navigator
from beastbt.robot.profile import load_profile
from beastbt.testing import MissionHarness
from conftest import REPO
from nav_support import (events_of, harness, place_yaml, robot_without_global_costmap, robot_without_lidar,
                         true_distance_m)

FOOTPRINT_M = 0.15
CONFIG = LocalCostmapConfig()
INSCRIBED_M = FOOTPRINT_M + CONFIG.footprint_padding_m
LIMITS = Limits(max_speed_mps=0.35, max_turn_rate_rps=math.radians(120), max_accel_mps2=1.0,
                max_angular_accel_rps2=math.radians(360))


def costmap_with(points_odom: list[tuple[float, float]], centre=(0.0, 0.0), stamp_s: float = 0.0,
                 config: LocalCostmapConfig = CONFIG) -> RollingCostmap:
    """A costmap holding ``points_odom`` (seen from the odom origin), built round ``centre``."""
    cm = RollingCostmap(config, FOOTPRINT_M)
    cm.add_scan(stamp_s, np.array(points_odom, dtype=float).reshape(-1, 2), (0.0, 0.0, 0.0))
    cm.build(stamp_s, centre)
    return cm


def cost(cm: RollingCostmap, x: float, y: float) -> int:
    assert cm.latest is not None
    return int(cost_at(cm.latest, np.array([x]), np.array([y]))[0])


# -- the costmap ------------------------------------------------------------------------------------
def test_a_point_is_lethal_in_its_cell_and_inflated_around_it_as_nav2_does():
    cm = costmap_with([(1.02, 0.52)])
    assert cost(cm, 1.02, 0.52) == COST_LETHAL
    # the cell centres are on the 5 cm grid: the point's cell is centred at (1.025, 0.525)
    assert cost(cm, 1.025 + 0.10, 0.525) == COST_INSCRIBED           # 0.10 m: inside the footprint's reach
    assert cost(cm, 1.025, 0.525 - 0.15) == COST_INSCRIBED           # 0.15 m < 0.17 m inscribed
    d = 0.30
    expected = 252.0 * math.exp(-CONFIG.cost_scaling_factor * (d - INSCRIBED_M))
    assert cost(cm, 1.025 - d, 0.525) == pytest.approx(expected, abs=2)  # Nav2's exponential band
    assert 0 < cost(cm, 1.025 + 0.5, 0.525) < cost(cm, 1.025 + 0.3, 0.525)
    assert cost(cm, 1.025 + CONFIG.inflation_radius_m + 0.06, 0.525) == 0   # beyond the inflation radius
    assert cost(cm, -2.0, -2.0) == 0


def test_the_lut_is_monotonic_from_lethal_to_free():
    lut = inflation_lut(CONFIG, INSCRIBED_M)
    assert lut[0] == COST_LETHAL and lut[1] == COST_INSCRIBED and lut[-1] == 0
    assert np.all(np.diff(lut.astype(int)) <= 0)


def test_scan_points_are_placed_with_the_odom_pose_at_the_scan():
    cm = RollingCostmap(CONFIG, FOOTPRINT_M)
    # the robot at (1, 2) facing north: a point 1 m ahead of it is at (1, 3) in odom
    cm.add_scan(0.0, np.array([[1.0, 0.0]]), (1.0, 2.0, math.pi / 2))
    cm.build(0.0, (1.0, 2.0))
    assert cost(cm, 1.0, 3.0) == COST_LETHAL
    assert cost(cm, 2.0, 2.0) == 0
    # the window rolls with the robot, its origin on the grid
    assert cm.latest is not None
    assert cm.latest.origin_x_m == pytest.approx(1.0 - CONFIG.width_m / 2) and cm.latest.cost.shape == (120, 120)


def test_points_out_of_range_are_left_out():
    cfg = LocalCostmapConfig(obstacle_min_range_m=0.1, obstacle_max_range_m=2.0)
    cm = RollingCostmap(cfg, FOOTPRINT_M)
    cm.add_scan(0.0, np.array([[0.05, 0.0], [1.0, 1.0], [2.5, 0.0]]), (0.0, 0.0, 0.0))
    cm.build(0.0, (0.0, 0.0))
    assert cost(cm, 1.0, 1.0) == COST_LETHAL
    assert cost(cm, 0.05, 0.0) < COST_LETHAL and cost(cm, 2.5, 0.0) == 0


def test_a_person_who_walked_away_is_forgotten_within_the_persistence():
    cm = RollingCostmap(CONFIG, FOOTPRINT_M)
    person = np.array([[1.0, 0.0], [1.0, 0.05], [1.05, 0.0]])
    cm.add_scan(0.0, person, (0.0, 0.0, 0.0))
    cm.build(0.0, (0.0, 0.0))
    assert cost(cm, 1.0, 0.0) == COST_LETHAL
    # the next scans see the person 2 m to the left: while the old scan persists both are there
    moved = person + [0.0, 2.0]
    cm.add_scan(0.1, moved, (0.0, 0.0, 0.0))
    cm.build(0.1, (0.0, 0.0))
    assert cost(cm, 1.0, 0.0) == COST_LETHAL and cost(cm, 1.0, 2.0) == COST_LETHAL
    t = 0.1
    while t < CONFIG.observation_persistence_s + 0.15:
        t += 0.1
        cm.add_scan(t, moved, (0.0, 0.0, 0.0))
    cm.build(t, (0.0, 0.0))
    assert cost(cm, 1.0, 0.0) == 0 and cost(cm, 1.0, 2.0) == COST_LETHAL


def test_bad_costmap_and_planner_knobs_are_refused_at_their_section(tmp_path):
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    path = tmp_path / "robot.yaml"
    line = text.count("\n") + 3
    for section, knob in (("local_costmap", "resolution_m: 0"), ("local_planner", "vx_samples: 1"),
                          ("local_planner", "sim_time_s: 10 parsecs")):
        path.write_text(text + f"\n{section}:\n  {knob}\n", encoding="utf-8")
        with pytest.raises(InvalidInput) as err:
            local_navigator(load_profile(path))
        problem = err.value.problems[0]
        assert str(err.value).startswith(f"{path}:{line}:"), str(err.value)
        assert knob.split(":")[0] in problem.message
        assert problem.hint or "expected" in problem.message     # what is expected, in the hint or the message


# -- the planner ----------------------------------------------------------------------------------------
def pursue(pose: tuple[float, float, float], goal: tuple[float, float], speed: float) -> tuple[float, float]:
    """A plain pure pursuit toward ``goal``: what go_to prefers."""
    alpha = math.atan2(goal[1] - pose[1], goal[0] - pose[0]) - pose[2]
    alpha = (alpha + math.pi) % (2 * math.pi) - math.pi
    if abs(alpha) > math.radians(50):
        return 0.0, math.copysign(1.0, alpha)
    ld = max(math.hypot(goal[0] - pose[0], goal[1] - pose[1]), 1e-3)
    return speed, speed * 2.0 * math.sin(alpha) / ld


def drive(planner: DwaPlanner, cm: RollingCostmap, points: np.ndarray, goal: tuple[float, float],
          seconds: float = 60.0, dt: float = 0.1):
    """Drive a unicycle with the planner from the origin facing +x; returns the poses, the last plan and the
    closest approach (m) of the robot's centre to any point."""
    pose = (0.0, 0.0, 0.0)
    last = (0.0, 0.0)
    poses = [pose]
    least = math.inf
    plan = None
    t = 0.0
    while t < seconds and math.hypot(goal[0] - pose[0], goal[1] - pose[1]) > 0.2:
        pref = pursue(pose, goal, 0.3)
        plan = planner.plan(cm.latest, pose, last, pref, goal, 0.3, LIMITS.max_turn_rate_rps, goal)
        v, w = plan.linear_mps, plan.angular_rps
        x, y, th = pose
        pose = (x + v * dt * math.cos(th + w * dt / 2), y + v * dt * math.sin(th + w * dt / 2), th + w * dt)
        last = (v, w)
        poses.append(pose)
        least = min(least, float(np.min(np.hypot(points[:, 0] - pose[0], points[:, 1] - pose[1]))))
        t += dt
    return poses, plan, least


def box_points(x0: float, x1: float, y0: float, y1: float, step: float = 0.03) -> np.ndarray:
    xs = np.arange(x0, x1 + 1e-9, step)
    ys = np.arange(y0, y1 + 1e-9, step)
    edges = [np.column_stack((xs, np.full_like(xs, y0))), np.column_stack((xs, np.full_like(xs, y1))),
             np.column_stack((np.full_like(ys, x0), ys)), np.column_stack((np.full_like(ys, x1), ys))]
    return np.concatenate(edges)


def test_the_planner_goes_round_a_box_to_the_goal_behind_it_without_touching():
    bench = box_points(1.5, 1.9, -0.8, 0.8)          # a 1.6 m bench across the way, the goal right behind it
    cm = costmap_with([tuple(p) for p in bench], centre=(1.5, 0.0))
    planner = DwaPlanner(LocalPlannerConfig(), LIMITS)
    poses, plan, least = drive(planner, cm, bench, (3.0, 0.0))
    end = poses[-1]
    assert math.hypot(3.0 - end[0], end[1]) <= 0.2, end
    assert least > INSCRIBED_M, least                  # the footprint never touched the bench
    assert max(abs(p[1]) for p in poses) > 0.8         # it went round an end of the bench
    assert planner.nf_computed > 0


def test_in_the_open_the_planner_returns_the_preference_unchanged():
    cm = costmap_with([(0.0, 4.0)])                    # something far off to the side
    planner = DwaPlanner(LocalPlannerConfig(), LIMITS)
    plan = planner.plan(cm.latest, (0.0, 0.0, 0.0), (0.2, 0.0), (0.25, 0.1), (2.0, 0.0), 0.3, 2.0)
    assert plan.free and (plan.linear_mps, plan.angular_rps) == (0.25, 0.1) and not plan.blocked
    assert planner.nf_computed == 0


def test_the_planner_stops_and_reports_blocked_in_a_dead_end():
    # a pocket 2 m wide, closed ahead at x = 1.2, its sides running out of the window behind the robot
    ys = np.linspace(-1.0, 1.0, 80)
    xs = np.linspace(-3.5, 1.2, 180)
    wall = np.concatenate((np.column_stack((np.full_like(ys, 1.2), ys)), np.column_stack((xs, np.full_like(xs, 1.0))),
                           np.column_stack((xs, np.full_like(xs, -1.0)))))
    cm = costmap_with([tuple(p) for p in wall], centre=(0.0, 0.0))
    planner = DwaPlanner(LocalPlannerConfig(), LIMITS)
    poses, plan, least = drive(planner, cm, wall, (3.0, 0.0), seconds=20.0)
    assert plan is not None and plan.blocked and plan.linear_mps == 0.0
    assert least > INSCRIBED_M
    assert poses[-1][0] < 1.2 - INSCRIBED_M           # it stopped short of the wall


def test_an_obstacle_is_described_by_its_distance_and_side():
    assert describe_obstacle(0.62, math.radians(15)) == "obstacle 0.6 m ahead, 15 deg to the left"
    assert describe_obstacle(1.0, math.radians(-2)) == "obstacle 1.0 m ahead"
    assert describe_obstacle(0.4, math.radians(-120)) == "obstacle 0.4 m 120 deg to the right"


# -- go_to on the simulator ---------------------------------------------------------------------------------
def test_go_to_blocked_by_a_wall_across_the_way_fails_after_blocked_after_naming_the_obstacle(tmp_path):
    # Without the global costmap (which would lead round the wall's end, 15 m off: tests/test_global_costmap.py),
    # the local costmap alone sees no way round.
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 10.0)}
steps:
  - go_to: {{place: a, blocked_after: 6 s}}
""", walls=[[-15.0, 5.0, 15.0, 5.0]], robot=robot_without_global_costmap(tmp_path))
    plans = []
    while not h.done and h.now_s < 200:
        h.tick()
        plans.append(h.blackboard("local_plan"))
    assert h.result == "failure"
    failed = events_of(h, "step_failed")
    assert len(failed) == 1
    text = failed[0].text
    # The obstacle named with where it is: ahead, or to a side once the robot has turned in place along the wall
    # (a stop of the collision monitor holds the travel, not the turn the local planner asks for).
    assert re.search(r"blocked for 6 s: obstacle \d+\.\d m (ahead|\d+ deg to the (left|right)), \d+\.\d m to a", text), text
    metres = float(text.split("obstacle ")[1].split(" m")[0])
    assert 0.15 < metres < 1.0                        # it stopped short, but close
    assert h.summary()["truth"]["collisions"] == 0
    assert h.truth.y < 5.0 - 0.15
    assert h.blackboard("costmap") is not None
    assert any(p is not None and p.blocked for p in plans)   # the plan said so while it waited
    assert plans[-1] is None                                  # and no plan is shown once the step has ended


def test_go_to_goes_round_a_box_while_it_still_finds_its_heading(tmp_path):
    # No magnetometer in the test field: go_to drives straight ahead to find its heading, and a bench is in the way.
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 9.0)}
steps:
  - go_to: a
""", obstacles=[{"shape": "box", "x": 0.1, "y": 2.5, "size_m": [1.2, 0.4], "yaw_deg": 0}])
    finding = []
    while not h.done and h.now_s < 120:
        h.tick()
        tip = h.run.root.tip()
        if tip is not None and tip.feedback_message.startswith("finding the heading") and abs(h.truth.y - 2.5) < 0.5:
            finding.append(h.truth.x)
    assert h.result == "success", [e.text for e in events_of(h, "step_failed")]
    assert finding and max(abs(x - 0.1) for x in finding) > 0.6 + 0.15   # it passed the bench beside it
    assert h.summary()["truth"]["collisions"] == 0


def test_go_to_waits_for_a_person_in_a_doorway_longer_than_stuck_after_and_then_goes_through(tmp_path):
    # A wall across the field with a 1 m doorway; a person stands in it until 30 s, then walks on ahead.
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 7.0)}
steps:
  - go_to: {{place: a, stuck_after: 5 s, blocked_after: 30 s}}
""", walls=[[-10.0, 4.0, -0.5, 4.0], [0.5, 4.0, 10.0, 4.0]],
        obstacles=[{"shape": "person", "radius_m": 0.25, "speed_mps": 0.8, "path": [[0.0, 4.0], [0.0, 14.0]],
                    "start_s": 30}])
    waited = 0.0
    while not h.done and h.now_s < 120:
        h.tick()
        # Standing, or creeping at the collision monitor's slow zone (about 2 cm/s) as it turns to face the person:
        # no progress either way.
        if h.now_s < 30 and h.truth.y > 3.0 and h.truth.v_mps < 0.03:
            waited += h.dt_s
    assert h.result == "success", [e.text for e in events_of(h, "step_failed")]
    assert waited > 5.0                                   # it waited before the person for longer than stuck_after
    assert h.truth.y > 4.5                                # and went through the doorway once the person had gone
    assert h.summary()["truth"]["collisions"] == 0


def test_go_to_without_a_lidar_steers_by_pure_pursuit_alone(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 6.0)}
steps:
  - go_to: a
""", robot=robot_without_lidar(tmp_path))
    assert h.run_to_end(timeout_s=200) == "success"
    assert h.run.ctx.services.local_navigator is None
    assert h.blackboard("costmap") is None and h.blackboard("local_plan") is None
    assert true_distance_m(h, 0.0, 6.0) < 3.5


# -- the scenario ----------------------------------------------------------------------------------------
def run_route(world: str, seed: int = 1) -> dict:
    h = MissionHarness.from_file(REPO / "missions" / "gps_route.yaml", world=str(REPO / "worlds" / world), seed=seed)
    h.run_to_end(timeout_s=1500)
    return h.summary()


def test_the_gps_route_goes_round_the_benches_and_posts_without_touching_in_at_most_1_5_times_the_time():
    open_lawn = run_route("campus.yaml")
    obstacles = run_route("campus_obstacles.yaml")
    assert open_lawn["status"] == "success"
    assert obstacles["status"] == "success", obstacles["events"][-3:]
    assert obstacles["truth"]["collisions"] == 0
    assert obstacles["truth"]["min_clearance_m"] > 0.05
    assert obstacles["sim_time_s"] <= 1.5 * open_lawn["sim_time_s"]
    assert all(w["reached"] for w in obstacles["waypoints"])
