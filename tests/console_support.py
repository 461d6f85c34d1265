"""Helpers for the operator console's tests: a real ``beastbt run --console`` in a subprocess, and its API."""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any, Callable, Optional

CHROMIUM = next((p for p in (os.environ.get("BEASTBT_CHROMIUM"), shutil.which("chromium"), "/usr/bin/chromium",
                             shutil.which("chromium-browser")) if p and Path(p).exists()), None)
"""Debian's Chromium (``.ci/run`` installs it); the browser tests skip without it."""
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage"]
"""Flags for Chromium on a machine with no network beyond loopback (no background lookups)."""


WAIT = "mission: console_wait\nsteps:\n  - wait: 60 s\n"
"""A robot that stands for a minute: for driving it by hand and for the controls."""
SHORT = "mission: console_short\nsteps:\n  - drive: {distance: 0.3 m}\n  - wait: 1 s\n"
"""A run of a few seconds that succeeds."""
ASK = """mission: console_ask
steps:
  - ask: {id: door, question: "Is the door open?"}
    then:
      - drive: {distance: 0.4 m}
    else:
      - say: "staying"
"""
"""A question with no timeout: the run waits for the operator."""


class ConsoleRun:
    """``beastbt run MISSION --console HOST:0`` in a subprocess; ``url`` is the printed address (with any token)."""

    def __init__(self, mission: Path, *extra: str, host: str = "127.0.0.1", cwd: Optional[Path] = None) -> None:
        cmd = [sys.executable, "-m", "beastbt", "run", str(mission), "--console", f"{host}:0", *extra]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     cwd=str(cwd) if cwd else None, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.lines: list[str] = []
        deadline = time.monotonic() + 60
        self.url = ""
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError(f"beastbt ended before serving the console: {self.proc.stderr.read()}")
            self.lines.append(line)
            m = re.search(r"operator console: (\S+)", line)
            if m:
                self.url = m.group(1)
                break
        if not self.url:
            raise RuntimeError("no console address was printed")
        self.base = re.sub(r"/(\?.*)?$", "", self.url)
        self.port = int(self.base.rsplit(":", 1)[1])
        self.token = self.url.split("token=", 1)[1] if "token=" in self.url else None

    def api(self, path: str, body: Any = None, token: bool = True, host: Optional[str] = None) -> tuple[int, Any]:
        """(HTTP status, JSON) of a GET (no body) or POST (body) to the console."""
        base = self.base if host is None else f"http://{host}:{self.port}"
        url = base + path
        if token and self.token:
            url += ("&" if "?" in url else "?") + "token=" + self.token
        data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
        req = urllib.request.Request(url, data=data, method="GET" if body is None else "POST",
                                     headers={"Content-Type": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=10) as r:
                return r.status, json.loads(r.read() or b"null")
        except urllib.error.HTTPError as e:
            raw = e.read()
            try:
                return e.code, json.loads(raw)
            except ValueError:
                return e.code, raw.decode(errors="replace")

    def state(self) -> dict:
        """``GET /api/state``."""
        status, body = self.api("/api/state")
        assert status == 200, body
        return body

    def wait_state(self, predicate, timeout_s: float = 30.0) -> dict:
        """Poll the state until ``predicate(state)``; the last state (AssertionError on timeout)."""
        deadline = time.monotonic() + timeout_s
        state = self.state()
        while not predicate(state):
            if time.monotonic() > deadline:
                raise AssertionError(f"state never matched; last: {({k: v for k, v in state.items() if k != 'tree'})}")
            time.sleep(0.1)
            state = self.state()
        return state

    def finish(self, timeout_s: float = 60.0) -> tuple[int, str, str]:
        """Wait for the run to end: (exit code, stdout, stderr)."""
        out, err = self.proc.communicate(timeout=timeout_s)
        return self.proc.returncode, "".join(self.lines) + out, err

    def kill(self) -> None:
        """End the run if it is still going (SIGTERM: it stops the robot and writes its summary)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.communicate(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def wait_for_page(page: Any, expression: str, timeout_s: float = 20.0) -> Any:
    """Poll a JavaScript expression on a page until it is truthy; return its value (raises after ``timeout_s``).

    Playwright's ``wait_for_function`` compiles its predicate with ``new Function``, which the console's
    Content-Security-Policy forbids (no 'unsafe-eval'); ``evaluate`` goes through the DevTools protocol instead.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        value = page.evaluate(expression)
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"still false after {timeout_s} s: {expression}")
        page.wait_for_timeout(100)


