"""The mission step ``ros2_goals``: rviz2's "2D Goal Pose" on /goal_pose drives a ``beastbt run`` on the office map.

A simulated run of a mission whose step is ``ros2_goals: {goals: 1}`` (world and map: office) is watched by a
plain Zenoh peer that plays rviz2 on rmw_zenoh: once the run publishes /odom (its first tick is done, the step
listens), it sends a goal in the odom frame (not taken: goals are planned in the map frame) and then one in the
map frame, in the kitchen. The run's summary says the goal was reached along a planned path. Without --ros2, or
without a map, the mission is refused before anything moves, at the step's line.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import py_trees
import pytest

from beastbt.core.errors import InvalidInput
from beastbt.ros2 import rmw_zenoh as rz
from conftest import REPO
from fleet_support import free_port, wait_for
from ros2_support import peer_with_tokens

Status = py_trees.common.Status

MISSION = """mission: rviz_goals
world: office
map: office
steps:
  - ros2_goals: {goals: 1}
"""


def _goal(store, x: float, y: float, frame: str) -> bytes:
    t, g = store.types, "geometry_msgs/msg/"
    goal = t[g + "PoseStamped"](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=frame),
        pose=t[g + "Pose"](position=t[g + "Point"](x=x, y=y, z=0.0),
                           orientation=t[g + "Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
    return bytes(store.serialize_cdr(goal, g + "PoseStamped"))


def test_a_goal_from_rviz2_is_reached_by_the_ros2_goals_step_on_the_office_map(tmp_path):
    pytest.importorskip("zenoh")
    typesys = pytest.importorskip("rosbags.typesys")
    mission = tmp_path / "rviz_goals.yaml"
    mission.write_text(MISSION)
    summary = tmp_path / "summary.json"
    port = free_port()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "beastbt", "run", str(mission), "--speed", "max", "--max-time",
                             "60 min", "--no-record", "--summary", str(summary), "--ros2", f"tcp/127.0.0.1:{port}"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    s = None
    try:
        s = wait_for(lambda: (found := peer_with_tokens(port, lambda tokens: any(
            "/MS/" in t and "%goal_pose/geometry_msgs::msg::dds_::PoseStamped_/" in t for t in tokens)))
                     and found[0], 90, "the run's /goal_pose subscription")
        odom: list[bytes] = []
        sub = s.declare_subscriber(rz.topic_key(0, "/odom", "nav_msgs/msg/Odometry"),
                                   lambda sample: odom.append(sample.payload.to_bytes()))
        wait_for(lambda: odom, 60, "the run's first /odom (its first tick)")
        store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
        pub = s.declare_publisher(rz.topic_key(0, "/goal_pose", "geometry_msgs/msg/PoseStamped"))
        gid = rz.gid("@ros2_lv/0/test/0/1/MP/%/%/rviz2/%goal_pose/x/y/::,10:,:,:,,")
        pub.put(_goal(store, 0.5, 0.5, "odom"), attachment=rz.attachment(1, 0, gid))
        pub.put(_goal(store, 3.0, 5.5, "map"), attachment=rz.attachment(2, 0, gid))
        out = proc.communicate(timeout=300)[0]
        sub.undeclare()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        if s is not None:
            s.close()
    assert proc.returncode == 0, out[-3000:]
    result = json.loads(summary.read_text())
    assert result["status"] == "success"
    (waypoint,) = result["map_waypoints"]
    assert (waypoint["name"], waypoint["x"], waypoint["y"], waypoint["reached"]) == ("goal 1", 3.0, 5.5, True)
    assert waypoint["arrival_error_m"] < 0.5  # the true pose, in the map frame
    assert waypoint["path_m"] > 5.0  # planned through the office's and the kitchen's doors, not straight
    texts = [e["text"] for e in result["events"] if e["kind"] == "ros2"]
    assert any("in frame 'odom' not taken" in t for t in texts), texts
    assert any("goal 1 reached" in t for t in texts), texts


def _refusal(tmp_path, text: str, ros2) -> InvalidInput:
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions
    path = tmp_path / "m.yaml"
    path.write_text(text)
    with pytest.raises(InvalidInput) as caught:
        prepare(str(path), RunOptions(record=False, ros2=ros2))
    return caught.value


def test_without_the_ros2_link_the_mission_is_refused_at_the_step(tmp_path):
    text = "mission: m\nsteps:\n  - say: hi\n  - first_of:\n      - [ros2_goals: {for: 1 min}]\n"
    (problem,) = _refusal(tmp_path, text, None).problems
    assert (problem.position.line, problem.position.column) == (5, 10)
    assert "no ROS 2 link" in problem.message and "--ros2" in problem.hint


def test_without_a_map_the_mission_is_refused_before_the_link_opens(tmp_path):
    text = "mission: m\nsteps:\n  - ros2_goals: {}\n"
    (problem,) = _refusal(tmp_path, text, {"listen": "tcp/127.0.0.1:1", "config": None}).problems
    assert problem.position.line == 3 and "plans each goal on a map" in problem.message and "map:" in problem.hint


def test_with_a_link_that_takes_no_commands_the_mission_is_refused_before_the_link_opens(tmp_path):
    # plain TCP beyond loopback publishes only: the step would wait for goals it never takes (it failed at run time
    # saying "run it with --ros2", after the steps before it had run)
    text = "mission: m\nworld: office\nmap: office\nsteps:\n  - wait: 1 s\n  - ros2_goals: {}\n"
    # an address beyond loopback that is not this machine's: nothing listens, whatever the code does
    (problem,) = _refusal(tmp_path, text, {"listen": "tcp/192.0.2.1:7447", "config": None}).problems
    assert problem.position.line == 6 and "publishes only" in problem.message and "--ros2-config" in problem.hint


class _Leg(py_trees.behaviour.Behaviour):
    """A go_to stand-in: RUNNING until told how it ends; remembers the targets it started with."""

    def __init__(self, target) -> None:
        super().__init__(name="leg")
        self.target = target
        self.place = ""
        self.starts: list = []
        self.outcome = Status.RUNNING

    def initialise(self) -> None:
        self.starts.append((self.place, self.target()))
        self.outcome = Status.RUNNING

    def update(self):
        return self.outcome


def _step(**ends):
    from beastbt.behaviours.context import MissionContext
    from beastbt.behaviours.ros2_goals import GOAL_INBOX, GoalInbox, Ros2Goals
    from beastbt.core.clock import SimClock
    from beastbt.core.events import EventLog
    clock = SimClock()
    ctx = MissionContext(clock=clock, events=EventLog(clock))
    inbox = ctx.services.plugins[GOAL_INBOX] = GoalInbox()
    legs: list[_Leg] = []
    step = Ros2Goals("ros2_goals", ctx, lambda target: legs.append(_Leg(target)) or legs[0], **ends)
    return step, legs[0], inbox, clock, ctx


def test_ros2_goals_tick_by_tick_a_new_goal_replaces_one_under_way_and_an_unreached_goal_is_not_the_end():
    step, leg, inbox, clock, ctx = _step(goals=1)
    assert inbox.put(1.0, 2.0) is None  # before the step listens: not taken
    step.tick_once()
    assert step.status == Status.RUNNING and inbox.listening == 1 and leg.starts == []
    assert inbox.put(1.0, 2.0).number == 1
    step.tick_once()
    assert leg.starts == [("goal 1", (1.0, 2.0))]
    inbox.put(3.0, 4.0)  # rviz2's user changes their mind
    step.tick_once()
    assert leg.starts[-1] == ("goal 2", (3.0, 4.0)) and step.status == Status.RUNNING
    leg.outcome = Status.FAILURE  # no path: an event, and the step waits on
    step.tick_once()
    assert step.status == Status.RUNNING and leg.status == Status.INVALID
    assert any("goal 2 not reached" in e.text for e in ctx.events.events)
    inbox.put(5.0, 6.0)
    step.tick_once()
    leg.outcome = Status.SUCCESS
    step.tick_once()
    assert step.status == Status.SUCCESS and inbox.listening == 0
    assert [s[0] for s in leg.starts] == ["goal 1", "goal 2", "goal 3"]


def test_ros2_goals_for_a_time_gives_up_the_goal_under_way():
    step, leg, inbox, clock, _ = _step(duration_s=10.0)
    step.tick_once()
    inbox.put(1.0, 2.0)
    step.tick_once()
    assert leg.status == Status.RUNNING
    clock.advance(10.0)
    step.tick_once()
    assert step.status == Status.SUCCESS and leg.status == Status.INVALID and inbox.listening == 0


def test_a_task_with_parameters_is_walked_past_and_a_goals_step_inside_a_task_is_found(tmp_path):
    from beastbt.mission.model import load_mission
    from beastbt.ros2.goal_steps import goal_steps
    text = ("mission: m\ntasks:\n  look:\n    params: {angle: 45 deg}\n    steps:\n      - turn: {angle: $angle}\n"
            "  wait_goals:\n    - first_of:\n        - [ros2_goals: {goals: 1}]\n        - [say: none]\n"
            "steps:\n  - do: {task: look, angle: 30 deg}\n  - do: wait_goals\n")
    path = tmp_path / "m.yaml"
    path.write_text(text, encoding="utf-8")
    found = list(goal_steps(load_mission(path)))
    assert len(found) == 1 and found[0].goals == 1
