"""An occupancy grid map in ROS ``map_server`` format: a YAML file beside a PGM (or PNG) image.

The format is the one Nav2's ``map_server`` and ``map_saver`` read and write
(``nav2_map_server/src/map_io.cpp``), so a map built by beastbt opens in RViz
and Nav2, and theirs open here::

    image: office.pgm          # relative to the YAML's folder
    mode: trinary              # trinary (default), scale or raw
    resolution: 0.05           # metres per pixel
    origin: [-3.2, -7.5, 0.0]  # pose (x m, y m, yaw rad) of the image's lower-left pixel in the map frame
    negate: 0                  # 0: white is free, black is occupied
    occupied_thresh: 0.65
    free_thresh: 0.196

:class:`OccupancyMap` holds the grid as ``nav_msgs/OccupancyGrid`` does:
``data[row, col]`` with row 0 the *bottom* row of the image (the one at
``origin``), values ``-1`` unknown, ``0`` free, ``100`` occupied (and the
in-between percentages of ``scale`` mode). The map frame is beastbt's: x
forward and y left of the robot's pose when mapping began, as with
slam_toolbox; the YAML's ``origin`` only places the image in that frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional, Union

import numpy as np

from beastbt.core.errors import InvalidInput, Position, Problem
from beastbt.core.yaml_source import load_yaml

if TYPE_CHECKING:
    from beastbt.core.file_refs import FileRefs

UNKNOWN = -1
"""Occupancy value of a cell nothing has seen (``nav_msgs/OccupancyGrid``'s -1)."""
FREE = 0
"""Occupancy value of a free cell (percent)."""
OCCUPIED = 100
"""Occupancy value of an occupied cell (percent)."""

PGM_OCCUPIED = 0
"""Pixel ``map_saver`` writes for an occupied cell (black)."""
PGM_FREE = 254
"""Pixel ``map_saver`` writes for a free cell (white)."""
PGM_UNKNOWN = 205
"""Pixel ``map_saver`` writes for an unknown cell (grey)."""

DEFAULT_OCCUPIED_THRESH = 0.65
"""``map_saver``'s default: a pixel darker than this probability is occupied."""
DEFAULT_FREE_THRESH = 0.196
"""A pixel lighter than this probability is free. ROS 1's ``map_saver`` writes 0.196, the darkness of its own
unknown grey (205): map_server's test is ``occ < free_thresh``, so with it the grey reads back as unknown in every
map_server, where Nav2's default of 0.25 would read it as free."""

MAX_CELLS = 40_000_000
"""Largest map read or made (cells): 316 m x 316 m at 5 cm. Beyond it a file is refused rather than exhausting
memory on a Raspberry Pi."""

_MODES = ("trinary", "scale", "raw")
_HINT = "a map is a map_server YAML (image, resolution, origin, negate, occupied_thresh, free_thresh) beside its image"


@dataclass(frozen=True)
class OccupancyMap:
    """A 2D occupancy grid in the map frame (metres, radians), as ``nav_msgs/OccupancyGrid``.

    ``data`` is ``int8`` of shape (rows, cols), row 0 at ``origin_y`` (the
    image's bottom row), values -1 (unknown) or 0..100 (percent occupied).
    ``origin_*`` is the pose of the lower-left corner of cell (0, 0) in the
    map frame; ``resolution_m`` the side of a cell.
    """

    data: np.ndarray
    resolution_m: float
    origin_x: float = 0.0
    origin_y: float = 0.0
    origin_yaw: float = 0.0
    occupied_thresh: float = DEFAULT_OCCUPIED_THRESH
    free_thresh: float = DEFAULT_FREE_THRESH
    source: Optional[str] = field(default=None, compare=False)
    """The YAML file the map was read from, if any (for messages)."""

    def __post_init__(self) -> None:
        if self.data.ndim != 2 or self.data.dtype != np.int8:
            raise ValueError(f"OccupancyMap.data must be a 2D int8 array, got {self.data.dtype} {self.data.shape}")
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0):
            raise ValueError(f"OccupancyMap.resolution_m must be > 0, got {self.resolution_m}")

    # -- shape ---------------------------------------------------------------------------------------------------
    @property
    def rows(self) -> int:
        """Number of cells along the map's y (image height)."""
        return int(self.data.shape[0])

    @property
    def cols(self) -> int:
        """Number of cells along the map's x (image width)."""
        return int(self.data.shape[1])

    @property
    def width_m(self) -> float:
        """Extent along x (m)."""
        return self.cols * self.resolution_m

    @property
    def height_m(self) -> float:
        """Extent along y (m)."""
        return self.rows * self.resolution_m

    def occupied(self) -> np.ndarray:
        """Boolean mask of cells at or above the occupied threshold (``data >= occupied_thresh * 100``)."""
        return self.data >= int(math.ceil(self.occupied_thresh * 100))

    def free(self) -> np.ndarray:
        """Boolean mask of known cells below the free threshold."""
        return (self.data >= 0) & (self.data <= int(math.floor(self.free_thresh * 100)))

    def unknown(self) -> np.ndarray:
        """Boolean mask of cells nothing has seen."""
        return self.data < 0

    # -- frames --------------------------------------------------------------------------------------------------
    def to_cells(self, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
        """Map-frame points (m) to (col, row) cell indices, floor of the position; may lie outside the grid."""
        dx = np.asarray(x, dtype=float) - self.origin_x
        dy = np.asarray(y, dtype=float) - self.origin_y
        if self.origin_yaw:
            c, s = math.cos(self.origin_yaw), math.sin(self.origin_yaw)
            dx, dy = c * dx + s * dy, -s * dx + c * dy
        return (np.floor(dx / self.resolution_m).astype(np.int64), np.floor(dy / self.resolution_m).astype(np.int64))

    def cell_centres(self, col: Any, row: Any) -> tuple[np.ndarray, np.ndarray]:
        """Cell indices to the map-frame coordinates of the cells' centres (m)."""
        u = (np.asarray(col, dtype=float) + 0.5) * self.resolution_m
        v = (np.asarray(row, dtype=float) + 0.5) * self.resolution_m
        if self.origin_yaw:
            c, s = math.cos(self.origin_yaw), math.sin(self.origin_yaw)
            u, v = c * u - s * v, s * u + c * v
        return u + self.origin_x, v + self.origin_y

    def inside(self, col: Any, row: Any) -> np.ndarray:
        """Whether cell indices lie on the grid."""
        col, row = np.asarray(col), np.asarray(row)
        return (col >= 0) & (col < self.cols) & (row >= 0) & (row < self.rows)

    def value_at(self, x: float, y: float) -> int:
        """The occupancy of the cell holding map-frame point (x, y) (m): -1 unknown (also off the map), 0..100."""
        col, row = self.to_cells(x, y)
        if not self.inside(col, row):
            return UNKNOWN
        return int(self.data[int(row), int(col)])

    def with_data(self, data: np.ndarray) -> "OccupancyMap":
        """The same map geometry with other cell values."""
        return replace(self, data=data)


def empty_map(width_m: float, height_m: float, resolution_m: float, origin_x: float, origin_y: float,
              fill: int = UNKNOWN) -> OccupancyMap:
    """A map of ``width_m`` x ``height_m`` (m) at ``resolution_m`` (m per cell), its lower-left corner at
    (``origin_x``, ``origin_y``), every cell ``fill``."""
    cols = max(1, int(math.ceil(width_m / resolution_m - 1e-9)))
    rows = max(1, int(math.ceil(height_m / resolution_m - 1e-9)))
    if rows * cols > MAX_CELLS:
        raise ValueError(f"a map of {cols} x {rows} cells is larger than {MAX_CELLS} cells")
    return OccupancyMap(np.full((rows, cols), fill, dtype=np.int8), resolution_m, origin_x, origin_y)


# -- reading -----------------------------------------------------------------------------------------------------

def _problem(file: str, pos: Position, message: str, hint: str = _HINT) -> InvalidInput:
    return InvalidInput([Problem(file, pos, message, hint)])


def _read_image(path: Path, data: Optional[bytes] = None) -> np.ndarray:
    """The image's pixels as a 2D uint8/uint16 array (top row first); colour images are averaged as map_server does.
    ``data``: the file's bytes, already read (within the map image's cap)."""
    import cv2  # only a map needs OpenCV's image codecs

    try:
        if data is None:
            pixels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        else:
            pixels = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:  # OpenCV's own bound on pixels (2^30), a format it half-reads: the file's fault
        raise OSError(f"OpenCV cannot read it ({str(exc).strip().splitlines()[-1][:200]})") from None
    if pixels is None:
        raise OSError("not an image OpenCV can read (PGM, PNG, BMP, JPEG)")
    if pixels.ndim == 3:
        channels = pixels.shape[2]
        colour = pixels[:, :, :3] if channels >= 3 else pixels[:, :, :1]
        pixels = np.rint(colour.astype(float).mean(axis=2)).astype(pixels.dtype)
    return pixels


def _check_declared_size(image_path: Path, name: str, where: Position) -> None:
    """Refuse, at the YAML's ``image:``, an image whose header declares more than :data:`MAX_CELLS` pixels or
    declares no sensible size (issue 38: a PGM declaring 100,000 x 100,000), before any pixel is decoded; an image
    that cannot be opened is left to the reading, which says why."""
    from beastbt.mapping.image_header import ImageHeaderError, declared_size

    try:
        size = declared_size(image_path)
    except OSError:
        return  # reading the image says why, where the image is read
    except ImageHeaderError as exc:
        raise _problem(name, where, f"the map image {str(image_path)!r} cannot be read: {exc}",
                       "save the map again (beastbt map save, or map_saver), or point 'image:' at its PGM") from None
    if size is not None and size[0] * size[1] > MAX_CELLS:
        raise _problem(name, where, f"the map image {image_path.name} declares {size[0]:,} x {size[1]:,} pixels "
                                    f"({size[0] * size[1]:,}): a map holds at most {MAX_CELLS:,} cells",
                       "use a coarser resolution or crop the map (a 2 km x 2 km site at 5 cm is 1,600 million "
                       "cells: map it in parts)")


def load_map(path: Union[str, Path], refs: Optional["FileRefs"] = None) -> OccupancyMap:
    """Read a ``map_server`` YAML and its image into an :class:`OccupancyMap`.

    Pixels become occupancy as ``map_server`` does: with ``p`` the pixel's
    darkness in [0, 1] (``(max - v) / max``, or ``v / max`` with ``negate: 1``),
    ``trinary`` gives 100 above ``occupied_thresh``, 0 below ``free_thresh``
    and -1 between; ``scale`` gives the percentage between the thresholds;
    ``raw`` takes the pixel value itself. Raises :class:`InvalidInput` with the
    file, line and column of what is wrong. The image is read where ``refs`` allows (default: anywhere, as the
    command line does; :mod:`beastbt.core.file_refs`), a regular file within the map image's byte cap.
    """
    from beastbt.core.file_refs import CLI, MAP_IMAGE, RefusedFile
    path = Path(path)
    doc = load_yaml(path)
    name = doc.file
    d = doc.data

    def pos(key: str) -> Position:
        return doc.positions.get((key,), Position(1, 1))

    for key in ("image", "resolution"):
        if key not in d:
            raise _problem(name, Position(1, 1), f"'{key}' is missing")
    image = d["image"]
    if not isinstance(image, str) or not image:
        raise _problem(name, pos("image"), "'image' must be the image file's name", "e.g. image: office.pgm")
    resolution = d["resolution"]
    if isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not 0 < resolution <= 10:
        raise _problem(name, pos("resolution"), f"'resolution' must be metres per pixel, > 0 and at most 10, "
                                               f"got {resolution!r}", "e.g. resolution: 0.05")
    origin = d.get("origin", [0.0, 0.0, 0.0])
    if (not isinstance(origin, list) or len(origin) != 3
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in origin)):
        raise _problem(name, pos("origin"), "'origin' must be [x, y, yaw]: metres, metres, radians",
                       "e.g. origin: [-10.0, -10.0, 0.0]")
    mode = d.get("mode", "trinary")
    if mode not in _MODES:
        raise _problem(name, pos("mode"), f"'mode' must be one of {', '.join(_MODES)}, got {mode!r}")
    negate = d.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise _problem(name, pos("negate"), f"'negate' must be 0 or 1, got {negate!r}")
    thresholds = {}
    for key, default in (("occupied_thresh", DEFAULT_OCCUPIED_THRESH), ("free_thresh", DEFAULT_FREE_THRESH)):
        value = d.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1:
            raise _problem(name, pos(key), f"'{key}' must be a probability between 0 and 1, got {value!r}")
        thresholds[key] = float(value)
    if thresholds["free_thresh"] > thresholds["occupied_thresh"]:
        raise _problem(name, pos("free_thresh"), "'free_thresh' is above 'occupied_thresh'",
                       "free_thresh is the lighter bound (e.g. 0.25), occupied_thresh the darker (e.g. 0.65)")
    try:
        image_path = (refs or CLI).locate(image, path.parent, MAP_IMAGE)
        # The header first, where the policy allows reading: a declared size over the cap decodes nothing.
        _check_declared_size(image_path, name, pos("image"))
        pixels = _read_image(image_path, (refs or CLI).read_bytes(image_path, MAP_IMAGE, image))
    except RefusedFile as exc:
        if "does not exist" in exc.message:
            raise _problem(name, pos("image"), f"cannot read the map image '{image}': it does not exist",
                           "the image path is relative to the YAML's folder") from None
        raise _problem(name, pos("image"), exc.message, exc.hint) from None
    except OSError as exc:
        raise _problem(name, pos("image"), f"cannot read the map image {str(image_path)!r}: {exc}",
                       "the image path is relative to the YAML's folder") from None
    if pixels.size > MAX_CELLS:
        raise _problem(name, pos("image"), f"the map image has {pixels.size} pixels, more than {MAX_CELLS}",
                       "use a coarser resolution or crop the map")

    top_max = float(np.iinfo(pixels.dtype).max) if pixels.dtype.kind in "ui" else 255.0
    if mode == "raw":
        data = np.where(pixels > 100, UNKNOWN, pixels).astype(np.int8)
    else:
        darkness = pixels.astype(float) / top_max if negate else (top_max - pixels.astype(float)) / top_max
        occ_t, free_t = thresholds["occupied_thresh"], thresholds["free_thresh"]
        data = np.full(pixels.shape, UNKNOWN, dtype=np.int8)
        data[darkness > occ_t] = OCCUPIED
        data[darkness < free_t] = FREE
        if mode == "scale":
            between = (darkness >= free_t) & (darkness <= occ_t)
            if occ_t > free_t:
                data[between] = np.rint(99 * (darkness[between] - free_t) / (occ_t - free_t)).astype(np.int8)
    return OccupancyMap(np.ascontiguousarray(data[::-1]), float(resolution), float(origin[0]), float(origin[1]),
                        float(origin[2]), thresholds["occupied_thresh"], thresholds["free_thresh"], source=name)


