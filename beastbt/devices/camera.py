"""The camera driver: newest frame from a ``cv2.VideoCapture``-like source, with reopen.

:class:`Camera` reads frames through the :class:`~beastbt.devices.interfaces.FrameSource`
protocol: on the robot that is a ``cv2.VideoCapture`` on ``/dev/video0``
(V4L2, see HARDWARE.md "Camera", opened by :func:`open_video_capture`); in
the simulator a :class:`beastbt.sim.camera_emulator.SimCamera` that renders
the floor. Each frame is stamped with the injected clock and numbered. When
the source vanishes (a read fails, or it reports it is not opened) the driver
reports ``camera_lost``, releases it and retries ``open_source()`` every
``reopen_interval_s``; meanwhile its data is stale. It never raises out of
:meth:`Camera.poll`.

A camera that hands over its own JPEG frames (``read_jpeg()``: a USB camera's MJPEG through
:class:`MjpegCapture`, recorded frames through :class:`MjpegReplay`, the simulator's fake
MJPEG camera) is *compressed*: each :class:`CameraFrame` carries those bytes untouched
(``jpeg``), for the console (and the ``--stream`` server), and its pixels are decoded only when the caller
asks (vision), possibly at a fraction of the size (:func:`decode_jpeg`).

A camera that hands over its own H.264 (``read_h264()``: the Pi camera through picamera2's ``H264Encoder``, a
V4L2 camera with H.264 through PyAV (:class:`V4l2H264Capture`), recorded access units through
:class:`H264Replay`, the simulator's fake H.264 camera :class:`EncodingH264Camera`) gives one access unit
(Annex B) per frame (``h264``), for the console to pass on untouched. H.264 pictures depend on the ones before
them: once vision has asked for pixels, every access unit is decoded (PyAV), not only the frames it uses.

:class:`CameraConfig` also carries the camera's mounting on the robot
(height, pitch, field of view, forward offset), which
:class:`beastbt.vision.camera_model.CameraGeometry` turns into the
image <-> floor mapping the line detector needs.
"""

from __future__ import annotations

import io
import math
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, TypeVar, Union

import cv2
import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.blackboard.types import CameraFrame
from beastbt.core.config import dataclass_from_dict
from beastbt.devices.interfaces import EventSink, FrameSource, ignore_events
from beastbt.core.clock import Clock


FORMATS = ("auto", "mjpeg", "h264", "raw")
"""What a camera may hand over (``camera.format``)."""

JPEG_SOI = b"\xff\xd8"
"""The two bytes every JPEG starts with."""


def decode_jpeg(data: bytes, reduction: int = 1) -> Optional[np.ndarray]:
    """A JPEG as BGR uint8, decoded at 1/``reduction`` of its size (1, 2, 4 or 8: libjpeg scales while it
    decodes, which costs a fraction of a full decode); None when it does not decode."""
    flag = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
            8: cv2.IMREAD_REDUCED_COLOR_8}[reduction]
    image = cv2.imdecode(np.frombuffer(data, np.uint8), flag)
    return image if image is not None and image.size else None


