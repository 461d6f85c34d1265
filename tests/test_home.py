"""Home is the fused start position once the estimator has settled, not the first raw fix (issue 37, item 3)."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import jsonschema
import pytest

from beastbt.run.home import HOME_MAX_SIGMA_M, HOME_MIN_FIXES, HOME_WAIT_S, HomeFinder
from beastbt.run.summary import human_summary
from beastbt.testing import MissionHarness
from conftest import REPO

GO_AND_BACK = f"""mission: go_and_back
world: {REPO / 'worlds' / 'campus.yaml'}
steps:
  - drive: {{distance: 10 m, speed: 0.3 m/s}}
  - turn: {{angle: 90 deg}}
  - drive: {{distance: 5 m, speed: 0.3 m/s}}
  - return_home: {{}}
"""


def _true_offset_m(h: MissionHarness, lat: float, lon: float) -> float:
    """How far (lat, lon) is from where the simulated robot truly started, m."""
    world = h.prepared.world
    e, n, _ = world.frame.to_enu(lat, lon, None)
    return math.hypot(e - world.start_x, n - world.start_y)


@pytest.mark.parametrize("seed", [1, 2, 3, 6])  # 2, 3 and 6: the first raw fix was 4-6 m from the start
def test_return_home_ends_near_the_true_start(seed):
    h = MissionHarness.from_yaml(GO_AND_BACK, base_dir=REPO, seed=seed)
    assert h.run_to_end() == "success"
    home = h.run.home_set
    assert home is not None and home.how == "fused_start"
    assert home.fixes >= HOME_MIN_FIXES and home.sigma_m <= HOME_MAX_SIGMA_M
    assert _true_offset_m(h, *h.run.home) < 2.0  # the fused start, not a single fix metres off
    world, truth = h.prepared.world, h.run.io.sim.truth
    ended_m = math.hypot(truth.x - world.start_x, truth.y - world.start_y)
    # Arrival is judged on the estimate (within the default 2 m): the true end adds home's and the estimate's error.
    assert ended_m < 2.0 + 2.0, ended_m


def fix(t: float, lat: float = 40.0, lon: float = -3.0) -> SimpleNamespace:
    return SimpleNamespace(lat=lat, lon=lon, quality=1, time_utc=f"{t:.0f}", stamp_s=t)


def pose(t: float, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, sigma: float = 0.5, lat: float = 40.0,
         lon: float = -3.0, heading: bool = True) -> SimpleNamespace:
    cov = ((sigma ** 2, 0.0, 0.0), (0.0, sigma ** 2, 0.0), (0.0, 0.0, 0.01))
    return SimpleNamespace(stamp_s=t, x=x, y=y, yaw=yaw, covariance=cov, position_valid=True, heading_valid=heading,
                           lat=lat, lon=lon)


def test_home_waits_for_the_fixes_and_the_covariance_then_takes_the_start():
    start = pose(0.0)
    finder = HomeFinder(fused=True, start_odom=start)
    odom = pose(0.0)
    for t in range(1, HOME_MIN_FIXES):
        assert finder.update(float(t), [fix(t)], pose(t), odom) is None  # too few fixes yet
    assert finder.update(float(HOME_MIN_FIXES), [fix(HOME_MIN_FIXES)], pose(HOME_MIN_FIXES, sigma=3.0), odom) is None
    # Settled, 4 m north of the start by the wheels (which face east: their frame is turned 90 deg from the world's).
    moved = pose(11.0, x=4.0, y=0.0, yaw=0.0)
    home = finder.update(11.0, [fix(11)], pose(11.0, yaw=math.pi / 2), moved)
    assert home is not None and home.how == "fused_start" and home.moved_m == pytest.approx(4.0)
    assert (home.lat - 40.0) * 111_320 == pytest.approx(-4.0, abs=0.05)  # 4 m south of where the robot is now
    assert home.lon == pytest.approx(-3.0, abs=1e-7)
    assert "fused start position" in home.text() and "once the estimate settled" in home.text()


def test_home_waits_for_a_heading_once_the_robot_moved_and_is_set_anyway_late():
    finder = HomeFinder(fused=True, start_odom=pose(0.0))
    moved = pose(0.0, x=3.0)
    for t in range(1, 20):
        assert finder.update(float(t), [fix(t)], pose(t, heading=False), moved) is None
    late = finder.update(1.0 + HOME_WAIT_S, [], pose(31.0, heading=False, sigma=2.5), moved)
    assert late is not None and late.how == "fused_start_unsettled"


def test_without_an_estimator_home_is_the_first_fix_and_says_so():
    home = HomeFinder(fused=False, start_odom=pose(0.0)).update(2.0, [fix(2, lat=41.0)], None, pose(2.0))
    assert home is not None and home.how == "first_fix" and home.lat == 41.0
    assert "first GPS fix" in home.text()


def test_the_summary_says_how_home_was_set(tmp_path):
    h = MissionHarness.from_yaml(GO_AND_BACK, base_dir=REPO, seed=1, max_time_s=15.0)
    h.run_to_end()
    summary = h.summary()
    schema = json.loads((REPO / "schemas" / "summary.schema.json").read_text(encoding="utf-8"))
    jsonschema.validate(summary, schema)
    assert summary["home"]["how"] == "fused_start" and summary["home"]["fixes"] >= HOME_MIN_FIXES
    assert any(e["kind"] == "home" and "fused start position" in e["text"] for e in summary["events"])
    assert "  home: the fused start position, set at" in human_summary(summary)


def test_return_home_at_the_start_says_it_waits_for_home_not_for_a_fix(tmp_path):
    mission = tmp_path / "home_first.yaml"
    mission.write_text(f"mission: home_first\nworld: {REPO / 'worlds' / 'campus.yaml'}\nsteps:\n  - return_home: {{}}\n",
                       encoding="utf-8")
    h = MissionHarness.from_file(mission, seed=1)
    node = next(n for n in h.root.iterate() if n.name.startswith("return_home"))
    said_after_a_fix = set()
    while not h.done and h.now_s < 120:
        h.tick()
        if h.blackboard("gps_fix") is not None and node.status.name == "RUNNING":
            said_after_a_fix.add(node.feedback_message)
    assert h.result == "success"
    assert "waiting for home: the position estimate is settling" in said_after_a_fix
    assert "waiting for a GPS fix" not in said_after_a_fix
