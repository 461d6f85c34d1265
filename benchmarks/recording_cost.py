"""What recording a run costs, measured in one run of this script.

Prints:
1. the tick-loop cost with and without recording: the time the loop thread
   spends in ``run.tick()`` per tick (the recorder's tick side included), on
   the patrol mission paced at FACTOR x real time so that the loop sleeps
   between ticks as it does on the robot; within that one run, blocks of
   ticks take turns without recording, with a do-nothing recorder (what any
   recorder costs the runner) and with recording, so that all see the same
   machine (goal: recording adds at most 10%);
2. the same at ``--speed max``, where the loop never sleeps and the writer
   thread competes with it for the interpreter (the GIL): here the figure is
   the wall time per tick of the whole run, writer included;
3. the size of the MCAP file of a 10-minute simulated patrol (repeat forever,
   stopped at 10 min) without images (goal: under 20 MB), and the writer's
   CPU time per tick.

Run: python benchmarks/recording_cost.py [--factor F] [--paced-s S] [--pairs N] [--max-s S]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import beastbt.plugins  # noqa: E402,F401  (installs the recorder)
from beastbt.runtime.recording import recorder_of  # noqa: E402
from beastbt.runtime.session import RunOptions, execute, prepare  # noqa: E402

PATROL = REPO / "missions" / "patrol.yaml"


def patrol_forever_text() -> str:
    """The patrol mission, repeated forever (for long runs)."""
    text = PATROL.read_text(encoding="utf-8")
    if "times: 3" not in text:
        raise SystemExit("missions/patrol.yaml changed: 'times: 3' not found")
    return text.replace("times: 3", "times: forever")


def prepared_run(record: bool, speed: object, max_time_s: float, runs_dir: str, images_hz: float = 2.0,
                 open_world: bool = False):
    """A patrol (repeated forever) prepared with or without recording."""
    opts = RunOptions(seed=1, speed=speed, max_time_s=max_time_s, record=record, runs_dir=runs_dir,
                      extras={"record_images": images_hz})
    text = patrol_forever_text()
    if open_world:
        # Without the corridor's walls: odometry drift cannot end a long run against a wall.
        text = "\n".join(line for line in text.splitlines() if not line.startswith("world:")) + "\n"
    return prepare(str(PATROL), opts, mission_text=text)


def one_run(record: bool, speed: object, max_time_s: float, runs_dir: str, images_hz: float = 2.0,
            open_world: bool = False) -> dict:
    """One patrol run through the real loop (``execute``); wall time, ticks, summary, recording path."""
    p = prepared_run(record, speed, max_time_s, runs_dir, images_hz, open_world)
    rec = recorder_of(p.run)
    t0 = time.perf_counter()
    with open(os.devnull, "w") as devnull:
        summary = execute(p, devnull)
    out = {"wall_s": time.perf_counter() - t0, "ticks": summary["ticks"], "summary": summary}
    if rec is not None:
        out["path"] = rec.paths[0]
        out["writer_cpu_s"] = rec.writer_cpu_s
    return out


def paced(factor: float, sim_s: float, block_ticks: int, runs_dir: str) -> None:
    """Section 1: loop-thread time per tick on a paced loop; recording on, off, and a do-nothing recorder, in turn."""
    p = prepared_run(True, factor, sim_s, runs_dir)
    run = p.run
    rec = recorder_of(run)
    tick = run.tick
    perf = time.perf_counter
    modes = ("off", "noop", "on")
    costs: dict[str, list[float]] = {m: [] for m in modes}
    cpu: dict[str, list[float]] = {m: [] for m in modes}
    recorders = {"off": [], "noop": [lambda r: None], "on": [rec.on_tick]}
    thread_time = time.thread_time

    def timed_tick():
        # Blocks of ticks take turns: no recorder at all (the loop then skips building the TickRecord),
        # a recorder that does nothing (what any recorder costs the runner), and the MCAP recorder; so all
        # three are measured under the same machine conditions, in one run.
        mode = modes[(run.ticks // block_ticks) % 3]
        run.recorders[:] = recorders[mode]
        c0 = thread_time()
        t0 = perf()
        status = tick()
        costs[mode].append(perf() - t0)
        cpu[mode].append(thread_time() - c0)
        return status

    run.tick = timed_tick  # execute() calls run.tick(): time exactly what the loop pays
    with open(os.devnull, "w") as devnull:
        execute(p, devnull)
    mean = {m: statistics.fmean(costs[m]) for m in modes}
    cpu_median = {m: statistics.median(cpu[m]) for m in modes}
    median = {m: statistics.median(costs[m]) for m in modes}
    print(f"1. tick-loop cost, one run paced at {factor:g}x real time, {sim_s:g} s simulated, in turns of "
          f"{block_ticks} ticks ({len(costs['off'])}/{len(costs['noop'])}/{len(costs['on'])} ticks):")
    print(f"   without recording:      {mean['off'] * 1e6:7.1f} us per tick (mean; median {median['off'] * 1e6:.1f} us)")
    print(f"   a do-nothing recorder:  {mean['noop'] * 1e6:7.1f} us per tick (mean; median {median['noop'] * 1e6:.1f} us)"
          "  (the runner's TickRecord and node changes)")
    print(f"   with recording:         {mean['on'] * 1e6:7.1f} us per tick (mean; median {median['on'] * 1e6:.1f} us)")
    print(f"   recording adds {100 * (mean['on'] / mean['off'] - 1):+.1f}% (mean), "
          f"{100 * (median['on'] / median['off'] - 1):+.1f}% (median)  [goal: at most +10%]; "
          f"writer thread CPU {rec.writer_cpu_s / max(1, len(costs['on'])) * 1e6:.0f} us per recorded tick, "
          "done while the loop sleeps")
    print(f"   CPU time of the loop's thread per tick, median (other processes do not count): without "
          f"{cpu_median['off'] * 1e6:.1f} us, do-nothing recorder {cpu_median['noop'] * 1e6:.1f} us, with recording "
          f"{cpu_median['on'] * 1e6:.1f} us ({100 * (cpu_median['on'] / cpu_median['off'] - 1):+.1f}%)")
    print("   (means move with the odd garbage collection or preemption that lands in one block of ticks; the medians "
          "are the steady cost)")


def flat_out(pairs: int, segment_s: float, runs_dir: str) -> None:
    """Section 2: wall time per tick at --speed max (the writer thread competes for the GIL)."""
    walls = {False: [], True: []}
    for _ in range(pairs):
        for record in (False, True):
            r = one_run(record, "max", segment_s, runs_dir)
            walls[record].append(r["wall_s"] / r["ticks"])
    off, on = statistics.median(walls[False]), statistics.median(walls[True])
    print(f"2. at --speed max (no sleep between ticks; writer and loop share one interpreter):")
    print(f"   without recording: {off * 1e6:7.1f} us per tick of wall time")
    print(f"   with recording:    {on * 1e6:7.1f} us per tick of wall time (writer included: "
          f"{100 * (on / off - 1):+.1f}%)")


def ten_minutes(runs_dir: str) -> None:
    """Section 3: file size of 10 simulated minutes of patrol, no images."""
    r = one_run(True, "max", 600.0, runs_dir, images_hz=0.0, open_world=True)
    size = Path(r["path"]).stat().st_size
    rec = r["summary"].get("recording", {})
    print(f"3. 10-minute simulated patrol, no images: {size / 1e6:.2f} MB "
          f"({rec.get('messages')} messages, {rec.get('dropped')} dropped, {r['ticks']} ticks; "
          f"{size / r['ticks']:.0f} bytes per tick)  [goal: under 20 MB]")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factor", type=float, default=10.0, help="pace of section 1, x real time (default 10)")
    ap.add_argument("--paced-s", type=float, default=180.0, help="simulated seconds of section 1 (default 180)")
    ap.add_argument("--block-ticks", type=int, default=20, help="ticks per on/off block in section 1 (default 20)")
    ap.add_argument("--pairs", type=int, default=3, help="section 2: runs with and without recording (default 3)")
    ap.add_argument("--max-s", type=float, default=120.0, help="simulated seconds per section-2 run (default 120)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as runs_dir:
        paced(args.factor, args.paced_s, args.block_ticks, runs_dir)
        flat_out(args.pairs, args.max_s, runs_dir)
        ten_minutes(runs_dir)


if __name__ == "__main__":
    main()
