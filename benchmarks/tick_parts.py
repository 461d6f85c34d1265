"""Where a tick's time goes: the share of each stage of ``Runner.tick``, under cProfile, recorded and not.

Runs ``python -m cProfile -m beastbt run MISSION --speed max --max-time T`` in a
subprocess, recorded and with ``--no-record``, and splits the time spent inside
``beastbt/run/runner.py:tick`` among what it calls directly: the simulator's
advance (physics and the emulated devices), ``sense`` (drivers, estimator,
the recording's reads), the tree (``tick_once``), ``actuate`` (mux, gate,
collision monitor, base, the recording's writes) and the rest. Start-up is
left out (only time under ``tick`` counts).

Anchor: the tick itself; the figures are shares of it, not absolute times:
cProfile adds a cost to every Python call, so it inflates the parts made of
many small calls (the tree, the drivers) against NumPy's. The µs per tick
printed are under cProfile, for scale only; real ones are in
benchmarks/sim_speed.py and benchmarks/realtime_cpu.py.

Run: python benchmarks/tick_parts.py [--mission missions/patrol.yaml] [--seconds 60]
"""

from __future__ import annotations

import argparse
import pstats
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def parts(profile: Path, top: int = 6) -> tuple[int, float, list[tuple[str, float]]]:
    """(ticks, seconds under tick, [(callee, seconds inside it from tick)]) of a cProfile output, largest first."""
    stats = pstats.Stats(str(profile))
    tick = next(key for key in stats.stats  # type: ignore[attr-defined]
                if key[0].endswith("run/runner.py") and key[2] == "tick")
    _, ticks, _, tick_s, _ = stats.stats[tick]  # type: ignore[attr-defined]
    inside = []
    for (filename, _, name), (_, _, _, _, callers) in stats.stats.items():  # type: ignore[attr-defined]
        if tick in callers:
            where = filename.split("site-packages/")[-1].split("beastbt/")[-1]
            inside.append((f"{where}:{name}", callers[tick][3]))
    inside.sort(key=lambda item: -item[1])
    rest = tick_s - sum(s for _, s in inside[:top])
    return ticks, tick_s, inside[:top] + [("(the rest, and tick's own lines)", rest)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mission", default="missions/patrol.yaml", help="mission file (default the patrol)")
    parser.add_argument("--seconds", type=float, default=60.0, help="mission seconds per run (default 60)")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="beastbt-tick-parts-"))
    shares: dict[bool, tuple[float, list[tuple[str, float]]]] = {}
    for record in (False, True):
        profile = folder / f"{'recorded' if record else 'unrecorded'}.prof"
        command = [sys.executable, "-m", "cProfile", "-o", str(profile), "-m", "beastbt", "run", args.mission,
                   "--speed", "max", "--max-time", f"{args.seconds} s"]
        command += ["--runs-dir", str(folder)] if record else ["--no-record"]
        subprocess.run(command, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        ticks, tick_s, inside = parts(profile)
        print(f"{args.mission} {'recorded' if record else '--no-record'}: {ticks} ticks, "
              f"{tick_s / ticks * 1e6:.0f} µs per tick under cProfile")
        for name, seconds in inside:
            print(f"  {name:45s} {seconds / ticks * 1e6:7.0f} µs  {seconds / tick_s:6.1%}")
        shares[record] = (tick_s / ticks * 1e6, inside)
    # Saved for benchmarks/check_docs.py (benchmarks/figures.py prints them): docs/performance.md quotes them.
    from figures import Figures
    figures = Figures("tick_parts")
    for record, (us, inside) in shares.items():
        mode = "recorded" if record else "unrecorded"
        figures.put(f"{mode}.us_per_tick", us)
        for name, seconds in inside:
            where, _, func = name.rpartition(":")  # sim/robot.py:advance -> robot_advance
            stage = "rest" if name.startswith("(") else re.sub(r"[^a-z0-9]+", "_", f"{Path(where).stem}_{func}".lower())
            stage = stage.strip("_")
            figures.put(f"{mode}.{stage}_pct", 100 * seconds / (sum(s for _, s in inside) or 1))
    figures.save()


if __name__ == "__main__":
    main()
