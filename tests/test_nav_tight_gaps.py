"""Tight gaps: a gap at least the robot's width plus 10 cm is planned through when it is the way, and driven slowly.

* the global costmap (0.1 m cells) lets a path through a 0.40 m gap wherever it falls on the grid, and never through
  a 0.32 m one: the obstacle layer's half cells tell them apart; without ``narrow_gaps`` neither passes (before);
* the local planner takes an arc into a gap whose middle is within the padding but clear of the footprint, at
  ``local_planner.narrow_speed_mps`` at most;
* on the simulator, missions/tight_gap.yaml leaves the pen of worlds/field_gap.yaml (its only gap 0.40 m, the robot
  0.30 m across) without touching, below the narrow speed in the gap; the same pen with a 0.32 m gap
  (worlds/field_gap_narrow.yaml) fails at once, naming why; a gap measured a little too narrow from afar is looked
  at from close by first.

benchmarks/tight_gaps.py sweeps seeds 1-5 and gap widths (docs/navigation.md, Tight gaps).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.blackboard.types import FusedPose, LaserScan
from beastbt.devices.lidar_scan import LidarMounting
from beastbt.estimation.geodesy import LocalFrame
from beastbt.navigation.global_navigator import GlobalNavigator, sample_polyline
from beastbt.navigation.global_planner import GlobalPlannerConfig, NoPath
from beastbt.navigation.local_costmap import LocalCostmapConfig, RollingCostmap
from beastbt.navigation.local_navigator import SCAN_LATENCY_S, STEADY_TURN_RATE_RPS, LocalNavigator
from beastbt.navigation.local_planner import DwaPlanner, Limits, LocalPlannerConfig
from beastbt.navigation.obstacle_layer import GlobalCostmapConfig, ObstacleLayer
from beastbt.testing import MissionHarness
from conftest import REPO

FOOTPRINT_M = 0.15
MOUNT = LidarMounting(0.0, 0.0, 0.12, 0.0)
LIMITS = Limits(max_speed_mps=0.35, max_turn_rate_rps=math.radians(120), max_accel_mps2=1.0,
                max_angular_accel_rps2=math.radians(360))


def plans_through(gap_m: float, offset_m: float, narrow_gaps: bool = True) -> bool:
    """Whether the global costmap (GPS window, default cells) plans through a wall at y = 3 m whose only gap is
    ``gap_m`` wide, centred ``offset_m`` off the grid's lines."""
    g = GlobalNavigator(GlobalCostmapConfig(width_m=20.0), GlobalPlannerConfig(narrow_gaps=narrow_gaps),
                        FOOTPRINT_M, MOUNT)
    xs = np.arange(-10.0, 10.0, 0.01) + offset_m
    xs = xs[np.abs(xs - offset_m) > gap_m / 2]
    g.layer.mark_points(xs, np.full(len(xs), 3.0))
    try:
        g.plan((0.0, 0.0), (0.0, 6.0), 0.0, "b")
        return True
    except NoPath:
        return False


OFFSETS = (0.0, 0.013, 0.025, 0.037, 0.05, 0.062, 0.075, 0.087)


def test_the_global_costmap_passes_the_width_plus_10_cm_and_not_plus_2_cm_wherever_the_gap_falls():
    assert all(plans_through(0.40, off) for off in OFFSETS)
    assert not any(plans_through(0.32, off) for off in OFFSETS)
    # Without narrow gaps the padding is impassable, as before: 0.40 m is too narrow.
    assert not any(plans_through(0.40, off, narrow_gaps=False) for off in OFFSETS)
    # Taken when it is the way, not when a way round costs little more: round a 1.2 m wall's end, not through its gap
    # (a narrow cell costs three times its length).
    g = GlobalNavigator(GlobalCostmapConfig(width_m=20.0), GlobalPlannerConfig(), FOOTPRINT_M, MOUNT)
    xs = np.arange(-0.6, 0.6, 0.01)
    xs = xs[np.abs(xs) > 0.20]
    g.layer.mark_points(xs, np.full(len(xs), 3.0))
    assert np.abs(g.plan((0.0, 0.0), (0.0, 6.0), 0.0, "b").points[:, 0]).max() > 0.6


