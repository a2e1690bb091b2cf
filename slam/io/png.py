"""Fast decoding of the PNG files of RGB-D logs: 8-bit RGB and 16-bit grey, non-interlaced.

This module owns reading one RGB or disparity frame from disk. The RGB-D frames of the texture
stage are the common PNG kinds (8-bit RGB colour images, 16-bit single-channel disparity
images, no interlacing); for those the file is parsed here (chunk CRCs checked), inflated with
libdeflate (the ``deflate`` package, about 3× faster than zlib) and unfiltered by
:func:`slam.kernels.png.unfilter_rows`. Both release the GIL, so decoding threads run in
parallel. The pixels are the bytes OpenCV returns (tests/test_png.py). Any other PNG (palette,
alpha, grey of another depth, interlaced, colour-management chunks such as ``gAMA``, ``iCCP``,
``sBIT``, ``tRNS``) or anything that does not parse goes through ``cv2.imread``, which then
decides whether it is readable at all.
"""

from __future__ import annotations

import struct
from pathlib import Path

import deflate
import numpy as np
from numpy.typing import NDArray

from slam.kernels.png import unfilter_rows

SIGNATURE = b"\x89PNG\r\n\x1a\n"
"""The 8 bytes every PNG file starts with."""

PLAIN_CHUNKS = frozenset({b"IHDR", b"IDAT", b"IEND", b"tEXt", b"zTXt", b"iTXt", b"pHYs", b"tIME"})
"""Chunks that do not change the pixels OpenCV returns; any other one sends a file to OpenCV."""


def _parse(data: bytes, bit_depth: int, colour_type: int) -> tuple[int, int, bytes] | None:
    """``(width, height, concatenated IDAT bytes)`` of a non-interlaced PNG of this bit depth and
    colour type whose chunks are all in :data:`PLAIN_CHUNKS` with valid CRCs, else ``None``."""
    if not data.startswith(SIGNATURE):
        return None
    pos, size = len(SIGNATURE), len(data)
    header = None
    idat: list[bytes] = []
    ended = False
    while pos + 12 <= size:
        (length,) = struct.unpack_from(">I", data, pos)
        kind = data[pos + 4 : pos + 8]
        end = pos + 8 + length
        if end + 4 > size or kind not in PLAIN_CHUNKS:
            return None
        if deflate.crc32(data[pos + 4 : end]) != struct.unpack_from(">I", data, end)[0]:
            return None
        if kind == b"IHDR":
            header = data[pos + 8 : end]
        elif kind == b"IDAT":
            idat.append(data[pos + 8 : end])
        elif kind == b"IEND":
            ended = True
            break
        pos = end + 4
    if not ended or header is None or len(header) != 13 or not idat:
        return None
    width, height, depth, colour, method, filtering, interlace = struct.unpack(">IIBBBBB", header)
    if (depth, colour, method, filtering, interlace) != (bit_depth, colour_type, 0, 0, 0):
        return None
    if width == 0 or height == 0:
        return None
    return width, height, b"".join(idat)


def _decode(path: Path, bit_depth: int, colour_type: int, channels: int) -> NDArray | None:
    """The unfiltered image bytes ``(H, W·channels·bit_depth/8)`` of the PNG at ``path`` when it
    is of the given kind, else ``None`` (the caller falls back to OpenCV)."""
    try:
        data = Path(path).read_bytes()
    except OSError:
        return None
    parsed = _parse(data, bit_depth, colour_type)
    if parsed is None:
        return None
    width, height, stream = parsed
    bpp = channels * bit_depth // 8
    row_bytes = width * bpp
    size = height * (row_bytes + 1)
    try:
        raw = deflate.zlib_decompress(stream, size)
    except deflate.DeflateError:
        return None
    if len(raw) != size:
        return None
    out = np.empty((height, row_bytes), dtype=np.uint8)
    if not unfilter_rows(np.frombuffer(raw, dtype=np.uint8), height, row_bytes, bpp, out):
        return None
    return out


def read_rgb(path: Path) -> NDArray[np.uint8] | None:
    """The ``(H, W, 3)`` uint8 image of a colour PNG in **RGB** order (C-contiguous), or ``None``
    when it is missing, unreadable (as OpenCV decides for the PNG kinds not decoded here) or a
    grey image (colour type 0 or 4, which OpenCV would turn into a colour image of grey)."""
    rows = _decode(path, 8, 2, 3)
    if rows is not None:
        return rows.reshape(rows.shape[0], -1, 3)
    if _colour_type(path) in (0, 4):
        return None
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        return None
    return np.ascontiguousarray(image[:, :, ::-1])


def _colour_type(path: Path) -> int | None:
    """The PNG colour type of the file's IHDR (0 grey, 2 RGB, 3 palette, 4 grey + alpha, 6 RGBA),
    ``None`` when it is no PNG or cannot be read."""
    try:
        with open(path, "rb") as f:
            head = f.read(26)
    except OSError:
        return None
    if len(head) < 26 or not head.startswith(b"\x89PNG\r\n\x1a\n") or head[12:16] != b"IHDR":
        return None
    return head[25]


def read_unchanged(path: Path) -> NDArray | None:
    """The image of a PNG as ``cv2.imread(path, cv2.IMREAD_UNCHANGED)`` returns it (16-bit grey
    decoded here as native-endian ``(H, W)`` uint16), or ``None`` when missing or unreadable."""
    rows = _decode(path, 16, 0, 1)
    if rows is not None:
        return rows.view(">u2").astype(np.uint16)
    import cv2

    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
