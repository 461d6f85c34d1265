"""``beastbt serve --ros2``: the robot stays in the ROS graph between missions, and rviz2's goals become missions.

A ``/goal_pose`` (rviz2's "2D Goal Pose") becomes a mission with one planned
``go_to`` (:func:`~beastbt.ros2.link.goal_mission`) handed to the serving loop
as the station's missions are, so it is checked, assembled and run the same
way (recorded, every safety part); on the world's or profile's map when the
robot has one (``serve --world worlds/office.yaml``: the office map). A new goal
while a goal runs replaces it (as Nav2 does); while a station's mission runs,
the goal waits for it to end.
"""

from __future__ import annotations

import sys
from typing import Any, Optional

from beastbt.ros2 import cdr
from beastbt.ros2.link import GoalListener, goal_mission, options_from

GOAL_MISSION = "ros2_goal"


class Ros2Serving:
    """The ROS 2 side of ``beastbt serve``: the run option for each mission, the listener between them."""

    def __init__(self, agent: Any, profile: Any, ros2: dict, world: Optional[str] = None) -> None:
        self.agent = agent
        self.map_file = goal_map(profile, world)
        """The map goals are planned on: the profile's ``ros2: map:``, else the world's ``map:``; None: none."""
        self.options = options_from(profile.section("ros2"), ros2.get("listen"), ros2.get("config"))
        self.ros2 = dict(ros2, on_goal=self.on_goal)
        self.listener: Optional[GoalListener] = None
        self.goals = 0

    def run_option(self) -> dict:
        """``RunOptions.ros2`` of each mission (the run's link hands its goals here)."""
        return self.ros2

    def idle(self) -> None:
        """No mission runs: listen for goals."""
        if self.listener is None:
            try:
                self.listener = GoalListener(self.options, self.on_goal).open()
            except Exception as exc:  # noqa: BLE001 - the robot serves on without ROS 2 goals; said once each time
                print(f"beastbt serve: ROS 2 goals not taken while idle: {exc}", file=sys.stderr, flush=True)

    def busy(self) -> None:
        """A mission starts: its run's link takes the port."""
        if self.listener is not None:
            self.listener.close()
            self.listener = None

    def on_goal(self, pose: cdr.PoseStamped, run: Any) -> None:
        """A goal (any thread; ``run`` the mission running now, or None): queue its mission for the loop."""
        from beastbt.fleet.agent import MissionRequest
        self.goals += 1
        x, y = pose.position[0], pose.position[1]

        def answer(ok: bool, body: dict) -> None:
            if not ok:
                print(f"beastbt serve: ROS 2 goal ({x:.2f}, {y:.2f}) not taken: {body.get('error')} "
                      f"{body.get('errors', '')}".rstrip(), file=sys.stderr, flush=True)
        # on_robot: the goal's map is the one the robot's own profile names (ros2: map:), read where it says
        self.agent.missions.put(MissionRequest(goal_mission(pose, self.map_file), answer, on_robot=True))
        if run is not None and run.mission.name == GOAL_MISSION:
            run.abort("a new ROS 2 goal")  # the next goal replaces this one
        elif run is not None:
            run.events.add("ros2", f"ROS 2 goal ({x:.2f}, {y:.2f}) m waits for this mission to end")

    def close(self) -> None:
        """Serving ends."""
        self.busy()


def goal_map(profile: Any, world: Optional[str]) -> Optional[str]:
    """The map file goals go on (absolute): the profile's ``ros2: map:`` (relative to the profile), else the
    ``map:`` of the ``--world`` file (relative to the world), else None."""
    from pathlib import Path
    name = (profile.section("ros2") or {}).get("map")
    base = Path(profile.file).parent if name and getattr(profile, "file", None) else None
    if not name and world:
        import yaml
        try:
            data = yaml.safe_load(Path(world).read_text(encoding="utf-8")) or {}
        except (OSError, yaml.YAMLError):
            data = {}
        name = data.get("map") if isinstance(data, dict) else None
        base = Path(world).parent
    if not isinstance(name, str) or not name:
        return None
    path = Path(name)
    return str(path if path.is_absolute() or base is None else (base / path).resolve())


__all__ = ["Ros2Serving", "GOAL_MISSION", "goal_map"]
