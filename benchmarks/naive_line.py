"""The naive line follower's image step, the anchor of the vision benchmarks.

What the line-following tutorials for the Raspberry Pi do with each frame
(and what beastbt's :class:`~beastbt.vision.line_detector.LineDetector` is
measured against): grey, blur, Otsu threshold of the lower third of the
image, the largest dark contour, and its centroid's column as the offset.
No bird's-eye view, no bands, no junctions: the least work that follows a
line, so the ratio says what the detector's extra answers cost.
"""

from __future__ import annotations

from typing import Optional

import cv2
import numpy as np


def naive_line_offset(image: np.ndarray) -> Optional[float]:
    """The line's centroid in the lower third of a BGR ``image``, as a fraction of the width from the centre
    (-0.5 left .. +0.5 right), or None when no dark region is found."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    roi = grey[2 * grey.shape[0] // 3:, :]
    blurred = cv2.GaussianBlur(roi, (5, 5), 0)
    _, mask = cv2.threshold(blurred, 0, 255, cv2.THRESH_BINARY_INV + cv2.THRESH_OTSU)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return None
    moments = cv2.moments(max(contours, key=cv2.contourArea))
    if moments["m00"] == 0:
        return None
    return moments["m10"] / moments["m00"] / image.shape[1] - 0.5
