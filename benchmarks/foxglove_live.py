"""What serving a run live to Foxglove costs the tick loop, measured in one run of this script.

Prints the time the loop thread spends in ``run.tick()`` per tick on the
patrol, paced at FACTOR x real time (the loop sleeps between ticks, as on the
robot), recorded as usual, in three modes that take turns in rounds of runs
(so that all see the same machine):

* ``recorded``: recording only (the baseline, no ``--foxglove``);
* ``live, no client``: ``--foxglove`` on a free port, nobody connected;
* ``live, 1 client``: the same with one WebSocket client (another process,
  as Foxglove would be) subscribed to every channel, counting what arrives.

Goal: one connected client adds at most 5 % per tick to ``live, no client``.
The headline is the mean with the slowest 1 % of each mode's ticks left out
(one preemption moves a plain mean by several per cent); the median is
printed beside it. Also printed: the messages and megabytes the client got,
and the writer process's CPU per tick (the live server runs in it, on
another core).

Run: python benchmarks/foxglove_live.py [--factor F] [--sim-s S] [--rounds N]
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from beastbt.assembly import prepare  # noqa: E402
from beastbt.recording.recorder import recorder_of  # noqa: E402
from beastbt.run.session import RunOptions, execute  # noqa: E402

PATROL = REPO / "missions" / "patrol.yaml"

CLIENT = r'''
import asyncio, json, sys, time
import websockets

async def main(port):
    deadline = time.monotonic() + 30
    while True:
        try:
            ws = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                                          max_size=None)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)
    messages = size = 0
    async with ws:
        try:
            async for frame in ws:
                if isinstance(frame, str):
                    op = json.loads(frame)
                    if op["op"] == "advertise":
                        subs = [{"id": i, "channelId": c["id"]} for i, c in enumerate(op["channels"])]
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                elif frame[0] == 1:
                    messages += 1
                    size += len(frame)
        except websockets.ConnectionClosed:
            pass
    print(messages, size)

asyncio.run(main(int(sys.argv[1])))
'''
"""A Foxglove-protocol client in its own process: subscribes to every channel, counts messages until the end."""

MODES = ("recorded", "live, no client", "live, 1 client")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def trimmed_mean(values: list[float], cut: float = 0.01) -> float:
    """The mean without the largest ``cut`` fraction of the values."""
    ordered = sorted(values)
    keep = max(1, int(round(len(ordered) * (1.0 - cut))))
    return statistics.fmean(ordered[:keep])


def one_run(mode: str, factor: float, sim_s: float, runs_dir: str) -> dict:
    """One paced patrol in ``mode``: the loop thread's time in each tick (s), the client's counts, writer CPU."""
    port = free_port()
    live = ("127.0.0.1", port) if mode != "recorded" else None
    opts = RunOptions(seed=1, speed=factor, max_time_s=sim_s, record=True, runs_dir=runs_dir, foxglove=live)
    p = prepare(str(PATROL), opts)
    run, rec = p.run, recorder_of(p.run)
    tick = run.tick
    costs: list[float] = []
    perf = time.perf_counter

    def timed_tick():
        t = perf()
        status = tick()
        costs.append(perf() - t)
        return status

    run.tick = timed_tick  # execute() calls run.tick(): time exactly what the loop pays
    client = None
    if mode == "live, 1 client":
        client = subprocess.Popen([sys.executable, "-c", CLIENT, str(port)], stdout=subprocess.PIPE, text=True)
    with open(os.devnull, "w") as devnull:
        execute(p, devnull)
    out = {"costs": costs, "writer_cpu_s": rec.writer_cpu_s / max(1, len(costs))}
    if client is not None:
        messages, size = (int(v) for v in client.communicate(timeout=60)[0].split())
        out.update(messages=messages, bytes=size)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--factor", type=float, default=4.0, help="pace, times real time (default 4)")
    ap.add_argument("--sim-s", type=float, default=30.0, help="simulated seconds per run (default 30)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of the three modes (default 3)")
    args = ap.parse_args()
    costs: dict[str, list[float]] = {m: [] for m in MODES}
    writer_cpu: dict[str, list[float]] = {m: [] for m in MODES}
    received: list[tuple[int, int]] = []
    with tempfile.TemporaryDirectory() as runs_dir:
        for k in range(args.rounds):
            order = MODES[k % 3:] + MODES[:k % 3]  # each mode goes first, second and third in turn
            for mode in order:
                r = one_run(mode, args.factor, args.sim_s, runs_dir)
                costs[mode].extend(r["costs"])
                writer_cpu[mode].append(r["writer_cpu_s"])
                if "messages" in r:
                    received.append((r["messages"], r["bytes"]))
    print(f"tick-loop cost per tick, patrol paced at {args.factor:g}x real time, {args.rounds} rounds of "
          f"{args.sim_s:g} s simulated per mode:")
    trimmed = {m: trimmed_mean(costs[m]) for m in MODES}
    for m in MODES:
        print(f"   {m + ':':17s} {trimmed[m] * 1e6:7.1f} us (mean without the slowest 1%; median "
              f"{statistics.median(costs[m]) * 1e6:.1f} us; {len(costs[m])} ticks); writer process "
              f"{statistics.median(writer_cpu[m]) * 1e6:.0f} us CPU per tick on another core")
    client_vs_none = trimmed["live, 1 client"] / trimmed["live, no client"] - 1
    print(f"   one connected client adds {100 * client_vs_none:+.1f}% to the live server alone  [goal: at most +5%]")
    print(f"   the live server alone adds {100 * (trimmed['live, no client'] / trimmed['recorded'] - 1):+.1f}% "
          f"to recording; with a client {100 * (trimmed['live, 1 client'] / trimmed['recorded'] - 1):+.1f}%")
    if received:
        ticks = args.sim_s * 20
        m, b = (statistics.median(v) for v in zip(*received))
        print(f"   the client got {m:.0f} messages ({b / 1e6:.1f} MB) per run, {m / ticks:.0f} per tick")
    from figures import Figures  # benchmarks/figures.py: saved for benchmarks/check_docs.py, printed
    figures = Figures("foxglove_live")
    for mode in MODES:
        key = re.sub(r"[^a-z0-9]+", "_", mode.lower()).strip("_")
        figures.put(f"{key}.tick_us", trimmed[mode] * 1e6)
        figures.put(f"{key}.writer_us", statistics.median(writer_cpu[mode]) * 1e6)
    figures.put("client_vs_none_pct", 100 * client_vs_none)
    figures.put("live_vs_recorded_pct", 100 * (trimmed["live, no client"] / trimmed["recorded"] - 1))
    if received:  # a client that got nothing measured nothing: the figure says so
        figures.put("client_messages_per_run", statistics.median(m for m, _ in received))
    figures.save()


if __name__ == "__main__":
    main()
