"""The operator console's own process: the web server and the video encoder, away from the tick loop.

A run with ``--console`` starts this process (``python -m beastbt.live.console_process
READ_FD WRITE_FD``) and talks to it over two pipes with pickled messages
(:class:`multiprocessing.connection.Connection`). Python runs one thread at
a time per process: served from the run's own process, a busy page would
take the interpreter from the loop (and a loop at full speed would starve the
page). Here the server, the JPEG encoder and the simulated viewer camera
have an interpreter and a core of their own, as the recording's writer does.

From the run (``inbox``):

* ``("config", dict)`` first: where to listen, the token, the video settings,
  the camera's geometry and, on the simulator, how to build a viewer camera;
* ``("state", seq, json_text, caption)`` a few times a second (the state as the page gets it, and the video
  caption's lines), ``("map", layers)`` now and then;
* ``("jpeg", seq, captured_s, jpeg_bytes, detection, lookahead_m)``: a camera's own JPEG, sent on untouched;
  ``("h264", seq, captured_s, access_unit, keyframe, detection, lookahead_m)``: a camera's own H.264, likewise;
  ``("frame", shm_name, shape, seq, captured_s, detection, lookahead_m)``: a
  camera frame (pixels) in shared memory; ``("pose", truth)``: where the simulated
  viewer camera is now; ``("result", request_id, ok, payload)``: a control's outcome;
  ``("photo", file_name, name, time_s, path)``: a photo the run saved, served as ``/api/photos/<file_name>``;
* ``("close",)``: send the final state to every viewer and end.

To the run (``outbox``): ``("ready", port, url)`` or ``("error", errno, text)``
once; ``("control", request_id, name, body)`` for each control;
``("viewers", count)`` when the number of video viewers changes.

When the run's process dies, its end of the pipe closes and this process ends too.
"""

from __future__ import annotations

import itertools
import sys
import threading
import time
from concurrent.futures import Future
from multiprocessing.connection import Connection
from typing import Any, Optional

import numpy as np

from beastbt.live.console_control import Refused
from beastbt.live.console_server import ConsoleServer
from beastbt.live.console_video import ConsoleVideo, VideoConfig


class RemoteState:
    """The run's last state and map as they came over the pipe (the server's ``state`` and ``map_source``).

    The state comes as JSON text, made by the run, with the video caption worked out of it: this process
    passes the text on to every page as it came and never parses it."""

    def __init__(self, seq: int = 0, text: str = "{}", caption: Optional[list[str]] = None) -> None:
        self._latest: tuple[int, str, list[str]] = (seq, text, caption or [])
        self.layers: dict = {}

    def put(self, seq: int, text: str, caption: list[str]) -> None:
        """A new state from the run: its number, its JSON text, its video caption."""
        self._latest = (seq, text, caption)  # one tuple, replaced whole: readers on other threads see old or new

    def latest_json(self) -> tuple[int, str]:
        """The last state: (its number, its JSON text)."""
        seq, text, _ = self._latest
        return seq, text

    def caption(self) -> list[str]:
        """The video caption of the last state."""
        return self._latest[2]

    def map(self) -> dict:
        """The map's layers and trail, as last sent."""
        return self.layers


class RemoteControls:
    """Controls sent to the run; each answer comes back as a ``result`` message and resolves its Future."""

    def __init__(self, outbox: Connection, lock: threading.Lock) -> None:
        self.outbox = outbox
        self.lock = lock
        self.pending: dict[int, Future] = {}
        self.ids = itertools.count(1)
        self.closed = False

    def submit(self, name: str, body: dict) -> Future:
        """Send a control to the run; the Future gets the result or raises :class:`Refused`."""
        future: Future = Future()
        if self.closed:
            future.set_exception(Refused(409, "the run has ended"))
            return future
        request = next(self.ids)
        self.pending[request] = future
        try:
            with self.lock:
                self.outbox.send(("control", request, name, body))
        except (OSError, ValueError):
            self.pending.pop(request, None)
            future.set_exception(Refused(409, "the run has ended"))
        return future

    def resolve(self, request: int, ok: bool, payload: Any) -> None:
        """The run's answer to a control."""
        future = self.pending.pop(request, None)
        if future is None or future.done():
            return
        if ok:
            future.set_result(payload)
        else:
            future.set_exception(Refused(int(payload[0]), str(payload[1])))

    def close(self) -> None:
        """The run has ended: every control still waiting is refused."""
        self.closed = True
        for future in list(self.pending.values()):
            if not future.done():
                future.set_exception(Refused(409, "the run has ended"))
        self.pending.clear()


def _viewer_camera(spec: Optional[dict]) -> Optional[Any]:
    """The simulator's viewer camera (same floor, mounting and effects, a noise generator of its own), or None."""
    if not spec:
        return None
    from beastbt.parts.camera import PLAIN_FLOOR, build_floor
    from beastbt.sim.camera_emulator import SimCamera
    from beastbt.sim.cpu_account import SIM_CPU
    SIM_CPU.open_from_environment()  # rendering the viewer's picture is the simulator's work (benchmarks)
    floor = build_floor(spec["floor"] if spec["floor"] is not None else PLAIN_FLOOR, spec["floor_seed"])
    return SimCamera(floor, spec["geometry"], np.random.default_rng(spec["floor_seed"] + 1), spec["effects"],
                     spec.get("scenery"), markers=spec.get("markers") or ())


