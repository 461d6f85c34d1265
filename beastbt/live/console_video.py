"""The console's live video: the camera's own frames, as JPEG held to a bit budget per viewer, with the overlay
drawn by the page.

How frames flow, so that nobody waits for anybody and nothing is done twice:

* it runs in the console's own process (:mod:`beastbt.live.console_process`). A camera that gives its own
  JPEG (a USB camera's MJPEG, the simulator's fake MJPEG camera) hands its bytes over untouched
  (:meth:`ConsoleVideo.pass_jpeg`, on the thread that read them from the run): they go to the viewers as they
  are, never decoded or encoded here, and never handed to another thread of ours. A camera that gives
  pixels hands them over through shared memory; they are JPEG-encoded once, at the camera's own size
  (smaller only when over ``width_px`` x ``height_px``). On the
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
  viewer skips frames; it never slows the encoder, the loop or the other viewers. The senders are woken
  on the server's event loop when a frame is ready (:meth:`ConsoleVideo.add_waker`), not by a thread that
  waits for frames: each frame costs one wake-up of the loop, whatever the number of viewers.

Each frame goes out as one binary WebSocket message: a 16-byte header (the wall time it was captured, Unix
ms as a little-endian float64; its sequence number, uint32; the JPEG quality, uint16, 0 for the camera's
own JPEG passed through; the overlay's length in bytes, uint16), the overlay (UTF-8 JSON), then the JPEG.
The page uses the capture time to show the frame's age.

H.264 (:mod:`beastbt.devices.h264`) goes only to a viewer that said it decodes it: the page sends
``{"accept": ["h264", "jpeg"]}`` as a text message when it opens the socket (WebCodecs ``VideoDecoder``, or
else Media Source Extensions, that play H.264); a page that says nothing, or ``{"accept": ["jpeg"], "why": ...}``, gets
JPEG, byte for byte as before. An H.264 message has the same header with the quality field
:data:`H264_KEY` (a keyframe, SPS and PPS in front) or :data:`H264_DELTA`, then the overlay, then one access unit
(Annex B). H.264 is sent when the camera gives its own (passed on untouched), or when the console encodes
pixels and the codec (``VideoConfig.codec``: auto, jpeg, h264) resolved to the hardware encoder; a camera's own
JPEG always goes as it came. Every viewer reads every access unit in order (:class:`~beastbt.devices.h264.UnitRing`);
a new viewer starts at the newest keyframe still held (at most a second or two back), and one that had to skip a
unit (slow, or over its budget) waits for the next keyframe and asks the encoder for one (at most once a second;
a camera's own H.264 has one every second or so).
"""

from __future__ import annotations

import json
import struct
import sys
import threading
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from beastbt.devices.h264 import HARDWARE_ENCODER, H264Decoder, H264Encoder, UnitRing, resolve_codec
from beastbt.live.video_stream import LatestSlot, encode_jpeg

HEADER = struct.Struct("<dIHH")
"""Frame header: capture wall time (Unix ms, float64), sequence number, JPEG quality (0: the camera's own), overlay
length (bytes)."""
QUALITY_MIN = 20
QUALITY_MAX = 90
PASSED_THROUGH = 0
"""The header's quality for a camera's own JPEG, sent as it came."""
H264_KEY = 0xFF01
"""The header's quality field for an H.264 keyframe (not a JPEG: every value from 0xFF00 up is another codec)."""
H264_DELTA = 0xFF02
"""The header's quality field for an H.264 access unit that needs the ones before it."""
KEYFRAME_REQUEST_S = 1.0
"""A viewer waiting for a keyframe asks the encoder for one at most this often (s): keyframes are large."""


@dataclass(frozen=True)
class VideoConfig:
    """The console's video: the largest frame sent (px; a camera's own JPEG is sent at its size), most frames a
    second, the bit budget per viewer (bit/s), whether the page draws the overlay."""

    width_px: int = 1280
    height_px: int = 720
    fps: float = 25.0
    budget_bps: float = 4_500_000.0
    overlay: bool = True
    codec: str = "auto"
    """What the console encodes pixels to: auto (H.264 with the hardware encoder, else JPEG), jpeg or h264."""
    h264_encoder: str = HARDWARE_ENCODER
    """PyAV's encoder for ``h264`` and ``auto`` (tests may name a software one; never a default)."""


