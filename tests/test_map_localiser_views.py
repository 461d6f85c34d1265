"""What people see of the localisation on a map: the particles and the match quality in the recording.

A recorded tour of the office world on its map carries ``/localisation/particles``
(a ``foxglove.SceneUpdate``: one stroke per particle, in ``map``) and
``/localisation/quality`` (``beastbt.LocalisationQuality``) at 2 Hz, each
message what its schema describes, and the particles lie round the robot where ``/tf`` puts it, even when the
wheels' heading and the gyro's disagree.
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
    rec = read_recording(folder / "run.mcap", topics=["/localisation/particles", "/localisation/quality", "/map/pose"])
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
    assert last["frame_id"] == "map"
    on_map = rec.topic("/map/pose")[-1]["pose"]["position"]
    cx, cy = cloud_middle(clouds[-1])
    # On the map, round the robot: the cloud's middle within a few centimetres of the pose on the map.
    assert math.hypot(cx - on_map["x"], cy - on_map["y"]) <= 0.1


def cloud_middle(update: dict) -> tuple[float, float]:
    """The middle of a particle cloud's strokes (the median of their starts: recovery may have drawn a few particles
    anywhere on the map), in the entity's frame, m."""
    starts = update["entities"][0]["lines"][0]["points"][0::2]
    return statistics.median(p["x"] for p in starts), statistics.median(p["y"] for p in starts)


def slipping_profile(tmp_path) -> str:
    """The simulator's robot whose tracks lose a tenth of their travel: the wheels count more turn than the gyro
    sees (after the U-turn of the test below, their heading is 16 degrees off)."""
    from conftest import REPO
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    assert "  slip_bias: 0.005" in text
    profile = tmp_path / "slipping.yaml"
    profile.write_text(text.replace("  slip_bias: 0.005", "  slip_bias: 0.1"), encoding="utf-8")
    return str(profile)


def test_the_particles_lie_round_the_robot_where_tf_puts_it_when_wheels_and_gyro_disagree(tmp_path):
    """The cloud is drawn in a frame whose place of the robot (/tf's) is the localiser's: its middle is on the robot.

    Drawn in ``odom`` through the localiser's own map -> odom (its odometry turned by the gyro), the cloud of this
    run stood 0.7 m off the robot after the U-turn and the drive (the wheels' heading 16 degrees from the gyro's)."""
    office_map_file(tmp_path)
    mission = tmp_path / "tour.yaml"
    # standing 2.5 s first, the IMU driver knows its gyro's bias and the localiser's odometry turns with the gyro
    mission.write_text(mission_text("tour", "  - wait: 2.5 s\n  - drive: {distance: 1.5 m}\n"
                                            "  - turn: {angle: 180 deg}\n  - drive: {distance: 3 m}\n"
                                            "  - wait: 1.5 s\n"))
    folder, summary = record_run(mission, tmp_path / "runs", seed=1, robot=slipping_profile(tmp_path),
                               simulate=True)
    assert summary["status"] == "success" and summary["localisation"]["gyro_ticks"] > 400
    rec = read_recording(folder / "run.mcap", topics=["/localisation/particles", "/tf", "/map/pose"])
    last = rec.topic("/localisation/particles")[-1]  # while the robot stands, at the end of the wait
    frame = last["entities"][0]["frame_id"]
    tf = {t["child_frame_id"]: t for t in rec.topic("/tf")[-1]["transforms"]}
    robot = _planar(tf["base_link"])  # in odom
    if frame == "map":
        robot = compose(_planar(tf["odom"]), robot)
    # The premise: the wheels' heading (odom) is far from the localiser's on the map (map -> odom turns by it).
    assert abs(math.degrees(_planar(tf["odom"])[2])) > 10.0
    cx, cy = cloud_middle(last)
    assert math.hypot(cx - robot[0], cy - robot[1]) <= 0.1, (frame, (cx, cy), robot)
    if frame == "map":  # and there the localiser puts the robot, within centimetres of the truth
        on_map = rec.topic("/map/pose")[-1]["pose"]["position"]
        assert math.hypot(cx - on_map["x"], cy - on_map["y"]) <= 0.1
        assert summary["truth"]["position_error_max_m"] < 0.1


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
