"""``/plan`` of a GPS go_to for ROS 2: live on the link and in the exported bag, as the recording's ``/plan``.

The fence crossing (missions/fence_crossing.yaml on worlds/field_fence.yaml, seed 1) runs in this process with
``--ros2`` and a recording until just after its first replan (the first way round at 3.05 s, the next at 3.5 s),
then stops. A plain Zenoh peer (rviz2's place) subscribes to ``/plan`` on rmw_zenoh's key before the run starts;
each plan the navigator makes is noted with its goal. The recording is then exported as a ROS 2 bag and read back
with rosbags' reader.
"""

from __future__ import annotations

import io
import json
import threading
import time

import numpy as np
import pytest

from beastbt.assembly import prepare
from beastbt.ros2 import bag
from beastbt.ros2 import rmw_zenoh as rz
from beastbt.ros2.topics import RunTopics
from beastbt.run.session import RunOptions, execute
from conftest import REPO
from fleet_support import free_port, wait_for

zenoh = pytest.importorskip("zenoh")
typesys = pytest.importorskip("rosbags.typesys")
highlevel = pytest.importorskip("rosbags.highlevel")

STOP_S = 3.8
"""The run stops here (sim s): after the first way round (3.05 s) and its first replan (3.5 s)."""
FENCE_X_M = 8.0
"""The fence in odom: odom x is north (the robot starts facing north), the fence across it at x = 8 m from
y = -4 m to 4 m (worlds/field_fence.yaml)."""


def _peer(port: int):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    return zenoh.open(conf)


def _points(path) -> np.ndarray:
    return np.array([[p.pose.position.x, p.pose.position.y] for p in path.poses], dtype=float).reshape(-1, 2)


def crossing_y(pts: np.ndarray) -> float:
    """Odom y (m) where the polyline ``pts`` first crosses the fence's line x = :data:`FENCE_X_M`."""
    i = int(np.argmax(pts[:, 0] >= FENCE_X_M))
    assert i > 0 and pts[i - 1, 0] < FENCE_X_M, "the way does not cross the fence's line"
    (x0, y0), (x1, y1) = pts[i - 1], pts[i]
    return float(y0 + (y1 - y0) * (FENCE_X_M - x0) / (x1 - x0))


def _recorded_lines(rec) -> list:
    """The recording's /plan as [(frame or None, points (n, 2))]: None and no points for a deletion."""
    out = []
    for _, msg in rec.messages.get("/plan", []):
        if msg["entities"]:
            e = msg["entities"][0]
            out.append((e["frame_id"], np.array([[p["x"], p["y"]] for p in e["lines"][0]["points"]], dtype=float)))
        else:
            out.append((None, np.zeros((0, 2))))
    return out


@pytest.fixture(scope="module")
def fence(tmp_path_factory):
    """The fence run to its first replan, watched on /plan: {received Paths, plans made, recording, bag messages}."""
    tmp = tmp_path_factory.mktemp("gps_plan")
    port = free_port()
    p = prepare(str(REPO / "missions" / "fence_crossing.yaml"),
                RunOptions(seed=1, runs_dir=str(tmp / "runs"), max_time_s=STOP_S,
                           ros2={"listen": f"tcp/127.0.0.1:{port}"}))
    nav = p.run.ctx.services.local_navigator.global_nav
    plans: list = []
    plan = nav.plan

    def noting_plan(start, goal, tolerance_m, name):
        path = plan(start, goal, tolerance_m, name)
        plans.append((goal, path.points.copy()))
        return path

    replan = nav.replan

    def noting_replan(start, goal, tolerance_m, name, previous):
        path = replan(start, goal, tolerance_m, name, previous)
        plans.append((goal, path.points.copy()))  # a way mended on its side ends on the goal too
        return path

    nav.plan = noting_plan
    nav.replan = noting_replan
    (topics,) = [r.__self__ for r in p.run.recorders if isinstance(getattr(r, "__self__", None), RunTopics)]
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    received: list = []
    lock = threading.Lock()
    s = _peer(port)
    try:
        def take(sample) -> None:
            with lock:
                received.append(store.deserialize_cdr(sample.payload.to_bytes(), "nav_msgs/msg/Path"))
        sub = s.declare_subscriber(rz.topic_key(0, "/plan", "nav_msgs/msg/Path"), take)
        wait_for(lambda: topics.wanted("plan"), 30, "the link to see the /plan subscriber")
        summary = execute(p, io.StringIO())
        from beastbt.recording.reader import read_recording
        rec = read_recording(p.folder.path / "run.mcap", topics=["/plan", "/path"])
        expected = len(rec.messages.get("/plan", []))
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            with lock:
                if len(received) >= expected:
                    break
            time.sleep(0.05)
        sub.undeclare()
    finally:
        s.close()
    out = tmp / "out.mcap"
    counts = bag.export_ros2(p.folder.path, out)
    bagged: list = []
    with highlevel.AnyReader([out]) as reader:
        for conn, t_ns, raw in reader.messages():
            if conn.topic == "/plan":
                bagged.append((t_ns, reader.deserialize(raw, conn.msgtype), conn.msgtype))
    return {"summary": summary, "received": list(received), "plans": plans, "rec": rec, "bag": bagged,
            "counts": counts}


