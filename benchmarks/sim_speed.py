"""Simulator speed and the cost of a compiled tree, measured in one run.

Prints:
1. the simulator's real-time factor on the patrol mission (goal: at least 100x
   on one core), over several seeds;
2. the per-tick cost of the compiled patrol tree against a hand-built py_trees
   tree of the same shape whose leaves do the same blackboard work (goal: the
   compiled tree costs no more than 1.3 times the hand-built one).

3. the cost of a full simulated tick of the patrol (the default simulated
   robot as users get it: Waveshare base, GPS, IMU, EKF and camera parts;
   physics, emulators, drivers, estimator, tree, mux, gate, watchdog) against
   the sum of two anchors measured in the same run: one tick of a hand-built
   py_trees tree of the same shape, and one filterpy EKF predict+update with
   the state size of ours. Goal (issue 11): at most 8x;
4. what a part that the mission does not use costs per tick: the patrol on
   the default robot against the same robot without its GPS, IMU and camera
   sections (goal: nothing, within the noise: the parts that nothing reads
   sleep); and, for comparison, the recorded patrol, whose recording reads
   them.

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


def full_tick_us(profile: str, seed: int = 1) -> tuple[float, int]:
    """Wall time per tick (us) of a whole patrol run at --speed max, unrecorded; and the ticks."""
    p = prepare(PATROL, RunOptions(robot=profile, seed=seed, record=False, simulate=profile != "sim"))
    t0 = time.perf_counter()
    with open("/dev/null", "w") as devnull:
        s = execute(p, devnull)
    return (time.perf_counter() - t0) / s["ticks"] * 1e6, s["ticks"]


def recorded_tick_us(seed: int = 1) -> float:
    """Wall time per tick (us) of the patrol recorded to MCAP: the recording reads the GPS, IMU and EKF, so they are awake."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        p = prepare(PATROL, RunOptions(seed=seed, record=False, record_path=str(Path(tmp) / "run.mcap")))
        t0 = time.perf_counter()
        with open("/dev/null", "w") as devnull:
            s = execute(p, devnull)
        return (time.perf_counter() - t0) / s["ticks"] * 1e6


def ekf_anchor_us(calls: int = 5000) -> float:
    """One filterpy ExtendedKalmanFilter predict+update with our EKF's state size and a 2-D position fix (us)."""
    import numpy as np
    from filterpy.kalman import ExtendedKalmanFilter

    from beastbt.estimation.ekf import STATE_SIZE
    ekf = ExtendedKalmanFilter(dim_x=STATE_SIZE, dim_z=2)
    ekf.F = np.eye(STATE_SIZE)
    ekf.Q = np.eye(STATE_SIZE) * 1e-3
    ekf.R = np.eye(2)
    H = np.zeros((2, STATE_SIZE))
    H[0, 0] = H[1, 1] = 1.0
    z = np.array([0.1, 0.2])
    t0 = time.perf_counter()
    for _ in range(calls):
        ekf.predict()
        ekf.update(z, lambda x: H, lambda x: H @ x)
    return (time.perf_counter() - t0) / calls * 1e6


def without_unused_parts() -> str:
    """robots/sim.yaml without the GPS, IMU and camera the patrol does not use: a profile file."""
    import tempfile

    import yaml
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    for section in ("gps", "imu", "camera", "line_detector", "line_follower", "estimator"):
        data.pop(section, None)
    data["robot"] = "sim_bare"
    path = Path(tempfile.mkdtemp()) / "sim_bare.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return str(path)


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
    bare = without_unused_parts()
    full, bare_ticks, ekf = [], [], []
    for _ in range(3):  # interleaved, so both see the same machine
        full.append(full_tick_us("sim")[0])
        bare_ticks.append(full_tick_us(bare)[0])
        ekf.append(ekf_anchor_us())
    tick, anchor = statistics.median(full), hand_us + statistics.median(ekf)
    print(f"full sim tick of the patrol: {tick:.0f} us; anchors: hand-built tree {hand_us:.1f} us + filterpy EKF "
          f"predict+update {statistics.median(ekf):.1f} us = {anchor:.1f} us; ratio {tick / anchor:.1f}x (goal <= 8x)")
    print(f"unused parts: the patrol ticks in {tick:.0f} us on the default robot (GPS, IMU, camera, EKF) and "
          f"{statistics.median(bare_ticks):.0f} us without them")
    print(f"for comparison, recorded to MCAP (the recording reads GPS, IMU and the fused pose, so they stay awake): "
          f"{recorded_tick_us():.0f} us per tick")


if __name__ == "__main__":
    main()
