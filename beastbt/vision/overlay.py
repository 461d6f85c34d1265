"""Drawing what the line detector found onto a picture of any size, for the operator's live video.

:func:`draw_detection` works from a :class:`~beastbt.vision.line_detector.LineDetection`
(a finished result, safe to hand to another thread) and the camera's
:class:`~beastbt.vision.camera_model.CameraGeometry`, rescaled to the
picture's size, so the overlay can be drawn after the frame was resized for
streaming. :func:`draw_caption` writes lines of text on a dark band at the top.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence

import cv2
import numpy as np

from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.line_detector import LineDetection

LINE_BGR = (0, 220, 0)
TARGET_BGR = (0, 0, 255)
JUNCTION_BGR = (255, 0, 255)
END_BGR = (0, 128, 255)


def draw_detection(image: np.ndarray, detection: Optional[LineDetection], geometry: CameraGeometry,
                   lookahead_m: float) -> np.ndarray:
    """Draw the tracked line, the look-ahead target, a junction and a line end on ``image`` (BGR, in place).

    ``geometry`` is the camera that took the frame (any size: it is rescaled
    to ``image``); ``lookahead_m`` is where the detector reports the offset (m).
    Returns ``image``.
    """
    if detection is None:
        return image
    h, w = image.shape[:2]
    geom = geometry.scaled_to(w, h)
    scale = max(1, int(round(w / 320)))

    def px(points: np.ndarray) -> np.ndarray:
        uv = geom.ground_to_pixels(np.asarray(points, float).reshape(-1, 2))
        uv = uv[np.isfinite(uv).all(axis=1)]
        return np.round(uv).astype(np.int32)

    obs = detection.observation
    if len(detection.points) >= 2:
        pts = px(detection.points)
        if len(pts) >= 2:
            cv2.polylines(image, [pts], False, LINE_BGR, 2 * scale, cv2.LINE_AA)
    if obs.seen:
        t = px(np.array([[lookahead_m, obs.offset_m]]))
        if len(t):
            cv2.circle(image, (int(t[0][0]), int(t[0][1])), 5 * scale, TARGET_BGR, 2 * scale, cv2.LINE_AA)
    if detection.intersection_xy is not None:
        j = px(np.array([detection.intersection_xy]))
        if len(j):
            cv2.drawMarker(image, (int(j[0][0]), int(j[0][1])), JUNCTION_BGR, cv2.MARKER_CROSS, 16 * scale, 2 * scale)
    if detection.end_xy is not None:
        e = px(np.array([detection.end_xy]))
        if len(e):
            cv2.drawMarker(image, (int(e[0][0]), int(e[0][1])), END_BGR, cv2.MARKER_TILTED_CROSS, 12 * scale, 2 * scale)
    return image


def describe(detection: Optional[LineDetection]) -> str:
    """One line about a detection for a caption: offset, angle, junction or end."""
    if detection is None:
        return "line: -"
    obs = detection.observation
    if not obs.seen:
        return "line: not seen"
    text = f"line {obs.offset_m * 100:+.1f} cm {math.degrees(obs.angle_rad):+.0f} deg"
    if obs.intersection and obs.intersection_distance_m is not None:
        text += f"  {detection.intersection_kind or 'junction'} at {obs.intersection_distance_m:.2f} m"
    if obs.line_end:
        text += "  end in view"
    return text


def draw_caption(image: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """Write ``lines`` of text on a dark band across the top of ``image`` (BGR, in place); returns it."""
    if not lines:
        return image
    h, w = image.shape[:2]
    size = max(0.4, w / 1000.0)
    thick = 1 if w < 900 else 2
    step = int(22 * size / 0.5)
    band = min(h, step * len(lines) + step // 3)
    image[:band] >>= 1  # darken the band (halve) so the text reads on any floor
    for i, text in enumerate(lines):
        cv2.putText(image, text, (6, step * (i + 1) - step // 4), cv2.FONT_HERSHEY_SIMPLEX, size, (255, 255, 255),
                    thick, cv2.LINE_AA)
    return image


__all__ = ["draw_detection", "draw_caption", "describe"]
