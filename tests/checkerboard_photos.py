"""Photo-like checkerboard pictures from a known camera, for testing ``beastbt camera calibrate``.

A printed board (:data:`BOARD`: 9x6 inner corners, 25 mm squares, a white margin) is held at several poses
before :data:`TRUE_CAMERA` (640x480, fx 610, fy 604, principal point off the middle, barrel distortion). Each
picture is rendered pixel by pixel from the lens's own model: every pixel's ray (``cv2.undistortPoints`` of
the true camera) meets the board's plane at a point whose square is black or white, four samples a pixel.
``cv2.projectPoints`` of the true camera keeps only poses that show the whole board. Then the picture is made
to look like a cheap camera's: a little defocus blur, sensor noise, light falling off across it, and a JPEG
round trip at quality 60.

Run it to look at them: ``python tests/checkerboard_photos.py OUT_DIR`` writes the JPEG files.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import cv2
import numpy as np

from beastbt.vision.calibration import Board, CameraIntrinsics

BOARD = Board(cols=9, rows=6, square_m=0.025)
"""The printed board: 9x6 inner corners (10x7 squares) of 25 mm."""

TRUE_CAMERA = CameraIntrinsics(width_px=640, height_px=480, fx_px=610.0, fy_px=604.0, cx_px=331.0, cy_px=229.0,
                               distortion=(-0.12, 0.05, 0.0, 0.0, 0.0))
"""The camera the photos come from (what a calibration should find)."""

MARGIN_SQUARES = 1.0
"""White paper around the squares, in squares."""


def _rays(camera: CameraIntrinsics, supersample: int) -> np.ndarray:
    """Each sample's ray through the true lens: (h*s, w*s, 2) normalised image coordinates (x/z, y/z)."""
    s = supersample
    offsets = (np.arange(s) + 0.5) / s - 0.5
    u = (np.arange(camera.width_px)[:, None] + offsets[None, :]).ravel()
    v = (np.arange(camera.height_px)[:, None] + offsets[None, :]).ravel()
    uu, vv = np.meshgrid(u, v)
    pts = np.column_stack([uu.ravel(), vv.ravel()]).astype(np.float64).reshape(-1, 1, 2)
    norm = cv2.undistortPoints(pts, camera.camera_matrix, np.array(camera.distortion),
                               criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9))
    return norm.reshape(len(v), len(u), 2)


def render(rvec: np.ndarray, tvec: np.ndarray, rays: np.ndarray, camera: CameraIntrinsics = TRUE_CAMERA,
           board: Board = BOARD, supersample: int = 2) -> np.ndarray:
    """The clean grey picture (uint8) of ``board`` at pose (rvec, tvec: board -> camera, metres) on a grey room."""
    r, _ = cv2.Rodrigues(rvec)
    t = np.asarray(tvec, float).ravel()
    n = r[:, 2]  # the board's normal in the camera frame
    d = float(n @ t)
    ray = np.dstack([rays, np.ones(rays.shape[:2])])
    denom = ray @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = d / denom
    points = ray * lam[..., None] - t  # camera frame, relative to the board's origin
    bx, by = points @ r[:, 0], points @ r[:, 1]  # on the board's plane, metres
    sq = board.square_m
    # The board's inner corners sit at (i*sq, j*sq); its squares run from -sq to (cols)*sq (rows likewise).
    col, row = np.floor(bx / sq) + 1, np.floor(by / sq) + 1
    in_squares = (col >= 0) & (col <= board.cols) & (row >= 0) & (row <= board.rows)
    m = MARGIN_SQUARES * sq
    on_paper = (bx >= -sq - m) & (bx <= board.cols * sq + m) & (by >= -sq - m) & (by <= board.rows * sq + m)
    on_paper &= lam > 0
    grey = np.full(rays.shape[:2], 120.0)  # the room behind
    grey[on_paper] = 235.0
    black = in_squares & on_paper & ((col + row) % 2 == 0)
    grey[black] = 25.0
    s = supersample
    h, w = camera.height_px, camera.width_px
    return grey.reshape(h, s, w, s).mean(axis=(1, 3)).astype(np.uint8)


def degrade(grey: np.ndarray, rng: np.random.Generator, blur_px: float = 0.7, noise_std: float = 5.0,
            jpeg_quality: int = 60, light_ramp: float = 0.4) -> bytes:
    """A cheap camera's JPEG of a clean grey picture: blur, uneven light, noise, then JPEG at ``jpeg_quality``."""
    img = cv2.GaussianBlur(grey.astype(np.float32), (0, 0), blur_px)
    h, w = img.shape
    ramp = 1.0 - light_ramp * np.linspace(0.0, 1.0, w)[None, :] * np.linspace(0.5, 1.0, h)[:, None]
    img = img * ramp + rng.normal(0.0, noise_std, img.shape)
    bgr = cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    assert ok
    return data.tobytes()


def poses(count: int, rng: np.random.Generator, camera: CameraIntrinsics = TRUE_CAMERA,
          board: Board = BOARD) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` board poses (rvec, tvec) tilted up to about 35 degrees each way, 0.3-0.5 m away, each showing
    the whole board (its outer squares' corners inside the picture by 20 px, by ``cv2.projectPoints``)."""
    centre = np.array([(board.cols - 1) * board.square_m / 2, (board.rows - 1) * board.square_m / 2, 0.0])
    outline = np.array([[-board.square_m, -board.square_m, 0.0], [board.cols * board.square_m, -board.square_m, 0.0],
                        [board.cols * board.square_m, board.rows * board.square_m, 0.0],
                        [-board.square_m, board.rows * board.square_m, 0.0]])
    out: list[tuple[np.ndarray, np.ndarray]] = []
    while len(out) < count:
        ax, ay, az = rng.uniform(-35, 35), rng.uniform(-35, 35), rng.uniform(-20, 20)
        r = (cv2.Rodrigues(np.radians([ax, 0.0, 0.0]))[0] @ cv2.Rodrigues(np.radians([0.0, ay, 0.0]))[0]
             @ cv2.Rodrigues(np.radians([0.0, 0.0, az]))[0])
        where = np.array([rng.uniform(-0.08, 0.08), rng.uniform(-0.06, 0.06), rng.uniform(0.3, 0.5)])
        tvec = where - r @ centre  # the board's middle at ``where``
        rvec = cv2.Rodrigues(r)[0]
        px, _ = cv2.projectPoints(outline, rvec, tvec, camera.camera_matrix, np.array(camera.distortion))
        px = px.reshape(-1, 2)
        if (px.min() >= 20 and px[:, 0].max() <= camera.width_px - 21 and px[:, 1].max() <= camera.height_px - 21
                and math.degrees(math.acos(abs(r[2, 2]))) < 50):
            out.append((rvec, tvec))
    return out


def write_photos(folder: Path, count: int = 10, seed: int = 7) -> list[str]:
    """Write ``count`` photo-like board pictures (``board-NN.jpg``) into ``folder``; their paths."""
    rng = np.random.default_rng(seed)
    rays = _rays(TRUE_CAMERA, 2)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, (rvec, tvec) in enumerate(poses(count, rng)):
        path = folder / f"board-{i:02d}.jpg"
        path.write_bytes(degrade(render(rvec, tvec, rays), rng))
        paths.append(str(path))
    return paths


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python tests/checkerboard_photos.py OUT_DIR")
    for p in write_photos(Path(sys.argv[1])):
        print(p)
