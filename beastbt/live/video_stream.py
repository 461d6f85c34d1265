"""Live video for the operator: the camera as MJPEG over HTTP, with the mission's current step.

``beastbt run MISSION --stream [HOST:]PORT`` starts a :class:`VideoStreamServer`
(stdlib :class:`http.server.ThreadingHTTPServer`, bound to 127.0.0.1 unless a
host is given) for the length of the run:

* ``/stream.mjpg``: ``multipart/x-mixed-replace`` JPEG frames (what browsers,
  VLC and ``ffplay`` show as live video); each part carries ``X-Frame-Seq``.
* ``/snapshot.jpg``: the newest frame as one JPEG.
* ``/status.json``: mission, current step, status, time, pose, line.
* ``/``: a minimal page that shows the stream and polls the status.

How frames flow, so that nobody waits for anybody: the tick loop hands each
new camera frame to :meth:`VideoStreamServer.publish`, which only stores a
reference in a latest-frame slot and notifies (no copy, no encoding). One
encoder thread takes the newest frame at most ``fps`` times a second (only
while someone watches), scales it to the stream size, draws the overlay (the
detected line and the current step) and JPEG-encodes it once into a second
latest-frame slot. Every client's handler thread sends the newest JPEG, then
waits for a newer one: a slow client skips frames (it always gets the newest
when it is ready again; its kernel send buffer is kept to a few frames,
``send_buffer_bytes``, so that the newest is not queued behind old ones), and
a client that takes nothing for ``client_timeout_s`` is dropped. The server is closed at the end of the run
(``Prepared.closers``): the encoder stops and every client connection is shut.

Options (``RunOptions`` / the command line): ``stream`` (``--stream``),
``stream_size`` (``--stream-size 640x480``), ``stream_quality``
(``--stream-quality 80``), ``stream_fps`` (``--stream-fps 25``),
``stream_no_overlay`` (``--stream-no-overlay``). In the simulator the camera
is switched on for the stream; run with ``--speed realtime`` to watch. A camera
that gives its own JPEG (``camera.format``) is streamed as it came, with
``--stream-no-overlay`` at the camera's size: nothing is encoded then.
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import TYPE_CHECKING, Any, Callable, Optional
from urllib.parse import urlsplit

import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.live.endpoint import (SECURITY_HEADERS, host_allowed, host_on_network, is_loopback, parse_endpoint,
                                   parse_size, same_origin)
from beastbt.core.config import dataclass_from_dict

if TYPE_CHECKING:  # OpenCV comes with these: imported where a frame is drawn or encoded, not by the console's
    # process, which passes a camera's own JPEG on without either
    from beastbt.vision.camera_model import CameraGeometry
    from beastbt.vision.line_detector import LineDetection

BOUNDARY = "beastbtframe"
"""The multipart boundary of /stream.mjpg."""

NO_CAMERA_PERIOD_S = 1.0
"""Without a camera, a blank captioned frame is streamed this often (clock seconds)."""


@dataclass
@schema_defaults("parts/video_stream.schema.json")
class StreamConfig:
    """The live video server (``beastbt run --stream ...``)."""

    # Address to listen on. 127.0.0.1 (default) is this machine only; 0.0.0.0 every interface.
    host: str
    # TCP port; 0 picks a free one (see VideoStreamServer.port).
    port: int
    # Size of the streamed frames, pixels; 0 x 0 streams the camera's own size.
    width_px: int
    height_px: int
    # JPEG quality, 1-100 (OpenCV's IMWRITE_JPEG_QUALITY). 80 is sharp; 50 halves the bytes.
    jpeg_quality: int
    # Most frames encoded per second (wall clock); newer camera frames in between are skipped.
    fps: float
    # Draw the detected line, junctions and the current step on the frames.
    overlay: bool
    # A client that accepts no data for this long is disconnected, seconds.
    client_timeout_s: float
    # Kernel send buffer per viewer, bytes (a few frames). Small keeps a slow viewer on the newest
    # frame instead of seconds-old ones queued in the OS; too small limits throughput on links with
    # long round trips (rate <= buffer / round trip). 0 leaves the OS's autotuning (up to megabytes).
    send_buffer_bytes: int

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise ValueError(f"stream.port must be 0..65535, got {self.port}")
        if (self.width_px == 0) != (self.height_px == 0) or not (
                self.width_px == 0 or (16 <= self.width_px <= 7680 and 16 <= self.height_px <= 4320)):
            raise ValueError(f"stream size must be 0x0 (the camera's) or 16x16..7680x4320 pixels, got "
                             f"{self.width_px}x{self.height_px}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"stream JPEG quality must be 1..100, got {self.jpeg_quality}")
        if not 0.1 <= self.fps <= 120.0:
            raise ValueError(f"stream fps must be in [0.1, 120], got {self.fps}")
        if not self.client_timeout_s > 0:
            raise ValueError(f"stream client_timeout_s must be > 0 s, got {self.client_timeout_s}")
        if self.send_buffer_bytes < 0:
            raise ValueError(f"stream send_buffer_bytes must be >= 0, got {self.send_buffer_bytes}")

    @classmethod
    def from_dict(cls, d: Any) -> "StreamConfig":
        """Build from a mapping of the fields above; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "stream")