def test_the_local_planner_drives_into_a_narrow_gap_at_the_narrow_speed():
    config = LocalPlannerConfig()
    # A wall 0.1 m ahead across x, its gap 0.40 m wide on the robot's line; the robot at 0.3 m/s toward it.
    ys = np.arange(-3.0, 3.0, 0.01)
    ys = ys[np.abs(ys) > 0.20]
    cm = RollingCostmap(LocalCostmapConfig(), FOOTPRINT_M, narrow=True)
    cm.add_scan(0.0, np.column_stack((np.full(len(ys), 0.1), ys)), (0.0, 0.0, 0.0))
    cm.build(0.0, (0.0, 0.0))
    planner = DwaPlanner(config, LIMITS)
    plan = planner.plan(cm.latest, (0.0, 0.0, 0.0), (0.3, 0.0), (0.3, 0.0), (1.5, 0.0), 0.35, 2.0, (3.0, 0.0))
    assert plan.narrow and not plan.blocked
    assert 0.0 < plan.linear_mps <= config.narrow_speed_mps + 1e-9
    assert abs(plan.angular_rps) < 0.5


def test_the_pen_is_left_through_its_gap_slowly_and_a_gap_8_cm_narrower_fails_at_once():
    mission = REPO / "missions" / "tight_gap.yaml"
    h = MissionHarness.from_file(mission, world=str(REPO / "worlds" / "field_gap.yaml"), seed=1)
    narrow_speed = LocalPlannerConfig().narrow_speed_mps
    fastest_in_gap = 0.0
    while not h.done and h.now_s < 150.0:
        h.tick()
        if abs(h.truth.y - 3.0) < 0.1:  # the robot's centre in the gap (the wall at y = 3 m)
            fastest_in_gap = max(fastest_in_gap, abs(h.truth.v_mps))
    summary = h.summary()
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["truth"]["collisions"] == 0
    assert h.truth.y > 3.3                                  # out of the pen
    assert 0.0 < fastest_in_gap <= 1.05 * narrow_speed       # the wheels' own lag and slip aside
    narrow = MissionHarness.from_file(mission, world=str(REPO / "worlds" / "field_gap_narrow.yaml"), seed=1)
    narrow.run_to_end(timeout_s=60.0)
    summary = narrow.summary()
    assert summary["status"] == "failure" and summary["sim_time_s"] < 10.0
    assert summary["truth"]["collisions"] == 0
    failed = [e["text"] for e in summary["events"] if e["kind"] == "step_failed"]
    assert failed and "no gap on the way is wide enough for the robot (wider than 0.30 m)" in failed[0]


def wall_scan(robot: np.ndarray, centre: np.ndarray, along: np.ndarray, gap_m: float, hole: bool = True
              ) -> LaserScan:
    """A 0.5 degree scan from ``robot`` (x, y m; the LiDAR facing +x) of a straight wall through ``centre`` (m) in
    the direction ``along`` (unit), with an opening ``gap_m`` wide round ``centre`` (none when not ``hole``): beams
    through the opening and away from the wall return nothing."""
    angles = np.radians(np.arange(-180.0, 180.0, 0.5))
    ranges = np.full(len(angles), np.nan)
    normal = np.array([-along[1], along[0]])
    towards = np.column_stack((np.cos(angles), np.sin(angles))) @ normal
    t = ((centre - robot) @ normal) / np.where(np.abs(towards) > 1e-9, towards, np.nan)
    beyond = (robot + t[:, None] * np.column_stack((np.cos(angles), np.sin(angles))) - centre) @ along
    hit = (t > 0) & ((np.abs(beyond) > gap_m / 2) | (not hole))
    ranges[hit] = t[hit]
    return LaserScan(0.0, angles, ranges, np.zeros(len(angles)), 10.0, "test")


def slanted_wall(gap_m: float) -> tuple[GlobalNavigator, np.ndarray, np.ndarray, np.ndarray]:
    """A navigator whose layer holds a 60 m wall 3 m ahead at 45 degrees to the cells, its only opening ``gap_m``
    wide; and the wall's gap centre, direction and normal. Scans are only looked through, never marked: the marks
    stay as given."""
    g = GlobalNavigator(GlobalCostmapConfig(width_m=20.0), GlobalPlannerConfig(), FOOTPRINT_M, MOUNT)
    a = math.radians(45.0)
    along, normal = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    centre = 3.0 * normal
    s = np.arange(-30.0, 30.0, 0.01)
    wall = centre + s[np.abs(s) > gap_m / 2][:, None] * along
    g.layer.mark_points(wall[:, 0], wall[:, 1])
    g.layer.update = lambda *a, **k: 0
    return g, centre, along, normal


