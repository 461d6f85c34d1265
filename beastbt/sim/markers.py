"""Flat printed things the simulated camera sees: fiducial tags and QR boards on walls or posts.

A world's ``tags:`` (``{id: 0, family: apriltag_36h11, size_m: 0.16, x, y, z_m, facing_deg, mount: wall|post}``)
and ``qr_boards:`` (``{text: dock-a, size_m: 0.2, x, y, z_m, facing_deg, mount}``) become
:class:`PlanarMarker`: a printed image (the marker by ``cv2.aruco.generateImageMarker``, the QR code by
``cv2.QRCodeEncoder``, with its white margin) on an upright square whose centre is at (x, y, z_m) in the
world (m) and whose face points toward ``facing_deg`` (deg counter-clockwise from east). ``size_m`` is the
side of the black square (for a tag, what a detector's pose needs); the printed sheet is larger by its margin.
A tag on a ``post`` stands on a thin dark pole from the floor.

:func:`draw_planar` warps a printed image into a frame by the camera's projection (one
``cv2.warpPerspective`` over the quad's bounding box, blended through a mask): the simulated camera
calls it after the scenery (:class:`MarkerPainter`), and the photo-like test images use it too.
Markers are drawn over the scenery: a person passing in front of a tag does not hide it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional, Sequence

import cv2
import numpy as np

from beastbt.vision.camera_model import CameraGeometry
from beastbt.vision.fiducials import DEFAULT_FAMILY, DEFAULT_TAG_SIZE_M, FAMILIES, marker_image, marker_margin_fraction

TEXTURE_PX = 240
"""Side of a printed image's texture (px): about 10 texture px per tag cell, finer than the camera sees it."""

NEAR_M = 0.05
"""A quad with a corner nearer the camera than this (m, along its axis) is not drawn."""

POST_WIDTH_M = 0.05
"""Width of the pole a tag on a post stands on (m)."""

POST_BGR = (70, 70, 75)
BACK_BGR = (200, 200, 200)
"""The back of a printed sheet, seen from behind."""

QR_MARGIN_MODULES = 4
"""White modules around a QR code (the standard's quiet zone)."""


def qr_image(text: str, side_px: int = TEXTURE_PX) -> tuple[np.ndarray, float]:
    """The printed QR code of ``text`` (grey uint8, ``side_px`` square with its quiet zone), and the share of its
    side each margin takes."""
    encoder = cv2.QRCodeEncoder.create()
    code = encoder.encode(text)  # one pixel per module, with no margin
    modules = code.shape[0]
    total = modules + 2 * QR_MARGIN_MODULES
    padded = cv2.copyMakeBorder(code, QR_MARGIN_MODULES, QR_MARGIN_MODULES, QR_MARGIN_MODULES, QR_MARGIN_MODULES,
                                cv2.BORDER_CONSTANT, value=255)
    return cv2.resize(padded, (side_px, side_px), interpolation=cv2.INTER_NEAREST), QR_MARGIN_MODULES / total


@dataclass(frozen=True)
class PlanarMarker:
    """A printed square standing upright: ``texture`` (grey or BGR) over the sheet, centre (x, y, z) m,
    ``facing_rad`` (yaw of the face's normal, CCW from east), ``sheet_m`` the printed sheet's side (m).
    ``kind`` is ``tag`` or ``qr``; ``label`` the tag id or the QR text; ``post`` a pole under it."""

    kind: str
    label: str
    x: float
    y: float
    z: float
    facing_rad: float
    size_m: float
    sheet_m: float
    texture: np.ndarray
    post: bool = False

    def corners_world(self) -> np.ndarray:
        """The sheet's corners (4, 3) m in the world: top-left, top-right, bottom-right, bottom-left as printed."""
        return square_corners(self.x, self.y, self.z, self.facing_rad, self.sheet_m)

    def post_corners_world(self) -> np.ndarray:
        """The pole's face (4, 3) m, from the floor to the sheet's lower edge, in the sheet's plane just behind it."""
        c, s = math.cos(self.facing_rad), math.sin(self.facing_rad)
        right = np.array([-s, c, 0.0])  # the sheet's right, seen from in front
        back = np.array([self.x, self.y, 0.0]) - 0.005 * np.array([c, s, 0.0])
        h = POST_WIDTH_M / 2
        low, high = 0.0, self.z - self.sheet_m / 2
        return np.array([back - h * right + [0, 0, high], back + h * right + [0, 0, high],
                         back + h * right + [0, 0, low], back - h * right + [0, 0, low]])


