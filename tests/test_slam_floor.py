"""SLAM among people: transient returns (people walking, people standing a while and leaving) do not become walls.

``missions/floor_people_tour.yaml`` drives ``worlds/floor_people.yaml`` (five rooms off a corridor, fifteen
people: walking in the rooms and along the corridor, six standing for 20-30 s, four of them inside the doors, then
walking off) with ``--build-map``, on seeds 1-5, and the map is judged against the world by
``tests/slam_judge.py``: at least 90 % of the wall cells seen are marked, at most 5 % of the occupied cells are
ghosts (more than 10 cm from any wall or fixed obstacle), and the robot touched nothing. Before the map cleared
along later beams strongly enough (hit +0.9, crossing -0.25, clamp +-5) the ghosts were 4.7-5.2 %.

The rendering rules themselves are checked on hand-made keyframes: a cell hit once and seen through once
later is not occupied; a cell a standing person saturated clears after six looks through it; a wall hit
again and again survives a beam crossing it; a dropout marks and clears nothing.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from beastbt.mapping.slam import Keyframe, MappingConfig, OnlineMapper, render_map
from slam_judge import FLOOR_TOUR, judged_world, run_and_judge

ORIGIN = (0.0, 0.0, 0.0)


def keyframe(*points: tuple[float, float]) -> Keyframe:
    """A keyframe at the map's origin whose scan has returns at ``points`` (base_link, m)."""
    return Keyframe(0.0, np.array(points, dtype=float), (0.0, 0.0), ORIGIN, 0.0, np.empty((0, 2)))


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_a_map_built_among_people_marks_the_walls_and_no_people(seed: int, tmp_path: Path) -> None:
    summary, j = run_and_judge(FLOOR_TOUR, seed, tmp_path)
    assert summary["status"] == "success" and summary["truth"]["collisions"] == 0
    assert j.seen > 800  # the corridor and, through their doors, the five rooms
    assert j.marked >= 0.90, f"seed {seed}: {j.marked:.1%} of the {j.seen} wall cells seen are marked"
    assert j.ghosts <= 0.05, f"seed {seed}: {j.ghosts:.1%} of the {j.occupied} occupied cells are ghosts"


def test_a_cell_hit_once_and_seen_through_once_later_is_not_occupied() -> None:
    # A person 1 m ahead in one scan; in the next it has gone and the beam reaches the wall 2 m ahead.
    grid = render_map([keyframe((1.0, 0.0)), keyframe((2.0, 0.0))], [ORIGIN] * 2, 0.05, MappingConfig())
    assert grid.value_at(2.0, 0.0) >= 65  # the wall, seen once: occupied
    assert grid.value_at(1.0, 0.0) < 65  # where the person was: not occupied (the seen-through clears it)


def test_a_cell_a_standing_person_saturated_clears_after_six_looks_through_it() -> None:
    config = MappingConfig()
    stood = [keyframe((1.0, 0.0))] * 20  # a person standing 1 m ahead for twenty keyframes
    gone = [keyframe((2.0, 0.0))] * 6  # then gone: six scans see through to the wall
    grid = render_map(stood + gone, [ORIGIN] * 26, 0.05, config)
    assert grid.value_at(1.0, 0.0) < 65
    assert grid.value_at(2.0, 0.0) >= 65


def test_a_wall_hit_again_and_again_survives_a_beam_crossing_it() -> None:
    # Three scans end on the wall cell, then one beam (noise, a grazing angle) crosses it to a return beyond.
    grid = render_map([keyframe((2.0, 0.0))] * 3 + [keyframe((3.0, 0.0))], [ORIGIN] * 4, 0.05, MappingConfig())
    assert grid.value_at(2.0, 0.0) >= 65


def test_dropouts_and_ranges_beyond_the_lidar_mark_and_clear_nothing() -> None:
    # A room of radius 2 m seen from its centre, standing still: a quarter of the beams without a return (NaN,
    # or 0 as a driver may report it) and a quarter beyond the range (a reflection, 15 m).
    mapper = OnlineMapper()
    mapper.add_odom(0.0, 0.0, 0.0, 0.0)
    angles = np.radians(np.arange(0.0, 360.0, 1.0))
    ranges = np.full(angles.shape, 2.0)
    ranges[0:45] = np.nan
    ranges[45:90] = 0.0
    ranges[180:270] = 15.0
    assert mapper.add_scan(0.1, angles, ranges, 0.0)
    grid = mapper.occupancy_map()
    assert grid is not None
    rows, cols = np.nonzero(grid.occupied())
    x, y = grid.cell_centres(cols, rows)
    assert len(x) > 0 and np.all(np.abs(np.hypot(x, y) - 2.0) < 0.1)  # only the room's wall
    bearing = np.degrees(np.arctan2(y, x)) % 360.0
    assert not np.any((bearing > 2) & (bearing < 88)) and not np.any((bearing > 182) & (bearing < 268))
    # and nothing is cleared along them: the cell 1 m out in the dropped sectors is still unknown
    for deg in (20.0, 60.0, 225.0):
        assert grid.value_at(math.cos(math.radians(deg)), math.sin(math.radians(deg))) == -1


def test_the_judge_measures_a_map_against_the_world_it_was_built_in():
    """``python tests/slam_judge.py MISSION`` judged every map against the floor among people, whatever world the
    mission named (a clean map of another floor came out 14 % of its walls marked, 87 % ghosts)."""
    repo = Path(__file__).resolve().parent.parent
    assert judged_world(repo / "missions" / "office_tour.yaml").resolve() == (repo / "worlds" / "office.yaml").resolve()
    assert judged_world(repo / "missions" / "office_tour.yaml", Path("w.yaml")) == Path("w.yaml")
    assert judged_world(FLOOR_TOUR).resolve().name == "floor_people.yaml"