STILL_M = 0.005
"""How far a stopped robot's reported pose may still move (m): the odometry reads 0.000 m/s (rounded) while the
last fraction of a millimetre of the ramp-down lands, which the pose, rounded to the millimetre, can show."""


def moved_m(a: dict, b: dict) -> float:
    """How far apart two poses of the console's state are, in x plus y (m)."""
    return abs(a["x"] - b["x"]) + abs(a["y"] - b["y"])


def run_with_console(folder: Path, profile: Path, mission: str, speed: str, watch: bool,
                     accept: Optional[list[str]] = None, max_time_s: float = 120.0,
                     until: Optional[Callable[[list], bool]] = None) -> tuple[Any, list]:
    """Run ``mission`` on the simulator with ``profile`` and the console; with ``watch``, a viewer follows
    /api/video from before the start to the end (the video messages it got), first saying the codecs it
    ``accept``s when given (``{"accept": [...]}``, as the page does). With ``until``, the viewer ends the run
    (``POST /api/abort``) as soon as ``until(messages)`` holds: a long mission then lasts as long as a loaded
    machine needs to deliver what the test counts, not a fixed wall-clock time."""
    import aiohttp

    from beastbt.assembly import prepare
    from beastbt.run.session import RunOptions, execute
    (folder / "m.yaml").write_text(mission, encoding="utf-8")
    opts = RunOptions(robot=str(profile), simulate=True, record=False, speed=speed, console=("127.0.0.1", 0),
                      max_time_s=max_time_s)
    with contextlib.redirect_stdout(io.StringIO()):
        prepared = prepare(str(folder / "m.yaml"), opts)
    link = prepared.run.ctx.services.plugins["console"]
    messages: list = []
    aborted: list = []
    done = threading.Event()

    async def follow() -> None:
        async with aiohttp.ClientSession() as session:
            seen.append("connecting")
            async with session.ws_connect(link.url.rstrip("/") + "/api/video", max_msg_size=0) as ws:
                seen.append("connected")
                if accept is not None:
                    await ws.send_str(json.dumps({"accept": accept}))
                while not done.is_set():
                    try:
                        msg = await ws.receive(timeout=0.2)
                    except asyncio.TimeoutError:
                        continue
                    if msg.type != aiohttp.WSMsgType.BINARY:
                        seen.append(f"the socket ended: {msg.type.name} {str(msg.data)[:200]}")
                        break
                    messages.append(msg.data)
                    if until is not None and not aborted and until(messages):
                        aborted.append(True)
                        async with session.post(link.url.rstrip("/") + "/api/abort", json={}) as answer:
                            assert answer.status == 200, await answer.text()

    failed: list[BaseException] = []
    seen: list[str] = []

    def watch_video() -> None:
        try:
            asyncio.run(follow())
        except BaseException as exc:  # noqa: BLE001 - said by the test's thread, not lost in this one
            failed.append(exc)

    viewer = threading.Thread(target=watch_video)
    if watch:
        viewer.start()
        deadline = time.monotonic() + 30
        while link.viewers < 1 and not failed and time.monotonic() < deadline:  # watching before the start
            time.sleep(0.02)
        if link.viewers < 1:
            import sys
            import traceback
            stack = "".join(traceback.format_stack(sys._current_frames()[viewer.ident])) if viewer.is_alive() else ""
            process = link._proc.poll() if link._proc is not None else "none"
            alive = viewer.is_alive()  # before the end below closes its socket
            done.set()
            prepared.abandon()
            raise AssertionError((f"the viewer never watched /api/video: {failed[0]!r}" if failed else
                                  "the console counted no viewer of /api/video within 30 s") +
                                 f"; the viewer: {seen}, alive {alive}; the console's process: "
                                 f"{process}; {link.url}\n{stack}")
    execute(prepared, out=io.StringIO())
    done.set()
    if watch:
        viewer.join(10)
        assert not failed, f"the viewer of /api/video failed: {failed[0]!r}"
    return prepared, messages


def capture_reads(monkeypatch: Any, cls: type, method: str) -> list[bytes]:
    """Patch ``cls.method`` (a camera's ``read_jpeg``/``read_h264``) to note every frame it hands over; the list."""
    made: list[bytes] = []
    real = getattr(cls, method)

    def noted(self: Any) -> tuple[bool, Any]:
        ok, data = real(self)
        if ok:
            made.append(data)
        return ok, data

    monkeypatch.setattr(cls, method, noted)
    return made
