"""What recording a run costs: recorded runs of a mission against unrecorded runs of the same mission.

Anchor: the same mission (default missions/patrol.yaml, on the default
simulated robot, seed 1) run unrecorded (``RunOptions(record=False)``, what
``--no-record`` gives), prepared and run by the same code (``prepare``,
``execute``) in this same process. Anchor and subject runs are interleaved:
each rep runs one of each, in an order that alternates from rep to rep, so
that both see the same machine (this machine is shared: compare the ratios,
not the absolute times, with other runs of the script). Every figure is the
median over the reps, with the spread (lowest to highest) beside it.

Prints:
1. at ``--speed max``: the wall time per tick of whole runs, from the first
   tick to ``execute`` returning (so the end of a recorded run, the writer
   process draining its queue and closing the file, counts), recorded and
   unrecorded; their ratio per rep (goal, issue 26: at most 1.5x); beside it
   the tick loop alone (first tick to last), the time spent in the
   recorder's own code in the loop (``on_tick``: queueing, pickling, the
   pipe), and the CPU the writer process used per tick (on another core). A third mode, recorded with
   ``--record-sensors`` (every sensor awake and recorded), is measured in the
   same reps for comparison. Then the CPU per tick of each mode, from the
   first tick to the end: this process and the writer process's whole life
   (its start-up too), and its ratio per rep: what the wall-time ratio tends
   to on a busy machine, where the writer's CPU is taken from the loop;
2. at ``--speed realtime``: runs of ``--realtime-s`` seconds (default 20),
   recorded and unrecorded: the share of one core used while the mission
   runs (from 3 s into it to its last tick: start-up is left out), counting
   this process (every thread) and the recording's writer process; the
   difference in percentage points per rep (goal, issue 26: at most +1 % of
   a core);
3. with ``--size``: the size of the MCAP file of a 10-minute simulated patrol
   (repeated forever, stopped at 10 min; no images), goal under 20 MB;
4. with ``--nav-views``: what the global costmap's views (``/global_costmap``
   and ``/plan``, :mod:`beastbt.recording.global_views`) add to a recorded
   run at ``--speed realtime``: the patrol (``--mission``) and the fence
   crossing (missions/fence_crossing.yaml, where the global costmap changes
   at every scan and the robot plans round the fence), each recorded with the
   views and with them switched off (their sampler returns nothing), runs of
   ``--realtime-s`` seconds interleaved as in section 2; the difference in
   percentage points of one core (goal, issue 32: under 1 %); and what one
   message costs: reading the marks on the tick side and building the Grid on
   the writer's, for the fence's marks and for a 40 m window one tenth marked
   (its size too).

Run: python benchmarks/recording_cost.py [--reps N] [--realtime-s S] [--mission FILE] [--robot PROFILE] [--size]
[--skip-max] [--skip-realtime] [--nav-views]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.assembly import prepare  # noqa: E402
from beastbt.recording.recorder import recorder_of  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402
from figures import Figures  # noqa: E402  (benchmarks/figures.py, beside this script)

PATROL = REPO / "missions" / "patrol.yaml"
TICKS_PER_S = os.sysconf("SC_CLK_TCK")
MODES = ("unrecorded", "recorded", "sensors")
"""Anchor, subject, and (speed max only) the subject with --record-sensors."""


def options(mode: str, speed: object, max_time_s: Optional[float], runs_dir: str, robot: str) -> RunOptions:
    """The run options of one ``mode``; everything else the same."""
    return RunOptions(robot=robot, seed=1, speed=speed, max_time_s=max_time_s, record=mode != "unrecorded",
                      runs_dir=runs_dir, record_sensors=mode == "sensors", simulate=robot != "sim")


def _proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (0 once it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICKS_PER_S


def _children_cpu_s() -> float:
    """User + system CPU seconds of this process's children that have ended (the writer processes)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def one_run(mission: str, opts: RunOptions, window_from_s: float = 0.0, mission_text: Optional[str] = None) -> dict:
    """One run through the real loop. Returns: ticks; ``loop_s`` (first tick's start to last tick's end) and
    ``run_s`` (first tick's start to ``execute`` returning), wall seconds; ``writer_cpu_s``; and, over the window
    from the first tick at or after ``window_from_s`` of mission time to the last tick, ``window_wall_s`` and
    ``window_cpu_s`` (this process, every thread, plus the writer process)."""
    children0 = _children_cpu_s()
    p = prepare(mission, opts, mission_text=mission_text)
    run = p.run
    rec = recorder_of(run)
    tick = run.tick
    marks: dict[str, float] = {}
    perf, cpu = time.perf_counter, time.process_time

    def writer_cpu() -> float:
        proc = getattr(rec, "_proc", None) if rec is not None else None
        return _proc_cpu_s(proc.pid) if proc is not None else 0.0

    def timed_tick():
        if "first" not in marks:
            marks["first"], marks["cpu_first"] = perf(), cpu()
        if "w0" not in marks and run.elapsed_s >= window_from_s:
            marks["w0"], marks["c0"], marks["k0"] = perf(), cpu() + writer_cpu(), run.ticks
        status = tick()
        marks["last"] = perf()
        return status

    run.tick = timed_tick
    inside = [0.0]
    if rec is not None:
        on_tick = rec.on_tick

        def timed_on_tick(record) -> None:
            t0 = perf()
            on_tick(record)
            inside[0] += perf() - t0

        run.recorders[run.recorders.index(on_tick)] = timed_on_tick
    with open(os.devnull, "w") as devnull:
        # Where the window ends: the last tick; read as the loop returns, before the closers (the writer's end).
        closers = p.closers
        closers.insert(0, lambda: marks.update(w1=perf(), c1=cpu() + writer_cpu(), k1=run.ticks))
        summary = execute(p, devnull)
    end, cpu_end = perf(), cpu()
    # CPU from the first tick to the end: this process (every thread), and the writer process's whole life
    # (reaped by the end of the run: its start-up, before the first tick too, and its end count).
    cpu_s = cpu_end - marks["cpu_first"] + _children_cpu_s() - children0
    out = {"ticks": summary["ticks"], "loop_s": marks["last"] - marks["first"], "run_s": end - marks["first"],
           "cpu_s": cpu_s,
           "writer_cpu_s": rec.writer_cpu_s if rec is not None else 0.0, "on_tick_s": inside[0], "summary": summary,
           "path": rec.paths[0] if rec is not None and rec.paths else None}
    if "w0" in marks:
        out["window_wall_s"] = marks["w1"] - marks["w0"]
        out["window_cpu_s"] = marks["c1"] - marks["c0"]
        out["window_ticks"] = marks["k1"] - marks["k0"]
    return out


