"""What people see of the global costmap, the way round and the recoveries: ``/global_costmap`` and ``/plan`` in the
recording (and so in Foxglove live, which sends the same bytes), the shipped layout, the console's layer, and the
recoveries in ``beastbt report``.

The fence run (missions/fence_crossing.yaml on worlds/field_fence.yaml, seed 1, about 7 s) is recorded once, in
this process, so that what was recorded can be held against what the navigator held: each time the tick side
reads the obstacle layer for the view, the test notes the layer's marks, and each plan the navigator makes, its goal.
"""

from __future__ import annotations

import base64
import functools
import io
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from beastbt.assembly import prepare
from beastbt.blackboard.types import COST_INSCRIBED, COST_LETHAL
from beastbt.recording import global_views as gv
from beastbt.recording.foxglove_live import LATCHED
from beastbt.recording.layout import LAYOUT_FILE
from beastbt.recording.schemas import CHANNELS
from beastbt.run.session import RunOptions, execute
from conftest import REPO

OFFICIAL = Path("/work/shared/data/foxglove")
if not OFFICIAL.is_dir():
    OFFICIAL = REPO / "tests" / "data" / "foxglove"  # the same files, @foxglove/schemas 2.1.0


@functools.lru_cache(maxsize=None)
def check(name: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(json.loads((OFFICIAL / f"{name}.json").read_text(encoding="utf-8")))


def grid_costs(msg: dict) -> np.ndarray:
    cols = msg["column_count"]
    return np.frombuffer(base64.b64decode(msg["data"]), dtype=np.uint8).reshape(-1, cols)


@pytest.fixture(scope="module")
def fence_run(tmp_path_factory):
    """The fence crossing recorded: (summary, {topic: [(schema name, log time s from the first message, message)]},
    the marks the views read [(layer marks copy, origin x, origin y)], the plans made [(goal odom, path points)],
    the navigator)."""
    runs = tmp_path_factory.mktemp("runs")
    p = prepare(str(REPO / "missions" / "fence_crossing.yaml"), RunOptions(seed=1, runs_dir=str(runs)))
    nav = p.run.ctx.services.local_navigator.global_nav
    seen: list = []
    marks_of = gv.marks_of

    def noting_marks_of(source):
        layer = source[1]
        seen.append((layer.marked.copy(), layer.origin_x, layer.origin_y))
        return marks_of(source)

    plans: list = []
    plan = nav.plan

    def noting_plan(start, goal, tolerance_m, name):
        path = plan(start, goal, tolerance_m, name)
        plans.append((goal, path.points.copy()))
        return path

    replan = nav.replan

    def noting_replan(start, goal, tolerance_m, name, previous):
        path = replan(start, goal, tolerance_m, name, previous)
        plans.append((goal, path.points.copy()))  # a way mended on its side ends where the way it mends did
        return path

    nav.plan = noting_plan
    nav.replan = noting_replan
    gv.marks_of = noting_marks_of
    try:
        summary = execute(p, io.StringIO())
    finally:
        gv.marks_of = marks_of
    rows: dict[str, list] = {}
    with open(Path(p.folder.path) / "run.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            rows.setdefault(channel.topic, []).append((schema.name, message.log_time, json.loads(message.data)))
    return summary, rows, seen, plans, nav


def test_the_fence_run_records_the_global_costmap_and_the_plan_as_foxglove_s_own_schemas_say(fence_run):
    summary, rows, _, _, _ = fence_run
    assert summary["status"] == "success" and summary["truth"]["collisions"] == 0
    for topic, schema in (("/global_costmap", "Grid"), ("/plan", "SceneUpdate")):
        assert rows.get(topic), f"no messages on {topic}"
        assert CHANNELS[topic]["title"] == f"foxglove.{schema}"
        for name, _, msg in rows[topic]:
            assert name == f"foxglove.{schema}"
            assert not [e.message for e in check(schema).iter_errors(msg)], topic
    grids = [m for _, _, m in rows["/global_costmap"]]
    assert all(g["frame_id"] == "odom" and g["fields"] == [{"name": "cost", "offset": 0, "type": 1}] for g in grids)
    times = [t / 1e9 for _, t, _ in rows["/global_costmap"]]
    assert all(b - a >= gv.GLOBAL_COSTMAP_PERIOD_S - 1e-6 for a, b in zip(times, times[1:]))  # at most 1 Hz
    assert len(grids) <= summary["sim_time_s"] / gv.GLOBAL_COSTMAP_PERIOD_S + 1
    # Compact: the box round the fence (8 m) and its inflation, not the 40 m window's 160,000 cells.
    assert max(len(base64.b64decode(g["data"])) for g in grids) < 20_000
    assert {"/global_costmap", "/plan"} <= set(LATCHED)  # sent on change only: a late live client gets them again


def test_the_recorded_grid_holds_the_marks_the_navigator_had_with_the_planners_costs(fence_run):
    _, rows, seen, _, nav = fence_run
    grids = [m for _, _, m in rows["/global_costmap"]]
    sent = [s for s in seen if s[0].any()]
    assert len(sent) >= len(grids) >= 10
    matched = 0
    for marked, ox, oy in seen:
        for g in grids:
            costs = grid_costs(g)
            res = g["cell_size"]["x"]
            c0 = int(round((g["pose"]["position"]["x"] - ox) / res))
            r0 = int(round((g["pose"]["position"]["y"] - oy) / res))
            lethal = np.zeros_like(marked)
            rr, cc = np.nonzero(costs == COST_LETHAL)
            lethal[rr + r0, cc + c0] = True
            if np.array_equal(lethal, marked):  # every marked cell lethal in the grid, and nothing else
                matched += 1
                break
    assert matched >= len(grids)  # each grid recorded is the layer as the navigator had it at some sample
    # The costs round the marks are the planner's own: the last grid against the navigator's costmap of those marks.
    last = grids[-1]
    marked, ox, oy = next(s for s in reversed(seen) if s[0].any())
    nav.layer.marked = marked
    nav.layer.version += 1
    planner_cost = nav.costmap().cost
    costs = grid_costs(last)
    res = last["cell_size"]["x"]
    c0 = int(round((last["pose"]["position"]["x"] - ox) / res))
    r0 = int(round((last["pose"]["position"]["y"] - oy) / res))
    box = planner_cost[r0:r0 + costs.shape[0], c0:c0 + costs.shape[1]]
    assert np.array_equal(box, costs)
    assert (costs == COST_INSCRIBED).any() and ((costs > 0) & (costs < COST_INSCRIBED)).any()  # inflated round them
    outside = planner_cost.copy()
    outside[r0:r0 + costs.shape[0], c0:c0 + costs.shape[1]] = 0
    assert not outside.any()  # every cell outside the box is free


def test_the_marks_lie_on_the_fence(fence_run):
    _, rows, _, _, _ = fence_run
    g = rows["/global_costmap"][-1][2]
    costs = grid_costs(g)
    res = g["cell_size"]["x"]
    rr, cc = np.nonzero(costs == COST_LETHAL)
    # odom starts at the world's start facing north: odom x is north (world y), odom y is west (-world x).
    x = g["pose"]["position"]["x"] + (cc + 0.5) * res
    y = g["pose"]["position"]["y"] + (rr + 0.5) * res
    assert len(x) >= 60  # most of the 8 m fence's 80 cells
    on_fence = (np.abs(x - 8.0) < 0.4) & (np.abs(y) <= 4.2)
    assert on_fence.mean() > 0.9


def test_each_plan_recorded_is_a_way_the_navigator_planned_and_ends_on_its_goal(fence_run):
    _, rows, _, plans, _ = fence_run
    updates = [m for _, _, m in rows["/plan"]]
    drawn = [m["entities"][0] for m in updates if m["entities"]]
    assert drawn and plans
    for e in drawn:
        assert e["frame_id"] == "odom"
        pts = np.array([[p["x"], p["y"]] for p in e["lines"][0]["points"]])
        match = [(goal, path) for goal, path in plans if path.shape == pts.shape and np.allclose(path, pts)]
        assert match, "a recorded plan the navigator never made"
        goal, _ = match[0]
        assert pts[-1] == pytest.approx(goal, abs=1e-9)  # the plan's last pose is the goal
        assert {"key": "goal", "value": "far_side"} in e["metadata"]
    # The ways go round the fence's west end (4 m off the straight line), farther out as more of the fence is seen;
    # the last one past the end by more than the robot's inscribed radius, not through the gap.
    ends = [max(p["y"] for p in e["lines"][0]["points"]) for e in drawn]
    assert ends[-1] > 4.0 + 0.15 and ends[-1] > ends[0]
    # Once past the fence the straight line is clear again: the way round is taken off.
    assert updates[-1]["deletions"] and not updates[-1]["entities"]


def test_the_shipped_layout_shows_the_global_costmap_and_the_plan():
    topics = json.loads(LAYOUT_FILE.read_text(encoding="utf-8"))["configById"]["3D!beastbt"]["topics"]
    assert topics["/global_costmap"]["visible"] and topics["/global_costmap"]["colorField"] == "cost"
    assert topics["/plan"]["visible"]


def test_the_console_draws_the_marks_as_a_placed_image_and_the_way_round():
    """The console's state carries the marks (a PNG placed on the plan) and the way round as its path."""
    import cv2

    from beastbt.live.console_state import MapFrame, obstacle_layers
    from beastbt.navigation.global_navigator import PathFollow
    from beastbt.recording.obstacle_views import board_reader
    from beastbt.testing import MissionHarness
    h = MissionHarness.from_file(REPO / "missions" / "fence_crossing.yaml", seed=1)
    h.tick()
    run = h.run
    nav = run.ctx.services.local_navigator.global_nav
    nav.layer.mark_points(np.array([2.0, 2.15, 2.0]), np.array([1.0, 1.0, -0.5]))  # cells of 0.1 m
    nav.following = PathFollow(np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 0.0]]))
    frame = MapFrame(run, h.prepared.world)
    pose = frame.pose()
    out = obstacle_layers(run, frame, board_reader(), run.clock.now(), pose, gv.ConsoleGlobalLayer())
    layer = out["global_costmap"]
    png = base64.b64decode(layer["png"].split(",", 1)[1])
    image = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image.shape[:2] == (16, 2)  # rows -0.5 .. 1.0 m, columns 2.0 .. 2.15 m: the marks' box
    assert (image[:, :, 3] > 0).sum() == 3
    assert layer["width_m"] == pytest.approx(0.2) and layer["height_m"] == pytest.approx(1.6)
    assert len(out["path"]) == 3
    # odom and the plan: the robot's pose in both
    odo = run.odom
    yaw = pose[2] - odo.yaw
    ex = pose[0] + math.cos(yaw) * (3.0 - odo.x) - math.sin(yaw) * (0.0 - odo.y)
    assert out["path"][-1][0] == pytest.approx(ex, abs=0.02)
    none = obstacle_layers(run, frame, board_reader(), run.clock.now(), pose)
    assert none["global_costmap"] is None  # without the layer cache the state stays as before


