"""Start-up cost of the ``beastbt`` command, against importing its two validation libraries, in one run.

Prints the median wall time of each command (as a fresh ``python -m beastbt``
process), interleaved with the baseline ``python -c "import yaml, jsonschema"``
so that both see the same machine load, and the ratio to that baseline.
Goal (issue 11): ``beastbt validate missions/patrol.yaml`` takes at most 3x
the baseline. ``--help``, ``tree`` and ``runs`` are printed for reference;
``run --max-time 1 s`` shows what a run pays on top (the EKF, OpenCV, the
parts of the default simulated robot).

Run: python benchmarks/startup.py [--repeats N]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PATROL = str(REPO / "missions" / "patrol.yaml")
BASELINE = [sys.executable, "-c", "import yaml, jsonschema"]


def wall_s(cmd: list[str]) -> float:
    """Wall time of one run of ``cmd`` (s); output discarded."""
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9, help="runs of each command (default 9)")
    args = parser.parse_args()
    runs_dir = tempfile.mkdtemp(prefix="beastbt-startup-")
    commands = {
        "validate missions/patrol.yaml": ["validate", PATROL],
        "--help": ["--help"],
        "tree missions/patrol.yaml": ["tree", PATROL],
        "runs": ["runs", "--runs-dir", runs_dir],
        "run patrol --max-time 1 s": ["run", PATROL, "--no-record", "--max-time", "1 s"],
    }
    times: dict[str, list[float]] = {name: [] for name in commands}
    baseline: list[float] = []
    wall_s(BASELINE)  # warm the file cache
    for _ in range(args.repeats):
        for name, words in commands.items():
            baseline.append(wall_s(BASELINE))
            times[name].append(wall_s([sys.executable, "-m", "beastbt", *words]))
    base = statistics.median(baseline)
    print(f"baseline python -c 'import yaml, jsonschema': {base * 1000:7.1f} ms (median of {len(baseline)})")
    for name, values in times.items():
        med = statistics.median(values)
        goal = "  (goal <= 3x)" if name.startswith("validate") else ""
        print(f"beastbt {name:32s} {med * 1000:7.1f} ms  = {med / base:4.2f}x baseline{goal}")


if __name__ == "__main__":
    main()