def square_corners(x: float, y: float, z: float, facing_rad: float, side_m: float) -> np.ndarray:
    """An upright square's corners (4, 3) m, centre (x, y, z), face toward ``facing_rad``: top-left, top-right,
    bottom-right, bottom-left as seen from in front."""
    c, s = math.cos(facing_rad), math.sin(facing_rad)
    right = np.array([-s, c, 0.0])
    up = np.array([0.0, 0.0, 1.0])
    centre = np.array([x, y, z])
    h = side_m / 2
    return np.array([centre - h * right + h * up, centre + h * right + h * up,
                     centre + h * right - h * up, centre - h * right - h * up])


def markers_of_world(tags: Optional[Sequence[dict]], qr_boards: Optional[Sequence[dict]]) -> list[PlanarMarker]:
    """The :class:`PlanarMarker` of a world's checked ``tags:`` and ``qr_boards:`` items; ``ValueError`` on a bad one."""
    out: list[PlanarMarker] = []
    for i, t in enumerate(tags or []):
        family = str(t.get("family", DEFAULT_FAMILY))
        if family not in FAMILIES:
            raise ValueError(f"tags[{i}].family: unknown marker family {family!r} (one of {', '.join(FAMILIES)})")
        size = float(t.get("size_m", DEFAULT_TAG_SIZE_M))
        margin = marker_margin_fraction(family)
        texture = marker_image(family, int(t["id"]), TEXTURE_PX)
        out.append(PlanarMarker("tag", str(int(t["id"])), float(t["x"]), float(t["y"]), float(t.get("z_m", 0.3)),
                                math.radians(float(t.get("facing_deg", 0.0))), size, size / (1 - 2 * margin),
                                texture, t.get("mount", "wall") == "post"))
    for b in qr_boards or []:
        size = float(b.get("size_m", 0.2))
        texture, margin = qr_image(str(b["text"]))
        out.append(PlanarMarker("qr", str(b["text"]), float(b["x"]), float(b["y"]), float(b.get("z_m", 0.3)),
                                math.radians(float(b.get("facing_deg", 0.0))), size, size / (1 - 2 * margin),
                                texture, b.get("mount", "wall") == "post"))
    return out


def project(points_cam: np.ndarray, camera_matrix: np.ndarray) -> Optional[np.ndarray]:
    """Pixels (N, 2) of camera-frame points (N, 3) m, or None when one is nearer than :data:`NEAR_M`."""
    if (points_cam[:, 2] < NEAR_M).any():
        return None
    uv = points_cam[:, :2] / points_cam[:, 2:3]
    return uv * [camera_matrix[0, 0], camera_matrix[1, 1]] + camera_matrix[:2, 2]


