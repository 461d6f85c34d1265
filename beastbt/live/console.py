"""The operator console of a run (``beastbt run MISSION --console [HOST:]PORT``): wiring it into the run.

One page with what a field operator needs in one place: live video, where
the robot is, what the mission is doing, progress, and a way to take over
(pause, resume, abort, e-stop, a joystick, answers to the mission's
questions). What is where:

* :mod:`beastbt.live.console_state`: the state object and the map's layers (built here, on the tick thread);
* :mod:`beastbt.live.console_control`: the controls, carried out on the tick thread;
* :mod:`beastbt.live.tuning`: live tuning's knobs, set by the ``tune`` control (saving writes the profile's file on
  a thread of its own, never the tick thread's);
* :mod:`beastbt.live.console_process`: the console's own process, with the web server
  (:mod:`beastbt.live.console_server`) and the video encoder (:mod:`beastbt.live.console_video`);
* ``console_page/``: the page, its script and style (shipped in the package, no CDN).

:class:`ConsoleLink` is the run's end of the pipes to that process. The tick
thread writes itself, a few times a second (a state; while someone watches, a
camera frame through shared memory or the viewer camera's pose), to a
non-blocking pipe: what the process has not read yet waits in a buffer, and
while it does, new states are dropped rather than ever making the loop wait.
(A thread of ours that wakes up to send would cost the loop more: measured in
``benchmarks/console.py``.) A reader thread, asleep until the process writes,
takes the controls: the e-stop and its reset are carried out at once (they are
safe from any thread), the others are queued for the tick thread, and every
answer goes back.
"""

from __future__ import annotations

import dataclasses
import errno
import os
import pickle
import select
import struct
import secrets
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any, Optional

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.live.console_control import ConsoleControls, Refused
from beastbt.live.console_state import ConsoleState, state_json, video_caption
from beastbt.live.console_video import VideoConfig
from beastbt.live.endpoint import is_loopback, parse_endpoint

MAP_PERIOD_S = 1.0
"""The map's layers and trail are sent to the console's process this often (wall s)."""
START_TIMEOUT_S = 30.0
"""How long the console's process may take to listen (s): it imports aiohttp and OpenCV."""
PENDING_MAX_BYTES = 1 << 20
"""While this much is still waiting for the console's process, the tick thread sends nothing new (bytes)."""
FRAME_SLOTS = 3
"""Shared-memory buffers camera frames rotate through (the process copies a frame out long before its turn)."""


