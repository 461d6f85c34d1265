"""Camera calibration from checkerboard photos: the lens's intrinsics (fx, fy, cx, cy) and its distortion.

OpenCV does the work: ``cv2.findChessboardCorners`` finds the board's inner corners in each photo,
``cv2.cornerSubPix`` refines them to a fraction of a pixel, and ``cv2.calibrateCamera`` fits the pinhole
camera and the ``plumb_bob`` distortion (k1, k2, p1, p2, k3) that best explain them all. The RMS reprojection
error (pixels) says how well: under about 0.5 px is a good calibration, over 1 px means blurred photos, a
board that is not flat, or too few views.

A board is named by its *inner* corners (``9x6``: 9 along, 6 down; a board of 10x7 squares) and the side of
one square (``25mm``). Photos should show the whole board, tilted differently in each (at least
:data:`MIN_PHOTOS` usable ones), all at the size the robot's camera delivers.

:func:`calibrate` raises :class:`CalibrationRefused` (its message names the file) for an unreadable photo, a
photo of another size, or too few photos where the board is found. :meth:`CameraIntrinsics.profile_section`
is what the robot profile's ``camera.intrinsics:`` holds (see ``schemas/parts/camera.schema.json``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence

import cv2
import numpy as np

MIN_PHOTOS = 5
"""Fewest photos with the board found that a calibration accepts: fewer leave fx, fy, cx, cy poorly fixed."""

SUBPIX_WINDOW_PX = 5
"""Half side of the window cornerSubPix searches around each corner (pixels; OpenCV's samples use 5 to 11)."""

SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.001)
"""Stop refining a corner after 40 iterations or a move under 0.001 px."""


class CalibrationRefused(ValueError):
    """A calibration that cannot be made: the message says which file and why, and what to do."""


@dataclass(frozen=True)
class Board:
    """A printed checkerboard: ``cols`` x ``rows`` inner corners, squares ``square_m`` metres on a side."""

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        if self.cols < 3 or self.rows < 3:
            raise ValueError(f"a board needs at least 3x3 inner corners, got {self.cols}x{self.rows}")
        if self.cols == self.rows:
            # a square pattern has no way up: its corners can be numbered from any of its four sides
            raise ValueError(f"a {self.cols}x{self.rows} board is square, so its orientation is ambiguous; "
                             "use one with a different number of corners each way, such as 9x6")
        if not self.square_m > 0.0:
            raise ValueError(f"the square's side must be > 0 m, got {self.square_m}")

    @classmethod
    def parse(cls, size: str, square: str) -> "Board":
        """A board from ``--board 9x6`` (inner corners) and ``--square 25mm`` (a distance); ValueError if bad."""
        from beastbt.core.units import parse_quantity
        m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", size)
        if m is None:
            raise ValueError(f"--board {size!r}: expected the inner corners as COLSxROWS, such as 9x6 "
                             "(a board of 10 by 7 squares)")
        if re.fullmatch(r"\s*[-+]?[\d.]+\s*", str(square)):  # a bare number: metres or millimetres? ask
            raise ValueError(f"--square {square!r}: give the unit, such as 25mm or 2.5cm")
        try:
            square_m = parse_quantity(square, "distance")
        except ValueError as exc:
            raise ValueError(f"--square {square!r}: {exc}") from None
        return cls(int(m.group(1)), int(m.group(2)), square_m)

    def object_points(self) -> np.ndarray:
        """The inner corners on the board's plane, in the order OpenCV finds them: (cols*rows, 3) metres, z = 0."""
        grid = np.mgrid[0:self.cols, 0:self.rows].T.reshape(-1, 2)
        return np.column_stack([grid * self.square_m, np.zeros(len(grid))]).astype(np.float32)


