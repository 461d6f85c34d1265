"""The worlds built for the global costmap (worlds/field_fence.yaml, worlds/field_dead_end.yaml), on two seeds.

* missions/fence_crossing.yaml: a GPS route across a field with an 8 m fence whose only gap (0.25 m) is narrower
  than the robot; the way is round an end, 4 m off the line. It must succeed in at most 1.5x the time of the same
  route on the empty field (worlds/field.yaml), without touching the fence.
* missions/dead_end.yaml: a place behind a U-shaped dead end (6 m x 5 m, open towards the robot). It must succeed
  in at most 3x the empty field's time, without touching the U.

benchmarks/nav_worlds.py sweeps seeds 1-5 of both courses (its last figures: benchmarks/results/nav_worlds.json);
the tests keep two seeds so that CI stays within its time.

Without the global costmap (``global_costmap: {enabled: false}``, as before it) both fail: the local costmap is
6 m wide and forgets what it saw, so the robot pushes at the gap or into the U until it is blocked.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import pytest

from beastbt.testing import MissionHarness
from conftest import REPO
from nav_support import robot_without_global_costmap

SEEDS = (1, 4)


def run(mission: str, world: str, seed: int, robot: Optional[str] = None, until_s: float = 400.0) -> tuple[dict, float]:
    """One run at full speed: the summary and the farthest the robot went east or west (m, true)."""
    kw = {"robot": robot} if robot is not None else {}
    h = MissionHarness.from_file(REPO / "missions" / mission, world=str(REPO / "worlds" / world), seed=seed, **kw)
    widest = 0.0
    while not h.done and h.now_s < until_s:
        h.tick()
        widest = max(widest, abs(h.truth.x))
    return h.summary(), widest


@pytest.mark.parametrize("mission, world, ratio", [("fence_crossing.yaml", "field_fence.yaml", 1.5),
                                                   ("dead_end.yaml", "field_dead_end.yaml", 3.0)])
def test_the_way_round_is_found_on_every_seed_in_time_and_without_contact(mission, world, ratio):
    for seed in SEEDS:
        empty, _ = run(mission, "field.yaml", seed)
        assert empty["status"] == "success", (seed, empty["events"][-3:])
        summary, widest = run(mission, world, seed)
        assert summary["status"] == "success", (seed, summary["events"][-3:])
        assert summary["truth"]["collisions"] == 0, seed
        assert summary["sim_time_s"] <= ratio * empty["sim_time_s"], (seed, summary["sim_time_s"], empty["sim_time_s"])
        assert any(e["kind"] == "replan" and "planned round" in e["text"] for e in summary["events"]), seed
        assert widest > 3.0 + 0.15, (seed, widest)       # round the fence's end or the U's side, not through


def test_without_the_global_costmap_the_fence_blocks_the_robot(tmp_path: Path):
    summary, widest = run("fence_crossing.yaml", "field_fence.yaml", 1, robot=robot_without_global_costmap(tmp_path))
    assert summary["status"] == "failure"
    assert summary["truth"]["collisions"] == 0
    assert widest < 4.0
