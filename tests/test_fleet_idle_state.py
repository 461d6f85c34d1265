"""What an idle robot reports on the fleet (issue 37, 8): its pose and battery, never ``null`` for a simulated robot.

A simulated robot stands at its world's start with its world's battery before its first run, then where its last
run left it; a robot reports its last run's estimate and battery. (The CLI's ``serve --sim`` is checked in
``test_fleet_default_safe.py``.)
"""

from __future__ import annotations

import math
from types import SimpleNamespace

from beastbt.fleet.agent import FleetAgent
from beastbt.fleet.config import FleetOptions


def _link(state: dict) -> SimpleNamespace:
    """A run's link as the agent sees it (only its last state is read when it ends)."""
    return SimpleNamespace(latest=lambda: state, run=None)


def test_a_simulated_robot_reports_where_it_stands_and_its_battery_before_and_after_a_run():
    agent = FleetAgent("sim-1", FleetOptions("tcp/127.0.0.1:7447"))
    agent.stand({"world": "plain", "x": 1.5, "y": -2.0, "yaw": math.pi / 2, "radius_m": 0.2}, 12.3, shared=False)
    idle = agent.idle_state()
    assert idle["status"] == "idle" and idle["mission"] is None
    assert idle["pose"] == {"x": 1.5, "y": -2.0, "yaw_deg": 90.0, "heading_deg": 0.0}
    assert idle["battery"]["volts"] == 12.3 and 0 < idle["battery"]["percent"] <= 100
    assert "sim" not in agent.current_state()  # not in a shared world: no obstacle to the others
    agent.link = _link({"pose": {"x": 4.0, "y": 0.5, "yaw_deg": 10.0, "heading_deg": 80.0},
                        "battery": {"volts": 12.1, "percent": 90.0}})
    agent.detach({"mission": "m", "status": "success"})
    idle = agent.idle_state()
    assert idle["pose"]["x"] == 4.0 and idle["battery"]["volts"] == 12.1  # the last run's


def test_in_a_shared_world_it_reports_its_true_pose_where_the_others_see_it():
    agent = FleetAgent("sim-2", FleetOptions("tcp/127.0.0.1:7447"))
    agent.stand({"world": "yard", "x": 0.0, "y": 1.0, "yaw": 0.0, "radius_m": 0.2}, 12.0)
    state = agent.current_state()
    assert state["sim"]["y"] == 1.0 and state["pose"]["y"] == 1.0 and state["battery"]["volts"] == 12.0
