"""CPU used by a run at ``--speed realtime``, as a share of one core, measured on this machine.

For the patrol and the line mission, recorded (the default) and with
``--no-record``: each runs as ``python -m beastbt run MISSION --speed realtime
--max-time T`` in a subprocess. The steady share is read while the mission
runs: the CPU time (user + system, from ``/proc/PID/stat``) of the run and of
its children (the recording writer) is sampled every 0.25 s, and the share is
the CPU spent between 3 s after the start-up (the recording writer starts then too) and 0.5 s before the mission's
end, over that wall time. The start-up (imports, loading, assembling) is
timed by a run of the same command with ``--max-time 0.05 s``. Beside it, the
older figure: the whole run's CPU (``getrusage(RUSAGE_CHILDREN)``) minus that
start-up run's, over the wall time minus its wall time; it also counts what
the end of a longer run costs more (closing a bigger recording), so it reads
higher.

The patrol is also run on robots/sim.yaml without its ``lidar:`` section:
the baseline, measured in the same run, against which the LiDAR's share
(emulator, driver, collision monitor, /scan) is the difference and the ratio.
Goal (issues 11 and 20): the patrol, with the LiDAR, under 5 % of one core.

Run: python benchmarks/realtime_cpu.py [--seconds T]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import yaml

REPO = Path(__file__).resolve().parent.parent
MISSIONS = {"patrol": "missions/patrol.yaml", "line": "missions/line_to_intersection.yaml"}
TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def _cpu_s(pid: int) -> Optional[float]:
    """User + system CPU seconds of process ``pid`` so far (None once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def _children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid`` (the recording writer)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", encoding="ascii") as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        out.append(int(entry))
            except (FileNotFoundError, ProcessLookupError, IndexError, ValueError):
                pass
    return out


def run(mission: str, seconds: float, record: bool, runs_dir: str,
        robot: Optional[str] = None) -> tuple[float, float, dict, list[tuple[float, float]]]:
    """(cpu s, wall s, summary, [(wall s since start, cpu s of the run and its children)]) of one realtime run of
    ``mission`` lasting at most ``seconds`` of mission time."""
    summary = Path(runs_dir) / "summary.json"
    args = [sys.executable, "-m", "beastbt", "run", mission, "--speed", "realtime", "--max-time", f"{seconds} s",
            "--summary", str(summary)] + (["--runs-dir", runs_dir] if record else ["--no-record"])
    args += ["--robot", robot, "--sim"] if robot else []
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    samples: list[tuple[float, float]] = []
    children: dict[int, float] = {}  # the latest CPU seen of each child (kept once it has ended)
    while proc.poll() is None:
        for child in _children(proc.pid):
            children[child] = _cpu_s(child) or children.get(child, 0.0)
        own = _cpu_s(proc.pid)
        if own is not None:
            samples.append((time.perf_counter() - t0, own + sum(children.values())))
        time.sleep(0.25)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, json.loads(summary.read_text()), samples


def steady_share(samples: list[tuple[float, float]], start_s: float, end_s: float) -> float:
    """CPU seconds per wall second between the samples nearest to ``start_s`` and ``end_s`` (wall s)."""
    inside = [s for s in samples if start_s <= s[0] <= end_s]
    if len(inside) < 2:
        return float("nan")
    (t0, c0), (t1, c1) = inside[0], inside[-1]
    return (c1 - c0) / max(t1 - t0, 1e-9)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="mission seconds per run (default 30)")
    args = parser.parse_args()
    runs_dir = tempfile.mkdtemp(prefix="beastbt-realtime-")
    data = yaml.safe_load((REPO / "robots" / "sim.yaml").read_text(encoding="utf-8"))
    bare_robot = Path(runs_dir) / "sim_no_lidar.yaml"
    bare_robot.write_text(yaml.safe_dump({k: v for k, v in data.items() if k != "lidar"}, sort_keys=False),
                          encoding="utf-8")
    rows = [("patrol", None, True), ("patrol", str(bare_robot), True), ("patrol", None, False),
            ("patrol", str(bare_robot), False), ("line", None, True), ("line", None, False)]
    steady: dict[tuple, float] = {}
    for name, robot, record in rows:
        start_cpu, start_wall, _, _ = run(MISSIONS[name], 0.05, record, runs_dir, robot)
        cpu, wall, summary, samples = run(MISSIONS[name], args.seconds, record, runs_dir, robot)
        # The mission runs from about start_wall to start_wall + its seconds (realtime): its middle part.
        share = steady_share(samples, start_wall + 3.0, start_wall + summary["sim_time_s"] - 0.5)
        older = (cpu - start_cpu) / max(wall - start_wall, 1e-9)
        steady[(name, robot is None, record)] = share
        label = ("recorded" if record else "--no-record") + ("" if robot is None else ", no LiDAR")
        goal = "  (goal < 5 %)" if name == "patrol" and robot is None else ""
        print(f"{name:7s} {label:23s} {summary['sim_time_s']:6.1f} s of mission in {wall:6.1f} s: cpu {cpu:5.2f} s, "
              f"start-up {start_cpu:4.2f} s; steady {100 * share:5.2f} % of one core{goal} "
              f"(whole run minus start-up: {100 * older:4.1f} %)")
    for record in (True, False):
        with_lidar, without = steady[("patrol", True, record)], steady[("patrol", False, record)]
        print(f"patrol {'recorded' if record else '--no-record'}: the LiDAR adds {100 * (with_lidar - without):4.2f} % "
              f"of one core (x{with_lidar / without:4.2f} the profile without it, measured in this run)")


if __name__ == "__main__":
    main()