def draw_planar(out: np.ndarray, texture: np.ndarray, corners_px: np.ndarray) -> bool:
    """Warp ``texture`` (grey or BGR) into ``out`` (BGR, in place) so its corners land on ``corners_px`` (4, 2):
    top-left, top-right, bottom-right, bottom-left. False when the quad is off the frame."""
    h, w = out.shape[:2]
    x0, y0 = np.floor(corners_px.min(axis=0)).astype(int)
    x1, y1 = np.ceil(corners_px.max(axis=0)).astype(int) + 1
    x0, y0, x1, y1 = max(0, x0), max(0, y0), min(w, x1), min(h, y1)
    if x0 >= x1 or y0 >= y1:
        return False
    th, tw = texture.shape[:2]
    # Texture pixel centres run from 0 to side-1; the printed edges lie half a pixel outside them.
    src = np.array([[-0.5, -0.5], [tw - 0.5, -0.5], [tw - 0.5, th - 0.5], [-0.5, th - 0.5]], np.float32)
    dst = (corners_px - [x0, y0]).astype(np.float32)
    m = cv2.getPerspectiveTransform(src, dst)
    size = (x1 - x0, y1 - y0)
    tex = texture if texture.ndim == 3 else cv2.cvtColor(texture, cv2.COLOR_GRAY2BGR)
    warped = cv2.warpPerspective(tex, m, size, flags=cv2.INTER_AREA if _shrinks(m) else cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_REPLICATE)
    # The mask drawn with subpixel edges (antialiased), so that a marker's outline moves smoothly.
    mask = np.zeros((size[1], size[0]), np.uint8)
    cv2.fillConvexPoly(mask, np.rint(dst * 16).astype(np.int32), 255, cv2.LINE_AA, 4)
    roi = out[y0:y1, x0:x1]
    alpha = mask.astype(np.float32)[..., None] / 255.0
    roi[:] = (warped * alpha + roi * (1.0 - alpha) + 0.5).astype(np.uint8)
    return True


def _shrinks(m: np.ndarray) -> bool:
    """True when the warp shrinks the texture (OpenCV's warp samples; shrinking is where it aliases)."""
    return abs(float(np.linalg.det(m[:2, :2]))) < 1.0


class MarkerPainter:
    """Draws a world's planar markers into frames of one camera (see the module docstring)."""

    def __init__(self, markers: Sequence[PlanarMarker]) -> None:
        self.markers = list(markers)

    def draw(self, out: np.ndarray, geom: CameraGeometry, x_m: float, y_m: float, yaw_rad: float) -> int:
        """Draw the markers seen from the robot at (x, y m, yaw rad), far to near; how many were drawn."""
        if not self.markers:
            return 0
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        body_from_world = np.array([[c, s, 0.0, -(c * x_m + s * y_m)], [-s, c, 0.0, s * x_m - c * y_m],
                                    [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
        cam_from_world = geom.camera_from_body @ body_from_world
        rot, trans = cam_from_world[:, :3], cam_from_world[:, 3]
        cam_pos = -rot.T @ trans
        k = geom.camera_matrix
        order = sorted(self.markers, key=lambda mk: -math.hypot(mk.x - cam_pos[0], mk.y - cam_pos[1]))
        drawn = 0
        for mk in order:
            if mk.post:
                uv = project(mk.post_corners_world() @ rot.T + trans, k)
                if uv is not None:
                    cv2.fillConvexPoly(out, np.rint(uv * 16).astype(np.int32), POST_BGR, cv2.LINE_AA, 4)
            corners = mk.corners_world()
            uv = project(corners @ rot.T + trans, k)
            if uv is None:
                continue
            facing = np.array([math.cos(mk.facing_rad), math.sin(mk.facing_rad), 0.0])
            if float(facing @ (cam_pos - corners.mean(axis=0))) <= 0:  # seen from behind: the sheet's blank back
                cv2.fillConvexPoly(out, np.rint(uv * 16).astype(np.int32), BACK_BGR, cv2.LINE_AA, 4)
                continue
            drawn += int(draw_planar(out, mk.texture, uv))
        return drawn


def marker_schema_problem(value: Any) -> Optional[tuple[int, str]]:
    """Why a ``tags:`` list cannot be drawn, as (item index, message): an id beyond its family's dictionary; or None."""
    for i, t in enumerate(value or []):
        family = str(t.get("family", DEFAULT_FAMILY))
        if family not in FAMILIES:
            return i, f"unknown marker family {family!r}"
        size = cv2.aruco.getPredefinedDictionary(FAMILIES[family]).bytesList.shape[0]
        if not 0 <= int(t["id"]) < size:
            return i, f"{family} has ids 0 to {size - 1}, got {t['id']}"
    return None


__all__ = ["PlanarMarker", "MarkerPainter", "draw_planar", "markers_of_world", "qr_image", "square_corners", "project",
           "marker_schema_problem"]