class ConsoleLink:
    """The run's end of the console's process (see the module docstring)."""

    def __init__(self, run: Any, state: ConsoleState, controls: ConsoleControls, host: str, port: int,
                 video: VideoConfig, token_always: bool = False) -> None:
        self.run = run
        self.state = state
        self.controls = controls
        self.host = host
        self.port = port
        self.require_token = token_always or not is_loopback(host)
        """Every request needs the token: off loopback, or with ``--console-token always`` (a proxy, a tunnel)."""
        self.token = secrets.token_urlsafe(18) if self.require_token else ""
        self.video = video
        self.viewers = 0
        self.url = ""
        self.dropped = 0
        self._write_lock = threading.Lock()
        self._pending = b""
        """Bytes written but not yet taken by the pipe (it is non-blocking)."""
        self._deferred: list[bytes] = []
        """Answers that could not be written at once (another thread was writing): they go with the next write."""
        self._fd = -1
        self._proc: Optional[subprocess.Popen] = None
        self._inbox: Optional[Connection] = None
        self._outbox: Optional[Connection] = None
        self._reader: Optional[threading.Thread] = None
        self._segments: list[Any] = []
        self._slot = 0
        self._last_map_wall = -1e9
        self._sent_map_version = -1
        self._last_video_wall = -1e9
        self._fed_seq = 0
        self._closing = False

    # -- life ------------------------------------------------------------------------
    def start(self) -> None:
        """Start the console's process and wait until it listens; OSError (with errno) when it cannot."""
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        self._proc = subprocess.Popen([sys.executable, "-m", "beastbt.live.console_process", str(to_child_r),
                                       str(from_child_w)], pass_fds=(to_child_r, from_child_w), close_fds=True,
                                      stdin=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self._outbox = Connection(to_child_w, readable=False)
        self._inbox = Connection(from_child_r, writable=False)
        io = self.run.io
        pipeline = io.camera
        text, caption = self._state_fields(self.state.latest().state)  # served from the first request on
        config = {"host": self.host, "port": self.port, "token": self.token or None,
                  "require_token": self.require_token,
                  "video": dataclasses.asdict(self.video), "camera": pipeline is not None,
                  "geometry": pipeline.geometry if pipeline is not None else None,
                  "camera_fps": pipeline.config.fps if pipeline is not None else None,
                  "viewer_camera": io.viewer_camera,
                  "state": text, "caption": caption, "map": self._map()}
        self._outbox.send(("config", config))
        if not self._inbox.poll(START_TIMEOUT_S):
            self._proc.kill()
            raise OSError(errno.ETIMEDOUT, "the console's process did not start")
        answer = self._inbox.recv()
        if answer[0] == "error":
            self._proc.wait(5)
            raise OSError(answer[1], answer[2])
        _, self.port, self.url = answer
        self._fd = to_child_w
        os.set_blocking(self._fd, False)
        self._reader = threading.Thread(target=self._read_loop, name="beastbt-console-read", daemon=True)
        self._reader.start()

    def close(self) -> None:
        """Send the final state, tell the process to end, wait for it (a few seconds at most)."""
        if self._proc is None or self._closing:
            return
        self.controls.close()
        self._last_map_wall = -1e9  # the final state goes with the final map
        self._closing = True
        self.state.publish()
        self._send(("close",), block=True)
        try:
            self._proc.wait(5.0)
        except subprocess.TimeoutExpired:
            self._proc.kill()
        if self._reader is not None:
            self._reader.join(2.0)
        for connection in (self._inbox, self._outbox):
            if connection is not None:
                connection.close()
        for segment in self._segments:
            segment.close()
            segment.unlink()

    # -- the tick thread -------------------------------------------------------------
    def _send(self, message: tuple, block: bool = False, keep: bool = False) -> bool:
        """Write one message to the process; False when it was dropped (the process is behind, or gone).

        The tick thread never blocks: it skips while another thread writes or
        while earlier bytes still wait. ``keep`` (an answer to a control) is
        never dropped: it goes with the next write when it cannot go now.
        ``block`` (the reader thread's answers, the final words) waits until
        the pipe has taken everything.
        """
        if self._fd < 0:
            return False
        payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        framed = struct.pack("!i", len(payload)) + payload  # multiprocessing's framing, for Connection.recv
        if not block and (len(self._pending) > PENDING_MAX_BYTES or not self._write_lock.acquire(blocking=False)):
            if keep:
                self._deferred.append(framed)
            else:
                self.dropped += 1
            return False
        if block:
            self._write_lock.acquire()
        try:
            deferred, self._deferred = self._deferred, []
            data = self._pending + b"".join(deferred) + framed
            data = self._write_some(data)
            while block and data:
                select.select([], [self._fd], [], 1.0)
                data = self._write_some(data)
            self._pending = data
            return True
        except OSError:
            self._fd = -1  # the process has gone: the console is over, the run goes on
            return False
        finally:
            self._write_lock.release()

    def _write_some(self, data: bytes) -> bytes:
        try:
            written = os.write(self._fd, data)
        except BlockingIOError:
            written = 0
        return data[written:]

    def on_publish(self, seq: int, state: dict) -> None:
        """A new state (the tick thread): for the process, with the map now and then, and before a page asks.

        The map goes first when its layers changed (``map_version``), so that
        the page, which fetches the map when it sees a new version, gets the new one.
        """
        block = self._closing  # the final state and map always go
        wall = time.monotonic()
        if wall - self._last_map_wall >= MAP_PERIOD_S or state["map_version"] != self._sent_map_version:
            self._last_map_wall = wall
            self._sent_map_version = state["map_version"]
            self._send(("map", self._map()), block)
        for photo in self.state.photos.untold():  # before the state that lists it; never dropped (keep)
            self._send(photo, block, keep=True)
        self._send(("state", seq, *self._state_fields(state)), block)

    @staticmethod
    def _state_fields(state: dict) -> tuple[str, list[str]]:
        """(the state's JSON text, its video caption): the console's process passes the text on and never parses
        it."""
        return state_json(state), video_caption(state)

    def _map(self) -> dict:
        return {**self.state.layers(), "trail": list(self.state.trail)}

    def feed_video(self, run: Any) -> None:
        """While someone watches (the tick thread): the camera's own JPEG as it came, else the newest camera
        frame's pixels, or on the simulator the viewer camera's pose."""
        wall = time.monotonic()
        if wall - self._last_video_wall < 1.0 / self.video.fps:
            return
        pipeline = run.io.camera
        if pipeline is None:
            return
        if pipeline.config.format == "h264":
            self._feed_h264(pipeline, wall)
            return
        if pipeline.threaded or pipeline.config.format == "mjpeg":
            jpeg = self._read_for_viewer(pipeline)
        else:
            jpeg = None
        latest = pipeline.latest
        if jpeg is not None:
            if jpeg.seq != self._fed_seq:
                self._fed_seq = jpeg.seq
                self._last_video_wall = wall
                detection = latest[1] if latest is not None else None
                self._send(("jpeg", jpeg.seq, time.time(), jpeg.jpeg, detection, pipeline.lookahead_m))
            return
        viewer_renders = run.io.viewer_camera is not None and run.io.sim is not None
        # A camera on only for the recording gives a few frames a second: in the simulator the viewer's own
        # camera renders the full rate instead (on the robot those few frames are all there is).
        if pipeline.enabled and (pipeline.frame_period_s is None or not viewer_renders):
            if latest is None or latest[0].seq == self._fed_seq:
                return
            frame, detection = latest
            self._fed_seq = frame.seq
            self._last_video_wall = wall
            self._send(self._frame_message(frame.image, frame.seq, detection, pipeline.lookahead_m))
        elif viewer_renders:
            t = run.io.sim.truth
            self._last_video_wall = wall
            from beastbt.parts.camera import persons_xy  # the viewer draws the persons where they are now
            self._send(("pose", (t.x, t.y, t.yaw, t.v_mps, t.w_rps, t.pan_rad, t.tilt_rad, persons_xy(run.io.sim))))

    def _feed_h264(self, pipeline: Any, wall: float) -> None:
        """The camera's own H.264: every access unit read since the last call, in order and untouched (a viewer
        decodes each from the one before it). After a pause (nobody fed for a second) the old ones are dropped."""
        from beastbt.devices.h264 import is_keyframe
        if wall - self._last_video_wall > 1.0:
            pipeline.h264_units.clear()
        self._read_for_viewer(pipeline)
        self._last_video_wall = wall
        latest = pipeline.latest
        detection = latest[1] if latest is not None else None
        units = pipeline.h264_units
        while units:
            frame = units.popleft()
            self._send(("h264", frame.seq, time.time(), frame.h264, is_keyframe(frame.h264), detection,
                        pipeline.lookahead_m))

    @staticmethod
    def _read_for_viewer(pipeline: Any) -> Any:
        """The camera read for a viewer: the robot's camera thread reads for the console too while someone watches
        (a camera that gives JPEG or H.264 is then read but not decoded: decoding is for vision, at its own rate);
        a camera nobody else reads is read now, only as often as someone watches. The newest own JPEG frame."""
        if pipeline.threaded:
            if "console" not in pipeline.reasons:
                pipeline.enable("console", pixels=False)
            return pipeline.latest_jpeg
        return pipeline.read_for_viewer()

    def stop_video(self, run: Any) -> None:
        """Nobody watches any more (the tick thread): the robot's camera stops reading for the console."""
        pipeline = run.io.camera
        if pipeline is not None and "console" in pipeline.reasons:
            pipeline.disable("console")

    # -- the sender and the reader ---------------------------------------------------
    def _frame_message(self, image: Any, seq: int, detection: Any, lookahead_m: float) -> tuple:
        """Copy a frame into the next shared-memory slot (the tick thread) and say where it is."""
        import numpy as np
        from multiprocessing import shared_memory
        if not self._segments or self._segments[0].size < image.nbytes:
            for segment in self._segments:
                segment.close()
                segment.unlink()
            self._segments = [shared_memory.SharedMemory(create=True, size=image.nbytes) for _ in range(FRAME_SLOTS)]
        segment = self._segments[self._slot]
        self._slot = (self._slot + 1) % FRAME_SLOTS
        np.ndarray(image.shape, np.uint8, buffer=segment.buf[:image.nbytes])[...] = image
        return ("frame", segment.name, image.shape, seq, time.time(), detection, lookahead_m)

    def _read_loop(self) -> None:
        from beastbt.run.safety import request_estop, reset_estop
        inbox = self._inbox
        assert inbox is not None
        run = self.run
        while True:
            try:
                message = inbox.recv()
            except (EOFError, OSError):
                return
            kind = message[0]
            if kind == "viewers":
                self.viewers = int(message[1])
            elif kind == "control":
                _, request, name, body = message
                if name == "estop":  # at once, from this thread: the latch is safe from any thread
                    first = request_estop(run, "operator console")
                    run.io.wakeup.set()
                    self._reply(request, True, {"estop": True, "newly_latched": first})
                elif name == "estop_reset":
                    if run.status is not None:
                        self._reply(request, False, (409, "the run has ended"))
                    elif not run.mux.estop_latched:
                        self._reply(request, False, (409, "the e-stop is not latched"))
                    else:
                        reset_estop(run, "operator console")
                        self._reply(request, True, {"estop": False})
                elif name == "tune_save":  # the file is written on a thread of its own: the loop never waits for it
                    threading.Thread(target=self._save_tuning, args=(request,), name="beastbt-tuning-save",
                                     daemon=True).start()
                else:
                    future = self.controls.submit(name, body)
                    future.add_done_callback(lambda f, request=request: self._answered(request, f))

    def _save_tuning(self, request: int) -> None:
        """``POST /api/tuning/save``: the changes written into the profile's file (:func:`save_through`)."""
        from beastbt.live.tuning import save_through
        try:
            self._reply(request, True, save_through(self.controls, 2.0))
        except Refused as exc:
            self._reply(request, False, (exc.status, str(exc)))
        except Exception as exc:  # noqa: BLE001 - a timeout, a run that ended: an answer, never a dead thread
            self._reply(request, False, (503, f"could not save the tuning: {type(exc).__name__} {exc}".strip()))

    def _answered(self, request: int, future: Any) -> None:
        # Called where the control was carried out: the tick thread, which must not block on the pipe.
        error = future.exception()
        if error is None:
            self._reply(request, True, future.result(), block=False)
        elif isinstance(error, Refused):
            self._reply(request, False, (error.status, str(error)), block=False)
        else:
            self._reply(request, False, (400, str(error)), block=False)

    def _reply(self, request: int, ok: bool, payload: Any, block: bool = True) -> None:
        self._send(("result", request, ok, payload), block=block, keep=True)


def console_codec(prepared: Any) -> str:
    """The console's video codec from the profile (``camera.console_codec``: auto, jpeg, h264); ``h264`` on a
    machine without the hardware H.264 encoder is an error at that key (auto would give JPEG here)."""
    pipeline = prepared.run.io.camera
    codec = pipeline.config.console_codec if pipeline is not None else "auto"
    if codec != "h264" or pipeline.config.format == "h264":  # a camera's own H.264 needs no encoder here
        return codec
    from beastbt.devices.h264 import resolve_codec
    try:
        resolve_codec(codec)
    except ValueError as exc:
        raise InvalidInput([prepared.profile.doc.problem(
            ("camera", "console_codec"), f"camera.console_codec: {exc}",
            "use auto (the hardware encoder where there is one, JPEG elsewhere) or jpeg")]) from None
    return codec


def install_console(prepared: Any) -> ConsoleLink:
    """Start the console for ``prepared``'s run: its process, its tick hook and reactor; print its address."""
    spec = prepared.options.console
    try:
        host, port = spec if isinstance(spec, tuple) else parse_endpoint(spec, "--console")
    except ValueError as exc:
        raise InvalidInput([Problem("--console", Position(), str(exc), "e.g. --console 8080 or --console 0.0.0.0:8080")]) from None
    run = prepared.run
    wall = time.monotonic  # the console paces itself for people, in wall time; the run's clock is untouched
    state = ConsoleState(run, prepared.world, wall)
    controls = ConsoleControls(run, wall)
    link = ConsoleLink(run, state, controls, host, port, VideoConfig(codec=console_codec(prepared)),
                       token_always=getattr(prepared.options, "console_token", "auto") == "always")
    state.on_publish = link.on_publish
    try:
        link.start()
    except OSError as exc:
        hint = (f"this computer has no address {host}: use 127.0.0.1 (this computer only), 0.0.0.0 (every "
                f"network) or one of its own addresses" if exc.errno == errno.EADDRNOTAVAIL
                else "pick another port, or 0 for any free one")
        raise InvalidInput([Problem("--console", Position(), f"cannot listen on {host}:{port}: {exc.strerror or exc}",
                                    hint)]) from None
    pending, apply_pending, feed = controls.pending, controls.apply_pending, link.feed_video
    camera = run.io.camera

    def console_tick(run: Any, now_s: float) -> None:
        # One hook, each part with its cheap test first: most ticks have nothing queued and nobody
        # watching the video, and the console must cost the loop next to nothing (benchmarks/console.py).
        if controls.stick_held or not pending.empty():
            apply_pending(now_s)
        state(run, now_s)
        if link.viewers > 0:
            feed(run)
        elif camera is not None and "console" in camera.reasons:
            link.stop_video(run)

    run.hooks.insert(0, console_tick)  # before the tree: a pause or an answer counts in the tick that follows it
    run.reactors.append(controls)
    prepared.closers.append(link.close)
    run.ctx.services.plugins["console"] = link
    print(f"operator console: {link.url}", flush=True)
    run.events.add("console", f"operator console on {link.url.split('?')[0]}")
    return link


__all__ = ["install_console", "ConsoleLink"]
