"""The studio's worker processes: warm ones ready for each check, killed and replaced when a check must end.

Checking, compiling, drawing and editing a text take CPU and, for a hostile or
huge text, without bound. They run in worker processes
(:mod:`beastbt.studio.worker`), a few kept warm, one job at a time each. A job
ends early in three ways, each with the worker killed (SIGKILL: a process can
be stopped, a thread cannot) and a fresh one started in its place:

* it took more than ``timeout_s`` (``"time"``);
* its client went away (``"gone"``): nobody waits for the answer;
* it ran out of the worker's address space (``"memory"``; the worker ends itself);
* the studio is ending (``"closing"``).

A request that finds no worker free within ``wait_s`` is told the studio is
busy (``"busy"``). Each worker has a thread of the studio's that writes its jobs
and reads its answers, so the event loop never blocks on a pipe; the loop only
waits on futures.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import threading
from concurrent.futures import Future
from pathlib import Path
from typing import Callable, Optional

WORKERS = 2
"""Worker processes kept warm: the page asks for a check, then a map (and a tree), one after the other."""
WORK_TIMEOUT_S = 10.0
"""A check, a tree, a map or an edit that takes longer is ended (s): the page asks 300 ms after the last key."""
WAIT_FOR_WORKER_S = 10.0
"""How long a request waits for a free worker before the studio says it is busy (s)."""
WORKER_MEMORY_BYTES = 1 << 30
"""Each worker's address space (``RLIMIT_AS``, bytes): a text that would take more is too large to check here."""
POLL_S = 0.1
"""How often a waiting request looks whether its client is still there (s)."""
START_FAILURES = 3
"""After this many workers in a row die before they are ready, the studio stops starting more."""