@dataclass(frozen=True)
class CameraIntrinsics:
    """A calibrated camera: focal lengths and principal point (pixels) at ``width_px`` x ``height_px``, the
    ``plumb_bob`` distortion (k1, k2, p1, p2, k3) and the calibration's RMS reprojection error (pixels)."""

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    rms_px: Optional[float] = None

    def __post_init__(self) -> None:
        if self.width_px < 2 or self.height_px < 2:
            raise ValueError("intrinsics: the image size must be at least 2x2 pixels, "
                             f"got {self.width_px}x{self.height_px}")
        if not (self.fx_px > 0.0 and self.fy_px > 0.0):
            raise ValueError(f"intrinsics: fx_px and fy_px must be > 0 px, got {self.fx_px} and {self.fy_px}")
        if len(self.distortion) not in (4, 5):
            raise ValueError("intrinsics: distortion is k1, k2, p1, p2 (, k3): 4 or 5 numbers, "
                             f"got {len(self.distortion)}")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "CameraIntrinsics":
        """From the profile's ``camera.intrinsics:`` mapping (its schema checked it); ValueError if bad."""
        from beastbt.core.config import dataclass_from_dict
        d = dict(d)
        if "distortion" in d:
            d["distortion"] = tuple(float(v) for v in d["distortion"])
        return dataclass_from_dict(cls, d, "camera.intrinsics")

    @property
    def camera_matrix(self) -> np.ndarray:
        """The 3x3 matrix K (pixels)."""
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    def profile_section(self) -> dict:
        """The profile's ``camera.intrinsics:`` mapping (numbers rounded to what a calibration can tell)."""
        out: dict = {"width_px": self.width_px, "height_px": self.height_px,
                     "fx_px": round(self.fx_px, 2), "fy_px": round(self.fy_px, 2),
                     "cx_px": round(self.cx_px, 2), "cy_px": round(self.cy_px, 2),
                     "distortion": [round(float(d), 5) for d in self.distortion]}
        if self.rms_px is not None:
            out["rms_px"] = round(self.rms_px, 3)
        return out


@dataclass
class Calibration:
    """What :func:`calibrate` found: the intrinsics, the photos used, and the photos skipped with why."""

    intrinsics: CameraIntrinsics
    used: list[str] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)


def find_corners(grey: np.ndarray, board: Board) -> Optional[np.ndarray]:
    """The board's inner corners in a grey image, refined to subpixel: (cols*rows, 1, 2) float32; None if the
    whole board is not found."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(grey, (board.cols, board.rows), flags=flags)
    if not found or corners is None:
        return None
    return cv2.cornerSubPix(grey, corners, (SUBPIX_WINDOW_PX, SUBPIX_WINDOW_PX), (-1, -1), SUBPIX_CRITERIA)


def calibrate(paths: Sequence[str], board: Board, min_photos: int = MIN_PHOTOS) -> Calibration:
    """Calibrate from the photos at ``paths``; raises :class:`CalibrationRefused` naming the file at fault."""
    size: Optional[tuple[int, int]] = None
    first = ""
    image_points: list[np.ndarray] = []
    used: list[str] = []
    skipped: list[tuple[str, str]] = []
    for path in paths:
        if Path(path).is_dir():
            raise CalibrationRefused(f"{path}: a folder, not a photo; give the photos in it, such as {Path(path) / '*.jpg'}")
        if not Path(path).is_file():
            hint = ("a shell pattern that matches nothing comes as it is written: check the folder and the extension "
                    "(.jpg, .png...)" if any(c in str(path) for c in "*?[") else "check the path")
            raise CalibrationRefused(f"{path}: no such file; {hint}")
        grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if grey is None or not grey.size:
            raise CalibrationRefused(f"{path}: not an image OpenCV can read (JPEG, PNG, BMP, TIFF...)")
        here = (grey.shape[1], grey.shape[0])
        if size is None:
            size, first = here, path
        elif here != size:
            raise CalibrationRefused(f"{path}: {here[0]}x{here[1]} pixels, but {first} is {size[0]}x{size[1]}; "
                                     "calibrate with photos all taken at the size the robot's camera delivers")
        corners = find_corners(grey, board)
        if corners is None:
            skipped.append((path, f"no {board.cols}x{board.rows} board found"))
            continue
        image_points.append(corners)
        used.append(path)
    if size is None:
        raise CalibrationRefused("no photos given")
    if len(used) < min_photos:
        missing = "; ".join(f"{p}: {why}" for p, why in skipped)
        raise CalibrationRefused(
            f"the board was found in {len(used)} of {len(paths)} photos, and a calibration needs at least "
            f"{min_photos}" + (f" ({missing})" if missing else "") +
            f"; check --board names the inner corners ({board.cols}x{board.rows} is a board of "
            f"{board.cols + 1}x{board.rows + 1} squares), and take more photos showing the whole board, "
            "tilted differently in each")
    objects = [board.object_points()] * len(image_points)
    rms, k, dist, _, _ = cv2.calibrateCamera(objects, image_points, size, None, None)
    d = tuple(float(v) for v in np.asarray(dist).ravel()[:5])
    intrinsics = CameraIntrinsics(size[0], size[1], float(k[0, 0]), float(k[1, 1]), float(k[0, 2]),
                                  float(k[1, 2]), d, float(rms))
    return Calibration(intrinsics, used, skipped)


__all__ = ["Board", "Calibration", "CalibrationRefused", "CameraIntrinsics", "MIN_PHOTOS", "calibrate",
           "find_corners"]
