"""What people see of the localisation on a map: the particles and the match quality in the recording.

A recorded tour of the office world on its map carries ``/localisation/particles``
(a ``foxglove.SceneUpdate``: one stroke per particle, in ``odom``) and
``/localisation/quality`` (``beastbt.LocalisationQuality``) at 2 Hz, each
message what its schema describes, and the particles lie round the robot.
"""

from __future__ import annotations

import math
import statistics

import jsonschema

from beastbt.recording import schemas as rs
from beastbt.recording.reader import read_recording
from localisation_support import mission_text, office_map_file
from recording_support import record_run
from test_obstacle_views import errors


def test_a_recorded_tour_on_a_map_has_the_particles_and_the_match_quality(tmp_path):
    office_map_file(tmp_path)
    mission = tmp_path / "tour.yaml"
    mission.write_text(mission_text("tour", "  - drive: {distance: 1.5 m}\n  - turn: {angle: 90 deg}\n"))
    folder, summary = record_run(mission, tmp_path / "runs", seed=0)
    assert summary["status"] == "success"
    rec = read_recording(folder / "run.mcap", topics=["/localisation/particles", "/localisation/quality", "/odom"])
    clouds, quality = rec.topic("/localisation/particles"), rec.topic("/localisation/quality")
    duration = summary["sim_time_s"]
    assert abs(len(quality) - duration / 0.5) <= 2 and len(clouds) == len(quality)  # 2 Hz
    for q in quality:
        jsonschema.validate(q, rs.CHANNELS["/localisation/quality"])
    assert all(q["localized"] for q in quality) and quality[-1]["updates"] > 10
    for cloud in clouds:
        assert not errors("SceneUpdate", cloud), errors("SceneUpdate", cloud)
    last = clouds[-1]["entities"][0]
    points = last["lines"][0]["points"]
    assert len(points) == 2 * 200  # 200 of the 400 particles, a stroke each
    odom = rec.topic("/odom")[-1]["pose"]["position"]
    starts = points[0::2]
    cx = statistics.median(p["x"] for p in starts)
    cy = statistics.median(p["y"] for p in starts)
    # In odom, round the robot: the cloud's middle (the median: recovery may have drawn a few particles anywhere
    # on the map) within a few centimetres of the odometry pose.
    assert math.hypot(cx - odom["x"], cy - odom["y"]) <= 0.1
