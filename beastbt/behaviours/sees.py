"""The ``{sees: ...}`` condition: the camera sees a tag, a QR code, motion or a colour now.

Each test asks the run's :class:`~beastbt.vision.watch.VisionWatch` (``ctx.services.vision``), which
runs the detector on the newest frame when it has not yet. Without a fresh frame the answer is
unknown (it does not hold). Motion counts only while the robot stands still: its odometry says it
neither drives nor turns (:data:`STILL_MPS`, :data:`STILL_RPS`).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Optional

from beastbt.behaviours.conditions import Condition, ConditionReader
from beastbt.core.units import format_quantity

STILL_MPS = 0.01
"""Slower than this (m/s) the base stands still, for motion detection."""
STILL_RPS = 0.02
"""Turning slower than this (rad/s) the base stands still, for motion detection."""


def sees_text(c: Any) -> str:
    """The condition in words, as the mission wrote it (``c``: a :class:`beastbt.mission.steps.Sees`)."""
    if c.what == "tag":
        within = f" within {format_quantity(c.within_m, 'distance')}" if c.within_m is not None else ""
        family = "" if c.family in (None, "apriltag_36h11") else f" ({c.family})"
        return f"sees tag {c.tag_id}{family}{within}"
    if c.what == "qr":
        return f'sees QR "{c.text}"'
    if c.what == "motion":
        return "sees motion"
    name = c.colour if isinstance(c.colour, str) else "colour"
    return f"sees {name} (at least {c.min_area_frac * 100:g} %)"


def still(r: ConditionReader) -> bool:
    """The base stands still by its odometry (no odometry: not known to be still, so no motion is reported)."""
    pose = r.get("pose_odom")
    if pose is None:
        return False
    return abs(pose.speed_mps) < STILL_MPS and abs(pose.yaw_rate_rps) < STILL_RPS


def sees_condition(c: Any, reader: ConditionReader) -> Condition:
    """The :class:`Condition` of ``{sees: ...}`` (``c``: a :class:`beastbt.mission.steps.Sees`; reads the vision
    service and, for motion, ``pose_odom``)."""
    detail = {"text": ""}

    def watch(r: ConditionReader):  # the service is installed after the tree is compiled
        return r.ctx.services.vision

    test: Callable[[ConditionReader], Optional[bool]]
    if c.what == "tag":
        def test(r: ConditionReader) -> Optional[bool]:
            w = watch(r)
            if w is not None and c.size_m is not None:
                w.tag_sizes_m[c.tag_id] = c.size_m  # its distance (and the views') measured by its own size, as dock does
            tags = None if w is None else w.tags(r.ctx.now(), (c.family or "apriltag_36h11",))
            if tags is None:
                return None
            for t in tags:
                if t.id == c.tag_id and (c.within_m is None or t.distance_m <= c.within_m):
                    detail["text"] = f" ({t.distance_m:.2f} m at {math.degrees(t.bearing_rad):.0f} deg)"
                    return True
            return False
    elif c.what == "qr":
        def test(r: ConditionReader) -> Optional[bool]:
            w = watch(r)
            codes = None if w is None else w.qr_codes(r.ctx.now())
            if codes is None:
                return None
            return any(q.text == c.text for q in codes)
    elif c.what == "motion":
        def test(r: ConditionReader) -> Optional[bool]:
            w = watch(r)
            result = None if w is None else w.motion(r.ctx.now(), still(r))
            if result is None or not result.warm:
                return None
            if result.moving:
                detail["text"] = f" ({result.area_frac * 100:.1f} % of the picture)"
            return result.moving
    else:
        from beastbt.vision.colour import ColourRange
        colour = ColourRange.parse(c.colour)

        def test(r: ConditionReader) -> Optional[bool]:
            w = watch(r)
            seen = None if w is None else w.colour(r.ctx.now(), colour)
            if seen is None:
                return None
            blob, cam = seen
            if blob is None or blob.area_frac < c.min_area_frac:
                return False
            detail["text"] = (f" ({blob.area_frac * 100:.1f} % at "
                              f"{math.degrees(blob.bearing_rad(cam.camera_matrix)):.0f} deg)")
            return True

    return Condition(sees_text(c), test, reader, lambda: detail["text"])


__all__ = ["sees_condition", "sees_text", "still", "STILL_MPS", "STILL_RPS"]
