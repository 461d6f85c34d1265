"""Coloured things: the largest blob of a colour range in a frame, its bearing and its share of the picture.

A :class:`ColourRange` is one of the named colours (:data:`NAMED_COLOURS`: ``red``,
``green``, ``blue``, ``yellow``) or ``{hsv: [[h, s, v], [h, s, v]]}`` (low and high
corners in OpenCV's HSV: hue 0-179, saturation and value 0-255; a low hue above the
high one wraps through red). :class:`ColourFinder` thresholds a small copy of the
frame (``work_width_px`` wide) with ``cv2.inRange`` and takes the largest connected
blob. Nothing here touches devices, the clock or the blackboard.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import cv2
import numpy as np

HsvBox = tuple[tuple[int, int, int], tuple[int, int, int]]

NAMED_COLOURS: dict[str, tuple[HsvBox, ...]] = {
    # Saturation and value floors keep grey floors, white walls and shadows out.
    "red": (((0, 110, 60), (8, 255, 255)), ((172, 110, 60), (179, 255, 255))),
    "yellow": (((20, 110, 90), (34, 255, 255)),),
    "green": (((42, 90, 50), (86, 255, 255)),),
    "blue": (((98, 110, 50), (128, 255, 255)),),
}
"""The colours a mission names and their HSV boxes (OpenCV scale); red straddles hue 0."""


@dataclass(frozen=True)
class ColourRange:
    """A colour as HSV boxes (any pixel inside one of them counts); ``name`` is how the mission wrote it."""

    name: str
    boxes: tuple[HsvBox, ...]

    @classmethod
    def parse(cls, value: Any) -> "ColourRange":
        """A named colour, ``{hsv: [[h, s, v], [h, s, v]]}`` or the two corners as a tuple; ``ValueError`` says what
        is wrong."""
        if isinstance(value, str):
            if value not in NAMED_COLOURS:
                raise ValueError(f"unknown colour {value!r}: one of {', '.join(NAMED_COLOURS)} or {{hsv: [[h, s, v], "
                                 "[h, s, v]]}")
            return cls(value, NAMED_COLOURS[value])
        if isinstance(value, tuple) and len(value) == 2:  # the two corners alone, as a mission's typed value keeps them
            value = {"hsv": value}
        if isinstance(value, dict) and "hsv" in value:
            try:
                lo, hi = value["hsv"]
                lo = tuple(int(x) for x in lo)
                hi = tuple(int(x) for x in hi)
            except (TypeError, ValueError):  # not two lists of numbers: say the shape, not Python's words
                lo = hi = ()
            if len(lo) != 3 or len(hi) != 3:
                raise ValueError("hsv needs two [h, s, v] triples: [[h, s, v], [h, s, v]]")
            for a, b, top in zip(lo, hi, (179, 255, 255)):
                if not (0 <= a <= top and 0 <= b <= top):
                    raise ValueError(f"hsv values must be hue 0-179, saturation and value 0-255, got {lo} {hi}")
            if lo[0] > hi[0]:  # a hue range through red: two boxes
                boxes: tuple[HsvBox, ...] = ((lo, (179, hi[1], hi[2])), ((0, lo[1], lo[2]), hi))  # type: ignore[assignment]
            else:
                boxes = ((lo, hi),)  # type: ignore[assignment]
            return cls(f"hsv {list(lo)}-{list(hi)}", boxes)
        raise ValueError(f"a colour is a name ({', '.join(NAMED_COLOURS)}) or {{hsv: [[h, s, v], [h, s, v]]}}, "
                         f"got {value!r}")


@dataclass(frozen=True)
class ColourBlob:
    """The largest blob of a colour: ``area_frac`` of the frame (0-1), ``centre_px`` and ``box_px`` (x, y, w, h)
    in the frame's own pixels."""

    area_frac: float
    centre_px: tuple[float, float]
    box_px: tuple[int, int, int, int]

    def bearing_rad(self, camera_matrix: np.ndarray) -> float:
        """Direction of the blob off the optical axis (rad, positive left) for a camera with ``camera_matrix``."""
        return -math.atan2(self.centre_px[0] - camera_matrix[0, 2], camera_matrix[0, 0])


class ColourFinder:
    """Finds the largest blob of a :class:`ColourRange` in a frame (see the module docstring)."""

    def __init__(self, work_width_px: int = 160) -> None:
        self.work_width_px = int(work_width_px)
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))

    def hsv(self, image: np.ndarray) -> tuple[np.ndarray, float]:
        """The frame reduced to the working width and turned to HSV, and the scale used (work px per image px)."""
        h, w = image.shape[:2]
        scale = min(1.0, self.work_width_px / w)
        small = cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA) \
            if scale < 1.0 else image
        return cv2.cvtColor(small, cv2.COLOR_BGR2HSV), scale

    def find(self, image: np.ndarray, colour: ColourRange, hsv: Optional[tuple[np.ndarray, float]] = None
             ) -> Optional[ColourBlob]:
        """The largest blob of ``colour`` in ``image`` (BGR), or None; ``hsv`` reuses :meth:`hsv` of the same frame."""
        small, scale = hsv if hsv is not None else self.hsv(image)
        mask = None
        for lo, hi in colour.boxes:
            part = cv2.inRange(small, np.array(lo, np.uint8), np.array(hi, np.uint8))
            mask = part if mask is None else cv2.bitwise_or(mask, part)
        assert mask is not None
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        n, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        if n <= 1:
            return None
        best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        x, y, bw, bh, area = (int(v) for v in stats[best])
        cu, cv_ = centroids[best]
        inv = 1.0 / scale
        # centroids are in the small frame's pixel centres: back to the full frame's
        return ColourBlob(area / float(mask.size), ((cu + 0.5) * inv - 0.5, (cv_ + 0.5) * inv - 0.5),
                          (int(x * inv), int(y * inv), int(math.ceil(bw * inv)), int(math.ceil(bh * inv))))


__all__ = ["ColourBlob", "ColourFinder", "ColourRange", "NAMED_COLOURS"]
