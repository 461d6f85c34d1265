"""What the operator console costs, and what its viewers get. Not a test: prints figures.

1. **Per-tick cost** at full speed: the same long patrol on the simulator,
   ``beastbt run --speed max`` without the console (the baseline, measured in
   this run) and with ``--console`` and one viewer (a client process that
   follows ``WS /api/ws`` and ``WS /api/video`` as the page does). Wall seconds
   per tick from each run's summary; runs alternate, the median of each is
   compared, as wall time and as the loop thread's own CPU time (what the
   console adds to the loop itself; its server and encoder are a process of
   their own, on the other core). The runs are made in this process, through the same
   ``prepare`` and ``execute`` as the command line. Goal (issue 13): <= 5 %
   more per tick.
2. **API latency** while the mission runs at full speed, in runs of their
   own: the viewer also polls ``GET /api/state`` back to back (a client that
   heavy costs the loop more than a viewer does). Goal: p99 < 20 ms.
3. **Video at the browser**: the line mission and the patrol at ``--speed realtime`` with the
   page open in headless Chromium (Debian's), read from the page itself
   (``window.beastbtVideoStats``): frames a second, Mbit/s per viewer and the
   frame's age when drawn (capture to canvas). Goal: <= 5 Mbit/s at 1280x720,
   about 25 fps. A second viewer that reads nothing (a stalled link) is
   connected at the same time, to show that it slows neither the mission nor
   the first viewer.

Run: python benchmarks/console.py [--repeats 3] [--passes 30] [--video-seconds 12]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

VIEWER = textwrap.dedent('''
    import asyncio, json, struct, sys, time
    import aiohttp
    base = sys.argv[1]
    async def main():
        lat, states, vbytes, frames = [], 0, 0, 0
        async with aiohttp.ClientSession() as s:
            async def follow_state():
                nonlocal states
                try:
                    async with s.ws_connect(base + "/api/ws") as ws:
                        async for m in ws:
                            states += 1
                except Exception:
                    pass
            async def follow_video():
                nonlocal vbytes, frames
                try:
                    async with s.ws_connect(base + "/api/video", max_msg_size=0) as ws:
                        async for m in ws:
                            vbytes += len(m.data); frames += 1
                except Exception:
                    pass
            async def poll():
                while True:
                    t = time.perf_counter()
                    try:
                        async with s.get(base + "/api/state") as r:
                            await r.read()
                    except Exception:
                        return
                    lat.append(time.perf_counter() - t)
            poll_too = len(sys.argv) > 2 and sys.argv[2] == "poll"
            tasks = [asyncio.ensure_future(c()) for c in (follow_state, follow_video) + ((poll,) if poll_too else ())]
            await tasks[0]
            for t in tasks[1:]:
                t.cancel()
        print(json.dumps({"latencies": lat, "states": states, "video_bytes": vbytes, "frames": frames}))
    asyncio.run(main())
''')


def long_patrol(folder: Path, passes: int) -> Path:
    """The patrol, ``passes`` times over, in an open world (no walls for its drift to meet over a long run)."""
    text = (REPO / "missions" / "patrol.yaml").read_text(encoding="utf-8")
    text = "\n".join(line for line in text.splitlines() if not line.startswith("world:")) + "\n"
    text = text.replace("times: 3", f"times: {passes}")
    path = folder / "long_patrol.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def run_once(mission: Path, folder: Path, console: bool, poll: bool = False) -> dict:
    """One run in this process (so that the loop thread's CPU can be read), with a viewer process if ``console``."""
    import contextlib
    import io
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    opts = RunOptions(record=False, console=("127.0.0.1", 0) if console else None)
    with contextlib.redirect_stdout(io.StringIO()):
        prepared = prepare(str(mission), opts)
    viewer = None
    if console:
        server = prepared.run.ctx.services.plugins["console"]
        viewer = subprocess.Popen([sys.executable, "-c", VIEWER, server.url.rstrip("/")] + (["poll"] if poll else []),
                                  stdout=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 20
        while server.viewers < 1 and time.monotonic() < deadline:  # the viewer is watching before the start
            time.sleep(0.02)
    cpu0, wall0 = time.thread_time(), time.perf_counter()
    summary = execute(prepared, out=io.StringIO())
    cpu, wall = time.thread_time() - cpu0, time.perf_counter() - wall0
    out = {"summary": summary, "loop_cpu_s": cpu, "wall_s": wall}
    if viewer is not None:
        stdout, _ = viewer.communicate(timeout=120)
        out["viewer"] = json.loads(stdout or "{}")
    return out


def per_tick_us(result: dict, key: str = "wall_s") -> float:
    return result[key] / max(1, result["summary"]["ticks"]) * 1e6


def tick_cost(repeats: int, passes: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        mission = long_patrol(folder, passes)
        base, with_console, latencies, states, video = [], [], [], [], []
        base_cpu, console_cpu = [], []
        for _ in range(repeats):
            r = run_once(mission, folder, False)
            base.append(per_tick_us(r))
            base_cpu.append(per_tick_us(r, "loop_cpu_s"))
            r = run_once(mission, folder, True)
            with_console.append(per_tick_us(r))
            console_cpu.append(per_tick_us(r, "loop_cpu_s"))
            v = r.get("viewer", {})
            states.append(v.get("states", 0) / max(1e-9, r["wall_s"]))
            video.append(v.get("frames", 0))
        for _ in range(repeats):  # a client polling the API back to back: its latency, not part of the cost above
            latencies += run_once(mission, folder, True, poll=True).get("viewer", {}).get("latencies", [])
        b, c = statistics.median(base), statistics.median(with_console)
        ticks = run_once(mission, folder, False)["summary"]["ticks"]
        print(f"1. per tick at full speed ({ticks} ticks, {repeats} runs each, median):")
        print(f"   without console {b:7.1f} us   runs: {', '.join(f'{x:.1f}' for x in base)}")
        print(f"   console+viewer  {c:7.1f} us   runs: {', '.join(f'{x:.1f}' for x in with_console)}")
        print(f"   ratio {c / b:.3f}  (wall time per tick: the console's process and the viewer share the cores)")
        bc, cc = statistics.median(base_cpu), statistics.median(console_cpu)
        print(f"   the loop thread's own CPU per tick: without {bc:.1f} us, with console+viewer {cc:.1f} us, "
              f"ratio {cc / bc:.3f}  (goal <= 1.05)")
        print(f"   the viewer got {statistics.median(states):.1f} states/s and {statistics.median(video):.0f} video frames")
        if latencies:
            lat = sorted(latencies)
            p = lambda q: lat[min(len(lat) - 1, int(q * len(lat)))] * 1000  # noqa: E731
            print(f"2. GET /api/state during the runs ({len(lat)} requests): p50 {p(0.5):.2f} ms  p99 {p(0.99):.2f} ms  "
                  f"max {lat[-1] * 1000:.2f} ms  (goal p99 < 20 ms)")


def video_at_browser(seconds: float, mission: str) -> None:
    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("3. video: skipped (pip install playwright)")
        return
    if not Path(chromium).exists():
        print("3. video: skipped (no Chromium; apt-get install chromium)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "beastbt", "run", str(REPO / "missions" / mission),
               "--speed", "realtime", "--no-record", "--max-time", f"{seconds + 15:g} s", "--console", "127.0.0.1:0",
               "--summary", str(Path(tmp) / "s.json")]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, cwd=tmp)
        url = ""
        while not url:
            line = proc.stdout.readline()
            m = re.search(r"operator console: (\S+)", line)
            url = m.group(1) if m else ""
            if not line:
                raise RuntimeError("no console address")
        import socket
        stalled = socket.create_connection(("127.0.0.1", int(url.split(":")[2].split("/")[0])))
        stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        stalled.sendall(b"GET /api/video HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                        b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=["--no-sandbox", "--disable-gpu",
                                         "--disable-background-networking", "--disable-component-update"])
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url)
            deadline = time.monotonic() + 30  # polled: the console's CSP forbids wait_for_function's eval
            while not page.evaluate("window.beastbtVideoStats && window.beastbtVideoStats.frames > 5"):
                assert time.monotonic() < deadline, "no video in the page after 30 s"
                page.wait_for_timeout(100)
            t0 = time.monotonic()
            first = page.evaluate("({f: window.beastbtVideoStats.frames, b: window.beastbtVideoStats.bytes})")
            page.wait_for_timeout(seconds * 1000)
            last = page.evaluate("({f: window.beastbtVideoStats.frames, b: window.beastbtVideoStats.bytes, "
                                 "ages: window.beastbtVideoStats.ages.slice(-200), "
                                 "w: document.getElementById('video').width, h: document.getElementById('video').height})")
            span = time.monotonic() - t0
            state = json.loads(__import__("urllib.request").request.urlopen(url.split("?")[0] + "api/state").read())
            browser.close()
        stalled.close()
        proc.terminate()
        proc.communicate(timeout=60)
        fps = (last["f"] - first["f"]) / span
        mbps = (last["b"] - first["b"]) * 8 / span / 1e6
        ages = sorted(last["ages"])
        print(f"3. video at the browser, {mission}, {last['w']}x{last['h']}, {span:.1f} s, a stalled viewer too:")
        print(f"   {fps:.1f} fps, {mbps:.2f} Mbit/s per viewer (goal <= 5 at about 25 fps)")
        print(f"   frame age capture->canvas: p50 {ages[len(ages) // 2]:.0f} ms  p95 {ages[int(len(ages) * 0.95)]:.0f} ms  "
              f"max {ages[-1]:.0f} ms")
        print(f"   mission time after {span:.1f} s of watching: {state['time_s']:.1f} s (realtime: it kept pace)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--passes", type=int, default=30, help="patrol passes per run (longer runs, steadier figures)")
    ap.add_argument("--video-seconds", type=float, default=12.0)
    args = ap.parse_args()
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    tick_cost(args.repeats, args.passes)
    # The line mission's camera runs at its own 15 fps (the frames the detector sees); the patrol does not use
    # the camera, so the video renders the simulated view itself at the video's 25 fps.
    for mission in ("line_to_intersection.yaml", "patrol.yaml"):
        video_at_browser(args.video_seconds, mission)


if __name__ == "__main__":
    main()
