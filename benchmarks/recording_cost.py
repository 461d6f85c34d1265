"""What recording a run costs, measured in one run of this script.

Prints:
1. the tick-loop cost with and without recording: the time the loop thread
   spends in ``run.tick()`` per tick (the recorder's tick side included), on
   the patrol mission paced at FACTOR x real time so that the loop sleeps
   between ticks as it does on the robot; within that one run, blocks of
   ticks take turns without recording, with a do-nothing recorder (what any
   recorder costs the runner) and with recording, so that all see the same
   machine (goal: recording adds at most 10%). The headline is the mean
   with the slowest 1% of each mode's ticks left out (a preemption landing
   in one block moves a plain mean by several per cent); the median and
   the plain mean are printed beside it;
2. the same at ``--speed max``, where the loop never sleeps: the wall time
   per tick of the tick loop (first tick to last) with and without
   recording, in alternating pairs of runs; what the end of a run takes
   (the writer's last batch, closing the file), once per run; and the
   writer process's CPU per tick (it runs on another core);
3. the size of the MCAP file of a 10-minute simulated patrol (repeat forever,
   stopped at 10 min) without images (goal: under 20 MB).

Run: python benchmarks/recording_cost.py [--factor F] [--paced-s S] [--pairs N] [--max-s S]

The sim robot's camera is on, with images recorded at the default 2 Hz, in
sections 1 and 2; the corridor world of the patrol is left out in section
2 and 3 (a long run must not end against a wall).
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.recording.recorder import recorder_of  # noqa: E402
from beastbt.assembly import prepare  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402

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
                      record_images_hz=images_hz)
    text = patrol_forever_text()
    if open_world:
        # Without the corridor's walls: odometry drift cannot end a long run against a wall.
        text = "\n".join(line for line in text.splitlines() if not line.startswith("world:")) + "\n"
    return prepare(str(PATROL), opts, mission_text=text)


def one_run(record: bool, speed: object, max_time_s: float, runs_dir: str, images_hz: float = 2.0,
            open_world: bool = False) -> dict:
    """One patrol run through the real loop (``execute``): wall time of the whole run and of its tick loop
    (first tick's start to last tick's end), ticks, summary, recording path."""
    p = prepared_run(record, speed, max_time_s, runs_dir, images_hz, open_world)
    rec = recorder_of(p.run)
    run = p.run
    tick = run.tick
    span = [0.0, 0.0]

    def timed_tick():
        t = time.perf_counter()
        if not span[0]:
            span[0] = t
        status = tick()
        span[1] = time.perf_counter()
        return status

    run.tick = timed_tick
    t0 = time.perf_counter()
    with open(os.devnull, "w") as devnull:
        summary = execute(p, devnull)
    t1 = time.perf_counter()
    out = {"wall_s": t1 - t0, "loop_s": span[1] - span[0], "end_s": t1 - span[1], "ticks": summary["ticks"],
           "summary": summary}
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
    inside: list[float] = []

    def recording(record) -> None:
        t = perf()
        rec.on_tick(record)
        inside.append(perf() - t)

    recorders = {"off": [], "noop": [lambda r: None], "on": [recording]}
    thread_time = time.thread_time
    # Each round of three blocks visits the three modes in a random order (seeded): a fixed rotation can
    # line up with the mission's own rhythm (a drive leg, a turn) and favour one mode.
    rng = random.Random(1)
    schedule: list[str] = []
    for _ in range(4096):
        schedule.extend(rng.sample(modes, 3))

    def timed_tick():
        # Blocks of ticks take turns: no recorder at all (the loop then skips building the TickRecord),
        # a recorder that does nothing (what any recorder costs the runner), and the MCAP recorder; so all
        # three are measured under the same machine conditions, in one run.
        mode = schedule[(run.ticks // block_ticks) % len(schedule)]
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
    trimmed = {m: trimmed_mean(costs[m]) for m in modes}
    mean = {m: statistics.fmean(costs[m]) for m in modes}
    median = {m: statistics.median(costs[m]) for m in modes}
    cpu_trimmed = {m: trimmed_mean(cpu[m]) for m in modes}
    print(f"1. tick-loop cost, one run paced at {factor:g}x real time, {sim_s:g} s simulated, in turns of "
          f"{block_ticks} ticks ({len(costs['off'])}/{len(costs['noop'])}/{len(costs['on'])} ticks):")
    for m, label in (("off", "without recording:     "), ("noop", "a do-nothing recorder: "),
                     ("on", "with recording:        ")):
        print(f"   {label} {trimmed[m] * 1e6:7.1f} us per tick (mean without the slowest 1%; median "
              f"{median[m] * 1e6:.1f}, mean {mean[m] * 1e6:.1f})")
    print(f"   recording adds {100 * (trimmed['on'] / trimmed['off'] - 1):+.1f}%  [goal: at most +10%]  "
          f"(median {100 * (median['on'] / median['off'] - 1):+.1f}%, mean {100 * (mean['on'] / mean['off'] - 1):+.1f}%)")
    print(f"   CPU time of the loop's thread per tick (other processes do not count): without "
          f"{cpu_trimmed['off'] * 1e6:.1f} us, do-nothing recorder {cpu_trimmed['noop'] * 1e6:.1f} us, with recording "
          f"{cpu_trimmed['on'] * 1e6:.1f} us ({100 * (cpu_trimmed['on'] / cpu_trimmed['off'] - 1):+.1f}%)")
    print(f"   of which the recorder's own code in the loop (queueing; one pickle and one pipe write per batch): "
          f"{trimmed_mean(inside) * 1e6:.1f} us per tick (mean without the slowest 1%; median "
          f"{statistics.median(inside) * 1e6:.1f})")
    print(f"   the writer process used {rec.writer_cpu_s / max(1, len(costs['on'])) * 1e6:.0f} us of CPU per recorded "
          "tick, on another core")


def trimmed_mean(values: list[float], cut: float = 0.01) -> float:
    """The mean without the largest ``cut`` fraction of the values."""
    ordered = sorted(values)
    keep = max(1, int(round(len(ordered) * (1.0 - cut))))
    return statistics.fmean(ordered[:keep])


def flat_out(pairs: int, segment_s: float, runs_dir: str) -> None:
    """Section 2: at --speed max, with and without recording in pairs: wall time per tick of the tick loop,
    and what the end of the run (the writer draining, the file closed) adds once."""
    loops: dict[bool, list[float]] = {False: [], True: []}
    ends: dict[bool, list[float]] = {False: [], True: []}
    writer_cpu: list[float] = []
    for _ in range(pairs):
        for record in (False, True):
            r = one_run(record, "max", segment_s, runs_dir, open_world=True)
            loops[record].append(r["loop_s"] / r["ticks"])
            ends[record].append(r["end_s"])
            if record:
                writer_cpu.append(r["writer_cpu_s"] / r["ticks"])
    off, on = statistics.median(loops[False]), statistics.median(loops[True])
    ratios = [b / a - 1 for a, b in zip(loops[False], loops[True])]
    print(f"2. at --speed max (no sleep between ticks), {pairs} pairs of {segment_s:g} s simulated runs, median:")
    print(f"   without recording: {off * 1e6:7.1f} us per tick of wall time")
    print(f"   with recording:    {on * 1e6:7.1f} us per tick of wall time")
    print(f"   recording adds {100 * statistics.median(ratios):+.1f}% (median of the pairs: "
          + ", ".join(f"{100 * r:+.0f}%" for r in ratios) + ")  [goal: at most +10%]")
    print(f"   the end of a run (summary, files; with recording the writer's last batch and closing the file): "
          f"{statistics.median(ends[False]) * 1e3:.0f} ms without, {statistics.median(ends[True]) * 1e3:.0f} ms with")
    print(f"   the writer process used {statistics.median(writer_cpu) * 1e6:.0f} us of CPU per tick, on another core")


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
    ap.add_argument("--block-ticks", type=int, default=10, help="ticks per on/off block in section 1 (default 10)")
    ap.add_argument("--pairs", type=int, default=7, help="section 2: runs with and without recording (default 7)")
    ap.add_argument("--max-s", type=float, default=300.0, help="simulated seconds per section-2 run (default 300)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as runs_dir:
        paced(args.factor, args.paced_s, args.block_ticks, runs_dir)
        flat_out(args.pairs, args.max_s, runs_dir)
        ten_minutes(runs_dir)


if __name__ == "__main__":
    main()
