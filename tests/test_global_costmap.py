"""The global costmap with memory: the obstacle layer (marking, ray-traced clearing, the rolling window), planning
round what it holds on GPS, and the map's blocked cells clearing the same way.

Scans are made by hand: a LiDAR at a pose, beams every degree, each beam's range the nearest of the segments
given (NaN when it meets none within 12 m), as the simulator's LiDAR would return them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from beastbt.blackboard.types import LaserScan
from beastbt.devices.lidar_scan import LidarMounting
from beastbt.mapping.occupancy_map import FREE, empty_map
from beastbt.navigation.global_navigator import (SWITCH_FRACTION, SWITCH_MIN_M, GlobalNavigator, PathFollow,
                                                sample_polyline)
from beastbt.navigation.global_planner import GlobalPlannerConfig, NoPath
from beastbt.navigation.obstacle_layer import GlobalCostmapConfig, ObstacleLayer

CONFIG = GlobalCostmapConfig()
ANGLES = np.radians(np.arange(-180.0, 180.0, 1.0))
MOUNT = LidarMounting(0.0, 0.0, 0.12, 0.0)


def ranges_to(segments: list[tuple[float, float, float, float]], pose: tuple[float, float, float],
              max_range_m: float = 12.0) -> np.ndarray:
    """The range (m) of each beam of :data:`ANGLES` from ``pose`` to the nearest segment; NaN where none."""
    x, y, yaw = pose
    out = np.full(len(ANGLES), np.nan)
    dx, dy = np.cos(ANGLES + yaw), np.sin(ANGLES + yaw)
    for x0, y0, x1, y1 in segments:
        ex, ey = x1 - x0, y1 - y0
        den = dx * ey - dy * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((x0 - x) * ey - (y0 - y) * ex) / den
            u = ((x0 - x) * dy - (y0 - y) * dx) / den
        hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1) & (t <= max_range_m)
        out = np.where(hit & ~(out <= t), t, out)
    return out


def layer(width_m: float = 20.0, config: GlobalCostmapConfig = CONFIG) -> ObstacleLayer:
    n = int(round(width_m / config.resolution_m))
    return ObstacleLayer(config, n, n, config.resolution_m, -width_m / 2, -width_m / 2)


def marked_at(lay: ObstacleLayer, x: float, y: float) -> bool:
    row, col, _ = lay.cells(np.array([x]), np.array([y]))
    return bool(lay.marked[row[0], col[0]])


def marked_near(lay: ObstacleLayer, x: float, y: float, r: float = 0.25) -> bool:
    """Whether any cell within ``r`` (m) of (x, y) is marked."""
    rows, cols = lay.shape
    yy = lay.origin_y + (np.arange(rows) + 0.5) * lay.resolution_m
    xx = lay.origin_x + (np.arange(cols) + 0.5) * lay.resolution_m
    near = (yy[:, None] - y) ** 2 + (xx[None, :] - x) ** 2 <= r * r
    return bool((lay.marked & near).any())


PERSON = [(3.0, -0.2, 3.0, 0.2), (2.8, -0.2, 3.2, -0.2), (2.8, 0.2, 3.2, 0.2)]
FENCE = [(5.0, -3.0, 5.0, 3.0)]


def test_what_the_lidar_saw_stays_marked_when_it_no_longer_sees_it():
    lay = layer()
    lay.update((0.0, 0.0, 0.0), ANGLES, ranges_to(FENCE, (0.0, 0.0, 0.0)))
    assert marked_at(lay, 5.0, 0.0) and marked_at(lay, 5.0, 2.5)
    # Behind a wall (a building between), for as long as you like: no beam passes through the fence, so it stays.
    # (The local costmap forgets a point after observation_persistence_s.)
    pose = (-3.0, 0.0, math.pi)
    for _ in range(20):
        lay.update(pose, ANGLES, ranges_to([(-6.0, -9.0, -6.0, 9.0), (-2.0, -9.0, -2.0, 9.0)], pose))
    assert marked_at(lay, 5.0, 0.0) and marked_at(lay, 5.0, 2.5)


def test_a_person_who_walked_away_is_cleared_by_the_beams_that_pass_where_they_stood_and_a_fence_stays():
    lay = layer()
    behind = [(8.0, -9.0, 8.0, 9.0)]                      # a wall behind, so the beams have an end
    pose = (0.0, 0.0, 0.0)
    lay.update(pose, ANGLES, ranges_to(PERSON + behind, pose))
    assert marked_near(lay, 3.0, 0.0)
    before = lay.version
    lay.update(pose, ANGLES, ranges_to(behind, pose))     # the person has gone: the beams reach the wall
    assert not marked_near(lay, 3.0, 0.0) and marked_at(lay, 8.05, 0.0)
    assert lay.version > before and lay.cleared_total > 0
    # A fence seen again and again stays marked (its own returns mark it after the clearing).
    for _ in range(5):
        lay.update(pose, ANGLES, ranges_to(FENCE + behind, pose))
    assert marked_at(lay, 5.0, 0.0) and marked_at(lay, 5.0, -2.0)


def test_a_beam_without_return_clears_only_when_told_that_no_return_is_open_space():
    for clear, expected in ((True, False), (False, True)):
        lay = layer(config=GlobalCostmapConfig(clear_on_no_return=clear))
        pose = (0.0, 0.0, 0.0)
        lay.update(pose, ANGLES, ranges_to(PERSON, pose))
        lay.update(pose, ANGLES, ranges_to([], pose))     # nothing at all within range now
        assert marked_near(lay, 3.0, 0.0) is expected


def test_marks_beyond_the_raytrace_range_are_not_cleared_and_far_returns_do_not_mark():
    cfg = GlobalCostmapConfig(obstacle_max_range_m=6.0, raytrace_max_range_m=6.5)
    lay = layer(config=cfg)
    lay.mark_points(np.array([7.5]), np.array([0.0]))
    pose = (0.0, 0.0, 0.0)
    lay.update(pose, ANGLES, ranges_to([(9.0, -9.0, 9.0, 9.0)], pose))
    assert marked_at(lay, 7.5, 0.0)                      # 7.5 m away: beyond 6.5 m, not cleared
    assert not marked_at(lay, 9.0, 0.0)                  # the wall 9 m away is beyond 6 m: not marked


def test_the_rolling_window_keeps_its_marks_in_place_as_it_moves():
    lay = layer(width_m=20.0)
    lay.mark_points(np.array([4.0]), np.array([3.0]))
    assert not lay.recentre(2.0, 0.0)                     # within recentre_m of the centre: it stays
    assert lay.recentre(8.0, 1.0)
    cx, cy = lay.centre
    assert abs(cx - 8.0) <= 0.1 and abs(cy - 1.0) <= 0.1
    assert marked_at(lay, 4.0, 3.0) and lay.marked.sum() == 1
    assert lay.recentre(30.0, 0.0)                        # the mark has left the window: forgotten
    assert lay.marked.sum() == 0


def test_clear_around_forgets_the_marks_within_the_radius_only():
    lay = layer()
    lay.mark_points(np.array([1.0, 4.0]), np.array([0.0, 0.0]))
    assert lay.clear_around(0.0, 0.0, 2.0) == 1
    assert not marked_at(lay, 1.0, 0.0) and marked_at(lay, 4.0, 0.0)


# -- planning on GPS: the rolling window ------------------------------------------------------------------------
def navigator() -> GlobalNavigator:
    return GlobalNavigator(GlobalCostmapConfig(), GlobalPlannerConfig(), 0.15, MOUNT)


def scan_of(segments, pose) -> LaserScan:
    return LaserScan(0.0, ANGLES, ranges_to(segments, pose), np.zeros(len(ANGLES)), 10.0, "test")


def test_a_fence_across_the_way_blocks_the_straight_line_and_the_plan_goes_round_its_end():
    g = navigator()
    fence = [(8.0, -4.0, 8.0, -0.125), (8.0, 0.125, 8.0, 4.0)]  # across the way at x = 8, a 0.25 m gap
    for x in (2.0, 3.0, 4.0):
        g.observe(scan_of(fence, (x, 0.0, 0.0)), (x, 0.0, 0.0))
    assert g.blocked(((4.0, 0.0), (14.0, 0.0)))
    assert not g.blocked(((4.0, 6.0), (14.0, 6.0)))
    path = g.plan((4.0, 0.0), (14.0, 0.0), 1.0, "far_side")
    assert not g.blocked(path.points, skip_m=0.2)
    assert np.abs(path.points[:, 1]).max() > 4.0          # round an end of the fence, 4 m off the line
    assert path.length_m < 10.0 + 2 * 4.5                 # and not much farther than it must


def _wall_seen(g: GlobalNavigator, x: float, y0: float, y1: float) -> None:
    """Mark a wall along x from y0 to y1 (m) in ``g``'s layer, as the LiDAR would have."""
    g.layer.mark_points(*sample_polyline(np.array([[x, y0], [x, y1]], float), 0.05).T)


