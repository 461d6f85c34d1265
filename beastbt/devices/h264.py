"""H.264 for the console's video: which encoder this machine has, the encoder, and the Annex B bits the wire needs.

The console sends H.264 only where it saves work: the Raspberry Pi 4's hardware encoder (V4L2 memory-to-memory,
``h264_v4l2m2m`` through PyAV, the well-kept FFmpeg binding; ``/dev/video11`` on a Pi) costs the CPU next to
nothing, where JPEG-encoding each frame in software costs most of a Pi core. Elsewhere the console encodes JPEG:
a software H.264 encoder would cost more CPU than JPEG, so it is never chosen by ``auto`` (a test may name one).
A camera that gives its own H.264 (the Pi camera through picamera2's ``H264Encoder``, a V4L2 camera with H.264, a
file) hands its access units over untouched; nothing here re-encodes them.

Everything on the wire is Annex B (start codes, ``00 00 01``), one access unit (one picture) per message, the
sequence and picture parameter sets (SPS, PPS) in front of every keyframe so that a viewer can start at any
keyframe. PyAV (``pip install 'beastbt[video]'``) is needed to encode or decode; the parsing here is plain Python.
"""

from __future__ import annotations

import os
import sys
import threading
from collections import deque
from fractions import Fraction
from typing import Any, Optional

import numpy as np

HARDWARE_ENCODER = "h264_v4l2m2m"
"""FFmpeg's encoder for a V4L2 memory-to-memory H.264 device (the Pi 4's ``bcm2835-codec``)."""
HARDWARE_DEVICE = "/dev/video11"
"""The Pi's H.264 encoder device (bcm2835-codec): without it ``h264_v4l2m2m`` has nothing to open on a Pi."""
CODECS = ("auto", "jpeg", "h264")
"""The console's video codec (``camera.console_codec``): auto (hardware H.264 when present, else JPEG)."""

NAL_SLICE = 1
NAL_IDR = 5
NAL_SEI = 6
NAL_SPS = 7
NAL_PPS = 8
NAL_AUD = 9
START = b"\x00\x00\x01"


def _nal_spans(data: bytes) -> list[tuple[int, int, int]]:
    """(where its start code begins, where the unit begins, where it ends) for each NAL unit of Annex B ``data``."""
    spans: list[tuple[int, int, int]] = []
    i = data.find(START)
    while i >= 0:
        begin = i + 3
        j = data.find(START, begin)
        end = len(data) if j < 0 else j
        if j >= 0:
            while end > begin and data[end - 1] == 0:  # a 4-byte start code (or trailing zeros): not the unit's
                end -= 1
        code = i - 1 if i > 0 and data[i - 1] == 0 else i
        if end > begin:
            spans.append((code, begin, end))
        i = j
    return spans


def nal_units(data: bytes) -> list[bytes]:
    """The NAL units of an Annex B byte string, each without its start code (3- or 4-byte)."""
    return [data[begin:end] for _, begin, end in _nal_spans(data)]


def nal_type(unit: bytes) -> int:
    """A NAL unit's type (5: IDR slice, 7: SPS, 8: PPS...)."""
    return unit[0] & 0x1F


def is_keyframe(access_unit: bytes) -> bool:
    """True when the access unit holds an IDR slice (a picture that decodes without the ones before it)."""
    # The header byte of each unit is all it takes: no unit is copied (this runs on every frame a viewer gets).
    return any(access_unit[begin] & 0x1F == NAL_IDR for _, begin, _ in _nal_spans(access_unit))


def avc1_codec(access_unit: bytes) -> Optional[str]:
    """The WebCodecs/MIME codec string of the stream (``avc1.PPCCLL``: profile, constraint flags, level from the
    SPS), or None when the access unit has no SPS."""
    for unit in nal_units(access_unit):
        if nal_type(unit) == NAL_SPS and len(unit) >= 4:
            return "avc1." + unit[1:4].hex().upper()
    return None


def split_access_units(stream: bytes) -> list[bytes]:
    """The access units (pictures, Annex B, with the parameter sets and SEI before them) of an H.264 elementary
    stream, as ``ffmpeg -c:v copy -f h264`` or a camera writes it.

    A new access unit begins at an access unit delimiter, at an SPS/PPS/SEI after a picture's slices, or at a
    slice whose ``first_mb_in_slice`` is 0 (its first bit after the header is 1) after another picture's slices.
    """
    units: list[bytes] = []
    first = -1
    has_slice = False
    for code, begin, end in _nal_spans(stream):
        unit = stream[begin:min(end, begin + 2)]
        kind = nal_type(unit)
        is_slice = kind in (NAL_SLICE, NAL_IDR)
        starts = kind in (NAL_AUD, NAL_SPS, NAL_PPS, NAL_SEI) or (is_slice and len(unit) > 1 and unit[1] & 0x80)
        if first < 0:
            first = code
        elif has_slice and starts:
            units.append(stream[first:code])  # the bytes as they were, start codes and all
            first, has_slice = code, False
        has_slice = has_slice or is_slice
    if first >= 0 and has_slice:
        units.append(stream[first:])
    return units


