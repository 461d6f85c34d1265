"""The collision monitor below the tree: zones, approach, min_points, a silent LiDAR, driving away, events,
and the run's safety path (teleop and the mission alike) with scans fed through ``io.sensors['lidar']``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import jsonschema
import numpy as np
import pytest
import yaml

from beastbt.actuation.collision_monitor import (APPROACH, NONE, SILENT, SLOW, STOP, CollisionMonitor,
                                                 CollisionMonitorConfig, default_zones, inside_polygon)
from beastbt.blackboard.types import VelocityCommand
from beastbt.core.errors import InvalidInput
from beastbt.core.schema_check import load_schema
from beastbt.devices.lidar_scan import LaserScan, LidarMounting
from beastbt.robot.profile import load_profile
from beastbt.testing import MissionHarness

from conftest import REPO

R = 0.15       # footprint radius, m
VMAX = 0.5     # top speed, m/s
N = 450        # points per scan (an LD19 at 10 Hz)


def wall_scan(distance_m: float, stamp_s: float = 0.0, half_width_m: float = 1.0, bearing_deg: float = 0.0,
              n: int = N) -> LaserScan:
    """A straight wall ``distance_m`` from the LiDAR, facing it at ``bearing_deg``, in the LiDAR's frame."""
    angles = np.linspace(-math.pi, math.pi, n, endpoint=False)
    rel = angles - math.radians(bearing_deg)
    c = np.cos(rel)
    with np.errstate(divide="ignore"):
        ranges = np.where(c > 1e-6, distance_m / c, np.nan)
    ranges[np.abs(ranges * np.sin(rel)) > half_width_m] = np.nan
    return LaserScan(stamp_s, angles, ranges, np.full(n, 100.0), 10.0, "test")


def points_scan(points: list[tuple[float, float]], stamp_s: float = 0.0, n: int = N) -> LaserScan:
    """A scan with returns only at ``points`` ([x, y] in the LiDAR's frame, metres)."""
    angles = np.linspace(-math.pi, math.pi, n, endpoint=False)
    ranges = np.full(n, np.nan)
    for x, y in points:
        i = int(np.argmin(np.abs(np.angle(np.exp(1j * (angles - math.atan2(y, x)))))))
        angles[i] = math.atan2(y, x)
        ranges[i] = math.hypot(x, y)
    return LaserScan(stamp_s, angles, ranges, np.full(n, 100.0), 10.0, "test")


class Feed:
    """The narrow interface: ``latest_scan()`` gives whatever the test put there."""

    def __init__(self, scan: Optional[LaserScan] = None) -> None:
        self.scan = scan

    def __call__(self) -> Optional[LaserScan]:
        return self.scan


def monitor(scan: Optional[LaserScan] = None, mounting: Optional[LidarMounting] = None,
            **config: dict) -> tuple[CollisionMonitor, Feed, list]:
    events: list = []
    feed = Feed(scan)
    cfg = CollisionMonitorConfig.from_dict(config)
    m = CollisionMonitor(cfg, feed, R, VMAX, mounting, lambda kind, text: events.append((kind, text)))
    return m, feed, events


def cmd(v: float, w: float = 0.0, t: float = 0.0, source: str = "mission") -> VelocityCommand:
    return VelocityCommand(v, w, t, source)


# -- zones ------------------------------------------------------------------------------
def test_a_wall_inside_the_stop_zone_stops_a_forward_command_and_lets_its_turn_through():
    m, _, events = monitor(wall_scan(0.22))
    out = m.limit(cmd(0.3, 0.2), 0.05)
    # The travel stops; the turn in place brings no point closer to the circular footprint, and is what takes a
    # robot held beside a corner to where its arc is free.
    assert (out.linear_mps, out.angular_rps) == (0.0, 0.2)
    assert m.action == STOP
    assert m.limit(out, 0.1) == out and m.action == NONE  # the turn in place itself is not limited
    assert [k for k, _ in events] == ["collision_monitor"] and "stop" in events[0][1] and "0.22 m" in events[0][1]


def test_a_wall_in_the_slow_zone_scales_the_command_by_the_ratio():
    # Slow zone reaches 0.25 + 0.5 = 0.75 m ahead; at 0.3 m/s the approach check sees no contact within 1.2 s.
    m, _, _ = monitor(wall_scan(0.6), slow={"ratio": 0.4})
    out = m.limit(cmd(0.3, 0.1), 0.05)
    assert m.action == SLOW
    assert out.linear_mps == pytest.approx(0.12) and out.angular_rps == pytest.approx(0.04)
    clear, _, _ = monitor(wall_scan(0.9))
    assert clear.limit(cmd(0.3, 0.1), 0.05) == cmd(0.3, 0.1) and clear.action == NONE


