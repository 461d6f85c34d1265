"""What ``beastbt run`` prints at the end: collisions and clearance when there is something to hit or a LiDAR to
see it, and arrivals that say they are judged on the estimate (issue 37, item 7)."""

from __future__ import annotations

import os
import subprocess
import sys

from beastbt.run.summary import human_summary, waypoint_text
from conftest import REPO


def summary(**extra) -> dict:
    base = {"mission": "m", "status": "success", "sim_time_s": 10.0, "wall_time_s": 1.0, "ticks": 200,
            "distance_m": 3.0, "max_speed_mps": 0.3, "waypoints": [], "events": []}
    base.update(extra)
    return base


def test_collisions_and_clearance_show_with_obstacles_or_a_lidar():
    walls = summary(truth={"collisions": 1, "min_clearance_m": 0.0})
    assert "  obstacles: 1 collision, least clearance 0.00 m (truth)" in human_summary(walls).splitlines()
    lidar = summary(truth={"collisions": 0, "min_clearance_m": None}, collision_monitor={"episodes": {"stop": 2}})
    assert "  obstacles: 0 collisions (truth); collision monitor: stop 2" in human_summary(lidar).splitlines()
    robot = summary(collision_monitor={"episodes": {}})  # a real robot with a LiDAR: no truth
    assert "  obstacles: collision monitor: never acted" in human_summary(robot).splitlines()
    open_field = summary(truth={"collisions": 0, "min_clearance_m": None})  # nothing to hit, nothing to see it
    assert "obstacles" not in human_summary(open_field)


def test_an_arrival_says_it_is_judged_on_the_estimate_and_how_far_it_truly_was():
    wp = {"name": "a", "lat": 40.0, "lon": -3.0, "reached": True, "arrival_error_m": 2.64, "time_s": 31.5,
          "tolerance_m": 2.0, "estimated_error_m": 1.93}
    line = next(x for x in human_summary(summary(waypoints=[wp], truth={})).splitlines() if "waypoint a" in x)
    assert line == ("  waypoint a: reached at 31.5 s (arrival is judged on the estimate: 1.93 m off by the estimate, "
                    "tolerance 2.00 m); truly 2.64 m off (beyond the tolerance by the estimate's own error)")
    robot = human_summary(summary(waypoints=[dict(wp, arrival_error_m=1.93)]))  # no truth: the estimate's only
    assert "truly" not in robot and "1.93 m off by the estimate" in robot
    assert waypoint_text("b", False, 2.0, None, None, None) == "b: NOT reached"


def test_beastbt_run_prints_the_obstacles_of_a_world_with_walls(tmp_path):
    mission = tmp_path / "wait.yaml"
    mission.write_text(f"mission: wait\nworld: {REPO / 'worlds' / 'corridor.yaml'}\nsteps:\n  - wait: 1 s\n")
    done = subprocess.run([sys.executable, "-m", "beastbt", "run", str(mission), "--no-record"], capture_output=True,
                          text=True, timeout=180, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert done.returncode == 0, done.stderr
    assert any(line.startswith("  obstacles: 0 collisions, least clearance ") and "collision monitor" in line
               for line in done.stdout.splitlines()), done.stdout


def test_docks_photos_and_alerts_are_said_at_the_end():
    # The summary held them (vision, alerts) but the lines printed at the end said nothing of them.
    dock = {"tag": 0, "time_s": 44.65, "status": "docked", "retries": 1, "distance_m": 0.25, "error_m": 0.0045,
            "error_deg": 0.04, "truth": {"error_m": 0.2295, "error_deg": 0.13}}
    lines = human_summary(summary(truth={}, vision={"docks": [dock, {"tag": 5, "time_s": 60.0, "status": "failed"}],
                                                    "photos": [{"name": "gate"}, {"name": "alert-1"}]},
                                  alerts=[{"time_s": 3.0, "text": "a"}, {"time_s": 28.0, "text": "someone walks"}]))
    assert lines.splitlines()[3:] == [
        "  dock at tag 0: docked at 44.6 s, 0.4 cm and 0.0 deg off the goal by the estimate; truly 22.9 cm and 0.1 deg "
        "(after 1 retry)",
        "  dock at tag 5: failed at 60.0 s",
        "  photos: 2 (gate, alert-1)",
        "  alerts: 2, the last at 28.0 s: someone walks"]
    assert "photos" not in human_summary(summary(vision={"photos": [], "docks": []}))