class ParameterSets:
    """Keeps the stream's last SPS and PPS and puts them in front of a keyframe that came without them (an encoder
    that sends them once, as extradata or in its first packet, and never again)."""

    def __init__(self) -> None:
        self.sps: Optional[bytes] = None
        self.pps: Optional[bytes] = None

    def complete(self, access_unit: bytes) -> bytes:
        """``access_unit``, with the SPS and PPS in front when it is a keyframe without them."""
        units = nal_units(access_unit)
        kinds = {nal_type(u) for u in units}
        for u in units:
            if nal_type(u) == NAL_SPS:
                self.sps = u
            elif nal_type(u) == NAL_PPS:
                self.pps = u
        if NAL_IDR in kinds and not {NAL_SPS, NAL_PPS} <= kinds and self.sps and self.pps:
            return b"\x00\x00\x00\x01" + self.sps + b"\x00\x00\x00\x01" + self.pps + access_unit
        return access_unit


_detected: dict[str, tuple[bool, str]] = {}
_detect_lock = threading.Lock()


def encoder_available(name: str = HARDWARE_ENCODER) -> tuple[bool, str]:
    """(True, "") when PyAV can open the H.264 encoder ``name`` here, else (False, why). Found once per process:
    for the hardware encoder, by its device (``/dev/video11`` on Linux) and then by opening it on a small frame."""
    with _detect_lock:
        if name not in _detected:
            _detected[name] = _detect(name)
        return _detected[name]


def _detect(name: str) -> tuple[bool, str]:
    # The device first: a machine without it (most) does not pay for importing FFmpeg.
    if name == HARDWARE_ENCODER and sys.platform.startswith("linux") and not os.path.exists(HARDWARE_DEVICE):
        return False, f"no V4L2 H.264 encoder device ({HARDWARE_DEVICE}: the Raspberry Pi's bcm2835-codec)"
    try:
        import av
    except ImportError:
        return False, "PyAV is not installed (pip install 'beastbt[video]')"
    try:
        context = av.CodecContext.create(name, "w")
    except Exception as exc:  # noqa: BLE001 - not in this FFmpeg build
        return False, f"FFmpeg (PyAV {av.__version__}) has no encoder {name} ({exc})"
    try:
        _configure(context, 320, 240, 15.0, 1_000_000)
        context.open()
    except Exception as exc:  # noqa: BLE001 - the build has it, this machine has no device behind it
        return False, f"the encoder {name} does not open here ({exc})"
    finally:
        try:
            context.close()
        except Exception:  # noqa: BLE001
            pass
    return True, ""


SOFTWARE_ENCODERS = ("libx264", "libopenh264")
"""Software H.264 encoders a PyAV wheel may carry: for the simulator's fake H.264 camera and tests, never ``auto``."""


def software_encoder() -> Optional[str]:
    """The first software H.264 encoder PyAV opens here (``libx264``, ``libopenh264``), or None."""
    return next((name for name in SOFTWARE_ENCODERS if encoder_available(name)[0]), None)


def pyav_installed() -> bool:
    """True when PyAV (``av``) can be imported (without importing it)."""
    import importlib.util
    return importlib.util.find_spec("av") is not None


def resolve_codec(requested: str, encoder: str = HARDWARE_ENCODER) -> tuple[str, str]:
    """What the console's video encodes, for ``requested`` (auto, jpeg, h264): ("jpeg" or "h264", why).

    ``auto`` is H.264 only with the encoder (by default the hardware one) present, else JPEG; ``h264`` without
    it raises ``ValueError`` saying why."""
    if requested not in CODECS:
        raise ValueError(f"the console's video codec must be one of {', '.join(CODECS)}, got {requested!r}")
    if requested == "jpeg":
        return "jpeg", "asked for"
    ok, why = encoder_available(encoder)
    if ok:
        return "h264", f"{encoder} is present"
    if requested == "h264":
        raise ValueError(f"h264 needs the H.264 encoder {encoder}, which this machine does not have: {why}")
    return "jpeg", why


def _configure(context: Any, width: int, height: int, fps: float, bit_rate: float) -> None:
    context.width = width
    context.height = height
    context.pix_fmt = "yuv420p"
    rate = Fraction(fps).limit_denominator(1000)
    context.time_base = 1 / rate
    context.framerate = rate
    context.bit_rate = int(bit_rate)
    context.gop_size = max(1, int(round(fps)))  # a keyframe a second: a new viewer waits at most that long
    context.max_b_frames = 0  # no reordering: each picture is shown as it arrives
    if context.name == "libx264":
        context.options = {"preset": "ultrafast", "tune": "zerolatency"}


