"""Start-up cost of the ``beastbt`` command, against importing its two validation libraries, in one run.

Prints the median wall time of each command (as a fresh ``python -m beastbt``
process), interleaved with the baseline ``python -c "import yaml, jsonschema"``
so that both see the same machine load, and the ratio to that baseline.
Goals: ``beastbt validate missions/patrol.yaml`` at most 3x the baseline
(issue 11), ``beastbt tree missions/patrol.yaml`` at most 2x (issue 26);
``--help`` and ``runs`` are printed for reference. ``run --max-time 1 s``
shows what a run pays on top (OpenCV, the parts of the default simulated
robot). "first tick" is the time from starting ``beastbt run
missions/patrol.yaml --no-record`` to the start of its first tick (issue 26:
at most 1 s), read from the wall clock in the child (a wrapper around
``MissionRun.tick`` that the command itself never sees) against the wall
clock just before the child was started.

Every command, the baseline included, runs with Python's bytecode cache
written and warm (``PYTHONDONTWRITEBYTECODE`` is removed from the children's
environment and each command runs once before timing), as after an
installation: the libraries' caches are written by pip, and beastbt's own
would otherwise be compiled from source on every run. ``--cold`` keeps the
caller's environment instead (caches already written are still read).

Run: python benchmarks/startup.py [--repeats N] [--cold]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PATROL = str(REPO / "missions" / "patrol.yaml")
BASELINE = [sys.executable, "-c", "import yaml, jsonschema"]
FIRST_TICK = """
import sys, time
from beastbt.run.runner import MissionRun
tick = MissionRun.tick
def first(self):
    # The first tick's start, on the wall clock shared with the parent; then the original tick only.
    sys.stderr.write(f"FIRST_TICK {time.time()!r}\\n")
    MissionRun.tick = tick
    return tick(self)
MissionRun.tick = first
from beastbt.cli import main
sys.exit(main(sys.argv[1:]))
"""
"""The child of the first-tick figure: ``beastbt ARGS`` with the start of its first tick written to stderr."""
ENV: dict[str, str] = dict(os.environ)


def wall_s(cmd: list[str]) -> float:
    """Wall time of one run of ``cmd`` (s); output discarded."""
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False, env=ENV)
    return time.perf_counter() - t0


def first_tick_s(words: list[str]) -> float:
    """Wall time (s) from starting ``beastbt WORDS`` to the start of its first tick."""
    t0 = time.time()
    out = subprocess.run([sys.executable, "-c", FIRST_TICK, *words], cwd=REPO, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True, check=False, env=ENV)
    stamps = [line.split()[1] for line in out.stderr.splitlines() if line.startswith("FIRST_TICK ")]
    if not stamps:
        raise SystemExit(f"no tick in 'beastbt {' '.join(words)}': {out.stderr[-500:]}")
    return float(stamps[0]) - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9, help="runs of each command (default 9)")
    parser.add_argument("--cold", action="store_true", help="keep PYTHONDONTWRITEBYTECODE if the caller set it")
    args = parser.parse_args()
    if not args.cold:
        ENV.pop("PYTHONDONTWRITEBYTECODE", None)
    runs_dir = tempfile.mkdtemp(prefix="beastbt-startup-")
    commands = {
        "validate missions/patrol.yaml": ["validate", PATROL],
        "--help": ["--help"],
        "tree missions/patrol.yaml": ["tree", PATROL],
        "runs": ["runs", "--runs-dir", runs_dir],
        "run patrol --max-time 1 s": ["run", PATROL, "--no-record", "--max-time", "1 s"],
    }
    first_tick_words = ["run", PATROL, "--no-record", "--max-time", "0.1 s"]
    goals = {"validate": "  (goal <= 3x)", "tree": "  (goal <= 2x)"}
    times: dict[str, list[float]] = {name: [] for name in commands}
    first_ticks: list[float] = []
    baseline: list[float] = []
    wall_s(BASELINE)  # warm the file cache (and write the bytecode caches)
    for words in commands.values():
        wall_s([sys.executable, "-m", "beastbt", *words])
    first_tick_s(first_tick_words)
    for _ in range(args.repeats):
        for name, words in commands.items():
            baseline.append(wall_s(BASELINE))
            times[name].append(wall_s([sys.executable, "-m", "beastbt", *words]))
        baseline.append(wall_s(BASELINE))
        first_ticks.append(first_tick_s(first_tick_words))
    base = statistics.median(baseline)
    print(f"bytecode caches: {'as the caller has them' if args.cold else 'written and warm'}")
    print(f"baseline python -c 'import yaml, jsonschema': {base * 1000:7.1f} ms (median of {len(baseline)}, "
          f"{min(baseline) * 1000:.1f}-{max(baseline) * 1000:.1f})")
    for name, values in times.items():
        med = statistics.median(values)
        print(f"beastbt {name:32s} {med * 1000:7.1f} ms ({min(values) * 1000:.0f}-{max(values) * 1000:.0f})"
              f"  = {med / base:4.2f}x baseline{goals.get(name.split()[0], '')}")
    med = statistics.median(first_ticks)
    print(f"beastbt run patrol: first tick after  {med * 1000:7.1f} ms ({min(first_ticks) * 1000:.0f}-"
          f"{max(first_ticks) * 1000:.0f})  = {med / base:4.2f}x baseline  (goal <= 1000 ms)")
    # Saved for benchmarks/check_docs.py (benchmarks/figures.py prints them), for the docs that quote them.
    from figures import Figures
    figures = Figures("startup")
    figures.spread("baseline_ms", baseline, 1000)
    for name, values in times.items():
        key = name.split()[0].strip("-") if name.split()[0] != "run" else "run_1s"
        figures.spread(f"{key}_ms", values, 1000)
        figures.put(f"{key}_ratio", statistics.median(values) / base)
    figures.spread("first_tick_ms", first_ticks, 1000)
    figures.save()


if __name__ == "__main__":
    main()
