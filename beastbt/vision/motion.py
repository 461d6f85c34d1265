"""Motion in front of a robot that stands still: OpenCV's MOG2 background subtraction with an area threshold.

:class:`MotionDetector` keeps a background model (``cv2.createBackgroundSubtractorMOG2``)
of small grey frames (``work_width_px`` wide: motion of a person needs no detail, and a small frame
costs a fraction of a millisecond). A frame taken while the robot moves (``still`` False) throws the
model away: the whole picture moves then, and a model learnt from one place says nothing about the
next. After ``warmup_frames`` still frames the model knows the scene, and motion is reported when the
moving foreground (shadows left out, specks opened away) covers at least ``min_area_frac`` of the frame.
Nothing here touches devices, the clock or the blackboard.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np


@dataclass(frozen=True)
class MotionResult:
    """What one frame showed: ``area_frac`` of the frame moving (0-1), ``box_px`` around the largest moving
    region (x, y, w, h in the frame's own pixels) or None, and ``moving`` (the area reached the threshold
    once the model was warm)."""

    area_frac: float
    box_px: Optional[tuple[int, int, int, int]]
    moving: bool
    warm: bool


class MotionDetector:
    """MOG2 on small grey frames while the robot stands still (see the module docstring).

    ``min_area_frac``: the moving share of the frame that counts as motion (0.005 = 0.5 %: a person
    walking 5 m away at 62 deg of view). ``var_threshold``: MOG2's squared-distance threshold (grey
    levels squared; 25 keeps sensor noise out).
    """

    def __init__(self, min_area_frac: float = 0.005, work_width_px: int = 160, warmup_frames: int = 8,
                 history: int = 100, var_threshold: float = 25.0) -> None:
        if not 0.0 < min_area_frac < 1.0:
            raise ValueError(f"min_area_frac must be in (0, 1), got {min_area_frac}")
        self.min_area_frac = float(min_area_frac)
        self.work_width_px = int(work_width_px)
        self.warmup_frames = int(warmup_frames)
        self.history = int(history)
        self.var_threshold = float(var_threshold)
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        self._model: Optional[cv2.BackgroundSubtractorMOG2] = None
        self.still_frames = 0
        """Frames learnt since the model was last thrown away."""

    def reset(self) -> None:
        """Forget the background (the robot moved): motion is reported again after the warm-up."""
        self._model = None
        self.still_frames = 0

    def process(self, image: np.ndarray, still: bool = True) -> MotionResult:
        """Learn ``image`` (BGR or grey) into the model and say how much of it moves; ``still`` False resets."""
        if not still:
            self.reset()
            return MotionResult(0.0, None, False, False)
        h, w = image.shape[:2]
        scale = min(1.0, self.work_width_px / w)
        small = cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA) \
            if scale < 1.0 else image
        grey = small if small.ndim == 2 else cv2.cvtColor(small, cv2.COLOR_BGR2GRAY)
        grey = cv2.GaussianBlur(grey, (3, 3), 0)
        if self._model is None:
            self._model = cv2.createBackgroundSubtractorMOG2(self.history, self.var_threshold, False)
        # Learn fast while warming up (the first frames are all there is), then at the model's own pace.
        rate = 1.0 / (self.still_frames + 1) if self.still_frames < self.warmup_frames else -1.0
        mask = self._model.apply(grey, learningRate=rate)
        self.still_frames += 1
        warm = self.still_frames > self.warmup_frames
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        moving = int(cv2.countNonZero(mask))
        area = moving / float(mask.size)
        box = None
        if moving:
            x, y, bw, bh = cv2.boundingRect(mask)
            box = (int(x / scale), int(y / scale), int(bw / scale), int(bh / scale))
        return MotionResult(area, box, warm and area >= self.min_area_frac, warm)


__all__ = ["MotionDetector", "MotionResult"]