def test_a_gap_that_looks_a_little_too_narrow_is_planned_through_to_look_and_given_up_from_close_by():
    # A 0.34 m opening at 45 degrees to the cells measures just under what the costmap lets through (the robot's
    # 0.30 m and half a fine cell either side), as a 0.40 m gap seen on the slant from afar once did. With no other
    # way the robot goes to look at it from close by, where the measure is good; still too narrow there, the goal
    # fails and the gap is not tried again.
    g, centre, along, normal = slanted_wall(0.34)
    goal = tuple(6.0 * normal)
    with pytest.raises(NoPath):
        g.plan((0.0, 0.0), goal, 0.0, "b")  # no scan has looked through it: the marks alone, too narrow
    g.observe(wall_scan(np.zeros(2), centre, along, 0.34), (0.0, 0.0, 0.0))
    path = g.plan((0.0, 0.0), goal, 0.0, "b")
    assert len(g.tentative) == 1 and float(np.hypot(*(g.tentative[0] - centre))) < 0.05
    assert np.hypot(*(sample_polyline(path.points, 0.01) - centre).T).min() < 0.05  # through its middle
    # From 0.6 m before it, seen through and measured the same: no way, and no second look from farther back.
    near = centre - 0.6 * normal
    g.observe(wall_scan(near, centre, along, 0.34), (near[0], near[1], 0.0))
    with pytest.raises(NoPath, match="no gap on the way is wide enough"):
        g.plan(tuple(near), goal, 0.0, "b")
    g.observe(wall_scan(np.zeros(2), centre, along, 0.34), (0.0, 0.0, 0.0))
    with pytest.raises(NoPath):
        g.plan((0.0, 0.0), goal, 0.0, "b")
    assert g.tentative == [] and len(g.refuted) >= 1


def test_a_hole_between_a_walls_marks_that_no_beam_went_through_is_not_looked_at():
    # The same 0.34 m hole in the marks, but the wall is whole there (its hits were sparse): every beam toward it
    # returns from the wall, so nothing says it is a gap.
    g, centre, along, normal = slanted_wall(0.34)
    g.observe(wall_scan(np.zeros(2), centre, along, 0.34, hole=False), (0.0, 0.0, 0.0))
    with pytest.raises(NoPath):
        g.plan((0.0, 0.0), tuple(6.0 * normal), 0.0, "b")
    assert g.tentative == []


# -- a gap at a slant to the grid, and scans taken while turning ------------------------------------------------------
# The odom frame turns with the robot's heading at the start, so a wall square to the world lies at any angle to the
# global costmap's cells. Three things closed a 0.40 m gap met on the slant (a pen left with the robot started at
# 45 degrees to its walls failed "no way" on every seed): the clearance was measured along the cells' columns and
# rows only, a gap's cells were found by looking along lines of cells only, and the scans taken as the robot turned
# in place at the start marked the gap's mouth 5-10 cm off (the marks stay until a beam passes through them).


def plans_through_slanted(gap_m: float, angle_deg: float, offset_m: float) -> bool:
    """Whether the global costmap plans through the gap (``gap_m`` wide, its centre ``offset_m`` along the wall from
    the robot's line) of a 60 m wall 3 m ahead, the wall at ``angle_deg`` to the grid's x axis."""
    g = GlobalNavigator(GlobalCostmapConfig(width_m=20.0), GlobalPlannerConfig(), FOOTPRINT_M, MOUNT)
    a = math.radians(angle_deg)
    along, normal = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    centre = 3.0 * normal + offset_m * along
    s = np.arange(-30.0, 30.0, 0.01)
    wall = centre + s[np.abs(s) > gap_m / 2][:, None] * along
    g.layer.mark_points(wall[:, 0], wall[:, 1])
    try:
        path = g.plan((0.0, 0.0), tuple(6.0 * normal), 0.0, "b")
    except NoPath:
        return False
    crossing = sample_polyline(path.points, 0.01)
    assert np.hypot(*(crossing - centre).T).min() < 0.05  # through the gap, near its centre (crossed square)
    return True


