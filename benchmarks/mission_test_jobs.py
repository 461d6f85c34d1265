"""How much faster ``beastbt test -j 2`` runs a 10-seed mission test than ``-j 1`` (the issue's goal: 1.6x on two cores).

Not a test: the speed-up depends on the machine and on what else runs on it. It writes a short mission (a 3 m
drive in the corridor, a person walking toward the robot) and a test file with ``seeds`` seeds into a temporary
folder, runs ``beastbt test --no-record -j 1`` and ``-j 2`` on it (each in a process of its own, alternated,
``rounds`` times), and prints the wall times and the speed-up of the medians.
Run: python benchmarks/mission_test_jobs.py [SEEDS] [ROUNDS]
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from figures import Figures  # noqa: E402 - beside this file, as the other benchmarks import it

REPO = Path(__file__).resolve().parent.parent

MISSION = f"""\
mission: drive_corridor
world: {REPO / "worlds" / "corridor.yaml"}
steps:
  - drive: {{distance: 3 m, speed: 0.2 m/s}}
"""

TEST = """\
test: a person walks down the corridor
mission: m.yaml
seeds: {seeds}
events:
  - {{at: 2 s, person: {{from: [9, 0.5], to: [1, 0.5], speed: 0.8 m/s}}}}
"""


def timed(folder: Path, jobs: int) -> float:
    """Wall seconds of one ``beastbt test -j JOBS --no-record`` over ``folder``."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "beastbt", "test", str(folder), "-j", str(jobs), "--no-record"],
                          capture_output=True, text=True, env=env, cwd=folder)
    took = time.perf_counter() - start
    if done.returncode not in (0, 1):
        raise SystemExit(f"beastbt test failed to run:\n{done.stdout}\n{done.stderr}")
    return took


def main(seeds: int = 10, rounds: int = 3) -> None:
    """Print the wall time of -j 1 and -j 2 over ``rounds`` alternated rounds, and the speed-up of the medians."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "m.yaml").write_text(MISSION, encoding="utf-8")
        (folder / "corridor.test.yaml").write_text(TEST.format(seeds=seeds), encoding="utf-8")
        one, two = [], []
        for _ in range(rounds):
            one.append(timed(folder, 1))
            two.append(timed(folder, 2))
        print(f"cores available: {len(os.sched_getaffinity(0))}; load average: {os.getloadavg()[0]:.2f}")
        print(f"{seeds} seeds, -j 1: {', '.join(f'{t:.2f}' for t in one)} s (median {statistics.median(one):.2f})")
        print(f"{seeds} seeds, -j 2: {', '.join(f'{t:.2f}' for t in two)} s (median {statistics.median(two):.2f})")
        print(f"speed-up of -j 2 over -j 1: {statistics.median(one) / statistics.median(two):.2f}x")
        figures = Figures("mission_test_jobs")
        figures.put("seeds", float(seeds))
        figures.spread("j1_s", one)
        figures.spread("j2_s", two)
        figures.put("speedup", statistics.median(one) / statistics.median(two), 3)
        figures.save()


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
