"""What people see of obstacles in Foxglove: /costmap, /local_plan, /collision_monitor/zones, /sim/persons and
/sim/contact.

The local planner is another part's work: here a hand-made planner (a tick
hook) writes a :class:`LocalCostmap` and a :class:`LocalPlan` on the
blackboard for a while and then stops, as a go_to step would; the views must
show them while they are fresh and take them off after. Every message of the
new channels validates against Foxglove's own schema (``tests/data/foxglove``).
"""

from __future__ import annotations

import base64
import functools
import io
import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from beastbt.assembly import prepare
from beastbt.blackboard import catalogue
from beastbt.blackboard.types import COST_LETHAL, LocalCostmap, LocalPlan
from beastbt.recording import obstacle_views as ov
from beastbt.recording.foxglove_live import LATCHED
from beastbt.recording.schemas import CHANNELS
from beastbt.run.session import RunOptions, execute
from conftest import REPO
from recording_support import rude_person_world

OFFICIAL = REPO / "tests" / "data" / "foxglove"
PERSON_WORLD = REPO / "worlds" / "corridor_person.yaml"
WAIT_MISSION = "mission: stand\nsteps:\n  - wait: 16 s\n"
"""The robot stands; the person (from 5 s, 0.8 m/s, from x 9.5 m) walks into it at about 15 s."""
PLAN_UNTIL_S = 6.0
"""The hand-made planner writes until this simulated time, then stops (its values go stale)."""


