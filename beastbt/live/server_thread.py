"""An asyncio event loop on a daemon thread of its own, for the web servers that live beside a run or a command.

The console and the studio each serve from such a thread: the loop binds the
server first and a failure to bind (a port in use, an address that is not
this machine's) is raised in the caller of :func:`start_loop_thread`, so a
command can say it before anything runs.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any, Awaitable, Callable, Optional


def start_loop_thread(bind: Callable[[], Awaitable[Any]], name: str,
                      after: Optional[Callable[[], Awaitable[Any]]] = None,
                      timeout_s: float = 10.0) -> tuple[threading.Thread, asyncio.AbstractEventLoop]:
    """Start a daemon thread named ``name`` running a new event loop: ``bind()`` first, then the loop until it is
    stopped (``loop.call_soon_threadsafe(loop.stop)``), then ``after()`` if given. Waits up to ``timeout_s`` (s)
    for the bind; re-raises what the bind raised. Returns (thread, loop)."""
    ready = threading.Event()
    failure: list[BaseException] = []
    loop = asyncio.new_event_loop()

    def serve() -> None:
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(bind())
        except BaseException as exc:  # noqa: BLE001 - handed to the caller below
            failure.append(exc)
            ready.set()
            loop.close()
            return
        ready.set()
        loop.run_forever()
        if after is not None:
            loop.run_until_complete(after())
        loop.close()

    thread = threading.Thread(target=serve, name=name, daemon=True)
    thread.start()
    ready.wait(timeout_s)
    if failure:
        raise failure[0]
    return thread, loop