FIGURES = Figures("recording_cost")
"""The figures this run prints, saved at its end for benchmarks/check_docs.py (benchmarks/figures.py)."""


def spread(values: list[float], scale: float = 1.0, fmt: str = "{:.1f}") -> str:
    """``median (lowest-highest)`` of ``values`` times ``scale``."""
    return (fmt.format(statistics.median(values) * scale) + " (" + fmt.format(min(values) * scale) + "-"
            + fmt.format(max(values) * scale) + ")")


def flat_out(mission: str, robot: str, reps: int, runs_dir: str) -> None:
    """Section 1: per tick at --speed max, the three modes interleaved."""
    per_tick: dict[str, list[float]] = {m: [] for m in MODES}
    loop: dict[str, list[float]] = {m: [] for m in MODES}
    writer: dict[str, list[float]] = {m: [] for m in MODES}
    on_tick: dict[str, list[float]] = {m: [] for m in MODES}
    cpu: dict[str, list[float]] = {m: [] for m in MODES}
    ticks = 0
    one_run(mission, options("recorded", "max", None, runs_dir, robot))  # warm-up: imports, caches (not counted)
    for rep in range(reps):
        order = MODES if rep % 2 == 0 else tuple(reversed(MODES))
        for mode in order:
            r = one_run(mission, options(mode, "max", None, runs_dir, robot))
            ticks = r["ticks"]
            per_tick[mode].append(r["run_s"] / r["ticks"])
            loop[mode].append(r["loop_s"] / r["ticks"])
            writer[mode].append(r["writer_cpu_s"] / r["ticks"])
            on_tick[mode].append(r["on_tick_s"] / r["ticks"])
            cpu[mode].append(r["cpu_s"] / r["ticks"])
    print(f"1. --speed max, {Path(mission).name} on robot {robot}, {reps} reps of each ({ticks} ticks a run), "
          f"median (lowest-highest):")
    for mode, label in (("unrecorded", "unrecorded (anchor)"), ("recorded", "recorded"),
                        ("sensors", "recorded, --record-sensors")):
        print(f"   {label:27s} {spread(per_tick[mode], 1e6)} us per tick, first tick to the end of the run "
              f"(tick loop alone {spread(loop[mode], 1e6)} us, of which the recorder's own code "
              f"{spread(on_tick[mode], 1e6)} us; writer process {spread(writer[mode], 1e6, '{:.0f}')} us of CPU "
              f"per tick, on another core)")
    for mode in MODES:
        FIGURES.spread(f"max.{mode}_us", per_tick[mode], 1e6)
        FIGURES.spread(f"max.{mode}_writer_us", writer[mode], 1e6)
        FIGURES.spread(f"max.{mode}_recorder_us", on_tick[mode], 1e6)
    for mode, label in (("recorded", "recorded"), ("sensors", "with --record-sensors")):
        ratios = [b / a for a, b in zip(per_tick["unrecorded"], per_tick[mode])]
        loop_ratios = [b / a for a, b in zip(loop["unrecorded"], loop[mode])]
        goal = "  [goal: at most 1.5x]" if mode == "recorded" else ""
        FIGURES.spread(f"max.{mode}_ratio", ratios)
        print(f"   {label}: {spread(ratios, fmt='{:.2f}')}x the unrecorded run per tick{goal} "
              f"(tick loop alone {spread(loop_ratios, fmt='{:.2f}')}x)")
    # What a busy machine sees: there the writer's CPU is taken from the loop (the kernel shares a core between
    # the processes of one session), so the wall-time ratio tends to this one as the load grows.
    print(f"   CPU per tick from the first tick to the end (this process, and the writer process's whole life, "
          f"its start-up included): unrecorded {spread(cpu['unrecorded'], 1e6)} us, recorded "
          f"{spread(cpu['recorded'], 1e6)} us, --record-sensors {spread(cpu['sensors'], 1e6)} us")
    for mode in MODES:
        FIGURES.spread(f"max.{mode}_cpu_us", cpu[mode], 1e6)
    for mode, label in (("recorded", "recorded"), ("sensors", "with --record-sensors")):
        cpu_ratios = [b / a for a, b in zip(cpu["unrecorded"], cpu[mode])]
        FIGURES.spread(f"max.{mode}_cpu_ratio", cpu_ratios)
        print(f"   {label}: {spread(cpu_ratios, fmt='{:.2f}')}x the unrecorded run's CPU per tick")


