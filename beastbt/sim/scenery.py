"""What the simulated camera sees besides painted lines: the ground, the sky, walls and obstacles standing up.

:class:`Scenery` is plain data (it crosses to the console's process): the
world's walls and obstacles, and which ground it has. :func:`ground_texture`
builds the ground once per kind and seed as a periodic BGR tile (its right
edge continues its left, its bottom its top), which the camera samples through
its floor homography with wrap-around (:func:`ground_world_from_canvas`), so
the ground covers the whole world at the cost of one perspective warp. :class:`SceneryRenderer` draws, on a
rendered frame, the sky above the horizon and the walls, boxes, cylinders and
persons as flat-shaded vertical faces, far to near (the painter's algorithm:
each face is short, so sorting by distance occludes correctly).

Heights are not in the world file: walls are :data:`WALL_HEIGHT_M` tall with a
dark skirting board, boxes :data:`BOX_HEIGHT_M`, cylinders
:data:`CYLINDER_HEIGHT_M`, persons :data:`PERSON_HEIGHT_M`. The ground is
low in contrast on purpose: its darkest speck is far from the line detector's
``contrast_ratio`` (a line is 60 % darker than the floor around it), so it is
never taken for tape.

World frame: east-north-up metres; camera frame as
:attr:`beastbt.vision.camera_model.CameraGeometry.camera_from_body` gives it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Literal, Optional, Sequence

import cv2
import numpy as np

from beastbt.sim.obstacles import BoxObstacle, CylinderObstacle, Obstacle, Person
from beastbt.vision.camera_model import CameraGeometry

GroundKind = Literal["grass", "tiles"]
"""``grass`` outdoors (a world without walls), ``tiles`` indoors (a world with walls)."""

WALL_HEIGHT_M = 2.0
"""Height of every wall, m (above the camera, so a tilted-up camera sees walls, not over them)."""

SKIRTING_M = 0.08
"""Height of the dark skirting board at the foot of a wall, m: it marks where the wall meets the floor."""

BOX_HEIGHT_M = 0.5
"""Height of a box obstacle (a bench, a planter), m."""

CYLINDER_HEIGHT_M = 1.0
"""Height of a cylinder obstacle (a post, a bollard), m."""

PERSON_HEIGHT_M = 1.7
"""Height of a person, m: legs to 0.85 m, torso to 1.5 m, head above."""

CYLINDER_SIDES = 16
"""Flat faces around a cylinder or a person."""

FACE_LENGTH_M = 0.5
"""Walls and box sides are cut into faces at most this long, so that sorting faces by distance occludes right."""

NEAR_M = 0.02
"""Faces are clipped this far in front of the camera (m), so that a wall beside the camera projects finitely."""

TEXTURE_RES_M = 0.01
"""Ground texture cell, m (1 cm: the 3 x 3 canvas stays within a few megabytes and the processor's caches)."""

TEXTURE_TILE_PX = 500
"""Ground texture period in cells (5 m): the pattern repeats every 5 m, beyond what one view shows in detail.

A multiple of 5 (GROUND_LEVELS) and of TILE_SIZE_M / TEXTURE_RES_M."""

TILE_SIZE_M = 0.5
"""Indoor floor tiles, m square (TEXTURE_TILE_PX x TEXTURE_RES_M is a whole number of them)."""

LIGHT_DIRECTION_DEG = 210.0
"""Where the light comes from, deg CCW from east (the sun in the south-west): faces toward it are brighter."""

SUBPIXEL_BITS = 4
"""Fixed-point bits of the polygon vertices handed to OpenCV (1/16 pixel)."""

# Colours, BGR 0-255.
WALL_BGR = (196, 212, 222)
# The skirting is 40 % darker than the floor tiles: a clear foot, short of what the line detector takes for tape (60 %).
SKIRTING_BGR = (100, 112, 126)
BOX_BGR = (60, 105, 150)
PAINT_BGR = {"red": (40, 40, 200), "green": (60, 160, 50), "blue": (190, 90, 30), "yellow": (40, 200, 220)}
"""A painted box's colours (``colour:`` of a world's box), saturated enough for the colour finder under shading."""
CYLINDER_BGR = (125, 125, 130)
LEGS_BGR = (110, 72, 48)
SHIRT_BGR = (60, 60, 185)
HEAD_BGR = (140, 172, 215)
SKY_HORIZON_BGR = (235, 215, 190)
SKY_ZENITH_BGR = (205, 150, 90)
CEILING_BGR = (228, 230, 232)


@dataclass(frozen=True)
class Scenery:
    """The world around the floor as the camera draws it: walls (x1, y1, x2, y2 m), obstacles, ground and seed.

    ``ground`` None keeps the world's own floor raster (a world with ``floor:``)
    and, above the horizon, the camera's plain ``sky_grey``; otherwise the ground
    texture of that kind covers the world and the sky (``grass``) or a ceiling
    (``tiles``) is drawn above the horizon. Persons are drawn where the caller
    says they are now (:meth:`SceneryRenderer.draw_solids`), in the order of
    :attr:`persons`.
    """

    walls: tuple[tuple[float, float, float, float], ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    ground: Optional[GroundKind] = None
    seed: int = 0

    @classmethod
    def of_world(cls, walls: Sequence[Any], obstacles: Sequence[Obstacle], has_floor: bool, seed: int) -> "Scenery":
        """The scenery of a world: its walls (anything with x1..y2), obstacles; tiles indoors, grass outdoors."""
        segs = tuple((float(w.x1), float(w.y1), float(w.x2), float(w.y2)) for w in walls)
        ground: Optional[GroundKind] = None if has_floor else ("tiles" if segs else "grass")
        return cls(walls=segs, obstacles=tuple(obstacles), ground=ground, seed=int(seed))

    @property
    def persons(self) -> list[Person]:
        """The walking persons among the obstacles, in world order."""
        return [o for o in self.obstacles if isinstance(o, Person)]

    @property
    def empty(self) -> bool:
        """True when there is nothing to draw beyond the world's own floor."""
        return self.ground is None and not self.walls and not self.obstacles


# --- the ground -------------------------------------------------------------------------
def _periodic_noise(rng: np.random.Generator, n: int, sigma_px: float) -> np.ndarray:
    """Smooth noise on an ``n`` x ``n`` torus (a Gaussian blur of white noise, done in the Fourier domain), unit std."""
    f = np.fft.fftfreq(n).astype(np.float32)
    r2 = f[:, None] ** 2 + f[None, :] ** 2
    spectrum = np.fft.rfft2(rng.standard_normal((n, n)).astype(np.float32))
    spectrum *= np.exp(-2.0 * math.pi**2 * sigma_px**2 * r2[:, : n // 2 + 1])
    out = np.fft.irfft2(spectrum, s=(n, n)).astype(np.float32)
    return out / max(float(out.std()), 1e-9)


@lru_cache(maxsize=4)
def ground_texture(kind: GroundKind, seed: int) -> np.ndarray:
    """The periodic ground tile of ``kind`` (BGR uint8, TEXTURE_TILE_PX square at TEXTURE_RES_M), same for a seed.

    Cached: treat it as read-only.
    """
    n = TEXTURE_TILE_PX
    rng = np.random.default_rng([seed, 1 if kind == "grass" else 2])
    cell = TEXTURE_RES_M
    if kind == "grass":
        patches = _periodic_noise(rng, n, 0.6 / cell)  # lawn patches about a metre across
        tufts = _periodic_noise(rng, n, 0.04 / cell)  # tufts a few centimetres across
        grain = _periodic_noise(rng, n, 0.6)  # blades
        lush = np.array([48, 128, 62], np.float32)
        dry = np.array([70, 150, 128], np.float32)
        mix = np.clip(0.35 + 0.25 * patches, 0.0, 1.0)[..., None]
        img = lush * (1.0 - mix) + dry * mix
        img *= (1.0 + 0.07 * tufts + 0.05 * grain)[..., None]
    else:
        tiles_per_side = int(round(n * cell / TILE_SIZE_M))
        pitch = n // tiles_per_side
        base = np.array([172, 184, 192], np.float32)
        shade = 1.0 + 0.035 * rng.standard_normal((tiles_per_side, tiles_per_side)).astype(np.float32)
        img = base * np.kron(shade, np.ones((pitch, pitch), np.float32))[..., None]
        img *= (1.0 + 0.025 * _periodic_noise(rng, n, 0.03 / cell) + 0.015 * _periodic_noise(rng, n, 1.0))[..., None]
        grout = np.zeros(n, bool)
        grout[np.arange(n) % pitch < max(1, round(0.01 / cell))] = True  # a 1 cm joint, 12 % darker: never tape
        img[grout, :] *= 0.88
        img[:, grout] *= 0.88
    return np.clip(img, 0, 255).astype(np.uint8)


GROUND_LEVELS = ((1, 3), (5, 9))
"""The ground's two sampling levels: (cells of the tile averaged into one, tiles per canvas side).

Level 0 is the tile itself, 3 x 3 (the ground within 5 m); level 1 is the
tile averaged 5 x 5 into 5 cm cells, 9 x 9 (the ground within 20 m), so that
the far ground, where one pixel spans many cells, shows their average instead
of flickering.
"""

FINE_GROUND_M = 4.0
"""Image rows that see the ground nearer than this (m, on the centre column) sample level 0; farther rows level 1."""


@lru_cache(maxsize=4)
def ground_canvas(kind: GroundKind, seed: int, level: int = 0) -> np.ndarray:
    """The ground tile of ``kind`` at sampling ``level`` (GROUND_LEVELS), repeated to a square canvas (read-only).

    What the camera samples; see :func:`ground_world_from_canvas`.
    """
    shrink, tiles = GROUND_LEVELS[level]
    tile = ground_texture(kind, seed)
    if shrink > 1:
        n = TEXTURE_TILE_PX // shrink
        tile = cv2.resize(tile, (n, n), interpolation=cv2.INTER_AREA)
    return np.tile(tile, (tiles, tiles, 1))


def ground_world_from_canvas(x_m: float, y_m: float, level: int = 0) -> np.ndarray:
    """3x3 affine map from :func:`ground_canvas` (col, row) to world (x east, y north) m, for a camera at (x, y).

    The canvas is placed, by whole periods of the tile, so that (x, y) lies in
    its middle tile: the ground within (tiles - 1) / 2 periods of the camera
    samples inside the canvas. OpenCV's wrap-around border is several times
    slower than an inside sample, so only the ground beyond wraps.
    """
    shrink, tiles = GROUND_LEVELS[level]
    r = TEXTURE_RES_M * shrink
    period = TEXTURE_TILE_PX * TEXTURE_RES_M
    half = tiles // 2
    west = period * (math.floor(x_m / period) - half)
    north = period * (math.floor(y_m / period) + half + 1)
    return np.array([[r, 0.0, west + 0.5 * r], [0.0, -r, north - 0.5 * r], [0.0, 0.0, 1.0]])


# --- solid faces ------------------------------------------------------------------------
@dataclass
class _Faces:
    """Quads standing in the world: corners (F, 4, 3) m, outward normals (F, 3), BGR colours (F, 3)."""

    quads: np.ndarray
    normals: np.ndarray
    colours: np.ndarray
    two_sided: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    @staticmethod
    def concat(parts: Sequence["_Faces"]) -> "_Faces":
        """All faces of ``parts`` in one set, in order."""
        parts = [p for p in parts if len(p.quads)]
        if not parts:
            return _Faces(np.zeros((0, 4, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool))
        return _Faces(np.concatenate([p.quads for p in parts]), np.concatenate([p.normals for p in parts]),
                      np.concatenate([p.colours for p in parts]), np.concatenate([p.two_sided for p in parts]))


def _upright(a: tuple[float, float], b: tuple[float, float], z0: float, z1: float, colour: Sequence[int],
             two_sided: bool, max_len: float = FACE_LENGTH_M) -> _Faces:
    """The vertical strip over the segment a -> b from height z0 to z1, cut into faces at most ``max_len`` long.

    Its normal points to the right of a -> b (outward for a counter-clockwise outline).
    """
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    length = math.hypot(dx, dy)
    if length <= 1e-9:
        return _Faces.concat([])
    k = max(1, int(math.ceil(length / max_len)))
    s = np.linspace(0.0, 1.0, k + 1)
    x, y = ax + s * dx, ay + s * dy
    quads = np.empty((k, 4, 3))
    quads[:, 0, :2] = np.column_stack([x[:-1], y[:-1]])
    quads[:, 1, :2] = np.column_stack([x[1:], y[1:]])
    quads[:, 2, :2] = quads[:, 1, :2]
    quads[:, 3, :2] = quads[:, 0, :2]
    quads[:, :2, 2] = z0
    quads[:, 2:, 2] = z1
    normal = np.array([dy / length, -dx / length, 0.0])
    return _Faces(quads, np.tile(normal, (k, 1)), np.tile(np.asarray(colour, float), (k, 1)), np.full(k, two_sided))


def _ring(n: int = CYLINDER_SIDES) -> np.ndarray:
    """The unit circle as ``n`` points, counter-clockwise."""
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.column_stack([np.cos(t), np.sin(t)])


def _prism(outline: np.ndarray, z0: float, z1: float, colour: Sequence[int]) -> _Faces:
    """The sides of an upright prism over a counter-clockwise outline (N, 2) m, from z0 to z1 m."""
    pts = [tuple(p) for p in outline.tolist()]
    return _Faces.concat([_upright(pts[i], pts[(i + 1) % len(pts)], z0, z1, colour, False)
                          for i in range(len(pts))])


def _person_template() -> _Faces:
    """A person at the origin with radius 1 (x, y scaled by the radius later): legs, shirt and head."""
    ring = _ring()
    return _Faces.concat([_prism(ring, 0.0, 0.85, LEGS_BGR), _prism(ring, 0.85, 1.5, SHIRT_BGR),
                          _prism(ring * 0.45, 1.5, PERSON_HEIGHT_M, HEAD_BGR)])


class SceneryRenderer:
    """Draws a :class:`Scenery`'s sky and standing things onto frames of one camera (see the module docstring)."""

    def __init__(self, scenery: Scenery) -> None:
        self.scenery = scenery
        indoor = scenery.ground == "tiles"
        self.sky_horizon = np.array(CEILING_BGR if indoor else SKY_HORIZON_BGR, np.float32)
        self.sky_zenith = np.array(CEILING_BGR if indoor else SKY_ZENITH_BGR, np.float32)
        parts = []
        for x1, y1, x2, y2 in scenery.walls:
            parts.append(_upright((x1, y1), (x2, y2), 0.0, SKIRTING_M, SKIRTING_BGR, True))
            parts.append(_upright((x1, y1), (x2, y2), SKIRTING_M, WALL_HEIGHT_M, WALL_BGR, True))
        for o in scenery.obstacles:
            if isinstance(o, BoxObstacle):
                # corners() run counter-clockwise, as _prism wants them
                paint = PAINT_BGR.get(o.colour, BOX_BGR) if o.colour else BOX_BGR
                parts.append(_prism(np.array(o.corners()), 0.0, BOX_HEIGHT_M, paint))
                top = np.array([[*c, BOX_HEIGHT_M] for c in o.corners()], float)[None]
                parts.append(_Faces(top, np.array([[0.0, 0.0, 1.0]]), np.array([paint], float) * 1.1,
                                    np.zeros(1, bool)))
            elif isinstance(o, CylinderObstacle):
                parts.append(_prism(np.array([o.x, o.y]) + o.radius_m * _ring(), 0.0, CYLINDER_HEIGHT_M, CYLINDER_BGR))
        self.static = _Faces.concat(parts)
        self._static_centres = self.static.quads.mean(axis=1) if len(self.static.quads) else np.zeros((0, 3))
        self._person = _person_template()
        self._person_radii = np.array([p.radius_m for p in scenery.persons], float)
        light = math.radians(LIGHT_DIRECTION_DEG)
        self._light = np.array([math.cos(light), math.sin(light), 0.0])

    def person_faces(self, persons_xy: Optional[np.ndarray]) -> _Faces:
        """The faces of the persons standing at ``persons_xy`` (N, 2) m (one row per person of the scenery)."""
        if persons_xy is None or not len(self._person_radii):
            return _Faces.concat([])
        xy = np.asarray(persons_xy, float).reshape(-1, 2)[: len(self._person_radii)]
        t = self._person
        quads = np.repeat(t.quads[None], len(xy), axis=0)
        quads[..., :2] *= self._person_radii[: len(xy), None, None, None]
        quads[..., :2] += xy[:, None, None, :]
        n = len(xy)
        return _Faces(quads.reshape(-1, 4, 3), np.tile(t.normals, (n, 1)), np.tile(t.colours, (n, 1)),
                      np.tile(t.two_sided, n))

    # --- drawing ---------------------------------------------------------------------
    def draw_sky(self, out: np.ndarray, geom: CameraGeometry, rows: int) -> None:
        """Fill image rows ``[0, rows)`` with the sky (or ceiling), brighter toward the horizon."""
        if rows <= 0:
            return
        v = np.arange(rows, dtype=np.float32)
        elevation = np.arctan2(geom.horizon_v - v, geom.focal_px)
        f = np.clip(elevation / math.radians(50.0), 0.0, 1.0)[:, None]
        colours = self.sky_horizon * (1.0 - f) + self.sky_zenith * f
        out[:rows] = np.rint(colours).astype(np.uint8)[:, None, :]

    def draw_solids(self, out: np.ndarray, geom: CameraGeometry, x_m: float, y_m: float, yaw_rad: float,
                    persons_xy: Optional[np.ndarray] = None) -> int:
        """Draw walls, obstacles and persons seen by the camera on robot pose (x, y m, yaw rad); faces drawn."""
        persons = self.person_faces(persons_xy)
        faces = _Faces.concat([self.static, persons]) if len(persons.quads) else self.static
        if not len(faces.quads):
            return 0
        # world -> camera: body = R(-yaw) (world - robot), camera = [R | -R t] body
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        body_from_world = np.array([[c, s, 0.0, -(c * x_m + s * y_m)], [-s, c, 0.0, s * x_m - c * y_m],
                                    [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
        cam_from_world = geom.camera_from_body @ body_from_world  # (3, 4)
        rot, trans = cam_from_world[:, :3], cam_from_world[:, 3]
        cam_pos = -rot.T @ trans  # camera centre in the world
        pts = faces.quads @ rot.T + trans  # (F, 4, 3) camera coordinates
        k = geom.camera_matrix
        fx, cx, cy = k[0, 0], k[0, 2], k[1, 2]
        w, h = geom.width_px, geom.height_px
        x, y, z = pts[..., 0], pts[..., 1], pts[..., 2]
        # Cull a face when all its corners are outside one plane of the view (near, left, right, top, bottom):
        # linear tests in camera coordinates, right for corners behind the camera too.
        outside = ((z < NEAR_M).all(axis=1) | (fx * x + (cx + 1.0) * z < 0).all(axis=1)
                   | (fx * x + (cx - w) * z > 0).all(axis=1) | (fx * y + (cy + 1.0) * z < 0).all(axis=1)
                   | (fx * y + (cy - h) * z > 0).all(axis=1))
        centres = faces.quads.mean(axis=1)
        to_cam = cam_pos - centres
        facing = np.einsum("ij,ij->i", faces.normals, to_cam) > 0
        idx = np.nonzero(~outside & (facing | faces.two_sided))[0]
        if not len(idx):
            return 0
        dist = np.hypot(to_cam[idx, 0], to_cam[idx, 1])
        order = idx[np.argsort(-dist, kind="stable")]  # far to near
        # Flat shading: vertical faces by the light's direction (a two-sided face by its lit side), tops bright.
        normals = faces.normals[order]
        lam = normals @ self._light
        lam = np.where(faces.two_sided[order], np.abs(lam), np.maximum(lam, 0.0))
        gain = np.where(normals[:, 2] > 0.5, 1.0, 0.62 + 0.38 * lam)
        colours = np.clip(faces.colours[order] * gain[:, None], 0, 255).tolist()
        one = float(1 << SUBPIXEL_BITS)
        limit = 8.0 * max(w, h) * one
        sel = pts[order]
        near = (sel[..., 2] < NEAR_M).any(axis=1)
        zc = np.maximum(sel[..., 2:3], NEAR_M)
        uv = np.clip(np.rint((sel[..., :2] / zc * fx + k[:2, 2]) * one), -limit, limit).astype(np.int32)
        for j in range(len(order)):
            poly = uv[j]
            if near[j]:
                clipped = _clip_near(sel[j])
                if len(clipped) < 3:
                    continue
                poly = np.clip(np.rint((clipped[:, :2] / clipped[:, 2:3] * fx + k[:2, 2]) * one), -limit, limit)
                poly = poly.astype(np.int32)
            cv2.fillConvexPoly(out, poly, colours[j], cv2.LINE_8, SUBPIXEL_BITS)
        return len(order)


def _clip_near(poly: np.ndarray) -> np.ndarray:
    """The part of a convex polygon (N, 3, camera frame) with z >= NEAR_M (Sutherland-Hodgman on one plane)."""
    out = []
    n = len(poly)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        pin, qin = p[2] >= NEAR_M, q[2] >= NEAR_M
        if pin:
            out.append(p)
        if pin != qin:
            t = (NEAR_M - p[2]) / (q[2] - p[2])
            out.append(p + t * (q - p))
    return np.array(out).reshape(-1, 3)


__all__ = ["Scenery", "SceneryRenderer", "GroundKind", "ground_texture", "ground_canvas", "ground_world_from_canvas",
           "WALL_HEIGHT_M", "SKIRTING_M", "BOX_HEIGHT_M", "CYLINDER_HEIGHT_M", "PERSON_HEIGHT_M"]
