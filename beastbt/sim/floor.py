"""The simulated floor: painted lines on a textured background, as an image and as geometry.

:class:`FloorMap` is built from a world file's ``floor:`` mapping. It is
rasterised once (OpenCV drawing) into a BGR image at ``resolution_m`` metres
per pixel, which :class:`beastbt.sim.camera_emulator.SimCamera` warps into
the camera's view; and it keeps the lines' centrelines as straight segments,
the ground TRUTH for scoring a line follower (:meth:`FloorMap.distance_to_line`)
and for checking detectors (:meth:`FloorMap.junctions`, :meth:`FloorMap.line_ends`).

World frame: east-north-up metres (x east, y north). The ``floor:`` form::

    floor:
      resolution_m: 0.005            # raster cell, metres (5 mm)
      margin_m: 1.0                  # plain floor drawn around the lines
      extent_m: {x: [-2, 6], y: [-2, 4]}   # optional explicit raster bounds
      background: {colour: 200, texture: 10, texture_scale_m: 0.02}
      lines:
        width_m: 0.019               # electrical tape
        colour: black                # grey level, [r, g, b] or a name
        paths:
          - path: [[0, 0], [3, 0], {arc: {center: [3, 0.5], radius_m: 0.5, from_deg: -90, to_deg: 90}}, [0, 1]]
            closed: true             # join the last point back to the first
          - {path: [[1.5, -0.5], [1.5, 1.5]], width_m: 0.025}   # per-path overrides
      lighting: {gradient: {direction_deg: 30, min_gain: 0.75, max_gain: 1.05}}
      shadows: [{rect: {center: [2, 0], size_m: [0.5, 0.3], angle_deg: 20}, darkness: 0.5, softness_m: 0.03},
                {circle: {center: [0, 1], radius_m: 0.2}, darkness: 0.4}]
      glare: [{center: [1, 1], radius_m: 0.1, strength: 0.8}]
      gaps: [{at: [2.5, 0], length_m: 0.04}]

An ``arc`` element expands to points on the circle from ``from_deg`` to
``to_deg`` (degrees CCW from east; counter-clockwise when ``to_deg >
from_deg``), joined by straight segments to its neighbours. Crossings and T
junctions arise wherever paths meet; gaps, shadows and glare change only the
picture, never the truth geometry.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Optional

import cv2
import numpy as np

from beastbt.core.schema_defaults import schema_default
from beastbt.vision.line_detector import junction_kind

MAX_RASTER_PIXELS = 40_000_000
"""Largest floor raster we agree to build (about 120 MB as BGR)."""

ARC_SAGITTA_M = 0.0005
"""Largest distance between an arc and its polyline approximation, metres."""

SUPERSAMPLING = 4
"""Lines are drawn at this many times the raster resolution, then averaged down (anti-aliasing)."""

PAINT_TILE_PX = 512
"""Lines are painted in tiles of this many raster pixels square (bounds the supersampled canvas to 4 MB)."""

JUNCTION_PROBE_RADIUS_M = 0.05
"""Radius of the circle used to count the arms meeting at a point, metres."""

NAMED_COLOURS_RGB: dict[str, tuple[int, int, int]] = {
    "black": (20, 20, 20),
    "dark_grey": (70, 70, 70),
    "grey": (128, 128, 128),
    "light_grey": (190, 190, 190),
    "white": (245, 245, 245),
    "yellow": (235, 200, 30),
    "orange": (240, 120, 20),
    "red": (200, 30, 30),
    "green": (30, 150, 60),
    "blue": (30, 60, 200),
}
"""Colours a world file may name, as (r, g, b) 0-255 (tape and floor paint, not pure primaries)."""

_GRADIENT = "/properties/lighting/properties/gradient/properties"


def _default(pointer: str, name: str) -> Any:
    """The floor schema's default for ``name`` at ``pointer`` (the one place a floor default is stated)."""
    return schema_default("parts/floor.schema.json#" + pointer, name)


# --- validation helpers ------------------------------------------------------------------
def _check_keys(d: Any, allowed: Sequence[str], what: str, required: Sequence[str] = ()) -> Mapping:
    """Return ``d`` if it is a mapping with only ``allowed`` keys and all ``required`` ones; else ValueError."""
    if not isinstance(d, Mapping):
        raise ValueError(f"{what}: expected a mapping, got {type(d).__name__}")
    for key in d:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), list(allowed), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ValueError(f"{what}: unknown key '{key}'{hint} (known keys: {', '.join(allowed)})")
    for key in required:
        if key not in d:
            raise ValueError(f"{what}: missing required key '{key}'")
    return d


