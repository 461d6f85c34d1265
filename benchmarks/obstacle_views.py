"""What the obstacle views cost the tick loop and the recording, measured in one run of this script.

One simulated patrol in the corridor with the pacing person (worlds/corridor_person.yaml, robots/sim.yaml with
its LD19), recorded, with a hand-made local planner writing a 60 x 60 costmap and a plan on the blackboard every
scan (what go_to will do). Prints, per tick:

1. the obstacle sampler's time in the loop (:class:`~beastbt.recording.obstacle_views.ObstacleSampler.sample`)
   against the whole tick's (``run.tick``) in the same run;
2. the console's obstacle layers (:func:`~beastbt.live.console_state.obstacle_layers`) against the whole
   console state that holds them (``ConsoleState.build``), each built every tick here (the console builds
   its state at most 10 times a second of wall time);
3. the bytes the new channels add to the MCAP (their messages' JSON, before compression) against all channels.

Run: python benchmarks/obstacle_views.py [--seconds S]
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.assembly import prepare  # noqa: E402
from beastbt.blackboard import catalogue  # noqa: E402
from beastbt.blackboard.types import COST_LETHAL, LocalCostmap, LocalPlan  # noqa: E402
from beastbt.live.console_state import ConsoleState, MapFrame, obstacle_layers  # noqa: E402
from beastbt.recording import obstacle_views  # noqa: E402
from beastbt.recording.obstacle_views import board_reader  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402

NEW = ("/costmap", "/local_plan", "/collision_monitor/zones", "/sim/persons", "/sim/contact")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="simulated seconds (default 60)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        p = prepare(str(REPO / "missions" / "patrol.yaml"),
                    RunOptions(seed=1, max_time_s=args.seconds, runs_dir=tmp,
                               world=str(REPO / "worlds" / "corridor_person.yaml")))
        run = p.run
        board = catalogue.writer("bench_planner", ("costmap", "local_plan"))
        last = [-1.0]

        def planner(r, now_s: float) -> None:
            if now_s - last[0] >= 0.1 - 1e-9:
                last[0] = now_s
                cost = np.zeros((60, 60), dtype=np.uint8)
                cost[::7, ::5] = COST_LETHAL
                board.costmap = LocalCostmap(now_s, r.odom.x - 1.5, r.odom.y - 1.5, 0.05, cost)
            board.local_plan = LocalPlan(now_s, np.column_stack((np.linspace(0, 1, 20) + r.odom.x,
                                                                 np.full(20, r.odom.y))), 0.2)

        run.hooks.append(planner)
        sampler_s: list[float] = []
        real_sample = obstacle_views.ObstacleSampler.sample

        def timed_sample(self, now_s: float):
            t0 = time.perf_counter()
            out = real_sample(self, now_s)
            sampler_s.append(time.perf_counter() - t0)
            return out

        obstacle_views.ObstacleSampler.sample = timed_sample  # type: ignore[method-assign]
        tick_s: list[float] = []
        real_tick = run.tick

        def timed_tick():
            t0 = time.perf_counter()
            out = real_tick()
            tick_s.append(time.perf_counter() - t0)
            return out

        run.tick = timed_tick  # type: ignore[method-assign]
        layers_s: list[float] = []
        build_s: list[float] = []
        state = ConsoleState(run, p.world, time.monotonic, period_s=1e9)
        reader = board_reader()

        frame = MapFrame(run, p.world)

        def console(r, now_s: float) -> None:
            pose = frame.pose()
            t0 = time.perf_counter()
            obstacle_layers(r, frame, reader, now_s, pose)
            t1 = time.perf_counter()
            state.build()
            t2 = time.perf_counter()
            layers_s.append(t1 - t0)
            build_s.append(t2 - t1)

        run.hooks.append(console)
        execute(p, io.StringIO())
        obstacle_views.ObstacleSampler.sample = real_sample  # type: ignore[method-assign]
        sizes: dict[str, int] = {}
        from mcap.reader import make_reader
        with open(Path(p.folder.path) / "run.mcap", "rb") as f:
            for _, channel, message in make_reader(f).iter_messages():
                sizes[channel.topic] = sizes.get(channel.topic, 0) + len(message.data)
        mcap_bytes = (Path(p.folder.path) / "run.mcap").stat().st_size

    us = 1e6
    n = len(tick_s)
    print(f"{n} ticks, {args.seconds:g} s simulated, the planner writing a 60 x 60 costmap at 10 Hz and a plan "
          "each tick")
    print(f"1. sampler in the loop: {np.mean(sampler_s) * us:.1f} us per tick "
          f"(median {np.median(sampler_s) * us:.1f}); whole tick {np.mean(tick_s) * us:.0f} us: {np.mean(sampler_s) / np.mean(tick_s):.1%} of the tick")
    print(f"2. console obstacle layers: {np.mean(layers_s) * us:.0f} us (median {np.median(layers_s) * us:.0f}) of the "
          f"whole state's {np.mean(build_s) * us:.0f} us ({np.mean(layers_s) / np.mean(build_s):.0%}); built at most "
          f"10 times a second of wall time: {10 * np.mean(layers_s):.2%} of a core at most")
    new = sum(sizes.get(t, 0) for t in NEW)
    total = sum(sizes.values())
    print(f"3. new channels: {new / 1024:.0f} kB of {total / 1024:.0f} kB of JSON ({new / total:.1%}); "
          + ", ".join(f"{t} {sizes.get(t, 0) / 1024:.0f} kB" for t in NEW) + f"; the file {mcap_bytes / 1024:.0f} kB")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("obstacle_views")
    figures.put("sampler_median_us", np.median(sampler_s) * us)
    figures.put("sampler_mean_us", np.mean(sampler_s) * us)
    figures.put("layers_median_ms", np.median(layers_s) * 1000)
    figures.put("layers_pct_at_most", 1000 * np.mean(layers_s))
    figures.put("new_channels_pct", 100 * new / total)
    figures.save()


if __name__ == "__main__":
    main()
