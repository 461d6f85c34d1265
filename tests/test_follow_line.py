"""follow_line on the simulator: every ``until``, losing the line, the junction under the centre, the camera's gimbal.

The worlds here are small floors written by each test (a raster of a few
square metres renders in milliseconds); the robot is the built-in ``sim``
profile, whose camera is read by the real camera driver and line detector.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from beastbt.testing import MissionHarness
from conftest import REPO

CROSS_WORLD = """
world: cross
start: {{x: {x0}, y: 0.0, yaw_deg: 0}}
floor:
  margin_m: 0.6
  background: {{colour: 190, texture: 6}}
  lines:
    width_m: 0.019
    colour: black
    paths:
      - path: [[0.0, 0.0], [2.0, 0.0]]          # ends at x = 2
      - path: [[1.2, -0.4], [1.2, 0.4]]         # crosses it at (1.2, 0)
"""

BEND_WORLD = """
world: bend
start: {x: 0.2, y: 0.0, yaw_deg: 0}
floor:
  margin_m: 0.6
  background: {colour: 190, texture: 6}
  lines:
    width_m: 0.019
    paths:
      - path: [[0.0, 0.0], [1.5, 0.0], {arc: {center: [1.5, 0.35], radius_m: 0.35, from_deg: -90, to_deg: 90}}, [0.5, 0.7]]
