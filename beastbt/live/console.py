"""The operator console of a run (``beastbt run MISSION --console [HOST:]PORT``): wiring it into the run.

One page with what a field operator needs in one place: live video, where
the robot is, what the mission is doing, progress, and a way to take over
(pause, resume, abort, e-stop, a joystick, answers to the mission's
questions). What is where:

* :mod:`beastbt.live.console_state`: the state object and the map's layers;
* :mod:`beastbt.live.console_control`: the controls, carried out on the tick thread;
* :mod:`beastbt.live.console_video`: the video, held to a bit budget per viewer;
* :mod:`beastbt.live.console_server`: the aiohttp server and the HTTP/WebSocket contract;
* ``console_page/``: the page, its script and style (shipped in the package, no CDN).
"""

from __future__ import annotations

import time
from typing import Any

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.live.console_control import ConsoleControls
from beastbt.live.console_server import ConsoleServer
from beastbt.live.console_state import ConsoleState
from beastbt.live.console_video import ConsoleVideo, VideoConfig
from beastbt.live.endpoint import parse_endpoint


YIELD_EVERY_S = 0.01
"""A simulation at full speed naps 0.2 ms this often (wall s), so that the console answers within milliseconds."""


def install_console(prepared: Any) -> ConsoleServer:
    """Start the console for ``prepared``'s run: its hooks, reactor and closer; print its address."""
    spec = prepared.options.console
    try:
        host, port = spec if isinstance(spec, tuple) else parse_endpoint(spec, "--console")
    except ValueError as exc:
        raise InvalidInput([Problem("--console", Position(), str(exc), "e.g. --console 8080 or --console 0.0.0.0:8080")]) from None
    run = prepared.run
    wall = time.monotonic  # the console paces itself for people, in wall time; the run's clock is untouched
    state = ConsoleState(run, prepared.world, wall)
    controls = ConsoleControls(run, wall)
    video = ConsoleVideo(VideoConfig(), wall, time.time, lambda: _caption(state))
    server = ConsoleServer(state, controls, video, run, prepared.world, host, port)
    try:
        server.start()
    except OSError as exc:
        import errno
        hint = (f"this computer has no address {host}: use 127.0.0.1 (this computer only), 0.0.0.0 (every "
                f"network) or one of its own addresses" if exc.errno == errno.EADDRNOTAVAIL
                else "pick another port, or 0 for any free one")
        raise InvalidInput([Problem("--console", Position(), f"cannot listen on {host}:{port}: {exc.strerror or exc}",
                                    hint)]) from None
    video.start()
    pending, apply_pending, feed = controls.pending, controls.apply_pending, video.feed

    def console_tick(run: Any, now_s: float) -> None:
        # One hook for the three, each with its cheap test first: most ticks have nothing queued and
        # nobody new to show, and the console must cost the loop next to nothing (benchmarks/console.py).
        if controls.stick_held or not pending.empty():
            apply_pending(now_s)
        state(run, now_s)
        if video.viewers > 0:
            feed(run, now_s)

    run.hooks.insert(0, console_tick)  # before the tree: a pause or an answer counts in the tick that follows it
    run.reactors.append(controls)
    run.yield_every_s = YIELD_EVERY_S

    def close() -> None:
        controls.close()
        state.publish()  # the final state, for the viewers' last message
        server.close()
        video.close()

    prepared.closers.append(close)
    run.ctx.services.plugins["console"] = server
    print(f"operator console: {server.url}", flush=True)
    run.events.add("console", f"operator console on {server.url.split('?')[0]}")
    return server


def _caption(state: ConsoleState) -> list[str]:
    s = state.latest().state
    return [f"{s['mission']}  {s['status']}  t {s['time_s']:.1f} s", f"step: {s['step']}"]


__all__ = ["install_console"]
