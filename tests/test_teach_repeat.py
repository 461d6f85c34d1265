"""Teach and repeat: beastbt route from-run writes the path a recorded run drove as a GPX route that a mission repeats."""

from __future__ import annotations

import os
import subprocess
import sys

from beastbt.estimation.geodesy import distance_m
from beastbt.mission.model import load_mission
from conftest import REPO


def beastbt(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], capture_output=True, text=True, timeout=180,
                          cwd=cwd, env=dict(os.environ, PYTHONPATH=str(REPO)))


def test_a_driven_run_becomes_a_route_that_a_mission_repeats(tmp_path):
    taught = tmp_path / "teach.yaml"
    taught.write_text(f"mission: teach\nworld: {REPO / 'worlds' / 'campus.yaml'}\nsteps:\n"
                      f"  - wait: 3 s\n  - drive: {{distance: 8 m, speed: 0.3 m/s}}\n  - turn: {{angle: 90 deg}}\n"
                      f"  - drive: {{distance: 6 m, speed: 0.3 m/s}}\n")
    # The drive never reads the position: without --record-sensors its GPS and EKF sleep, and nothing is taught.
    assert beastbt("run", str(taught), "--runs-dir", str(tmp_path / "asleep"), "--seed", "3").returncode == 0
    [asleep] = (tmp_path / "asleep").iterdir()
    refused = beastbt("route", "from-run", str(asleep), "--out", str(tmp_path / "none.gpx"))
    assert refused.returncode == 2 and "--record-sensors" in refused.stderr and "Traceback" not in refused.stderr
    assert beastbt("run", str(taught), "--runs-dir", str(tmp_path / "runs"), "--seed", "3",
                   "--record-sensors", "--record-images", "0").returncode == 0
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


def test_from_run_says_what_is_wrong(tmp_path):
    (tmp_path / "x.mcap").write_text("not a recording")
    done = beastbt("route", "from-run", str(tmp_path / "x.mcap"), "--out", str(tmp_path / "p.gpx"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    missing = beastbt("route", "from-run", str(tmp_path / "none"), "--out", str(tmp_path / "p.gpx"))
    assert missing.returncode == 2 and "no such run folder or file" in missing.stderr
    bad = beastbt("route", "from-run", str(tmp_path), "--every", "0 m")
    assert bad.returncode == 2 and "not a positive distance" in bad.stderr