def test_the_run_went_to_its_first_replan_and_recorded_the_way_round(fence):
    assert fence["summary"]["status"] == "stopped"
    assert len(fence["plans"]) >= 2  # the first way round and one replan
    assert sum(1 for frame, _ in _recorded_lines(fence["rec"]) if frame == "odom") >= 2


def test_a_plain_zenoh_peer_gets_the_way_round_on_plan_ending_on_the_goal_and_round_the_fence(fence):
    paths = [m for m in fence["received"] if m.poses]
    assert len(paths) >= 2, f"{len(fence['received'])} /plan messages, {len(paths)} with poses"
    plans = fence["plans"]
    for path in paths:
        assert path.header.frame_id == "odom" and {p.header.frame_id for p in path.poses} == {"odom"}
        pts = _points(path)
        match = [goal for goal, made in plans if made.shape == pts.shape and np.allclose(made, pts, atol=1e-9)]
        assert match, "a /plan the navigator never made"
        assert pts[-1] == pytest.approx(match[0], abs=1e-9)  # the last pose is the goal
        assert pts[-1][0] > FENCE_X_M  # beyond the fence
        # Round the fence, not through its gap (0.25 m wide on the straight line y = 0): where the way crosses the
        # fence's line it is past the end of what the LiDAR has seen of the fence so far, metres off the line.
        assert abs(crossing_y(pts)) > 1.5
    # As more of the fence is seen the way goes round farther out (the whole fence is seen after this run stops).
    assert abs(crossing_y(_points(paths[-1]))) > abs(crossing_y(_points(paths[0])))


def test_live_plan_is_the_recordings_plan_message_for_message(fence):
    """On change, as the recording: the same ways in the same order, and an empty Path where the line was taken off."""
    recorded = _recorded_lines(fence["rec"])
    live = [(m.header.frame_id if m.poses else None, _points(m)) for m in fence["received"]]
    assert len(live) == len(recorded)
    for (frame, pts), (rframe, rpts) in zip(live, recorded):
        assert frame == rframe and pts.shape == rpts.shape and np.allclose(pts, rpts, atol=1e-6)
    assert all(m.header.frame_id == "odom" for m in fence["received"])  # an empty Path too: the way's frame


def test_the_bag_plan_carries_the_recordings_gps_plan(fence):
    recorded = _recorded_lines(fence["rec"])
    assert not fence["rec"].messages.get("/path")  # a GPS run: no map planner's path
    bagged = fence["bag"]
    assert fence["counts"]["/plan"] == len(bagged) == len(recorded)
    offset = fence["rec"].log_time_offset_ns
    times = [t for t, _ in fence["rec"].messages["/plan"]]
    assert [t for t, _, _ in bagged] == [t + offset for t in times]
    for (_, msg, typ), (frame, pts) in zip(bagged, recorded):
        assert typ == "nav_msgs/msg/Path"
        assert msg.header.frame_id == (frame or "odom")  # a deletion: an empty path in the way's frame
        got = _points(msg)
        assert got.shape == pts.shape and np.allclose(got, pts, atol=1e-9)