class H264Encoder:
    """Encodes BGR frames to H.264 access units (Annex B, SPS/PPS on every keyframe) with PyAV's ``encoder``
    (the hardware one by default), at ``bit_rate`` (bit/s) and ``fps``; (re)opened at each new frame size."""

    def __init__(self, encoder: str = HARDWARE_ENCODER, bit_rate: float = 2_000_000.0, fps: float = 25.0) -> None:
        self.encoder = encoder
        self.bit_rate = bit_rate
        self.fps = fps
        self._context: Any = None
        self._size: Optional[tuple[int, int]] = None
        self._pts = 0
        self._key_wanted = False
        self._sets = ParameterSets()
        self.frames = 0
        """Frames encoded so far."""

    def request_keyframe(self) -> None:
        """The next frame is encoded as a keyframe (a viewer has just joined or lost a frame)."""
        self._key_wanted = True

    def encode(self, image: np.ndarray) -> list[tuple[bytes, bool]]:
        """The access units (bytes, keyframe?) the encoder gives for ``image`` (BGR uint8; cropped to even sides)."""
        import av
        from av.video.frame import PictureType
        h, w = image.shape[:2]
        w, h = w - w % 2, h - h % 2
        if self._size != (w, h):
            self.close()
            self._context = av.CodecContext.create(self.encoder, "w")
            _configure(self._context, w, h, self.fps, self.bit_rate)
            self._context.open()
            self._size = (w, h)
            self._key_wanted = False  # a new stream starts with one
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image[:h, :w]), format="bgr24").reformat(
            format="yuv420p")
        frame.pts = self._pts
        self._pts += 1
        if self._key_wanted:
            frame.pict_type = PictureType.I
            self._key_wanted = False
        self.frames += 1
        out = []
        for packet in self._context.encode(frame):
            data = self._sets.complete(bytes(packet))
            out.append((data, bool(packet.is_keyframe) or is_keyframe(data)))
        return out

    def close(self) -> None:
        """Let go of the encoder (the hardware one is a shared device)."""
        if self._context is not None:
            try:
                self._context.close()
            except Exception:  # noqa: BLE001 - closing must not fail the caller
                pass
        self._context = None
        self._size = None


class H264Decoder:
    """Decodes access units to BGR frames with PyAV's software decoder (a viewer that cannot decode H.264 gets the
    camera's H.264 as JPEG; a camera's H.264 decoded for vision). Until the first keyframe nothing decodes."""

    def __init__(self) -> None:
        import av
        self._av = av
        self._context = av.CodecContext.create("h264", "r")
        self._keyed = False

    def decode(self, access_unit: bytes) -> Optional[np.ndarray]:
        """The picture ``access_unit`` completes (BGR uint8), or None (before a keyframe, or it does not decode)."""
        if not self._keyed:
            if not is_keyframe(access_unit):
                return None
            self._keyed = True
        try:
            frames = self._context.decode(self._av.Packet(access_unit))
        except Exception:  # noqa: BLE001 - a broken unit: wait for the next keyframe
            self._keyed = False
            return None
        return frames[-1].to_ndarray(format="bgr24") if frames else None


class UnitRing:
    """The last access units (or anything) in order, each with a sequence number, for viewers that each read
    every one in turn; a reader that falls behind the ring's length learns it missed some (thread-safe)."""

    def __init__(self, length: int = 64) -> None:
        self._cond = threading.Condition()
        self._items: deque[tuple[int, Any]] = deque(maxlen=length)
        self.seq = 0
        self.closed = False

    def put(self, item: Any) -> int:
        """Append ``item``; its sequence number."""
        with self._cond:
            self.seq += 1
            self._items.append((self.seq, item))
            self._cond.notify_all()
            return self.seq

    def next_after(self, seq: int, timeout_s: float) -> Optional[tuple[int, Any, bool]]:
        """The first item after ``seq`` once there is one (or ``timeout_s`` passed, or closed: None), as
        (seq, item, missed): ``missed`` True when items after ``seq`` are gone from the ring."""
        with self._cond:
            if self.seq <= seq and not self.closed and timeout_s > 0:
                self._cond.wait_for(lambda: self.seq > seq or self.closed, timeout_s)
            if self.closed or self.seq <= seq or not self._items:
                return None
            first = self._items[0][0]
            index = max(0, seq + 1 - first)
            got_seq, item = self._items[index]
            return got_seq, item, got_seq > seq + 1

    def newest_where(self, test: Any) -> Optional[int]:
        """The sequence number of the newest item still in the ring for which ``test(item)`` is true, or None."""
        with self._cond:
            for seq, item in reversed(self._items):
                if test(item):
                    return seq
        return None

    def close(self) -> None:
        """Wake every reader for good."""
        with self._cond:
            self.closed = True
            self._cond.notify_all()


__all__ = ["CODECS", "HARDWARE_ENCODER", "HARDWARE_DEVICE", "SOFTWARE_ENCODERS", "software_encoder", "pyav_installed", "H264Encoder", "H264Decoder", "ParameterSets",
           "UnitRing", "avc1_codec", "encoder_available", "is_keyframe", "nal_units", "resolve_codec",
           "split_access_units"]
