"""The simulated camera: renders what the robot's camera would see of the floor.

:class:`SimCamera` implements the :class:`~beastbt.devices.interfaces.FrameSource`
protocol (``isOpened``/``read``/``release``), so the real
:class:`beastbt.devices.camera.Camera` driver reads it exactly as it reads a
``cv2.VideoCapture``. The runner calls :meth:`SimCamera.update` with the
robot's true pose; :meth:`SimCamera.read` warps the floor raster of a
:class:`~beastbt.sim.floor.FloorMap` into the image with one
``cv2.warpPerspective`` (floor raster -> world -> body -> image homography,
including the gimbal's pan/tilt), only for the image rows below the horizon.
With a :class:`~beastbt.sim.scenery.Scenery` it also draws the world around
the floor: a ground texture where the world has no ``floor:`` (sampled the same
way, wrapping around its periodic tile), the sky or a ceiling above the horizon,
and walls, obstacles and persons standing up (:mod:`beastbt.sim.scenery`).
Camera effects (:class:`CameraEffects`): exposure flicker, vignetting,
sensor noise and motion blur from the true speed, all driven by the
``numpy.random.Generator`` handed in, so a seed gives the same pictures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

import cv2
import numpy as np

from beastbt.core.schema_defaults import schema_defaults
from beastbt.core.config import dataclass_from_dict
from beastbt.sim.cpu_account import CAMERA, SIM_CPU
from beastbt.sim.floor import FloorMap
from beastbt.sim.markers import MarkerPainter, PlanarMarker
from beastbt.sim.scenery import FINE_GROUND_M, Scenery, SceneryRenderer, ground_canvas, ground_world_from_canvas
from beastbt.sim.truth import RobotTruth
from beastbt.vision.camera_model import CameraGeometry

NOISE_BANK_SIZE = 8
"""Pre-drawn sensor-noise fields; each frame picks one at a random offset (drawing fresh noise costs milliseconds)."""

NOISE_BANK_MARGIN_PX = 16
"""Extra rows/columns in each noise field, so that random offsets decorrelate frames."""


@dataclass
@schema_defaults("parts/camera_effects.schema.json")
class CameraEffects:
    """Imperfections of the simulated camera (world file ``camera_effects:``). Zero turns an effect off."""

    # Standard deviation of per-pixel sensor noise, grey levels (0-255 scale).
    noise_std: float
    # Standard deviation of the frame-to-frame exposure (brightness) gain, fraction (0.03 = 3 %).
    exposure_jitter: float
    # Darkening of the image corners by the lens, fraction at the corners (0.25 = 25 % darker).
    vignetting: float
    # Exposure time for motion blur, seconds: the image smears by speed x exposure.
    # 0 turns motion blur off.
    exposure_s: float
    # Grey level rendered above the horizon in a world with floor: (elsewhere the scenery draws a sky), 0-255.
    sky_grey: int
    # Probability that a read() returns no frame (a dropped frame), 0-1.
    drop_probability: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.noise_std <= 100.0:
            raise ValueError(f"camera_effects.noise_std must be in [0, 100] grey levels, got {self.noise_std}")
        if not 0.0 <= self.exposure_jitter <= 1.0:
            raise ValueError(f"camera_effects.exposure_jitter must be in [0, 1], got {self.exposure_jitter}")
        if not 0.0 <= self.vignetting < 1.0:
            raise ValueError(f"camera_effects.vignetting must be in [0, 1), got {self.vignetting}")
        if not 0.0 <= self.exposure_s <= 1.0:
            raise ValueError(f"camera_effects.exposure_s must be in [0, 1] s, got {self.exposure_s}")
        if not 0 <= self.sky_grey <= 255:
            raise ValueError(f"camera_effects.sky_grey must be in [0, 255], got {self.sky_grey}")
        if not 0.0 <= self.drop_probability <= 1.0:
            raise ValueError(f"camera_effects.drop_probability must be in [0, 1], got {self.drop_probability}")

    @classmethod
    def from_dict(cls, d: Any) -> "CameraEffects":
        """Build from a world file dict; unknown keys or bad values raise ``ValueError``."""
        return dataclass_from_dict(cls, d, "camera_effects")

    @classmethod
    def none(cls) -> "CameraEffects":
        """A perfect camera: no noise, flicker, vignetting or blur."""
        return cls(noise_std=0.0, exposure_jitter=0.0, vignetting=0.0, exposure_s=0.0)


class SimCamera:
    """A frame source that renders the floor as seen from the robot's true pose.

    ``geometry`` gives image size, field of view and mounting; the truth's
    ``pan_rad``/``tilt_rad`` turn the camera further (pan left, tilt up).
    Frames are BGR uint8 ``(height_px, width_px, 3)``. ``scenery`` adds the
    ground, sky, walls and obstacles; ``persons_xy`` says where the scenery's
    persons are now ((N, 2) m, world frame), read at each frame. ``markers``: the world's tags and QR
    boards (:mod:`beastbt.sim.markers`), drawn over the scenery.
    """

    def __init__(self, floor: FloorMap, geometry: CameraGeometry, rng: np.random.Generator,
                 effects: Optional[CameraEffects] = None, scenery: Optional[Scenery] = None,
                 persons_xy: Optional[Callable[[], Any]] = None, markers: Sequence[PlanarMarker] = ()) -> None:
        self.floor = floor
        self._markers = MarkerPainter(markers) if markers else None
        self.scenery = scenery if scenery is not None and not scenery.empty else None
        self.persons_xy = persons_xy
        self._painter = SceneryRenderer(self.scenery) if self.scenery is not None else None
        self._ground: Optional[np.ndarray] = None
        self._ground_far_bgr = np.zeros(3, np.uint8)
        self._ground_far: Optional[np.ndarray] = None
        if self.scenery is not None and self.scenery.ground is not None:
            self._ground = ground_canvas(self.scenery.ground, self.scenery.seed, 0)
            self._ground_far = ground_canvas(self.scenery.ground, self.scenery.seed, 1)
            # Ground farther than about 30 m is finer than a pixel: it shows as the texture's average colour.
            self._ground_far_bgr = np.rint(self._ground_far.reshape(-1, 3).mean(axis=0)).astype(np.uint8)
        self.geometry = geometry
        self.rng = rng
        self.effects = effects if effects is not None else CameraEffects()
        self.truth = RobotTruth()
        self.frames_rendered = 0
        """Frames produced by :meth:`read` so far."""
        self._opened = True
        self._unplugged = False
        self._geom_cache: tuple[tuple[float, float], CameraGeometry] = ((0.0, 0.0), geometry)
        h, w = geometry.height_px, geometry.width_px
        self._out = np.empty((h, w, 3), np.uint8)
        self._sky = np.array([self.effects.sky_grey] * 3, np.uint8)
        self._border = tuple(float(c) for c in floor.background_bgr)
        e = self.effects
        self._noise_bank: Optional[tuple[np.ndarray, np.ndarray]] = None
        """The noise fields as (up, down): each pixel's noise is up - down, one of them zero (uint8 both)."""
        if e.noise_std > 0:
            m = NOISE_BANK_MARGIN_PX
            bank = rng.standard_normal((NOISE_BANK_SIZE, h + m, w + m, 3), dtype=np.float32) * np.float32(e.noise_std)
            noise = np.clip(np.rint(bank), -127, 127).astype(np.int16)
            # Two saturating uint8 operations (add the positive part, subtract the negative one) give exactly
            # the saturated sum with the signed noise, several times faster than one add of uint8 and int16.
            self._noise_bank = (np.clip(noise, 0, None).astype(np.uint8), np.clip(-noise, 0, None).astype(np.uint8))
        self._vignette: Optional[np.ndarray] = None
        if e.vignetting > 0:
            yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
            r2 = ((xx - (w - 1) / 2) / (w / 2)) ** 2 + ((yy - (h - 1) / 2) / (h / 2)) ** 2
            gain_map = np.clip(1.0 - e.vignetting * r2 / 2.0, 0.0, 1.0) * 255.0
            self._vignette = np.repeat(np.round(gain_map)[..., None], 3, axis=2).astype(np.uint8)

    # --- the simulator side ------------------------------------------------------------
    def update(self, truth: RobotTruth) -> None:
        """Set the robot's true pose, speeds and gimbal angles for the next frames."""
        self.truth = truth

    def unplug(self) -> None:
        """Make the camera vanish: reads fail and it cannot be reopened until :meth:`replug`."""
        self._unplugged = True
        self._opened = False

    def replug(self) -> None:
        """Connect the camera again (the driver still has to reopen it)."""
        self._unplugged = False

    def reopen(self) -> "SimCamera":
        """What the driver's ``open_source`` calls: opens again unless unplugged; returns self."""
        self._opened = not self._unplugged
        return self

    # --- the FrameSource side ------------------------------------------------------------
    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        """True while the camera is connected and not released."""
        return self._opened and not self._unplugged

    def release(self) -> None:
        """Close the camera (reads fail until :meth:`reopen`)."""
        self._opened = False

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """Render the current view: ``(True, frame)``, or ``(False, None)`` when closed or a frame drops."""
        if not self.isOpened():
            return False, None
        if self.effects.drop_probability > 0 and self.rng.random() < self.effects.drop_probability:
            return False, None
        t = self.truth
        persons = self.persons_xy() if self.persons_xy is not None else None
        frame = self.render(t.x, t.y, t.yaw, t.v_mps, t.w_rps, t.pan_rad, t.tilt_rad, persons)
        self.frames_rendered += 1
        return True, frame

    # --- rendering ---------------------------------------------------------------------
    def _geometry_for(self, pan_rad: float, tilt_rad: float) -> CameraGeometry:
        key, geom = self._geom_cache
        if key != (pan_rad, tilt_rad):
            geom = self.geometry.with_pan_tilt(pan_rad, tilt_rad)
            self._geom_cache = ((pan_rad, tilt_rad), geom)
        return geom

    def render(self, x_m: float, y_m: float, yaw_rad: float, v_mps: float = 0.0, w_rps: float = 0.0,
               pan_rad: float = 0.0, tilt_rad: float = 0.0, persons_xy: Optional[Any] = None) -> np.ndarray:
        """The camera image (BGR uint8, a new array) for the robot at (x, y metres, yaw rad) with all effects.

        ``persons_xy``: where the scenery's persons stand ((N, 2) m, world frame); None draws no person.
        Its CPU time is the simulator's (:mod:`beastbt.sim.cpu_account`), in whichever process it renders.
        """
        outer = SIM_CPU.enter(CAMERA)
        try:
            return self._render(x_m, y_m, yaw_rad, v_mps, w_rps, pan_rad, tilt_rad, persons_xy)
        finally:
            SIM_CPU.leave(outer)

    def _render(self, x_m: float, y_m: float, yaw_rad: float, v_mps: float, w_rps: float, pan_rad: float,
                tilt_rad: float, persons_xy: Optional[Any]) -> np.ndarray:
        geom = self._geometry_for(pan_rad, tilt_rad)
        h, w = geom.height_px, geom.width_px
        out = self._out
        # Rows at or just below the horizon see the floor at huge distances: start a
        # little lower, where a pixel covers less than about 30 m of floor.
        v0 = max(0, min(h, int(math.floor(geom.horizon_v + geom.focal_px * 0.007)) + 1))
        ground = self._ground
        if ground is not None:
            if v0 > 0:
                sky_rows = max(0, min(v0, int(math.floor(geom.horizon_v)) + 1))
                assert self._painter is not None
                self._painter.draw_sky(out, geom, sky_rows)
                out[sky_rows:v0] = self._ground_far_bgr
            if v0 < h:
                self._draw_ground(out, geom, x_m, y_m, yaw_rad, v0)
        elif v0 > 0:
            out[:v0] = self._sky
        if ground is None and v0 < h:
            img_from_raster = geom.image_from_raster(x_m, y_m, yaw_rad, self.floor.world_from_raster)
            shift = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, -v0], [0.0, 0.0, 1.0]])
            sub_from_raster = shift @ img_from_raster
            cv2.warpPerspective(
                self.floor.image,
                sub_from_raster,
                (w, h - v0),
                dst=out[v0:],
                flags=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=self._border,
            )
        if self._painter is not None:
            self._painter.draw_solids(out, geom, x_m, y_m, yaw_rad, persons_xy)
        if self._markers is not None:
            self._markers.draw(out, geom, x_m, y_m, yaw_rad)
        img = out
        e = self.effects
        if e.exposure_s > 0:
            img = self._motion_blur(img, geom, v_mps, w_rps)
        gain = 1.0 + (e.exposure_jitter * float(self.rng.standard_normal()) if e.exposure_jitter > 0 else 0.0)
        if self._vignette is not None:
            # one saturating integer multiply does vignetting and exposure together
            img = cv2.multiply(img, self._vignette, scale=gain / 255.0, dtype=cv2.CV_8U)
        elif gain != 1.0:
            img = cv2.convertScaleAbs(img, alpha=gain)
        if self._noise_bank is not None:
            k = int(self.rng.integers(NOISE_BANK_SIZE))
            oy, ox = (int(v) for v in self.rng.integers(NOISE_BANK_MARGIN_PX + 1, size=2))
            up, down = self._noise_bank
            img = cv2.add(img, up[k, oy : oy + h, ox : ox + w], dst=None if img is out else img)
            img = cv2.subtract(img, down[k, oy : oy + h, ox : ox + w], dst=img)
        return img.copy() if img is out else img

    def _draw_ground(self, out: np.ndarray, geom: CameraGeometry, x_m: float, y_m: float, yaw_rad: float,
                     v0: int) -> None:
        """Warp the ground canvases into rows ``[v0, h)``: the coarse one beyond FINE_GROUND_M, the fine one nearer."""
        assert self._ground is not None and self._ground_far is not None
        h, w = geom.height_px, geom.width_px
        # Row of the centre column that sees the floor FINE_GROUND_M ahead of the camera.
        depression = math.atan2(geom.height_m, FINE_GROUND_M) - math.radians(geom.pitch_deg)
        v_fine = max(v0, min(h, int(math.ceil((h - 1) / 2.0 + geom.focal_px * math.tan(depression)))))
        img_from_world = geom.image_from_world(x_m, y_m, yaw_rad)
        for canvas, level, top, bottom in ((self._ground_far, 1, v0, v_fine), (self._ground, 0, v_fine, h)):
            if top >= bottom:
                continue
            shift = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, -top], [0.0, 0.0, 1.0]])
            cv2.warpPerspective(canvas, shift @ img_from_world @ ground_world_from_canvas(x_m, y_m, level),
                                (w, bottom - top), dst=out[top:bottom], flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_WRAP)

    def _motion_blur(self, img: np.ndarray, geom: CameraGeometry, v_mps: float, w_rps: float) -> np.ndarray:
        """Smear along the image motion of the floor point at the image centre during the exposure."""
        e = self.effects
        centre = geom.pixel_to_ground((geom.width_px - 1) / 2.0, (geom.height_px - 1) / 2.0 + geom.height_px / 4.0)
        if centre is None:
            return img
        x, y = centre
        dt = e.exposure_s
        # Floor point in the body frame after the robot moved v*dt forward and turned w*dt.
        a = -w_rps * dt
        xr, yr = x - v_mps * dt, y
        x2, y2 = math.cos(a) * xr - math.sin(a) * yr, math.sin(a) * xr + math.cos(a) * yr
        p1, p2 = geom.ground_to_pixel(x, y), geom.ground_to_pixel(x2, y2)
        if p1 is None or p2 is None:
            return img
        du, dv = p2[0] - p1[0], p2[1] - p1[1]
        length = math.hypot(du, dv)
        if length < 1.0:
            return img
        n = min(31, int(math.ceil(length)) | 1)
        kernel = np.zeros((n, n), np.float32)
        c = n // 2
        cv2.line(kernel, (int(round(c - du / 2)), int(round(c - dv / 2))), (int(round(c + du / 2)), int(round(c + dv / 2))), 1.0, 1)
        kernel /= kernel.sum()
        return cv2.filter2D(img, -1, kernel)


