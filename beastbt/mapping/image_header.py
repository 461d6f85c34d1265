"""The pixel size a map image declares in its header, read before any pixel is decoded.

A PGM declaring 100,000 x 100,000 pixels made OpenCV refuse it with an
assertion, which reached the user as an "internal error" (issue 38); a smaller
lie, within OpenCV's own bound, would have it allocate gigabytes. So the map
loader reads the header first (a few hundred bytes) and refuses an image over
its pixel cap before decoding it. Netpbm (PGM, PPM, PBM: what ``map_server``
writes), PNG and BMP headers are read here; other formats are left to OpenCV,
whose own bound (2^30 pixels) and errors the loader turns into a positioned
problem.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import Optional

HEADER_BYTES = 4096
"""How much of the file is read for its header: a Netpbm header with its comments fits, PNG's needs 24 bytes."""

_NETPBM = re.compile(rb"\AP([1-6])((?:\s+|#[^\n]*\n)+)(\d+)((?:\s+|#[^\n]*\n)+)(\d+)")
"""A Netpbm header's magic number, width and height, with the whitespace and comments between them."""


class ImageHeaderError(ValueError):
    """A header that declares no sensible size (a width of 0, no digits where the width goes)."""


def declared_size(path: Path) -> Optional[tuple[int, int]]:
    """(width, height) in pixels that the image at ``path`` declares, from its first :data:`HEADER_BYTES`; None
    for a format whose header is not read here. Raises OSError when the file cannot be read and
    :class:`ImageHeaderError` when a Netpbm, PNG or BMP header is broken."""
    with open(path, "rb") as f:
        head = f.read(HEADER_BYTES)
    return size_of_header(head)


def size_of_header(head: bytes) -> Optional[tuple[int, int]]:
    """:func:`declared_size` of the image whose first bytes are ``head``."""
    if head[:1] == b"P" and head[1:2] in b"123456" and len(head) > 2:
        match = _NETPBM.match(head)
        if match is None:
            raise ImageHeaderError("its PGM/PPM header has no width and height (P5, then the width and the height "
                                   "in digits)")
        width, height = int(match.group(3)), int(match.group(5))
    elif head[:8] == b"\x89PNG\r\n\x1a\n":
        if len(head) < 24 or head[12:16] != b"IHDR":
            raise ImageHeaderError("its PNG header is cut short")
        width, height = struct.unpack(">II", head[16:24])
    elif head[:2] == b"BM":
        if len(head) < 26:
            raise ImageHeaderError("its BMP header is cut short")
        width, height = struct.unpack("<ii", head[18:26])
        width, height = abs(width), abs(height)  # a negative height is a top-down BMP
    else:
        return None
    if width == 0 or height == 0:
        raise ImageHeaderError(f"its header declares {width} x {height} pixels: an empty image")
    return width, height


__all__ = ["declared_size", "size_of_header", "ImageHeaderError", "HEADER_BYTES"]
