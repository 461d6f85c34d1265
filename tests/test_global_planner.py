"""The global planner on the office map: optimal against SciPy's Dijkstra, clear of walls, through door middles,
unknown cells lethal, and every unreachable goal refused at once with its reason."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from beastbt.mapping.occupancy_map import FREE, OCCUPIED, UNKNOWN, empty_map, load_map
from beastbt.mapping.rasterise import mark_outlines
from beastbt.navigation.global_planner import (GlobalCostmap, GlobalPlannerConfig, NoPath, plan_path,
                                               path_length_m)
from tests.map_support import OFFICE_MAP, office_to_map, office_truth_map

FOOTPRINT_M = 0.15
CONFIG = GlobalPlannerConfig()


@pytest.fixture(scope="module")
def office() -> GlobalCostmap:
    return GlobalCostmap(office_truth_map(), CONFIG, FOOTPRINT_M)


def reference_cost(costmap: GlobalCostmap, start_rc: tuple[int, int], goal_rc: tuple[int, int]) -> float:
    """Plain Dijkstra (no heuristic) on the planner's own step costs: the optimum (cells)."""
    g = costmap.graph()
    matrix = csr_matrix((g.weights.ravel(), g.indices, g.indptr), shape=(g.n, g.n))
    dist = dijkstra(matrix, directed=True, indices=g.node(*start_rc))
    return float(dist[g.node(*goal_rc)])


def path_cost(costmap: GlobalCostmap, points: np.ndarray) -> float:
    """The step costs (cells) along an 8-connected path of cell centres."""
    g = costmap.graph()
    col, row = costmap.grid.to_cells(points[:, 0], points[:, 1])
    total = 0.0
    for (r0, c0), (r1, c1) in zip(zip(row, col), zip(row[1:], col[1:])):
        u, v = g.node(int(r0), int(c0)), g.node(int(r1), int(c1))
        k = list(g.indices[8 * u:8 * u + 8]).index(v)
        total += g.weights[u, k]
    return total


def test_the_committed_office_map_is_the_worlds_truth_map():
    saved = load_map(OFFICE_MAP)
    truth = office_truth_map()
    assert (saved.origin_x, saved.origin_y, saved.resolution_m) == (truth.origin_x, truth.origin_y, 0.05)
    assert np.array_equal(saved.occupied(), truth.occupied()) and np.array_equal(saved.unknown(), truth.unknown())


@pytest.mark.parametrize("goal_world", [(5.5, 7.0), (7.5, 2.5), (12.0, 1.0), (11.0, 8.5)])
def test_a_star_is_within_a_few_percent_of_the_optimum(office, goal_world):
    start = (0.0, 0.0)
    goal = office_to_map(*goal_world)
    path = plan_path(office, start, goal, smooth=False)
    col, row = office.grid.to_cells([start[0], goal[0]], [start[1], goal[1]])
    best = reference_cost(office, (int(row[0]), int(col[0])), (int(row[1]), int(col[1])))
    cells = np.column_stack(office.grid.cell_centres(*office.grid.to_cells(path.points[:, 0], path.points[:, 1])))
    got = path_cost(office, cells)
    assert np.isfinite(best)
    assert best - 1e-6 <= got <= best * 1.03, (got, best)


def test_the_path_keeps_clear_of_walls_and_goes_through_the_middle_of_doors(office):
    start, goal = (0.0, 0.0), office_to_map(5.5, 7.0)  # office -> corridor -> kitchen
    path = plan_path(office, start, goal)
    dense = np.concatenate([np.linspace(a, b, 20) for a, b in zip(path.points[:-1], path.points[1:])])
    col, row = office.grid.to_cells(dense[:, 0], dense[:, 1])
    clearance = office.distance_m[row, col]
    assert clearance.min() > office.inscribed_m  # never in the inscribed zone
    # the office door spans world x 2.0-3.0 at y 4.0; where the path crosses that wall it is near the door's middle
    door_y = office_to_map(0.0, 4.0)[1]
    i = int(np.argmin(np.abs(dense[:, 1] - door_y)))
    assert abs(dense[i, 0] - office_to_map(2.5, 4.0)[0]) < 0.12
    # the shortened path is shorter than the 8-connected one, and neither is absurdly long
    raw = plan_path(office, start, goal, smooth=False)
    assert path.length_m < raw.length_m
    assert path.length_m < 1.3 * np.hypot(goal[0], goal[1]) + 2.0


def test_cost_weight_zero_takes_the_shortest_way():
    grid = office_truth_map()
    near = GlobalCostmap(grid, GlobalPlannerConfig(cost_weight=0.0), FOOTPRINT_M)
    far = GlobalCostmap(grid, CONFIG, FOOTPRINT_M)
    goal = office_to_map(12.0, 1.0)
    short, careful = plan_path(near, (0.0, 0.0), goal), plan_path(far, (0.0, 0.0), goal)
    assert short.length_m <= careful.length_m + 1e-6
    dense = lambda p: np.concatenate([np.linspace(a, b, 20) for a, b in zip(p.points[:-1], p.points[1:])])  # noqa: E731
    clear = lambda cm, p: np.percentile(cm.distance_m[tuple(cm.grid.to_cells(*dense(p).T)[::-1])], 10)  # noqa: E731
    assert clear(far, careful) > clear(near, short)


