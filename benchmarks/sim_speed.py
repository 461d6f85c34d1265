"""Simulator speed and the cost of a compiled tree, measured in one run.

Prints:
1. the simulator's real-time factor on the patrol mission (goal: at least 100x
   on one core), over several seeds;
2. the per-tick cost of the compiled patrol tree against a hand-built py_trees
   tree of the same shape whose leaves do the same blackboard work (goal: the
   compiled tree costs no more than 1.3 times the hand-built one).

Run: python benchmarks/sim_speed.py [--seeds N]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import py_trees

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.blackboard import catalogue  # noqa: E402
from beastbt.blackboard.types import FusedPose, VelocityCommand  # noqa: E402
from beastbt.assembly import prepare  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402

PATROL = str(REPO / "missions" / "patrol.yaml")


def real_time_factor(seeds: int) -> list[float]:
    """Sim seconds per wall second of whole patrol runs (loading excluded)."""
    factors = []
    for seed in range(1, seeds + 1):
        p = prepare(PATROL, RunOptions(seed=seed, record=False))
        t0 = time.perf_counter()
        with open("/dev/null", "w") as devnull:
            s = execute(p, devnull)
        factors.append(s["sim_time_s"] / (time.perf_counter() - t0))
    return factors


class HandLeaf(py_trees.behaviour.Behaviour):
    """A hand-written leaf doing what a drive leaf does with the blackboard: read a pose, write a command."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.bb = self.attach_blackboard_client(name)
        self.bb.register_key("pose_odom", access=py_trees.common.Access.READ)
        self.bb.register_key("cmd_mission", access=py_trees.common.Access.WRITE)

    def update(self) -> py_trees.common.Status:
        pose = self.bb.pose_odom
        self.bb.cmd_mission = VelocityCommand(0.1, -0.5 * pose.yaw, pose.stamp_s)
        return py_trees.common.Status.RUNNING


def hand_built_like(root: py_trees.behaviour.Behaviour) -> py_trees.behaviour.Behaviour:
    """Rebuild ``root``'s shape with plain py_trees composites/decorators and HandLeaf leaves."""
    if isinstance(root, py_trees.decorators.Decorator):
        return py_trees.decorators.Repeat(root.name, hand_built_like(root.decorated), -1)
    if root.children:
        return py_trees.composites.Sequence(root.name, memory=True, children=[hand_built_like(c) for c in root.children])
    return HandLeaf(root.name)


def per_tick_us(root: py_trees.behaviour.Behaviour, ticks: int) -> float:
    t0 = time.perf_counter()
    for _ in range(ticks):
        root.tick_once()
    return (time.perf_counter() - t0) / ticks * 1e6


def tree_cost(ticks: int = 20000, rounds: int = 5) -> tuple[float, float]:
    """Median per-tick cost (us) of the compiled patrol tree and of its hand-built twin, interleaved."""
    p = prepare(PATROL, RunOptions(seed=1, record=False))
    compiled = p.run.root
    # Hold the pose still so the first drive keeps RUNNING: every tick walks the same path.
    w = catalogue.writer("bench", ("pose_odom", "now_s"))
    w.pose_odom = FusedPose(0.0, 0.0, 0.0, 0.0)
    hand = hand_built_like(compiled)
    c, h = [], []
    for _ in range(rounds):
        c.append(per_tick_us(compiled, ticks))
        h.append(per_tick_us(hand, ticks))
    return statistics.median(c), statistics.median(h)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    f = real_time_factor(args.seeds)
    print(f"patrol real-time factor over {len(f)} seeds: median {statistics.median(f):.0f}x, "
          f"min {min(f):.0f}x (goal >= 100x)")
    compiled_us, hand_us = tree_cost()
    print(f"per-tick cost: compiled patrol tree {compiled_us:.1f} us, hand-built py_trees tree of the same shape "
          f"{hand_us:.1f} us, ratio {compiled_us / hand_us:.2f} (goal <= 1.3)")


if __name__ == "__main__":
    main()