"""


def world(tmp_path: Path, text: str, name: str = "w.yaml") -> str:
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def harness(tmp_path: Path, steps: str, world_text: str, seed: int = 3, **kw) -> MissionHarness:
    w = world(tmp_path, world_text)
    return MissionHarness.from_yaml(f"mission: t\nworld: {w}\nsteps:\n{steps}", seed=seed, **kw)


def failures(h: MissionHarness) -> list[str]:
    return [e.text for e in h.events if e.kind == "step_failed"]


def test_until_intersection_ends_with_the_centre_over_the_junction(tmp_path):
    h = harness(tmp_path, "  - follow_line: {speed: 0.12 m/s, until: intersection}\n", CROSS_WORLD.format(x0=0.2))
    name = "follow line until intersection at 0.12 m/s"
    # the camera sees the crossing first, while the centre is still well short of it ...
    assert h.tick_until(lambda h: bool(h.blackboard("line") and h.blackboard("line").intersection), 30)
    seen_at = h.truth.x
    assert 1.2 - 0.8 < seen_at < 1.2 - 0.2
    assert h.status_of(name) == "RUNNING"
    # ... and the step ends only when the centre is over it
    assert h.run_to_end(60) == "success"
    assert abs(h.truth.x - 1.2) < 0.02 and abs(h.truth.y) < 0.02
    s = h.summary()["truth"]
    assert s["intersections_passed"] == 1 and s["intersections_detected"] == 1 and s["false_intersections"] == 0


def test_until_line_end_succeeds_when_the_line_runs_out(tmp_path):
    h = harness(tmp_path, "  - follow_line: {speed: 0.12 m/s, until: line_end}\n", CROSS_WORLD.format(x0=0.2))
    assert h.run_to_end(60) == "success"
    assert 1.6 < h.truth.x < 2.0  # past the crossing, stopped before the tape's end
    assert failures(h) == []


def test_losing_the_line_fails_after_lost_after(tmp_path):
    h = harness(tmp_path, "  - follow_line: {speed: 0.12 m/s, until: {distance: 3 m}, lost_after: 0.5 s}\n",
                CROSS_WORLD.format(x0=0.2))
    assert h.run_to_end(60) == "failure"
    [text] = failures(h)
    assert "line lost for" in text and float(text.split("lost for ")[1].split(" s")[0]) <= 0.7
    assert 1.6 < h.truth.x < 2.0
    assert h.last_sent.is_zero()


def test_no_line_in_sight_fails_at_once(tmp_path):
    # facing away from the line: nothing to follow
    text = CROSS_WORLD.format(x0=0.2).replace("yaw_deg: 0", "yaw_deg: 90")
    h = harness(tmp_path, "  - follow_line: {until: line_end}\n", text)
    assert h.run_to_end(10) == "failure"
    assert "no line in sight" in failures(h)[0]
    assert h.now_s < 0.5 + 1.0 + 0.3  # the camera settles, then lost_after (1 s)


def test_until_distance_and_time(tmp_path):
    h = harness(tmp_path, "  - follow_line: {speed: 0.12 m/s, until: {distance: 1 m}}\n", CROSS_WORLD.format(x0=0.2))
    assert h.run_to_end(30) == "success"
    assert abs(h.run.bb.pose_odom.distance_m - 1.0) < 0.02
    assert abs(h.truth.x - 1.2) < 0.03
    h = harness(tmp_path, "  - follow_line: {speed: 0.12 m/s, until: {time: 3 s}}\n", CROSS_WORLD.format(x0=0.2))
    assert h.run_to_end(30) == "success"
    assert 3.0 <= h.now_s <= 3.15


def test_follows_a_bend_and_slows_down_in_it(tmp_path):
    h = harness(tmp_path, "  - follow_line: {speed: 0.15 m/s, until: {distance: 2.3 m}}\n", BEND_WORLD, seed=5)
    speeds_straight, speeds_curve = [], []

    def watch(h: MissionHarness) -> bool:
        cmd = h.blackboard("cmd_mission")
        if cmd is not None and cmd.linear_mps > 0:
            (speeds_curve if h.truth.x > 1.55 else speeds_straight if 0.5 < h.truth.x < 1.3 else []).append(cmd.linear_mps)
        return h.done

    h.tick_until(watch, 60)
    assert h.result == "success"
    assert h.truth.y > 0.6 and math.cos(h.truth.yaw) < -0.9  # round the bend, heading back west
    s = h.summary()["truth"]
    assert s["line_within_5cm_frac"] == 1.0 and s["line_error_p95_m"] < 0.03
    assert min(speeds_straight) > 0.14
    assert sum(speeds_curve) / len(speeds_curve) < 0.8 * 0.15


def test_follow_line_points_the_gimbal_ahead_first(tmp_path):
    steps = "  - look: {pan: 45 deg, tilt: 20 deg}\n  - follow_line: {until: {time: 2 s}}\n"
    h = harness(tmp_path, steps, CROSS_WORLD.format(x0=0.2))
    assert h.run_to_end(30) == "success"
    gimbal = [c for c in h.wire if c.get("T") == 133]
    assert gimbal[-1]["X"] == 0 and gimbal[-1]["Y"] == 0
    assert abs(h.truth.pan_rad) < 1e-9 and abs(h.truth.tilt_rad) < 1e-9
    # it stood still while the gimbal came back, then followed
    start = next(r.now_s for r in h.records if any(n[0].startswith("follow line") and n[1] == "RUNNING" for n in r.changed_nodes))
    moving = [r.now_s for r in h.records if r.cmd_gate.linear_mps > 0]
    assert moving and moving[0] >= start + 0.5 - 1e-6


def test_intersection_and_line_seen_conditions(tmp_path):
    steps = ("  - wait_until: line_seen\n  - if: intersection\n    then: [{say: 'junction ahead'}]\n    else: [{say: 'no junction'}]\n")
    h = harness(tmp_path, steps, CROSS_WORLD.format(x0=0.7))  # the crossing is 0.5 m ahead, in view
    assert h.run_to_end(10) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["junction ahead"]
    h = harness(tmp_path, steps, CROSS_WORLD.format(x0=0.1))  # 1.1 m ahead: out of view
    assert h.run_to_end(10) == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["no junction"]


def test_no_camera_means_not_available(tmp_path):
    profile = (REPO / "robots" / "sim.yaml").read_text().split("\ncamera:")[0]
    p = tmp_path / "nocam.yaml"
    p.write_text(profile)
    h = harness(tmp_path, "  - follow_line: {until: line_end}\n", CROSS_WORLD.format(x0=0.2), robot=str(p))
    assert h.run_to_end(5) == "failure"
    assert "needs a camera" in failures(h)[0]


def test_a_mission_that_never_looks_renders_nothing(tmp_path):
    h = harness(tmp_path, "  - drive: {distance: 0.3 m}\n", CROSS_WORLD.format(x0=0.2))
    assert h.run_to_end(10) == "success"
    assert h.run.io.camera.frames == 0 and h.run.io.sim_camera is None
    assert "line_error_p95_m" not in h.summary()["truth"]


def test_pca9685_pan_tilt_are_centred_for_follow_line(tmp_path):
    """A DIY robot whose camera sits on PCA9685 servos: follow_line centres them through the register map."""
    profile = (REPO / "robots" / "diy_pwm.yaml").read_text()
    profile += "\ncamera:\n  device: sim\n"
    p = tmp_path / "diy_cam.yaml"
    p.write_text(profile)
    steps = "  - look: {pan: -30 deg}\n  - follow_line: {until: {time: 1 s}}\n"
    h = harness(tmp_path, steps, CROSS_WORLD.format(x0=0.2), robot=str(p))
    h.tick(3)  # the look step is settling
    assert h.status_of("look pan -30 deg") == "RUNNING"
    chip = h.run.io.sim_pca9685
    board = h.run.io.servo_board
    pan = board.servos.servos["pan"]
    assert chip.pulse_s(pan.channel) * 1000 == pytest.approx(pan.pulse_ms_for(-30.0), abs=0.01)
    assert h.run_to_end(10) == "success"
    for name in ("pan", "tilt"):
        cal = board.servos.servos[name]
        assert chip.pulse_s(cal.channel) * 1000 == pytest.approx(cal.pulse_ms_for(0.0), abs=0.01)
    assert abs(h.truth.pan_rad) < 0.01


def test_the_robot_camera_runs_in_its_own_thread_and_survives_a_missing_device(tmp_path):
    """On the robot: a thread reads and detects; the tick's poll hands over the newest frame and observation."""
    import threading

    import numpy as np

    from beastbt.devices.camera import Camera, CameraConfig
    from beastbt.vision.camera_pipeline import CameraPipeline
    from beastbt.core.clock import WallClock
    from beastbt.core.events import EventLog
    from beastbt.robot.profile import load_profile
    from beastbt.robot.robot_io import RobotIO
    from beastbt.parts.camera import attach_camera
    from beastbt.sim.camera_emulator import CameraEffects, SimCamera
    from beastbt.sim.floor import FloorMap
    from beastbt.sim.truth import RobotTruth

    floor = FloorMap.from_dict({"margin_m": 0.5, "lines": {"paths": [{"path": [[0, 0], [2, 0]]}]}}, np.random.default_rng(0))
    config = CameraConfig(fps=30.0)
    clock = WallClock()
    holder = {}

    def make_camera() -> Camera:
        cam = SimCamera(floor, pipeline.geometry, np.random.default_rng(0), CameraEffects.none())
        cam.update(RobotTruth(x=0.5, y=0.0, yaw=0.0))
        holder["cam"] = cam
        return Camera(cam.reopen, clock, config=config)

    pipeline = CameraPipeline(make_camera, config)
    pipeline.start_thread()
    try:
        got: list = []
        for _ in range(500):  # bounded wait for the thread's first frames
            got = pipeline.poll(clock.now()) or got
            if got:
                break
            threading.Event().wait(0.01)
        frame, obs = got
        assert frame.image.shape == (240, 320, 3) and obs.seen and abs(obs.offset_m) < 0.01
        assert pipeline.poll(clock.now()) in ([], [pipeline.latest[0], pipeline.latest[1].observation])
    finally:
        pipeline.close()
    assert pipeline._thread is None

    profile_text = (REPO / "robots" / "ugv_beast.yaml").read_text().replace("device: /dev/video0", "device: /dev/video_beastbt_missing")
    p = tmp_path / "beast.yaml"
    p.write_text(profile_text)
    events = EventLog(clock)
    io = RobotIO(base=None)  # type: ignore[arg-type]  # only the camera is attached here
    attach_camera(load_profile(p), io, clock, events)
    try:
        assert "camera" in io.capabilities and io.camera._thread is None  # nothing read until the run needs it
        io.camera.enable("follow_line")
        assert io.camera._thread is not None
        for _ in range(200):  # bounded wait for the thread's first attempt to open the device
            if any(e.kind == "camera_lost" for e in events.events):
                break
            threading.Event().wait(0.01)
        assert io.sensors["camera"](clock.now()) == []
        assert any(e.kind == "camera_lost" and "video_beastbt_missing" in e.text for e in events.events)
    finally:
        for close in io.closers:
            close()
