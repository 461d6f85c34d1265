"""The marker families a mission or a world may name, and how many ids each has, without loading OpenCV.

Checking a mission or a world file must not cost OpenCV's import; :mod:`beastbt.vision.fiducials` holds each
family's OpenCV dictionary, and the tests hold the two the same.
"""

from __future__ import annotations

from typing import Optional

TAG_IDS = {"apriltag_36h11": 587, "apriltag_25h9": 35, "aruco_4x4_50": 50, "aruco_5x5_100": 100,
           "aruco_6x6_250": 250, "aruco_original": 1024}
"""How many markers each family has (ids 0 to N - 1), as OpenCV's dictionaries hold them."""


def tag_id_problem(family: str, tag_id: int) -> Optional[str]:
    """Why ``tag_id`` is not a marker of ``family`` (an id beyond its dictionary), or None (an unknown family is
    the schema's to report)."""
    count = TAG_IDS.get(family)
    if count is None or 0 <= tag_id < count:
        return None
    return f"{family} has ids 0 to {count - 1}, got {tag_id}"


__all__ = ["TAG_IDS", "tag_id_problem"]
