"""Try it in the studio (docs/studio.md, Try it): as fast as the machine can by default, a speed the request may set
(validated), no cap of the studio's own on mission time, the run recorded in the folder's ``runs/`` (``beastbt runs``
lists it) with its report served, and a time left in wall seconds from the measured speed-up.

A real studio on a free loopback port; requests are raw HTTP, as the page sends them.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections import deque
from pathlib import Path

import pytest

from beastbt.studio.trial import mission_time_left, pace_of, speed_argument
from beastbt.studio.files import FileRefused
from conftest import REPO
from test_studio_api import Studio

# Seven steps of 100 s of mission time: longer than the 10 minutes the studio used to cap a try at, and a
# progress (steps done of 7) with an estimate of the mission time left after the first step.
LONG_WAITS = "mission: long_waits\nsteps:\n" + "".join(f"  - wait: 100 s  # {i}\n" for i in range(7))


@pytest.fixture
def studio(tmp_path: Path):
    s = Studio(tmp_path)
    yield s
    s.server.close()


def wait_until_ended(studio: Studio, run_id: str, timeout_s: float = 240) -> dict:
    deadline = time.monotonic() + timeout_s
    state = studio.get(f"/api/try/{run_id}")[1]
    while state["state"] == "running" and time.monotonic() < deadline:
        time.sleep(0.5)
        state = studio.get(f"/api/try/{run_id}")[1]
    return state


@pytest.mark.parametrize("given,expected", [(None, "max"), ("max", "max"), ("realtime", "realtime"), (10, "10"),
                                            ("10", "10"), (2.5, "2.5")])
def test_a_tries_speed_is_max_unless_asked(given, expected):
    assert speed_argument(given) == expected


@pytest.mark.parametrize("bad", ["fast", "", True, 0, -3, "nan", "inf", 1e9, [10], {"x": 1}])
def test_a_speed_that_is_not_one_is_refused(bad):
    with pytest.raises(FileRefused) as refused:
        speed_argument(bad)
    assert refused.value.status == 400 and "'speed' is \"max\"" in str(refused.value)


def test_the_api_refuses_a_bad_speed_or_max_time_before_anything_runs(studio):
    for body in ({"speed": "fast"}, {"speed": True}, {"speed": 0}, {"max_time": "soon"}, {"max_time": "0 s"}):
        status, answer = studio.post("/api/try", {"text": LONG_WAITS, **body})
        assert status == 400, (body, answer)
        assert ("'speed'" if "speed" in body else "'max_time'") in answer["error"]
    assert not (studio.folder / "runs").exists()


def test_the_pace_is_mission_seconds_per_wall_second_and_the_time_left_is_wall_time():
    samples = deque([(100.0, 0.0), (101.0, 8.0), (102.0, 16.0)])
    assert pace_of(samples, 80.0, 102.0) == {"speedup": 8.0, "time_left_s": 10.0}
    assert pace_of(samples, None, 102.0) == {"speedup": 8.0, "time_left_s": None}  # no estimate yet
    assert pace_of(deque([(100.0, 0.0)]), 80.0, 100.0) == {"speedup": None, "time_left_s": None}
    paused = deque([(100.0, 30.0), (101.0, 30.0), (102.0, 30.0)])
    assert pace_of(paused, 80.0, 102.0) == {"speedup": 0.0, "time_left_s": None}  # a paused run: no time left
    # only the last PACE_WINDOW_S count: a run that sped up shows its pace now
    changed = deque([(0.0, 0.0), (50.0, 50.0), (100.0, 1000.0), (101.0, 1020.0)])
    assert pace_of(changed, 40.0, 101.0)["speedup"] == 20.0


def test_the_mission_time_left_is_the_consoles_estimate_which_falls_within_a_step():
    from beastbt.run.progress import Progress, eta_s
    # 7 steps of 100 s, the console's progress as the studio reads it at 40 times real time (a poll every 16 s of
    # mission time). The console credits the running step, so its estimate is the mission time left as it is:
    # scaled back to a step's end, or to between two polls, the running step would be counted twice (at 112 s,
    # 538 s instead of 588 s).
    lefts = []
    for poll in range(44):
        sim_s = 16.0 * poll
        done = int(sim_s // 100)
        progress = Progress(done, 7, eta_s(done, 7, sim_s, 100.0 * done)).as_dict()
        left = mission_time_left(progress)
        if done == 0:
            assert left is None  # no step done yet: no pace
        else:
            assert left == pytest.approx(700.0 - sim_s), (sim_s, progress)
            lefts.append(left)
    assert len(lefts) == 37 and all(b < a for a, b in zip(lefts, lefts[1:]))  # poll by poll, through each step
    # a step that overran its pace: the console holds at the steps after it, and so does the time left
    assert mission_time_left(Progress(1, 7, eta_s(1, 7, 250.0, 100.0)).as_dict()) == pytest.approx(500.0)
    assert mission_time_left({"done": 7, "total": 7, "eta_s": 0.0}) == 0.0
    assert mission_time_left({"done": 3, "total": None, "eta_s": None}) is None  # a loop without a count
    assert mission_time_left({}) is None and mission_time_left({"eta_s": True}) is None


def test_a_try_runs_fast_past_ten_minutes_into_the_folders_runs_with_its_report_and_a_wall_time_left(studio):
    status, started = studio.post("/api/try", {"text": LONG_WAITS, "path": "long_waits.yaml"})
    assert status == 200, started
    run_id = started["run_id"]
    paces = []
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline:
        status, live = studio.get(f"/api/try/{run_id}/console/api/state")
        if status == 409:  # ended
            break
        if status == 200 and live["pace"]["time_left_s"] is not None:
            paces.append((live["time_s"], live["progress"]["done"], live["pace"]))
        time.sleep(0.4)
    state = wait_until_ended(studio, run_id)
    assert state["speed"] == "max"
    assert state["exit_code"] == 0, state["output"]
    # 700 s of mission time: no cap of 10 min (the studio's old one) cut it short
    assert state["summary"]["status"] == "success" and state["summary"]["sim_time_s"] >= 700
    wall = state["summary"].get("wall_time_s")
    print(f"700 s of mission time in {wall} s of wall time; paces seen: {paces[:3]}")
    assert paces, "no time left was ever given"
    for sim_s, done, pace in paces:
        assert pace["speedup"] > 1.5  # as fast as the machine can, not real time
        # the mission time left, at the pace of the steps done (100 s each), in wall seconds at the speed-up; the
        # console's estimate is read a poll after the step ended, so it runs a little over
        mission_left = 700 - sim_s
        assert pace["time_left_s"] == pytest.approx(mission_left / pace["speedup"], rel=0.5, abs=0.5), (sim_s, pace)
        assert pace["time_left_s"] < mission_left / 1.5  # not the real-time estimate
    lefts = [pace["time_left_s"] for _, _, pace in paces]
    assert all(b <= a * 1.25 + 0.5 for a, b in zip(lefts, lefts[1:])), lefts  # it falls as the run goes on
    assert lefts[-1] < lefts[0]
    # recorded in the folder's runs/: beastbt runs there lists it, and the report is the studio's to serve
    assert state["run_folder"].startswith("runs/") and (studio.folder / state["run_folder"] / "summary.json").is_file()
    listed = subprocess.run([sys.executable, "-m", "beastbt", "runs"], cwd=studio.folder, capture_output=True,
                            text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert listed.returncode == 0 and Path(state["run_folder"]).name in listed.stdout, listed.stdout + listed.stderr
    assert state["report"] == f"/api/try/{run_id}/report/"
    status, html = studio.get(state["report"])
    assert status == 200 and "long_waits" in html
    assert not list(studio.folder.glob(".*.try-*"))  # the hidden copy is gone


def test_a_try_at_real_time_measures_a_pace_near_one_and_a_max_time_given_caps_it(studio):
    text = "mission: slow\nsteps:\n" + "".join(f"  - wait: 1 s  # {i}\n" for i in range(30))
    run_id = studio.post("/api/try", {"text": text, "speed": "realtime", "max_time": "4 s"})[1]["run_id"]
    seen = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        status, live = studio.get(f"/api/try/{run_id}/console/api/state")
        if status == 409:
            break
        if status == 200 and live["pace"]["speedup"] is not None:
            seen.append(live["pace"]["speedup"])
        time.sleep(0.3)
    state = wait_until_ended(studio, run_id)
    assert state["speed"] == "realtime"
    assert state["summary"]["status"] == "stopped" and state["summary"]["sim_time_s"] <= 4.1
    assert seen and all(0.2 < s < 2.0 for s in seen), seen  # paced to real time (a loaded machine lags)
    assert 0.5 < sorted(seen)[len(seen) // 2] < 1.5, seen
