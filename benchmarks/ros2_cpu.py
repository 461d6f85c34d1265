"""What ``--ros2`` adds to a realtime patrol with the LiDAR: share of one core, with a ROS 2 laptop subscribed.

The patrol (missions/patrol.yaml, robots/sim.yaml with its LD19) runs at
``--speed realtime --no-record`` twice per rep, side by side (paired: on a
shared machine both runs see the same load, so their difference is the
link's, not the neighbours'): without the link, and with ``--ros2
tcp/127.0.0.1:PORT`` while a Zenoh peer in this process subscribes to ``**``
(a laptop that takes every topic: the most a link sends). The steady share is measured as in
benchmarks/realtime_cpu.py (CPU of the run and its children from /proc,
from 3 s after the start to 0.5 s before the end, over that wall time); the
peer's own CPU is not counted (it is the laptop's). What ``--ros2`` costs
includes the sensors it keeps awake for its topics (the IMU, the battery).
Goal of issue 35: at most 1 % of one core.

A second row subscribes only to what docs/ros2/beastbt.rviz shows (``/map``,
``/tf``, ``/tf_static``, ``/scan``, ``/odom``, ``/plan``): the link makes and
sends nothing else (Zenoh's matching status).

Run: python benchmarks/ros2_cpu.py [--seconds 20] [--reps 3]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from realtime_cpu import _children, _cpu_s, steady_share  # noqa: E402 - the same measurement


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


RVIZ_KEYS = tuple(f"0/{name}/**" for name in ("map", "tf", "tf_static", "scan", "odom", "plan"))
"""What rviz2 with docs/ros2/beastbt.rviz subscribes to (the camera display is off)."""


def paired_run(seconds: float, keys: tuple[str, ...] = ("**",)) -> tuple[float, float, int]:
    """(steady share of one core without the link, with it, messages the peer got) of two realtime patrols run
    side by side, the peer subscribed to ``keys``."""
    port = _free_port()
    env = dict(os.environ, PYTHONPATH=str(REPO))

    def start(ros2: bool) -> subprocess.Popen:
        args = [sys.executable, "-m", "beastbt", "run", "missions/patrol.yaml", "--speed", "realtime", "--max-time",
                f"{seconds} s", "--no-record"] + (["--ros2", f"tcp/127.0.0.1:{port}"] if ros2 else [])
        return subprocess.Popen(args, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    t0 = time.perf_counter()
    procs = {False: start(False), True: start(True)}
    count = [0]
    lock = threading.Lock()
    session = None
    samples: dict[bool, list] = {False: [], True: []}
    children: dict[bool, dict[int, float]] = {False: {}, True: {}}
    ends: dict[bool, float] = {}
    try:
        while len(ends) < 2:
            now = time.perf_counter() - t0
            if session is None and now > 1.0:
                session = _subscribe(port, count, lock, keys)
            for ros2, proc in procs.items():
                if ros2 in ends:
                    continue
                if proc.poll() is not None:
                    ends[ros2] = now
                    continue
                kids = children[ros2]
                for child in _children(proc.pid):
                    kids[child] = _cpu_s(child) or kids.get(child, 0.0)
                own = _cpu_s(proc.pid)
                if own is not None:
                    samples[ros2].append((now, own + sum(kids.values()), []))
            time.sleep(0.25)
    finally:
        if session is not None:
            session.close()
    base, with_link = (steady_share(samples[r], 3.0, ends[r] - 0.5) for r in (False, True))
    return base, with_link, count[0]


def _subscribe(port: int, count: list, lock: threading.Lock, keys: tuple[str, ...]) -> Optional[object]:
    import zenoh
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    try:
        session = zenoh.open(conf)
    except Exception:  # noqa: BLE001 - not listening yet: tried again on the next sample
        return None

    def take(sample: object) -> None:
        with lock:
            count[0] += 1
    for key in keys:
        session.declare_subscriber(key, take)
    return session


def main() -> None:
    """Run the rows and save the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    from figures import Figures
    figures = Figures("ros2_cpu")
    base, with_ros2, messages = [], [], []
    for rep in range(args.reps):
        share, share_ros2, n = paired_run(args.seconds)
        base.append(share)
        with_ros2.append(share_ros2)
        messages.append(n)
        print(f"rep {rep + 1}: without {base[-1] * 100:.2f} %, with --ros2 {with_ros2[-1] * 100:.2f} % of a core "
              f"({n} messages to the peer)", flush=True)
    added = [w - b for w, b in zip(with_ros2, base)]
    figures.spread("patrol.pct", base, 100.0)
    figures.spread("patrol_ros2.pct", with_ros2, 100.0)
    figures.spread("added.pct", added, 100.0)
    figures.put("messages_per_s", statistics.median(messages) / max(args.seconds - 1.0, 1.0))
    rviz, rviz_messages = [], []
    for rep in range(args.reps):
        share, share_ros2, n = paired_run(args.seconds, RVIZ_KEYS)
        rviz.append(share_ros2 - share)
        rviz_messages.append(n)
        print(f"rviz rep {rep + 1}: without {share * 100:.2f} %, with --ros2 {share_ros2 * 100:.2f} % of a core "
              f"({n} messages to rviz2's topics)", flush=True)
    figures.spread("added_rviz.pct", rviz, 100.0)
    figures.put("rviz_messages_per_s", statistics.median(rviz_messages) / max(args.seconds - 1.0, 1.0))
    figures.save()


if __name__ == "__main__":
    main()