@dataclass
@schema_defaults("parts/camera.schema.json#/properties/mounting")
class CameraMounting:
    """Where the camera sits on the robot and where it looks (profile ``camera.mounting:``).

    Body frame: x forward, y left, z up, origin at the robot centre on the floor.
    """

    # Height of the camera's optical centre above the floor, metres.
    height_m: float
    # Downward pitch of the optical axis below horizontal, degrees (down positive).
    # Line following needs the floor in view: 30-60 deg is typical.
    pitch_deg: float
    # Horizontal field of view, degrees (Pi Camera v2: 62.2; Module 3: 66; OV5647: 54).
    # The vertical field follows from the image aspect ratio (square pixels).
    hfov_deg: float
    # Forward offset of the camera from the robot centre, metres (ahead positive).
    x_offset_m: float

    def __post_init__(self) -> None:
        if not 0.0 < self.height_m <= 5.0:
            raise ValueError(f"camera.mounting.height_m must be in (0, 5] m, got {self.height_m}")
        if not -89.0 <= self.pitch_deg <= 90.0:
            raise ValueError(f"camera.mounting.pitch_deg must be in [-89, 90] deg, got {self.pitch_deg}")
        if not 5.0 <= self.hfov_deg <= 170.0:
            raise ValueError(f"camera.mounting.hfov_deg must be in [5, 170] deg, got {self.hfov_deg}")
        if not -2.0 <= self.x_offset_m <= 2.0:
            raise ValueError(f"camera.mounting.x_offset_m must be in [-2, 2] m, got {self.x_offset_m}")

    @classmethod
    def from_dict(cls, d: Any) -> "CameraMounting":
        """Build from a profile dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "camera.mounting")


@dataclass
@schema_defaults("parts/camera.schema.json", computed={"mounting": "a nested config: CameraMounting reads its own defaults"})
class CameraConfig:
    """Which camera to open and how (robot profile ``camera:``)."""

    # V4L2 device: a path ("/dev/video0") or an index (0). On a Pi 4 with the
    # libcamera stack the CSI camera appears as /dev/video0 through the V4L2 compat layer.
    device: Union[str, int]
    # Requested frame width and height, pixels. 320x240 is plenty for line following
    # and cheapest; 640x480 is the common native mode (the detector downsamples).
    width_px: int
    height_px: int
    # Requested frame rate, frames per second. poll() also reads at most this often
    # (by the injected clock), so a simulated camera renders exactly this rate.
    fps: float
    # Mounting geometry of the camera on the robot.
    mounting: CameraMounting = field(default_factory=CameraMounting)
    # While the camera is lost, seconds between attempts to reopen it.
    reopen_interval_s: float
    # Frames older than this are stale, seconds. Default 3 frame periods at 15 fps.
    stale_after_s: float
    # Consecutive failed reads from a source that still claims to be open before it
    # is declared lost and reopened (V4L2 occasionally drops a single frame).
    lost_after_failures: int
    # Which camera stack reads it: auto (picamera2 when it sees a Pi camera, else V4L2), picamera2 or v4l2.
    backend: str
    # What the camera hands over: auto (V4L2: the camera's own MJPEG when it offers it, else raw pixels;
    # picamera2 and the simulator: pixels), mjpeg (the camera's JPEG; a Pi camera's from the Pi's hardware
    # encoder; on the simulator a fake MJPEG camera), h264 (the camera's H.264: a Pi camera's from the Pi's
    # hardware encoder, a V4L2 camera's through PyAV, a .h264 file; on the simulator a fake H.264 camera)
    # or raw.
    # The camera's JPEG goes to the console untouched; only the frames vision or the recording needs are decoded.
    format: str
    # What the console encodes pixels to: auto (the Pi's hardware H.264 encoder when present, else JPEG), jpeg
    # or h264 (the hardware encoder; an error where there is none). A camera's own JPEG or H.264 goes as it came.
    console_codec: str
    # The calibrated lens as ``beastbt camera calibrate`` writes it (fx_px, fy_px, cx_px, cy_px at width_px x
    # height_px, distortion), read by beastbt.vision.camera_model.CameraGeometry.from_config; None: the ideal
    # pinhole of mounting.hfov_deg.
    intrinsics: Optional[dict]

    def __post_init__(self) -> None:
        if isinstance(self.device, bool) or not isinstance(self.device, (str, int)):
            raise ValueError(f"camera.device must be a path or an index, got {self.device!r}")
        if not 16 <= self.width_px <= 8192 or not 16 <= self.height_px <= 8192:
            raise ValueError(f"camera.width_px/height_px must be 16..8192, got {self.width_px}x{self.height_px}")
        if not 0.5 <= self.fps <= 240.0:
            raise ValueError(f"camera.fps must be in [0.5, 240], got {self.fps}")
        if not self.reopen_interval_s > 0.0:
            raise ValueError(f"camera.reopen_interval_s must be > 0 s, got {self.reopen_interval_s}")
        if not self.stale_after_s > 0.0:
            raise ValueError(f"camera.stale_after_s must be > 0 s, got {self.stale_after_s}")
        if self.lost_after_failures < 1:
            raise ValueError(f"camera.lost_after_failures must be >= 1, got {self.lost_after_failures}")
        if self.format not in FORMATS:
            raise ValueError(f"camera.format must be one of {', '.join(FORMATS)}, got {self.format!r}")
        if self.console_codec not in ("auto", "jpeg", "h264"):
            raise ValueError(f"camera.console_codec must be one of auto, jpeg, h264, got {self.console_codec!r}")

    @classmethod
    def from_dict(cls, d: Any) -> "CameraConfig":
        """Build from a profile dict (with a nested ``mounting`` dict); bad keys raise ``ValueError``."""
        if isinstance(d, Mapping) and "mounting" in d:
            d = dict(d)
            mounting = CameraMounting.from_dict(d.pop("mounting"))
            cfg = dataclass_from_dict(cls, d, "camera")
            cfg.mounting = mounting
            return cfg
        return dataclass_from_dict(cls, d, "camera")


class MjpegCapture:
    """A V4L2 camera that hands over its own MJPEG frames: ``read_jpeg()`` gives each frame's JPEG bytes untouched.

    OpenCV's V4L2 backend with ``CAP_PROP_FOURCC`` MJPG and ``CAP_PROP_CONVERT_RGB`` 0 returns the camera's
    buffer (a 1 x N uint8 array) instead of decoding it. :meth:`read` decodes, for a caller that wants pixels.
    """

    def __init__(self, capture: Any) -> None:
        self._cap = capture
        self.compressed = True
        """False once the backend turned out to decode anyway (then :meth:`read` gives its pixels)."""

    def isOpened(self) -> bool:  # noqa: N802 - the cv2.VideoCapture name
        """True while the device is open."""
        return bool(self._cap.isOpened())

    def read_jpeg(self) -> tuple[bool, Optional[bytes]]:
        """(True, the newest frame's JPEG bytes), or (False, None) when the read failed or gave no JPEG."""
        ok, buf = self._cap.read()
        if not ok or buf is None:
            return False, None
        if buf.ndim == 3:  # the backend decoded in spite of CONVERT_RGB 0: pixels from now on
            self.compressed = False
            return False, None
        data = np.asarray(buf, np.uint8).tobytes()
        return (True, data) if data[:2] == JPEG_SOI else (False, None)

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """(True, the newest frame as BGR), or (False, None)."""
        if not self.compressed:
            return self._cap.read()
        ok, data = self.read_jpeg()
        image = decode_jpeg(data) if ok and data is not None else None
        return (image is not None), image

    def release(self) -> None:
        """Close the device."""
        self._cap.release()


def split_jpegs(data: bytes) -> list[bytes]:
    """The JPEG frames of an MJPEG file (JPEGs back to back, as ``ffmpeg -c:v copy -f mjpeg`` writes them)."""
    frames: list[bytes] = []
    start = data.find(JPEG_SOI + b"\xff")
    while start >= 0:
        end = data.find(b"\xff\xd9", start + 2)
        if end < 0:
            break
        # An end marker is followed by the next frame's start (or the file's end): else it was inside a thumbnail.
        nxt = data.find(JPEG_SOI + b"\xff", end + 2)
        while nxt > end + 2 and data.find(b"\xff\xd9", end + 2, nxt) >= 0:
            end = data.find(b"\xff\xd9", end + 2, nxt)
        frames.append(data[start:end + 2])
        start = nxt
    return frames


_Replay = TypeVar("_Replay", bound="_LoopedReplay")


class _LoopedReplay:
    """A fake camera's common part: hands over recorded compressed frames (bytes) in a loop, untouched, until
    released. Subclasses name the read (``read_jpeg``, ``read_h264``) and decode for ``read()``."""

    compressed = True

    def __init__(self, items: list[bytes]) -> None:
        self.items = items
        self.index = 0
        self._open = True
        self.frames_read = 0
        """Frames (access units) handed over so far."""

    def isOpened(self) -> bool:  # noqa: N802 - the cv2.VideoCapture name
        """True until released."""
        return self._open

    def _next(self) -> tuple[bool, Optional[bytes]]:
        """(True, the next frame's bytes), or (False, None) once released."""
        if not self._open:
            return False, None
        data = self.items[self.index]
        self.index = (self.index + 1) % len(self.items)
        self.frames_read += 1
        return True, data

    def release(self) -> None:
        """Close it (reads fail)."""
        self._open = False

    EMPTY_FILE = "nothing to replay in it"
    """What a file with no frame of this kind is told (after its path)."""

    @staticmethod
    def split(data: bytes) -> list[bytes]:
        """A file's bytes cut into the frames (access units) this kind of camera hands over."""
        raise NotImplementedError

    @classmethod
    def from_file(cls: type[_Replay], path: str) -> _Replay:
        """The replay of a file's frames (``ValueError`` naming the file when it holds none, or they cannot be
        replayed)."""
        with open(path, "rb") as f:
            items = cls.split(f.read())
        if not items:
            raise ValueError(f"{path}: {cls.EMPTY_FILE}")
        try:
            return cls(items)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None


class MjpegReplay(_LoopedReplay):
    """A fake MJPEG camera: replays JPEG frames (a list, or an MJPEG file's) in a loop through ``read_jpeg()``.

    The frames are real JPEG bytes, handed over untouched as a USB camera's are, so that the camera path of
    the robot (passed through to the console, decoded only for vision) runs on a machine without a camera.
    """

    def __init__(self, frames: list[bytes]) -> None:
        if not frames:
            raise ValueError("an MJPEG replay needs at least one JPEG frame")
        super().__init__(frames)

    @property
    def frames(self) -> list[bytes]:
        """The JPEG frames it replays."""
        return self.items

    EMPTY_FILE = "no JPEG frame in it (expected JPEGs back to back, an .mjpeg file)"

    @staticmethod
    def split(data: bytes) -> list[bytes]:
        """An MJPEG file's JPEG frames."""
        return split_jpegs(data)

    def read_jpeg(self) -> tuple[bool, Optional[bytes]]:
        """(True, the next frame's JPEG bytes), or (False, None) once released."""
        return self._next()

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """(True, the next frame decoded to BGR), or (False, None)."""
        ok, data = self.read_jpeg()
        image = decode_jpeg(data) if ok and data is not None else None
        return (image is not None), image


H264_SUFFIXES = (".h264", ".264")
"""A ``device`` with one of these suffixes is an H.264 elementary stream (Annex B) replayed as a camera."""


class H264Replay(_LoopedReplay):
    """A fake H.264 camera: replays the access units of an H.264 file (Annex B, as ``ffmpeg -c:v copy -f h264``
    writes it; or a list of units) in a loop through ``read_h264()``, untouched, as a camera's encoder gives them.
    The first unit must be a keyframe (with SPS and PPS), so that every round decodes from its start."""

    def __init__(self, units: list[bytes]) -> None:
        from beastbt.devices.h264 import is_keyframe
        if not units:
            raise ValueError("an H.264 replay needs at least one access unit")
        if not is_keyframe(units[0]):
            raise ValueError("an H.264 replay must start at a keyframe (an IDR picture with its SPS and PPS)")
        super().__init__(units)
        self._decoder: Any = None

    @property
    def units(self) -> list[bytes]:
        """The access units it replays."""
        return self.items

    EMPTY_FILE = "no H.264 access unit in it (expected an Annex B elementary stream, .h264)"

    @staticmethod
    def split(data: bytes) -> list[bytes]:
        """An H.264 file's access units (it must start at a keyframe: the constructor checks)."""
        from beastbt.devices.h264 import split_access_units
        return split_access_units(data)

    def read_h264(self) -> tuple[bool, Optional[bytes]]:
        """(True, the next access unit's bytes), or (False, None) once released."""
        return self._next()

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """(True, the next picture decoded to BGR), or (False, None) (PyAV decodes every unit in order)."""
        from beastbt.devices.h264 import H264Decoder
        ok, data = self.read_h264()
        if not ok or data is None:
            return False, None
        if self._decoder is None:
            self._decoder = H264Decoder()
        image = self._decoder.decode(data)
        return (image is not None), image


class EncodingH264Camera:
    """A fake H.264 camera on the simulator: each frame a pixel source (a :class:`SimCamera`) renders, handed over
    as the access unit a camera's own encoder would give (``read_h264``), so that the H.264 camera path (passed to
    the console untouched) runs end to end. It encodes with PyAV's software ``encoder`` (the wheel's libx264):
    that stands for a camera's hardware, which does it for free, and costs this process, not the console's."""

    compressed = True

    def __init__(self, camera: Any, fps: float = 15.0, encoder: Optional[str] = None,
                 bit_rate: float = 1_000_000.0) -> None:
        from beastbt.devices.h264 import H264Encoder, software_encoder
        self.camera = camera
        self.encoder = H264Encoder(encoder or software_encoder() or "libx264", bit_rate, fps)
        self._queue: list[bytes] = []
        self.frames_encoded = 0
        """Access units handed over so far."""

    def reopen(self) -> "EncodingH264Camera":
        """What the driver's ``open_source`` calls: the simulated camera opens again unless unplugged."""
        self.camera.reopen()
        return self

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        """True while the pixel source is open."""
        return bool(self.camera.isOpened())

    def release(self) -> None:
        """Close it (reads fail until :meth:`reopen`)."""
        self.camera.release()

    def read_h264(self) -> tuple[bool, Optional[bytes]]:
        """Render the current view and give its access unit: ``(True, unit)``, or ``(False, None)``."""
        ok, frame = self.camera.read()
        if not ok or frame is None:
            return False, None
        units = self.encoder.encode(frame)
        if not units:
            return False, None
        self.frames_encoded += 1
        return True, b"".join(unit for unit, _ in units)

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """Render the current view as pixels."""
        return self.camera.read()


class V4l2H264Capture:
    """A V4L2 camera that gives H.264 (a UVC H.264 camera; the Pi camera through the V4L2 compatibility layer),
    read with PyAV's demuxer: ``read_h264()`` hands over each packet (one access unit) untouched, with the SPS and
    PPS put in front of a keyframe that came without them. Needs PyAV (``pip install 'beastbt[video]'``)."""

    compressed = True

    def __init__(self, config: "CameraConfig") -> None:
        import av

        from beastbt.devices.h264 import ParameterSets
        device = config.device if isinstance(config.device, str) else f"/dev/video{config.device}"
        if isinstance(device, str) and device.isdigit():
            device = f"/dev/video{device}"
        self._container = av.open(device, format="v4l2", options={
            "input_format": "h264", "video_size": f"{config.width_px}x{config.height_px}",
            "framerate": f"{config.fps:g}"})
        self._packets = self._container.demux(video=0)
        self._sets = ParameterSets()
        self._open = True
        self._decoder: Any = None

    def isOpened(self) -> bool:  # noqa: N802 - the cv2.VideoCapture name
        """True until released or the device fails."""
        return self._open

    def read_h264(self) -> tuple[bool, Optional[bytes]]:
        """(True, the next access unit), or (False, None) when the device gave none."""
        try:
            for packet in self._packets:
                if packet.size:
                    return True, self._sets.complete(bytes(packet))
        except Exception:  # noqa: BLE001 - an unplugged camera is "lost" for the driver
            pass
        self._open = False
        return False, None

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """(True, the next picture as BGR), or (False, None)."""
        from beastbt.devices.h264 import H264Decoder
        ok, data = self.read_h264()
        if not ok or data is None:
            return False, None
        if self._decoder is None:
            self._decoder = H264Decoder()
        image = self._decoder.decode(data)
        return (image is not None), image

    def release(self) -> None:
        """Close the device."""
        if self._open:
            self._open = False
        try:
            self._container.close()
        except Exception:  # noqa: BLE001 - a vanished device may fail to close; it is gone anyway
            pass


class _NewestUnits(io.BufferedIOBase):
    """picamera2's output for its H.264 encoder: keeps the last access units in order (a viewer needs every one)
    and wakes a reader waiting for the next."""

    def __init__(self, length: int = 64) -> None:
        super().__init__()
        from beastbt.devices.h264 import UnitRing
        self.ring = UnitRing(length)

    def writable(self) -> bool:
        """An output picamera2 writes to."""
        return True

    def write(self, buf: Any) -> int:  # type: ignore[override]
        """One access unit from the encoder's thread."""
        self.ring.put(bytes(buf))
        return len(buf)


class _NewestJpeg(io.BufferedIOBase):
    """picamera2's output for its MJPEG encoder: keeps the newest JPEG and wakes a reader waiting for it."""

    def __init__(self) -> None:
        super().__init__()
        self._cond = threading.Condition()
        self.frame: Optional[bytes] = None
        self.count = 0

    def writable(self) -> bool:
        """An output picamera2 writes to."""
        return True

    def write(self, buf: Any) -> int:  # type: ignore[override]
        """One encoded frame from the encoder's thread."""
        with self._cond:
            self.frame = bytes(buf)
            self.count += 1
            self._cond.notify_all()
        return len(buf)

    def newer(self, count: int, timeout_s: float) -> tuple[int, Optional[bytes]]:
        """The newest frame once there is one after frame ``count`` (or ``timeout_s`` passed): (count, JPEG)."""
        with self._cond:
            self._cond.wait_for(lambda: self.count > count, timeout_s)
            return self.count, (self.frame if self.count > count else None)


class Picamera2Capture:
    """A Raspberry Pi camera (libcamera, through picamera2) behind the ``cv2.VideoCapture`` methods the driver uses.

    ``read()`` returns the newest BGR frame of ``width_px`` x ``height_px``.
    Pi cameras on a recent Raspberry Pi OS are libcamera devices, which
    OpenCV's V4L2 backend cannot read. With ``camera.format: mjpeg`` the Pi's hardware JPEG encoder
    (picamera2's ``MJPEGEncoder``) encodes every frame and ``read_jpeg()`` hands its bytes over untouched
    (:attr:`compressed`); ``read()`` then decodes them.
    """

    def __init__(self, config: CameraConfig) -> None:
        from picamera2 import Picamera2  # only on a Pi with the camera stack installed

        self._camera = Picamera2()
        size = (int(config.width_px), int(config.height_px))
        frame_us = int(1e6 / config.fps)
        self._wait_s = 2.0 * frame_us / 1e6
        self.compressed = config.format in ("mjpeg", "h264")
        self._jpeg: Optional[_NewestJpeg] = None
        self._units: Optional[_NewestUnits] = None
        self._decoder: Any = None
        self._count = 0
        # The hardware encoder takes YUV420; the pixel path wants "RGB888" (B, G, R in memory: OpenCV's order).
        video = self._camera.create_video_configuration(
            main={"size": size, "format": "YUV420" if self.compressed else "RGB888"}, buffer_count=2,
            controls={"FrameDurationLimits": (frame_us, frame_us)})
        self._camera.configure(video)
        if config.format == "h264":
            from picamera2.encoders import H264Encoder
            from picamera2.outputs import FileOutput
            self._units = _NewestUnits(max(8, int(4 * config.fps)))
            # SPS and PPS with every keyframe (repeat), a keyframe a second (iperiod): a viewer may join any time.
            encoder = H264Encoder(bitrate=2_000_000, repeat=True, iperiod=max(1, int(round(config.fps))))
            self._camera.start_recording(encoder, FileOutput(self._units))
        elif self.compressed:
            from picamera2.encoders import MJPEGEncoder
            from picamera2.outputs import FileOutput
            self._jpeg = _NewestJpeg()
            self._camera.start_recording(MJPEGEncoder(), FileOutput(self._jpeg))
        else:
            self._camera.start()
        self._open = True

    def isOpened(self) -> bool:  # noqa: N802 - the cv2.VideoCapture name
        """True until released."""
        return self._open

    def read_jpeg(self) -> tuple[bool, Optional[bytes]]:
        """(True, the hardware encoder's next JPEG), or (False, None) when none came within two frame periods."""
        if self._jpeg is None or not self._open:
            return False, None
        self._count, data = self._jpeg.newer(self._count, self._wait_s)
        return (True, data) if data else (False, None)

    def read_h264(self) -> tuple[bool, Optional[bytes]]:
        """(True, the hardware encoder's next access unit, in order), or (False, None) when none came within two
        frame periods. A reader more than the output's length behind skips to the oldest unit it still has."""
        if self._units is None or not self._open:
            return False, None
        got = self._units.ring.next_after(self._count, self._wait_s)
        if got is None:
            return False, None
        self._count, data, _ = got
        return True, data

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """(True, the newest frame as BGR uint8), or (False, None) when it cannot be had."""
        if self._units is not None:
            from beastbt.devices.h264 import H264Decoder
            ok, data = self.read_h264()
            if not ok or data is None:
                return False, None
            if self._decoder is None:
                self._decoder = H264Decoder()
            image = self._decoder.decode(data)
            return (image is not None), image
        if self.compressed:
            ok, data = self.read_jpeg()
            image = decode_jpeg(data) if ok and data is not None else None
            return (image is not None), image
        try:
            # picamera2's "RGB888" is laid out B, G, R in memory: already OpenCV's order.
            return True, self._camera.capture_array("main")
        except Exception:  # noqa: BLE001 - a camera that fails is "lost" for the driver, never an exception
            return False, None

    def release(self) -> None:
        """Stop and close the camera."""
        if self._open:
            self._open = False
            try:
                if self.compressed:
                    self._camera.stop_recording()
                else:
                    self._camera.stop()
                self._camera.close()
            except Exception:  # noqa: BLE001 - closing a vanished camera may fail; it is gone anyway
                pass


def h264_problem(config: CameraConfig, simulated: bool) -> Optional[str]:
    """Why ``camera.format: h264`` cannot work here (None when it can): the simulator's fake H.264 camera needs a
    software encoder in PyAV; a V4L2 H.264 camera needs PyAV to read it (a Pi camera through picamera2 does not)."""
    from beastbt.devices.h264 import pyav_installed, software_encoder
    if config.format != "h264":
        return None
    if simulated:
        if software_encoder() is None:
            return ("h264 on the simulator needs PyAV with a software H.264 encoder (libx264 or libopenh264) for "
                    "its fake H.264 camera, and this machine has none")
        return None
    device = config.device
    if isinstance(device, str) and device.lower().endswith(H264_SUFFIXES):
        return None
    if camera_backend(config) == "v4l2" and not pyav_installed():
        return "h264 from a V4L2 camera is read through PyAV, which is not installed"
    return None


def picamera2_cameras() -> int:
    """How many cameras libcamera sees through picamera2 (0 when picamera2 is not installed)."""
    try:
        from picamera2 import Picamera2
    except Exception:  # noqa: BLE001 - not installed, or its native parts are missing
        return 0
    try:
        return len(Picamera2.global_camera_info())
    except Exception:  # noqa: BLE001
        return 0


def camera_backend(config: CameraConfig) -> str:
    """Which backend opens ``config``'s camera: ``picamera2`` or ``v4l2`` (``backend: auto`` tries picamera2 first)."""
    if config.backend != "auto":
        return config.backend
    return "picamera2" if picamera2_cameras() > 0 else "v4l2"


def open_video_capture(config: CameraConfig) -> Any:
    """Open the real camera: a Pi camera through picamera2, or ``device`` through OpenCV's V4L2 (see :func:`camera_backend`).

    For V4L2: request size, rate and a 1-frame buffer.

    ``config.device`` may be ``/dev/videoN``, ``"N"`` or ``N``. The buffer of one
    frame makes ``read()`` return the newest frame instead of a queued old one.
    The returned capture may be unopened (``isOpened()`` False) if the device is
    missing; :class:`Camera` treats that as "lost" and retries.
    """
    if camera_backend(config) == "picamera2":
        try:
            return Picamera2Capture(config)
        except Exception:  # noqa: BLE001 - a missing or busy Pi camera is "lost" for the driver, which retries
            return _Unopened()
    device: Union[str, int] = config.device
    if isinstance(device, str) and device.lower().endswith(H264_SUFFIXES):
        try:  # recorded H.264 access units, replayed as a camera's encoder gives them (tests, a robot without it)
            return H264Replay.from_file(device)
        except (OSError, ValueError):
            return _Unopened()
    if config.format == "h264":
        try:
            return V4l2H264Capture(config)
        except Exception:  # noqa: BLE001 - no PyAV, no such device, no H.264 on it: "lost" for the driver
            return _Unopened()
    if isinstance(device, str) and device.lower().endswith((".mjpeg", ".mjpg")):
        try:  # recorded MJPEG frames, replayed as a camera would give them (tests, a robot without its camera)
            return MjpegReplay.from_file(device)
        except (OSError, ValueError):
            return _Unopened()
    if isinstance(device, str) and device.isdigit():
        device = int(device)
    cap = cv2.VideoCapture(device, cv2.CAP_V4L2)
    if cap.isOpened():
        if config.format != "raw":
            # Ask for the camera's own JPEG before the size: a USB camera gives its larger sizes only as MJPEG.
            cap.set(cv2.CAP_PROP_FOURCC, float(cv2.VideoWriter_fourcc(*"MJPG")))
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, float(config.width_px))
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, float(config.height_px))
        cap.set(cv2.CAP_PROP_FPS, float(config.fps))
        cap.set(cv2.CAP_PROP_BUFFERSIZE, 1.0)
        if config.format != "raw" and int(cap.get(cv2.CAP_PROP_FOURCC)) == cv2.VideoWriter_fourcc(*"MJPG"):
            if cap.set(cv2.CAP_PROP_CONVERT_RGB, 0.0):  # hand over the JPEG bytes, not decoded pixels
                return MjpegCapture(cap)
    return cap


