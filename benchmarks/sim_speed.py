"""Simulator speed and what one tick of the patrol costs, against anchors measured in the same process.

Anchors (timed interleaved with the subjects: every rep runs each of them
once, in the same order, so that all see the same machine; figures are
medians over ``--reps`` reps, at least 5, with the spread, lowest to highest):

* the hand-built tree: a py_trees tree of the compiled patrol tree's shape
  (``Sequence(memory=True)`` and ``Repeat``, as the compiler makes them),
  whose leaves do a drive leaf's blackboard work (read the pose, write a
  command). It runs the same paths the patrol runs: a survey run of the
  patrol records, leaf by leaf, the status each ``update()`` returned, and
  each hand-built leaf returns those statuses in turn; so the hand-built
  tree starts, runs and finishes the same leaves at the same ticks (drives,
  looks, waits, turns, three times), not only the first drive's RUNNING;
* a filterpy ``ExtendedKalmanFilter`` predict + update with our EKF's state
  size and a 2-D position fix.

Subjects, all on missions/patrol.yaml, the default simulated robot, seed 1,
``--speed max``, unrecorded:

1. the compiled tree (``root.tick_once()``, timed inside a real patrol run)
   against the hand-built tree over the same ticks (goal: at most 1.3x);
2. the patrol as it runs, the EKF asleep (nothing reads the fused pose: the
   GPS, the IMU and the EKF sleep), per tick: physics, emulators, drivers,
   LiDAR and collision monitor, odometry, tree, mux, gate, watchdog; against
   the hand-built tree alone;
3. the patrol with every part awake (the GPS, the IMU and the EKF polled
   and fused each tick, as ``--record-sensors`` keeps them; here without
   recording), per tick, against the hand-built tree plus one EKF step;
4. the patrol on robots/sim.yaml without the GPS, IMU and camera sections
   (what a part the mission does not use costs: goal nothing, within the
   spread) against the default robot, both EKF asleep;
5. the simulator's real-time factor on whole patrol runs, over ``--seeds``
   seeds (goal: at least 100x on one core).

Recording's cost is in benchmarks/recording_cost.py.

Run: python benchmarks/sim_speed.py [--reps N] [--seeds N]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Iterator

import py_trees

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import beastbt.assembly as assembly  # noqa: E402
from beastbt.blackboard import catalogue  # noqa: E402
from beastbt.blackboard.types import FusedPose, VelocityCommand  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402

PATROL = str(REPO / "missions" / "patrol.yaml")


# -- running the patrol ----------------------------------------------------------------------------


@contextlib.contextmanager
def all_awake() -> Iterator[None]:
    """Within: no part sleeps (as with ``--record-sensors``), whatever the run reads."""
    asleep = assembly.asleep
    assembly.asleep = lambda parts, demand: []
    try:
        yield
    finally:
        assembly.asleep = asleep


def patrol(robot: str = "sim", seed: int = 1, awake: bool = False, tree_times: list | None = None,
           survey: dict | None = None) -> tuple[float, int, float]:
    """One whole patrol at --speed max, unrecorded: (wall s per tick of the loop, ticks, sim s / wall s).

    ``tree_times``: gets the wall time of each ``root.tick_once()``; ``survey``: gets, per leaf (its index among
    the tree's leaves), the statuses its ``update()`` returned, in order.
    """
    opts = RunOptions(robot=robot, seed=seed, record=False, simulate=robot != "sim")
    if awake:
        with all_awake():
            p = assembly.prepare(PATROL, opts)
    else:
        p = assembly.prepare(PATROL, opts)
    run = p.run
    if tree_times is not None:
        tick_once, perf = run.root.tick_once, time.perf_counter

        def timed_tick_once() -> None:
            t0 = perf()
            tick_once()
            tree_times.append(perf() - t0)

        run.root.tick_once = timed_tick_once
    if survey is not None:
        for i, leaf in enumerate(leaves(run.root)):
            leaf.update = _noting(leaf.update, survey.setdefault(i, []))
    tick, span = run.tick, [0.0, 0.0]

    def timed_tick():
        t = time.perf_counter()
        span[0] = span[0] or t
        status = tick()
        span[1] = time.perf_counter()
        return status

    run.tick = timed_tick
    with open("/dev/null", "w") as devnull:
        s = execute(p, devnull)
    loop = span[1] - span[0]
    return loop / s["ticks"], s["ticks"], s["sim_time_s"] / loop


def _noting(update: Callable[[], py_trees.common.Status], out: list) -> Callable[[], py_trees.common.Status]:
    def noted() -> py_trees.common.Status:
        status = update()
        out.append(status)
        return status
    return noted


def leaves(root: py_trees.behaviour.Behaviour) -> list[py_trees.behaviour.Behaviour]:
    """The tree's leaves, in the order :meth:`iterate` visits them."""
    return [n for n in root.iterate() if not n.children and not isinstance(n, py_trees.decorators.Decorator)]


# -- the anchors -----------------------------------------------------------------------------------


class HandLeaf(py_trees.behaviour.Behaviour):
    """A hand-written leaf doing a drive leaf's blackboard work (read a pose, write a command) and returning, tick
    by tick, the statuses the patrol's leaf in its place returned."""

    def __init__(self, name: str, statuses: list[py_trees.common.Status]) -> None:
        super().__init__(name)
        self.bb = self.attach_blackboard_client(name)
        self.bb.register_key("pose_odom", access=py_trees.common.Access.READ)
        self.bb.register_key("cmd_mission", access=py_trees.common.Access.WRITE)
        self.script = statuses
        self.next = 0

    def update(self) -> py_trees.common.Status:
        pose = self.bb.pose_odom
        self.bb.cmd_mission = VelocityCommand(0.1, -0.5 * pose.yaw, pose.stamp_s)
        status = self.script[self.next] if self.next < len(self.script) else py_trees.common.Status.RUNNING
        self.next += 1
        return status


def hand_built_like(root: py_trees.behaviour.Behaviour, survey: dict) -> py_trees.behaviour.Behaviour:
    """``root``'s shape in plain py_trees (Sequence with memory, Repeat) with :class:`HandLeaf` leaves scripted by
    ``survey`` (leaf index -> statuses)."""
    counter = iter(range(10**9))

    def build(node: py_trees.behaviour.Behaviour) -> py_trees.behaviour.Behaviour:
        if isinstance(node, py_trees.decorators.Repeat):
            return py_trees.decorators.Repeat(node.name, build(node.decorated), node.num_success)
        if isinstance(node, py_trees.decorators.Decorator):
            raise SystemExit(f"sim_speed.py: no hand-built twin for decorator {type(node).__name__}")
        if node.children:
            if not isinstance(node, py_trees.composites.Sequence):
                raise SystemExit(f"sim_speed.py: no hand-built twin for composite {type(node).__name__}")
            return py_trees.composites.Sequence(node.name, memory=True, children=[build(c) for c in node.children])
        return HandLeaf(node.name, survey.get(next(counter), []))

    return build(root)


def hand_tree_per_tick(root: py_trees.behaviour.Behaviour, survey: dict, ticks: int) -> float:
    """Wall s per tick of a fresh hand-built twin of ``root`` over ``ticks`` ticks (the patrol's)."""
    hand = hand_built_like(root, survey)
    w = catalogue.writer("bench", ("pose_odom",))
    w.pose_odom = FusedPose(0.0, 0.0, 0.0, 0.0)
    perf = time.perf_counter
    total = 0.0
    for _ in range(ticks):
        t0 = perf()
        hand.tick_once()
        total += perf() - t0
        if hand.status != py_trees.common.Status.RUNNING and hand.status != py_trees.common.Status.INVALID:
            break
    off = [leaf.name for leaf in leaves(hand) if leaf.next != len(leaf.script)]
    if off:  # the twin did not take the patrol's paths: its figure would compare unlike with like
        raise SystemExit(f"sim_speed.py: the hand-built tree left the patrol's paths at {', '.join(off[:3])}")
    return total / ticks


def ekf_step(calls: int = 2000) -> float:
    """Wall s of one filterpy ExtendedKalmanFilter predict+update with our EKF's state size and a 2-D fix."""
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
    return (time.perf_counter() - t0) / calls


def without_unused_parts() -> str:
    """robots/sim.yaml without the GPS, IMU and camera the patrol does not use: a profile file."""
    import yaml
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    for section in ("gps", "imu", "camera", "line_detector", "line_follower", "estimator"):
        data.pop(section, None)
    data["robot"] = "sim_bare"
    path = Path(tempfile.mkdtemp()) / "sim_bare.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return str(path)


# -- printing ----------------------------------------------------------------------------------------


def spread(values: list[float], scale: float = 1.0, fmt: str = "{:.1f}") -> str:
    """``median (lowest-highest)`` of ``values`` times ``scale``."""
    return (fmt.format(statistics.median(values) * scale) + " (" + fmt.format(min(values) * scale) + "-"
            + fmt.format(max(values) * scale) + ")")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=7, help="reps of every subject and anchor (default 7, at least 5)")
    ap.add_argument("--seeds", type=int, default=5, help="seeds for the real-time factor (default 5)")
    args = ap.parse_args()
    if args.reps < 5:
        ap.error("--reps: at least 5 (medians over fewer say little)")
    survey: dict[int, list] = {}
    patrol(survey=survey)  # the paths the patrol runs, leaf by leaf (and a warm-up: imports, caches)
    bare = without_unused_parts()
    m: dict[str, list[float]] = collections.defaultdict(list)
    ticks = 0
    for _ in range(args.reps):
        tree_times: list[float] = []
        asleep_tick, ticks, _ = patrol(tree_times=tree_times)
        m["asleep"].append(asleep_tick)
        m["compiled"].append(sum(tree_times) / ticks)
        m["hand"].append(hand_tree_per_tick(assembly.prepare(PATROL, RunOptions(record=False)).run.root, survey,
                                            ticks))
        m["awake"].append(patrol(awake=True)[0])
        m["ekf"].append(ekf_step())
        m["bare"].append(patrol(robot=bare)[0])
    ratio = {k: [a / b for a, b in zip(m[k], m["hand"])] for k in ("compiled", "asleep")}
    ratio["awake"] = [a / (h + e) for a, h, e in zip(m["awake"], m["hand"], m["ekf"])]
    ratio["bare"] = [a / b for a, b in zip(m["asleep"], m["bare"])]
    us = 1e6
    print(f"patrol, default simulated robot, --speed max, {ticks} ticks a run; {args.reps} reps, interleaved; "
          f"median (lowest-highest):")
    print(f"anchors: hand-built tree on the patrol's paths {spread(m['hand'], us)} us per tick; filterpy EKF "
          f"predict+update {spread(m['ekf'], us)} us")
    print(f"1. compiled patrol tree {spread(m['compiled'], us)} us per tick = "
          f"{spread(ratio['compiled'], fmt='{:.2f}')}x the hand-built tree (goal <= 1.3)")
    print(f"2. patrol tick, EKF asleep: {spread(m['asleep'], us, '{:.0f}')} us = {spread(ratio['asleep'])}x the "
          f"hand-built tree alone")
    print(f"3. patrol tick, every part awake (GPS, IMU, EKF): {spread(m['awake'], us, '{:.0f}')} us = "
          f"{spread(ratio['awake'])}x the hand-built tree + an EKF step")
    print(f"4. unused parts: the default robot's patrol tick is {spread(ratio['bare'], fmt='{:.2f}')}x that of the "
          f"robot without GPS, IMU and camera ({spread(m['bare'], us, '{:.0f}')} us; goal: 1, within the spread)")
    factors = [patrol(seed=seed)[2] for seed in range(1, args.seeds + 1)]
    print(f"5. patrol real-time factor over {len(factors)} seeds: {spread(factors, fmt='{:.0f}')}x "
          f"(goal >= 100x)")
    # Saved for benchmarks/check_docs.py (benchmarks/figures.py prints them): docs/performance.md quotes them.
    from figures import Figures
    figures = Figures("sim_speed")
    for key in ("hand", "ekf", "compiled", "asleep", "awake", "bare"):
        figures.spread(f"{key}_us", m[key], us)
    for key, values in ratio.items():
        figures.spread(f"{key}_ratio", values)
    figures.spread("realtime_factor", factors)
    figures.save()


if __name__ == "__main__":
    main()