def test_a_way_blocked_as_more_of_its_wall_is_seen_is_mended_on_its_side_not_swapped_for_the_other_end():
    # A wall across the way, seen from -3 to 3 m: the robot, a little below the middle, plans round its lower end.
    g = navigator()
    _wall_seen(g, 8.0, -3.0, 3.0)
    start, goal = (4.0, -0.3), (14.0, 0.0)
    first = g.plan(start, goal, 1.0, "far_side")
    assert first.points[:, 1].min() < -3.0
    # More of the wall appears below (beyond the LiDAR's reach before): the lower end is now about as far as the
    # upper one, so a plan from scratch may take either. The way it went on is mended, round the new lower end.
    _wall_seen(g, 8.0, -4.0, -3.0)
    assert g.way_blocked(first.points, skip_m=g.inscribed_m)
    fresh = g.plan(start, goal, 1.0, "far_side")
    assert fresh.points[:, 1].max() > 3.0                  # from scratch: the other end
    mended = g.replan(start, goal, 1.0, "far_side", first.points)
    assert mended.points[:, 1].min() < -4.0 and mended.points[:, 1].max() < 1.0
    assert not g.way_blocked(mended.points, skip_m=g.inscribed_m)
    assert mended.length_m <= fresh.length_m + max(SWITCH_MIN_M, SWITCH_FRACTION * mended.length_m)  # not clearly longer
    # The wall goes on far below: the upper end is now clearly shorter, and the way swaps to it.
    _wall_seen(g, 8.0, -12.0, -4.0)
    swapped = g.replan(start, goal, 1.0, "far_side", mended.points)
    assert swapped.points[:, 1].max() > 3.0
    assert not g.way_blocked(swapped.points, skip_m=g.inscribed_m)


