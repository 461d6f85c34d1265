"""Live video over HTTP: real JPEG frames from a running simulated mission, slow viewers, the page and snapshot.

Everything listens on 127.0.0.1 on a port the OS picks. No assertion is on
wall-clock time: waits are bounded (they only turn a hang into a failure).
"""

from __future__ import annotations

import http.client
import json
import socket
import threading

import cv2
import numpy as np
import pytest

from beastbt import cli
from beastbt.core.errors import InvalidInput
from beastbt.live.video_stream import (BOUNDARY, StreamConfig, VideoStreamServer, config_from_options,
                                          parse_endpoint)
from beastbt.run.session import RunOptions
from beastbt.testing import MissionHarness
from conftest import REPO

MISSION = REPO / "missions" / "line_to_intersection.yaml"
WAIT_S = 20.0  # a bound for waits on other threads, never a timing requirement


def read_part(f) -> tuple[dict, bytes]:
    """One part of a multipart/x-mixed-replace stream from a file-like object: (headers, body)."""
    line = f.readline()
    while line in (b"\r\n", b"\n"):
        line = f.readline()
    assert line.strip() == f"--{BOUNDARY}".encode(), line
    headers = {}
    while True:
        line = f.readline().strip()
        if not line:
            break
        k, v = line.decode().split(":", 1)
        headers[k.strip().lower()] = v.strip()
    body = f.read(int(headers["content-length"]))
    return headers, body


class Viewer(threading.Thread):
    """A /stream.mjpg client reading ``want`` frames (decoded with cv2.imdecode) in a thread."""

    def __init__(self, port: int, want: int) -> None:
        super().__init__(daemon=True)
        self.port, self.want = port, want
        self.frames: list[tuple[int, np.ndarray]] = []
        self.error: BaseException | None = None
        self.content_type = ""

    def run(self) -> None:
        try:
            conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=WAIT_S)
            conn.request("GET", "/stream.mjpg")
            resp = conn.getresponse()
            self.content_type = resp.getheader("Content-Type")
            while len(self.frames) < self.want:
                headers, body = read_part(resp)
                image = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR)
                self.frames.append((int(headers["x-frame-seq"]), image))
            conn.close()
        except BaseException as exc:  # reported by the test
            self.error = exc


def get(port: int, path: str) -> tuple[int, str, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=WAIT_S)
    conn.request("GET", path)
    r = conn.getresponse()
    out = (r.status, r.getheader("Content-Type"), r.read())
    conn.close()
    return out


def test_stream_of_a_running_mission_gives_real_jpeg_frames():
    h = MissionHarness.from_file(MISSION, seed=2, stream=("127.0.0.1", 0), stream_size=(320, 240))
    server: VideoStreamServer = h.run.ctx.services.video_stream
    pipeline = h.run.io.camera
    try:
        assert server.port != 0 and server.config.host == "127.0.0.1"
        viewer = Viewer(server.port, want=5)
        viewer.start()
        assert h.tick_until(lambda h: server.client_count == 1 or not viewer.is_alive(), 5.0) and server.client_count == 1
        seen = pipeline.frames
        while viewer.is_alive() and not h.done:
            h.tick()
            if pipeline.frames != seen:  # a new camera frame: let the encoder catch up (lockstep, bounded)
                seen = pipeline.frames
                assert server.wait_encoded(server.raw.seq, WAIT_S)
        viewer.join(WAIT_S)
        assert viewer.error is None, viewer.error
        assert viewer.content_type == f"multipart/x-mixed-replace; boundary={BOUNDARY}"
        seqs = [s for s, _ in viewer.frames]
        assert len(seqs) == 5 and seqs == sorted(seqs) and len(set(seqs)) == 5
        for _, image in viewer.frames:
            assert image is not None and image.shape == (240, 320, 3)
            assert image.std() > 10  # a picture of the floor and line, not a blank
        status = json.loads(get(server.port, "/status.json")[2])
        assert status["mission"] == "line_to_junction"
        assert status["step"].startswith("follow line until intersection")
        code, ctype, body = get(server.port, "/snapshot.jpg")
        assert code == 200 and ctype == "image/jpeg"
        assert cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR).shape == (240, 320, 3)
    finally:
        for close in h.prepared.closers:
            close()
    assert server.client_count == 0
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", server.port), timeout=2).close()


def noise_frame(rng: np.random.Generator, k: int) -> np.ndarray:
    # noise compresses badly: big JPEGs that fill a stalled viewer's socket at once
    image = rng.integers(0, 256, (720, 1280, 3), dtype=np.uint8)
    cv2.putText(image, str(k), (50, 200), cv2.FONT_HERSHEY_SIMPLEX, 6, (255, 255, 255), 12)
    return image