def _number(v: Any, what: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{what}: expected a number, got {v!r}")
    if not lo <= v <= hi:
        raise ValueError(f"{what}: {v} is outside [{lo:g}, {hi:g}]")
    return float(v)


def _point(v: Any, what: str) -> tuple[float, float]:
    if not isinstance(v, Sequence) or isinstance(v, str) or len(v) != 2:
        raise ValueError(f"{what}: expected a point [x, y] in metres, got {v!r}")
    return _number(v[0], what), _number(v[1], what)


def parse_colour(v: Any, what: str) -> tuple[int, int, int]:
    """A colour from a world file as OpenCV BGR 0-255: a grey level, ``[r, g, b]`` or a name."""
    if isinstance(v, str):
        if v not in NAMED_COLOURS_RGB:
            close = difflib.get_close_matches(v, list(NAMED_COLOURS_RGB), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ValueError(f"{what}: unknown colour '{v}'{hint} (known: {', '.join(NAMED_COLOURS_RGB)})")
        r, g, b = NAMED_COLOURS_RGB[v]
        return b, g, r
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        grey = int(round(_number(v, what, 0, 255)))
        return grey, grey, grey
    if isinstance(v, Sequence) and len(v) == 3:
        r, g, b = (int(round(_number(c, what, 0, 255))) for c in v)
        return b, g, r
    raise ValueError(f"{what}: expected a grey level 0-255, [r, g, b] or a colour name, got {v!r}")


def _arc_points(d: Any, what: str) -> list[tuple[float, float]]:
    """Points along an ``arc`` element, spaced so the chord error stays below ARC_SAGITTA_M."""
    arc = _check_keys(d, ("center", "radius_m", "from_deg", "to_deg"), what, ("center", "radius_m", "from_deg", "to_deg"))
    cx, cy = _point(arc["center"], f"{what}.center")
    r = _number(arc["radius_m"], f"{what}.radius_m", 1e-3, 1e4)
    a0 = math.radians(_number(arc["from_deg"], f"{what}.from_deg"))
    a1 = math.radians(_number(arc["to_deg"], f"{what}.to_deg"))
    if a0 == a1:
        raise ValueError(f"{what}: from_deg and to_deg are equal (an arc needs a sweep)")
    step = 2.0 * math.acos(max(-1.0, 1.0 - ARC_SAGITTA_M / r))
    n = max(2, int(math.ceil(abs(a1 - a0) / step)) + 1)
    return [(cx + r * math.cos(a), cy + r * math.sin(a)) for a in np.linspace(a0, a1, n)]


@dataclass(frozen=True)
class FloorLine:
    """One painted path: centreline ``points`` (N, 2) in world metres, ``closed`` loop, width and BGR colour."""

    points: np.ndarray
    closed: bool
    width_m: float
    colour_bgr: tuple[int, int, int]

    def segments(self) -> np.ndarray:
        """The centreline as (M, 2, 2) segments [[x0, y0], [x1, y1]] in metres."""
        pts = np.vstack([self.points, self.points[:1]]) if self.closed else self.points
        return np.stack([pts[:-1], pts[1:]], axis=1)


def _point_segment_distances(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distances (N, M) from points (N, 2) to segments (M, 2, 2)."""
    a = segs[None, :, 0, :]
    ab = segs[None, :, 1, :] - a
    ap = p[:, None, :] - a
    denom = np.maximum((ab * ab).sum(-1), 1e-18)
    t = np.clip((ap * ab).sum(-1) / denom, 0.0, 1.0)
    d = ap - t[..., None] * ab
    return np.sqrt((d * d).sum(-1))


def floor_lines(f: Mapping) -> list[FloorLine]:
    """The painted lines of a world's ``floor:`` mapping (centrelines in world metres), without rasterising it.

    :meth:`FloorMap.from_dict` paints them; recordings draw them in Foxglove's 3D view and map. ValueError
    on bad input.
    """
    lines: list[FloorLine] = []
    if "lines" in f:
        ld = _check_keys(f["lines"], ("width_m", "colour", "paths"), "floor.lines", ("paths",))
        width = _number(ld.get("width_m", _default("/properties/lines/properties", "width_m")), "floor.lines.width_m", 0.001, 1.0)
        colour = parse_colour(ld.get("colour", _default("/properties/lines/properties", "colour")), "floor.lines.colour")
        paths = ld["paths"]
        if not isinstance(paths, Sequence) or isinstance(paths, str):
            raise ValueError("floor.lines.paths: expected a list of paths")
        for i, p in enumerate(paths):
            what = f"floor.lines.paths[{i}]"
            pd = _check_keys(p, ("path", "closed", "width_m", "colour"), what, ("path",))
            pts: list[tuple[float, float]] = []
            items = pd["path"]
            if not isinstance(items, Sequence) or isinstance(items, str):
                raise ValueError(f"{what}.path: expected a list of points [x, y] and arcs")
            for j, item in enumerate(items):
                if isinstance(item, Mapping):
                    _check_keys(item, ("arc",), f"{what}.path[{j}]", ("arc",))
                    new = _arc_points(item["arc"], f"{what}.path[{j}].arc")
                else:
                    new = [_point(item, f"{what}.path[{j}]")]
                for q in new:  # drop repeated points (an arc starting where the last point was)
                    if not pts or math.hypot(q[0] - pts[-1][0], q[1] - pts[-1][1]) > 1e-9:
                        pts.append(q)
            closed = pd.get("closed", _default("/$defs/path/properties", "closed"))
            if not isinstance(closed, bool):
                raise ValueError(f"{what}.closed: expected true or false, got {closed!r}")
            if closed and len(pts) > 2 and math.hypot(pts[0][0] - pts[-1][0], pts[0][1] - pts[-1][1]) < 1e-9:
                pts.pop()
            if len(pts) < 2:
                raise ValueError(f"{what}.path: a path needs at least two distinct points")
            lines.append(
                FloorLine(
                    points=np.array(pts, dtype=float),
                    closed=closed,
                    width_m=_number(pd.get("width_m", width), f"{what}.width_m", 0.001, 1.0),
                    colour_bgr=parse_colour(pd["colour"], f"{what}.colour") if "colour" in pd else colour,
                )
            )
    return lines


class FloorMap:
    """A floor with lines: a BGR raster for the camera and centreline segments for ground truth.

    Build it with :meth:`from_dict` from a world file's ``floor:`` mapping.
    ``rng`` drives the background texture, so a given seed gives the same floor.
    """

    def __init__(
        self,
        lines: list[FloorLine],
        resolution_m: float = 0.005,
        extent_m: Optional[tuple[float, float, float, float]] = None,
        margin_m: float = 1.0,
        background_bgr: tuple[int, int, int] = (200, 200, 200),
        texture: float = 8.0,
        texture_scale_m: float = 0.02,
        lighting: Optional[Mapping] = None,
        shadows: Sequence[Mapping] = (),
        glare: Sequence[Mapping] = (),
        gaps: Sequence[tuple[float, float, float]] = (),
        rng: Optional[np.random.Generator] = None,
    ) -> None:
        self.lines = list(lines)
        self.resolution_m = float(resolution_m)
        self.background_bgr = tuple(int(c) for c in background_bgr)
        self.gaps = list(gaps)
        segs = [ln.segments() for ln in self.lines]
        self.segments = np.concatenate(segs) if segs else np.zeros((0, 2, 2))
        """All centreline segments (M, 2, 2) in world metres."""
        self._seg_path = np.concatenate([np.full(len(s), i) for i, s in enumerate(segs)]) if segs else np.zeros(0, int)
        self._seg_index = np.concatenate([np.arange(len(s)) for s in segs]) if segs else np.zeros(0, int)
        if extent_m is None:
            if len(self.segments):
                pts = self.segments.reshape(-1, 2)
                lo, hi = pts.min(0) - margin_m, pts.max(0) + margin_m
            else:
                lo, hi = np.array([-margin_m, -margin_m]), np.array([margin_m, margin_m])
            extent_m = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
        self.x_min, self.x_max, self.y_min, self.y_max = extent_m
        if not (self.x_max > self.x_min and self.y_max > self.y_min):
            raise ValueError(f"floor.extent_m is empty: x {self.x_min}..{self.x_max}, y {self.y_min}..{self.y_max}")
        self.width_px = int(math.ceil((self.x_max - self.x_min) / self.resolution_m))
        self.height_px = int(math.ceil((self.y_max - self.y_min) / self.resolution_m))
        if self.width_px * self.height_px > MAX_RASTER_PIXELS:
            raise ValueError(
                f"floor raster would be {self.width_px}x{self.height_px} pixels; make floor.resolution_m coarser "
                f"(now {self.resolution_m} m) or floor.extent_m smaller"
            )
        res = self.resolution_m
        # Raster pixel centres (integers, as OpenCV has them) -> world metres; rows run north to south.
        self.world_from_raster = np.array([[res, 0.0, self.x_min + 0.5 * res], [0.0, -res, self.y_max - 0.5 * res], [0.0, 0.0, 1.0]])
        """3x3 affine map from raster (col, row) to world (x, y) metres."""
        self.raster_from_world = np.linalg.inv(self.world_from_raster)
        """3x3 affine map from world (x, y) metres to raster (col, row)."""
        self._junctions: Optional[list[tuple[float, float, str]]] = None
        self._line_ends: Optional[list[tuple[float, float]]] = None
        self.image = self._rasterise(texture, texture_scale_m, lighting or {}, shadows, glare, rng or np.random.default_rng(0))
        """The floor as a BGR uint8 image, ``height_px`` x ``width_px``; north up, east right."""

    # --- construction from a world file ------------------------------------------------------
    @classmethod
    def from_dict(cls, floor: Any, rng: Optional[np.random.Generator] = None) -> "FloorMap":
        """Build from a world file's ``floor:`` mapping (see the module docstring); ValueError on bad input."""
        f = _check_keys(floor, ("resolution_m", "margin_m", "extent_m", "background", "lines", "lighting", "shadows", "glare", "gaps"), "floor")
        res = _number(f.get("resolution_m", _default("/properties", "resolution_m")), "floor.resolution_m", 0.0005, 0.1)
        margin = _number(f.get("margin_m", _default("/properties", "margin_m")), "floor.margin_m", 0.0, 100.0)
        extent = None
        if "extent_m" in f:
            e = _check_keys(f["extent_m"], ("x", "y"), "floor.extent_m", ("x", "y"))
            ex, ey = _point(e["x"], "floor.extent_m.x"), _point(e["y"], "floor.extent_m.y")
            extent = (ex[0], ex[1], ey[0], ey[1])
        bg = _check_keys(f.get("background", {}), ("colour", "texture", "texture_scale_m"), "floor.background")
        background = parse_colour(bg.get("colour", _default("/properties/background/properties", "colour")), "floor.background.colour")
        texture = _number(bg.get("texture", _default("/properties/background/properties", "texture")), "floor.background.texture", 0.0, 100.0)
        texture_scale = _number(bg.get("texture_scale_m", _default("/properties/background/properties", "texture_scale_m")), "floor.background.texture_scale_m", res, 10.0)

        lines = floor_lines(f)

        lighting: dict = {}
        if "lighting" in f:
            li = _check_keys(f["lighting"], ("gradient",), "floor.lighting")
            if "gradient" in li:
                g = _check_keys(li["gradient"], ("direction_deg", "min_gain", "max_gain"), "floor.lighting.gradient")
                lighting = {
                    "direction_deg": _number(g.get("direction_deg", _default(_GRADIENT, "direction_deg")), "floor.lighting.gradient.direction_deg"),
                    "min_gain": _number(g.get("min_gain", _default(_GRADIENT, "min_gain")), "floor.lighting.gradient.min_gain", 0.0, 4.0),
                    "max_gain": _number(g.get("max_gain", _default(_GRADIENT, "max_gain")), "floor.lighting.gradient.max_gain", 0.0, 4.0),
                }
        shadows = []
        for i, s in enumerate(_as_list(f.get("shadows", []), "floor.shadows")):
            what = f"floor.shadows[{i}]"
            sd = _check_keys(s, ("rect", "circle", "darkness", "softness_m"), what)
            if ("rect" in sd) == ("circle" in sd):
                raise ValueError(f"{what}: give exactly one shape, 'rect' or 'circle'")
            shadow: dict = {
                "darkness": _number(sd.get("darkness", _default("/properties/shadows/items/properties", "darkness")), f"{what}.darkness", 0.0, 1.0),
                "softness_m": _number(sd.get("softness_m", _default("/properties/shadows/items/properties", "softness_m")), f"{what}.softness_m", 0.0, 5.0),
            }
            if "rect" in sd:
                r = _check_keys(sd["rect"], ("center", "size_m", "angle_deg"), f"{what}.rect", ("center", "size_m"))
                shadow["rect"] = (
                    _point(r["center"], f"{what}.rect.center"),
                    _point(r["size_m"], f"{what}.rect.size_m"),
                    _number(r.get("angle_deg", _default("/properties/shadows/items/properties/rect/properties", "angle_deg")), f"{what}.rect.angle_deg"),
                )
            else:
                c = _check_keys(sd["circle"], ("center", "radius_m"), f"{what}.circle", ("center", "radius_m"))
                shadow["circle"] = (_point(c["center"], f"{what}.circle.center"), _number(c["radius_m"], f"{what}.circle.radius_m", 0.0, 1e3))
            shadows.append(shadow)
        glare = []
        for i, g in enumerate(_as_list(f.get("glare", []), "floor.glare")):
            what = f"floor.glare[{i}]"
            gd = _check_keys(g, ("center", "radius_m", "strength"), what, ("center", "radius_m"))
            glare.append(
                {
                    "center": _point(gd["center"], f"{what}.center"),
                    "radius_m": _number(gd["radius_m"], f"{what}.radius_m", 1e-3, 100.0),
                    "strength": _number(gd.get("strength", _default("/properties/glare/items/properties", "strength")), f"{what}.strength", 0.0, 2.0),
                }
            )
        gaps = []
        for i, g in enumerate(_as_list(f.get("gaps", []), "floor.gaps")):
            what = f"floor.gaps[{i}]"
            gd = _check_keys(g, ("at", "length_m"), what, ("at", "length_m"))
            at = _point(gd["at"], f"{what}.at")
            gaps.append((at[0], at[1], _number(gd["length_m"], f"{what}.length_m", 0.0, 10.0)))
        return cls(
            lines,
            resolution_m=res,
            extent_m=extent,
            margin_m=margin,
            background_bgr=background,
            texture=texture,
            texture_scale_m=texture_scale,
            lighting=lighting,
            shadows=shadows,
            glare=glare,
            gaps=gaps,
            rng=rng,
        )

    # --- raster ------------------------------------------------------------------------------
    def world_to_raster(self, x_m: float, y_m: float) -> tuple[float, float]:
        """Raster (col, row) of a world point in metres (fractional; integers at pixel centres)."""
        return (x_m - self.x_min) / self.resolution_m - 0.5, (self.y_max - y_m) / self.resolution_m - 0.5

    def _to_px(self, pts: np.ndarray, shift: int) -> np.ndarray:
        """World points -> fixed-point raster coordinates for OpenCV drawing with ``shift`` bits."""
        cr = np.column_stack([(pts[:, 0] - self.x_min) / self.resolution_m - 0.5, (self.y_max - pts[:, 1]) / self.resolution_m - 0.5])
        return np.round(cr * (1 << shift)).astype(np.int32)

    def _rasterise(self, texture: float, texture_scale_m: float, lighting: Mapping, shadows: Sequence[Mapping], glare: Sequence[Mapping], rng: np.random.Generator) -> np.ndarray:
        h, w, res = self.height_px, self.width_px, self.resolution_m
        shift = 4  # sub-pixel drawing precision of shadows: 1/16 pixel
        img = np.empty((h, w, 3), np.float32)
        img[:] = np.array(self.background_bgr, np.float32)
        if texture > 0:
            # Low-frequency blotches (texture_scale_m) upsampled smoothly, plus fine grain.
            lo_w = max(2, int(math.ceil(w * res / texture_scale_m)) + 1)
            lo_h = max(2, int(math.ceil(h * res / texture_scale_m)) + 1)
            blotch = cv2.resize(rng.standard_normal((lo_h, lo_w)).astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
            blotch *= texture / max(float(blotch.std()), 1e-6)
            img += blotch[..., None]
        # Lines, grouped by look; gaps erase paint (their truth stays continuous).
        groups: dict[tuple[int, int, int], list[FloorLine]] = {}
        for ln in self.lines:
            groups.setdefault(ln.colour_bgr, []).append(ln)
        for colour, lns in groups.items():
            painted = self._paint(lns)
            if painted is None:
                continue
            (y0, x0), cover = painted
            y1, x1 = y0 + cover.shape[0], x0 + cover.shape[1]
            a = cover.astype(np.float32)[..., None] / 255.0
            sub = img[y0:y1, x0:x1]
            sub *= 1.0 - a
            sub += a * np.array(colour, np.float32)
        # Lighting: one multiplicative gain map (gradient x shadows), then additive glare.
        if lighting or shadows:
            gain = np.ones((h, w), np.float32)
            if lighting:
                a = math.radians(lighting["direction_deg"])
                cols = (np.arange(w, dtype=np.float32) + 0.5) * res * math.cos(a)
                rows = -(np.arange(h, dtype=np.float32) + 0.5) * res * math.sin(a)
                ramp = rows[:, None] + cols[None, :]
                ramp -= ramp.min()
                ramp /= max(float(ramp.max()), 1e-9)
                gain = (lighting["min_gain"] + (lighting["max_gain"] - lighting["min_gain"]) * ramp).astype(np.float32)
            for s in shadows:
                self._apply_shadow(gain, s, shift)
            img *= gain[..., None]
        for g in glare:
            cx, cy = self.world_to_raster(*g["center"])
            sigma = g["radius_m"] / res / 2.0
            r = int(math.ceil(3 * sigma))
            x0, x1 = max(0, int(cx) - r), min(w, int(cx) + r + 1)
            y0, y1 = max(0, int(cy) - r), min(h, int(cy) + r + 1)
            if x0 >= x1 or y0 >= y1:
                continue
            xx = np.arange(x0, x1, dtype=np.float32) - cx
            yy = np.arange(y0, y1, dtype=np.float32) - cy
            spot = np.exp(-(yy[:, None] ** 2 + xx[None, :] ** 2) / (2 * sigma * sigma)) * (255.0 * g["strength"])
            img[y0:y1, x0:x1] += spot[..., None]
        return np.clip(img, 0, 255).astype(np.uint8)

    def _paint(self, lines: Sequence[FloorLine]) -> Optional[tuple[tuple[int, int], np.ndarray]]:
        """Paint coverage (uint8 0-255) of ``lines`` minus the gaps: ((row0, col0), patch) or None if off the raster.

        Drawn without anti-aliasing at SUPERSAMPLING times the raster
        resolution and averaged down, tile by tile: OpenCV's own anti-aliased
        thick lines come out about 1.5 px too wide, by an amount that depends
        on the angle, which would make the tape wider than the world says.
        """
        res, ss, shift = self.resolution_m, SUPERSAMPLING, 3
        shapes: list[tuple[str, np.ndarray, float]] = []  # (kind, points in raster px, radius px)
        for ln in lines:
            # OpenCV's fill includes the pixels on both edges: half a supersampled pixel too wide each side.
            half = max(0.5 / ss, ln.width_m / res / 2.0 - 0.5 / ss)
            pts = np.column_stack([(ln.points[:, 0] - self.x_min) / res - 0.5, (self.y_max - ln.points[:, 1]) / res - 0.5])
            if ln.closed:
                pts = np.vstack([pts, pts[:1]])
            for p, q in zip(pts[:-1], pts[1:]):
                d = q - p
                n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-12) * half
                shapes.append(("quad", np.array([p + n, q + n, q - n, p - n]), 0.0))
            for p in pts[1:-1] if not ln.closed else pts[:-1]:  # round joins; ends stay square-cut
                shapes.append(("disc", p[None, :], half))
        if not shapes:
            return None
        allpts = np.vstack([sh[1] for sh in shapes])
        margin = max(ln.width_m for ln in lines) / res + 2
        c0 = max(0, int(math.floor(allpts[:, 0].min() - margin)))
        r0 = max(0, int(math.floor(allpts[:, 1].min() - margin)))
        c1 = min(self.width_px, int(math.ceil(allpts[:, 0].max() + margin)) + 1)
        r1 = min(self.height_px, int(math.ceil(allpts[:, 1].max() + margin)) + 1)
        if c0 >= c1 or r0 >= r1:
            return None
        gaps = [(np.array(self.world_to_raster(gx, gy)), glen / 2 / res) for gx, gy, glen in self.gaps]
        out = np.zeros((r1 - r0, c1 - c0), np.uint8)
        one = float(1 << shift)
        for tr in range(r0, r1, PAINT_TILE_PX):
            for tc in range(c0, c1, PAINT_TILE_PX):
                th, tw = min(PAINT_TILE_PX, r1 - tr), min(PAINT_TILE_PX, c1 - tc)
                canvas = np.zeros((th * ss, tw * ss), np.uint8)
                origin = np.array([tc, tr], float)

                def fixed(p: np.ndarray) -> np.ndarray:
                    # raster pixel centre c covers [c - 0.5, c + 0.5): supersampled centre (c - origin + 0.5) ss - 0.5
                    return np.round(((p - origin + 0.5) * ss - 0.5) * one).astype(np.int32)

                for kind, pts, radius in shapes:
                    if kind == "quad":
                        cv2.fillConvexPoly(canvas, fixed(pts), 255, cv2.LINE_8, shift)
                    else:
                        c = fixed(pts)[0]
                        cv2.circle(canvas, (int(c[0]), int(c[1])), int(round(radius * ss * one)), 255, -1, cv2.LINE_8, shift)
                for centre, radius in gaps:
                    c = fixed(centre[None, :])[0]
                    cv2.circle(canvas, (int(c[0]), int(c[1])), int(round(radius * ss * one)), 0, -1, cv2.LINE_8, shift)
                out[tr - r0 : tr - r0 + th, tc - c0 : tc - c0 + tw] = cv2.resize(canvas, (tw, th), interpolation=cv2.INTER_AREA)
        return (r0, c0), out

    def _apply_shadow(self, gain: np.ndarray, s: Mapping, shift: int) -> None:
        """Multiply ``gain`` by (1 - darkness) inside the shadow shape, with soft edges."""
        h, w, res = self.height_px, self.width_px, self.resolution_m
        soft_px = s["softness_m"] / res
        pad = int(math.ceil(3 * soft_px)) + 2
        if "rect" in s:
            (cx, cy), (sl, sw), ang = s["rect"]
            a = math.radians(ang)
            u, v = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
            c = np.array([cx, cy])
            poly = np.array([c + u * sl / 2 + v * sw / 2, c - u * sl / 2 + v * sw / 2, c - u * sl / 2 - v * sw / 2, c + u * sl / 2 - v * sw / 2])
        else:
            (cx, cy), rad = s["circle"]
            t = np.linspace(0, 2 * math.pi, 64, endpoint=False)
            poly = np.column_stack([cx + rad * np.cos(t), cy + rad * np.sin(t)])
        px = self._to_px(poly, 0)
        x0, y0 = max(0, px[:, 0].min() - pad), max(0, px[:, 1].min() - pad)
        x1, y1 = min(w, px[:, 0].max() + pad + 1), min(h, px[:, 1].max() + pad + 1)
        if x0 >= x1 or y0 >= y1:
            return
        mask = np.zeros((y1 - y0, x1 - x0), np.float32)
        cv2.fillPoly(mask, [self._to_px(poly, shift) - np.array([x0, y0]) * (1 << shift)], 1.0, cv2.LINE_AA, shift)
        if soft_px > 0.5:
            mask = cv2.GaussianBlur(mask, (0, 0), soft_px)
        gain[y0:y1, x0:x1] *= 1.0 - s["darkness"] * mask

    # --- truth geometry --------------------------------------------------------------------
    def distance_to_line(self, x_m: float, y_m: float) -> float:
        """Distance in metres from a world point to the nearest line centreline (inf with no lines)."""
        if not len(self.segments):
            return math.inf
        return float(_point_segment_distances(np.array([[x_m, y_m]]), self.segments).min())

    def distances_to_line(self, xy: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`distance_to_line` for (N, 2) world points, metres."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        if not len(self.segments):
            return np.full(len(xy), np.inf)
        return _point_segment_distances(xy, self.segments).min(axis=1)

    def nearest_on_line(self, x_m: float, y_m: float) -> tuple[float, float, float]:
        """Nearest centreline point (x, y metres) to a world point and the line's heading there (rad CCW from east).

        The heading follows the path's drawing direction.
        """
        d = _point_segment_distances(np.array([[x_m, y_m]]), self.segments)[0]
        i = int(np.argmin(d))
        a, b = self.segments[i]
        ab = b - a
        t = float(np.clip(np.dot([x_m, y_m] - a, ab) / max(float(ab @ ab), 1e-18), 0.0, 1.0))
        p = a + t * ab
        return float(p[0]), float(p[1]), math.atan2(ab[1], ab[0])

    def _arm_angles(self, x: float, y: float, radius_m: float = JUNCTION_PROBE_RADIUS_M) -> list[float]:
        """Directions (rad) in which centrelines leave a circle of ``radius_m`` around (x, y)."""
        a = self.segments[:, 0, :] - np.array([x, y])
        d = self.segments[:, 1, :] - self.segments[:, 0, :]
        qa = (d * d).sum(1)
        qb = 2 * (a * d).sum(1)
        qc = (a * a).sum(1) - radius_m**2
        disc = qb * qb - 4 * qa * qc
        angles: list[float] = []
        for sign in (-1.0, 1.0):
            with np.errstate(invalid="ignore", divide="ignore"):
                s = (-qb + sign * np.sqrt(np.maximum(disc, 0))) / (2 * np.maximum(qa, 1e-18))
            ok = (disc >= 0) & (s >= 0) & (s <= 1)
            pts = a[ok] + s[ok, None] * d[ok]
            angles.extend(np.arctan2(pts[:, 1], pts[:, 0]).tolist())
        unique: list[float] = []
        for ang in sorted(angles):  # a polyline vertex on the circle is hit by two segments
            if not unique or abs(math.remainder(ang - unique[-1], 2 * math.pi)) > math.radians(2):
                unique.append(ang)
        if len(unique) > 1 and abs(math.remainder(unique[0] - unique[-1], 2 * math.pi)) <= math.radians(2):
            unique.pop()
        return unique

    def junctions(self) -> list[tuple[float, float, str]]:
        """Where lines meet: (x, y, kind) in world metres, kind ``+`` (4+ arms), ``T`` or ``Y`` (3 arms).

        The kind follows :func:`beastbt.vision.line_detector.junction_kind`, the
        rule the detector uses, counting arms on a JUNCTION_PROBE_RADIUS_M circle.
        Computed from segment intersections (paths crossing, a path crossing
        itself, a path ending on another), merged within 3 cm. Two paths that
        simply continue one another are not a junction.
        """
        if self._junctions is None:
            self._junctions = self._find_junctions()
        return list(self._junctions)

    def _find_junctions(self) -> list[tuple[float, float, str]]:
        segs = self.segments
        m = len(segs)
        if m < 2:
            return []
        i, j = np.triu_indices(m, 1)
        same = self._seg_path[i] == self._seg_path[j]
        adjacent = same & (np.abs(self._seg_index[i] - self._seg_index[j]) == 1)
        # the closing segment of a closed path touches its first segment
        for p, ln in enumerate(self.lines):
            if ln.closed:
                n = len(ln.points)
                adjacent |= same & (self._seg_path[i] == p) & (((self._seg_index[i] == 0) & (self._seg_index[j] == n - 1)))
        i, j = i[~adjacent], j[~adjacent]
        p, r = segs[i, 0], segs[i, 1] - segs[i, 0]
        q, s = segs[j, 0], segs[j, 1] - segs[j, 0]
        rxs = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
        qp = q - p
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / rxs
            u = (qp[:, 0] * r[:, 1] - qp[:, 1] * r[:, 0]) / rxs
        tol = 1e-6
        lr, ls = np.linalg.norm(r, axis=1), np.linalg.norm(s, axis=1)
        ok = (np.abs(rxs) > 1e-12) & (t >= -tol / lr) & (t <= 1 + tol / lr) & (u >= -tol / ls) & (u <= 1 + tol / ls)
        pts = p[ok] + t[ok, None] * r[ok]
        clusters: list[list[float]] = []
        for x, y in pts.tolist():
            for c in clusters:
                if math.hypot(x - c[0] / c[2], y - c[1] / c[2]) < 0.03:
                    c[0] += x
                    c[1] += y
                    c[2] += 1
                    break
            else:
                clusters.append([x, y, 1])
        out = []
        for cx, cy, n in clusters:
            x, y = cx / n, cy / n
            kind = junction_kind(self._arm_angles(x, y))
            if kind is not None:
                out.append((x, y, kind))
        return out

    def line_ends(self) -> list[tuple[float, float]]:
        """Free ends of open paths (not touching any other line), world metres."""
        if self._line_ends is None:
            ends = []
            for ln in self.lines:
                if ln.closed:
                    continue
                for x, y in (ln.points[0], ln.points[-1]):
                    if len(self._arm_angles(float(x), float(y))) == 1:
                        ends.append((float(x), float(y)))
            self._line_ends = ends
        return list(self._line_ends)


def _as_list(v: Any, what: str) -> list:
    if v is None:
        return []
    if not isinstance(v, Sequence) or isinstance(v, str):
        raise ValueError(f"{what}: expected a list")
    return list(v)
