"""A benchmark's last output: the figures it printed, saved to ``benchmarks/results/<benchmark>.json``.

Each benchmark collects the figures it prints in a :class:`Figures` and calls :meth:`Figures.save` at the end of
its ``main()``. The results files are committed: they are the "last output" that ``benchmarks/check_docs.py``
compares the figures quoted in README.md and docs/ with (CI never runs the benchmarks). ``save`` also prints
every figure it saves under its key, so that whatever the docs quote is on the benchmark's own output.

A results file holds, for each figure, its value and the run that measured it (UTC time, command line, load
average, machine). A run merges into the file: the figures it measured replace theirs, the others (a part the
run left out, e.g. ``console.py --only cpu``) keep the run that measured them.

``BEASTBT_FIGURES_DIR`` (an environment variable) saves elsewhere, e.g. for a trial run that must not touch the
committed figures. Keys are lower-case words joined by dots (``patrol.recorded_lidar_console.pct``); the docs
quote a figure as ``<benchmark>.<key>`` (see docs/performance.md, "How the figures are checked").
"""

from __future__ import annotations

import datetime
import json
import math
import os
import platform
import re
import shlex
import statistics
import sys
from pathlib import Path
from typing import Iterable, Optional

RESULTS = Path(__file__).resolve().parent / "results"
REPO = RESULTS.parent.parent
KEY = re.compile(r"^[a-z0-9_]+(\.[a-z0-9_]+)*$")


def results_dir() -> Path:
    """Where results files are read and written: ``BEASTBT_FIGURES_DIR`` or ``benchmarks/results``."""
    env = os.environ.get("BEASTBT_FIGURES_DIR")
    return Path(env) if env else RESULTS


def machine() -> str:
    """A one-line summary of this machine: CPU model, cores, architecture, Python."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace").splitlines():
            if line.split(":")[0].strip() in ("model name", "Model"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores ({platform.machine()}), Python {platform.python_version()}"


def command_line() -> str:
    """The command that ran this benchmark, as a person would type it from the repository's root."""
    script = Path(sys.argv[0]).resolve()
    try:
        script_text = str(script.relative_to(REPO))
    except ValueError:
        script_text = sys.argv[0]
    return shlex.join(["python", script_text, *sys.argv[1:]])


def dumps(data: dict) -> str:
    """A results file's text: one line per run and per figure, so that a diff shows which figures changed."""
    def one(value: object) -> str:
        return json.dumps(value, ensure_ascii=False)  # on one line, no indentation

    runs = ",\n".join(f"  {one(run)}" for run in data["runs"])
    figures = ",\n".join(f"  {one(key)}: {one(fig)}" for key, fig in data["figures"].items())
    return (f'{{\n "benchmark": {one(data["benchmark"])},\n "runs": [\n{runs}\n ],\n'
            f' "figures": {{\n{figures}\n }}\n}}\n')


class Figures:
    """The named figures one benchmark run printed; ``save`` writes them to its results file.

    ``benchmark`` is the results file's name (the script's stem: ``console`` for benchmarks/console.py).
    """

    def __init__(self, benchmark: str) -> None:
        """An empty set of figures for ``benchmark``."""
        self.benchmark = benchmark
        self.values: dict[str, float] = {}

    def put(self, key: str, value: float, digits: int = 6) -> float:
        """Keep ``value`` under ``key`` (rounded to ``digits`` significant digits); return it."""
        if not KEY.match(key):
            raise ValueError(f"figure key {key!r}: expected lower-case words joined by dots")
        value = float(value)
        if math.isfinite(value) and value != 0:
            value = round(value, digits - 1 - int(math.floor(math.log10(abs(value)))))
        self.values[key] = value
        return value

    def spread(self, key: str, values: Iterable[float], scale: float = 1.0) -> None:
        """Keep the median, min and max of ``values`` times ``scale`` as ``key.median``, ``key.min``, ``key.max``."""
        vals = [v * scale for v in values]
        if not vals:
            return
        self.put(f"{key}.median", statistics.median(vals))
        self.put(f"{key}.min", min(vals))
        self.put(f"{key}.max", max(vals))

    def save(self, out=None) -> Optional[Path]:
        """Merge these figures into ``<results>/<benchmark>.json``, print them, and return the file's path."""
        if not self.values:
            return None
        folder = results_dir()
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{self.benchmark}.json"
        old: dict = {}
        if path.exists():
            try:
                old = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                old = {}
        run = {"utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
               "command": command_line(), "load": [round(x, 2) for x in os.getloadavg()], "machine": machine()}
        runs: list[dict] = list(old.get("runs", []))
        figures: dict[str, dict] = {k: v for k, v in old.get("figures", {}).items() if k not in self.values}
        runs.append(run)
        for key, value in self.values.items():
            figures[key] = {"value": value, "run": len(runs) - 1}
        # Keep only the runs some figure still comes from, renumbered in order.
        used = sorted({f["run"] for f in figures.values()})
        renumber = {old_i: new_i for new_i, old_i in enumerate(used)}
        data = {"benchmark": self.benchmark, "runs": [runs[i] for i in used],
                "figures": {k: {"value": f["value"], "run": renumber[f["run"]]} for k, f in sorted(figures.items())}}
        path.write_text(dumps(data), encoding="utf-8")
        stream = out or sys.stdout
        try:
            shown = path.resolve().relative_to(REPO)
        except ValueError:
            shown = path
        print(f"figures saved to {shown} (quoted in the docs as {self.benchmark}.KEY; "
              f"load {run['load'][0]:.2f}):", file=stream)
        for key, value in self.values.items():
            print(f"  {key} = {value:g}", file=stream)
        return path