def test_default_zones_grow_with_the_footprint_and_the_top_speed():
    stop, slow = default_zones(0.15, 0.5)
    assert stop[:, 0].max() == pytest.approx(0.15 + 0.05 + 0.05) and stop[:, 0].min() == pytest.approx(-0.25)
    assert stop[:, 1].max() == pytest.approx(0.18)
    assert slow[:, 0].max() == pytest.approx(0.25 + 0.5) and slow[:, 1].max() == pytest.approx(0.23)
    bigger_stop, bigger_slow = default_zones(0.3, 1.0)
    assert bigger_stop[:, 0].max() > stop[:, 0].max() and bigger_slow[:, 0].max() > slow[:, 0].max()
    assert bigger_stop[:, 1].max() > stop[:, 1].max()


def test_driving_along_a_wall_beside_the_footprint_is_not_stopped():
    # A wall parallel to the robot, 0.2 m to its left (0.05 m from the footprint): a corridor, a doorway's jamb.
    m, _, _ = monitor(wall_scan(0.2, bearing_deg=90.0, half_width_m=2.0), slow={"enabled": False})
    assert m.limit(cmd(0.3), 0.0) == cmd(0.3)
    assert m.limit(cmd(0.3, 1.0), 0.05).linear_mps < 0.3 and m.action == APPROACH   # turning into it is not


def test_the_profile_zones_replace_the_defaults():
    m, _, _ = monitor(wall_scan(0.5), stop={"polygon_m": [[0.6, 0.3], [0.0, 0.3], [0.0, -0.3], [0.6, -0.3]]})
    assert m.limit(cmd(0.2), 0.05).linear_mps == 0.0 and m.action == STOP


# -- approach --------------------------------------------------------------------------
def test_approach_scales_by_the_free_time_over_time_s():
    m, _, _ = monitor(wall_scan(0.6), slow={"enabled": False})
    out = m.limit(cmd(0.5), 0.05)
    # Contact once the centre is 0.45 m on: 0.9 s at 0.5 m/s; the last free step of 0.05 s is 0.9 s.
    assert m.action == APPROACH
    assert out.linear_mps == pytest.approx(0.5 * 0.9 / 1.2)


@pytest.mark.parametrize("stop_enabled", [False, True])
def test_approach_brings_the_robot_to_a_stop_before_the_wall(stop_enabled):
    wall_x = 1.5
    m, feed, _ = monitor(slow={"enabled": False}, stop={"enabled": stop_enabled})
    x, dt, out = 0.0, 0.05, cmd(0.5)
    gaps = []
    for k in range(600):  # 30 s of 20 Hz ticks, a fresh scan every tick
        feed.scan = wall_scan(wall_x - x, stamp_s=k * dt)
        out = m.limit(cmd(0.5, 0.0, k * dt), k * dt)
        x += out.linear_mps * dt
        gaps.append(wall_x - x - R)
    assert min(gaps) > 0.0                    # never touched
    assert out.linear_mps == 0.0              # and came to rest
    assert gaps[-1] < (0.12 if stop_enabled else 0.03)   # close to the wall: it was not stopped far away


def test_an_arc_that_curves_into_a_post_is_slowed_but_the_straight_line_past_it_is_not():
    post = [(0.4 + 0.01 * i, 0.4) for i in range(4)]   # ahead and to the left, outside the stop zone
    m, _, _ = monitor(points_scan(post), slow={"enabled": False})
    assert m.limit(cmd(0.5), 0.0).linear_mps == pytest.approx(0.5)
    arc = m.limit(cmd(0.5, 1.25), 0.0)   # a 0.4 m radius turn to the left runs through the post
    assert arc.linear_mps < 0.5 and m.action == APPROACH
    assert arc.angular_rps / arc.linear_mps == pytest.approx(1.25 / 0.5)   # the same arc, slower


# -- min_points --------------------------------------------------------------------------
def test_fewer_than_min_points_are_noise():
    two = [(0.2, 0.0), (0.21, 0.02)]
    m, _, events = monitor(points_scan(two))
    assert m.limit(cmd(0.3), 0.05) == cmd(0.3) and m.action == NONE and events == []
    m3, _, _ = monitor(points_scan(two + [(0.2, -0.03)]))
    assert m3.limit(cmd(0.3), 0.05).linear_mps == 0.0 and m3.action == STOP
    m1, _, _ = monitor(points_scan(two), min_points=2)
    assert m1.limit(cmd(0.3), 0.05).linear_mps == 0.0


