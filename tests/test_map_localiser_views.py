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

from beastbt.estimation.map_localiser import compose
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


def _planar(transform: dict) -> tuple[float, float, float]:
    p, q = transform["translation"], transform["rotation"]
    return float(p["x"]), float(p["y"]), 2.0 * math.atan2(float(q["z"]), float(q["w"]))


def test_on_a_map_tf_puts_the_robot_where_the_localiser_says(tmp_path):
    """/tf's map -> odom is the localiser's (as AMCL publishes it), so base_link lands on /map/pose, on /map.

    Compared while the robot stands (after the drive and after the turn): /tf's period and /map/pose's differ,
    and a moving robot is elsewhere a tick later. The fused estimate's map -> odom put it metres away."""
    office_map_file(tmp_path)
    mission = tmp_path / "tour.yaml"
    mission.write_text(mission_text("tour", "  - drive: {distance: 1.5 m}\n  - wait: 1.5 s\n"
                                            "  - turn: {angle: 90 deg}\n  - wait: 1.5 s\n"))
    folder, summary = record_run(mission, tmp_path / "runs", seed=1)
    assert summary["status"] == "success"
    rec = read_recording(folder / "run.mcap", topics=["/tf", "/map/pose"])

    def stamp(t: dict) -> float:
        return t["sec"] + t["nsec"] * 1e-9

    def planar_pose(msg: dict) -> tuple[float, float, float]:
        p, q = msg["pose"]["position"], msg["pose"]["orientation"]
        return float(p["x"]), float(p["y"]), 2.0 * math.atan2(float(q["z"]), float(q["w"]))

    tfs = [(stamp(m["transforms"][0]["timestamp"]), m["transforms"]) for m in rec.topic("/tf")]
    poses = [(stamp(m["timestamp"]), planar_pose(m)) for m in rec.topic("/map/pose")]
    checked = 0
    def same(a: tuple[float, float, float], b: tuple[float, float, float]) -> bool:
        return math.hypot(a[0] - b[0], a[1] - b[1]) < 0.002 and abs(a[2] - b[2]) < 0.002

    for (_, before), (t1, pose), (_, later) in zip(poses, poses[1:], poses[2:]):
        still = same(before, pose) and same(pose, later)
        after = [tf for t, tf in tfs if t > t1 + 1e-6]
        if not still or not after:
            continue
        by_child = {t["child_frame_id"]: t for t in after[0]}
        assert by_child["odom"]["parent_frame_id"] == "map"
        x, y, yaw = compose(_planar(by_child["odom"]), _planar(by_child["base_link"]))
        assert math.hypot(x - pose[0], y - pose[1]) < 0.01, (x, y, pose)
        assert abs(math.remainder(yaw - pose[2], math.tau)) < math.radians(0.5)
        checked += 1
    assert checked >= 6


def test_the_reports_error_plot_has_the_localisers_error_on_the_map(tmp_path):
    from beastbt.recording.report import RunData, position_errors

    office_map_file(tmp_path)
    mission = tmp_path / "tour.yaml"
    mission.write_text(mission_text("tour", "  - drive: {distance: 1.5 m}\n  - turn: {angle: 90 deg}\n"))
    folder, summary = record_run(mission, tmp_path / "runs", seed=2)
    assert summary["truth"]["map_from_world"] is not None
    errors = position_errors(RunData.load(str(folder)))
    times, errs = errors["localiser on the map"]
    assert len(errs) > 10 and times == sorted(times)
    rms = math.sqrt(sum(e * e for e in errs) / len(errs))
    # the same error the run measured every tick (the report has it at 5 Hz): centimetres, not the map's offset
    assert abs(rms - summary["truth"]["position_error_rms_m"]) < 0.02
    assert max(errs) < 0.2
