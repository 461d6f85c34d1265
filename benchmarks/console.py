"""What the operator console costs, and what its viewers get. Not a test: prints figures.

**Anchor**: the same run without the console (``beastbt run`` through the same ``prepare`` and ``execute`` as
the command line, in this process). Every rep runs the anchor and each subject one after the other, in this
process, so that a busy machine slows them alike; figures are medians over ``--reps`` (>= 5) with the spread
(min..max) beside them.

1. **CPU at real time, one viewer** (the issue's figure; goal: <= 5 % of a core on the robot's camera path,
   <= 10 % on the simulated camera). The patrol at ``--speed realtime`` for ``--seconds`` (it does not use the
   camera itself), with a viewer process that follows ``WS /api/ws`` and ``WS /api/video`` as the page does
   (offering permessage-deflate, as every browser does: a server that took it for the video would deflate
   every frame):

   * anchor: no console;
   * ``sim camera``: ``robots/sim.yaml``, whose simulated camera gives pixels: the console's own process
     renders the view and JPEG-encodes it;
   * ``fake MJPEG``: the same profile with ``camera.format: mjpeg``: the simulator's fake USB camera renders
     and encodes each frame (what a camera's hardware does for free), and its JPEG goes to the viewer
     untouched: the robot's camera path;
   * ``fake H.264`` (when PyAV's wheel has a software H.264 encoder): ``camera.format: h264``, the simulator's
     fake camera encodes each frame to H.264 (what a Pi camera's hardware encoder does for free) and the viewer,
     saying it plays H.264 as the page does, gets its access units untouched.

   Printed: the console process's own CPU (from /proc, from the start of the run to its end, % of one core;
   its start-up, before the run, apart in CPU seconds);
   this process's extra CPU over the anchor (the loop's feed, the pipe; for the fake MJPEG camera also its
   rendering and encoding, shown apart as ``camera``); and the sum, the whole cost of watching.
2. **Tick wall time at full speed**: the long patrol at ``--speed max``, anchor against console + one viewer
   (the simulated camera), wall time per tick and the loop thread's own CPU per tick, as ratios per rep.
3. **API latency**: ``GET /api/state`` polled back to back by the viewer during the full-speed runs with the
   console (a client that heavy costs the loop more than a viewer does): p50 and p99 per rep. Goal p99 < 20 ms.
4. **Video at the browser** (``--browser``): the line mission and the patrol at ``--speed realtime`` with the
   page open in headless Chromium (Debian's), read from the page (``window.beastbtVideoStats``): frames a
   second, Mbit/s per viewer, the frame's age when drawn; a stalled second viewer is connected meanwhile.

Run: python benchmarks/console.py [--reps 5] [--seconds 10] [--passes 10] [--browser]
"""

from __future__ import annotations

import argparse
import contextlib
import io
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
from typing import Any, Callable, Optional

from figures import Figures  # benchmarks/figures.py, beside this script

REPO = Path(__file__).resolve().parent.parent
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")

VIEWER = textwrap.dedent('''
    import asyncio, json, struct, sys, time
    import aiohttp
    base = sys.argv[1]
    async def main():
        lat, states, vbytes, frames, passed = [], 0, 0, 0, 0
        async with aiohttp.ClientSession() as s:
            async def follow_state():
                nonlocal states
                try:
                    async with s.ws_connect(base + "/api/ws", compress=15) as ws:
                        async for m in ws:
                            states += 1
                except Exception:
                    pass
            async def follow_video():
                nonlocal vbytes, frames, passed
                try:
                    async with s.ws_connect(base + "/api/video", max_msg_size=0, compress=15) as ws:
                        if "h264" in sys.argv[2:]:  # as the page does where it can play H.264
                            await ws.send_str(json.dumps({"accept": ["h264", "jpeg"]}))
                        async for m in ws:
                            vbytes += len(m.data); frames += 1
                            q = struct.unpack_from("<H", m.data, 12)[0]
                            passed += q == 0 or q >= 0xFF00  # the camera's own JPEG, or an H.264 unit
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
            poll_too = "poll" in sys.argv[2:]
            tasks = [asyncio.ensure_future(c()) for c in (follow_state, follow_video) + ((poll,) if poll_too else ())]
            await tasks[0]
            for t in tasks[1:]:
                t.cancel()
        print(json.dumps({"latencies": lat, "states": states, "video_bytes": vbytes, "frames": frames,
                          "passed_through": passed}))
    asyncio.run(main())
''')