# -- a silent LiDAR --------------------------------------------------------------------------
def test_a_stale_scan_holds_the_robot_with_one_event_and_it_goes_on_when_scans_return():
    m, feed, events = monitor(wall_scan(3.0, stamp_s=0.0))
    assert m.limit(cmd(0.3), 0.25) == cmd(0.3)           # 0.25 s old: fresh enough
    for k in range(10):
        out = m.limit(cmd(0.3, 0.5), 0.31 + 0.05 * k)    # older than 0.3 s
        assert (out.linear_mps, out.angular_rps) == (0.0, 0.0) and m.action == SILENT
    silent = [t for _, t in events if "silent" in t]
    assert len(silent) == 1 and "0.31 s" in silent[0]
    feed.scan = wall_scan(3.0, stamp_s=0.8)
    assert m.limit(cmd(0.3), 0.85) == cmd(0.3) and m.action == NONE
    assert len(events) == 2 and "back" in events[-1][1]


def test_no_scan_yet_holds_motion_but_says_nothing_while_standing_still():
    m, feed, events = monitor(None)
    assert m.limit(cmd(0.0), 0.0) == cmd(0.0) and events == []
    assert m.limit(cmd(0.2), 0.05).linear_mps == 0.0 and len(events) == 1
    feed.scan = wall_scan(3.0, stamp_s=0.1)
    assert m.limit(cmd(0.2), 0.12) == cmd(0.2)
    assert len(events) == 2 and "first LiDAR scan" in events[-1][1]


# -- driving away --------------------------------------------------------------------------
def test_reversing_or_turning_in_place_from_a_wall_ahead_is_let_through():
    m, _, events = monitor(wall_scan(0.2))
    assert m.limit(cmd(-0.2), 0.0) == cmd(-0.2) and m.action == NONE
    assert m.limit(cmd(0.0, 1.0), 0.05) == cmd(0.0, 1.0)
    assert m.limit(cmd(-0.2, 0.5), 0.1) == cmd(-0.2, 0.5)
    assert events == []
    assert m.limit(cmd(0.05), 0.15).linear_mps == 0.0     # but not a creep forward


def test_driving_forward_away_from_a_wall_behind_is_let_through_and_reversing_into_it_is_not():
    m, _, _ = monitor(wall_scan(0.2, bearing_deg=180.0))
    assert m.limit(cmd(0.3), 0.0) == cmd(0.3)
    assert m.limit(cmd(-0.3), 0.05).linear_mps == 0.0 and m.action == STOP


def test_inside_the_footprint_already_reversing_still_works():
    m, _, _ = monitor(wall_scan(0.1))   # closer than the footprint radius (bumped, or a wall that moved)
    assert m.limit(cmd(-0.1), 0.0) == cmd(-0.1)
    assert m.limit(cmd(0.1), 0.05).linear_mps == 0.0


# -- the mounting --------------------------------------------------------------------------
def test_points_are_moved_from_the_lidar_frame_to_base_link():
    backwards = LidarMounting(x_m=0.0, y_m=0.0, z_m=0.1, yaw_deg=180.0)
    m, _, _ = monitor(wall_scan(0.2, bearing_deg=180.0), mounting=backwards)   # behind the LiDAR = ahead of the robot
    assert m.limit(cmd(0.3), 0.0).linear_mps == 0.0
    assert m.limit(cmd(-0.3), 0.05) == cmd(-0.3)
    forward = LidarMounting(x_m=0.3, y_m=0.0, z_m=0.1, yaw_deg=0.0)   # 0.45 m from base_link: outside the stop zone
    m2, _, _ = monitor(wall_scan(0.15), mounting=forward, slow={"enabled": False}, approach={"enabled": False})
    assert m2.limit(cmd(0.3), 0.0) == cmd(0.3)