class _Unopened:
    """A capture that could not be opened (``isOpened()`` False), as ``cv2.VideoCapture`` returns one."""

    def isOpened(self) -> bool:  # noqa: N802 - the cv2.VideoCapture name
        return False

    def read(self) -> tuple[bool, None]:
        return False, None

    def release(self) -> None:
        pass


class Camera:
    """Polls a frame source for its newest frame and reopens it when it disappears.

    ``open_source()`` returns a fresh :class:`FrameSource` (``lambda:
    open_video_capture(cfg)`` on the robot). :meth:`poll` returns a
    :class:`CameraFrame` (BGR uint8, stamped with ``clock.now()`` in seconds,
    ``seq`` counting from 1) or ``None`` when no frame is due or none could be
    read. Events: ``camera_lost`` (once per outage), ``camera_reopened``,
    ``camera_read_error`` (a single failed read). On the robot ``read()``
    blocks for up to one frame period, so run ``poll`` in the camera's thread.
    """

    def __init__(
        self,
        open_source: Callable[[], FrameSource],
        clock: Clock,
        events: EventSink = ignore_events,
        config: Optional[CameraConfig] = None,
    ) -> None:
        self.config = config if config is not None else CameraConfig()
        self._open_source = open_source
        self._clock = clock
        self._events = events
        self._source: Optional[FrameSource] = None
        self._lost = False  # an outage has been reported and not yet ended
        self._ever_opened = False
        self._period_s = 1.0 / self.config.fps
        self._next_due_s: Optional[float] = None
        self._next_open_s = -math.inf
        self._failures_in_row = 0
        self.seq = 0
        """Number of frames delivered so far (the ``seq`` of the last frame)."""
        self.last_frame_s: Optional[float] = None
        """Clock time of the newest frame, seconds (None before the first)."""
        self.read_errors = 0
        """Reads that failed (returned no frame or raised) since construction."""
        self.reopens = 0
        """Times the source was reopened after being lost."""
        self._h264_decoder: Any = None
        self._h264_fed = -1
        """The seq of the last H.264 unit the decoder took (-1: none): pictures decode only in order."""
        self.decode_every_h264 = False
        """Set once pixels were asked of an H.264 camera: from then on every unit is decoded as it is read."""
        self._try_open(self._clock.now())

    # --- state -------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        """True while an opened source is held."""
        return self._source is not None

    def is_stale(self, now_s: float) -> bool:
        """True when there is no frame younger than ``stale_after_s`` at ``now_s`` seconds."""
        return self.last_frame_s is None or now_s - self.last_frame_s > self.config.stale_after_s

    # --- polling -------------------------------------------------------------------
    def poll(self, pixels: bool = True, reduction: int = 1) -> Optional[CameraFrame]:
        """Read the newest frame if one is due (at most ``fps`` per clock second); never raises.

        From a camera that hands over its own JPEG (:attr:`compressed`), the frame carries those bytes
        (``jpeg``) untouched; its ``image`` is decoded only when ``pixels`` is True, at 1/``reduction`` of the
        size (1, 2, 4, 8). With ``pixels`` False such a frame's ``image`` is None: :meth:`decode` gives the
        pixels later. A camera that gives pixels always fills ``image`` (and ``jpeg`` is None).
        """
        now = self._clock.now()
        if self._source is None:
            if now < self._next_open_s or not self._try_open(now):
                return None
        if self._next_due_s is not None and now < self._next_due_s - 1e-9:
            return None
        # Schedule by adding whole periods, not "now + period": a 20 Hz tick then
        # still yields 15 fps on average instead of every other tick (10 fps).
        if self._next_due_s is None or now - self._next_due_s > self._period_s:
            self._next_due_s = now + self._period_s
        else:
            self._next_due_s += self._period_s
        got = self._read(now, pixels, reduction)
        if got is None:
            return None
        self._failures_in_row = 0
        self.seq += 1
        self.last_frame_s = now
        image, jpeg = got
        if self.h264:
            unit = jpeg
            if pixels or self.decode_every_h264:
                self.decode_every_h264 = True
                image = self._decode_h264(unit, self.seq)  # type: ignore[arg-type]
            return CameraFrame(stamp_s=now, image=image, seq=self.seq, h264=unit)  # type: ignore[arg-type]
        return CameraFrame(stamp_s=now, image=image, seq=self.seq, jpeg=jpeg)  # type: ignore[arg-type]

    @property
    def compressed(self) -> bool:
        """True while the held source hands over its own JPEG frames (``read_jpeg``)."""
        source = self._source
        return source is not None and bool(getattr(source, "compressed", hasattr(source, "read_jpeg")))

    @property
    def h264(self) -> bool:
        """True while the held source hands over its own H.264 access units (``read_h264``)."""
        return self._source is not None and hasattr(self._source, "read_h264")

    def _decode_h264(self, unit: bytes, seq: int) -> Optional[np.ndarray]:
        """The picture of H.264 unit ``seq`` (BGR), or None: not in order after the last one decoded, it waits
        for the next keyframe (a picture decoded from a missing one would be wrong)."""
        from beastbt.devices.h264 import H264Decoder
        try:
            if self._h264_decoder is None or seq != self._h264_fed + 1:
                self._h264_decoder = H264Decoder()
            self._h264_fed = seq
            return self._h264_decoder.decode(unit)
        except Exception:  # noqa: BLE001 - no PyAV, a broken unit: no pixels, never a crash
            return None

    def decode(self, frame: CameraFrame, reduction: int = 1) -> Optional[CameraFrame]:
        """``frame`` with its pixels (decoded from its JPEG at 1/``reduction`` of the size when it has none
        yet; from its H.264 unit at full size, in order only), or None when it does not decode; never raises."""
        if frame.image is None and frame.h264 is not None:
            self.decode_every_h264 = True  # the units after this one are decoded as they are read
            image = self._decode_h264(frame.h264, frame.seq) if frame.seq == self._h264_fed + 1 else None
            if image is None:
                self.read_errors += 1
                self._events("camera_read_error", f"camera frame {frame.seq}: no H.264 picture yet (it waits for "
                                                  "a keyframe)")
                return None
            return CameraFrame(stamp_s=frame.stamp_s, image=image, seq=frame.seq, h264=frame.h264)
        if frame.image is not None or frame.jpeg is None:
            return frame
        try:
            image = decode_jpeg(frame.jpeg, reduction)
        except Exception:  # noqa: BLE001 - a broken frame is a read error, never a crash
            image = None
        if image is None:
            self.read_errors += 1
            self._events("camera_read_error", f"camera frame {frame.seq} is not a JPEG that decodes")
            return None
        return CameraFrame(stamp_s=frame.stamp_s, image=image, seq=frame.seq, jpeg=frame.jpeg)

    def close(self) -> None:
        """Release the source (a later poll reopens it)."""
        self._release()

    # --- internals -------------------------------------------------------------------
    def _read(self, now: float, pixels: bool = True,
              reduction: int = 1) -> Optional[tuple[Optional[np.ndarray], Optional[bytes]]]:
        """One read from the held source, as (pixels, JPEG); handles and reports every failure."""
        source = self._source
        assert source is not None
        image: Optional[np.ndarray] = None
        jpeg: Optional[bytes] = None
        try:
            if not source.isOpened():
                self._declare_lost(now, "camera source reports it is no longer opened")
                return None
            if self.h264:
                ok, data = source.read_h264()  # type: ignore[attr-defined]
                jpeg = bytes(data) if ok and data else None  # the unit: poll() files it under h264
                ok = jpeg is not None
            elif self.compressed:
                ok, data = source.read_jpeg()  # type: ignore[attr-defined]
                if ok and data:
                    jpeg = bytes(data)
                    image = decode_jpeg(jpeg, reduction) if pixels else None
                    ok = image is not None or not pixels
                else:
                    ok = False
            else:
                ok, frame = source.read()
                image = self._as_bgr(frame) if ok else None
                ok = image is not None
        except Exception as exc:  # cv2.error, OSError...: a fault, never a crash
            ok = False
            self._events("camera_read_error", f"camera read raised {type(exc).__name__}: {exc}")
        if ok:
            return image, jpeg
        self.read_errors += 1
        self._failures_in_row += 1
        still_open = True
        try:
            still_open = bool(source.isOpened())
        except Exception:
            still_open = False
        if not still_open or self._failures_in_row >= self.config.lost_after_failures:
            self._declare_lost(now, f"camera read failed {self._failures_in_row} time(s) in a row")
        return None

    @staticmethod
    def _as_bgr(frame: Any) -> Optional[np.ndarray]:
        """Frame as BGR uint8 (h, w, 3); grey frames are expanded; anything else is rejected."""
        if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.size == 0:
            return None
        if frame.ndim == 2:
            return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        if frame.ndim == 3 and frame.shape[2] == 3:
            return frame
        if frame.ndim == 3 and frame.shape[2] == 4:
            return cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
        return None

    def _declare_lost(self, now: float, why: str) -> None:
        self._release()
        self._next_open_s = now + self.config.reopen_interval_s
        if not self._lost:
            self._lost = True
            self._events("camera_lost", f"camera {self.config.device} lost ({why}); retrying every {self.config.reopen_interval_s:g} s")

    def _try_open(self, now: float) -> bool:
        """Try ``open_source()`` once; True when an opened source is now held."""
        self._next_open_s = now + self.config.reopen_interval_s
        source: Optional[FrameSource] = None
        try:
            source = self._open_source()
            opened = source is not None and bool(source.isOpened())
        except Exception as exc:
            opened = False
            why = f"opening raised {type(exc).__name__}: {exc}"
        else:
            why = "device did not open"
        if not opened:
            if source is not None:
                try:
                    source.release()
                except Exception:
                    pass
            if not self._lost:
                self._lost = True
                self._events("camera_lost", f"camera {self.config.device} unavailable ({why}); retrying every {self.config.reopen_interval_s:g} s")
            return False
        self._source = source
        self._failures_in_row = 0
        self._next_due_s = None
        if self._lost:
            self._lost = False
            if self._ever_opened:
                self.reopens += 1
            again = "opened again" if self._ever_opened else "opened"
            self._events("camera_reopened", f"camera {self.config.device} {again}")
        self._ever_opened = True
        return True

    def _release(self) -> None:
        if self._source is not None:
            try:
                self._source.release()
            except Exception:
                pass
        self._source = None