class SimMjpegCamera:
    """A fake V4L2 MJPEG camera on the simulator: each frame the :class:`SimCamera` renders, handed over as the
    JPEG a USB camera's own encoder would give (``read_jpeg``), so that the robot's camera path (the JPEG
    passed to the console untouched, decoded only for vision) runs end to end on the simulator.

    Encoding stands for the camera's hardware, which does it for free: a benchmark counts it apart from the
    console. It renders only when read, as the :class:`SimCamera` does. ``quality`` is the JPEG quality (1-100).
    """

    compressed = True

    def __init__(self, camera: SimCamera, quality: int = 80) -> None:
        self.camera = camera
        self.quality = int(quality)
        self.frames_encoded = 0
        """Frames handed over as JPEG so far."""

    def reopen(self) -> "SimMjpegCamera":
        """What the driver's ``open_source`` calls: the simulated camera opens again unless unplugged."""
        self.camera.reopen()
        return self

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        """True while the simulated camera is connected and not released."""
        return self.camera.isOpened()

    def release(self) -> None:
        """Close it (reads fail until :meth:`reopen`)."""
        self.camera.release()

    def read_jpeg(self) -> tuple[bool, Optional[bytes]]:
        """Render the current view and give it as JPEG bytes: ``(True, jpeg)``, or ``(False, None)``."""
        ok, frame = self.camera.read()
        if not ok or frame is None:
            return False, None
        outer = SIM_CPU.enter(CAMERA)  # the camera's hardware encodes: the simulator's work
        try:
            done, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, self.quality])
        finally:
            SIM_CPU.leave(outer)
        self.frames_encoded += int(done)
        return (True, buf.tobytes()) if done else (False, None)

    def read(self) -> tuple[bool, Optional[np.ndarray]]:
        """Render the current view as pixels (what :meth:`read_jpeg` would encode)."""
        return self.camera.read()
