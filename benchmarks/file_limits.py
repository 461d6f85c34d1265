"""What oversized route files, joystick scripts, GeoJSON and map images cost ``beastbt validate`` and ``run``.

The probe's inputs of issue 38, generated into a temporary folder (tests/hostile_files.py): a GPX and a KML of
2 million points (over the 16 MB cap: refused by ``stat``), a GPX and a KML of 200,000 points (under the cap, over
the 10,000 points: counted while the XML streams), a 2-million-event joystick script (63 MB) and a 200,000-event
one (under its 8 MB cap, over its 10,000 events), a 200,000-deep GeoJSON, a PGM declaring 100,000 x 100,000 pixels.
Each is checked by a fresh ``python -m beastbt`` process; the script prints its median wall time, processor time
and peak RSS (from ``os.wait4``), with ``validate missions/patrol.yaml`` interleaved as the baseline. Goal: every
one refused (exit 2) in under 2 s and under 200 MB. Before the bounds, the 2-million-point GPX was still validating
after 120 s, and the 2-million-event script reached 3.9 GB in validate and 800 MB in run.

Run: python benchmarks/file_limits.py [--repeats N]
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
sys.path.insert(0, str(REPO / "tests"))
from hostile_files import write_gpx, write_kml, write_script  # noqa: E402 - the files the tests refuse

PATROL = str(REPO / "missions" / "patrol.yaml")


def measure(cmd: list[str], cwd: Path) -> tuple[float, float, int, float]:
    """(wall time s, peak RSS MB, exit status, processor time s) of one run of ``cmd``; output discarded."""
    t0 = time.perf_counter()
    child = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             env=dict(os.environ, PYTHONPATH=str(REPO)))
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - t0
    child.returncode = os.waitstatus_to_exitcode(status)
    return wall, usage.ru_maxrss / 1024.0, child.returncode, usage.ru_utime + usage.ru_stime


def _route(folder: Path, name: str) -> str:
    mission = folder / f"route_{name.replace('.', '_')}.yaml"
    mission.write_text(f"mission: m\nsteps:\n  - route: {{file: {name}}}\n")
    return str(mission)


def probes(folder: Path) -> dict[str, list[str]]:
    """Write the probe's files into ``folder``; name -> the beastbt arguments that check one."""
    write_gpx(folder / "gpx_2m.gpx", 2_000_000)
    write_kml(folder / "kml_2m.kml", 2_000_000)
    write_gpx(folder / "gpx_200k.gpx", 200_000)
    write_kml(folder / "kml_200k.kml", 200_000)
    write_script(folder / "joystick_2m.yaml", 2_000_000)
    write_script(folder / "joystick_200k.yaml", 200_000)
    (folder / "deep.geojson").write_text("[" * 200_000 + "]" * 200_000)
    (folder / "huge.pgm").write_bytes(b"P5\n100000 100000\n255\n" + bytes(1000))
    (folder / "huge.yaml").write_text("image: huge.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    (folder / "map_mission.yaml").write_text("mission: m\nmap: huge.yaml\nsteps:\n  - wait: 1 s\n")
    return {
        "gpx 2M points (validate)": ["validate", _route(folder, "gpx_2m.gpx")],
        "kml 2M points (validate)": ["validate", _route(folder, "kml_2m.kml")],
        "gpx 200k points (validate)": ["validate", _route(folder, "gpx_200k.gpx")],
        "kml 200k points (validate)": ["validate", _route(folder, "kml_200k.kml")],
        "joystick 2M events (validate)": ["validate", str(folder / "joystick_2m.yaml")],
        "joystick 2M events (run)": ["run", PATROL, "--joystick", str(folder / "joystick_2m.yaml")],
        "joystick 200k events (validate)": ["validate", str(folder / "joystick_200k.yaml")],
        "joystick 200k events (run)": ["run", PATROL, "--joystick", str(folder / "joystick_200k.yaml")],
        "geojson 200k deep (validate)": ["validate", _route(folder, "deep.geojson")],
        "pgm 100k x 100k (validate)": ["validate", str(folder / "map_mission.yaml")],
    }


def main() -> None:
    """Check every probe ``--repeats`` times and print the medians."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs of each probe (default 3)")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="beastbt-file-limits-"))
    commands = probes(folder)
    baseline: list[tuple[float, float, int, float]] = []
    results: dict[str, list[tuple[float, float, int, float]]] = {name: [] for name in commands}
    for _ in range(args.repeats):
        for name, words in commands.items():  # interleaved: the same load for all
            baseline.append(measure([sys.executable, "-m", "beastbt", "validate", PATROL], folder))
            results[name].append(measure([sys.executable, "-m", "beastbt", *words], folder))
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("file_limits")
    base_s = statistics.median(b[0] for b in baseline)
    base_mb = statistics.median(b[1] for b in baseline)
    print(f"baseline validate patrol.yaml: {base_s * 1000:7.1f} ms, {base_mb:6.1f} MB peak RSS")
    figures.put("baseline_ms", base_s * 1000)
    figures.put("baseline_mb", base_mb)
    for name, runs in results.items():
        wall = statistics.median(r[0] for r in runs)
        rss = statistics.median(r[1] for r in runs)
        cpu = statistics.median(r[3] for r in runs)
        exits = sorted({r[2] for r in runs})
        # On a busy machine the wall time is the processor time stretched by the load: judged on the latter.
        verdict = "ok" if cpu < 2.0 and rss < 200 and exits == [2] else "MISSED"
        print(f"{name:34s} {wall * 1000:7.1f} ms ({cpu * 1000:7.1f} ms of processor) {rss:6.1f} MB  "
              f"exit {','.join(map(str, exits))}  {verdict}")
        key = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        figures.put(f"{key}.ms", wall * 1000)
        figures.put(f"{key}.cpu_ms", cpu * 1000)
        figures.put(f"{key}.mb", rss)
    figures.save()


if __name__ == "__main__":
    main()
