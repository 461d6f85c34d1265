"""Teach and repeat: beastbt route from-run writes the path a recorded run drove as a GPX route that a mission repeats."""

from __future__ import annotations

import math
import os
import subprocess
import sys

from beastbt.estimation.geodesy import distance_m
from beastbt.mission.model import load_mission
from beastbt.sim.world import load_world
from conftest import REPO


def beastbt(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, timeout=180,
                          cwd=cwd, env=dict(os.environ, PYTHONPATH=str(REPO)))


def test_a_driven_run_becomes_a_route_that_a_mission_repeats(tmp_path):
    taught = tmp_path / "teach.yaml"
    taught.write_text(f"mission: teach\nworld: {REPO / 'worlds' / 'campus.yaml'}\nsteps:\n"
                      f"  - wait: 3 s\n  - drive: {{distance: 8 m, speed: 0.3 m/s}}\n  - turn: {{angle: 90 deg}}\n"
                      f"  - drive: {{distance: 6 m, speed: 0.3 m/s}}\n")
    # No flag: the drive never reads the position, and the recording keeps where the robot was all the same.
    assert beastbt("run", str(taught), "--runs-dir", str(tmp_path / "runs"), "--seed", "3").returncode == 0
    [run] = (tmp_path / "runs").iterdir()
    done = beastbt("route", "from-run", str(run), "--every", "2 m", "--out", str(tmp_path / "path.gpx"))
    assert done.returncode == 0, done.stderr
    assert "of the fused path" in done.stdout
    repeat = tmp_path / "repeat.yaml"
    repeat.write_text(f"mission: repeat\nworld: {REPO / 'worlds' / 'campus.yaml'}\nsteps:\n"
                      f"  - route: {{file: path.gpx}}\n")
    mission = load_mission(repeat)
    points = [mission.places[name] for name in mission.steps[0].places]
    assert 6 <= len(points) <= 10  # about 14 m of driving, one point every 2 m
    gaps = [distance_m(a.lat, a.lon, b.lat, b.lon) for a, b in zip(points, points[1:])]
    assert all(g >= 2.0 for g in gaps[:-1]) and max(gaps) < 4.0
    corner = max(range(1, len(points) - 1), key=lambda i: abs(
        distance_m(points[0].lat, points[0].lon, points[i].lat, points[i].lon)
        + distance_m(points[i].lat, points[i].lon, points[-1].lat, points[-1].lon)
        - distance_m(points[0].lat, points[0].lon, points[-1].lat, points[-1].lon)))
    assert distance_m(points[0].lat, points[0].lon, points[corner].lat, points[corner].lon) > 5.0  # the L is kept


def test_a_joystick_drive_without_flags_is_taught_where_it_truly_went(tmp_path):
    """Teach by hand: a scripted joystick drives an L on the simulator; the plain recorded run becomes a route whose
    points lie on the true path (the simulator's), and whose GPS fixes were recorded at the receiver's rate."""
    from beastbt.recording.reader import read_recording
    from beastbt.estimation.geodesy import LocalFrame
    stick = tmp_path / "drive.yaml"
    stick.write_text("- {at: 1 s, press: enable}\n- {at: 1.5 s, linear: 0.8, angular: 0}\n"
                     "- {at: 31 s, linear: 0, angular: 0.6}\n- {at: 34 s, linear: 0.8, angular: 0}\n"
                     "- {at: 54 s, linear: 0, angular: 0}\n- {at: 55 s, release: enable}\n")
    mission = tmp_path / "by_hand.yaml"
    mission.write_text(f"mission: by_hand\nworld: {REPO / 'worlds' / 'campus.yaml'}\nsteps:\n"
                       f"  - teleop: {{until: released}}\n")
    ran = beastbt("run", str(mission), "--joystick", str(stick), "--runs-dir", str(tmp_path / "runs"), "--seed", "5")
    assert ran.returncode == 0, ran.stdout + ran.stderr
    [run] = (tmp_path / "runs").iterdir()
    rec = read_recording(run / "run.mcap", topics=("/sensors/gps", "/sensors/imu", "/estimate/fused", "/truth"))
    fixes = rec.topic("/sensors/gps")
    assert len({m.get("time_utc") for m in fixes}) >= 40  # the 1 Hz receiver's epochs over ~55 s, every one
    assert not rec.topic("/sensors/imu")  # the IMU still sleeps (and the base's samples nobody reads are left out)
    fused = [m for m in rec.topic("/estimate/fused") if m.get("position_valid")]
    assert len(fused) >= 50  # at least once a second while the robot drove (more: at pose_rate_hz)
    done = beastbt("route", "from-run", str(run), "--every", "2 m", "--out", str(tmp_path / "path.gpx"))
    assert done.returncode == 0, done.stderr
    assert "of the fused path" in done.stdout
    repeat = tmp_path / "repeat.yaml"
    repeat.write_text(f"mission: repeat\nworld: {REPO / 'worlds' / 'campus.yaml'}\nsteps:\n"
                      f"  - route: {{file: path.gpx}}\n")
    points = [p for p in load_mission(repeat).places.values()]
    assert len(points) >= 8
    world = load_world(REPO / "worlds" / "campus.yaml")
    frame = LocalFrame(world.frame.lat0_deg, world.frame.lon0_deg, world.frame.alt0_m)
    truth = [(m["x"], m["y"]) for m in rec.topic("/truth")]
    for p in points:  # every taught point lies near where the robot truly drove
        e, n, _ = frame.to_enu(p.lat, p.lon)
        assert min(math.hypot(e - x, n - y) for x, y in truth) < 3.0, (e, n)


def test_from_run_says_what_is_wrong(tmp_path):
    (tmp_path / "x.mcap").write_text("not a recording")
    done = beastbt("route", "from-run", str(tmp_path / "x.mcap"), "--out", str(tmp_path / "p.gpx"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    missing = beastbt("route", "from-run", str(tmp_path / "none"), "--out", str(tmp_path / "p.gpx"))
    assert missing.returncode == 2 and "no such run folder or file" in missing.stderr
    bad = beastbt("route", "from-run", str(tmp_path), "--every", "0 m")
    assert bad.returncode == 2 and "not a positive distance" in bad.stderr