@dataclass(frozen=True)
class Encoded:
    """One frame to send: the message (header + overlay + JPEG or H.264), its raw frame's sequence, capture time
    (wall s), JPEG quality (0: the camera's own; :data:`H264_KEY`, :data:`H264_DELTA`: H.264)."""

    message: bytes
    seq: int
    captured_wall_s: float
    quality: int

    @property
    def key(self) -> bool:
        """True for a frame that decodes alone (every JPEG, an H.264 keyframe)."""
        return self.quality != H264_DELTA


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
        self.units = UnitRing(max(8, int(2 * config.fps)))
        """The H.264 access units (:class:`Encoded`), every one in order, for the viewers that take H.264."""
        self.codec = "jpeg"
        """What pixels are encoded to: "h264" or "jpeg" (``config.codec`` resolved at :meth:`start`)."""
        self.codec_why = ""
        """Why :attr:`codec` is what it is (the encoder found, or why none was)."""
        self.source = "none"
        """What the last frame came as: "jpeg" (the camera's own), "h264" (the camera's own), "pixels"."""
        self.feeds: set["ViewerFeed"] = set()
        self.frames_h264 = 0
        """H.264 access units sent on: the camera's own, or encoded here."""
        self._h264: Optional[H264Encoder] = None
        self._decoder: Optional[H264Decoder] = None
        self._unit_seq = 0
        self._last_key_request = -1e9
        self._lock = threading.Lock()
        self._camera_seq: Optional[int] = None
        self._broken = False
        self.units_dropped = 0
        """A camera's H.264 units not sent: after one that never reached this process, until the next keyframe."""
        self._wakers: tuple[Callable[[], None], ...] = ()
        self._overlay_cache: tuple[Any, bytes] = (None, b"")

    @property
    def target_bytes(self) -> float:
        """The size a frame should have for ``fps`` frames to fit the budget (bytes, with 10 % headroom)."""
        return 0.9 * self.config.budget_bps / 8.0 / self.config.fps

    # -- life --------------------------------------------------------------------------
    @property
    def h264_active(self) -> bool:
        """True while the frames go out as H.264 to the viewers that take it (the camera's own H.264, or pixels
        with the H.264 encoder); a camera's own JPEG always goes as JPEG."""
        return self.source == "h264" or (self.source in ("pixels", "none") and self.codec == "h264")

    def feed(self) -> "ViewerFeed":
        """A new viewer's feed (JPEG until its page says it decodes H.264); :meth:`ViewerFeed.close` at its end."""
        feed = ViewerFeed(self)
        with self._lock:
            self.feeds.add(feed)
        return feed

    def _wants(self) -> tuple[bool, bool]:
        """(JPEG wanted, H.264 wanted) by the viewers now (JPEG when nobody said: an old page, a test)."""
        with self._lock:
            feeds = list(self.feeds)
        if not feeds:
            return True, False
        return any(f.codec == "jpeg" for f in feeds), any(f.codec == "h264" for f in feeds)

    def add_waker(self, waker: Callable[[], None]) -> None:
        """Call ``waker`` (from whichever thread made it) each time a frame or an H.264 unit is ready, and at
        :meth:`close`: a viewer's sender waits on its own event loop instead of in a thread."""
        with self._lock:
            self._wakers = self._wakers + (waker,)

    def remove_waker(self, waker: Callable[[], None]) -> None:
        """Stop calling ``waker``."""
        with self._lock:
            self._wakers = tuple(w for w in self._wakers if w is not waker)

    def wake_viewers(self) -> None:
        """Call every waker (a frame is ready, or the end has come): from any thread."""
        for waker in self._wakers:  # a tuple replaced whole: safe to walk while a viewer comes or goes
            waker()

    def pass_jpeg(self, jpeg: bytes, detection: Any, geometry: Any, lookahead_m: float, captured: float) -> None:
        """A camera's own JPEG (the run paces them to ``fps``): to the viewers as it came, from the caller's
        thread (there is nothing to encode, so no hand-over to the video thread)."""
        self.source = "jpeg"
        raw = ("jpeg", jpeg, detection, geometry, lookahead_m, captured)
        self.encoded.put(self.encode(raw, self.frames_passed + 1))  # encode counts it in frames_passed
        self.wake_viewers()

    def want_keyframe(self) -> None:
        """A viewer waits for a keyframe: the encoder makes the next frame one (at most once a second)."""
        now = self.wall()
        if now - self._last_key_request >= KEYFRAME_REQUEST_S and self._h264 is not None:
            self._last_key_request = now
            self._h264.request_keyframe()

    def pass_h264(self, access_unit: bytes, key: bool, detection: Any, geometry: Any, lookahead_m: float,
                  captured: float, camera_seq: Optional[int] = None) -> None:
        """A camera's own H.264 access unit (Annex B, SPS/PPS before a keyframe): to the H.264 viewers as it came
        (called for every unit, in order; ``camera_seq`` its number from the camera, when known: after a unit
        that never came, the ones up to the next keyframe would not decode, and are not sent). A viewer that
        cannot decode H.264 gets it decoded and JPEG-encoded, only while there is one."""
        self.source = "h264"
        if camera_seq is not None:
            gap = self._camera_seq is not None and camera_seq != self._camera_seq + 1
            self._camera_seq = camera_seq
            self._broken = (self._broken or gap) and not key
            if self._broken:
                self.units_dropped += 1
                return
        self._put_unit(access_unit, key, self._overlay_bytes(detection, geometry, lookahead_m), captured)
        jpeg_wanted, _ = self._wants()
        if not jpeg_wanted or not self.feeds:
            self._decoder = None  # a later JPEG viewer starts again at a keyframe
            return
        try:
            if self._decoder is None:
                self._decoder = H264Decoder()
            image = self._decoder.decode(access_unit)
        except Exception as exc:  # noqa: BLE001 - PyAV missing or a broken unit: the H.264 viewers go on
            self._decoder = None
            self.codec_why = f"the camera's H.264 cannot be decoded here: {exc}"
            return
        if image is not None:
            self.raw.put((image, detection, geometry, lookahead_m, captured, "decoded"))

    def _put_unit(self, access_unit: bytes, key: bool, overlay: bytes, captured: float) -> None:
        self._unit_seq += 1
        quality = H264_KEY if key else H264_DELTA
        message = HEADER.pack(captured * 1000.0, self._unit_seq & 0xFFFFFFFF, quality, len(overlay)) + overlay
        self.units.put(Encoded(message + access_unit, self._unit_seq, captured, quality))
        self.frames_h264 += 1
        self.wake_viewers()

    def start(self) -> "ConsoleVideo":
        """Resolve the codec (``auto``: the hardware H.264 encoder when present, else JPEG; ``h264`` without it
        falls back to JPEG with a warning: the run checked it first) and start the video thread."""
        try:
            self.codec, self.codec_why = resolve_codec(self.config.codec, self.config.h264_encoder)
        except ValueError as exc:
            self.codec, self.codec_why = "jpeg", str(exc)
            print(f"beastbt console: {exc}; sending JPEG", file=sys.stderr)
        self._thread = threading.Thread(target=self._encode_loop, name="beastbt-console-video", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the video thread; wake every viewer's sender for good."""
        self._closing.set()
        self.raw.close()
        self.encoded.close()
        self.units.close()
        self.wake_viewers()
        if self._thread is not None:
            self._thread.join(2.0)
        if self._h264 is not None:
            self._h264.close()

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
                self._send(raw, seq)
            except Exception as exc:  # noqa: BLE001 - a bad frame must not end the video
                print(f"beastbt console: could not send a frame: {exc!r}", file=sys.stderr)

    def _encode_pulled(self) -> None:
        pull = self.pull
        if pull is None:
            return
        try:
            image = pull()
            self._seq += 1
            self._send((image, None, None, 0.25, self.epoch()), self._seq)
        except Exception as exc:  # noqa: BLE001 - a bad frame must not end the video
            print(f"beastbt console: could not render a frame: {exc!r}", file=sys.stderr)

    def _send(self, raw: tuple, seq: int) -> None:
        """One raw frame to the viewers: JPEG for those that take JPEG, H.264 for those that take it."""
        if len(raw) == 5:
            self.source = "pixels"
        jpeg_wanted, h264_wanted = self._wants()
        if h264_wanted and self.codec == "h264" and self.source == "pixels":
            self._encode_h264(raw)
        if jpeg_wanted:
            self.encoded.put(self.encode(raw[:5], seq))
            self.wake_viewers()

    def _encode_h264(self, raw: tuple) -> None:
        image, detection, geometry, lookahead_m, captured = raw[:5]
        cfg = self.config
        h, w = image.shape[:2]
        if w > cfg.width_px or h > cfg.height_px:
            import cv2
            scale = min(cfg.width_px / w, cfg.height_px / h)
            image = cv2.resize(image, (max(2, int(w * scale)), max(2, int(h * scale))), interpolation=cv2.INTER_AREA)
        if self._h264 is None:
            # Half the budget: H.264 at 2-3 Mbit/s looks as good as JPEG at twice that.
            self._h264 = H264Encoder(cfg.h264_encoder, 0.5 * cfg.budget_bps, cfg.fps)
        overlay = self._overlay_bytes(detection, geometry, lookahead_m)
        for unit, key in self._h264.encode(image):
            self._put_unit(unit, key, overlay, captured)

    def _overlay_bytes(self, detection: Any, geometry: Any, lookahead_m: float) -> bytes:
        if not self.config.overlay:
            return b""
        caption = self.caption()
        # The caption changes a few times a second and the detection with each frame it was made on: frames
        # between (a camera faster than the state, or no line detector) reuse the last overlay.
        # The key holds the detection and geometry themselves (compared by identity): a freed object's id could
        # be taken by a new one.
        key = (caption, detection, geometry, lookahead_m)
        cached_key, cached = self._overlay_cache
        if (cached_key is not None and cached_key[0] == caption and cached_key[1] is detection
                and cached_key[2] is geometry and cached_key[3] == lookahead_m):
            return cached
        data = json.dumps(overlay_of(caption, detection, geometry, lookahead_m), separators=(",", ":"))
        out = data.encode()[:0xFFFF]
        self._overlay_cache = (key, out)
        return out

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


class ViewerFeed:
    """What one viewer gets (its WebSocket sender calls :meth:`next_message`): JPEG frames, newest first, or
    every H.264 access unit in order from a keyframe on, within its bit budget (:class:`BudgetGuard`)."""

    def __init__(self, video: ConsoleVideo) -> None:
        self.video = video
        self.guard = BudgetGuard(video.config.budget_bps, video.wall)
        self.accepts_h264 = False
        """The page said it decodes H.264 (WebCodecs or MSE, with the codec supported)."""
        self.why_not_h264 = ""
        """What the page said when it cannot decode H.264."""
        self._last_jpeg = 0
        self._last_unit = video.units.seq
        self._need_key = True
        self._was = "jpeg"
        self.skipped = 0
        """Messages not sent to this viewer: over its budget, or H.264 units before its next keyframe."""

    @property
    def codec(self) -> str:
        """What this viewer gets now: "h264" or "jpeg"."""
        return "h264" if self.accepts_h264 and self.video.h264_active else "jpeg"

    def hello(self, text: str) -> None:
        """The page's word on what it decodes: ``{"accept": ["h264", "jpeg"]}`` (``why``: why not H.264)."""
        try:
            said = json.loads(text)
        except ValueError:
            return
        if not isinstance(said, dict) or not isinstance(said.get("accept"), list):
            return
        self.accepts_h264 = "h264" in said["accept"]
        self.why_not_h264 = str(said.get("why", ""))[:200]
        self._switch()

    def _switch(self) -> str:
        """The codec now; on a change, this viewer goes on from the new stream's newest frame (H.264: from the
        newest keyframe still held, at most a second or two old, so that the picture comes at once; a camera's
        own H.264 cannot be asked for a keyframe)."""
        codec = self.codec
        if codec != self._was:
            self._was = codec
            key = self.video.units.newest_where(lambda encoded: encoded.key)
            self._last_unit = key - 1 if key is not None else max(0, self.video.units.seq - 1)
            self._last_jpeg = max(0, self.video.encoded.seq - 1)
            self._need_key = True
        return codec

    def next_message(self, timeout_s: float) -> Optional[bytes]:
        """The next message for this viewer once there is one (None: nothing to send within ``timeout_s``)."""
        codec = self._switch()
        if codec == "h264":
            return self._next_unit(timeout_s)
        got = self.video.encoded.wait_newer(self._last_jpeg, timeout_s)
        if got is None:
            return None
        self._last_jpeg, encoded = got
        if self.guard.allows(len(encoded.message)):
            return encoded.message
        self.skipped += 1
        return None

    def has_newer(self) -> bool:
        """True when a frame or unit newer than the last one :meth:`next_message` took is ready."""
        if self.codec == "h264":
            units = self.video.units
            return not units.closed and units.seq > self._last_unit
        encoded = self.video.encoded
        return not encoded.closed and encoded.seq > self._last_jpeg

    def _next_unit(self, timeout_s: float) -> Optional[bytes]:
        got = self.video.units.next_after(self._last_unit, timeout_s)
        if got is None:
            return None
        self._last_unit, encoded, missed = got
        if missed:
            self._need_key = True
        if self._need_key and not encoded.key:
            self.skipped += 1
            self.video.want_keyframe()
            return None
        if not self.guard.allows(len(encoded.message)):
            self.skipped += 1
            self._need_key = True  # the next unit would not decode without this one
            return None
        self._need_key = False
        return encoded.message

    def close(self) -> None:
        """The viewer has gone."""
        with self.video._lock:  # noqa: SLF001 - the video's own bookkeeping
            self.video.feeds.discard(self)


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


__all__ = ["ConsoleVideo", "VideoConfig", "Encoded", "BudgetGuard", "ViewerFeed", "HEADER", "PASSED_THROUGH",
           "H264_KEY", "H264_DELTA", "overlay_of"]
