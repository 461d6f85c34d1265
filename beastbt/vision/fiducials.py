"""Fiducial markers (AprilTag 36h11 and ArUco): which ids a frame shows, and where each tag is.

:class:`FiducialDetector` wraps OpenCV's ``cv2.aruco.ArucoDetector`` (one per
dictionary asked for) and solves each marker's pose with ``cv2.solvePnP``
(``SOLVEPNP_IPPE_SQUARE``, the solver made for one square) from the camera's
intrinsics. A :class:`TagDetection` gives the tag in the camera frame (x right,
y down, z along the optical axis, metres) and, when the camera's mounting is
given (``camera_from_body``, a 3x4 ``[R | t]`` as
:attr:`~beastbt.vision.camera_model.CameraGeometry.camera_from_body` gives it),
in the robot's base frame (x forward, y left, z up, metres): its position, the
bearing and range to it, and ``facing_rad``, the direction its face points
(yaw in the base frame; a tag seen head-on points back at the robot, about
pi). Nothing here touches devices, the clock or the blackboard.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

import cv2
import numpy as np

FAMILIES: Mapping[str, int] = {
    "apriltag_36h11": cv2.aruco.DICT_APRILTAG_36h11,
    "apriltag_25h9": cv2.aruco.DICT_APRILTAG_25h9,
    "aruco_4x4_50": cv2.aruco.DICT_4X4_50,
    "aruco_5x5_100": cv2.aruco.DICT_5X5_100,
    "aruco_6x6_250": cv2.aruco.DICT_6X6_250,
    "aruco_original": cv2.aruco.DICT_ARUCO_ORIGINAL,
}
"""Marker families by the name a world or a mission uses, and their OpenCV dictionary."""

DEFAULT_FAMILY = "apriltag_36h11"
"""The family of a tag whose family is not named: AprilTag 36h11, as Nav2's docking examples use."""

DEFAULT_TAG_SIZE_M = 0.16
"""Side of a tag's black square (m) when the mission does not say: a tag printed on an A4 sheet."""