def proc_cpu_s(pid: int) -> float:
    """CPU seconds (user + system) a process has used so far, from /proc."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


def long_patrol(folder: Path, passes: int) -> Path:
    """The patrol, ``passes`` times over, in an open world (no walls for its drift to meet over a long run)."""
    text = (REPO / "missions" / "patrol.yaml").read_text(encoding="utf-8")
    text = "\n".join(line for line in text.splitlines() if not line.startswith("world:")) + "\n"
    text = text.replace("times: 3", f"times: {passes}")
    path = folder / "long_patrol.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def mjpeg_profile(folder: Path, fmt: str = "mjpeg") -> Path:
    """robots/sim.yaml with ``camera.format: FMT``: the simulator's fake camera that gives its own JPEG (mjpeg) or
    its own H.264 (h264, encoded by PyAV's software encoder, standing for a Pi camera's hardware encoder)."""
    text = (REPO / "robots" / "sim.yaml").read_text(encoding="utf-8")
    assert "  device: sim\n" in text
    path = folder / f"sim_{fmt}.yaml"
    path.write_text(text.replace("  device: sim\n", f"  device: sim\n  format: {fmt}\n"), encoding="utf-8")
    return path


def run_once(mission: Path, console: bool, speed: str = "max", max_time_s: Optional[float] = None,
             profile: Optional[Path] = None, poll: bool = False, h264: bool = False) -> dict:
    """One run in this process, with a viewer process when ``console``; CPU of this process, of its loop thread
    and of the console's process over ``execute``."""
    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    opts = RunOptions(record=False, console=("127.0.0.1", 0) if console else None, speed=speed,
                      max_time_s=max_time_s, **({"robot": str(profile), "simulate": True} if profile else {}))
    with contextlib.redirect_stdout(io.StringIO()):
        prepared = prepare(str(mission), opts)
    viewer = None
    out: dict[str, Any] = {}
    if console:
        link = prepared.run.ctx.services.plugins["console"]
        viewer = subprocess.Popen([sys.executable, "-c", VIEWER, link.url.rstrip("/")] + (["poll"] if poll else [])
                                  + (["h264"] if h264 else []),
                                  stdout=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 20
        while link.viewers < 1 and time.monotonic() < deadline:  # the viewer is watching before the start
            time.sleep(0.02)
        pid = link._proc.pid  # noqa: SLF001 - the benchmark reads the console process's CPU from /proc
        console_cpu0 = proc_cpu_s(pid)
        out["console_startup_cpu_s"] = console_cpu0  # its imports and start, before the run
        def sample() -> None:  # the first closer: before the console's process is told to end
            out["console_cpu_s"] = proc_cpu_s(pid) - console_cpu0
        prepared.closers.insert(0, sample)
    cpu0, thread0, wall0 = time.process_time(), time.thread_time(), time.perf_counter()
    summary = execute(prepared, out=io.StringIO())
    out.update(summary=summary, cpu_s=time.process_time() - cpu0, loop_cpu_s=time.thread_time() - thread0,
               wall_s=time.perf_counter() - wall0)
    camera = prepared.run.io.camera
    out["camera_frames"] = (getattr(camera, "jpeg_frames", 0), camera.frames) if camera is not None else (0, 0)
    if viewer is not None:
        stdout, _ = viewer.communicate(timeout=120)
        out["viewer"] = json.loads(stdout or "{}")
    return out


FIGURES = Figures("console")
"""The figures this run prints, saved at its end for benchmarks/check_docs.py (benchmarks/figures.py)."""


def spread(values: list[float], fmt: str = "{:.1f}") -> str:
    """Median with the spread: ``median (min..max)``."""
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))}..{fmt.format(max(values))})"


def percent(values: list[float]) -> str:
    """Fractions of a core as a median % with the spread."""
    return spread([v * 100 for v in values], "{:.1f}") + " %"


