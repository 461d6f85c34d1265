"""Recoveries before a navigation step gives up: clear the costmaps, back up, spin, wait (Nav2's order), each an
event and counted in the summary; per step ``recovery: {tries: N}`` or ``recovery: none``.

The simulator runs use a robot without the global costmap (``global_costmap: {enabled: false}``), so that the
local costmap alone decides when the robot is blocked, as the recoveries' trigger.
"""

from __future__ import annotations

import math

import jsonschema
import numpy as np

from beastbt.behaviours.recovery import ORDER, Recoveries, RecoveryConfig, RecoveryLog
from beastbt.core.schema_check import load_schema
from nav_support import events_of, harness, place_yaml, robot_without_global_costmap

DOORWAY = [[-10.0, 4.0, -0.5, 4.0], [0.5, 4.0, 10.0, 4.0]]


def person_until(seconds: float) -> list:
    """A person standing in the doorway until ``seconds``, then walking away ahead of the robot."""
    return [{"shape": "person", "radius_m": 0.25, "speed_mps": 0.8, "path": [[0.0, 4.0], [0.0, 14.0]],
             "start_s": seconds}]


def test_recoveries_keep_the_step_going_until_the_person_in_the_doorway_leaves(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 7.0)}
steps:
  - go_to: {{place: a, blocked_after: 6 s}}
""", walls=DOORWAY, obstacles=person_until(40.0), robot=robot_without_global_costmap(tmp_path))
    lowest_while_backing = math.inf
    backed_from = None
    while not h.done and h.now_s < 150:
        h.tick()
        tip = h.run.root.tip()
        if tip is not None and tip.feedback_message.startswith("recovering: backing up"):
            backed_from = backed_from if backed_from is not None else h.truth.y
            lowest_while_backing = min(lowest_while_backing, h.truth.y)
    assert h.result == "success", [e.text for e in events_of(h, "step_failed")]
    recoveries = events_of(h, "recovery")
    texts = [e.text for e in recoveries]
    assert texts and "recovery 1 of 4: clearing the costmaps" in texts[0], texts
    assert any("backing up 0.3 m" in t for t in texts) and all("because blocked for 6 s" in t for t in texts[:1])
    assert backed_from is not None and backed_from - lowest_while_backing > 0.2     # it really reversed
    summary = h.summary()
    assert summary["recoveries"]["count"] == len([t for t in texts if " of 4: " in t]) >= 2
    jsonschema.validate(summary, load_schema("summary.schema.json"))
    assert summary["truth"]["collisions"] == 0


def test_recovery_none_gives_up_at_once(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 7.0)}
steps:
  - go_to: {{place: a, blocked_after: 6 s, recovery: none}}
""", walls=DOORWAY, obstacles=person_until(40.0), robot=robot_without_global_costmap(tmp_path))
    h.run_to_end(timeout_s=150)
    assert h.result == "failure"
    assert not events_of(h, "recovery")
    assert "blocked for 6 s" in events_of(h, "step_failed")[0].text
    assert h.summary()["recoveries"] == {"count": 0, "kinds": {}}


def test_a_step_runs_as_many_recoveries_as_its_tries_in_nav2s_order_then_fails_with_its_reason(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 7.0)}
steps:
  - go_to: {{place: a, blocked_after: 6 s, recovery: {{tries: 3}}}}
""", walls=[[-10.0, 4.0, 10.0, 4.0]], robot=robot_without_global_costmap(tmp_path))
    h.run_to_end(timeout_s=200)
    assert h.result == "failure"
    kinds = [e.text.split(": ")[2].split(" ")[0] for e in events_of(h, "recovery") if " of 3: " in e.text]
    assert kinds == ["clearing", "backing", "spinning"], kinds
    assert h.summary()["recoveries"]["kinds"] == {"clear": 1, "back_up": 1, "spin": 1}
    assert "blocked for 6 s" in events_of(h, "step_failed")[0].text
    assert h.summary()["truth"]["collisions"] == 0


# -- back-up looks behind first ------------------------------------------------------------------------------
class FakeHost:
    """A navigation step as a recovery sees it: a pose, the scan's points, the commands sent."""

    name = "go_to a"

    def __init__(self, points: np.ndarray) -> None:
        from beastbt.blackboard.types import FusedPose
        self.pose = FusedPose(stamp_s=0.0, x=0.0, y=0.0, yaw=0.0)
        self.points = points
        self.commands: list[tuple[float, float]] = []
        self.cleared = 0

    def read(self, key: str):
        return self.pose if key == "pose_odom" else None

    def command(self, linear_mps: float, angular_rps: float) -> None:
        self.commands.append((linear_mps, angular_rps))

    def clear_costmaps_around(self, radius_m: float) -> int:
        self.cleared += 1
        return 7

    def points_base(self):
        return self.points


class FakeEvents(list):
    """Events as (kind, text) texts."""

    def add(self, kind: str, text: str) -> None:
        self.append(text)


def test_back_up_is_skipped_when_the_lidar_sees_something_close_behind_and_driven_when_free():
    events = FakeEvents()
    wall_behind = np.array([[-0.35, y] for y in np.linspace(-0.3, 0.3, 13)])
    for points, reverses in ((wall_behind, False), (wall_behind - [2.0, 0.0], True)):
        rec = Recoveries(RecoveryConfig(), 4, 0.15, RecoveryLog())
        host = FakeHost(points)
        rec.begin(host, events, 0.0, "stuck")              # clear
        assert host.cleared == 1 and not rec.tick(host, events, 0.05)
        rec.begin(host, events, 0.1, "stuck")              # back up
        assert rec.kind == "back_up"
        rec.tick(host, events, 0.15)
        assert any(v < 0 for v, _ in host.commands) is reverses
    assert any("no room behind to back up: skipped" in t for t in events)
    assert ORDER == ("clear", "back_up", "spin", "wait")
