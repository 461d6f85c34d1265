"""What hostile input files cost ``beastbt validate``: alias bombs and huge numbers, against starting Python + PyYAML.

Each file is checked by a fresh ``python -m beastbt validate FILE`` process;
the script prints its median wall time and its peak RSS (from ``os.wait4``),
interleaved with the baseline ``python -c "import yaml"`` so both see the same
machine load, and the ratios to that baseline. Goal (issue 25): every bomb is
refused (exit 2) in under a second and under 100 MB, i.e. at about the cost of
checking a good mission. Before the bound, the 6-level bomb took 5 s and 0.66 GB,
the 10^6 waits 14 s and a MemoryError at 1.5 GB.

Run: python benchmarks/input_limits.py [--repeats N]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
BASELINE = [sys.executable, "-c", "import yaml"]
sys.path.insert(0, str(REPO / "tests"))
from hostile_yaml import laughs, million_waits  # noqa: E402 - the bombs the tests refuse



FILES = {
    "good mission (patrol.yaml)": None,
    "billion laughs, 9 levels (mission)": "mission: b\nsteps:\n  - wait: 1 s\n" + laughs(9),
    "billion laughs, 10 levels (mission)": "mission: b\nsteps:\n  - wait: 1 s\n" + laughs(10),
    "6-level bomb (mission)": "mission: b\nsteps:\n  - wait: 1 s\n" + laughs(6),
    "10^6 waits through anchors": million_waits(),
    "10^6 waits through tasks calling tasks": "mission: calls\ntasks:\n  t0:\n" + "    - wait: 1 s\n" * 10
    + "".join(f"  t{i}:\n" + f"    - do: t{i - 1}\n" * 10 for i in range(1, 6)) + "steps:\n  - do: t5\n",
    "billion laughs (world)": "world: b\n" + laughs(9),
    "billion laughs (robot profile)": "robot: b\n" + laughs(9),
    "billion laughs (joystick script)": "- {at: 1 s, press: enable}\n" + "".join(
        f"- {{at: 2 s, press: enable, x: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10 if i else ["lol"] * 10) + "]}\n"
        for i in range(9)),
    # Read whole (the aliases add 9,900 values, within the bound), then refused for its unknown keys:
    "9,900 values through aliases (world)": "world: w\nx: &x [" + ", ".join(["1"] * 99) + "]\ny:\n"
    + "".join(f"  k{i}: *x\n" for i in range(99)),
    "5000-digit wait": "mission: n\nsteps:\n  - wait: " + "9" * 5000 + "\n",
}


def measure(cmd: list[str]) -> tuple[float, float, int]:
    """(wall time s, peak RSS MB, exit status) of one run of ``cmd``; output discarded."""
    t0 = time.perf_counter()
    child = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - t0
    child.returncode = os.waitstatus_to_exitcode(status)
    return wall, usage.ru_maxrss / 1024.0, child.returncode


def main() -> None:
    """Measure every file ``--repeats`` times and print the medians."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs of each file (default 5)")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="beastbt-input-limits-"))
    paths: dict[str, str] = {}
    for i, (name, text) in enumerate(FILES.items()):
        if text is None:
            paths[name] = str(REPO / "missions" / "patrol.yaml")
        else:
            path = folder / f"f{i}.yaml"
            path.write_text(text)
            paths[name] = str(path)
    baseline: list[tuple[float, float, int]] = []
    results: dict[str, list[tuple[float, float, int]]] = {name: [] for name in FILES}
    measure(BASELINE)  # warm the file cache
    for _ in range(args.repeats):
        for name, path in paths.items():
            baseline.append(measure(BASELINE))
            results[name].append(measure([sys.executable, "-m", "beastbt", "validate", path]))
    base_s = statistics.median(b[0] for b in baseline)
    base_mb = statistics.median(b[1] for b in baseline)
    print(f"baseline python -c 'import yaml': {base_s * 1000:7.1f} ms, {base_mb:6.1f} MB peak RSS "
          f"(median of {len(baseline)})")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("input_limits")
    figures.put("baseline_ms", base_s * 1000)
    figures.put("baseline_mb", base_mb)
    for name, runs in results.items():
        wall = statistics.median(r[0] for r in runs)
        rss = statistics.median(r[1] for r in runs)
        exits = sorted({r[2] for r in runs})
        bomb = not name.startswith(("good", "9,900"))
        verdict = ("  ok" if wall < 1.0 and rss < 100 and exits == [2] else "  MISSED") if bomb else ""
        print(f"validate {name:42s} {wall * 1000:7.1f} ms = {wall / base_s:4.1f}x  {rss:6.1f} MB = "
              f"{rss / base_mb:4.1f}x  exit {','.join(map(str, exits))}{verdict}")
        key = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        figures.put(f"{key}.ms", wall * 1000)
        figures.put(f"{key}.mb", rss)
    figures.save()


if __name__ == "__main__":
    main()