def real_time(mission: str, robot: str, reps: int, seconds: float, runs_dir: str) -> None:
    """Section 2: share of one core at --speed realtime, recorded and not, interleaved."""
    share: dict[str, list[float]] = {"unrecorded": [], "recorded": []}
    for rep in range(reps):
        order = ("unrecorded", "recorded") if rep % 2 == 0 else ("recorded", "unrecorded")
        for mode in order:
            r = one_run(mission, options(mode, "realtime", seconds, runs_dir, robot), window_from_s=3.0)
            share[mode].append(r["window_cpu_s"] / r["window_wall_s"])
    diffs = [b - a for a, b in zip(share["unrecorded"], share["recorded"])]
    print(f"2. --speed realtime, {seconds:g} s runs, {reps} reps of each; share of one core from 3 s into the mission "
          f"to its last tick (this process and the writer process), median (lowest-highest):")
    print(f"   unrecorded (anchor): {spread(share['unrecorded'], 100, '{:.2f}')} %")
    print(f"   recorded:            {spread(share['recorded'], 100, '{:.2f}')} %")
    print(f"   recording adds {spread(diffs, 100, '{:+.2f}')} % of one core  [goal: at most +1 %]")
    FIGURES.spread("realtime.unrecorded_pct", share["unrecorded"], 100)
    FIGURES.spread("realtime.recorded_pct", share["recorded"], 100)
    FIGURES.spread("realtime.added_points", diffs, 100)