def realtime_cpu(reps: int, seconds: float, mjpeg: bool = True) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        mission = long_patrol(folder, 10)
        subjects: list[tuple[str, Optional[Path]]] = [("sim camera", None)]
        if mjpeg:
            subjects.append(("fake MJPEG", mjpeg_profile(folder)))
            from beastbt.devices.h264 import software_encoder
            if software_encoder() is not None:  # a PyAV wheel with an H.264 encoder: the fake H.264 camera
                subjects.append(("fake H.264", mjpeg_profile(folder, "h264")))
        anchor: list[float] = []
        rows: dict[str, dict[str, list[float]]] = {name: {"console": [], "run": [], "total": [], "fps": [],
                                                          "mbps": [], "passed": [], "startup": []}
                                                    for name, _ in subjects}
        for _ in range(reps):
            base = run_once(mission, False, "realtime", seconds)
            anchor.append(base["cpu_s"] / base["wall_s"])
            for name, profile in subjects:
                r = run_once(mission, True, "realtime", seconds, profile, h264=name == "fake H.264")
                row, wall = rows[name], r["wall_s"]
                row["console"].append(r["console_cpu_s"] / wall)
                row["startup"].append(r["console_startup_cpu_s"])
                row["run"].append(r["cpu_s"] / wall - anchor[-1])
                row["total"].append(row["console"][-1] + row["run"][-1])
                v = r.get("viewer", {})
                row["fps"].append(v.get("frames", 0) / wall)
                row["mbps"].append(v.get("video_bytes", 0) * 8 / wall / 1e6)
                row["passed"].append(v.get("passed_through", 0) / max(1, v.get("frames", 0)))
        print(f"1. CPU at real time, the patrol for {seconds:g} s, one viewer ({reps} reps, median (min..max)):")
        print(f"   anchor (no console): the run's process {percent(anchor)} of a core")
        for name, _ in subjects:
            row = rows[name]
            print(f"   {name:10s}: console process {percent(row['console'])}, the run's process +{percent(row['run'])}"
                  f" over the anchor, together {percent(row['total'])}")
            print(f"   {'':10s}  viewer got {spread(row['fps'])} fps, {spread(row['mbps'], '{:.2f}')} Mbit/s, "
                  f"{statistics.median(row['passed']) * 100:.0f} % of frames the camera's own (JPEG or H.264) untouched; "
                  f"the console process's start-up {spread(row['startup'], '{:.2f}')} s of CPU (not in the shares)")
        FIGURES.spread("anchor_pct", anchor, 100)
        for name, _ in subjects:
            key = name.replace(" ", "_").replace(".", "").lower()
            for part, scale in (("console", 100), ("run", 100), ("total", 100), ("fps", 1), ("mbps", 1),
                                ("startup", 1)):
                FIGURES.spread(f"{key}.{part}{'_pct' if scale == 100 else ''}", rows[name][part], scale)
        print("   goals: console process <= 5 % (fake MJPEG, the robot's camera path), <= 10 % (sim camera); the fake "
              "MJPEG camera's rendering and encoding stand for the camera's hardware and are in 'the run's process'")


