"""QR codes: the text of every QR code a frame shows, and where it is.

:class:`QrReader` wraps OpenCV's ``cv2.QRCodeDetector`` (``detectAndDecodeMulti``).
A code whose corners are found but whose text cannot be read is left out: a
mission asks for a text. Nothing here touches devices, the clock or the blackboard.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np


@dataclass(frozen=True)
class QrDetection:
    """One QR code read in a frame: its ``text`` and its four corners (4, 2) px in the image."""

    text: str
    corners_px: np.ndarray

    @property
    def centre_px(self) -> tuple[float, float]:
        """The code's centre in the image (u, v px)."""
        c = self.corners_px.mean(axis=0)
        return float(c[0]), float(c[1])

    def bearing_rad(self, camera_matrix: np.ndarray) -> float:
        """Direction of the code off the optical axis (rad, positive left) for a camera with ``camera_matrix``."""
        u = self.centre_px[0]
        return -math.atan2(u - camera_matrix[0, 2], camera_matrix[0, 0])


class QrReader:
    """Reads QR codes with ``cv2.QRCodeDetector``: the frame as it is, then, when no code was read, enlarged
    ``upscale`` times (the decoder needs about four pixels per module: at 320x240 a 20 cm code is read
    within about 0.6 m as it is, and a little farther enlarged). About 20-50 ms a frame at 320x240: it runs
    at its own low rate (:mod:`beastbt.vision.detectors`)."""

    def __init__(self, upscale: float = 2.0) -> None:
        self.upscale = float(upscale)
        self._detector = cv2.QRCodeDetector()

    def read(self, image: np.ndarray) -> list[QrDetection]:
        """The QR code in ``image`` (BGR or grey) whose text could be read (one, or none: ``[]``).

        Tried in turn until one reads: the frame as it is; enlarged and sharpened (an unsharp mask undoes
        a cheap lens's blur and a JPEG's softening of the modules); enlarged only."""
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        for attempt in range(3 if self.upscale > 1.0 else 1):
            if attempt == 0:
                g, scale = grey, 1.0
            else:
                scale = self.upscale
                g = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
                if attempt == 1:
                    g = cv2.addWeighted(g, 2.5, cv2.GaussianBlur(g, (0, 0), scale), -1.5, 0)
            try:
                text, points, _ = self._detector.detectAndDecode(g)
            except cv2.error:  # OpenCV rejects some degenerate quads it found itself: no code in this frame
                continue
            if text and points is not None:
                return [QrDetection(str(text), np.asarray(points, float).reshape(4, 2) / scale)]
        return []

    def first(self, image: np.ndarray, text: Optional[str] = None) -> Optional[QrDetection]:
        """The first code read in ``image`` (with ``text`` when given), or None."""
        for d in self.read(image):
            if text is None or d.text == text:
                return d
        return None


__all__ = ["QrDetection", "QrReader"]
