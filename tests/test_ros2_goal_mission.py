"""``beastbt serve --ros2`` turns a ``/goal_pose`` into a mission's YAML: the goal's ``frame_id``, which comes from
the network, is quoted there, so that it can neither break the mission nor add keys to it (found by the acceptance
check of issue 35: a frame ``map: evil`` made the goal's mission unreadable, and a frame with newlines added keys).
"""

from __future__ import annotations

import pytest

from beastbt.ros2 import cdr


@pytest.mark.parametrize("frame", ["map: evil", "map\nworld: elsewhere\nspeed: 9 m/s", 'a "quoted" frame'])
def test_a_goals_frame_id_cannot_add_to_or_break_serves_goal_mission(frame):
    import yaml

    from beastbt.ros2.link import goal_mission
    pose = cdr.PoseStamped(0, frame, (1.0, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    mission = yaml.safe_load(goal_mission(pose, "/maps/office.yaml"))
    assert set(mission) == {"mission", "description", "map", "places", "steps"}
    assert mission["description"].endswith(f"m in {frame}") and mission["map"] == "/maps/office.yaml"
