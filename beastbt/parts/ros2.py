"""ROS 2 as a part: ``--ros2 [ENDPOINT]`` (or ``beastbt serve --ros2``) shows the run to ROS 2 over Zenoh.

Assembled only for a run with ``--ros2``; it imports Zenoh only then. The
profile's ``ros2:`` section (``schemas/parts/ros2.schema.json``) says the
domain, namespace, format and topics; :mod:`beastbt.ros2.link` does the rest.
The topics carry what the run reads anyway (as the console and the
recording, watching wakes no sensor); a topic the profile's ``ros2: topics:``
names explicitly keeps its sensor awake (``topics: [odom, tf, scan]``: the
LiDAR scans even for a mission that never reads it). The camera is never woken
(only the frames the run takes, with their JPEG, go out). A replay never
opens the link.
"""

from __future__ import annotations

from typing import Any, Mapping, Optional

from beastbt.robot.part import REPLAY, Build, Part, RefusalCheck
from beastbt.run.session import Prepared

READS = {"scan": "scan", "fix": "gps_fix", "imu": "imu", "battery": "battery"}
"""The readings (blackboard names) of the sensor topics: a topic the profile's ``ros2: topics:`` lists keeps its
sensor awake. /odom and /tf are the dead reckoning every run has: they wake no estimator."""


class Ros2Part(Part):
    """The run's ROS 2 link (docs/ros2.md)."""

    name = "ros2"
    section = "ros2"
    schema = "parts/ros2.schema.json"
    opens = "Zenoh session (peer, listening for a ROS 2 laptop: rmw_zenoh or zenoh-bridge-ros2dds)"
    takes = ("velocity (teleop source of the mux, as a remote stick: /cmd_vel)", "e-stop (/estop)",
             "initial pose (/initialpose)", "goals (/goal_pose, beastbt serve)")
    mode = ""

    def __init__(self) -> None:
        self.link: Optional[Any] = None
        self.reads: tuple[str, ...] = ()

    def steps(self) -> Mapping[str, Any]:
        """ros2_goals (docs/ros2.md): rviz2's goals, each a planned go_to on the mission's map."""
        from beastbt.ros2.goal_steps import build_ros2_goals
        return {"ros2_goals": build_ros2_goals}

    def attach(self, build: Build) -> None:
        """Note the mode, and the sensors the profile's ``ros2: topics:`` names (none without the list: the
        topics carry what the run reads anyway, and watching costs the run nothing more)."""
        self.mode = build.mode
        topics = (build.profile.section("ros2") or {}).get("topics") or ()
        self.reads = tuple(sorted({READS[t] for t in topics if t in READS}))

    def install(self, prepared: Prepared) -> None:
        """Open the link (a Zenoh session listening for the laptop) and hook it into the run."""
        cli = prepared.options.ros2
        if self.mode == REPLAY or cli is None:
            return
        from beastbt.ros2.goal_steps import refuse_without_link_or_map
        from beastbt.ros2.link import Ros2Link, options_from, takes_commands
        options = options_from(prepared.profile.section("ros2"), cli.get("listen"), cli.get("config"))
        # a ros2_goals step on no map, or with a link that takes no goals: refused before opening
        refuse_without_link_or_map(prepared.mission, has_link=True, takes_goals=takes_commands(options))
        link = self.link = Ros2Link(prepared, options, on_goal=cli.get("on_goal"))
        try:
            link.open()
        except Exception as exc:  # noqa: BLE001 - Zenoh says why it cannot listen (a port in use)
            from beastbt.core.errors import InvalidInput, Position, Problem
            raise InvalidInput([Problem("--ros2", Position(), f"the ROS 2 link cannot open: {exc}",
                                        "another program may listen on that port (a zenohd router, another "
                                        "beastbt): give --ros2 another endpoint, e.g. tcp/127.0.0.1:7448")]) from None
        prepared.closers.append(link.close)
        mode = "takes /cmd_vel, /goal_pose, /initialpose" if link.commands else "publishes only (plain TCP beyond " \
                                                                                 "loopback: no commands but /estop)"
        prepared.run.events.add("ros2", f"ROS 2 ({options.format}, domain {options.domain}, namespace "
                                        f"{options.namespace}) on {options.listen or options.config_file}: {mode}")


class Ros2GoalsCheck(RefusalCheck):
    """A run without ``--ros2`` of a mission with a ``ros2_goals`` step: refused before anything moves, at the step."""

    name = "ros2_goals_check"

    def check(self, prepared: Prepared) -> None:
        """InvalidInput at the step: the run has no ROS 2 link (or the mission no map)."""
        from beastbt.ros2.goal_steps import refuse_without_link_or_map
        refuse_without_link_or_map(prepared.mission, has_link=False)


def uses_ros2_goals(mission: Any) -> bool:
    """Whether ``mission`` has a ``ros2_goals`` step (the assembly's test for :class:`Ros2GoalsCheck`)."""
    from beastbt.ros2.goal_steps import uses_goals
    return uses_goals(mission)


__all__ = ["Ros2Part", "Ros2GoalsCheck", "uses_ros2_goals", "READS"]
