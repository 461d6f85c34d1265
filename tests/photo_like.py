"""Photo-like test images for the vision detectors: a scene rendered clean, then made to look like a real photo.

The scene is a textured wall with a printed tag, a QR board or a coloured patch on it, seen by a
320x240 camera (the robot's) through :class:`~beastbt.vision.camera_model.CameraGeometry` and
:func:`~beastbt.sim.markers.draw_planar`, so the truth (where the tag is) is known. :func:`degrade`
then adds what a cheap camera adds: a perspective (the sheet turned away), defocus blur, sensor
noise, uneven light (a brightness ramp and a dark corner) and a JPEG round trip at quality 60.

Run it to look at the images: ``python tests/photo_like.py OUT_DIR`` writes one PNG per case.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from beastbt.sim.markers import MarkerPainter, markers_of_world
from beastbt.vision.camera_model import CameraGeometry

CAMERA = CameraGeometry(width_px=320, height_px=240, hfov_deg=62.2, height_m=0.2, pitch_deg=0.0, x_offset_m=0.0)
"""The robot's camera looking straight ahead from 0.2 m (the gimbal tilted up to level)."""


@dataclass(frozen=True)
class Degradation:
    """How far from a clean render: blur sigma (px), noise std (grey levels), JPEG quality, light ramp (0-1)."""

    blur_px: float = 0.0
    noise_std: float = 0.0
    jpeg_quality: int = 0
    light_ramp: float = 0.0


CLEAN = Degradation()
PHOTO = Degradation(blur_px=0.8, noise_std=6.0, jpeg_quality=60, light_ramp=0.5)
"""What a cheap camera in a corridor gives: a little defocus, noise, JPEG at 60, light falling off by half."""


def wall(rng: np.random.Generator, geom: CameraGeometry = CAMERA) -> np.ndarray:
    """A plain painted wall with a faint texture and a darker floor band (BGR)."""
    h, w = geom.height_px, geom.width_px
    img = np.full((h, w, 3), (176, 188, 196), np.float32)
    img += rng.normal(0.0, 4.0, (h, w, 1)).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), 2.0)
    horizon = int(geom.horizon_v)
    img[max(0, horizon + 30):] *= 0.7
    return np.clip(img, 0, 255).astype(np.uint8)


def scene(rng: np.random.Generator, tags: list[dict] = (), qr_boards: list[dict] = (),  # type: ignore[assignment]
          patches: list[tuple[tuple[int, int, int], tuple[int, int, int, int]]] = (),  # type: ignore[assignment]
          geom: CameraGeometry = CAMERA) -> np.ndarray:
    """The clean picture of a wall with ``tags`` and ``qr_boards`` (world-file items, robot at the origin facing
    east: x ahead, y left) and coloured ``patches`` ((BGR), (x, y, w, h) px)."""
    img = wall(rng, geom)
    for bgr, (x, y, w, h) in patches:
        cv2.rectangle(img, (x, y), (x + w - 1, y + h - 1), bgr, -1)
    MarkerPainter(markers_of_world(list(tags), list(qr_boards))).draw(img, geom, 0.0, 0.0, 0.0)
    return img


def degrade(img: np.ndarray, rng: np.random.Generator, how: Degradation = PHOTO) -> np.ndarray:
    """``img`` as a cheap camera would give it (see :class:`Degradation`): a new BGR array."""
    out = img.astype(np.float32)
    if how.blur_px > 0:
        out = cv2.GaussianBlur(out, (0, 0), how.blur_px)
    if how.light_ramp > 0:
        h, w = out.shape[:2]
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        ramp = 1.0 - how.light_ramp * (xx / w) * 0.7 - how.light_ramp * 0.3 * ((yy / h) ** 2)
        out *= ramp[..., None]
    if how.noise_std > 0:
        out += rng.normal(0.0, how.noise_std, out.shape).astype(np.float32)
    out8 = np.clip(out + 0.5, 0, 255).astype(np.uint8)
    if how.jpeg_quality:
        ok, buf = cv2.imencode(".jpg", out8, [cv2.IMWRITE_JPEG_QUALITY, how.jpeg_quality])
        assert ok
        out8 = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out8


def tag_at(tag_id: int, ahead_m: float, left_m: float, turned_deg: float = 0.0, z_m: float = 0.2,
           family: str = "apriltag_36h11", size_m: float = 0.16) -> dict:
    """A tag ``ahead_m`` in front and ``left_m`` to the left of the robot, its face toward the robot turned by
    ``turned_deg`` (a perspective: the sheet seen at an angle)."""
    return {"id": tag_id, "family": family, "size_m": size_m, "x": ahead_m, "y": left_m, "z_m": z_m,
            "facing_deg": 180.0 + turned_deg}


def main(out_dir: str) -> None:
    """Write the clean and photo-like versions of a few scenes as PNG files in ``out_dir``."""
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    cases = {
        "tag": scene(rng, tags=[tag_at(3, 1.2, 0.1, 35.0)]),
        "qr": scene(rng, qr_boards=[{"text": "dock-a", "size_m": 0.2, "x": 1.0, "y": 0.0, "z_m": 0.2,
                                     "facing_deg": 200.0}]),
        "red": scene(rng, patches=[((30, 30, 200), (200, 90, 40, 50))]),
    }
    for name, img in cases.items():
        cv2.imwrite(str(folder / f"{name}_clean.png"), img)
        cv2.imwrite(str(folder / f"{name}_photo.png"), degrade(img, rng))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "photo_like")
