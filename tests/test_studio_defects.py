"""Four defects found by the hidden language checks (issue 23, item 6), each pinned here.

1. ``beastbt run MISSION --summary S | head -n 0``: a reader gone before the
   first write must not cut the run short.
2. ``beastbt validate`` warns about a speed above the robot's top speed (the
   default robot, or ``--robot``), as ``run`` does.
3. A keep-out stop's reason names the fence.
4. ``beastbt route from-run RUN --every 2 m`` (unquoted, as the README writes
   it) is accepted, as ``--max-time 10 min`` is.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from beastbt.estimation.geodesy import LocalFrame
from beastbt.testing import MissionHarness
from conftest import REPO

CAMPUS = REPO / "worlds" / "campus.yaml"


def beastbt(*args: str, stdout: object = subprocess.PIPE) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "beastbt", *args], stdout=stdout, stderr=subprocess.PIPE,
                          text=True, timeout=180, env=dict(os.environ, PYTHONPATH=str(REPO)))


def run_into_a_closed_pipe(*args: str) -> subprocess.CompletedProcess:
    """``beastbt run ARGS`` with its standard output a pipe whose reader has gone before the first write."""
    read, write = os.pipe()
    os.close(read)  # as 'head -n 0' does: it exits before reading anything
    try:
        return beastbt("run", *args, stdout=write)
    finally:
        os.close(write)


def test_a_run_whose_reader_is_gone_still_writes_its_summary_and_recording_and_exits_with_its_status(tmp_path):
    drive = tmp_path / "drive.yaml"
    drive.write_text(f"mission: drive\nworld: {CAMPUS}\nsteps:\n  - wait: 2 s\n"
                     f"  - drive: {{distance: 5 m, speed: 0.3 m/s}}\n", encoding="utf-8")
    done = run_into_a_closed_pipe(str(drive), "--summary", str(tmp_path / "s.json"), "--runs-dir",
                                  str(tmp_path / "runs"), "--seed", "1", "--max-time", "10", "min",
                                  "--record-sensors")  # the route below is taught from its GPS positions
    assert done.returncode == 0, done.stderr
    assert "BrokenPipe" not in done.stderr and "Traceback" not in done.stderr
    summary = json.loads((tmp_path / "s.json").read_text(encoding="utf-8"))
    assert summary["status"] == "success" and summary["distance_m"] > 4.5
    [run] = (tmp_path / "runs").iterdir()
    assert (run / "run.mcap").stat().st_size > 0 and json.loads((run / "summary.json").read_text())["status"] == \
        "success"
    # 4. the same run, taught as a route with '--every 2 m' unquoted: the same GPX as quoted
    unquoted = beastbt("route", "from-run", str(run), "--every", "2", "m", "--out", str(tmp_path / "a.gpx"))
    assert unquoted.returncode == 0, unquoted.stderr
    quoted = beastbt("route", "from-run", str(run), "--every", "2 m", "--out", str(tmp_path / "b.gpx"))
    assert quoted.returncode == 0 and (tmp_path / "a.gpx").read_text() == (tmp_path / "b.gpx").read_text()
    assert (tmp_path / "a.gpx").read_text().count("<rtept") >= 3
    wrong = beastbt("route", "from-run", str(run), "--every", "2", "metres", "--out", str(tmp_path / "c.gpx"))
    assert wrong.returncode == 2 and "did you mean '2 m'" in wrong.stderr  # a unit's spelling gets its hint


def test_a_failed_run_into_a_closed_pipe_exits_1_with_its_summary(tmp_path):
    far = tmp_path / "far.yaml"
    far.write_text("mission: far\nsteps:\n  - drive: {distance: 50 m, speed: 0.3 m/s}\n", encoding="utf-8")
    done = run_into_a_closed_pipe(str(far), "--summary", str(tmp_path / "s.json"), "--no-record",
                                  "--max-time", "3 s")
    assert done.returncode == 1, done.stderr
    assert json.loads((tmp_path / "s.json").read_text(encoding="utf-8"))["status"] in ("failure", "stopped")


def test_validate_warns_about_a_speed_above_the_robots_top_speed(tmp_path):
    fast = tmp_path / "fast.yaml"
    fast.write_text("mission: fast\nsteps:\n  - drive: {distance: 1 m, speed: 0.3 m/s}\n"
                    "  - drive: {distance: 1 m, speed: 0.6 m/s}\n", encoding="utf-8")
    default = beastbt("validate", str(fast))
    assert default.returncode == 0 and "ok, with 1 warning" in default.stdout
    assert f"{fast}:4:35: warning: speed 0.6 m/s is above the top speed of robot 'sim'" in default.stderr
    assert beastbt("validate", "--strict", str(fast)).returncode == 2
    # --robot decides: diy_pwm's top speed is 0.5 m/s (0.6 is above it), diy_can's 0.6 m/s (0.6 is not)
    pwm = beastbt("validate", "--robot", str(REPO / "robots" / "diy_pwm.yaml"), str(fast))
    assert pwm.returncode == 0 and "above the top speed of robot 'diy_pwm' 0.5 m/s" in pwm.stderr
    can = beastbt("validate", "--robot", str(REPO / "robots" / "diy_can.yaml"), str(fast))
    assert can.returncode == 0 and "top speed" not in can.stderr
    slow = tmp_path / "slow.yaml"
    slow.write_text("mission: slow\nsteps:\n  - drive: {distance: 1 m, speed: 0.2 m/s}\n", encoding="utf-8")
    assert beastbt("validate", str(slow)).stdout.strip() == f"{slow}: ok"


def test_a_keepout_stop_names_the_fence(tmp_path):
    datum = LocalFrame(40.41680, -3.70380)  # worlds/campus.yaml
    band = [datum.to_geodetic(e, n, 0.0)[:2] for e, n in ((-12, 8), (12, 8), (12, 14), (-12, 14))]
    corners = "[" + ", ".join(f"{{lat: {lat:.8f}, lon: {lon:.8f}}}" for lat, lon in band) + "]"
    h = MissionHarness.from_yaml(
        f"mission: fenced\nworld: campus.yaml\nfences:\n  yard: {{polygon: {corners}}}\n"
        f"  pond: {{polygon: {corners}, keep: out}}\n"
        f"failsafes:\n  keepout: {{fence: pond, margin: 1 m, then: stop}}\n"
        f"steps:\n  - wait: 3 s\n  - drive: {{distance: 20 m, speed: 0.4 m/s}}\n", base_dir=REPO / "worlds", seed=1)
    assert h.run_to_end(200) == "failure"
    [end] = [e for e in h.events if e.kind == "mission_end"]
    assert "failsafe keepout: stop" in end.text and "fence 'pond'" in end.text and "yard" not in end.text