def test_a_goal_enclosed_by_what_was_seen_fails_at_once_naming_why():
    g = navigator()
    # a 4 m box round the goal, every wall seen
    g.layer.mark_points(*sample_polyline(np.array([[6, -2], [10, -2], [10, 2], [6, 2], [6, -2]], float),
                                         0.05).T)
    assert g.blocked(((0.0, 0.0), (8.0, 0.0)))
    with pytest.raises(NoPath) as err:
        g.plan((0.0, 0.0), (8.0, 0.0), 1.0, "inside")
    assert "cannot be reached" in err.value.reason and "inside" in err.value.reason


def test_a_goal_beyond_the_window_is_planned_to_at_its_edge():
    g = navigator()
    target = g.clip_to_window((0.0, 0.0), (100.0, 0.0))
    assert target[0] == pytest.approx(20.0 - 1.0, abs=0.11) and target[1] == 0.0
    path = g.plan((0.0, 0.0), (100.0, 0.0), 2.0, "far")
    assert path.points[-1][0] < 20.0


def test_a_path_follower_moves_along_and_never_back():
    way = PathFollow(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]))
    assert way.length_m == pytest.approx(8.0)
    assert way.project((2.0, 0.3), 5.0) == pytest.approx(2.0)
    assert way.point_at(5.0) == pytest.approx((4.0, 1.0))
    assert way.project((1.8, 0.1), 5.0) == pytest.approx(2.0)   # never backwards
    assert way.ahead()[0] == pytest.approx((2.0, 0.0))


# -- on a map: cells the planner once marked blocked clear the same way --------------------------------------------
def test_cells_marked_blocked_on_a_map_are_cleared_when_a_beam_passes_through_them():
    from beastbt.behaviours.map_navigation import MapPlanner
    grid = empty_map(12.0, 6.0, 0.05, -1.0, -3.0, fill=FREE)
    planner = MapPlanner(grid)
    # What stopped the robot, marked as the blocked replan does: a box across the way at x = 4.
    ys = np.linspace(-3.0, 3.0, 200)
    planner.layer.mark_points(np.full(200, 4.0), ys)
    with pytest.raises(NoPath):
        planner.plan((0.0, 0.0), (8.0, 0.0), 0.1, "far")
    assert planner.costmap.lethal.sum() > 0
    # It was taken away: the next scan's beams pass where it stood and reach the end of the room.
    pose = (0.0, 0.0, 0.0)
    planner.layer.update(pose, ANGLES, ranges_to([(10.9, -3.0, 10.9, 3.0)], pose))
    path = planner.plan((0.0, 0.0), (8.0, 0.0), 0.1, "far")
    assert path.length_m == pytest.approx(8.0, abs=0.2)


# -- on the simulator: a place inside a closed pen ends the step, naming why ------------------------------------
def test_go_to_a_place_inside_a_closed_pen_ends_naming_why_instead_of_exploring_for_ever(tmp_path):
    # A closed pen 6 m x 6 m round the place (3 m from its walls, more than the GPS's error). The LiDAR cannot see
    # the far side from outside, and unseen cells are free: the planner leads round one side, then the other, each
    # time a wall appears on the way. Progress along those ways does not count for ever: once the place has come
    # no closer for 3 x 20 s the step gives up (or, when every wall has been seen, no way is left).
    from nav_support import events_of, harness, place_yaml
    box = [[-3.0, 6.0, 3.0, 6.0], [3.0, 6.0, 3.0, 12.0], [3.0, 12.0, -3.0, 12.0], [-3.0, 12.0, -3.0, 6.0]]
    h = harness(tmp_path, f"""
mission: t
places:
  inside: {place_yaml(0.0, 9.0, tolerance="0.5 m")}
steps:
  - go_to: {{place: inside, recovery: none}}
""", walls=box)
    h.run_to_end(timeout_s=300)
    assert h.result == "failure"
    failed = events_of(h, "step_failed")
    assert len(failed) == 1
    text = failed[0].text
    # Never "stuck" beside the pen: not held at one of its outer corners by the collision monitor (its stop zone
    # refused the local planner's slow turning arc there at every scan: the monitor now lets the turn through), nor
    # "no progress" driving on round it (ways replaced by new marks 4 times a second each showed less progress than
    # progress_m: what was gone along one now counts on the next).
    assert (("no way to inside" in text and "walls enclose it" in text)
            or "no closer to inside for 60 s on ways round" in text), text
    assert h.summary()["truth"]["collisions"] == 0
    # Its walls' corners are not people: no step aside for one (a phantom person once led the robot into a corner).
    assert events_of(h, "step_aside") == []
