"""The camera and the line detector as one sensor of the tick loop: frames and line observations.

:class:`CameraPipeline` owns a :class:`~beastbt.devices.camera.Camera` driver
(reading a ``cv2.VideoCapture`` on the robot, a
:class:`~beastbt.sim.camera_emulator.SimCamera` in the simulator) and a
:class:`~beastbt.vision.line_detector.LineDetector` built from the profile's
``camera:`` mounting and ``line_detector:`` section. Each new frame is run
through the detector; the tick loop's sensor poll (:meth:`CameraPipeline.poll`)
returns the new :class:`~beastbt.blackboard.types.CameraFrame` and its
:class:`~beastbt.blackboard.types.LineObservation`, which the runner publishes
as the blackboard keys ``camera_frame`` and ``line``.

Two ways to run it:

* **In lockstep** (the simulator): :meth:`poll` reads the camera itself, at
  the camera's frame rate by the simulated clock. A simulated camera only
  renders while the pipeline is *enabled* (:meth:`enable`): the run enables it
  when the mission uses the camera (``follow_line``, ``snapshot``, the
  ``intersection``/``line_seen`` conditions) or when video is streamed, so a
  mission that never looks costs nothing; a recording that keeps a few
  images a second enables it at that rate (:meth:`enable`'s ``max_rate_hz``).
* **In a thread** (the robot, :meth:`start_thread`): ``VideoCapture.read``
  blocks for up to a frame period, so a daemon thread reads and detects, and
  :meth:`poll` only hands over the newest result.

:attr:`CameraPipeline.latest` is the newest ``(frame, detection)`` pair, for
the video stream's overlay.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Callable, Optional

import numpy as np

from beastbt.blackboard.types import CameraFrame
from beastbt.devices.camera import Camera, CameraConfig
from beastbt.devices.interfaces import EventSink, ignore_events
from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.line_detector import LineDetection, LineDetector, LineDetectorConfig

Latest = tuple[CameraFrame, Optional[LineDetection]]

LINE_REASONS = frozenset({"follow_line", "intersection", "line_seen"})
"""Reasons whose frames only the line detector looks at (their JPEG may be decoded smaller)."""


class CameraPipeline:
    """A camera read frame by frame with the line detector run on every frame.

    ``make_camera`` builds the :class:`Camera` driver (called once, on the
    first :meth:`enable`, so that a simulated camera and its floor are only
    built when needed). ``detect`` False skips the line detector (frames only).
    """

    def __init__(self, make_camera: Callable[[], Camera], camera_config: CameraConfig,
                 detector_config: Optional[LineDetectorConfig] = None, events: EventSink = ignore_events,
                 detect: bool = True) -> None:
        self.config = camera_config
        self.geometry = CameraGeometry.from_config(camera_config)
        """The camera as the detector sees it (its mounting, with the gimbal at pan 0, tilt 0)."""
        self.detector = LineDetector(detector_config or LineDetectorConfig(), self.geometry)
        self.detect_lines = detect
        self.events = events
        self._make_camera = make_camera
        self.camera: Optional[Camera] = None
        self.enabled = False
        """True once something asked for frames (a mission that uses the camera, the video stream)."""
        self.threaded = False
        """Read in a thread of its own once enabled (the robot); False: :meth:`poll` reads (the simulator)."""
        self.reasons: list[str] = []
        """Why the pipeline was enabled (``follow_line``, ``stream``...), first reason first."""
        self.rate_limits: dict[str, Optional[float]] = {}
        """Reason -> the frames per second it needs (None: every frame the camera gives)."""
        self.pictures_only: set[str] = set()
        """Reasons that need the frames but not the line detector's observations (the recording)."""
        self.jpeg_only: set[str] = set()
        """Reasons that need the camera's own JPEG only, no pixels (the console's video on the robot)."""
        self.latest_jpeg: Optional[CameraFrame] = None
        """The newest frame that came as the camera's own JPEG (``jpeg`` set; ``image`` None when not decoded)."""
        self.jpeg_frames = 0
        """Frames that came as the camera's own JPEG."""
        self.h264_units: deque[CameraFrame] = deque(maxlen=64)
        """The camera's own H.264 frames (``h264`` set) not yet taken by the console, oldest first: a viewer needs
        every one in order (the console's link drains it)."""
        self.decoded = 0
        """JPEG frames decoded for vision or the recording."""
        self._next_frame_s = float("-inf")
        self.latest: Optional[Latest] = None
        """The newest frame and what the detector found in it (None before the first frame)."""
        self.frames = 0
        """Frames read so far."""
        self.detect_errors = 0
        self._lock = threading.Lock()
        self._handed_seq = 0
        self._thread: Optional[threading.Thread] = None
        self._idle_wait_s = 0.005
        self._stop = threading.Event()

    # -- switching on ---------------------------------------------------------------
    @property
    def lookahead_m(self) -> float:
        """Distance ahead of the robot centre at which the detector reports the line's offset (m)."""
        return self.detector.config.lookahead_m

    def check(self) -> None:
        """Raise ``ValueError`` when the mounting shows the detector too little floor (before anything moves)."""
        blank = np.full((self.config.height_px, self.config.width_px, 3), 128, np.uint8)
        self.detector.detect(blank, 0.0)
        self.detector.reset()
        self.detector.last = None

    def enable(self, reason: str, max_rate_hz: Optional[float] = None, lines: bool = True,
               pixels: bool = True) -> None:
        """Start reading frames (builds the camera on first use); ``reason`` is kept for the log.

        ``max_rate_hz``: the frames per clock second this reason needs (the recording keeps a few), None
        for every frame. While every reason has a rate, frames come at the highest: a simulated camera
        renders only those, and on the robot the others are read and dropped. ``lines`` False: this
        reason needs the pictures only; while no reason needs lines, the line detector does not run.
        ``pixels`` False: this reason needs the camera's own JPEG only (:attr:`latest_jpeg`): while no reason
        needs pixels, a camera that gives JPEG is read but nothing is decoded.
        """
        if reason not in self.reasons:
            self.reasons.append(reason)
        self.rate_limits[reason] = max_rate_hz if max_rate_hz is None or max_rate_hz > 0 else None
        if not lines:
            self.pictures_only.add(reason)
        else:
            self.pictures_only.discard(reason)
        if not pixels:
            self.jpeg_only.add(reason)
        else:
            self.jpeg_only.discard(reason)
        if self.enabled:
            return
        self.enabled = True
        if self.camera is None:
            self.camera = self._make_camera()
        if self.threaded:
            self._start_reader()

    def disable(self, reason: str) -> None:
        """``reason`` no longer needs frames; with no reason left the camera is not read (it stays open)."""
        if reason in self.reasons:
            self.reasons.remove(reason)
        self.rate_limits.pop(reason, None)
        self.pictures_only.discard(reason)
        self.jpeg_only.discard(reason)
        if not self.reasons:
            self.enabled = False

    @property
    def pixel_reasons(self) -> list[str]:
        """The reasons that need decoded pixels (vision, the recording), not the camera's JPEG alone."""
        return [r for r in self.reasons if r not in self.jpeg_only]

    @property
    def frame_period_s(self) -> Optional[float]:
        """Seconds between the frames with pixels the reasons need (None: every frame the camera gives)."""
        rates = [self.rate_limits.get(r) for r in self.pixel_reasons]
        if not rates or any(r is None for r in rates):
            return None
        return 1.0 / max(rates)  # type: ignore[type-var, arg-type]

    @property
    def decode_reduction(self) -> int:
        """1, 2, 4 or 8: how much smaller a JPEG frame is decoded. Only the line detector needs its pixels:
        decoded no wider than it works (``process_width_px``, libjpeg scales while decoding); else full size."""
        reasons = self.pixel_reasons
        work_w = self.detector.config.process_width_px
        if not reasons or not work_w or any(r not in LINE_REASONS for r in reasons):
            return 1
        reduction = 1
        while reduction < 8 and self.config.width_px // (2 * reduction) >= work_w:
            reduction *= 2
        return reduction

    def read_for_viewer(self) -> Optional[CameraFrame]:
        """The newest frame with the camera's own JPEG for a viewer (the tick thread, in lockstep): read one now
        when nothing else reads the camera (builds it on first use), so that a camera nobody else needs is read
        only as often as someone watches. None from a camera that gives pixels, or before any frame."""
        if self._thread is None and not self.enabled:
            if self.camera is None:
                self.camera = self._make_camera()
            frame = self.camera.poll(pixels=False)
            if frame is not None:
                self._keep_compressed(frame)
        return self.latest_jpeg

    def _keep_compressed(self, frame: CameraFrame) -> None:
        """Keep a frame's camera-compressed bytes for the viewers: the newest JPEG, or the H.264 unit in order."""
        if frame.jpeg is not None:
            self.latest_jpeg = frame
            self.jpeg_frames += 1
        elif frame.h264 is not None:
            self.h264_units.append(frame)

    def reset_detector(self) -> None:
        """Forget where the line was (a new follow_line step starts looking straight ahead)."""
        with self._lock:
            self.detector.reset()

    # -- the tick loop's sensor poll -------------------------------------------------------
    def poll(self, now_s: float) -> list:
        """The new frame and its line observation since the last call (``[]`` when none); never raises.

        Between the frames the reasons need, the camera is read only when a reason takes every JPEG (the
        console): a simulated camera then renders only what someone needs."""
        if not self.enabled:
            return []
        if self._thread is None and (now_s >= self._next_frame_s - 1e-9 or self.jpeg_only):
            self._read_one()
        if not self.pixel_reasons:
            return []  # frames read for a viewer alone are not the run's readings
        latest = self.latest
        if latest is None or latest[0].seq == self._handed_seq:
            return []
        frame, detection = latest
        self._handed_seq = frame.seq
        return [frame] if detection is None else [frame, detection.observation]

    def _read_one(self) -> bool:
        """Read the camera once (it decides whether a frame is due) and detect; True when a frame came."""
        camera = self.camera
        if camera is None:
            return False
        # A camera's own JPEG is decoded below, and only when needed. An H.264 camera's units are decoded as they
        # are read while a reason needs pixels: each picture needs the one before it.
        frame = camera.poll(pixels=camera.h264 and bool(self.pixel_reasons))
        if frame is None:
            return False
        self._keep_compressed(frame)
        if not self.pixel_reasons:
            if frame.image is not None:  # a camera that gives pixels: they are all a viewer can have
                self.latest = (frame, None)
            return True
        period = self.frame_period_s
        if period is not None:
            if frame.stamp_s < self._next_frame_s - 1e-9:
                return False  # read (a real camera's buffer is drained) but not needed
            # Whole periods from the last due time, as the recorder keeps its images: each frame is one it keeps.
            late = frame.stamp_s - self._next_frame_s
            self._next_frame_s = self._next_frame_s + period if late < period else frame.stamp_s + period
        else:
            self._next_frame_s = float("-inf")
        if frame.image is None:
            decoded = camera.decode(frame, self.decode_reduction)
            if decoded is None:
                return False
            frame = decoded
            self.decoded += 1
        detection: Optional[LineDetection] = None
        if self.detect_lines and any(r not in self.pictures_only for r in self.pixel_reasons):
            with self._lock:
                try:
                    detection = self.detector.detect_full(frame.image, frame.stamp_s)
                except Exception as exc:  # a detector fault degrades the line data, never the loop
                    self.detect_errors += 1
                    if self.detect_errors == 1 or self.detect_errors % 100 == 0:
                        self.events("line_detector_error", f"line detector failed ({self.detect_errors} so far): {exc!r}")
        self.frames += 1
        self.latest = (frame, detection)
        return True

    # -- the robot: a thread of its own -------------------------------------------------------
    def start_thread(self, idle_wait_s: float = 0.005) -> None:
        """Read and detect in a daemon thread (the robot); :meth:`poll` then hands over its newest result.

        ``Camera.poll`` returns at once when no frame is due; the thread then
        waits ``idle_wait_s`` (s) on its stop event instead of spinning.
        """
        self._idle_wait_s = idle_wait_s
        self.threaded = True
        if self.enabled:
            self._start_reader()
        else:
            self.enable("robot")

    def _start_reader(self) -> None:
        if self._thread is not None or self._stop.is_set():
            return
        idle_wait_s = self._idle_wait_s

        def loop() -> None:
            while not self._stop.is_set():
                if not self.enabled:  # nothing needs frames now (the console's viewers left): read none
                    self._stop.wait(0.05)
                    continue
                try:
                    got = self._read_one()
                except Exception as exc:  # Camera.poll never raises; this is the last guard of the thread
                    self.events("camera_error", f"camera thread: {exc!r}")
                    got = False
                if not got:
                    self._stop.wait(idle_wait_s)

        self._thread = threading.Thread(target=loop, name="beastbt-camera", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the thread (if any) and release the camera."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)
        if self.camera is not None:
            self.camera.close()


__all__ = ["CameraPipeline", "Latest"]
