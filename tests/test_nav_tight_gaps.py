"""Tight gaps: a gap at least the robot's width plus 10 cm is planned through when it is the way, and driven slowly.

* the global costmap (0.1 m cells) lets a path through a 0.40 m gap wherever it falls on the grid, and never through
  a 0.32 m one: the obstacle layer's half cells tell them apart; without ``narrow_gaps`` neither passes (before);
* the local planner takes an arc into a gap whose middle is within the padding but clear of the footprint, at
  ``local_planner.narrow_speed_mps`` at most;
* on the simulator, missions/tight_gap.yaml leaves the pen of worlds/field_gap.yaml (its only gap 0.40 m, the robot
  0.30 m across) without touching, below the narrow speed in the gap; the same pen with a 0.32 m gap
  (worlds/field_gap_narrow.yaml) fails at once, naming why.

benchmarks/tight_gaps.py sweeps seeds 1-5 and gap widths (docs/navigation.md, Tight gaps).
"""

from __future__ import annotations

import math

import numpy as np

from beastbt.devices.lidar_scan import LidarMounting
from beastbt.navigation.global_navigator import GlobalNavigator
from beastbt.navigation.global_planner import GlobalPlannerConfig, NoPath
from beastbt.navigation.local_costmap import LocalCostmapConfig, RollingCostmap
from beastbt.navigation.local_planner import DwaPlanner, Limits, LocalPlannerConfig
from beastbt.navigation.obstacle_layer import GlobalCostmapConfig
from beastbt.testing import MissionHarness
from conftest import REPO

FOOTPRINT_M = 0.15
MOUNT = LidarMounting(0.0, 0.0, 0.12, 0.0)
LIMITS = Limits(max_speed_mps=0.35, max_turn_rate_rps=math.radians(120), max_accel_mps2=1.0,
                max_angular_accel_rps2=math.radians(360))


def plans_through(gap_m: float, offset_m: float, narrow_gaps: bool = True) -> bool:
    """Whether the global costmap (GPS window, default cells) plans through a wall at y = 3 m whose only gap is
    ``gap_m`` wide, centred ``offset_m`` off the grid's lines."""
    g = GlobalNavigator(GlobalCostmapConfig(width_m=20.0), GlobalPlannerConfig(narrow_gaps=narrow_gaps),
                        FOOTPRINT_M, MOUNT)
    xs = np.arange(-10.0, 10.0, 0.01) + offset_m
    xs = xs[np.abs(xs - offset_m) > gap_m / 2]
    g.layer.mark_points(xs, np.full(len(xs), 3.0))
    try:
        g.plan((0.0, 0.0), (0.0, 6.0), 0.0, "b")
        return True
    except NoPath:
        return False


OFFSETS = (0.0, 0.013, 0.025, 0.037, 0.05, 0.062, 0.075, 0.087)


def test_the_global_costmap_passes_the_width_plus_10_cm_and_not_plus_2_cm_wherever_the_gap_falls():
    assert all(plans_through(0.40, off) for off in OFFSETS)
    assert not any(plans_through(0.32, off) for off in OFFSETS)
    # Without narrow gaps the padding is impassable, as before: 0.40 m is too narrow.
    assert not any(plans_through(0.40, off, narrow_gaps=False) for off in OFFSETS)
    # Taken when it is the way, not when a way round costs little more: round a 1.2 m wall's end, not through its gap
    # (a narrow cell costs three times its length).
    g = GlobalNavigator(GlobalCostmapConfig(width_m=20.0), GlobalPlannerConfig(), FOOTPRINT_M, MOUNT)
    xs = np.arange(-0.6, 0.6, 0.01)
    xs = xs[np.abs(xs) > 0.20]
    g.layer.mark_points(xs, np.full(len(xs), 3.0))
    assert np.abs(g.plan((0.0, 0.0), (0.0, 6.0), 0.0, "b").points[:, 0]).max() > 0.6


def test_the_local_planner_drives_into_a_narrow_gap_at_the_narrow_speed():
    config = LocalPlannerConfig()
    # A wall 0.1 m ahead across x, its gap 0.40 m wide on the robot's line; the robot at 0.3 m/s toward it.
    ys = np.arange(-3.0, 3.0, 0.01)
    ys = ys[np.abs(ys) > 0.20]
    cm = RollingCostmap(LocalCostmapConfig(), FOOTPRINT_M, narrow=True)
    cm.add_scan(0.0, np.column_stack((np.full(len(ys), 0.1), ys)), (0.0, 0.0, 0.0))
    cm.build(0.0, (0.0, 0.0))
    planner = DwaPlanner(config, LIMITS)
    plan = planner.plan(cm.latest, (0.0, 0.0, 0.0), (0.3, 0.0), (0.3, 0.0), (1.5, 0.0), 0.35, 2.0, (3.0, 0.0))
    assert plan.narrow and not plan.blocked
    assert 0.0 < plan.linear_mps <= config.narrow_speed_mps + 1e-9
    assert abs(plan.angular_rps) < 0.5


def test_the_pen_is_left_through_its_gap_slowly_and_a_gap_8_cm_narrower_fails_at_once():
    mission = REPO / "missions" / "tight_gap.yaml"
    h = MissionHarness.from_file(mission, world=str(REPO / "worlds" / "field_gap.yaml"), seed=1)
    narrow_speed = LocalPlannerConfig().narrow_speed_mps
    fastest_in_gap = 0.0
    while not h.done and h.now_s < 150.0:
        h.tick()
        if abs(h.truth.y - 3.0) < 0.1:  # the robot's centre in the gap (the wall at y = 3 m)
            fastest_in_gap = max(fastest_in_gap, abs(h.truth.v_mps))
    summary = h.summary()
    assert summary["status"] == "success", summary["events"][-3:]
    assert summary["truth"]["collisions"] == 0
    assert h.truth.y > 3.3                                  # out of the pen
    assert 0.0 < fastest_in_gap <= 1.05 * narrow_speed       # the wheels' own lag and slip aside
    narrow = MissionHarness.from_file(mission, world=str(REPO / "worlds" / "field_gap_narrow.yaml"), seed=1)
    narrow.run_to_end(timeout_s=60.0)
    summary = narrow.summary()
    assert summary["status"] == "failure" and summary["sim_time_s"] < 10.0
    assert summary["truth"]["collisions"] == 0
    failed = [e["text"] for e in summary["events"] if e["kind"] == "step_failed"]
    assert failed and "no gap on the way is wide enough for the robot (wider than 0.30 m)" in failed[0]
