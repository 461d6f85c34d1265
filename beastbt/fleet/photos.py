"""A robot's newest photo on the fleet: made small enough for the link on the robot, kept by the station.

A mission's ``photo:`` step (or an ``alert:`` with ``photo: true``) saves a full-resolution JPEG in the run
folder. The robot's agent puts a copy on ``beastbt/<name>/photo`` (:func:`~beastbt.fleet.keys.photo_key`): the
JPEG as payload, downscaled and re-encoded until it is at most :data:`PHOTO_MAX_BYTES` (a 640 px wide picture
at quality 80 is about 40 kB), and ``{robot, name, time_s}`` as the sample's attachment. Only the newest photo
not yet sent goes, off the tick thread, so a mission that photographs every door costs the link one small
picture at a time. The station keeps the latest per robot and serves it (``GET /api/robots/NAME/photo.jpg``).
"""

from __future__ import annotations

import json
from typing import Any, Optional

PHOTO_MAX_BYTES = 100_000
"""The largest JPEG a robot puts on the fleet (bytes): a robot's link has about 50 kB/s for its state."""
PHOTO_MAX_SIDE_PX = 640
"""A photo wider or taller than this is scaled down to it before it goes on the fleet (px)."""
QUALITIES = (80, 65, 50, 35)
"""JPEG qualities tried in turn until the photo fits :data:`PHOTO_MAX_BYTES` (halving its size after the last)."""


def fleet_jpeg(path: str, max_bytes: int = PHOTO_MAX_BYTES) -> Optional[bytes]:
    """The photo at ``path`` as a JPEG of at most ``max_bytes`` for the fleet, or None when it cannot be read."""
    import cv2
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        return None
    while True:
        h, w = image.shape[:2]
        scale = PHOTO_MAX_SIDE_PX / max(h, w)
        if scale < 1.0:
            image = cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))),
                               interpolation=cv2.INTER_AREA)
        for quality in QUALITIES:
            ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
            if ok and len(data) <= max_bytes:
                return data.tobytes()
        if max(h, w) <= 16:
            return None
        image = cv2.resize(image, (max(1, w // 2), max(1, h // 2)), interpolation=cv2.INTER_AREA)


def photo_attachment(robot: str, name: str, time_s: float) -> bytes:
    """The attachment that goes with a photo on the fleet: JSON ``{robot, name, time_s}``."""
    return json.dumps({"robot": robot, "name": name, "time_s": round(float(time_s), 2)}).encode()


def read_attachment(sample: Any) -> dict:
    """The ``{name, time_s}`` of a photo sample (empty name and 0 s when its attachment is missing or bad)."""
    meta: dict = {}
    try:
        raw = sample.attachment.to_bytes() if sample.attachment is not None else b""
        value = json.loads(raw) if raw else {}
        meta = value if isinstance(value, dict) else {}
    except (ValueError, UnicodeDecodeError, AttributeError, RecursionError):
        pass
    name = meta.get("name") if isinstance(meta.get("name"), str) else ""
    t = meta.get("time_s")
    return {"name": name[:80], "time_s": float(t) if isinstance(t, (int, float)) else 0.0}


__all__ = ["fleet_jpeg", "photo_attachment", "read_attachment", "PHOTO_MAX_BYTES", "PHOTO_MAX_SIDE_PX"]
