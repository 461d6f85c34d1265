"""A run on a saved map: its places get the waypoint table GPS routes get (summary, terminal, report), and the
report's path picture draws them and the localiser's pose (issue 37, items 6 and 16)."""

from __future__ import annotations

import json
import math

import jsonschema
import pytest

from beastbt.recording.report import RunData, draw_path, summary_text, waypoint_table
from recording_support import REPO, record_run
from tests.map_support import OFFICE_MAP, OFFICE_WORLD

MISSION = f"""mission: mark_and_back
world: {OFFICE_WORLD}
map: {OFFICE_MAP}
places:
  mark: {{x: 1.5 m, y: 0 m}}
steps:
  - go_to: mark
  - return_home
"""


@pytest.fixture(scope="module")
def map_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("map_run")
    mission = folder / "mark.yaml"
    mission.write_text(MISSION, encoding="utf-8")
    run_folder, summary = record_run(mission, folder / "runs", seed=1, max_time_s=120.0)
    return run_folder, summary


def test_places_on_a_map_are_waypoints_with_x_and_y(map_run):
    _, summary = map_run
    assert summary["status"] == "success"
    schema = json.loads((REPO / "schemas" / "summary.schema.json").read_text(encoding="utf-8"))
    jsonschema.validate(summary, schema)
    rows = summary["waypoints"]
    assert [w["name"] for w in rows] == ["mark", "home"]
    mark = rows[0]
    assert mark["lat"] is None and mark["lon"] is None and (mark["x"], mark["y"]) == (1.5, 0.0)
    assert mark["reached"] and mark["time_s"] > 0 and mark["tolerance_m"] > 0
    # The arrival error is the simulator's truth: what the localiser judged arrival on is beside it.
    assert mark["arrival_error_m"] == summary["map_waypoints"][0]["arrival_error_m"] is not None
    assert mark["estimated_error_m"] <= mark["tolerance_m"] + 1e-6


def test_the_report_lists_the_map_places_and_draws_them_with_the_localisers_pose(map_run):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    folder, _ = map_run
    data = RunData.load(str(folder))
    text = summary_text(data)
    assert "waypoints: none" not in text
    assert "mark: reached" in text and "[map x 1.50 m, y 0.00 m]" in text and "judged on the estimate" in text
    assert [row[0] for row in waypoint_table(data)] == ["mark", "home"]
    # The places, moved from the map's frame into the world's: the mark 1.5 m ahead of the start.
    targets = {name: (e, n) for name, e, n, _, _ in data.targets()}
    x0, y0, yaw0 = data.world_start
    assert math.hypot(targets["mark"][0] - (x0 + 1.5 * math.cos(yaw0)),
                      targets["mark"][1] - (y0 + 1.5 * math.sin(yaw0))) < 1e-6
    assert math.hypot(targets["home"][0] - x0, targets["home"][1] - y0) < 1e-6
    fig, ax = plt.subplots()
    labels = draw_path(data, ax)
    annotated = {t.get_text() for t in ax.texts}
    plt.close(fig)
    assert {"mark", "home"} <= annotated
    assert "localiser (map pose)" in labels and "fused estimate" not in labels
    # The line drawn is the localiser's: centimetres from the truth, where the fused (wheels and gyro) drifts.
    truth = data.rec.topic("/truth")
    path = data.localiser_path()
    assert len(path) > 20

    def off(p):
        return min(math.hypot(p[0] - m["x"], p[1] - m["y"]) for m in truth)
    assert max(off(p) for p in path) < 0.25