SLANTS = (10.0, 22.5, 37.0, 45.0, 60.0)
SLANT_OFFSETS = (0.0, 0.031, 0.062)


def test_the_global_costmap_passes_a_gap_at_a_slant_to_its_cells_and_never_the_width_plus_2_cm():
    assert all(plans_through_slanted(0.40, a, off) for a in SLANTS for off in SLANT_OFFSETS)
    assert not any(plans_through_slanted(0.32, a, off) for a in SLANTS for off in SLANT_OFFSETS)


def test_a_scan_taken_while_turning_is_deskewed_and_kept_from_the_global_costmap():
    nav = LocalNavigator(LocalCostmapConfig(), LocalPlannerConfig(), FOOTPRINT_M, MOUNT, LIMITS)
    rate = 1.0  # rad/s, turning in place, as go_to does toward a place behind it
    for k in range(21):
        t = 0.05 * k
        nav.observe(None, FusedPose(t, 0.0, 0.0, rate * t), t)
    # A 10 Hz revolution ending at 1.0 s (its stamp): each beam is turned by the turn still to come after it.
    n = 450
    angles = np.linspace(-math.pi, math.pi, n, endpoint=False)
    scan = LaserScan(1.0, angles, np.full(n, 2.0), np.zeros(n), 10.0, "ld19")
    fixed = nav.deskewed(scan, nav.pose_at(1.0))
    behind = (angles - fixed.angles_rad + math.pi) % (2 * math.pi) - math.pi
    assert behind[0] == pytest.approx(rate * (0.1 + SCAN_LATENCY_S), abs=2e-3)   # the first beam: a revolution ago
    assert behind[-1] == pytest.approx(rate * SCAN_LATENCY_S, abs=2e-3)
    assert np.all(np.diff(behind) < 0)
    assert nav.turn_rate_rps(scan) == pytest.approx(rate)
    nav.observe(scan, FusedPose(1.0, 0.0, 0.0, rate * 1.0), 1.0)
    assert nav.fresh is not None and nav.fresh_steady is None  # the local costmap takes it; the global one does not
    # Standing still, nothing to turn, and the global costmap takes it.
    still = LocalNavigator(LocalCostmapConfig(), LocalPlannerConfig(), FOOTPRINT_M, MOUNT, LIMITS)
    for k in range(21):
        still.observe(None, FusedPose(0.05 * k, 0.0, 0.0, 0.3), 0.05 * k)
    assert still.deskewed(scan, still.pose_at(1.0)) is scan
    still.observe(scan, FusedPose(1.0, 0.0, 0.0, 0.3), 1.0)
    assert still.fresh_steady is not None
    assert 0.0 < STEADY_TURN_RATE_RPS < rate


def test_a_fine_mark_a_beam_passes_through_is_cleared_and_the_wall_end_beside_it_stays():
    layer = ObstacleLayer(GlobalCostmapConfig(), 100, 100, 0.1, -5.0, -5.0, fine=True)
    # A wall along y = 2.05 from x = -3 to 0.06 (its end in the cell x 0.0-0.1), and a stray mark in the same cell
    # 3 cm past the end, in the gap: as a scan placed a degree off in a turn leaves it.
    xs = np.arange(-3.0, 0.06, 0.01)
    layer.mark_points(np.append(xs, 0.09), np.full(len(xs) + 1, 2.05))
    row, col, _ = layer.cells(np.array([0.09]), np.array([2.05]))
    fine = lambda x: layer.fine[int((2.05 + 5.0) / 0.025), int((x + 5.0) / 0.025)]  # noqa: E731
    assert fine(0.09) and fine(0.05)
    # Seen from the origin by a dense LiDAR: the beams toward the wall hit it, those past its end return nothing.
    angles = np.radians(np.arange(-180.0, 180.0, 0.25))
    ahead = (angles > 0.1) & (angles < math.pi - 0.1)
    wall = ahead.copy()
    wall[ahead] = 2.05 / np.tan(angles[ahead]) < 0.06
    ranges = np.full(len(angles), np.nan)
    ranges[wall] = 2.05 / np.sin(angles[wall])
    layer.update((0.0, 0.0, 0.0), angles, ranges)
    assert not fine(0.09)                                 # seen through: gone
    assert fine(0.05)                                     # the wall's end, hit: kept
    assert layer.marked[row[0], col[0]]                   # and its cell with it



