"""Pinhole camera geometry: where a point on the floor appears in the image, and back.

:class:`CameraGeometry` models an undistorted pinhole camera with square
pixels, built from the horizontal field of view and the image size, mounted
``height_m`` above a flat floor, ``x_offset_m`` ahead of the robot centre,
pitched ``pitch_deg`` down (and optionally panned ``pan_deg`` left). A calibrated camera
(``intrinsics``: the profile's ``camera.intrinsics:``, see :mod:`beastbt.vision.calibration`) takes its
focal lengths and principal point from there instead, scaled to the image size, and carries the lens's
distortion for the detectors (the floor mapping stays an ideal pinhole). Floor
points are in the robot body frame (x forward, y left, metres, origin at the
robot centre on the floor); pixels are (u right, v down) with integer values
at pixel centres, as OpenCV uses them.

Because the floor is a plane, the mapping floor -> image is a 3x3 homography;
the simulator composes it with the robot pose to render the camera's view of
a floor raster, and the line detector uses its inverse to look at the image
from above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Optional

import numpy as np

from beastbt.vision.calibration import CameraIntrinsics

if TYPE_CHECKING:  # only for the type of from_config's argument
    from beastbt.devices.camera import CameraConfig


@dataclass(frozen=True)
class CameraGeometry:
    """A pinhole camera over a flat floor: intrinsics from ``hfov_deg`` and size, extrinsics from the mounting.

    ``pitch_deg`` is the downward tilt of the optical axis below horizontal;
    ``pan_deg`` turns the camera left (CCW seen from above) about the vertical.
    """

    width_px: int = 320
    height_px: int = 240
    hfov_deg: float = 62.2
    height_m: float = 0.20
    pitch_deg: float = 40.0
    x_offset_m: float = 0.10
    y_offset_m: float = 0.0
    pan_deg: float = 0.0
    intrinsics: Optional[CameraIntrinsics] = None
    """The calibrated lens (at its own image size); None: the ideal pinhole of ``hfov_deg``."""

    def __post_init__(self) -> None:
        if self.width_px < 2 or self.height_px < 2:
            raise ValueError(f"image size must be at least 2x2 pixels, got {self.width_px}x{self.height_px}")
        if not 1.0 < self.hfov_deg < 179.0:
            raise ValueError(f"hfov_deg must be in (1, 179) deg, got {self.hfov_deg}")
        if not self.height_m > 0.0:
            raise ValueError(f"height_m must be > 0 m, got {self.height_m}")
        # Everything below depends only on the fields; compute it once.
        c = self.intrinsics
        if c is None:
            fx = fy = (self.width_px / 2.0) / math.tan(math.radians(self.hfov_deg) / 2.0)
            cx = (self.width_px - 1) / 2.0
            cy = (self.height_px - 1) / 2.0
        else:  # calibrated at c's size: scale to ours (pixel centres: u + 0.5 scales)
            sx, sy = self.width_px / c.width_px, self.height_px / c.height_px
            fx, fy = c.fx_px * sx, c.fy_px * sy
            cx, cy = (c.cx_px + 0.5) * sx - 0.5, (c.cy_px + 0.5) * sy - 0.5
        k = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        th = math.radians(self.pitch_deg)
        ps = math.radians(self.pan_deg)
        fwd = np.array([math.cos(th) * math.cos(ps), math.cos(th) * math.sin(ps), -math.sin(th)])
        right = np.array([math.sin(ps), -math.cos(ps), 0.0])
        down = np.cross(fwd, right)
        r_cam_body = np.vstack([right, down, fwd])  # rows: camera x, y, z axes in body coordinates
        t_body = np.array([self.x_offset_m, self.y_offset_m, self.height_m])
        image_from_ground = k @ np.column_stack([r_cam_body[:, 0], r_cam_body[:, 1], -r_cam_body @ t_body])
        object.__setattr__(self, "_k", k)
        object.__setattr__(self, "_r", r_cam_body)
        object.__setattr__(self, "_t", t_body)
        object.__setattr__(self, "_h", image_from_ground / image_from_ground[2, 2] if abs(image_from_ground[2, 2]) > 1e-12 else image_from_ground)
        object.__setattr__(self, "_h_inv", np.linalg.inv(image_from_ground))

    # --- construction ----------------------------------------------------------------
    @classmethod
    def from_config(cls, config: "CameraConfig") -> "CameraGeometry":
        """The geometry of a configured camera (its size, mounting and calibrated ``intrinsics`` if any)."""
        m = config.mounting
        raw = getattr(config, "intrinsics", None)
        return cls(
            intrinsics=CameraIntrinsics.from_dict(raw) if raw is not None else None,
            width_px=config.width_px,
            height_px=config.height_px,
            hfov_deg=m.hfov_deg,
            height_m=m.height_m,
            pitch_deg=m.pitch_deg,
            x_offset_m=m.x_offset_m,
        )

    def scaled_to(self, width_px: int, height_px: int) -> "CameraGeometry":
        """The same camera delivering ``width_px`` x ``height_px`` images (same field of view)."""
        if (width_px, height_px) == (self.width_px, self.height_px):
            return self
        return replace(self, width_px=int(width_px), height_px=int(height_px))

    def with_pan_tilt(self, pan_rad: float, tilt_rad: float) -> "CameraGeometry":
        """The camera after a gimbal turned it ``pan_rad`` left and ``tilt_rad`` up from its mounting."""
        if pan_rad == 0.0 and tilt_rad == 0.0:
            return self
        return replace(self, pan_deg=self.pan_deg + math.degrees(pan_rad), pitch_deg=self.pitch_deg - math.degrees(tilt_rad))

    # --- intrinsics ------------------------------------------------------------------
    @property
    def focal_px(self) -> float:
        """Focal length in pixels (same on both axes)."""
        return float(self._k[0, 0])  # type: ignore[attr-defined]

    @property
    def camera_matrix(self) -> np.ndarray:
        """The 3x3 intrinsic matrix K (pixels)."""
        return self._k.copy()  # type: ignore[attr-defined]

    @property
    def dist_coeffs(self) -> np.ndarray:
        """The lens's distortion (OpenCV's k1, k2, p1, p2, k3; no unit): zeros without a calibration."""
        if self.intrinsics is None:
            return np.zeros(5)
        return np.array(self.intrinsics.distortion, dtype=float)

    @property
    def horizon_v(self) -> float:
        """Image row of the horizon (pixels); rows below it (larger v) see the floor."""
        return float(self._k[1, 2] - self._k[1, 1] * math.tan(math.radians(self.pitch_deg)))  # type: ignore[attr-defined]

    @property
    def camera_from_body(self) -> np.ndarray:
        """3x4 matrix [R | -R t] from body points (x forward, y left, z up, metres) to the camera frame.

        Camera frame: x right, y down, z along the optical axis (metres); pixels are K times it, divided by z.
        """
        return np.column_stack([self._r, -self._r @ self._t])  # type: ignore[attr-defined]

    # --- floor <-> image -------------------------------------------------------------
    @property
    def image_from_ground(self) -> np.ndarray:
        """3x3 homography from floor points (x forward, y left, metres, body frame) to pixels (u, v)."""
        return self._h.copy()  # type: ignore[attr-defined]

    @property
    def ground_from_image(self) -> np.ndarray:
        """3x3 homography from pixels to floor points (valid only below the horizon)."""
        return self._h_inv.copy()  # type: ignore[attr-defined]

    def ground_to_pixel(self, x_fwd_m: float, y_left_m: float) -> Optional[tuple[float, float]]:
        """Pixel (u, v) where the floor point (x forward, y left, metres) appears; None if behind the camera."""
        p = self._r @ (np.array([x_fwd_m, y_left_m, 0.0]) - self._t)  # type: ignore[attr-defined]
        if p[2] <= 1e-9:
            return None
        k = self._k  # type: ignore[attr-defined]
        return float(k[0, 0] * p[0] / p[2] + k[0, 2]), float(k[1, 1] * p[1] / p[2] + k[1, 2])

    def pixel_to_ground(self, u: float, v: float) -> Optional[tuple[float, float]]:
        """Floor point (x forward, y left, metres, body frame) seen at pixel (u, v); None at or above the horizon."""
        k = self._k  # type: ignore[attr-defined]
        ray_cam = np.array([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], 1.0])
        ray = self._r.T @ ray_cam  # type: ignore[attr-defined]
        if ray[2] >= -1e-9:
            return None
        lam = -self.height_m / ray[2]
        return float(self._t[0] + lam * ray[0]), float(self._t[1] + lam * ray[1])  # type: ignore[attr-defined]

    def pixels_to_ground(self, uv: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`pixel_to_ground`: (N, 2) pixels -> (N, 2) floor points, NaN above the horizon."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        hom = np.column_stack([uv, np.ones(len(uv))]) @ self._h_inv.T  # type: ignore[attr-defined]
        out = np.full((len(uv), 2), np.nan)
        ok = uv[:, 1] > self.horizon_v + 1e-6
        out[ok] = hom[ok, :2] / hom[ok, 2:3]
        return out

    def ground_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`ground_to_pixel`: (N, 2) floor points -> (N, 2) pixels, NaN behind the camera."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        p = (np.column_stack([xy, np.zeros(len(xy))]) - self._t) @ self._r.T  # type: ignore[attr-defined]
        out = np.full((len(xy), 2), np.nan)
        ok = p[:, 2] > 1e-9
        k = self._k  # type: ignore[attr-defined]
        out[ok, 0] = k[0, 0] * p[ok, 0] / p[ok, 2] + k[0, 2]
        out[ok, 1] = k[1, 1] * p[ok, 1] / p[ok, 2] + k[1, 2]
        return out

    def nearest_visible_x_m(self) -> Optional[float]:
        """Forward distance (m, from the robot centre) of the nearest floor the image shows on its centre column."""
        p = self.pixel_to_ground((self.width_px - 1) / 2.0, self.height_px - 1.0)
        return None if p is None else p[0]

    # --- robot pose and floor raster ----------------------------------------------------
    def image_from_world(self, x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
        """3x3 homography from world floor points (ENU metres) to pixels, robot at (x, y, yaw CCW from east)."""
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        # body = R(-yaw) (world - position)
        body_from_world = np.array([[c, s, -(c * x_m + s * y_m)], [-s, c, s * x_m - c * y_m], [0.0, 0.0, 1.0]])
        return self._h @ body_from_world  # type: ignore[attr-defined]

    def image_from_raster(self, x_m: float, y_m: float, yaw_rad: float, world_from_raster: np.ndarray) -> np.ndarray:
        """3x3 homography from floor-raster pixels (col, row) to image pixels for a robot at (x, y, yaw).

        ``world_from_raster`` maps raster pixel centres to world ENU metres
        (see :attr:`beastbt.sim.floor.FloorMap.world_from_raster`).
        """
        return self.image_from_world(x_m, y_m, yaw_rad) @ world_from_raster
