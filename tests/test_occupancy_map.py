"""Occupancy maps in map_server format: what Nav2's map_server reads, we read; what we write, it reads.

The pixel rules follow ``nav2_map_server/src/map_io.cpp``: darkness ``p = (255 - v) / 255`` (``v / 255`` with
``negate: 1``); trinary: occupied above ``occupied_thresh``, free below ``free_thresh``, unknown between; scale:
the percentage between them; raw: the value itself. ``map_saver`` writes 0 / 254 / 205 for occupied / free /
unknown. Row 0 of the grid is the image's bottom row, at ``origin``.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from beastbt.core.errors import InvalidInput
from beastbt.mapping.occupancy_map import (FREE, OCCUPIED, UNKNOWN, OccupancyMap, empty_map, load_map, map_pixels,
                                           save_map)
from beastbt.mapping.rasterise import mark_outlines


def _write(folder: Path, pixels: np.ndarray, yaml_text: str, image: str = "m.pgm") -> Path:
    cv2.imwrite(str(folder / image), pixels)
    path = folder / "m.yaml"
    path.write_text(yaml_text.replace("IMAGE", image))
    return path


def test_a_map_saver_image_reads_as_map_server_would(tmp_path: Path) -> None:
    # top image row: occupied, unknown, free; bottom row: a light grey (free), a mid grey (unknown), a dark (occupied)
    pixels = np.array([[0, 205, 254], [230, 150, 60]], dtype=np.uint8)
    path = _write(tmp_path, pixels, "image: IMAGE\nresolution: 0.1\norigin: [-1.0, 2.0, 0.0]\nnegate: 0\n"
                                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    grid = load_map(path)
    assert grid.rows == 2 and grid.cols == 3
    # row 0 is the image's bottom row
    assert grid.data[0].tolist() == [FREE, UNKNOWN, OCCUPIED]
    assert grid.data[1].tolist() == [OCCUPIED, UNKNOWN, FREE]
    assert (grid.origin_x, grid.origin_y, grid.resolution_m) == (-1.0, 2.0, 0.1)
    # the centre of the image's top-left pixel
    assert grid.value_at(-0.95, 2.15) == OCCUPIED
    assert grid.value_at(-0.95, 2.05) == FREE


def test_negate_and_scale_modes(tmp_path: Path) -> None:
    pixels = np.array([[0, 128, 255]], dtype=np.uint8)
    negated = load_map(_write(tmp_path, pixels, "image: IMAGE\nresolution: 0.05\nnegate: 1\n"))
    assert negated.data[0].tolist() == [FREE, UNKNOWN, OCCUPIED]
    scaled = load_map(_write(tmp_path, pixels, "image: IMAGE\nresolution: 0.05\nmode: scale\n"))
    # p = 127/255 = 0.498 lies between 0.196 and 0.65: (0.498 - 0.196) / 0.454 * 99 = 66
    assert scaled.data[0].tolist() == [OCCUPIED, 66, FREE]
    raw = load_map(_write(tmp_path, np.array([[0, 42, 100, 101]], dtype=np.uint8),
                          "image: IMAGE\nresolution: 0.05\nmode: raw\n"))
    assert raw.data[0].tolist() == [0, 42, 100, UNKNOWN]


def test_a_png_image_with_colour_reads_too(tmp_path: Path) -> None:
    pixels = np.zeros((1, 2, 3), dtype=np.uint8)
    pixels[0, 1] = (254, 254, 254)
    grid = load_map(_write(tmp_path, pixels, "image: IMAGE\nresolution: 0.05\n", image="m.png"))
    assert grid.data[0].tolist() == [OCCUPIED, FREE]


def test_nav2s_default_free_thresh_reads_the_unknown_grey_as_free_as_nav2_does(tmp_path: Path) -> None:
    pixels = np.array([[205]], dtype=np.uint8)
    assert load_map(_write(tmp_path, pixels, "image: IMAGE\nresolution: 0.05\nfree_thresh: 0.25\n")).data[0, 0] == FREE


def test_saved_maps_round_trip_and_are_what_map_saver_writes(tmp_path: Path) -> None:
    grid = empty_map(3.0, 2.0, 0.05, -0.5, -1.0, fill=FREE)
    grid = mark_outlines(grid, segments=[(-0.5, -0.98, 2.5, -0.98)], circles=[(1.0, 0.0, 0.3)])
    unknown = grid.data.copy()
    unknown[30:, 50:] = UNKNOWN
    grid = grid.with_data(unknown)
    yaml_path, image_path = save_map(grid, tmp_path / "maps" / "office.yaml")
    assert image_path.name == "office.pgm" and image_path.read_bytes().startswith(b"P5")
    assert sorted(set(np.unique(cv2.imread(str(image_path), cv2.IMREAD_UNCHANGED)))) == [0, 205, 254]
    back = load_map(yaml_path)
    assert np.array_equal(back.data, grid.data)
    assert (back.origin_x, back.origin_y, back.resolution_m) == (-0.5, -1.0, 0.05)
    assert np.array_equal(map_pixels(back), map_pixels(grid))
    text = yaml_path.read_text()
    for key in ("image:", "resolution:", "origin:", "negate:", "occupied_thresh:", "free_thresh:"):
        assert key in text


def test_cells_and_their_centres_agree_with_a_rotated_origin() -> None:
    grid = OccupancyMap(np.zeros((40, 60), dtype=np.int8), 0.1, 2.0, -1.0, math.radians(30))
    rng = np.random.default_rng(3)
    col = rng.integers(0, 60, 200)
    row = rng.integers(0, 40, 200)
    x, y = grid.cell_centres(col, row)
    back_col, back_row = grid.to_cells(x, y)
    assert np.array_equal(back_col, col) and np.array_equal(back_row, row)
    # one cell along the image's x is 0.1 m along the rotated direction
    x0, y0 = grid.cell_centres(0, 0)
    x1, y1 = grid.cell_centres(1, 0)
    assert math.isclose(math.atan2(float(y1 - y0), float(x1 - x0)), math.radians(30), abs_tol=1e-9)


def test_the_outline_of_a_segment_is_marked_cell_by_cell() -> None:
    grid = mark_outlines(empty_map(2.0, 1.0, 0.1, 0.0, 0.0, fill=FREE), segments=[(0.05, 0.55, 1.95, 0.55)])
    assert grid.occupied()[5].all()
    assert grid.occupied().sum() == 20


@pytest.mark.parametrize("yaml_text, where, words", [
    ("image: m.pgm\n", (1, 1), "'resolution' is missing"),
    ("image: m.pgm\nresolution: -0.05\n", (2, 13), "'resolution' must be"),
    ("image: m.pgm\nresolution: 0.05\norigin: [1, 2]\n", (3, 9), "'origin' must be [x, y, yaw]"),
    ("image: m.pgm\nresolution: 0.05\nmode: fancy\n", (3, 7), "'mode' must be one of"),
    ("image: gone.pgm\nresolution: 0.05\n", (1, 8), "cannot read the map image"),
    ("image: m.pgm\nresolution: 0.05\nfree_thresh: 0.9\n", (3, 14), "'free_thresh' is above"),
])
def test_a_bad_map_file_is_refused_at_its_place(tmp_path: Path, yaml_text: str, where: tuple[int, int],
                                                words: str) -> None:
    cv2.imwrite(str(tmp_path / "m.pgm"), np.zeros((2, 2), dtype=np.uint8))
    (tmp_path / "m.yaml").write_text(yaml_text)
    with pytest.raises(InvalidInput) as caught:
        load_map(tmp_path / "m.yaml")
    problem = caught.value.problems[0]
    assert words in problem.message
    assert (problem.position.line, problem.position.column) == where
    assert problem.hint
