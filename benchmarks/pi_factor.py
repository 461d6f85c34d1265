"""How fast this machine does beastbt's kind of work: the factor that scales figures measured here to a Raspberry Pi 4.

A short mix of what a beastbt tick spends its CPU on, each item timed as the
median of several reps (each rep a batch of calls, per call in µs), with the spread
(lowest and highest rep):

- ``tree``: one tick of a small py_trees tree (a sequence of a selector and three
  leaves, as a compiled mission step is);
- ``ekf``: one filterpy ``ExtendedKalmanFilter`` predict and update (5 states, a
  2-D position fix), as the estimator's GPS step;
- ``raycast``: a NumPy ray-cast of one LD19 scan's size (456 rays) against
  24 wall segments, as the LiDAR emulator does;
- ``json``: ``json.dumps`` of one tick's record (pose, odometry, command, tree
  status), as a recording writes;
- ``video``: a cv2 resize of a 640x480 BGR frame to 320x240 and a JPEG encode of
  the 640x480 frame at quality 80, as the console's video does.

The score is the geometric mean of the items' medians (µs): lower is faster, and
each item weighs the same (a plain sum would be mostly the JPEG encode), so the
ratio of two machines' scores is the geometric mean of the items' ratios. The
score is no absolute figure: only a ratio of two machines' scores means something.

How to use it: run it on the development machine and on a Pi 4 (64-bit Raspberry
Pi OS, ``pip install beastbt`` there, the performance governor or the default
ondemand one at 1.5-1.8 GHz), each with ``--json FILE``; then
``python benchmarks/pi_factor.py --compare PI.json`` on either prints each item's
ratio and the factor (the ratio of the scores). docs/performance.md scales its
table by that factor; until someone runs this on a Pi, the factor there is an
estimate from published single-thread benchmarks, and says so.

Anchor: none inside one machine (it measures the machine, not beastbt); the
comparison is between two runs of this same script.

Run: python benchmarks/pi_factor.py [--reps 7] [--quick] [--json FILE] [--compare OTHER.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path
from typing import Callable

import numpy as np


def make_tree() -> Callable[[], None]:
    """A small py_trees tree (a sequence of a selector with two leaves, and three leaves); returns its tick."""
    import py_trees
    from py_trees.behaviours import Failure, Running, Success
    selector = py_trees.composites.Selector("pick", memory=False, children=[Failure(name="f"), Success(name="s")])
    root = py_trees.composites.Sequence("step", memory=False,
                                        children=[selector, Success(name="a"), Success(name="b"), Running(name="r")])
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    return tree.tick


def make_ekf() -> Callable[[], None]:
    """A 5-state filterpy EKF (x, y, heading, speed, turn rate) with a 2-D position fix; returns one predict+update."""
    from filterpy.kalman import ExtendedKalmanFilter
    ekf = ExtendedKalmanFilter(dim_x=5, dim_z=2)
    ekf.x = np.array([0.0, 0.0, 0.1, 0.3, 0.05])
    ekf.P *= 0.5
    ekf.Q = np.eye(5) * 1e-3
    ekf.R = np.eye(2) * 0.5
    dt = 0.05
    h_jac = np.array([[1.0, 0, 0, 0, 0], [0, 1.0, 0, 0, 0]])
    z = np.array([0.01, 0.0])

    def step() -> None:
        x, y, th, v, w = ekf.x
        ekf.F = np.array([[1, 0, -v * dt * np.sin(th), dt * np.cos(th), 0],
                          [0, 1, v * dt * np.cos(th), dt * np.sin(th), 0],
                          [0, 0, 1, 0, dt], [0, 0, 0, 1, 0], [0, 0, 0, 0, 1]])
        ekf.x = np.array([x + v * dt * np.cos(th), y + v * dt * np.sin(th), th + w * dt, v, w])
        ekf.predict()
        ekf.update(z, lambda _x: h_jac, lambda s: s[:2])
    return step


def make_raycast() -> Callable[[], None]:
    """A NumPy cast of 456 rays (one LD19 scan) from the origin against 24 segments; returns one scan."""
    rng = np.random.default_rng(0)
    a = rng.uniform(-8, 8, (24, 2))
    b = a + rng.uniform(-3, 3, (24, 2))
    angles = np.linspace(0, 2 * np.pi, 456, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)

    def cast() -> None:
        e = b - a                                              # segments' directions (S, 2)
        denom = dirs[:, None, 0] * e[None, :, 1] - dirs[:, None, 1] * e[None, :, 0]      # (R, S)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) / denom   # range along the ray
            u = (a[None, :, 0] * dirs[:, None, 1] - a[None, :, 1] * dirs[:, None, 0]) / denom  # along the segment
        hit = (t > 0) & (u >= 0) & (u <= 1)
        np.where(hit, t, 12.0).min(axis=1)
    return cast


def make_json() -> Callable[[], None]:
    """One tick's record as the recording writes it; returns one encode."""
    record = {"t": 12.35, "tick": 247, "pose": {"x": 1.234567, "y": -0.5678, "yaw": 0.7854, "cov": [0.01] * 9},
              "odom": {"vx": 0.3, "wz": 0.05, "left": 0.29, "right": 0.31}, "cmd": {"linear": 0.3, "angular": 0.05},
              "gps": {"lat": 51.507351, "lon": -0.127758, "fix": 1, "hdop": 0.9},
              "tree": [["patrol", "RUNNING"], ["go_to", "RUNNING"], ["check", "SUCCESS"]],
              "battery_v": 11.9}
    return lambda: json.dumps(record, separators=(",", ":"))


