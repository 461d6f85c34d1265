"""How much faster ``beastbt test -j 2`` runs a 10-seed mission test than ``-j 1`` (the issue's goal: 1.6x on two cores).

Not a test: the speed-up depends on the machine and on what else runs on it. It writes a test file of the corridor
patrol (missions/patrol.yaml, about 3 simulated minutes, a person walking the corridor) with ``seeds`` seeds into a
temporary folder (each run long enough that the run, not the start of Python, is what is measured), runs
``beastbt test --no-record -j 1`` and ``-j 2`` on it (each in a process of its own, alternated, ``rounds``
times), and prints the wall times, the speed-up of the medians, and the CPU time each took (on a shared
machine the CPU time shows what -j costs where the wall time shows the others' load).
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

TEST = """\
test: the corridor patrol with a person walking the corridor
mission: {mission}
seeds: {seeds}
max_time: 6 min
events:
  - {{at: 10 s, person: {{from: [9.5, 0.3], to: [0.5, 0.3], speed: 0.8 m/s}}}}
"""


def timed(folder: Path, jobs: int) -> tuple[float, float]:
    """Wall seconds and CPU seconds (user + system, its workers included) of one ``beastbt test -j JOBS
    --no-record`` over ``folder``."""
    import resource
    env = dict(os.environ, PYTHONPATH=str(REPO))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "beastbt", "test", str(folder), "-j", str(jobs), "--no-record"],
                          capture_output=True, text=True, env=env, cwd=folder)
    took = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in (0, 1):
        raise SystemExit(f"beastbt test failed to run:\n{done.stdout}\n{done.stderr}")
    return took, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(seeds: int = 10, rounds: int = 1) -> None:
    """Print the wall time of -j 1 and -j 2 over ``rounds`` alternated rounds, and the speed-up of the medians."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "patrol.test.yaml").write_text(TEST.format(mission=REPO / "missions" / "patrol.yaml", seeds=seeds),
                                                 encoding="utf-8")
        one, two, cpu_one, cpu_two = [], [], [], []
        for _ in range(rounds):
            for jobs, walls, cpus in ((1, one, cpu_one), (2, two, cpu_two)):
                wall, cpu = timed(folder, jobs)
                walls.append(wall)
                cpus.append(cpu)
        print(f"cores available: {len(os.sched_getaffinity(0))}; load average: {os.getloadavg()[0]:.2f}")
        print(f"{seeds} seeds, -j 1: {', '.join(f'{t:.2f}' for t in one)} s (median {statistics.median(one):.2f})")
        print(f"{seeds} seeds, -j 2: {', '.join(f'{t:.2f}' for t in two)} s (median {statistics.median(two):.2f})")
        print(f"speed-up of -j 2 over -j 1: {statistics.median(one) / statistics.median(two):.2f}x")
        # On a busy machine the wall times say more about the others than about -j; the CPU time does not: -j 2
        # costing the CPU time of -j 1 means the two cores share the work with little overhead.
        print(f"CPU time (user + system): -j 1 median {statistics.median(cpu_one):.2f} s, "
              f"-j 2 median {statistics.median(cpu_two):.2f} s")
        figures = Figures("mission_test_jobs")
        figures.put("seeds", float(seeds))
        figures.spread("j1_s", one)
        figures.spread("j2_s", two)
        figures.put("speedup", statistics.median(one) / statistics.median(two), 3)
        figures.spread("j1_cpu_s", cpu_one)
        figures.spread("j2_cpu_s", cpu_two)
        figures.save()


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