def marker_image(family: str, tag_id: int, side_px: int, border_cells: int = 1) -> np.ndarray:
    """The printable marker ``tag_id`` of ``family``: a grey (uint8) square ``side_px`` wide with a white margin of
    ``border_cells`` cells around the black square (what a printed tag looks like)."""
    dictionary = cv2.aruco.getPredefinedDictionary(FAMILIES[family])
    cells = dictionary.markerSize + 2  # the data cells and the black border
    total = cells + 2 * border_cells
    cell_px = max(1, side_px // total)
    inner = cv2.aruco.generateImageMarker(dictionary, int(tag_id), cells * cell_px, borderBits=1)
    pad = border_cells * cell_px
    out = cv2.copyMakeBorder(inner, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    return out if out.shape[0] == side_px else cv2.resize(out, (side_px, side_px), interpolation=cv2.INTER_NEAREST)


def marker_margin_fraction(family: str, border_cells: int = 1) -> float:
    """How much of :func:`marker_image`'s side is white margin on each side (fraction of the whole side)."""
    cells = cv2.aruco.getPredefinedDictionary(FAMILIES[family]).markerSize + 2
    return border_cells / (cells + 2 * border_cells)


@dataclass(frozen=True)
class TagDetection:
    """One marker in a frame.

    ``corners_px``: its four corners (4, 2) in the image, OpenCV's order (top-left, top-right, bottom-right,
    bottom-left as printed). ``rvec``/``tvec_m``: the tag's pose in the camera frame (Rodrigues vector, metres;
    tag frame: x right, y up along the print, z out of its face). ``position_m``: the tag centre in the base
    frame (x forward, y left, z up, m); ``facing_rad``: yaw of the tag's face normal in the base frame (rad);
    both None without the mounting.
    """

    family: str
    id: int
    corners_px: np.ndarray
    size_m: float
    rvec: np.ndarray
    tvec_m: np.ndarray
    position_m: Optional[tuple[float, float, float]] = None
    facing_rad: Optional[float] = None

    @property
    def distance_m(self) -> float:
        """Range to the tag centre (m): in the base plane when the mounting is known, else from the camera."""
        if self.position_m is not None:
            return math.hypot(self.position_m[0], self.position_m[1])
        return float(np.linalg.norm(self.tvec_m))

    @property
    def bearing_rad(self) -> float:
        """Direction of the tag centre (rad, positive left): in the base frame when known, else off the optical axis."""
        if self.position_m is not None:
            return math.atan2(self.position_m[1], self.position_m[0])
        return -math.atan2(float(self.tvec_m[0]), float(self.tvec_m[2]))

    @property
    def centre_px(self) -> tuple[float, float]:
        """The tag's centre in the image (u, v px)."""
        c = self.corners_px.mean(axis=0)
        return float(c[0]), float(c[1])


class FiducialDetector:
    """Finds markers of ``families`` and solves their pose; ``sizes_m`` gives a tag's side by id (else ``size_m``),
    read at each detection (the caller may add sizes later).

    Corners are refined to subpixel accuracy (``CORNER_REFINE_SUBPIX``: the pose needs it, and it costs a
    fraction of a millisecond at 320x240).
    """

    def __init__(self, families: Sequence[str] = (DEFAULT_FAMILY,), size_m: float = DEFAULT_TAG_SIZE_M,
                 sizes_m: Optional[Mapping[int, float]] = None) -> None:
        unknown = [f for f in families if f not in FAMILIES]
        if unknown:
            raise ValueError(f"unknown marker family {unknown[0]!r}: one of {', '.join(FAMILIES)}")
        if not size_m > 0:
            raise ValueError(f"tag size must be > 0 m, got {size_m}")
        self.families = tuple(families)
        self.size_m = float(size_m)
        self.sizes_m = sizes_m if sizes_m is not None else {}  # the caller's mapping, read at each detection
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self._detectors = [(f, cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(FAMILIES[f]), params))
                           for f in self.families]

    def detect(self, image: np.ndarray, camera_matrix: Optional[np.ndarray] = None,
               dist_coeffs: Optional[np.ndarray] = None,
               camera_from_body: Optional[np.ndarray] = None) -> list[TagDetection]:
        """Every marker in ``image`` (BGR or grey), sorted by family then id. Without ``camera_matrix`` no pose is
        solved (``rvec``/``tvec_m`` are zeros); with ``camera_from_body`` each tag is placed in the base frame."""
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        found: list[TagDetection] = []
        for family, detector in self._detectors:
            corners, ids, _ = detector.detectMarkers(grey)
            if ids is None:
                continue
            for quad, tag_id in zip(corners, ids.ravel()):
                found.append(self._solve(family, int(tag_id), quad.reshape(4, 2), camera_matrix, dist_coeffs,
                                         camera_from_body))
        found.sort(key=lambda d: (d.family, d.id))
        return found

    def _solve(self, family: str, tag_id: int, corners: np.ndarray, k: Optional[np.ndarray],
               dist: Optional[np.ndarray], camera_from_body: Optional[np.ndarray]) -> TagDetection:
        size = float(self.sizes_m.get(tag_id, self.size_m))
        zero = np.zeros(3)
        if k is None:
            return TagDetection(family, tag_id, corners, size, zero, zero)
        obj, img = tag_object_points(size), corners.astype(np.float64)
        dist = np.zeros(5) if dist is None else dist
        ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not (ok and np.isfinite(rvec).all() and np.isfinite(tvec).all()):
            # IPPE_SQUARE returns NaN for some near-symmetric quads; the general planar IPPE solves those.
            ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_IPPE)
        if not (ok and np.isfinite(rvec).all() and np.isfinite(tvec).all()):
            return TagDetection(family, tag_id, corners, size, zero, zero)
        rvec, tvec = rvec.ravel(), tvec.ravel()
        position: Optional[tuple[float, float, float]] = None
        facing: Optional[float] = None
        if camera_from_body is not None:
            r_cb, t_cb = camera_from_body[:, :3], camera_from_body[:, 3]
            p = r_cb.T @ (tvec - t_cb)  # camera -> body
            normal_cam = cv2.Rodrigues(rvec)[0][:, 2]
            n = r_cb.T @ normal_cam
            position = (float(p[0]), float(p[1]), float(p[2]))
            facing = math.atan2(float(n[1]), float(n[0]))
        return TagDetection(family, tag_id, corners, size, rvec, tvec, position, facing)


def tag_object_points(size_m: float) -> np.ndarray:
    """A tag's corners in its own frame (4, 3) m, in OpenCV's corner order (x right, y up, z out of the face)."""
    h = size_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


__all__ = ["FAMILIES", "DEFAULT_FAMILY", "DEFAULT_TAG_SIZE_M", "FiducialDetector", "TagDetection", "marker_image",
           "marker_margin_fraction", "tag_object_points"]