def patrol_forever_text() -> str:
    """The patrol mission, repeated forever, without its corridor (a long run must not end against a wall)."""
    text = PATROL.read_text(encoding="utf-8")
    if "times: 3" not in text:
        raise SystemExit("missions/patrol.yaml changed: 'times: 3' not found")
    text = text.replace("times: 3", "times: forever")
    return "\n".join(line for line in text.splitlines() if not line.startswith("world:")) + "\n"


def ten_minutes(runs_dir: str) -> None:
    """Section 3: file size of 10 simulated minutes of patrol, no images."""
    opts = RunOptions(seed=1, speed="max", max_time_s=600.0, record=True, runs_dir=runs_dir, record_images_hz=0.0)
    r = one_run(str(PATROL), opts, mission_text=patrol_forever_text())
    size = Path(r["path"]).stat().st_size
    rec = r["summary"].get("recording", {})
    print(f"3. 10-minute simulated patrol, no images: {size / 1e6:.2f} MB ({rec.get('messages')} messages, "
          f"{rec.get('dropped')} dropped, {r['ticks']} ticks; {size / r['ticks']:.0f} bytes per tick)  "
          f"[goal: under 20 MB]")
    FIGURES.put("ten_minutes.mb", size / 1e6)
    FIGURES.put("ten_minutes.bytes_per_tick", size / r["ticks"])


FENCE = REPO / "missions" / "fence_crossing.yaml"


def nav_views(mission: str, robot: str, reps: int, seconds: float, runs_dir: str) -> None:
    """Section 4: share of one core at --speed realtime, recorded with the global costmap's views and without."""
    from beastbt.recording import global_views
    sample = global_views.GlobalViewSampler.sample
    print(f"4. the global costmap's views (/global_costmap, /plan), --speed realtime, {seconds:g} s runs, {reps} reps "
          f"of each; share of one core from 3 s into the mission to its last tick (this process and the writer "
          f"process), median (lowest-highest):")
    for name, path in (("patrol", mission), ("fence", str(FENCE))):
        share: dict[str, list[float]] = {"without": [], "with": []}
        messages: list[float] = []
        for rep in range(reps):
            order = ("without", "with") if rep % 2 == 0 else ("with", "without")
            for mode in order:
                global_views.GlobalViewSampler.sample = sample if mode == "with" else (lambda self, now_s: {})
                try:
                    r = one_run(path, options("recorded", "realtime", seconds, runs_dir, robot), window_from_s=3.0)
                finally:
                    global_views.GlobalViewSampler.sample = sample
                share[mode].append(r["window_cpu_s"] / r["window_wall_s"])
                if mode == "with" and r["path"] is not None:
                    from beastbt.recording.reader import read_recording
                    rec = read_recording(r["path"], topics=["/global_costmap", "/plan"])
                    messages.append(sum(len(v) for v in rec.messages.values()))
        diffs = [b - a for a, b in zip(share["without"], share["with"])]
        print(f"   {Path(path).name}: without {spread(share['without'], 100, '{:.2f}')} %, with "
              f"{spread(share['with'], 100, '{:.2f}')} % ({spread(messages, 1, '{:.0f}')} messages on the two "
              f"channels a run); the views add {spread(diffs, 100, '{:+.2f}')} % of one core  [goal: under 1 %]")
        FIGURES.spread(f"nav_views.{name}.without_pct", share["without"], 100)
        FIGURES.spread(f"nav_views.{name}.with_pct", share["with"], 100)
        FIGURES.spread(f"nav_views.{name}.added_points", diffs, 100)
    one_message_cost()