# -- events --------------------------------------------------------------------------
def test_each_action_is_one_event_per_episode():
    m, feed, events = monitor(wall_scan(0.6, stamp_s=0.0))
    t = 0.0
    for _ in range(20):                     # slow, many ticks
        feed.scan = wall_scan(0.6, stamp_s=t)
        m.limit(cmd(0.3), t)
        t += 0.05
    for _ in range(20):                     # then stop, many ticks
        feed.scan = wall_scan(0.2, stamp_s=t)
        m.limit(cmd(0.3), t)
        t += 0.05
    for _ in range(20):                     # the wall comes back into the slow zone: the same episode
        feed.scan = wall_scan(0.6, stamp_s=t)
        m.limit(cmd(0.3), t)
        t += 0.05
    assert [text.split(":")[1].strip().split(" ")[0] for _, text in events] == ["slow", "stop"]
    for _ in range(30):                     # 1.5 s clear: the episode ends
        feed.scan = wall_scan(3.0, stamp_s=t)
        m.limit(cmd(0.3), t)
        t += 0.05
    feed.scan = wall_scan(0.2, stamp_s=t)
    m.limit(cmd(0.3), t)
    assert len(events) == 3 and "stop" in events[-1][1]


def test_disabled_passes_everything():
    m, _, events = monitor(wall_scan(0.1), enabled=False)
    assert m.limit(cmd(0.3), 10.0) == cmd(0.3) and events == []


def test_a_concave_zone_holds_only_what_is_inside_it():
    # A U open to the front: a point in the notch is outside the zone, one in an arm is inside.
    u_zone = [[0.6, 0.3], [0.0, 0.3], [0.0, -0.3], [0.6, -0.3], [0.6, -0.2], [0.1, -0.2], [0.1, 0.2], [0.6, 0.2]]
    notch = [(0.35, 0.0), (0.36, 0.01), (0.37, -0.01)]
    arm = [(0.35, 0.25), (0.36, 0.26), (0.37, 0.24)]
    for points, held in ((notch, False), (arm, True)):
        m, _, _ = monitor(points_scan(points), stop={"polygon_m": u_zone}, slow={"enabled": False},
                          approach={"enabled": False})
        assert (m.limit(cmd(0.2), 0.0).linear_mps == 0.0) is held
    assert list(inside_polygon(np.array(notch + arm), np.array(u_zone))) == [False] * 3 + [True] * 3


# -- the profile --------------------------------------------------------------------------
SIM_PROFILE = (REPO / "robots" / "sim.yaml").read_text()


def no_lidar_profile(tmp_path: Path) -> Path:
    data = yaml.safe_load(SIM_PROFILE)
    data.pop("lidar", None)
    data.pop("collision_monitor", None)
    path = tmp_path / "no_lidar.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def lidar_profile(tmp_path: Path, monitor_yaml: str = "") -> Path:
    text = SIM_PROFILE
    if "\nlidar:" not in text:
        text += "\nlidar: {type: ld19, port: /dev/null}\n"
    path = tmp_path / "lidar_robot.yaml"
    path.write_text(text + monitor_yaml)
    return path


def test_the_profile_section_takes_units_and_a_bad_value_names_its_line(tmp_path):
    from beastbt.core.events import EventLog
    from beastbt.core.clock import SimClock
    from beastbt.run.safety import guard_collisions
    path = lidar_profile(tmp_path, "collision_monitor: {source_timeout_s: 300 ms, approach: {time_s: 800 ms}}\n")
    m = guard_collisions(load_profile(path), EventLog(SimClock()), Feed())
    assert m is not None and m.config.source_timeout_s == pytest.approx(0.3)
    assert m.config.approach.time_s == pytest.approx(0.8)
    bad = lidar_profile(tmp_path, "collision_monitor: {min_points: 0}\n")
    with pytest.raises(InvalidInput) as err:
        load_profile(bad)
    text = str(err.value)
    assert "lidar_robot.yaml:" in text and "min_points" in text and "Traceback" not in text
    off = lidar_profile(tmp_path, "collision_monitor: {enabled: false}\n")
    assert guard_collisions(load_profile(off), EventLog(SimClock()), Feed()) is None
    assert guard_collisions(load_profile(no_lidar_profile(tmp_path)), EventLog(SimClock()), Feed()) is None


# -- through the run's safety path --------------------------------------------------------------
WALL_X = 1.2
WAIT = """
mission: t
steps:
  - wait: 20 s
"""
DRIVE = """
mission: t
steps:
  - drive: {distance: 3 m, speed: 0.3 m/s}
"""


def fake_lidar(h: MissionHarness, period_s: float = 0.1, silent_after_s: float = math.inf):
    """A LiDAR on ``io.sensors['lidar']`` that sees a wall across the world at x = WALL_X (from the true pose)."""
    state = {"next": 0.0}
    angles = np.linspace(-math.pi, math.pi, N, endpoint=False)

    def poll(now_s: float) -> list:
        if now_s + 1e-9 < state["next"] or now_s > silent_after_s:
            return []
        state["next"] = now_s + period_s
        truth = h.truth
        c = np.cos(truth.yaw + angles)
        with np.errstate(divide="ignore"):
            ranges = np.where(c > 1e-6, (WALL_X - truth.x) / c, np.nan)
        ranges[ranges > 12.0] = np.nan
        return [LaserScan(now_s, angles.copy(), ranges, np.full(N, 100.0), 10.0, "fake")]

    h.run.io.sensors["lidar"] = poll