def test_a_lone_dropout_along_a_fence_seen_from_its_gap_clears_nothing():
    # The robot 0.2 m before a fence (y = 0.2 m, along x), as in the fence's gap: its beams meet the fence at a
    # grazing angle, a metre or more apart far along it. A beam that lost its return (a dropout) in between is not
    # open space: the fence's cells along it stay (cleared, they were the holes the planner took for a way through).
    layer = ObstacleLayer(GlobalCostmapConfig(), 200, 200, 0.1, -10.0, -10.0, fine=True, dropouts_clear=False)
    xs = np.arange(0.5, 9.0, 0.01)
    layer.mark_points(xs, np.full(len(xs), 0.205))
    before = layer.marked.copy()
    angles = np.radians(np.arange(-180.0, 180.0, 0.8))
    toward = (angles > math.radians(1.4)) & (angles < math.radians(20.0))
    ranges = np.full(len(angles), np.nan)
    ranges[toward] = 0.205 / np.sin(angles[toward])
    lost = int(np.flatnonzero(toward)[2])  # 2.2 degrees: along the fence 4-9 m away
    ranges[lost] = np.nan
    layer.update((0.0, 0.0, 0.0), angles, ranges)
    assert layer.marked[before].all()                     # the fence's cells, every one kept
    # Open space (several beams in a row with no return) still clears: the cells of a person who walked away.
    layer.mark_points(np.array([-3.0]), np.array([0.0]))
    layer.update((0.0, 0.0, 0.0), angles, ranges)
    assert not layer.marked[layer.cells(np.array([-3.0]), np.array([0.0]))[:2]].any()


SLANTED_PEN_WORLD = """\
world: pen_at_a_slant
description: A 3 m x 3 m pen whose only way out is a 0.40 m gap in its north wall, 0.3 m from its east corner.
datum: {lat: 40.41680, lon: -3.70380, alt_m: 650}
start: {x: 0.0, y: 0.0, yaw_deg: 225}
battery: {start_v: 12.3, drain_v_per_s: 0.0002}
gps: {rate_hz: 1.0, white_sigma_m: 1.5, bias_sigma_m: 0.5, bias_tau_s: 60.0, jump_rate_per_s: 0.0, cold_start_s: 1.0,
      hdop: 0.9, sats: 9}
imu: {mag_field_ut: 45.0, mag_inclination_deg: 54.0, mag_declination_deg: 1.0}
walls:
  - [-1.5, 2.0, 0.8, 2.0]
  - [1.2, 2.0, 1.5, 2.0]
  - [1.5, 2.0, 1.5, -1.0]
  - [1.5, -1.0, -1.5, -1.0]
  - [-1.5, -1.0, -1.5, 2.0]
"""


def test_a_pen_is_left_through_a_gap_met_at_a_slant_to_the_start_heading(tmp_path):
    # The robot starts facing south-west, away from the gap (north, off to the east), so the odom frame (and the
    # global costmap's cells) lies at 45 degrees to the walls, and it turns in place before it drives. Before the
    # fixes above it failed at once on every seed, "no way to outside ... no gap on the way is wide enough".
    (tmp_path / "world.yaml").write_text(SLANTED_PEN_WORLD, encoding="utf-8")
    lat, lon, _ = LocalFrame(40.41680, -3.70380, 650.0).to_geodetic(4.0, 6.0)  # 4 m beyond the gap, 3 m east
    (tmp_path / "mission.yaml").write_text(
        f"mission: slanted_pen\nworld: world.yaml\nplaces:\n  outside: {{lat: {lat:.9f}, lon: {lon:.9f}, "
        f"tolerance: 1.5 m}}\nsteps:\n  - go_to: outside\n", encoding="utf-8")
    h = MissionHarness.from_file(tmp_path / "mission.yaml", world=str(tmp_path / "world.yaml"), seed=2)
    while not h.done and h.now_s < 120.0:
        h.tick()
    summary = h.summary()
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["truth"]["collisions"] == 0
    assert h.truth.y > 2.3                                  # out of the pen, through its gap
