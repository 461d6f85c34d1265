"""go_to on the simulated robot: the emulated GPS and IMU, the real drivers and the EKF, tick by tick."""

from __future__ import annotations

import math

from nav_support import events_of, harness, latlon, place_yaml, robot_without_lidar, true_distance_m


def test_go_to_a_place_finds_the_heading_then_arrives_within_its_tolerance(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  p: {place_yaml(3.0, 16.0, "3 m")}
steps:
  - go_to: p
""")
    node = "go_to p (within 3 m)"
    h.tick()
    assert h.status_of(node) == "RUNNING"
    assert h.node(node).feedback_message == "waiting for a GPS fix"
    assert h.sent[-1].is_zero()
    # Without a magnetometer the heading is unknown: it drives straight ahead to find it.
    assert h.tick_until(lambda h: "finding the heading" in h.node(node).feedback_message, timeout_s=5)
    assert not h.blackboard("pose").heading_valid
    assert h.tick_until(lambda h: h.blackboard("pose").heading_valid, timeout_s=90)
    assert h.run_to_end(timeout_s=200) == "success"
    pose = h.blackboard("pose")
    assert pose.position_valid and pose.lat is not None
    assert true_distance_m(h, 3.0, 16.0) < 3.0 + 1.5       # within tolerance, give or take the fused error
    assert max(c.linear_mps for c in h.sent) <= 0.2 + 1e-9   # the default go_to speed
    wp = h.summary()["waypoints"]
    assert len(wp) == 1 and wp[0]["name"] == "p" and wp[0]["reached"]
    assert wp[0]["lat"] == round(latlon(3.0, 16.0)[0], 8)
    assert abs(wp[0]["arrival_error_m"] - true_distance_m(h, 3.0, 16.0)) < 0.05  # the true error, at arrival


def test_go_to_coordinates_honours_the_step_tolerance_and_speed(tmp_path):
    lat, lon = latlon(0.0, 14.0)
    h = harness(tmp_path, f"""
mission: t
steps:
  - go_to: {{lat: {lat:.8f}, lon: {lon:.8f}, tolerance: 1 m, speed: 0.3 m/s}}
""")
    name = f"go_to {lat:.6f}, {lon:.6f} (within 1 m)"
    assert h.run_to_end(timeout_s=200) == "success"
    assert h.status_of(name) == "SUCCESS"
    assert "reached" in h.node(name).feedback_message
    assert max(c.linear_mps for c in h.sent) > 0.25           # the step's speed, not the default 0.2
    assert true_distance_m(h, 0.0, 14.0) < 1.0 + 1.5


def test_a_target_behind_is_turned_to_in_place_and_slowed_for_on_approach(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 14.0)}
  b: {place_yaml(0.0, 2.0)}
steps:
  - go_to: a
  - go_to: b
""")
    assert h.tick_until(lambda h: h.status_of("go_to a (within 2 m)") == "SUCCESS", timeout_s=200)
    start = len(h.records)
    assert h.run_to_end(timeout_s=200) == "success"
    leg = [r.cmd_mission for r in h.records[start:] if r.cmd_mission is not None]
    # b is behind: the first commands turn in place, no forward speed at all
    first = leg[:10]
    assert all(c.linear_mps == 0.0 and abs(c.angular_rps) >= 0.2 for c in first)
    # and the leg ends slowly: the last moving commands are slower than the cruise
    moving = [c.linear_mps for c in leg if c.linear_mps > 0]
    assert max(moving) == 0.2 and min(moving[-5:]) < 0.15
    assert true_distance_m(h, 0.0, 2.0) < 2.0 + 1.5


def test_go_to_fails_when_a_wall_blocks_it(tmp_path):
    # Without a LiDAR the wall is only felt: no progress (with one, the step is blocked: test_nav_obstacles.py).
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 14.0)}
  b: {place_yaml(12.0, 14.0)}
steps:
  - go_to: a
  - go_to: {{place: b, stuck_after: 3 s}}
""", walls=[[5.0, 5.0, 5.0, 25.0]], robot=robot_without_lidar(tmp_path))
    assert h.run_to_end(timeout_s=300) == "failure"
    assert h.status_of("go_to a (within 2 m)") == "SUCCESS"
    failed = events_of(h, "step_failed")
    assert len(failed) == 1 and "go_to b" in failed[0].text and "stuck: no progress for 3 s" in failed[0].text
    assert h.run.io.sim.drive.blocked or h.truth.x > 4.0      # it pushed against the wall
    wp = h.summary()["waypoints"]
    assert [(w["name"], w["reached"]) for w in wp] == [("a", True), ("b", False)]
    assert wp[1]["arrival_error_m"] is None


def test_go_to_without_any_fix_fails_after_its_gps_timeout_without_moving(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 10.0)}
steps:
  - go_to: {{place: a, gps_timeout: 4 s}}
""", gps={"cold_start_s": 1000})
    assert h.run_to_end(timeout_s=30) == "failure"
    assert 4.0 <= h.now_s <= 4.5
    assert "no GPS fix for 4 s" in events_of(h, "step_failed")[0].text
    assert all(c.is_zero() for c in h.sent)
    assert h.summary()["waypoints"] == [{"name": "a", "lat": round(latlon(0, 10)[0], 8),
                                         "lon": round(latlon(0, 10)[1], 8), "reached": False,
                                         "arrival_error_m": None, "time_s": h.summary()["waypoints"][0]["time_s"],
                                         "tolerance_m": 2.0, "estimated_error_m": None}]


def test_losing_the_fix_while_driving_dead_reckons_then_fails_after_the_timeout(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  far: {place_yaml(0.0, 60.0)}
steps:
  - go_to: far
""", gps={"dropouts_s": [[30.0, 1000.0]]})
    assert h.tick_until(lambda h: h.now_s >= 35.0, timeout_s=40)
    assert h.sent[-1].linear_mps > 0.1                       # still driving on the fused estimate, 5 s later
    assert h.run_to_end(timeout_s=60) == "failure"
    assert 39.0 <= h.now_s <= 40.5                            # the last fix at 29 s, then 10 s (the default)
    assert "no GPS fix for 10 s" in events_of(h, "step_failed")[0].text
    assert "gps_fix_lost" in [e.kind for e in h.events]


def test_turn_to_a_compass_heading_works_once_driving_gave_the_heading(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 14.0)}
steps:
  - go_to: a
  - turn: {{heading: 90 deg}}
""")
    assert h.run_to_end(timeout_s=200) == "success"
    assert h.status_of("turn to heading 90 deg") == "SUCCESS"
    # compass 90 deg is east: yaw 0 in ENU; the fused heading is good to a few degrees
    assert abs(math.degrees(h.truth.yaw)) < 8.0


def test_gps_fix_and_near_conditions_use_the_real_fixes(tmp_path):
    h = harness(tmp_path, f"""
mission: t
places:
  a: {place_yaml(0.0, 14.0, "2 m")}
steps:
  - wait_until: gps_fix
    timeout: 5 s
  - if: {{near: a, within: 3 m}}
    then: [say: "already there"]
    else: [say: "far from a"]
  - go_to: a
  - if: {{near: a, within: 3 m}}
    then: [say: "near a"]
    else: [say: "not near a"]
""", gps={"cold_start_s": 2.0})
    assert h.run_to_end(timeout_s=200) == "success"
    said = [e.text for e in events_of(h, "say")]
    assert said == ["far from a", "near a"]
    waited = h.node("wait until gps_fix (at most 5 s)")
    assert waited.status.name == "SUCCESS"
    assert events_of(h, "gps_fix_acquired")[0].time_s >= 2.0
