"""The console's live video: the camera with the overlay, as JPEG frames held to a bit budget per viewer.

How frames flow, so that nobody waits for anybody:

* it runs in the console's own process (:mod:`beastbt.live.console_process`):
  the run hands each new camera frame over through shared memory, only while
  someone watches, into a latest-frame slot (:attr:`ConsoleVideo.raw`). On the
  simulator, when the mission itself does not use the camera, the run sends
  only where the robot is, and the encoder renders the view with a camera of
  its own on the same mounting (:attr:`ConsoleVideo.pull`), so that watching
  costs the loop nothing;
* one encoder thread takes the newest frame at most ``fps`` times a second,
  scales it, draws the overlay (the detected line and the step) and encodes
  it once for every viewer. Its JPEG quality follows the bytes each frame
  took, so that a stream of ``fps`` frames fits ``budget_bps`` (an adaptive
  stream: a busy picture costs quality, not bandwidth);
* each viewer's WebSocket sender (:mod:`beastbt.live.console_server`) sends
  the newest frame when its previous one has gone, and skips a frame that
  would take it over the budget in the last second. A slow viewer skips
  frames; it never slows the encoder, the loop or the other viewers.

Each frame goes out as one binary WebSocket message: a 16-byte header (the
wall time it was captured, Unix ms as a little-endian float64; its sequence
number, uint32; the JPEG quality, uint32), then the JPEG. The page uses the
capture time to show the frame's age.
"""

from __future__ import annotations

import struct
import sys
import threading
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from beastbt.live.video_stream import LatestSlot, compose_frame, encode_jpeg

HEADER = struct.Struct("<dII")
"""Frame header: capture wall time (Unix ms, float64), sequence number, JPEG quality."""
QUALITY_MIN = 20
QUALITY_MAX = 90


@dataclass(frozen=True)
class VideoConfig:
    """The console's video: frame size (px), most frames a second, the bit budget per viewer (bit/s), overlay."""

    width_px: int = 1280
    height_px: int = 720
    fps: float = 25.0
    budget_bps: float = 4_500_000.0
    overlay: bool = True


@dataclass(frozen=True)
class Encoded:
    """One encoded frame: the message to send (header + JPEG), its raw frame's sequence, capture time (wall s)."""

    message: bytes
    seq: int
    captured_wall_s: float
    quality: int


class ConsoleVideo:
    """The encoder of one run's console video (see the module docstring).

    ``wall`` is a monotonic wall clock (s); ``epoch`` the wall time as Unix
    seconds (for the page's frame age); ``caption`` gives the overlay's text
    lines (the encoder thread calls it).
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
        self.bytes_encoded = 0
        self._closing = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._seq = 0
        self.pull: Optional[Callable[[], np.ndarray]] = None
        """Renders a frame on demand in the encoder thread (the simulator's viewer camera), when set."""


    @property
    def target_bytes(self) -> float:
        """The size a frame should have for ``fps`` frames to fit the budget (bytes, with 10 % headroom)."""
        return 0.9 * self.config.budget_bps / 8.0 / self.config.fps

    # -- life --------------------------------------------------------------------------
    def start(self) -> "ConsoleVideo":
        """Start the encoder thread."""
        self._thread = threading.Thread(target=self._encode_loop, name="beastbt-console-video", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the encoder; wake every viewer's sender for good."""
        self._closing.set()
        self.raw.close()
        self.encoded.close()
        if self._thread is not None:
            self._thread.join(2.0)

    # -- the encoder thread ------------------------------------------------------------
    def _encode_loop(self) -> None:
        period = 1.0 / self.config.fps
        next_wall = self.wall()
        done = 0
        while not self._closing.is_set():
            if self.pull is not None and self.viewers > 0:
                delay = next_wall - self.wall()
                if delay > 0:
                    self._closing.wait(delay)
                next_wall = max(next_wall + period, self.wall() - 0.5 * period)
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
                print(f"beastbt console: could not encode a frame: {exc!r}", file=sys.stderr)

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

    def encode(self, raw: tuple, seq: int) -> Encoded:
        """Scale, draw the overlay and JPEG-encode one frame; then steer the quality toward the budget."""
        image, detection, geometry, lookahead_m, captured = raw
        cfg = self.config
        out = compose_frame(image, (cfg.width_px, cfg.height_px), self.caption() if cfg.overlay else None,
                            detection, geometry, lookahead_m)
        quality = self.quality
        jpeg = encode_jpeg(out, quality)
        self._steer(len(jpeg))
        self.frames_encoded += 1
        self.bytes_encoded += len(jpeg)
        return Encoded(HEADER.pack(captured * 1000.0, seq & 0xFFFFFFFF, quality) + jpeg, seq, captured, quality)

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


__all__ = ["ConsoleVideo", "VideoConfig", "Encoded", "BudgetGuard", "HEADER"]
