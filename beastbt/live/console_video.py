"""The console's live video: the camera's own frames, as JPEG held to a bit budget per viewer, with the overlay
drawn by the page.

How frames flow, so that nobody waits for anybody and nothing is done twice:

* it runs in the console's own process (:mod:`beastbt.live.console_process`). A camera that gives its own
  JPEG (a USB camera's MJPEG, the simulator's fake MJPEG camera) hands its bytes over untouched
  (:attr:`ConsoleVideo.raw` gets ``("jpeg", bytes, ...)``): they go to the viewers as they are, never
  decoded or encoded here. A camera that gives pixels hands them over through shared memory; they are
  JPEG-encoded once, at the camera's own size (smaller only when over ``width_px`` x ``height_px``). On the
  simulator, when the mission itself does not use the camera, the run sends only where the robot is, and
  this process renders the view with a camera of its own on the same mounting (:attr:`ConsoleVideo.pull`),
  only while someone watches, so that watching costs the loop nothing;
* one thread takes the newest frame at most ``fps`` times a second and makes it one message for every
  viewer. When it encodes, its JPEG quality follows the bytes each frame took, so that a stream of ``fps``
  frames fits ``budget_bps`` (a busy picture costs quality, not bandwidth); a camera's own JPEG that is over
  the budget costs frames instead (:class:`BudgetGuard`);
* the overlay (the caption, the detected line, the target, a junction or a line end) is not drawn into the
  picture: it goes with each frame as a small JSON object in image fractions, and the page draws it on its
  canvas (``console_page/console.js``);
* each viewer's WebSocket sender (:mod:`beastbt.live.console_server`) sends the newest frame when its
  previous one has gone, and skips a frame that would take it over the budget in the last second. A slow
  viewer skips frames; it never slows the encoder, the loop or the other viewers.

Each frame goes out as one binary WebSocket message: a 16-byte header (the wall time it was captured, Unix
ms as a little-endian float64; its sequence number, uint32; the JPEG quality, uint16, 0 for the camera's
own JPEG passed through; the overlay's length in bytes, uint16), the overlay (UTF-8 JSON), then the JPEG.
The page uses the capture time to show the frame's age.
"""

from __future__ import annotations

import json
import struct
import sys
import threading
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from beastbt.live.video_stream import LatestSlot, encode_jpeg

HEADER = struct.Struct("<dIHH")
"""Frame header: capture wall time (Unix ms, float64), sequence number, JPEG quality (0: the camera's own), overlay
length (bytes)."""
QUALITY_MIN = 20
QUALITY_MAX = 90
PASSED_THROUGH = 0
"""The header's quality for a camera's own JPEG, sent as it came."""


@dataclass(frozen=True)
class VideoConfig:
    """The console's video: the largest frame sent (px; a camera's own JPEG is sent at its size), most frames a
    second, the bit budget per viewer (bit/s), whether the page draws the overlay."""

    width_px: int = 1280
    height_px: int = 720
    fps: float = 25.0
    budget_bps: float = 4_500_000.0
    overlay: bool = True


@dataclass(frozen=True)
class Encoded:
    """One frame to send: the message (header + overlay + JPEG), its raw frame's sequence, capture time (wall s),
    JPEG quality (0: the camera's own)."""

    message: bytes
    seq: int
    captured_wall_s: float
    quality: int


def overlay_of(caption: Optional[list[str]], detection: Any, geometry: Any, lookahead_m: float) -> dict:
    """What the page draws over a frame: the ``caption`` lines, and where the detector's line, target, junction
    and line end are, as fractions of the image's width and height (``geometry``: the camera that took it)."""
    out: dict[str, Any] = {"caption": list(caption or [])}
    if geometry is None:
        return out
    from beastbt.vision.overlay import describe
    out["caption"].append(describe(detection))
    if detection is None:
        return out
    w, h = float(geometry.width_px), float(geometry.height_px)

    def frac(points: Any) -> list[list[float]]:
        uv = geometry.ground_to_pixels(np.asarray(points, float).reshape(-1, 2))
        uv = uv[np.isfinite(uv).all(axis=1)]
        return [[round(float(u) / w, 4), round(float(v) / h, 4)] for u, v in uv]

    obs = detection.observation
    if len(detection.points) >= 2:
        out["line"] = frac(detection.points)
    if obs.seen:
        out["target"] = frac([[lookahead_m, obs.offset_m]])
    if detection.intersection_xy is not None:
        out["junction"] = frac([detection.intersection_xy])
    if detection.end_xy is not None:
        out["end"] = frac([detection.end_xy])
    return out