def monitor_events(h: MissionHarness) -> list[str]:
    return [e.text for e in h.events if e.kind == "collision_monitor"]


def test_the_mission_is_stopped_before_the_wall_through_the_run(tmp_path):
    h = MissionHarness.from_yaml(DRIVE, robot=str(lidar_profile(tmp_path)))
    assert h.run.collision_monitor is not None and "lidar" in h.run.reads()
    fake_lidar(h)
    h.tick_until(lambda h: h.now_s >= 8.0)
    assert h.result != "success"                              # the drive cannot finish: the wall is in the way
    assert WALL_X - h.truth.x > 0.15                          # the footprint never reached the wall
    assert WALL_X - h.truth.x < 0.5                           # and it got close (not stopped far away)
    assert abs(h.truth.v_mps) < 0.01
    texts = monitor_events(h)
    assert any("mission's command" in t for t in texts)
    assert len(texts) == len(set(texts)) and len(texts) <= 3  # once per action, not every tick
    summary = h.summary()
    jsonschema.validate(summary, load_schema("summary.schema.json"))
    fields = summary["collision_monitor"]
    assert fields["episodes"]["stop"] == 1 and fields["limited_ticks"]["stop"] > 20
    assert fields["zones"]["footprint_radius_m"] == pytest.approx(0.15) and len(fields["zones"]["stop"]) == 4


def test_teleop_is_limited_too(tmp_path):
    # The operator's gamepad (a joystick script through the real driver and the teleop part) pushes full ahead.
    script = [{"at": "0.2 s", "press": "enable"}, {"at": "0.2 s", "linear": 1.0},
              {"at": "8 s", "linear": -0.6}, {"at": "10 s", "release": "enable"}]
    h = MissionHarness.from_yaml(WAIT, robot=str(lidar_profile(tmp_path)), joystick=script)
    fake_lidar(h)
    h.tick_until(lambda h: h.now_s >= 7.9)
    assert h.records[-1].mux_source == "teleop" and h.records[-1].cmd_mux.linear_mps > 0.2
    assert WALL_X - h.truth.x > 0.15 and abs(h.truth.v_mps) < 0.01 and h.records[-1].cmd_gate.linear_mps == 0.0
    assert any(t.startswith("collision monitor: stop (teleop's command)") for t in monitor_events(h))
    x = h.truth.x
    h.tick_until(lambda h: h.now_s >= 9.5)   # the stick pulled back: backing away is let through at once
    assert h.truth.x < x - 0.1


def test_a_lidar_that_goes_silent_stops_the_run_and_it_goes_on_when_it_returns(tmp_path):
    h = MissionHarness.from_yaml(DRIVE, robot=str(lidar_profile(tmp_path)))
    fake_lidar(h, silent_after_s=1.0)
    h.tick_until(lambda h: h.now_s >= 2.5)
    assert abs(h.truth.v_mps) < 0.01 and h.run.collision_monitor.action == SILENT
    x = h.truth.x
    assert sum("silent" in t for t in monitor_events(h)) == 1
    fake_lidar(h)   # scans again
    h.tick_until(lambda h: h.now_s >= 3.5)
    assert h.truth.x > x + 0.05
    assert any("back" in t for t in monitor_events(h))


def test_without_lidar_readings_the_run_says_the_monitor_is_off(tmp_path):
    h = MissionHarness.from_yaml(DRIVE, robot=str(lidar_profile(tmp_path)))
    h.run.io.sensors.pop("lidar", None)
    h.tick(5)
    assert h.truth.v_mps > 0.0 or h.records[-1].cmd_gate.linear_mps > 0.0
    assert monitor_events(h) == ["collision monitor: off: this run has no LiDAR readings (io.sensors['lidar'])"]


def test_a_robot_without_lidar_has_no_monitor(tmp_path):
    h = MissionHarness.from_yaml(DRIVE, robot=str(no_lidar_profile(tmp_path)))
    assert h.run.collision_monitor is None and "lidar" not in h.run.reads()
    h.tick(10)
    assert h.records[-1].cmd_gate.linear_mps > 0.0 and monitor_events(h) == []