def test_the_bag_merges_path_and_plan_in_time_order(tmp_path, monkeypatch):
    """Both lines in one recording (not seen in practice): the bag's /plan keeps both, in time order, each deletion
    in its own line's frame."""
    from beastbt.recording import reader

    def line(sec: int, frame: str, pts) -> dict:
        return {"deletions": [], "entities": [{"timestamp": {"sec": sec, "nsec": 0}, "frame_id": frame,
                                               "lines": [{"points": [{"x": x, "y": y, "z": 0.0} for x, y in pts]}]}]}

    gone = {"deletions": [{"timestamp": {"sec": 9, "nsec": 0}, "type": 0, "id": "x"}], "entities": []}
    order = [("/path", 1_000, line(1, "map", [(0, 0), (1, 1)])), ("/plan", 3_000, line(3, "odom", [(2, 2)])),
             ("/path", 2_000, line(2, "map", [(5, 5)])), ("/plan", 4_000, gone), ("/path", 5_000, gone)]

    class Rec:
        log_time_offset_ns = 0

    rec = Rec()
    rec.order = order
    monkeypatch.setattr(reader, "find_recording", lambda run: run)
    monkeypatch.setattr(reader, "read_recording", lambda *a, **k: rec)
    out = tmp_path / "out.mcap"
    assert bag.export_ros2(tmp_path / "run.mcap", out) == {"/plan": 5}
    with highlevel.AnyReader([out]) as r:
        got = [(t, r.deserialize(raw, c.msgtype)) for c, t, raw in r.messages()]
    assert [t for t, _ in got] == [1_000, 2_000, 3_000, 4_000, 5_000]
    assert [(m.header.frame_id, len(m.poses)) for _, m in got] == [("map", 2), ("map", 1), ("odom", 1), ("odom", 0),
                                                                   ("map", 0)]


def test_plan_goes_on_change_for_someone_only_and_empty_when_the_way_is_dropped():
    """Tick by tick, the link's topics with a GPS navigator whose way the step sets and drops: nothing while no one
    subscribes, the way followed then as soon as someone does, nothing again while it stays, an empty Path (odom)
    when it is dropped."""
    from types import SimpleNamespace

    from beastbt.blackboard.types import FusedPose, VelocityCommand
    from beastbt.navigation.global_navigator import PathFollow
    from beastbt.robot.profile import load_profile
    from beastbt.run.runner import TickRecord
    nav = SimpleNamespace(following=None)
    run = SimpleNamespace(ctx=SimpleNamespace(services=SimpleNamespace(plugins={}, local_navigator=SimpleNamespace(
        global_nav=nav))))
    out: list = []
    someone = [False]
    topics = RunTopics(run, load_profile("sim"), frozenset({"plan"}), lambda name, payload: out.append((name, payload)),
                       0.0, lambda name: someone[0])
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    zero = VelocityCommand()
    tick = [0]

    def ticks(n: int) -> list:
        before = len(out)
        for _ in range(n):
            t = tick[0] * 0.05
            pose = FusedPose(t, 0.0, 0.0, 0.0)
            topics.on_tick(TickRecord(tick[0], t, [], pose, pose, zero, zero, zero, "mission", []))
            tick[0] += 1
        return [store.deserialize_cdr(p, "nav_msgs/msg/Path") for name, p in out[before:] if name == "plan"]

    assert ticks(4) == []  # no way
    way = PathFollow(np.array([[0.0, 0.0], [8.6, 2.0], [11.5, 1.3]]))
    nav.following = way
    assert ticks(4) == []  # no one subscribes: nothing made
    someone[0] = True
    (sent,) = ticks(4)  # someone came: the way followed now, once
    assert sent.header.frame_id == "odom" and np.allclose(_points(sent), way.points)
    assert ticks(6) == []  # the same way: nothing again
    nav.following = None
    (dropped,) = ticks(4)
    assert dropped.header.frame_id == "odom" and dropped.poses == []
    assert ticks(4) == []