def one_message_cost() -> None:
    """What one /global_costmap message costs on each side, for the fence's marks and a window one tenth marked."""
    import json

    import numpy as np

    from beastbt.navigation.global_planner import GlobalPlannerConfig
    from beastbt.navigation.obstacle_layer import GlobalCostmapConfig, ObstacleLayer
    from beastbt.recording import global_views
    n = 400  # the default window: 40 m at 0.1 m
    cases = {}
    fence = ObstacleLayer(GlobalCostmapConfig(), n, n, 0.1, -20.0, -20.0)
    fence.marked[280, 160:240] = True  # an 8 m fence 8 m ahead
    cases["fence"] = fence
    dense = ObstacleLayer(GlobalCostmapConfig(), n, n, 0.1, -20.0, -20.0)
    dense.marked[:] = np.random.default_rng(1).random((n, n)) < 0.1  # a cluttered window, marks everywhere
    cases["dense"] = dense
    for name, layer in cases.items():
        source = ("odom", layer, None, GlobalPlannerConfig(), 0.15)
        reps = 20
        t0 = time.process_time()
        for _ in range(reps):
            marks = global_views.marks_of(source)
        tick_us = (time.process_time() - t0) / reps * 1e6
        t0 = time.process_time()
        for _ in range(reps):
            text = json.dumps(global_views.global_costmap_grid(0, "odom", marks))
        writer_ms = (time.process_time() - t0) / reps * 1e3
        print(f"   one message, {name} ({marks.lethal.size} lethal cells of {n * n}): tick side {tick_us:.0f} us, "
              f"writer side {writer_ms:.1f} ms, {len(text) / 1e3:.1f} kB of JSON before the chunk's compression")
        FIGURES.put(f"nav_views.message.{name}.tick_us", tick_us)
        FIGURES.put(f"nav_views.message.{name}.writer_ms", writer_ms)
        FIGURES.put(f"nav_views.message.{name}.kb", len(text) / 1e3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=7, help="runs of each mode per section (default 7, at least 5)")
    ap.add_argument("--realtime-s", type=float, default=20.0, help="mission seconds of a real-time run (default 20)")
    ap.add_argument("--mission", default=str(PATROL), help="mission file (default missions/patrol.yaml)")
    ap.add_argument("--robot", default="sim", help="robot profile, run on the simulator (default sim)")
    ap.add_argument("--skip-realtime", action="store_true", help="leave out section 2 (real time)")
    ap.add_argument("--skip-max", action="store_true", help="leave out section 1 (--speed max)")
    ap.add_argument("--size", action="store_true", help="also section 3 (the size of a 10-minute recording)")
    ap.add_argument("--nav-views", action="store_true",
                    help="also section 4 (what /global_costmap and /plan add at real time)")
    args = ap.parse_args()
    if args.reps < 5:
        ap.error("--reps: at least 5 (medians over fewer say little)")
    print(f"load before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} (1, 5, 15 min)", flush=True)
    with tempfile.TemporaryDirectory() as runs_dir:
        if not args.skip_max:
            flat_out(args.mission, args.robot, args.reps, runs_dir)
        if not args.skip_realtime:
            real_time(args.mission, args.robot, args.reps, args.realtime_s, runs_dir)
        if args.size:
            ten_minutes(runs_dir)
        if args.nav_views:
            nav_views(args.mission, args.robot, args.reps, args.realtime_s, runs_dir)
    print(f"load after: {' '.join(f'{x:.2f}' for x in os.getloadavg())} (1, 5, 15 min)")
    FIGURES.save()  # benchmarks/results/recording_cost.json, quoted by docs/recording.md


if __name__ == "__main__":
    main()