def test_the_report_counts_the_recoveries_and_marks_them_on_the_path(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from beastbt.recording.report import RunData, draw_path, summary_text
    from nav_support import place_yaml, robot_without_global_costmap, write_world
    from recording_support import record_run
    world = write_world(tmp_path, walls=[[-10.0, 4.0, 10.0, 4.0]])
    mission = tmp_path / "wall.yaml"
    mission.write_text(f"""mission: wall
places:
  a: {place_yaml(0.0, 7.0)}
steps:
  - go_to: {{place: a, blocked_after: 4 s, recovery: {{tries: 2}}}}
""", encoding="utf-8")
    folder, summary = record_run(mission, tmp_path / "runs", world=world, robot=robot_without_global_costmap(tmp_path),
                                 max_time_s=120.0, simulate=True)
    assert summary["recoveries"] == {"count": 2, "kinds": {"clear": 1, "back_up": 1}}
    d = RunData.load(str(folder))
    found = d.recoveries()
    assert len(found) == 2 and "recovery 1 of 2: clearing the costmaps" in found[0][1]
    for _, _, (x, y) in found:
        assert abs(x) < 1.0 and 2.5 < y < 4.0  # in front of the wall, where the robot was held
    text = summary_text(d)
    assert "  recoveries: 2 (clear 1, back_up 1)" in text and "recovery 2 of 2: backing up" in text
    fig, ax = plt.subplots()
    labels = draw_path(d, ax)
    plt.close(fig)
    assert "recovery (2)" in labels