@functools.lru_cache(maxsize=None)
def check(name: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(json.loads((OFFICIAL / f"{name}.json").read_text(encoding="utf-8")))


def errors(name: str, message: dict) -> list[str]:
    return [e.message for e in check(name).iter_errors(message)]


def a_costmap(stamp_s: float, rows: int = 20, cols: int = 30) -> LocalCostmap:
    cost = np.zeros((rows, cols), dtype=np.uint8)
    cost[2, 5] = COST_LETHAL  # one obstacle cell: row 2 (south), column 5
    cost[rows - 1, :] = 100
    return LocalCostmap(stamp_s, -1.5, -1.0, 0.1, cost)


def test_the_costmap_is_a_uint8_grid_whose_rows_go_north_from_its_origin():
    cm = a_costmap(1.0)
    msg = ov.costmap_grid(5_000_000_000, "odom", cm)
    assert not errors("Grid", msg)
    assert msg["frame_id"] == "odom" and msg["column_count"] == 30 and msg["row_stride"] == 30
    assert msg["cell_size"] == {"x": 0.1, "y": 0.1} and msg["fields"] == [{"name": "cost", "offset": 0, "type": 1}]
    assert msg["pose"]["position"] == {"x": -1.5, "y": -1.0, "z": 0.0}
    data = np.frombuffer(base64.b64decode(msg["data"]), dtype=np.uint8).reshape(-1, msg["row_stride"])
    assert data.shape == (20, 30) and data[2, 5] == COST_LETHAL and data[0, 5] == 0 and (data[19] == 100).all()
    empty = ov.costmap_grid(6_000_000_000, "odom", None)
    assert not errors("Grid", empty) and empty["column_count"] == 0 and empty["data"] == ""
    # Foxglove's 3D panel counts rows as len(data) / row_stride and refuses a grid where that is not a whole number.
    assert empty["row_stride"] > 0 and len(base64.b64decode(empty["data"])) % empty["row_stride"] == 0
    assert len(data.tobytes()) % msg["row_stride"] == 0


def test_the_plan_is_a_line_in_odom_red_when_blocked_and_goes_away_when_absent():
    plan = LocalPlan(1.0, np.array([[0.0, 0.0], [0.5, 0.1], [1.0, 0.3]]), 0.3, 0.2, blocked=False)
    msg = ov.plan_update(1_000, "odom", plan)
    assert not errors("SceneUpdate", msg)
    (entity,) = msg["entities"]
    assert entity["frame_id"] == "odom" and [(p["x"], p["y"]) for p in entity["lines"][0]["points"]] == \
        [(0.0, 0.0), (0.5, 0.1), (1.0, 0.3)]
    blocked = ov.plan_update(1_000, "odom", LocalPlan(1.0, plan.points_xy, blocked=True))
    assert blocked["entities"][0]["lines"][0]["color"]["r"] > entity["lines"][0]["color"]["r"]
    gone = ov.plan_update(2_000, "odom", None)
    assert not errors("SceneUpdate", gone) and gone["entities"] == [] and gone["deletions"][0]["id"] == ov.PLAN_ID


def test_the_zones_ride_on_base_link_and_the_acting_one_is_drawn_bold():
    zones = {"stop": [[0.3, 0.2], [-0.3, 0.2], [-0.3, -0.2], [0.3, -0.2]],
             "slow": [[0.6, 0.25], [-0.3, 0.25], [-0.3, -0.25], [0.6, -0.25]]}
    quiet = ov.zones_update(1_000, "base_link", {"zones": zones, "action": "none"})
    stop = ov.zones_update(1_000, "base_link", {"zones": zones, "action": "stop", "reason": "5 points"})
    for msg in (quiet, stop):
        assert not errors("SceneUpdate", msg)
        (entity,) = msg["entities"]
        assert entity["frame_id"] == "base_link" and entity["frame_locked"]
    slow_q, stop_q = quiet["entities"][0]["lines"]
    slow_s, stop_s = stop["entities"][0]["lines"]
    assert [(p["x"], p["y"]) for p in stop_q["points"]] == [tuple(c) for c in zones["stop"]] and stop_q["type"] == 1
    assert stop_s["thickness"] > stop_q["thickness"] and stop_s["color"]["a"] > stop_q["color"]["a"]
    assert slow_s["thickness"] == slow_q["thickness"]  # only the acting zone changes
    assert stop["entities"][0]["texts"][0]["text"] == "collision monitor: stop" and not quiet["entities"][0]["texts"]




@pytest.fixture(scope="module")
def person_run(tmp_path_factory):
    """16 s standing in the corridor with the pacing person, a hand-made planner writing until 6 s; the messages."""
    p = prepare(str(tmp_path_factory.mktemp("m") / "m.yaml"),
                RunOptions(seed=1, runs_dir=str(tmp_path_factory.mktemp("runs")),
                           world=rude_person_world(tmp_path_factory.mktemp("world"))),
                mission_text=WAIT_MISSION)
    board = catalogue.writer("fake_planner", ("costmap", "local_plan"))
    made: list[LocalCostmap] = []

    def fake_planner(run, now_s: float) -> None:
        if now_s > PLAN_UNTIL_S:
            return
        if not made or now_s - made[-1].stamp_s >= 0.1 - 1e-9:  # a new costmap each scan (10 Hz)
            made.append(a_costmap(now_s))
            board.costmap = made[-1]
        board.local_plan = LocalPlan(now_s, np.array([[0.0, 0.0], [0.4, 0.05 * now_s], [0.8, 0.1 * now_s]]), 0.2)

    p.run.hooks.append(fake_planner)
    summary = execute(p, io.StringIO())
    rows: dict[str, list] = {}
    with open(Path(p.folder.path) / "run.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            rows.setdefault(channel.topic, []).append((schema.name, message.log_time, json.loads(message.data)))
    return summary, rows, made


def test_every_new_channel_validates_against_foxglove_s_schemas_and_is_declared(person_run):
    _, rows, _ = person_run
    for topic in ("/costmap", "/local_plan", "/collision_monitor/zones", "/sim/persons"):
        assert rows.get(topic), f"no messages on {topic}"
        for name, _, msg in rows[topic]:
            assert name == CHANNELS[topic]["title"]
            assert not errors(name.removeprefix("foxglove."), msg), topic
    for _, _, msg in rows["/sim/contact"]:
        jsonschema.Draft202012Validator(CHANNELS["/sim/contact"]).validate(msg)
    assert "/collision_monitor/zones" in LATCHED  # sent on change only: a late live client gets it again


def test_the_costmap_is_recorded_at_2_hz_while_fresh_then_taken_off(person_run):
    _, rows, made = person_run
    grids = rows["/costmap"]
    times = [t / 1e9 for _, t, _ in grids]
    assert len(made) > 50  # the planner made one each 0.1 s
    assert all(b - a >= ov.COSTMAP_PERIOD_S - 1e-6 for a, b in zip(times, times[1:-1]))
    assert len(grids) - 1 <= PLAN_UNTIL_S / ov.COSTMAP_PERIOD_S + 1  # about a fifth of what was made
    assert all(m["column_count"] == 30 for _, _, m in grids[:-1])
    last = grids[-1][2]
    assert last["column_count"] == 0  # the planner stopped: the view is cleared once, not resent
    assert times[-1] - times[-2] > ov.STALE_S - 0.2


def test_the_plan_follows_the_planner_then_is_deleted(person_run):
    _, rows, _ = person_run
    updates = [m for _, _, m in rows["/local_plan"]]
    drawn = [m["entities"][0] for m in updates if m["entities"]]
    assert len(drawn) >= 10 and all(e["frame_id"] == "odom" for e in drawn)
    ends = [e["lines"][0]["points"][-1]["y"] for e in drawn]
    assert ends == sorted(ends) and ends[-1] > ends[0]  # the hand-made plan bends more as time goes on
    assert updates[-1]["deletions"] and not updates[-1]["entities"]


def test_the_person_is_drawn_where_it_walks_and_contact_truth_is_sampled(person_run):
    summary, rows, _ = person_run
    xs = [m["entities"][0]["cylinders"][0]["pose"]["position"]["x"] for _, _, m in rows["/sim/persons"]]
    assert xs[0] > xs[-1] + 3.0  # walks west from the east end (5 s on at 0.8 m/s)
    contact = [m for _, _, m in rows["/sim/contact"]]
    assert contact[0]["persons"][0][:2] == [9.5, 0.3]
    gaps = [c["clearance_m"] for c in contact]
    assert min(gaps) == pytest.approx(summary["truth"]["min_clearance_m"], abs=0.05)
    assert gaps[0] > min(gaps) + 0.5  # it shrinks as the person comes closer
    assert contact[-1]["collisions"] == summary["truth"]["collisions"] >= 1  # the person walks into the robot
    hit = next(c for c in contact if c["collisions"])
    assert hit["in_contact"] and hit["clearance_m"] < 1e-3  # sampled at the contact itself, not up to 0.2 s later
    zones = [m["entities"][0] for _, _, m in rows["/collision_monitor/zones"]]
    assert zones[0]["frame_id"] == "base_link" and len(zones[0]["lines"]) == 2



def test_a_standing_person_is_redrawn_with_the_scene_when_map_is_anchored_on_earth(tmp_path):
    from beastbt.blackboard.types import FusedPose, VelocityCommand
    from beastbt.mission.model import load_mission
    from beastbt.recording.config import RecordingConfig
    from beastbt.recording.scene import scene_description
    from beastbt.recording.writer import RunFileWriter
    from beastbt.sim.world import load_world
    world = load_world(REPO / "worlds" / "campus_obstacles.yaml")  # its first bench stands at (0.3, 6.0)
    description = scene_description(load_mission(REPO / "missions" / "gps_route.yaml"), world, 0.15)
    writer = RunFileWriter([tmp_path / "w.mcap"], RecordingConfig(), {"mission": "w"}, [])
    writer.write(("scene", 0.0, description))
    # A person standing 2 m east of the bench (sampled once: it does not move, so it is not sent again).
    writer.write(("views", 0.1, {"contact": {"t_s": 0.1, "clearance_m": 1.0, "collisions": 0, "in_contact": False,
                                             "persons": [[2.3, 6.0, 0.25]], "moved": True}}))
    # The EKF anchors map 3 m east of the datum: the robot at map (0, 0) is at world (3, 0).
    lat, lon, _ = world.frame.to_geodetic(3.0, 0.0, 0.0)
    pose = FusedPose(0.2, 0.0, 0.0, 0.0, lat=lat, lon=lon)
    stop = VelocityCommand()
    writer.write(("tick", 1, 0.2, [], pose, pose, None, stop, stop, "mission", [], None, (False, ())))
    writer.finish()
    assert writer.error is None
    scenes, persons = [], []
    with open(tmp_path / "w.mcap", "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic == "/scene":
                scenes.append(json.loads(message.data))
            elif channel.topic == "/sim/persons":
                persons.append(json.loads(message.data))
    assert len(scenes) == 2 and len(persons) == 2  # drawn at the start, and again when the EKF anchored map

    def bench(scene: dict) -> tuple[float, float]:
        (obstacles,) = [e for e in scene["entities"] if e["id"] == "obstacles"]
        p = obstacles["cubes"][0]["pose"]["position"]
        return p["x"], p["y"]

    def person(update: dict) -> tuple[float, float]:
        p = update["entities"][0]["cylinders"][0]["pose"]["position"]
        return p["x"], p["y"]

    for scene, update in zip(scenes, persons):
        (bx, by), (px, py) = bench(scene), person(update)
        assert (px - bx, py - by) == pytest.approx((2.0, 0.0), abs=0.01)  # where the world has it, beside the bench
    assert bench(scenes[1]) == pytest.approx((0.3 - 3.0, 6.0), abs=0.05)  # map moved 3 m east


def test_a_route_round_the_campus_benches_records_the_planners_costmap_and_plan_as_foxglove_says(tmp_path):
    """The real local planner (not a hand-made one): its /costmap and /local_plan are recorded while it goes
    round the bench across the way to a, and each message is what Foxglove's own schemas describe."""
    from beastbt.recording.reader import read_recording
    from recording_support import GPS_ROUTE, record_run
    folder, summary = record_run(GPS_ROUTE, tmp_path / "runs", seed=1, max_time_s=45.0,
                                 world=str(REPO / "worlds" / "campus_obstacles.yaml"))
    assert summary["truth"]["collisions"] == 0
    rec = read_recording(folder / "run.mcap", topics=["/costmap", "/local_plan"])
    grids, plans = rec.topic("/costmap"), rec.topic("/local_plan")
    assert len(grids) >= 5 and any(g["column_count"] > 0 for g in grids)
    assert any(entity.get("lines") for p in plans for entity in p["entities"])
    for g in grids:
        assert not errors("Grid", g), errors("Grid", g)
    for p in plans:
        assert not errors("SceneUpdate", p), errors("SceneUpdate", p)
    import base64
    seen = max((np.frombuffer(base64.b64decode(g["data"]), dtype=np.uint8) == COST_LETHAL).sum() for g in grids)
    assert seen >= 3  # the bench's and the posts' returns, marked lethal