def tick_cost(reps: int, passes: int) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        mission = long_patrol(Path(tmp), passes)
        wall_ratio, cpu_ratio, base_us, with_us, p50, p99, p99_all = [], [], [], [], [], [], []
        ticks = 0
        for _ in range(reps):
            base = run_once(mission, False)
            sub = run_once(mission, True)
            ticks = base["summary"]["ticks"]
            b, s = base["wall_s"] / ticks * 1e6, sub["wall_s"] / sub["summary"]["ticks"] * 1e6
            base_us.append(b)
            with_us.append(s)
            wall_ratio.append(s / b)
            cpu_ratio.append((sub["loop_cpu_s"] / sub["summary"]["ticks"]) / (base["loop_cpu_s"] / ticks))
            lat = sorted(run_once(mission, True, poll=True).get("viewer", {}).get("latencies", []))
            if lat:
                p50.append(lat[len(lat) // 2] * 1000)
                p99.append(lat[min(len(lat) - 1, int(0.99 * len(lat)))] * 1000)
                p99_all += lat
        print(f"2. per tick at full speed, the patrol x{passes} ({ticks} ticks; {reps} reps, median (min..max)):")
        print(f"   anchor (no console) {spread(base_us)} us; console + one viewer {spread(with_us)} us")
        print(f"   wall time per tick: ratio {spread(wall_ratio, '{:.3f}')} (the console's process and the viewer "
              f"share the machine's cores with the loop)")
        print(f"   the loop thread's own CPU per tick: ratio {spread(cpu_ratio, '{:.3f}')}")
        FIGURES.spread("tick.anchor_us", base_us)
        FIGURES.spread("tick.console_us", with_us)
        FIGURES.spread("tick.wall_ratio", wall_ratio)
        FIGURES.spread("tick.loop_cpu_ratio", cpu_ratio)
        FIGURES.spread("api.p50_ms", p50)
        FIGURES.spread("api.p99_ms", p99)
        if p99:
            print(f"3. GET /api/state polled back to back during full-speed runs: p50 {spread(p50, '{:.2f}')} ms, "
                  f"p99 {spread(p99, '{:.2f}')} ms per rep (goal p99 < 20 ms)")


def video_at_browser(seconds: float, mission: str) -> None:
    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("4. video: skipped (pip install playwright)")
        return
    if not Path(chromium).exists():
        print("4. video: skipped (no Chromium; apt-get install chromium)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "beastbt", "run", str(REPO / "missions" / mission),
               "--speed", "realtime", "--no-record", "--max-time", f"{seconds + 15:g} s", "--console", "127.0.0.1:0",
               "--summary", str(Path(tmp) / "s.json")]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, cwd=tmp)
        assert proc.stdout is not None
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
        print(f"4. video at the browser, {mission}, canvas {last['w']}x{last['h']}, {span:.1f} s, "
              f"a stalled viewer too:")
        print(f"   {fps:.1f} fps, {mbps:.2f} Mbit/s per viewer (goal <= 5)")
        print(f"   frame age capture->canvas: p50 {ages[len(ages) // 2]:.0f} ms  p95 {ages[int(len(ages) * 0.95)]:.0f} ms  "
              f"max {ages[-1]:.0f} ms")
        print(f"   mission time after {span:.1f} s of watching: {state['time_s']:.1f} s (realtime: it kept pace)")
        key = f"browser.{Path(mission).stem}"
        FIGURES.put(f"{key}.fps", fps)
        FIGURES.put(f"{key}.mbps", mbps)
        FIGURES.put(f"{key}.age_p95_ms", ages[int(len(ages) * 0.95)])


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--reps", type=int, default=5, help="reps of anchor and subjects, interleaved (>= 5)")
    ap.add_argument("--seconds", type=float, default=10.0, help="length of each real-time run (simulated s)")
    ap.add_argument("--passes", type=int, default=10, help="patrol passes per full-speed run")
    ap.add_argument("--browser", action="store_true", help="also watch in headless Chromium (part 4)")
    ap.add_argument("--video-seconds", type=float, default=10.0)
    ap.add_argument("--only", choices=("cpu", "tick", "browser"), default=None,
                    help="run one part only (browser: part 4 alone)")
    ap.add_argument("--no-mjpeg", action="store_true", help="leave out the fake MJPEG camera (a tree without it)")
    args = ap.parse_args()
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    parts: list[Callable[[], None]] = []
    if args.only in (None, "cpu"):
        parts.append(lambda: realtime_cpu(args.reps, args.seconds, not args.no_mjpeg))
    if args.only in (None, "tick"):
        parts.append(lambda: tick_cost(args.reps, args.passes))
    for part in parts:
        part()
    if args.browser or args.only == "browser":
        # The line mission's camera runs at its own 15 fps (the frames the detector sees); the patrol does not use
        # the camera, so the console's process renders the simulated view itself, at the camera's rate.
        for mission in ("line_to_intersection.yaml", "patrol.yaml"):
            video_at_browser(args.video_seconds, mission)
    FIGURES.save()  # benchmarks/results/console.json, quoted by docs/console.md and docs/performance.md


if __name__ == "__main__":
    main()