class ConsoleVideo:
    """The video of one run's console (see the module docstring).

    ``wall`` is a monotonic wall clock (s); ``epoch`` the wall time as Unix
    seconds (for the page's frame age); ``caption`` gives the overlay's text
    lines (the video thread calls it).
    """

    def __init__(self, config: VideoConfig, wall: Callable[[], float], epoch: Callable[[], float],
                 caption: Callable[[], list[str]]) -> None:
        self.config = config
        self.wall = wall
        self.epoch = epoch
        self.caption = caption
        self.raw = LatestSlot()
        self.encoded = LatestSlot()
        self.viewers = 0
        self.quality = 70
        self.frames_encoded = 0
        """Frames JPEG-encoded here (pixels from the camera, or the simulator's viewer camera)."""
        self.frames_passed = 0
        """Camera JPEGs sent on as they came (no decode, no encode)."""
        self.bytes_encoded = 0
        self._closing = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._seq = 0
        self.pull: Optional[Callable[[], np.ndarray]] = None
        """Renders a frame on demand in the video thread (the simulator's viewer camera), when set."""
        self.pull_fps: Optional[float] = None
        """Most frames a second :attr:`pull` renders (None: ``fps``): a rendered camera need not beat its model."""

    @property
    def target_bytes(self) -> float:
        """The size a frame should have for ``fps`` frames to fit the budget (bytes, with 10 % headroom)."""
        return 0.9 * self.config.budget_bps / 8.0 / self.config.fps

    # -- life --------------------------------------------------------------------------
    def start(self) -> "ConsoleVideo":
        """Start the video thread."""
        self._thread = threading.Thread(target=self._encode_loop, name="beastbt-console-video", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the video thread; wake every viewer's sender for good."""
        self._closing.set()
        self.raw.close()
        self.encoded.close()
        if self._thread is not None:
            self._thread.join(2.0)

    # -- the video thread --------------------------------------------------------------
    def _encode_loop(self) -> None:
        period = 1.0 / self.config.fps
        next_wall = self.wall()
        done = 0
        while not self._closing.is_set():
            if self.pull is not None and self.viewers > 0:
                pull_period = 1.0 / min(self.config.fps, self.pull_fps or self.config.fps)
                delay = next_wall - self.wall()
                if delay > 0:
                    self._closing.wait(delay)
                next_wall = max(next_wall + pull_period, self.wall() - 0.5 * pull_period)
                self._encode_pulled()
                continue
            got = self.raw.wait_newer(done, 0.2)
            if got is None:
                continue
            delay = next_wall - self.wall()
            if delay > 0:
                self._closing.wait(delay)
                got = self.raw.get()
            seq, raw = got
            done = seq
            next_wall = max(next_wall + period, self.wall() - 0.5 * period)  # keep the rate; no burst after a stall
            try:
                self.encoded.put(self.encode(raw, seq))
            except Exception as exc:  # noqa: BLE001 - a bad frame must not end the video
                print(f"beastbt console: could not send a frame: {exc!r}", file=sys.stderr)

    def _encode_pulled(self) -> None:
        pull = self.pull
        if pull is None:
            return
        try:
            image = pull()
            self._seq += 1
            self.encoded.put(self.encode((image, None, None, 0.25, self.epoch()), self._seq))
        except Exception as exc:  # noqa: BLE001 - a bad frame must not end the video
            print(f"beastbt console: could not render a frame: {exc!r}", file=sys.stderr)

    def _overlay_bytes(self, detection: Any, geometry: Any, lookahead_m: float) -> bytes:
        if not self.config.overlay:
            return b""
        data = json.dumps(overlay_of(self.caption(), detection, geometry, lookahead_m), separators=(",", ":"))
        return data.encode()[:0xFFFF]

    def encode(self, raw: tuple, seq: int) -> Encoded:
        """One frame's message: a camera's own JPEG as it came (``("jpeg", bytes, detection, geometry,
        lookahead_m, captured)``), or pixels (``(image, detection, geometry, lookahead_m, captured)``) JPEG-encoded
        at their size (smaller only when over the configured size), the quality then steered toward the budget."""
        if isinstance(raw[0], str) and raw[0] == "jpeg":
            _, jpeg, detection, geometry, lookahead_m, captured = raw
            overlay = self._overlay_bytes(detection, geometry, lookahead_m)
            self.frames_passed += 1
            return Encoded(HEADER.pack(captured * 1000.0, seq & 0xFFFFFFFF, PASSED_THROUGH, len(overlay)) + overlay
                           + jpeg, seq, captured, PASSED_THROUGH)
        image, detection, geometry, lookahead_m, captured = raw
        cfg = self.config
        h, w = image.shape[:2]
        if w > cfg.width_px or h > cfg.height_px:
            import cv2
            scale = min(cfg.width_px / w, cfg.height_px / h)
            image = cv2.resize(image, (max(1, int(w * scale)), max(1, int(h * scale))), interpolation=cv2.INTER_AREA)
        quality = self.quality
        jpeg = encode_jpeg(image, quality)
        self._steer(len(jpeg))
        self.frames_encoded += 1
        self.bytes_encoded += len(jpeg)
        overlay = self._overlay_bytes(detection, geometry, lookahead_m)
        return Encoded(HEADER.pack(captured * 1000.0, seq & 0xFFFFFFFF, quality, len(overlay)) + overlay + jpeg,
                       seq, captured, quality)

    def _steer(self, size: int) -> None:
        # JPEG size grows roughly linearly with quality in the useful range: step toward the target,
        # faster down than up, so that a busy scene is brought under the budget within a few frames.
        ratio = self.target_bytes / max(1, size)
        step = (ratio - 1.0) * (25 if ratio < 1.0 else 10)
        self.quality = int(max(QUALITY_MIN, min(QUALITY_MAX, round(self.quality + max(-25, min(8, step))))))


class BudgetGuard:
    """A viewer's bit budget over a sliding second: may this message go now? (wall clock in s)"""

    def __init__(self, budget_bps: float, wall: Callable[[], float], window_s: float = 1.0) -> None:
        self.budget_bytes = budget_bps / 8.0 * window_s
        self.window_s = window_s
        self.wall = wall
        self.sent: list[tuple[float, int]] = []

    def allows(self, size: int) -> bool:
        """True when sending ``size`` bytes now keeps the last ``window_s`` within the budget (then counted)."""
        now = self.wall()
        self.sent = [(t, n) for t, n in self.sent if now - t < self.window_s]
        if self.sent and sum(n for _, n in self.sent) + size > self.budget_bytes:
            return False
        self.sent.append((now, size))
        return True


__all__ = ["ConsoleVideo", "VideoConfig", "Encoded", "BudgetGuard", "HEADER", "PASSED_THROUGH", "overlay_of"]
