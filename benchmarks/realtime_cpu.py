"""CPU used by a run at ``--speed realtime``, as a share of one core, measured on this machine.

For the patrol and the line mission, recorded (the default) and with
``--no-record``: each runs as ``python -m beastbt run MISSION --speed realtime
--max-time T`` in a subprocess whose CPU time (its own and its recording
writer's, user + system) is read with ``getrusage(RUSAGE_CHILDREN)``. A run
of the same command with ``--max-time 0.05 s`` measures the start-up
(imports, loading, assembling), so that the steady share, ``(cpu - start-up
cpu) / (wall - start-up wall)``, is what the loop costs while it runs.
Goal (issue 11): the patrol under 5 % of one core.

Run: python benchmarks/realtime_cpu.py [--seconds T]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
MISSIONS = {"patrol": "missions/patrol.yaml", "line": "missions/line_to_intersection.yaml"}


def run(mission: str, seconds: float, record: bool, runs_dir: str) -> tuple[float, float, dict]:
    """(cpu s, wall s, summary) of one realtime run of ``mission`` lasting at most ``seconds`` of mission time."""
    summary = Path(runs_dir) / "summary.json"
    args = [sys.executable, "-m", "beastbt", "run", mission, "--speed", "realtime", "--max-time", f"{seconds} s",
            "--summary", str(summary)] + (["--runs-dir", runs_dir] if record else ["--no-record"])
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(args, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, json.loads(summary.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="mission seconds per run (default 30)")
    args = parser.parse_args()
    runs_dir = tempfile.mkdtemp(prefix="beastbt-realtime-")
    for name, mission in MISSIONS.items():
        for record in (True, False):
            start_cpu, start_wall, _ = run(mission, 0.05, record, runs_dir)
            cpu, wall, summary = run(mission, args.seconds, record, runs_dir)
            steady = (cpu - start_cpu) / max(wall - start_wall, 1e-9)
            label = "recorded" if record else "--no-record"
            print(f"{name:7s} {label:12s} {summary['sim_time_s']:6.1f} s of mission in {wall:6.1f} s: cpu {cpu:5.2f} s, "
                  f"start-up {start_cpu:4.2f} s; steady {100 * steady:5.1f} % of one core"
                  + ("  (goal < 5 %)" if name == "patrol" else ""))


if __name__ == "__main__":
    main()