def corridor_map(fill_gap: int):
    """A 6 m x 3 m room split by a wall at x = 3 m with a 1 m gap filled with ``fill_gap``."""
    grid = empty_map(6.0, 3.0, 0.05, 0.0, 0.0, fill=FREE)
    grid = mark_outlines(grid, [(0, 0, 6, 0), (0, 3, 6, 3), (0, 0, 0, 3), (6, 0, 6, 3), (3, 0, 3, 1), (3, 2, 3, 3)])
    data = grid.data.copy()
    data[20:40, 50:70] = fill_gap  # x 2.5-3.5, y 1-2: the gap and round it
    return grid.with_data(data)


def test_unknown_cells_are_lethal_unless_allowed():
    grid = corridor_map(UNKNOWN)
    with pytest.raises(NoPath) as err:
        plan_path(GlobalCostmap(grid, CONFIG, FOOTPRINT_M), (1.0, 1.5), (5.0, 1.5), goal_name="b")
    assert "cannot be reached" in err.value.reason and err.value.reason.startswith("b ")
    path = plan_path(GlobalCostmap(grid, GlobalPlannerConfig(allow_unknown=True), FOOTPRINT_M), (1.0, 1.5),
                     (5.0, 1.5))
    assert path.points[-1][0] == pytest.approx(5.0)


def test_unreachable_goals_fail_at_once_with_the_reason(office):
    start = (0.0, 0.0)
    cases = {
        (50.0, 0.0): "off the map",
        office_to_map(5.0, 2.0): "occupied cell",   # on the office | lab wall
        office_to_map(13.5, 2.0): "occupied cell",  # inside the store's shelves
        office_to_map(5.08, 2.0): "from a wall",    # in the lab, 8 cm from the wall: too near for the robot
        (office.grid.origin_x + 0.1, office.grid.origin_y + 0.1): "unknown cell",
    }
    for goal, why in cases.items():
        with pytest.raises(NoPath) as err:
            plan_path(office, start, goal, goal_name="lab")
        assert why in err.value.reason, (goal, err.value.reason)
    # a tolerance lets a goal near a wall move to the nearest cell the robot fits
    assert plan_path(office, start, office_to_map(5.08, 2.0), tolerance_m=0.3).length_m > 2.0


def test_an_enclosed_goal_is_refused_without_a_search():
    grid = corridor_map(OCCUPIED)
    costmap = GlobalCostmap(grid, CONFIG, FOOTPRINT_M)
    with pytest.raises(NoPath) as err:
        plan_path(costmap, (1.0, 1.5), (5.0, 1.5), goal_name="store")
    assert "store (5.00, 1.50) m cannot be reached from here: walls enclose it" in err.value.reason
    assert costmap._graph is None  # the components answered: no graph was even built


def test_a_gap_open_only_corner_to_corner_is_refused_at_once_naming_why():
    """A wall two cells thick with a hole through it only corner to corner (as marks of a box in a door can leave):
    the search never cuts a corner, so the goal beyond is refused at once by the components, named, as any
    enclosed goal, not after a search that finds "no way"."""
    grid = empty_map(2.0, 1.0, 0.05, 0.0, 0.0, fill=FREE)
    data = grid.data.copy()
    data[:, 20:22] = OCCUPIED  # a wall at x 1.0-1.1 m
    data[9, 20] = data[10, 21] = FREE  # its only hole: two free cells that touch at a corner
    costmap = GlobalCostmap(grid.with_data(data), GlobalPlannerConfig(footprint_padding_m=0.0), 0.0)
    with pytest.raises(NoPath) as err:
        plan_path(costmap, (0.5, 0.5), (1.5, 0.5), goal_name="b")
    assert "b (1.50, 0.50) m cannot be reached from here: walls enclose it" in err.value.reason
    assert costmap._graph is None  # the components answered, as the search would have: no graph was built
    data[9, 21] = FREE  # a straight step through the hole: passable
    assert plan_path(GlobalCostmap(grid.with_data(data), GlobalPlannerConfig(footprint_padding_m=0.0), 0.0),
                     (0.5, 0.5), (1.5, 0.5)).length_m > 0.9


def test_new_lethal_cells_close_a_door_and_the_path_goes_another_way(office):
    start, goal = (0.0, 0.0), office_to_map(12.0, 1.0)  # office -> corridor -> store
    before = plan_path(office, start, goal)
    costmap = GlobalCostmap(office.grid, CONFIG, FOOTPRINT_M)
    xs = np.linspace(*(office_to_map(11.5, 4.0)[0], office_to_map(12.5, 4.0)[0]), 30)
    assert costmap.mark_lethal(xs, np.full(30, office_to_map(0, 4.0)[1])) > 0  # the store's door is shut
    with pytest.raises(NoPath) as err:
        plan_path(costmap, start, goal)
    assert "cannot be reached" in err.value.reason
    assert before.length_m > 10.0
    assert path_length_m(before.points) == pytest.approx(before.length_m)
