"""Each action of the language, ticked on the simulator: when it runs, succeeds and fails."""

from __future__ import annotations

import math

import pytest

from beastbt.testing import MissionHarness


def mission(steps: str, extra: str = "") -> MissionHarness:
    return MissionHarness.from_yaml(f"mission: t\n{extra}steps:\n{steps}")


def test_drive_distance_covers_it_and_stops():
    h = mission("  - drive: {distance: 1.5 m, speed: 0.2 m/s}\n")
    for _ in range(20):  # the collision monitor holds motion until the LiDAR's first scans (1 s at most)
        h.tick()
    assert h.status_of("drive 1.5 m at 0.2 m/s") == "RUNNING"
    assert h.last_sent.linear_mps > 0
    assert h.run_to_end(30) == "success"
    assert math.hypot(h.truth.x, h.truth.y) == pytest.approx(1.5, abs=0.05)
    assert h.wire[-1] == {"T": 1, "L": 0.0, "R": 0.0}


def test_drive_backwards_with_negative_distance():
    h = mission("  - drive: {distance: -0.5 m, speed: 0.1 m/s}\n")
    assert h.run_to_end(30) == "success"
    assert h.truth.x == pytest.approx(-0.5, abs=0.03)
    assert min(c.linear_mps for c in h.sent) < 0


def test_drive_never_exceeds_its_speed_or_the_mission_limit():
    h = mission("  - drive: {distance: 2 m, speed: 0.3 m/s}\n", "limits: {speed: 0.1 m/s}\n")
    assert h.run_to_end(60) == "success"
    assert max(c.linear_mps for c in h.sent) <= 0.1 + 1e-9


def test_drive_blocked_by_a_wall_fails_after_stuck_after(tmp_path):
    (tmp_path / "w.yaml").write_text("world: w\nwalls: [[1.0, -2, 1.0, 2]]\n")
    h = MissionHarness.from_yaml("mission: t\nworld: w.yaml\nsteps:\n  - drive: {distance: 3 m, stuck_after: 2 s}\n",
                                 base_dir=tmp_path)
    assert h.run_to_end(60) == "failure"
    failed = [e for e in h.events if e.kind == "step_failed"]
    assert failed and "blocked" in failed[0].text
    assert h.truth.x < 1.0
    assert h.last_sent.is_zero()


def test_drive_for_a_time():
    h = mission("  - drive: {time: 2 s, speed: 0.1 m/s}\n")
    h.tick(20)
    assert h.status_of("drive for 2 s at 0.1 m/s") == "RUNNING"
    assert h.run_to_end(10) == "success"
    assert h.now_s == pytest.approx(2.05, abs=0.06)


@pytest.mark.parametrize("angle", [90, -90, 180, 270])
def test_turn_by_angle_within_3_deg_of_odometry(angle):
    h = mission(f"  - turn: {{angle: {angle} deg}}\n")
    assert h.run_to_end(60) == "success"
    turned = math.degrees(h.blackboard("pose_odom").yaw)
    expected = (angle + 180) % 360 - 180
    assert abs((turned - expected + 180) % 360 - 180) <= 3.0
    # Positive is to the left (counter-clockwise): the first command has the sign of the angle.
    first = next(c for c in h.sent if c.angular_rps != 0)
    assert math.copysign(1, first.angular_rps) == math.copysign(1, angle)


BARE = ("robot: bare\ngeometry: {track_width_m: 0.17}\nlimits: {max_speed_mps: 0.3, max_turn_rate_dps: 90}\n"
        "base: {type: waveshare_serial, gimbal: false}\n")


def test_turn_to_heading_fails_without_a_heading_estimate(tmp_path):
    (tmp_path / "bare.yaml").write_text(BARE)
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - turn: {heading: 90 deg, stuck_after: 2 s}\n",
                                 robot=str(tmp_path / "bare.yaml"))
    h.tick(10)
    assert h.status_of("turn to heading 90 deg") == "RUNNING"   # waits for an estimate first
    assert h.run_to_end(10) == "failure"
    assert h.now_s == pytest.approx(2.0, abs=0.1)
    assert any("no heading" in e.text for e in h.events)
    assert all(c.is_zero() for c in h.sent)


@pytest.mark.parametrize("heading,yaw", [(0, 90), (180, -90), (270, 180)])
def test_turn_to_compass_heading_with_the_simulated_compass(heading, yaw):
    h = mission(f"  - turn: {{heading: {heading} deg}}\n")
    assert h.run_to_end(30) == "success"
    err = (math.degrees(h.truth.yaw) - yaw + 180) % 360 - 180
    assert abs(err) <= 5.0   # 3 deg on the estimate, plus the estimate's own error


def test_wait_stands_still_for_its_time():
    h = mission("  - wait: 1 s\n")
    h.tick(10)
    assert h.status_of("wait 1 s") == "RUNNING"
    assert h.run_to_end(5) == "success"
    assert all(c.is_zero() for c in h.sent)


def test_stop_waits_until_still():
    h = mission("  - drive: {time: 1 s, speed: 0.3 m/s}\n  - stop\n")
    h.tick_until(lambda h: h.status_of("stop") == "RUNNING", 5)
    assert abs(h.truth.v_mps) > 0.05
    assert h.run_to_end(10) == "success"
    assert abs(h.truth.v_mps) < 0.02


def test_look_moves_the_gimbal_through_the_base_protocol():
    h = mission("  - look: {pan: -45 deg, tilt: 10 deg}\n")
    assert h.run_to_end(5) == "success"
    gimbal = [c for c in h.wire if c.get("T") == 133]
    assert gimbal[-1]["X"] == 45.0 and gimbal[-1]["Y"] == 10.0   # the base's pan is negative to the left
    assert math.degrees(h.truth.pan_rad) == pytest.approx(-45.0)
    assert h.now_s == pytest.approx(0.55, abs=0.06)   # the default settle time


def test_servo_that_does_not_exist_fails():
    h = mission("  - servo: {name: gripper, angle: 30 deg}\n")
    assert h.run_to_end(5) == "failure"
    assert any("no servo named 'gripper'" in e.text for e in h.events)


def test_say_reaches_the_events_at_once():
    h = mission("  - say: \"Reached the door\"\n")
    assert h.tick() == "success"
    assert [e.text for e in h.events if e.kind == "say"] == ["Reached the door"]


def test_steps_needing_missing_parts_fail_clearly(tmp_path):
    profile = tmp_path / "bare.yaml"
    profile.write_text("robot: bare\ngeometry: {track_width_m: 0.2}\nlimits: {max_speed_mps: 0.3, max_turn_rate_dps: 90}\n"
                       "base: {type: waveshare_serial, gimbal: false}\n")
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - snapshot: {name: door}\n", robot=str(profile))
    h.run_to_end(5)
    assert h.result == "failure"
    assert any("not available on this robot" in e.text and "no camera" in e.text for e in h.events)
    h = MissionHarness.from_yaml("mission: t\nsteps:\n  - look: {pan: 10 deg}\n", robot=str(profile))
    assert h.run_to_end(5) == "failure"