def make_video() -> Callable[[], None]:
    """A 640x480 frame's resize to 320x240 and its JPEG encode at quality 80; returns one of each."""
    import cv2
    rng = np.random.default_rng(1)
    frame = np.zeros((480, 640, 3), np.uint8)      # a plausible render: gradients and a few shapes, not noise
    frame[:] = np.linspace(40, 200, 640, dtype=np.uint8)[None, :, None]
    for _ in range(12):
        x, y = rng.integers(0, 600), rng.integers(0, 440)
        colour = tuple(int(c) for c in rng.integers(0, 255, 3))
        cv2.rectangle(frame, (int(x), int(y)), (int(x) + 40, int(y) + 30), colour, -1)

    def step() -> None:
        cv2.resize(frame, (320, 240), interpolation=cv2.INTER_AREA)
        cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 80])
    return step


ITEMS: dict[str, tuple[Callable[[], Callable[[], None]], int]] = {
    # name: (factory, calls per rep), sized so that one rep takes some milliseconds here
    "tree": (make_tree, 400), "ekf": (make_ekf, 400), "raycast": (make_raycast, 100),
    "json": (make_json, 2000), "video": (make_video, 20)}


def measure(reps: int, scale: float = 1.0) -> dict[str, dict[str, float]]:
    """Per item: the median, lowest and highest of ``reps`` reps, in µs per call."""
    out = {}
    for name, (factory, calls) in ITEMS.items():
        fn = factory()
        n = max(1, int(calls * scale))
        for _ in range(max(1, n // 10)):   # warm-up: caches, lazy imports, allocators
            fn()
        per_call = []
        for _ in range(reps):
            t0 = time.perf_counter()
            for _ in range(n):
                fn()
            per_call.append((time.perf_counter() - t0) / n * 1e6)
        out[name] = {"median_us": statistics.median(per_call), "min_us": min(per_call), "max_us": max(per_call)}
    return out


def machine() -> str:
    """This machine's CPU model (from /proc/cpuinfo where there is one) and architecture."""
    model = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="ascii", errors="replace").splitlines():
            if line.split(":")[0].strip() in ("model name", "Model"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model} ({platform.machine()})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reps", type=int, default=7, help="reps per item; the median is reported (default 7)")
    parser.add_argument("--quick", action="store_true",
                        help="3 reps of a tenth of the calls: a smoke run, not a figure")
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON to FILE")
    parser.add_argument("--compare", metavar="OTHER", help="a JSON written by --json on another machine (the Pi)")
    args = parser.parse_args()
    reps, scale = (3, 0.1) if args.quick else (max(5, args.reps), 1.0)
    items = measure(reps, scale)
    score = statistics.geometric_mean([v["median_us"] for v in items.values()])
    print(f"machine: {machine()}; python {platform.python_version()}; {reps} reps per item")
    for name, v in items.items():
        print(f"  {name:8s} {v['median_us']:9.1f} µs per call (reps {v['min_us']:.1f}-{v['max_us']:.1f})")
    print(f"score: {score:.1f} µs (geometric mean of the medians; lower is faster)")
    result = {"machine": machine(), "python": platform.python_version(), "reps": reps, "items": items,
              "score_us": score}
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1), encoding="utf-8")
    if not args.quick:  # a smoke run is not a figure; saved for benchmarks/check_docs.py (benchmarks/figures.py)
        from figures import Figures
        figures = Figures("pi_factor")
        for name, v in items.items():
            figures.put(f"{name}_us", v["median_us"])
        figures.put("score_us", score)
        figures.save()
    if args.compare:
        other = json.loads(Path(args.compare).read_text(encoding="utf-8"))
        print(f"against {other['machine']} (its score {other['score_us']:.1f} µs):")
        for name, v in items.items():
            if name in other["items"]:
                print(f"  {name:8s} x{other['items'][name]['median_us'] / v['median_us']:5.2f}")
        print(f"factor: x{other['score_us'] / score:.2f} (its score over this machine's)")


if __name__ == "__main__":
    main()