# -- writing -----------------------------------------------------------------------------------------------------

def map_pixels(grid: OccupancyMap) -> np.ndarray:
    """The trinary image ``map_saver`` writes (top row first): occupied 0, free 254, unknown 205."""
    image = np.full(grid.data.shape, PGM_UNKNOWN, dtype=np.uint8)
    image[grid.free()] = PGM_FREE
    image[grid.occupied()] = PGM_OCCUPIED
    return np.ascontiguousarray(image[::-1])


def save_map(grid: OccupancyMap, yaml_path: Union[str, Path]) -> tuple[Path, Path]:
    """Write ``grid`` as ``map_saver`` does: a binary PGM (P5) in trinary mode beside a YAML naming it.

    The image is the YAML's name with ``.pgm``. Returns (yaml path, image path).
    """
    yaml_path = Path(yaml_path)
    image_path = yaml_path.with_suffix(".pgm")
    yaml_path.parent.mkdir(parents=True, exist_ok=True)
    pixels = map_pixels(grid)
    header = f"P5\n# beastbt map, {grid.resolution_m} m/pixel\n{grid.cols} {grid.rows}\n255\n".encode("ascii")
    image_path.write_bytes(header + pixels.tobytes())
    text = (
        f"image: {image_path.name}\n"
        "mode: trinary\n"
        f"resolution: {_num(grid.resolution_m)}\n"
        f"origin: [{_num(grid.origin_x)}, {_num(grid.origin_y)}, {_num(grid.origin_yaw)}]\n"
        "negate: 0\n"
        f"occupied_thresh: {_num(grid.occupied_thresh)}\n"
        f"free_thresh: {_num(grid.free_thresh)}\n"
    )
    yaml_path.write_text(text, encoding="utf-8")
    return yaml_path, image_path


def _num(value: float) -> str:
    """A float as YAML writes it, short and exact enough (micrometres)."""
    text = f"{value:.6f}".rstrip("0")
    return text + "0" if text.endswith(".") else text
