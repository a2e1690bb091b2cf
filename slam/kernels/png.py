"""PNG row unfiltering: the per-byte loop of :mod:`slam.io.png`'s decoder.

A PNG image is a zlib stream of rows, each a filter byte (0 None, 1 Sub, 2 Up, 3 Average,
4 Paeth) followed by the row's filtered bytes (PNG specification, section 9). This kernel undoes
the filters of every row; it takes the inflated bytes and returns nothing but the image bytes.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def unfilter_rows(raw: np.ndarray, height: int, row_bytes: int, bpp: int, out: np.ndarray) -> bool:
    """Undo the PNG filters of ``height`` rows of ``raw`` (each ``1 + row_bytes`` bytes: filter
    type, then the filtered row) into ``out`` (``(height, row_bytes)`` uint8); ``bpp`` is the bytes
    per pixel (the filters' left neighbour distance). Returns ``False`` on an unknown filter type
    (a corrupt image). Releases the GIL, so decoding threads run in parallel.
    """
    for i in range(height):
        base = i * (row_bytes + 1)
        kind = raw[base]
        src = base + 1
        if kind == 0:
            for x in range(row_bytes):
                out[i, x] = raw[src + x]
        elif kind == 1:
            for x in range(min(bpp, row_bytes)):
                out[i, x] = raw[src + x]
            for x in range(bpp, row_bytes):
                out[i, x] = (raw[src + x] + out[i, x - bpp]) & 0xFF
        elif kind == 2:
            if i == 0:
                for x in range(row_bytes):
                    out[i, x] = raw[src + x]
            else:
                for x in range(row_bytes):
                    out[i, x] = (raw[src + x] + out[i - 1, x]) & 0xFF
        elif kind == 3:
            for x in range(row_bytes):
                left = np.int32(out[i, x - bpp]) if x >= bpp else np.int32(0)
                up = np.int32(out[i - 1, x]) if i > 0 else np.int32(0)
                out[i, x] = (np.int32(raw[src + x]) + ((left + up) >> 1)) & 0xFF
        elif kind == 4:
            for x in range(row_bytes):
                a = np.int32(out[i, x - bpp]) if x >= bpp else np.int32(0)
                b = np.int32(out[i - 1, x]) if i > 0 else np.int32(0)
                c = np.int32(out[i - 1, x - bpp]) if (i > 0 and x >= bpp) else np.int32(0)
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                if pa <= pb and pa <= pc:
                    pred = a
                elif pb <= pc:
                    pred = b
                else:
                    pred = c
                out[i, x] = (np.int32(raw[src + x]) + pred) & 0xFF
        else:
            return False
    return True