def serve(inbox: Connection, outbox: Connection) -> int:
    """Run the console until the run says close or goes away; 0, or 1 when it could not listen."""
    kind, config = inbox.recv()
    assert kind == "config"
    lock = threading.Lock()
    state = RemoteState(0, config["state"], config["caption"])
    state.layers = config["map"]
    controls = RemoteControls(outbox, lock)
    video = ConsoleVideo(VideoConfig(**config["video"]), time.monotonic, time.time, state.caption)
    server = ConsoleServer(state, controls, video, state.map, config["host"], config["port"], config["token"],
                           require_token=config.get("require_token"))
    # Told at each change of the number of video viewers (on the server's thread): the run renders or reads the
    # camera for the console only while someone watches. Set before the server listens, and said only once the run
    # has the "ready" (its first answer); the count at that moment follows it under the same lock, so a page that
    # connects at once is never lost (a later "viewers 0" once overwrote its "1" and the run sent no video).
    announced = [False]

    def tell_viewers(_count: int) -> None:
        with lock:
            if announced[0]:
                outbox.send(("viewers", server.video.viewers))

    server.on_viewers = tell_viewers
    try:
        server.start()
    except OSError as exc:
        with lock:
            outbox.send(("error", exc.errno, exc.strerror or str(exc)))
        return 1
    with lock:
        outbox.send(("ready", server.port, server.url))
        announced[0] = True
        outbox.send(("viewers", server.video.viewers))
    video.start()
    camera_spec = config.get("viewer_camera")
    geometry = config.get("geometry")
    if not config.get("camera"):
        blank = np.full((360, 640, 3), 40, np.uint8)  # no camera: the overlay alone, on grey
        video.pull = lambda: blank
        video.pull_fps = 2.0  # nothing moves in it but the caption
    elif config.get("camera_fps"):
        video.pull_fps = float(config["camera_fps"])  # the viewer camera renders no faster than the camera
    pose: list = [None]
    camera_holder: list = []

    def render() -> np.ndarray:
        if not camera_holder:  # built when first watched: its floor and ground textures are the simulator's work
            from beastbt.sim.cpu_account import CAMERA, SIM_CPU
            camera_holder.append(SIM_CPU.call(CAMERA, _viewer_camera, camera_spec))
        t = pose[0]
        return camera_holder[0].render(*t)

    try:
        while True:
            try:
                msg = inbox.recv()
            except (EOFError, OSError):
                break
            kind = msg[0]
            if kind == "state":
                state.put(msg[1], msg[2], msg[3])
            elif kind == "map":
                state.layers = msg[1]
            elif kind == "photo":
                server.photos.add(msg[1], msg[2], msg[3], msg[4])
            elif kind == "result":
                controls.resolve(msg[1], msg[2], msg[3])
            elif kind == "pose":
                pose[0] = msg[1]
                if camera_spec and video.pull is None:
                    video.pull = render
            elif kind == "jpeg":
                _, seq, captured, jpeg, detection, lookahead = msg
                video.pull = None
                video.pass_jpeg(jpeg, detection, geometry, lookahead, captured)
            elif kind == "h264":  # a camera's own H.264 access unit: every one, in order, to the H.264 viewers
                _, seq, captured, unit, key, detection, lookahead = msg
                video.pull = None
                video.pass_h264(unit, key, detection, geometry, lookahead, captured, seq)
            elif kind == "frame":
                _, shm_name, shape, seq, captured, detection, lookahead = msg
                image = _read_frame(shm_name, shape)
                if image is not None:
                    video.pull = None
                    video.raw.put((image, detection, geometry, lookahead, captured))
            elif kind == "close":
                break
    finally:
        server.on_viewers = None
        controls.close()
        server.close()
        video.close()
    return 0


_SEGMENTS: dict[str, Any] = {}


def _read_frame(name: str, shape: tuple) -> Optional[np.ndarray]:
    """A copy of the frame the run left in shared memory ``name`` (None when it is gone)."""
    from multiprocessing import shared_memory
    segment = _SEGMENTS.get(name)
    if segment is None:
        try:
            segment = _SEGMENTS[name] = shared_memory.SharedMemory(name=name)
        except FileNotFoundError:
            return None
        try:  # the run made it and will remove it: this process must not (Python < 3.13 tracks what it opens)
            from multiprocessing import resource_tracker
            resource_tracker.unregister(segment._name, "shared_memory")  # noqa: SLF001
        except Exception:  # noqa: BLE001
            pass
    size = int(np.prod(shape))
    return np.ndarray(shape, np.uint8, buffer=segment.buf[:size]).copy()


def main(argv: list[str]) -> int:
    """``python -m beastbt.live.console_process READ_FD WRITE_FD``."""
    import cv2
    # The viewer camera's rendering and the JPEG encoder run on their own thread: OpenCV's worker pool would
    # spin between frames for nothing (see beastbt.parts.camera.OPENCV_THREADS).
    cv2.setNumThreads(1)
    inbox = Connection(int(argv[0]), writable=False)
    outbox = Connection(int(argv[1]), readable=False)
    try:
        return serve(inbox, outbox)
    finally:
        for segment in _SEGMENTS.values():
            segment.close()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