def test_a_slow_viewer_skips_frames_and_holds_up_nobody():
    server = VideoStreamServer(StreamConfig(port=0, width_px=0, height_px=0, jpeg_quality=80, fps=120.0,
                                            overlay=False)).start()
    rng = np.random.default_rng(0)
    try:
        slow = socket.socket()
        slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # a viewer on a bad link: tiny window
        slow.connect(("127.0.0.1", server.port))
        slow.sendall(b"GET /stream.mjpg HTTP/1.0\r\n\r\n")
        fast = Viewer(server.port, want=40)
        fast.start()
        for _ in range(int(WAIT_S * 100)):
            if server.client_count == 2:
                break
            threading.Event().wait(0.01)
        assert server.client_count == 2
        k = 0
        while fast.is_alive() and k < 300:
            k += 1
            server.publish(noise_frame(rng, k))  # the tick loop's side: never waits for a viewer
            assert server.wait_encoded(k, WAIT_S)
        fast.join(WAIT_S)
        assert fast.error is None, fast.error
        assert len(fast.frames) == 40 and [s for s, _ in fast.frames] == sorted(s for s, _ in fast.frames)
        stats = {c.address.split(":")[1]: c for c in server.clients()}
        slow_stats = stats[str(slow.getsockname()[1])]
        # stuck after what the kernel's socket buffers took (a few frames) while the fast one got 40
        assert slow_stats.frames < 20
        # the slow viewer reads again: after the buffered frames it gets the newest one, not the backlog
        f = slow.makefile("rb")
        while f.readline() not in (b"\r\n", b""):  # the HTTP response head
            pass
        seqs: list[int] = []
        while (not seqs or seqs[-1] < k) and len(seqs) < 30:
            headers, body = read_part(f)
            seqs.append(int(headers["x-frame-seq"]))
        assert seqs[-1] == k and len(seqs) < 30
        assert len(seqs) < k // 2  # most of the frames published meanwhile were skipped, not queued
        assert cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR).shape == (720, 1280, 3)
        assert slow_stats.skipped > 0
        slow.close()
    finally:
        server.close()
    assert server.client_count == 0


def test_page_snapshot_status_and_unknown_paths():
    server = VideoStreamServer(StreamConfig(port=0, width_px=160, height_px=120)).start()
    try:
        code, ctype, body = get(server.port, "/")
        assert code == 200 and ctype.startswith("text/html")
        assert b'src="/stream.mjpg"' in body and b"/status.json" in body
        assert get(server.port, "/snapshot.jpg")[0] == 503  # no frame yet
        server.publish(np.full((240, 320, 3), 200, np.uint8))
        server.set_status({"mission": "m", "step": "wait 2 s", "time_s": 1.5})
        code, ctype, body = get(server.port, "/snapshot.jpg")
        assert code == 200 and cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR).shape == (120, 160, 3)
        status = json.loads(get(server.port, "/status.json")[2])
        assert status["step"] == "wait 2 s" and status["stream"]["frames_published"] == 1
        assert get(server.port, "/nope")[0] == 404
    finally:
        server.close()


def test_stream_options():
    assert parse_endpoint("8080") == ("127.0.0.1", 8080)
    assert parse_endpoint(":81") == ("127.0.0.1", 81)
    assert parse_endpoint("0.0.0.0:9000") == ("0.0.0.0", 9000)
    with pytest.raises(ValueError):
        parse_endpoint("camera")
    cfg = config_from_options(RunOptions(stream="9001", stream_size="1280x720", stream_quality=60, stream_fps=10,
                                         stream_overlay=False))
    assert (cfg.host, cfg.port, cfg.width_px, cfg.height_px, cfg.jpeg_quality, cfg.fps, cfg.overlay) == \
        ("127.0.0.1", 9001, 1280, 720, 60, 10.0, False)
    assert config_from_options(RunOptions(stream=None)) is None
    with pytest.raises(InvalidInput):
        MissionHarness.from_file(MISSION, stream=("127.0.0.1", 0), stream_quality=0)


def test_cli_run_with_stream_closes_the_server(tmp_path):
    out = tmp_path / "s.json"
    before = {t.name for t in threading.enumerate()}
    code = cli.main(["run", str(MISSION), "--seed", "3", "--no-record", "--summary", str(out), "--stream", "127.0.0.1:0",
                     "--stream-size", "320x240", "--stream-fps", "10"])
    assert code == 0
    s = json.loads(out.read_text())
    assert any(e["kind"] == "stream" and "127.0.0.1" in e["text"] for e in s["events"])
    for t in threading.enumerate():
        if t.name.startswith("beastbt-stream") and t.name not in before:
            t.join(WAIT_S)
            assert not t.is_alive()