class WorkRefused(Exception):
    """A job that got no answer, and why: ``time``, ``memory``, ``gone``, ``busy``, ``broken`` or ``closing``."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


class _Worker:
    """One worker process and the thread that talks to it (jobs one at a time)."""

    def __init__(self, pool: "WorkPool") -> None:
        self.pool = pool
        self.process: Optional[subprocess.Popen] = None
        self.pid: Optional[int] = None
        self.ready = False
        self._jobs: "list[tuple[str, Future]]" = []
        self._wake = threading.Condition()
        self._killed = False
        self.thread = threading.Thread(target=self._serve, name="beastbt-studio-worker", daemon=True)

    def submit(self, line: str) -> Future:
        """Send one job (a JSON line); the future resolves to the answer (a dict), or None when the worker died."""
        done: Future = Future()
        with self._wake:
            self._jobs.append((line, done))
            self._wake.notify()
        return done

    def kill(self) -> None:
        """End the worker now (SIGKILL); its thread sees the pipe close and ends."""
        with self._wake:
            self._killed = True
            self._wake.notify()
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def _serve(self) -> None:
        pool = self.pool
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")  # threads only cost address space
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "beastbt.studio.worker", str(pool.folder), str(pool.memory_bytes)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=None, env=env, text=True, encoding="utf-8")
        except OSError as exc:
            pool._died(self, f"cannot start a worker: {exc}")
            return
        self.pid = self.process.pid
        if self._killed:  # the pool closed while it started
            self.kill()
        assert self.process.stdin is not None and self.process.stdout is not None
        first = self.process.stdout.readline()
        try:
            self.ready = "ready" in json.loads(first)
        except ValueError:
            self.ready = False
        if not self.ready:
            self._end()
            pool._died(self, "a worker ended before it was ready")
            return
        pool._ready(self)
        while True:
            with self._wake:
                while not self._jobs and not self._killed:
                    self._wake.wait()
                if self._killed and not self._jobs:
                    break
                line, done = self._jobs.pop(0)
            try:
                self.process.stdin.write(line + "\n")
                self.process.stdin.flush()
                answer = self.process.stdout.readline()
                message = json.loads(answer) if answer else None
            except (OSError, ValueError):
                message = None
            done.set_result(message)
            if message is None or "too_large" in message:
                break
        self._end()
        pool._died(self, "")

    def _end(self) -> None:
        assert self.process is not None
        if self.process.poll() is None:
            self.kill()
        try:
            self.process.wait(5.0)
        except subprocess.TimeoutExpired:
            pass
        for stream in (self.process.stdin, self.process.stdout):
            try:
                if stream is not None:
                    stream.close()
            except OSError:
                pass


class WorkPool:
    """The studio's warm worker processes for ``folder`` (see the module docstring)."""

    def __init__(self, folder: Path, size: int = WORKERS, timeout_s: float = WORK_TIMEOUT_S,
                 memory_bytes: int = WORKER_MEMORY_BYTES, wait_s: float = WAIT_FOR_WORKER_S) -> None:
        self.folder = folder
        self.size = size
        self.timeout_s = timeout_s
        self.memory_bytes = memory_bytes
        self.wait_s = wait_s
        self._loop: Optional[asyncio.AbstractEventLoop] = None
        self._idle: Optional[asyncio.Queue] = None
        self._lock = threading.Lock()
        self._workers: set[_Worker] = set()
        self._closed = False
        self._failures = 0
        self.broken: Optional[str] = None
        """Why no worker starts (after :data:`START_FAILURES` in a row), or None."""

    # -- life (the event loop's thread, except close) --------------------------------------------
    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start the workers; they serve once warm (about a second). Call in ``loop``'s thread."""
        self._loop = loop
        self._idle = asyncio.Queue()
        for _ in range(self.size):
            self._spawn()

    def _spawn(self) -> None:
        with self._lock:
            if self._closed or self.broken is not None:
                return
            worker = _Worker(self)
            self._workers.add(worker)
        worker.thread.start()

    def close(self) -> None:
        """Kill every worker now (from any thread); no new one starts."""
        with self._lock:
            self._closed = True
            workers = list(self._workers)
        for worker in workers:
            worker.kill()

    def pids(self) -> list[int]:
        """The process ids of the workers that are warm (ready for jobs, or doing one)."""
        with self._lock:
            return [w.pid for w in self._workers if w.pid is not None and w.ready]

    # -- from the workers' threads -------------------------------------------------------------------
    def _ready(self, worker: _Worker) -> None:
        self._failures = 0
        loop, idle = self._loop, self._idle
        if loop is not None and idle is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(idle.put_nowait, worker)
            except RuntimeError:  # the loop closed meanwhile
                pass

    def _died(self, worker: _Worker, why: str) -> None:
        """A worker ended: start another in its place, unless the studio is closing or workers keep dying."""
        with self._lock:
            self._workers.discard(worker)
            if not worker.ready and not self._closed:
                self._failures += 1
                if self._failures >= START_FAILURES:
                    self.broken = why or "the workers end before they are ready"
        self._spawn()

    # -- jobs -------------------------------------------------------------------------------------
    async def run(self, job: dict, gone: Callable[[], bool] = lambda: False) -> dict:
        """The worker's message for ``job`` (``{answer}``, ``{refused, error}`` or ``{failed}``); raises
        :class:`WorkRefused` when it gets none (too long, out of memory, the client gone, no worker free)."""
        assert self._loop is not None and self._idle is not None
        worker = await self._free_worker(gone)
        line = json.dumps(dict(job, cpu_s=2 * self.timeout_s + 5))
        answer = asyncio.wrap_future(worker.submit(line))
        deadline = self._loop.time() + self.timeout_s
        try:
            while True:
                done, _ = await asyncio.wait({answer}, timeout=POLL_S)
                if done:
                    break
                if gone():
                    raise WorkRefused("gone")
                if self._loop.time() >= deadline:
                    raise WorkRefused("time", f"{self.timeout_s:g} s")
        except BaseException:
            worker.kill()  # its thread sees it end and starts another
            raise
        message = answer.result()
        if self._closed:
            raise WorkRefused("closing")
        if message is None:  # it died under the job: a limit of the kernel's (CPU time, memory) or a crash
            raise WorkRefused("memory", "the worker ended")
        if "too_large" in message:
            raise WorkRefused("memory", f"{self.memory_bytes >> 20} MB")
        self._idle.put_nowait(worker)
        return message

    async def _free_worker(self, gone: Callable[[], bool]) -> _Worker:
        assert self._loop is not None and self._idle is not None
        deadline = self._loop.time() + self.wait_s
        while True:
            if self._closed:
                raise WorkRefused("closing")
            if self.broken is not None and self._idle.empty():
                raise WorkRefused("broken", self.broken)
            getter = asyncio.ensure_future(self._idle.get())
            try:
                done, _ = await asyncio.wait({getter}, timeout=POLL_S)
            except BaseException:
                if getter.done() and not getter.cancelled():
                    self._idle.put_nowait(getter.result())  # cancelled just as a worker came: give it back
                getter.cancel()
                raise
            if not done:
                getter.cancel()  # a get not yet resumed leaves its worker in the queue
            else:
                worker = getter.result()
                if worker.process is not None and worker.process.poll() is None:
                    return worker
                continue  # killed while idle (the studio is closing): take the next
            if gone():
                raise WorkRefused("gone")
            if self._loop.time() >= deadline:
                raise WorkRefused("busy", f"no worker free within {self.wait_s:g} s")


__all__ = ["WORK_TIMEOUT_S", "WORKER_MEMORY_BYTES", "WorkPool", "WorkRefused"]
