"""The pixel size a map image declares in its header, read before any pixel is decoded.

A PGM declaring 100,000 x 100,000 pixels made OpenCV refuse it with an
assertion, which reached the user as an "internal error" (issue 38); a smaller
lie, within OpenCV's own bound, would have it allocate gigabytes. So the map
loader reads the header first (a few hundred bytes) and refuses an image over
its pixel cap before decoding it. Netpbm (PGM, PPM, PBM: what ``map_server``
writes), PNG, BMP and JPEG headers are read here; other formats are left to
OpenCV, whose own bound (2^30 pixels) and errors the loader turns into a
positioned problem.
"""

from __future__ import annotations

import os
import re
import stat
import struct
from pathlib import Path
from typing import Optional

HEADER_BYTES = 1 << 16
"""How much of the file is read for its header: a Netpbm header with its comments fits, PNG's needs 24 bytes, a
JPEG's frame header comes after its EXIF and other segments (64 kB each at most)."""

_NETPBM = re.compile(rb"\AP([1-6])((?:\s+|#[^\n]*\n)+)(\d+)((?:\s+|#[^\n]*\n)+)(\d+)")
"""A Netpbm header's magic number, width and height, with the whitespace and comments between them."""


class ImageHeaderError(ValueError):
    """A header that declares no sensible size (a width of 0, no digits where the width goes)."""


def declared_size(path: Path) -> Optional[tuple[int, int]]:
    """(width, height) in pixels that the image at ``path`` declares, from its first :data:`HEADER_BYTES`; None
    for a format whose header is not read here, or what is no regular file. Raises OSError when the file cannot be
    read and :class:`ImageHeaderError` when a Netpbm, PNG, BMP or JPEG header is broken."""
    if not stat.S_ISREG(os.stat(path).st_mode):
        return None  # a device or a pipe is not opened here (a pipe would wait for a writer): the reading refuses it
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
    elif head[:3] == b"\xff\xd8\xff":
        found = _jpeg_size(head)
        if found is None:
            return None  # its frame header lies beyond the bytes read (a large EXIF block): OpenCV's bound holds
        width, height = found
    else:
        return None
    if width == 0 or height == 0:
        raise ImageHeaderError(f"its header declares {width} x {height} pixels: an empty image")
    return width, height


_JPEG_FRAMES = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
"""The JPEG markers that start a frame (SOF0..SOF15 less DHT, JPG and DAC): they carry the image's size."""


def _jpeg_size(head: bytes) -> Optional[tuple[int, int]]:
    """(width, height) from a JPEG's first frame header within ``head``, walking the segments before it."""
    pos = 2
    while pos + 4 <= len(head):
        if head[pos] != 0xFF:
            raise ImageHeaderError("its JPEG segments are broken")
        marker = head[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        length = int.from_bytes(head[pos + 2:pos + 4], "big")
        if marker in _JPEG_FRAMES:
            if pos + 9 > len(head):
                return None
            height, width = struct.unpack(">HH", head[pos + 5:pos + 9])
            return width, height
        if length < 2:
            raise ImageHeaderError("its JPEG segments are broken")
        pos += 2 + length
    return None


__all__ = ["declared_size", "size_of_header", "ImageHeaderError", "HEADER_BYTES"]
