"""What the detectors answered the mission, recorded (``/vision/answers``) and given back by ``beastbt replay``.

A recording keeps camera images as JPEG, a few a second (``--record-images``), while the
detectors of :class:`~beastbt.vision.watch.VisionWatch` looked at every frame the camera gave
vision (10 a second), uncompressed, and motion's background model grew from all of them. Run on the
recorded images, the detectors would answer differently and a replay would not do what the run did.
So each detector run's answer is recorded as it is made, with the frame it looked at:

* :class:`AnswerTap` (the recording side) wraps one run's watch: every answer a detector gives
  (``VisionWatch._keep``: its kind key such as ``tags:apriltag_36h11``, ``qr``, ``motion``,
  ``colour:red``), with the frame's ``seq``, ``stamp_s`` and size, the run's clock time, and for motion
  whether the robot stood still. The recorder takes them each tick; the writer turns each into a
  ``/vision/answers`` message (:func:`~beastbt.vision.answer_messages.answer_message`), every float exactly
  (JSON keeps them).
* :class:`ReplayVisionWatch` (the replay side) is a watch whose detectors are stand-ins: asked about a frame,
  a stand-in gives the recorded answer of that kind for that frame (:class:`RecordedAnswers`); only when
  the recording holds none (a changed mission asks something the run never asked, or a recording made
  before answers were kept) does it run the real detector, on the recorded image (the newest JPEG the
  recording kept, or grey), and count it (:attr:`ReplayVisionWatch.computed`): the replay's notes say so.

Everything else (which frame is fresh, each detector's rate, the gimbal turning the camera, a dock's
tag sizes) is the watch's own code, run again on the recorded frames' numbers and stamps.

On the robot the camera is read in a thread, so a detector may look at a frame the tick loop has not
handed over yet: :meth:`RecordedAnswers.newest_frame` lets the replay's watch see that frame at the tick
it was looked at. A QR code read on the robot's worker thread (``background_qr``) is not a detector run
of the watch's own and is not recorded: a replay reads the QR codes of those runs again on the recorded
images.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from beastbt.blackboard.types import CameraFrame
from beastbt.vision.colour import ColourBlob, ColourFinder, ColourRange
from beastbt.vision.fiducials import DEFAULT_TAG_SIZE_M, FiducialDetector, TagDetection
from beastbt.vision.motion import MotionDetector, MotionResult
from beastbt.vision.qr_codes import QrDetection, QrReader
from beastbt.vision.answer_messages import TOPIC, Answer
from beastbt.vision.watch import VisionWatch


# -- back from JSON ---------------------------------------------------------------------------------


def _from_array(d: dict) -> np.ndarray:
    return np.asarray(d["data"], dtype=np.dtype(d["dtype"]))


def value_of(kind: str, data: Any) -> Any:
    """The detector's answer back from :func:`~beastbt.vision.answer_messages.value_json`'s data (the same classes,
    arrays and floats)."""
    if data is None:
        return None
    if kind.startswith("tags:"):
        return [TagDetection(t["family"], int(t["id"]), _from_array(t["corners_px"]), float(t["size_m"]),
                             _from_array(t["rvec"]), _from_array(t["tvec_m"]),
                             None if t["position_m"] is None else tuple(float(v) for v in t["position_m"]),
                             None if t["facing_rad"] is None else float(t["facing_rad"])) for t in data]
    if kind == "qr":
        return [QrDetection(q["text"], _from_array(q["corners_px"])) for q in data]
    if kind == "motion":
        box = data["box_px"]
        return MotionResult(float(data["area_frac"]), None if box is None else tuple(int(v) for v in box),
                            bool(data["moving"]), bool(data["warm"]))
    if kind.startswith("colour:"):
        centre = tuple(float(v) for v in data["centre_px"])
        return ColourBlob(float(data["area_frac"]), centre, tuple(int(v) for v in data["box_px"]))  # type: ignore
    raise ValueError(f"unknown detector kind {kind!r}")


# -- the recording side -------------------------------------------------------------------------


class AnswerTap:
    """Keeps every answer one run's :class:`VisionWatch` makes, until :meth:`take` (the recorder, each tick).

    It wraps the watch's ``_keep`` (where each detector run's answer is kept) and ``motion`` (to know
    whether the robot stood still), the way the recorder wraps the run's servo sender: the watch does not
    know it is recorded, and a run that records nothing pays nothing.
    """

    def __init__(self) -> None:
        self.pending: list[Answer] = []
        self._still: Optional[bool] = None

    @classmethod
    def attach(cls, watch: VisionWatch) -> "AnswerTap":
        """A tap told every answer of ``watch``."""
        tap = cls()
        keep, motion = watch._keep, watch.motion

        def keep_and_tell(kind: str, frame: CameraFrame, now_s: float, value: Any) -> Any:
            out = keep(kind, frame, now_s, value)
            tap.on_answer(kind, frame, now_s, value)
            return out

        def motion_noting_still(now_s: float, still: bool) -> Optional[MotionResult]:
            tap._still = bool(still)
            return motion(now_s, still)

        watch._keep = keep_and_tell  # type: ignore[method-assign]
        watch.motion = motion_noting_still  # type: ignore[method-assign]
        return tap

    def on_answer(self, kind: str, frame: CameraFrame, now_s: float, value: Any) -> None:
        """Note one answer (colour's ``(blob, camera)``: the blob; the camera is the gimbal's, given again)."""
        if kind.startswith("colour:") and value is not None:
            value = value[0]
        shape = frame.image.shape
        self.pending.append(Answer(float(now_s), kind, int(frame.seq), float(frame.stamp_s),
                                   (int(shape[1]), int(shape[0])), self._still if kind == "motion" else None, value))

    def take(self) -> list[Answer]:
        """The answers made since the last call, oldest first."""
        out, self.pending = self.pending, []
        return out


# -- the replay side -----------------------------------------------------------------------------

_MISSING = object()


class RecordedAnswers:
    """The ``/vision/answers`` of a recording, by detector kind and frame (see the module docstring)."""

    def __init__(self, messages: list[dict]) -> None:
        self.by_frame: dict[tuple[str, int], deque[dict]] = {}
        self.kinds: set[str] = set()
        self.frames: list[tuple[float, int, float, tuple[int, int]]] = []
        """(clock time of the tick, seq, stamp, size) of each frame a detector looked at, in time order."""
        for m in messages:
            self.by_frame.setdefault((m["kind"], int(m["seq"])), deque()).append(m)
            self.kinds.add(m["kind"])
            self.frames.append((float(m["now_s"]), int(m["seq"]), float(m["stamp_s"]),
                                (int(m["size"][0]), int(m["size"][1]))))
        self.frames.sort(key=lambda f: (f[0], f[1]))
        self.count = len(messages)
        self.given = 0
        """Answers given back so far."""
        self._next = 0
        self._newest: Optional[tuple[float, int, float, tuple[int, int]]] = None

    def take(self, kind: str, seq: int, still: Optional[bool] = None) -> Any:
        """The next recorded answer of ``kind`` about frame ``seq`` (for motion: made with the same ``still``), or
        ``_MISSING``; each is given once (motion's model may answer twice about one frame after a reset)."""
        kept = self.by_frame.get((kind, seq))
        if not kept:
            return _MISSING
        for i, m in enumerate(kept):
            if still is None or m.get("still") is None or bool(m["still"]) == still:
                del kept[i]
                self.given += 1
                return value_of(kind, m["value"])
        return _MISSING

    def newest_frame(self, now_s: float) -> Optional[tuple[int, float, tuple[int, int]]]:
        """The newest frame (seq, stamp s, size) a detector had looked at by clock time ``now_s``, or None."""
        frames = self.frames
        while self._next < len(frames) and frames[self._next][0] <= now_s + 1e-9:
            f = frames[self._next]
            if self._newest is None or f[1] > self._newest[1]:
                self._newest = f
            self._next += 1
        return None if self._newest is None else self._newest[1:]


class _Detectors:
    """The stand-ins' shared state: the recorded answers, the real detectors built when one is missing."""

    def __init__(self, watch: "ReplayVisionWatch") -> None:
        self.watch = watch

    def answer(self, kind: str, compute: Callable[[], Any], still: Optional[bool] = None) -> Any:
        watch = self.watch
        frame = watch.looking_at
        if watch.answers is not None and frame is not None:
            got = watch.answers.take(kind, frame.seq, still)
            if got is not _MISSING:
                return got
        watch.computed[kind] = watch.computed.get(kind, 0) + 1
        return compute()


class _RecordedFiducials:
    """Stands in for a :class:`FiducialDetector` of ``families``."""

    def __init__(self, shared: _Detectors, families: tuple[str, ...]) -> None:
        self.shared, self.families = shared, families
        self.real: Optional[FiducialDetector] = None

    def detect(self, image: np.ndarray, camera_matrix: Any = None, dist_coeffs: Any = None,
               camera_from_body: Any = None) -> list[TagDetection]:
        def compute() -> list[TagDetection]:
            if self.real is None:
                self.real = FiducialDetector(self.families, DEFAULT_TAG_SIZE_M, self.shared.watch.tag_sizes_m)
            return self.real.detect(image, camera_matrix, dist_coeffs, camera_from_body)
        return self.shared.answer("tags:" + ",".join(self.families), compute)


class _FiducialsByFamilies(dict):
    """The watch's detectors by families: a stand-in for any families asked (``dict.get`` builds it)."""

    def __init__(self, shared: _Detectors) -> None:
        super().__init__()
        self.shared = shared

    def get(self, families: Any, default: Any = None) -> Any:  # type: ignore[override]
        if families not in self:
            self[families] = _RecordedFiducials(self.shared, tuple(families))
        return self[families]


class _RecordedQr:
    """Stands in for a :class:`QrReader`."""

    def __init__(self, shared: _Detectors) -> None:
        self.shared = shared
        self.real: Optional[QrReader] = None

    def read(self, image: np.ndarray) -> list[QrDetection]:
        def compute() -> list[QrDetection]:
            if self.real is None:
                self.real = QrReader()
            return self.real.read(image)
        return self.shared.answer("qr", compute)


class _RecordedMotion:
    """Stands in for a :class:`MotionDetector` (a real one learns from the frames it computes on)."""

    def __init__(self, shared: _Detectors) -> None:
        self.shared, self.real = shared, MotionDetector()

    def reset(self) -> None:
        self.real.reset()

    def process(self, image: np.ndarray, still: bool = True) -> MotionResult:
        return self.shared.answer("motion", lambda: self.real.process(image, still), bool(still))


class _RecordedColour:
    """Stands in for a :class:`ColourFinder`."""

    def __init__(self, shared: _Detectors) -> None:
        self.shared, self.real = shared, ColourFinder()

    def find(self, image: np.ndarray, colour: ColourRange, hsv: Any = None) -> Optional[ColourBlob]:
        return self.shared.answer("colour:" + colour.name, lambda: self.real.find(image, colour, hsv))


@dataclass
class ReplayVisionWatch(VisionWatch):
    """A :class:`VisionWatch` for ``beastbt replay``: its detectors give the recorded answers (see the module
    docstring); ``answers`` None: a recording without them, every detector runs on the recorded images."""

    answers: Optional[RecordedAnswers] = None

    def __post_init__(self) -> None:
        super().__post_init__()
        self.looking_at: Optional[CameraFrame] = None
        """The frame the watch is looking at now (what a stand-in is asked about)."""
        self.computed: dict[str, int] = {}
        """Kind key -> answers not in the recording, computed again on the recorded images."""
        shared = _Detectors(self)
        self._fiducials = _FiducialsByFamilies(shared)  # type: ignore[assignment]
        self._qr = _RecordedQr(shared)  # type: ignore[assignment]
        self._motion = _RecordedMotion(shared)  # type: ignore[assignment]
        self._colour = _RecordedColour(shared)  # type: ignore[assignment]

    def frame(self, now_s: float) -> Optional[CameraFrame]:
        """The newest fresh frame, as :meth:`VisionWatch.frame`; remembered for the stand-ins."""
        self.looking_at = super().frame(now_s)
        return self.looking_at


def replay_frames(handed: Callable[[], Optional[CameraFrame]], now: Callable[[], float],
                  answers: Optional[RecordedAnswers]) -> Callable[[], Optional[CameraFrame]]:
    """The replay's ``latest``: the newest frame the replay handed over (``handed``), or, when a detector had
    looked at a newer one by now (the robot's camera thread), that frame (its picture the newest handed one's, or
    grey at its size)."""
    made: dict[int, CameraFrame] = {}

    def latest() -> Optional[CameraFrame]:
        frame = handed()
        newer = answers.newest_frame(now()) if answers is not None else None
        if newer is None or (frame is not None and frame.seq >= newer[0]):
            return frame
        seq, stamp_s, (w, h) = newer
        if seq not in made:
            image = frame.image if frame is not None and frame.image.shape[:2] == (h, w) else \
                np.full((h, w, 3), 128, np.uint8)
            made.clear()
            made[seq] = CameraFrame(stamp_s, image, seq)
        return made[seq]
    return latest


__all__ = ["AnswerTap", "Answer", "RecordedAnswers", "ReplayVisionWatch", "replay_frames", "value_of", "TOPIC"]
