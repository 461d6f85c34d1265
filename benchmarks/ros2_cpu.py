"""What ``--ros2`` adds to a realtime patrol with the LiDAR: share of one core, with a ROS 2 laptop subscribed.

The patrol (missions/patrol.yaml, robots/sim.yaml with its LD19) runs at
``--speed realtime --no-record`` twice per rep, interleaved: without the
link, and with ``--ros2 tcp/127.0.0.1:PORT`` while a Zenoh peer in this
process subscribes to ``**`` (what rmw_zenoh on a laptop with rviz2 open
does: every topic flows). The steady share is measured as in
benchmarks/realtime_cpu.py (CPU of the run and its children from /proc,
from 3 s after the start to 0.5 s before the end, over that wall time); the
peer's own CPU is not counted (it is the laptop's). What ``--ros2`` costs
includes the sensors it keeps awake for its topics (the IMU, the battery).
Goal of issue 35: at most 1 % of one core.

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


def one_run(seconds: float, ros2: bool) -> tuple[float, int]:
    """(steady share of one core, messages the peer got) of one realtime patrol."""
    port = _free_port()
    args = [sys.executable, "-m", "beastbt", "run", "missions/patrol.yaml", "--speed", "realtime", "--max-time",
            f"{seconds} s", "--no-record"] + (["--ros2", f"tcp/127.0.0.1:{port}"] if ros2 else [])
    env = dict(os.environ, PYTHONPATH=str(REPO))
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    count = [0]
    lock = threading.Lock()
    session = None
    samples: list = []
    children: dict[int, float] = {}
    try:
        while proc.poll() is None:
            if ros2 and session is None and time.perf_counter() - t0 > 1.0:
                session = _subscribe(port, count, lock)
            for child in _children(proc.pid):
                children[child] = _cpu_s(child) or children.get(child, 0.0)
            own = _cpu_s(proc.pid)
            if own is not None:
                samples.append((time.perf_counter() - t0, own + sum(children.values()), []))
            time.sleep(0.25)
    finally:
        if session is not None:
            session.close()
    wall = time.perf_counter() - t0
    return steady_share(samples, 3.0, wall - 0.5), count[0]


def _subscribe(port: int, count: list, lock: threading.Lock) -> Optional[object]:
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
    session.declare_subscriber("**", take)
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
        share, _ = one_run(args.seconds, False)
        base.append(share)
        share, n = one_run(args.seconds, True)
        with_ros2.append(share)
        messages.append(n)
        print(f"rep {rep + 1}: without {base[-1] * 100:.2f} %, with --ros2 {with_ros2[-1] * 100:.2f} % of a core "
              f"({n} messages to the peer)", flush=True)
    added = [w - b for w, b in zip(with_ros2, base)]
    figures.spread("patrol.pct", base, 100.0)
    figures.spread("patrol_ros2.pct", with_ros2, 100.0)
    figures.spread("added.pct", added, 100.0)
    figures.put("messages_per_s", statistics.median(messages) / max(args.seconds - 1.0, 1.0))
    figures.save()


if __name__ == "__main__":
    main()
