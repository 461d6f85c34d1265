"""A mission that starts at a named place of its map, drives to another, and turns to a compass heading there.

The simulated robot is put at the kitchen (a copy of the office world with its start moved there, facing north);
the mission says ``start: kitchen`` with the kitchen's pose on the map. It must be localised from that place (the
true error small all along), reach the lab, and ``turn: {heading: 90 deg}`` must still mean east on the compass
(issue 21: a heading stays a compass heading on a map), not 90 degrees from the map's x axis.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

from beastbt.assembly import prepare
from beastbt.run.session import RunOptions, execute
from tests.map_support import OFFICE_MAP, OFFICE_WORLD

KITCHEN_WORLD = (5.5, 7.5)
"""The kitchen place (3.0 m, 5.5 m on the map) in the office world's frame: the map's origin is the world's start
(2.5, 2.0), facing east."""


def test_start_at_a_named_place_then_a_compass_heading_on_the_map(tmp_path: Path) -> None:
    world = OFFICE_WORLD.read_text().replace("start: {x: 2.5, y: 2.0, yaw_deg: 0}",
                                             f"start: {{x: {KITCHEN_WORLD[0]}, y: {KITCHEN_WORLD[1]}, yaw_deg: 90}}")
    assert "yaw_deg: 90}" in world
    (tmp_path / "office_kitchen.yaml").write_text(world)
    (tmp_path / "m.yaml").write_text(f"""mission: from_the_kitchen
world: office_kitchen.yaml
map: {OFFICE_MAP}
start: kitchen
places:
  kitchen: {{x: 3.0 m, y: 5.5 m, yaw: 90 deg}}
  lab: {{x: 6.0 m, y: 0.5 m}}
steps:
  - go_to: lab
  - turn: {{heading: 90 deg}}
""")
    summary = execute(prepare(str(tmp_path / "m.yaml"), RunOptions(record=False, seed=2)), io.StringIO())
    assert summary["status"] == "success", summary["events"][-3:]
    truth = summary["truth"]
    assert truth["collisions"] == 0
    # localised from the named place all along (a start taken as the map's origin would be metres off)
    assert truth["position_error_rms_m"] is not None and truth["position_error_rms_m"] < 0.10
    assert truth["position_error_max_m"] < 0.25
    final = truth["final_pose"]
    # the lab: (6.0, 0.5) on the map is (8.5, 2.5) in the world
    assert math.hypot(final["x"] - 8.5, final["y"] - 2.5) < 0.5
    # compass 90 deg is east: world yaw 0 (x east), whatever the map's axes
    assert abs(final["yaw_deg"]) < 6.0
