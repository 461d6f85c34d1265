"""What a Beast owner relies on when beastbt dies or the operator acts, measured in real time on a pty fake.

Prints, against the figures of issue 12:

1. kill-stop: ``beastbt run`` drives a fake Waveshare base (the firmware
   emulator behind a pseudo-terminal, ``tests/fake_waveshare.py``) and is
   killed with SIGKILL; the time from the kill to the firmware setting both
   wheel speeds to zero. Goal: within ``base.heartbeat_s`` + 0.2 s (0.7 s).
   Baseline in the same run: a program that drives with ``T:13`` (as beastbt
   did before), killed the same way.
2. teleop: joystick event to the first serial bytes carrying the new command,
   p99, with the joystick waking the loop and, as the baseline, without it
   (``benchmarks/teleop_latency.py``). Goal: p99 < 10 ms.

Run: python benchmarks/real_robot_safety.py [--kills 3] [--events 80]
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "benchmarks"))

from fake_waveshare import FakeWaveshare  # noqa: E402
from teleop_latency import percentile, run_adapter  # noqa: E402

HEARTBEAT_S = 0.5
DRIVE = "mission: far\nsteps:\n  - drive: {distance: 20 m, speed: 0.3 m/s}\n"
T13_DRIVER = """import json, os, sys, time
fd = os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY)
while True:
    os.write(fd, (json.dumps({"T": 13, "X": 0.3, "Z": 0.0}) + "\\n").encode())
    time.sleep(0.05)
"""


def profile(tmp: Path, port: str, firmware: str) -> Path:
    data = yaml.safe_load((REPO / "robots" / "ugv_beast.yaml").read_text(encoding="utf-8"))
    for section in ("gps", "imu", "camera", "joystick", "servos"):
        data.pop(section, None)
    data["base"].update(port=port, firmware=firmware, heartbeat_s=HEARTBEAT_S)
    path = tmp / f"beast_{firmware}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def kill_stop_s(firmware: str, beastbt: bool) -> float:
    """Seconds from SIGKILL of a driving program to zero wheel speeds on the fake (inf: it kept driving 5 s)."""
    with tempfile.TemporaryDirectory() as tmp_dir, FakeWaveshare(firmware) as fake:
        tmp = Path(tmp_dir)
        if beastbt:
            (tmp / "m.yaml").write_text(DRIVE)
            cmd = [sys.executable, "-m", "beastbt", "run", str(tmp / "m.yaml"), "--robot",
                   str(profile(tmp, fake.port, firmware)), "--no-record"]
        else:
            # The board as it boots: its one boot-time heartbeat stop is spent before anyone drives.
            time.sleep(3.2)
            cmd = [sys.executable, "-c", T13_DRIVER, fake.port]
        proc = subprocess.Popen(cmd, cwd=tmp, env=dict(os.environ, PYTHONPATH=str(REPO)),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            end = time.monotonic() + 30
            while fake.moving_since() is None and time.monotonic() < end:
                time.sleep(0.01)
            time.sleep(0.5)
            killed = time.monotonic()
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            end = killed + 5.0
            while fake.stopped_at(killed) is None and time.monotonic() < end:
                time.sleep(0.01)
            stopped = fake.stopped_at(killed)
        finally:
            if proc.poll() is None:
                proc.kill()
        return stopped - killed if stopped is not None else float("inf")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=3)
    ap.add_argument("--events", type=int, default=80)
    args = ap.parse_args()
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("real_robot_safety")
    print(f"kill -9 while driving -> wheels zero on the fake base (s); goal <= heartbeat_s + 0.2 = {HEARTBEAT_S + 0.2:g} s")
    for firmware in ("ros", "general"):
        times = [kill_stop_s(firmware, beastbt=True) for _ in range(args.kills)]
        base = kill_stop_s(firmware, beastbt=False)
        print(f"  ugv_base_{firmware:8s} beastbt: median {statistics.median(times):.3f} max {max(times):.3f} "
              f"(n={len(times)}) | a T:13 driver, killed: {'still driving after 5 s' if base == float('inf') else f'{base:.3f}'}")
        figures.put(f"kill.{firmware}.median_s", statistics.median(times))
        figures.put(f"kill.{firmware}.max_s", max(times))
    print("joystick event -> serial bytes with the new command (ms); goal p99 < 10 ms")
    for wake in (True, False):
        r = run_adapter("waveshare", args.events, 0, 1, wake=wake)
        print(f"  {'joystick wakes the loop' if wake else 'next 20 Hz tick (baseline)':28s} "
              f"p50 {1000 * percentile(r['lat'], 50):6.1f}  p99 {1000 * percentile(r['lat'], 99):6.1f}  n={len(r['lat'])}")
        key = "joystick.wake" if wake else "joystick.tick_only"
        figures.put(f"{key}.p50_ms", 1000 * percentile(r["lat"], 50))
        figures.put(f"{key}.p99_ms", 1000 * percentile(r["lat"], 99))
    figures.save()


if __name__ == "__main__":
    main()
