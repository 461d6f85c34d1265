"""What the ROS 2 link's CDR encoding costs: microseconds per message, for the messages a run sends most.

Encodes, many times over, an LD19 revolution as ``sensor_msgs/LaserScan``
(455 points with intensities: what ``/scan`` sends ten times a second), an
``nav_msgs/Odometry`` and a four-transform ``tf2_msgs/TFMessage`` (what
``/odom`` and ``/tf`` send at the pose rate), and prints the median time per
message over several rounds. Goal of issue 35: a LaserScan in at most 50 µs.
Timed with this thread's CPU time (on a shared machine the wall clock counts
other processes).

Run: python benchmarks/ros2_cdr.py [--rounds 7] [--count 2000]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.ros2 import cdr  # noqa: E402


def per_message_us(fn, count: int, rounds: int) -> float:
    """The median over ``rounds`` of the CPU time of one call of ``fn`` (µs), each round ``count`` calls."""
    times = []
    for _ in range(rounds):
        t0 = time.thread_time()
        for _ in range(count):
            fn()
        times.append((time.thread_time() - t0) / count * 1e6)
    return statistics.median(times)


def main() -> None:
    """Time the encoders and save the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--count", type=int, default=2000)
    args = ap.parse_args()
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("ros2_cdr")
    rng = np.random.default_rng(1)
    ranges = rng.uniform(0.05, 12.0, 455)  # float64 as the driver gives them: the encoder converts
    intens = rng.integers(0, 255, 455).astype(float)
    stamp = 1_733_520_000_123_456_789

    def scan() -> bytes:
        return cdr.encode_laser_scan(stamp, "lidar", -math.pi, math.pi, 2 * math.pi / 455, 1e-4 / 455, 0.1, 0.02,
                                     12.0, ranges, intens)

    cov = [0.0] * 36

    def odom() -> bytes:
        return cdr.encode_odometry(stamp, "odom", "base_link", (1.0, 2.0, 0.0), cdr.yaw_quaternion(0.3),
                                   (0.3, 0.0, 0.0), (0.0, 0.0, 0.1), cov, cov)

    transforms = [cdr.Transform(stamp, "map", "odom"), cdr.Transform(stamp, "odom", "base_link", (1.0, 2.0, 0.0)),
                  cdr.Transform(stamp, "base_link", "lidar", (0.0, 0.0, 0.2)),
                  cdr.Transform(stamp, "base_link", "camera_link", (0.1, 0.0, 0.2))]

    def tf() -> bytes:
        return cdr.encode_tf(transforms)

    for name, fn in (("laser_scan", scan), ("odometry", odom), ("tf4", tf)):
        us = per_message_us(fn, args.count, args.rounds)
        figures.put(f"{name}.us", us)
    figures.put("laser_scan.bytes", len(scan()))
    figures.save()


if __name__ == "__main__":
    main()