def compose_frame(image: np.ndarray, size: tuple[int, int], caption: Optional[list[str]],
                  detection: Optional[LineDetection], geometry: Optional[CameraGeometry],
                  lookahead_m: float) -> np.ndarray:
    """A camera frame scaled to ``size`` (width, height px) with the overlay: the detected line (when the camera
    has a detector) and the ``caption`` lines; no overlay when ``caption`` is None. ``image`` is not modified."""
    import cv2

    from beastbt.vision.overlay import describe, draw_caption, draw_detection
    h, w = image.shape[:2]
    if size != (w, h):
        out = cv2.resize(image, size, interpolation=cv2.INTER_AREA if size[0] < w else cv2.INTER_LINEAR)
    else:
        out = image.copy() if caption is not None else image
    if caption is not None:
        lines = list(caption)
        if geometry is not None:
            draw_detection(out, detection, geometry, lookahead_m)
            lines.append(describe(detection))
        draw_caption(out, lines)
    return out


def encode_jpeg(image: np.ndarray, quality: int) -> bytes:
    """``image`` as JPEG at ``quality`` (1-100)."""
    import cv2
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("cv2.imencode failed")
    return buf.tobytes()


class LatestSlot:
    """The newest item and its sequence number, with a condition to wait for a newer one (thread-safe)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self.seq = 0
        self.item: Any = None
        self.closed = False

    def put(self, item: Any) -> int:
        """Replace the item (never blocks on readers); return its sequence number."""
        with self._cond:
            self.seq += 1
            self.item = item
            self._cond.notify_all()
            return self.seq

    def get(self) -> tuple[int, Any]:
        """The newest (seq, item) now (seq 0: nothing yet)."""
        with self._cond:
            return self.seq, self.item

    def wait_newer(self, seq: int, timeout_s: float) -> Optional[tuple[int, Any]]:
        """Wait up to ``timeout_s`` for an item newer than ``seq``: (seq, item), or None (timeout or closed)."""
        with self._cond:
            if self.seq <= seq and not self.closed and timeout_s > 0:
                self._cond.wait_for(lambda: self.seq > seq or self.closed, timeout_s)
            if self.closed or self.seq <= seq:
                return None
            return self.seq, self.item

    def close(self) -> None:
        """Wake every waiter for good."""
        with self._cond:
            self.closed = True
            self._cond.notify_all()


@dataclass
class ClientStats:
    """One /stream.mjpg viewer: where from, frames handed to it (the last may be on its way), frames it skipped while busy."""

    address: str
    frames: int = 0
    skipped: int = 0
    bytes: int = 0
    connection: Any = None


@dataclass(frozen=True)
class _Raw:
    image: np.ndarray
    stamp_s: float
    detection: Optional[LineDetection]
    geometry: Optional[CameraGeometry]
    lookahead_m: float
    jpeg: Optional[bytes] = None


class VideoStreamServer:
    """The MJPEG server of one run (see the module docstring). ``wall`` is the wall clock for the frame rate (s)."""

    def __init__(self, config: Optional[StreamConfig] = None, wall: Callable[[], float] = time.monotonic) -> None:
        self.config = config or StreamConfig()
        self.wall = wall
        self.raw = LatestSlot()
        """The newest camera frame handed over by the tick loop."""
        self.jpeg = LatestSlot()
        """The newest encoded frame: ``(bytes, raw seq)``."""
        self._status: dict = {}
        self._status_lock = threading.Lock()
        self._clients: list[ClientStats] = []
        self._clients_lock = threading.Lock()
        self._wake = threading.Event()
        self._closing = threading.Event()
        self.frames_published = 0
        self.frames_encoded = 0
        self.encode_s = 0.0
        """Wall seconds spent scaling, drawing and encoding."""
        self.clients_served = 0
        self._httpd: Optional[ThreadingHTTPServer] = None
        self._threads: list[threading.Thread] = []

    # -- life ------------------------------------------------------------------------
    def start(self) -> "VideoStreamServer":
        """Bind, then serve and encode in daemon threads; raises OSError when the port is taken."""
        stream = self

        class Server(ThreadingHTTPServer):
            daemon_threads = True
            allow_reuse_address = True

        class Handler(_Handler):
            server_stream = stream

        self._httpd = Server((self.config.host, self.config.port), Handler)
        serve = threading.Thread(target=self._httpd.serve_forever, kwargs={"poll_interval": 0.2},
                                 name="beastbt-stream-http", daemon=True)
        encode = threading.Thread(target=self._encode_loop, name="beastbt-stream-encoder", daemon=True)
        self._threads = [serve, encode]
        serve.start()
        encode.start()
        return self

    @property
    def port(self) -> int:
        """The port actually bound (useful with port 0)."""
        return self._httpd.server_address[1] if self._httpd is not None else self.config.port

    @property
    def url(self) -> str:
        """``http://host:port/`` of the page."""
        host = self.config.host if self.config.host not in ("0.0.0.0", "") else socket.gethostname()
        return f"http://{host}:{self.port}/"

    def close(self) -> None:
        """Stop serving: the encoder ends, waiting handlers wake, every client connection is shut."""
        if self._closing.is_set():
            return
        self._closing.set()
        self._wake.set()
        self.raw.close()
        self.jpeg.close()
        with self._clients_lock:
            clients = list(self._clients)
        for c in clients:  # unblocks a handler stuck sending to a slow client
            try:
                c.connection.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        if self._httpd is not None:
            self._httpd.shutdown()
            self._httpd.server_close()
        for t in self._threads:
            t.join(2.0)

    # -- the tick loop's side (never blocks) ----------------------------------------------------
    def publish(self, image: np.ndarray, stamp_s: float = 0.0, detection: Optional[LineDetection] = None,
                geometry: Optional[CameraGeometry] = None, lookahead_m: float = 0.25,
                jpeg: Optional[bytes] = None) -> None:
        """Offer a new camera frame (BGR uint8; not copied: do not modify it afterwards); ``jpeg``: the camera's
        own JPEG of it, streamed as it is when there is no overlay to draw and no size to change."""
        self.raw.put(_Raw(image, stamp_s, detection, geometry, lookahead_m, jpeg))
        self.frames_published += 1
        self._wake.set()

    def set_status(self, status: dict) -> None:
        """The run's state for /status.json and the caption (a small dict, replaced whole)."""
        with self._status_lock:
            self._status = status

    def status(self) -> dict:
        """The last status with the server's own counters."""
        with self._status_lock:
            out = dict(self._status)
        out["stream"] = {"frames_published": self.frames_published, "frames_encoded": self.frames_encoded,
                         "clients": self.client_count}
        return out

    @property
    def client_count(self) -> int:
        """Viewers of /stream.mjpg connected now."""
        with self._clients_lock:
            return len(self._clients)

    def clients(self) -> list[ClientStats]:
        """The viewers connected now."""
        with self._clients_lock:
            return list(self._clients)

    def wait_encoded(self, raw_seq: int, timeout_s: float) -> bool:
        """Wait until the newest JPEG comes from raw frame ``raw_seq`` or a later one (True), or ``timeout_s`` (False)."""
        deadline = self.wall() + timeout_s
        seq, item = self.jpeg.get()
        while item is None or item[1] < raw_seq:
            left = deadline - self.wall()
            if left <= 0:
                return False
            got = self.jpeg.wait_newer(seq, left)
            if got is None:
                return False
            seq, item = got
        return True

    # -- encoding (its own thread) -------------------------------------------------------------
    def _encode_loop(self) -> None:
        period = 1.0 / self.config.fps
        next_s = self.wall()
        done = 0
        while not self._closing.is_set():
            got = self.raw.wait_newer(done, 0.5)
            if got is None:
                continue
            if self.client_count == 0:
                # Nobody watches: encode nothing, wait for a viewer (or a newer frame).
                self._wake.clear()
                if self.client_count == 0:
                    self._wake.wait(0.2)
                continue
            delay = next_s - self.wall()
            if delay > 0:
                self._closing.wait(delay)
                got = self.raw.get()  # whatever is newest after the wait
            seq, raw = got
            now = self.wall()
            next_s = max(next_s + period, now - 0.5 * period)  # keep the rate; no burst after a stall
            try:
                data = self.encode(raw)
            except Exception as exc:  # a bad frame must not end the stream
                print(f"beastbt stream: could not encode a frame: {exc!r}", file=sys.stderr)
                done = seq
                continue
            self.encode_s += self.wall() - now
            self.frames_encoded += 1
            self.jpeg.put((data, seq))
            done = seq

    def encode(self, raw: _Raw) -> bytes:
        """Scale, draw the overlay and JPEG-encode one frame (the encoder thread; /snapshot.jpg)."""
        cfg = self.config
        h, w = raw.image.shape[:2]
        if raw.jpeg is not None and not cfg.overlay and (cfg.width_px == 0 or (cfg.width_px, cfg.height_px) == (w, h)):
            return raw.jpeg  # the camera's own JPEG: nothing to draw, nothing to scale, so nothing to encode
        caption = None
        if cfg.overlay:
            st = self.status()
            caption = [f"{st.get('mission', '')}  {st.get('status', '')}  t {st.get('time_s', 0.0):.1f} s",
                       f"step: {st.get('step', '-')}"]
        out = compose_frame(raw.image, (cfg.width_px, cfg.height_px) if cfg.width_px else (w, h), caption,
                            raw.detection, raw.geometry, raw.lookahead_m)
        return encode_jpeg(out, cfg.jpeg_quality)

    # -- the handlers' side ----------------------------------------------------------------------
    def _add_client(self, c: ClientStats) -> None:
        with self._clients_lock:
            self._clients.append(c)
            self.clients_served += 1
        self._wake.set()

    def _remove_client(self, c: ClientStats) -> None:
        with self._clients_lock:
            if c in self._clients:
                self._clients.remove(c)

    def newest_jpeg(self) -> Optional[bytes]:
        """The newest encoded frame, or one encoded now from the newest camera frame; None before any frame."""
        _, item = self.jpeg.get()
        seq_raw, raw = self.raw.get()
        if item is not None and item[1] >= seq_raw:
            return item[0]
        if raw is None:
            return None
        return self.encode(raw)


PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>beastbt live</title>
<style>body{background:#1e1e1e;color:#ddd;font-family:sans-serif;margin:1em}
img{max-width:100%;border:1px solid #444}pre{font-size:1.1em}</style></head>
<body><h2 id="title">beastbt</h2>
<img src="/stream.mjpg" alt="live camera">
<pre id="status">waiting for the robot...</pre>
<script>
async function poll() {
  try {
    const s = await (await fetch('/status.json', {cache: 'no-store'})).json();
    document.getElementById('title').textContent = (s.mission || 'beastbt') + ': ' + (s.status || 'running');
    document.getElementById('status').textContent =
      'step:  ' + (s.step || '-') + '\\ntime:  ' + (s.time_s || 0).toFixed(1) + ' s\\n' +
      'pose:  ' + (s.pose || '-') + '\\n' + (s.line || '');
  } catch (e) {}
  setTimeout(poll, 500);
}
poll();
</script></body></html>
"""


class _Handler(BaseHTTPRequestHandler):
    """One HTTP request of the stream server."""

    server_stream: VideoStreamServer
    server_version = "beastbt-stream/1"

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - the stdlib's signature
        pass  # one line per request would drown the run's console

    def end_headers(self) -> None:
        """Every answer carries :data:`~beastbt.live.endpoint.SECURITY_HEADERS` (no referrer, no framing)."""
        for name, value in SECURITY_HEADERS.items():
            self.send_header(name, value)
        self.send_header("Content-Security-Policy", "frame-ancestors 'none'")  # the page's script is inline
        super().end_headers()

    def _refusal(self) -> Optional[str]:
        """Why this request is refused (403), or None: a ``Host`` that is not this server (DNS rebinding), or
        ``Origin`` of another page.

        Bound to loopback, ``Host`` must be ``localhost``, ``127.0.0.1``, ``[::1]`` or the bound address;
        bound to a network, an IP address or this computer's own name (a rebinding page shows its DNS name).
        """
        host = self.headers.get("Host")
        bound = self.server_stream.config.host
        ok = host_allowed(host, bound) if is_loopback(bound) else host_on_network(host)
        if not ok:
            return (f"this server answers to localhost, 127.0.0.1, [::1] or this computer's address, not Host "
                    f"'{(host or '')[:80]}' (a page that reached it under another name may not use it)")
        origin = self.headers.get("Origin")
        if origin is not None and not same_origin(origin, host):
            return f"a request from the page '{origin[:80]}' is refused: only this server's own page may use it"
        return None

    def _send(self, code: int, ctype: str, body: bytes) -> None:
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-cache, no-store")
        self.end_headers()
        self.wfile.write(body)

    def do_GET(self) -> None:  # noqa: N802 - the stdlib's name
        stream = self.server_stream
        path = urlsplit(self.path).path
        try:
            refusal = self._refusal()
            if refusal is not None:
                self._send(403, "text/plain; charset=utf-8", (refusal + "\n").encode())
            elif path in ("/", "/index.html"):
                self._send(200, "text/html; charset=utf-8", PAGE.encode())
            elif path == "/status.json":
                self._send(200, "application/json", json.dumps(stream.status()).encode())
            elif path == "/snapshot.jpg":
                data = stream.newest_jpeg()
                if data is None:
                    self._send(503, "text/plain", b"no camera frame yet\n")
                else:
                    self._send(200, "image/jpeg", data)
            elif path == "/stream.mjpg":
                self._stream(stream)
            else:
                self._send(404, "text/plain", b"not found: try /, /stream.mjpg, /snapshot.jpg or /status.json\n")
        except (BrokenPipeError, ConnectionResetError, socket.timeout, OSError):
            pass  # the viewer went away

    def _stream(self, stream: VideoStreamServer) -> None:
        self.connection.settimeout(stream.config.client_timeout_s)
        if stream.config.send_buffer_bytes:
            self.connection.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, stream.config.send_buffer_bytes)
        self.send_response(200)
        self.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
        self.send_header("Cache-Control", "no-cache, no-store")
        self.send_header("Pragma", "no-cache")
        self.end_headers()
        client = ClientStats(address=f"{self.client_address[0]}:{self.client_address[1]}", connection=self.connection)
        stream._add_client(client)
        last = 0
        try:
            while True:
                got = stream.jpeg.wait_newer(last, 0.5)
                if got is None:
                    if stream.jpeg.closed:
                        return
                    continue
                seq, (data, raw_seq) = got
                head = (f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(data)}\r\n"
                        f"X-Frame-Seq: {raw_seq}\r\n\r\n").encode()
                # counted before the write: a viewer that has the frame is always counted as having it
                if last:
                    client.skipped += max(0, seq - last - 1)
                client.frames += 1
                client.bytes += len(data)
                last = seq
                self.wfile.write(head + data + b"\r\n")
        finally:
            stream._remove_client(client)


# -- in a run -------------------------------------------------------------------------------------

def config_from_options(opts: Any) -> Optional[StreamConfig]:
    """The stream's config from a run's options (None when ``stream`` is not set); ValueError when bad."""
    spec = opts.stream
    if spec is None or spec is False:
        return None
    host, port = spec if isinstance(spec, tuple) else parse_endpoint(spec)
    d: dict = {"host": host, "port": port}
    size = opts.stream_size
    if size:
        d["width_px"], d["height_px"] = size if isinstance(size, tuple) else parse_size(size)
    if opts.stream_quality is not None:
        d["jpeg_quality"] = int(opts.stream_quality)
    if opts.stream_fps is not None:
        d["fps"] = float(opts.stream_fps)
    if not opts.stream_overlay:
        d["overlay"] = False
    return StreamConfig.from_dict(d)


def install_stream(prepared: Any) -> Optional[VideoStreamServer]:
    """With ``--stream``, serve the run's camera live until the run ends."""
    from beastbt.core.errors import InvalidInput, Position, Problem
    try:
        config = config_from_options(prepared.options)
    except ValueError as exc:
        raise InvalidInput([Problem("--stream", Position(), str(exc), "e.g. --stream 8080 --stream-size 640x480")]) from None
    if config is None:
        return None
    run = prepared.run
    server = VideoStreamServer(config)
    try:
        server.start()
    except OSError as exc:
        raise InvalidInput([Problem("--stream", Position(), f"cannot listen on {config.host}:{config.port}: {exc}",
                                    "pick another port, or 0 for any free one")]) from None
    prepared.closers.append(server.close)
    run.ctx.services.video_stream = server
    pipeline = run.io.camera
    if pipeline is not None:
        pipeline.enable("stream")
    run.recorders.append(_feeder(run, server, pipeline))
    print(f"live video: {server.url} (stream {server.url}stream.mjpg)", flush=True)
    run.events.add("stream", f"live video on {server.url}")
    return server


def _feeder(run: Any, server: VideoStreamServer, pipeline: Any) -> Callable[[Any], None]:
    """The recorder that hands each new camera frame and the run's state to the server."""
    state = {"seq": 0, "blank_s": -1e9}
    mission = run.mission.name

    def feed(rec: Any) -> None:
        latest = pipeline.latest if pipeline is not None else None
        from beastbt.vision.overlay import describe
        line = describe(latest[1]) if latest is not None and latest[1] is not None else ""
        server.set_status({"mission": mission, "status": run.status or "running", "step": run.current_step(),
                           "time_s": round(run.elapsed_s, 2), "pose": run.pose_text(), "line": line})
        if latest is not None:
            frame, detection = latest
            if frame.seq != state["seq"]:
                state["seq"] = frame.seq
                server.publish(frame.image, frame.stamp_s, detection, pipeline.geometry, pipeline.lookahead_m,
                               frame.jpeg)
        elif pipeline is None and rec.now_s - state["blank_s"] >= NO_CAMERA_PERIOD_S:
            state["blank_s"] = rec.now_s
            server.publish(np.full((240, 320, 3), 40, np.uint8), rec.now_s)

    return feed


__all__ = ["VideoStreamServer", "StreamConfig", "LatestSlot", "ClientStats", "compose_frame", "encode_jpeg",
           "parse_endpoint", "parse_size",
           "install_stream", "config_from_options", "BOUNDARY"]
