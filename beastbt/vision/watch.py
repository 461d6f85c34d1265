"""What the mission asks the camera: the detectors run on the newest frame, each only when asked and at its own rate.

:class:`VisionWatch` is the run's service behind ``{sees: ...}``, ``photo``, ``alert`` and
``dock`` (``ctx.services.vision``). It owns one detector of each kind
(:mod:`beastbt.vision.fiducials`, :mod:`~beastbt.vision.qr_codes`, :mod:`~beastbt.vision.motion`,
:mod:`~beastbt.vision.colour`), built the first time it is asked for: a mission that never asks for QR
codes never builds a QR reader. A detector runs when a condition or a step asks and the camera has a
frame it has not seen yet, and no more often than its rate (:class:`VisionRates`): the QR reader, at tens
of milliseconds a frame, reads twice a second; the others every frame they are asked about. Results are
kept per frame, so two conditions on one tick cost one detection.

Frames come from the camera pipeline (:class:`~beastbt.vision.camera_pipeline.CameraPipeline`, its
``latest``), which the run enables at :attr:`VisionRates.frame_rate_hz` when the mission uses these words.
The camera's pose on the robot follows the gimbal (``gimbal()``: pan, tilt in rad as commanded), so a tag
is placed in the base frame wherever the camera looks. Times are the run's clock (s).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Optional

from beastbt.blackboard.types import CameraFrame
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.colour import ColourBlob, ColourFinder, ColourRange
from beastbt.vision.fiducials import DEFAULT_TAG_SIZE_M, FiducialDetector, TagDetection
from beastbt.vision.motion import MotionDetector, MotionResult
from beastbt.vision.qr_codes import QrDetection, QrReader


@dataclass(frozen=True)
class VisionRates:
    """How often each detector may run (Hz of the run's clock) and how old a frame may be (s)."""

    frame_rate_hz: float = 10.0
    """Frames the camera hands to vision while a mission uses it."""
    tags_hz: float = 10.0
    qr_hz: float = 2.0
    motion_hz: float = 10.0
    colour_hz: float = 10.0
    max_age_s: float = 0.5
    """A frame older than this is no answer: the condition is unknown (it does not hold)."""
    motion_gap_s: float = 1.0
    """Motion not looked at for this long forgets its background (the robot may have moved meanwhile)."""


@dataclass
class PhotoLog:
    """The run's photos (``{name, time_s, file, size_px}``) for the summary, and how many alerts took one."""

    photos: list[dict[str, Any]] = field(default_factory=list)
    alert_photos: int = 0


@dataclass
class _Kept:
    """One detector's newest answer: for which frame, when it ran, and what it found."""

    seq: int = -1
    ran_s: float = float("-inf")
    value: Any = None


@dataclass
class VisionWatch:
    """The detectors on the camera's newest frame (see the module docstring).

    ``latest``: the camera's newest frame, or None; ``geometry``: the camera's mounting at pan 0, tilt 0;
    ``gimbal``: the gimbal's (pan, tilt) now (rad, pan left, tilt up).
    """

    latest: Callable[[], Optional[CameraFrame]]
    geometry: CameraGeometry
    gimbal: Callable[[], tuple[float, float]] = lambda: (0.0, 0.0)
    rates: VisionRates = field(default_factory=VisionRates)
    tag_sizes_m: dict[int, float] = field(default_factory=dict)
    """Tag id -> side of its black square (m), from the mission's dock steps; others are DEFAULT_TAG_SIZE_M."""
    log: PhotoLog = field(default_factory=PhotoLog)
    docks: list[dict[str, Any]] = field(default_factory=list)
    """Each dock step's end: tag, status, retries, estimated ``error_m``/``error_deg`` (and ``truth`` in the sim)."""
    background_qr: bool = False
    """Read QR codes on a worker thread (the robot) instead of the calling one (the simulator, in lockstep)."""
    on_dock: Optional[Callable[[dict[str, Any]], None]] = None
    """Told each dock entry as it is made (the simulator adds the true pose error)."""
    runs: dict[str, int] = field(default_factory=dict)
    """How often each detector ran (``tags``, ``qr``, ``motion``, ``colour``): the summary's ``vision.detections``."""
    listeners: list[Callable[[str, CameraFrame, Any], None]] = field(default_factory=list)
    """Told each detector's answer as it is made (its kind key, the frame it looked at, the answer): the views
    of :mod:`beastbt.vision.detection_feed` (the recording, the console)."""

    def __post_init__(self) -> None:
        self._fiducials: dict[tuple[str, ...], FiducialDetector] = {}
        self._qr: Optional[QrReader] = None
        self._motion: Optional[MotionDetector] = None
        self._colour: Optional[ColourFinder] = None
        self._kept: dict[str, _Kept] = {}
        self._motion_seen_s = float("-inf")
        self._motion_gimbal: Optional[tuple[float, float]] = None
        self._qr_pool: Any = None
        self._qr_pending: Any = None
        self._qr_last: Optional[list[QrDetection]] = None
        self._qr_frame: Optional[CameraFrame] = None
        self._camera: Optional[tuple[CameraGeometry, tuple[float, float, int, int], CameraGeometry]] = None
        """The last camera :meth:`camera_now` built: (the mounting it was built from, (pan, tilt, width, height),
        the camera)."""

    # -- frames -----------------------------------------------------------------------
    def frame(self, now_s: float) -> Optional[CameraFrame]:
        """The newest frame when it is fresh (at most ``rates.max_age_s`` old), else None."""
        frame = self.latest()
        if frame is None or frame.image is None or now_s - frame.stamp_s > self.rates.max_age_s:
            return None
        return frame

    def camera_now(self, frame: CameraFrame) -> CameraGeometry:
        """The camera that took ``frame``: its mounting turned by the gimbal, at the frame's size.

        Built again only when the gimbal's pan or tilt, the frame's size or the mounting (``geometry``, with its
        intrinsics: a frozen object, replaced to change) changed since the last call: a build makes the camera's
        matrices (0.1-0.9 ms), and the gimbal mostly stands still between detections."""
        pan, tilt = self.gimbal()
        h, w = frame.image.shape[:2]
        key = (pan, tilt, int(w), int(h))
        kept = self._camera
        if kept is not None and kept[0] is self.geometry and kept[1] == key:
            return kept[2]
        camera = self.geometry.with_pan_tilt(pan, tilt).scaled_to(w, h)
        self._camera = (self.geometry, key, camera)
        return camera

    def _due(self, kind: str, frame: CameraFrame, now_s: float, rate_hz: float) -> Optional[_Kept]:
        """The kept answer of ``kind`` when it is still the answer (same frame, or the rate forbids running)."""
        kept = self._kept.setdefault(kind, _Kept())
        if kept.seq == frame.seq or now_s - kept.ran_s < 1.0 / rate_hz - 1e-9:
            return kept
        return None

    def _keep(self, kind: str, frame: CameraFrame, now_s: float, value: Any) -> Any:
        self._kept[kind] = _Kept(frame.seq, now_s, value)
        self.runs[kind] = self.runs.get(kind, 0) + 1
        for tell in self.listeners:
            tell(kind, frame, value)
        return value

    # -- the detectors ------------------------------------------------------------------
    def tags(self, now_s: float, families: tuple[str, ...] = ("apriltag_36h11",)) -> Optional[list[TagDetection]]:
        """The tags of ``families`` in the newest frame, placed in the base frame; None without a fresh frame."""
        frame = self.frame(now_s)
        if frame is None:
            return None
        key = "tags:" + ",".join(families)
        kept = self._due(key, frame, now_s, self.rates.tags_hz)
        if kept is not None:
            return kept.value
        detector = self._fiducials.get(families)
        if detector is None:
            detector = self._fiducials[families] = FiducialDetector(families, DEFAULT_TAG_SIZE_M, self.tag_sizes_m)
        cam = self.camera_now(frame)
        found = detector.detect(frame.image, cam.camera_matrix, cam.dist_coeffs, cam.camera_from_body)
        return self._keep(key, frame, now_s, found)

    def tag(self, now_s: float, tag_id: int, family: str = "apriltag_36h11") -> Optional[TagDetection]:
        """Tag ``tag_id`` of ``family`` in the newest frame, or None (not seen, or no fresh frame)."""
        for t in self.tags(now_s, (family,)) or []:
            if t.id == tag_id:
                return t
        return None

    def qr_codes(self, now_s: float) -> Optional[list[QrDetection]]:
        """The QR codes read in the newest frame (at most ``rates.qr_hz`` reads a second); None without a frame.

        With ``background_qr`` (the robot: its frames come from a thread too) the reader runs on a worker
        thread of its own, since a read takes tens of milliseconds that the tick loop cannot spare: this
        returns the newest finished read (None before the first), at most one read in flight."""
        frame = self.frame(now_s)
        if frame is None:
            return None
        kept = self._due("qr", frame, now_s, self.rates.qr_hz)
        if kept is not None:
            return kept.value
        if self._qr is None:
            self._qr = QrReader()
        if not self.background_qr:
            return self._keep("qr", frame, now_s, self._qr.read(frame.image))
        if self._qr_pending is not None and self._qr_pending.done():
            self._qr_last = self._qr_pending.result()
            self._qr_pending = None
            if self._qr_frame is not None:
                for tell in self.listeners:
                    tell("qr", self._qr_frame, self._qr_last)
        if self._qr_pending is None:
            if self._qr_pool is None:
                from concurrent.futures import ThreadPoolExecutor
                self._qr_pool = ThreadPoolExecutor(1, thread_name_prefix="beastbt-qr")
            self._qr_pending = self._qr_pool.submit(self._qr.read, frame.image)
            self._qr_frame = frame
            self._kept["qr"] = _Kept(frame.seq, now_s, self._qr_last)
            self.runs["qr"] = self.runs.get("qr", 0) + 1
        return self._qr_last

    def close(self) -> None:
        """Stop the QR reader's worker thread, if one was started."""
        if self._qr_pool is not None:
            self._qr_pool.shutdown(wait=False, cancel_futures=True)
            self._qr_pool = None

    def motion(self, now_s: float, still: bool) -> Optional[MotionResult]:
        """Motion in the newest frame while the robot is ``still`` (its base and its gimbal); None without a frame.

        Looked at after a gap (``rates.motion_gap_s``), or with the gimbal turned since, the background is learnt
        again first."""
        frame = self.frame(now_s)
        if frame is None:
            return None
        gimbal = self.gimbal()
        if now_s - self._motion_seen_s > self.rates.motion_gap_s or gimbal != self._motion_gimbal:
            if self._motion is not None:
                self._motion.reset()
            self._kept.pop("motion", None)
        self._motion_seen_s = now_s
        self._motion_gimbal = gimbal
        kept = self._due("motion", frame, now_s, self.rates.motion_hz)
        if kept is not None and kept.value is not None:
            return kept.value
        if self._motion is None:
            self._motion = MotionDetector()
        return self._keep("motion", frame, now_s, self._motion.process(frame.image, still))

    def colour(self, now_s: float, colour: ColourRange) -> Optional[tuple[Optional[ColourBlob], CameraGeometry]]:
        """The largest blob of ``colour`` in the newest frame (None when there is none) and the camera that saw it;
        None without a fresh frame."""
        frame = self.frame(now_s)
        if frame is None:
            return None
        key = "colour:" + colour.name
        kept = self._due(key, frame, now_s, self.rates.colour_hz)
        if kept is not None:
            return kept.value
        if self._colour is None:
            self._colour = ColourFinder()
        blob = self._colour.find(frame.image, colour)
        return self._keep(key, frame, now_s, (blob, self.camera_now(frame)))


__all__ = ["VisionWatch", "VisionRates", "PhotoLog"]
