"""Element-wise work on big grids a block of rows at a time, to bound the temporaries.

A picture of a 5000 × 6500 map (``map.png``, ``map.pgm``, the recording's map) computed in one
NumPy expression holds several float64 temporaries of the whole grid at once (1 GB on
mit-killian); the same expression over blocks of rows gives the very same values (each cell's
value depends only on that cell) with temporaries of one block.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from slam.mapping import OccupancyGrid

BLOCK_CELLS = 1 << 21
"""Cells per block of rows (at least one row): 16 MB per float64 temporary."""


def by_rows(
    func: Callable[[NDArray], NDArray],
    array: NDArray,
    dtype: np.dtype | type,
    flip: bool = False,
    channels: int = 0,
) -> NDArray:
    """``func(array)`` computed over blocks of rows of ``array`` (2-D) into a new ``dtype`` array
    of the same shape; ``func`` must be element-wise (a block's result depends only on it).

    ``flip``: the rows in reverse order (``func(array)[::-1]``, written in place, without a
    second copy of the whole); ``channels``: each value repeated into that many channels,
    ``(rows, cols, channels)`` (what ``cv2.cvtColor(…, COLOR_GRAY2BGR)`` makes of a grey
    picture, without the grey one beside it)."""
    rows, cols = array.shape
    out = np.empty((rows, cols, channels) if channels else (rows, cols), dtype=dtype)
    step = max(1, BLOCK_CELLS // max(cols, 1))
    for r0 in range(0, rows, step):
        part = func(array[r0 : r0 + step])
        r1 = r0 + part.shape[0]
        if flip:
            part = part[::-1]
        target = out[rows - r1 : rows - r0] if flip else out[r0:r1]
        target[...] = part[..., None] if channels else part
    return out


def grid_image(grid: OccupancyGrid, channels: int = 0) -> NDArray[np.uint8]:
    """``grid.to_image()`` (:meth:`slam.mapping.OccupancyGrid.to_image`, the same bytes) computed
    a block of rows at a time; with ``channels`` each grey level repeated into that many
    (:func:`by_rows`)."""
    from slam.mapping import OccupancyGrid

    def block(rows: NDArray[np.float32]) -> NDArray[np.uint8]:
        part = OccupancyGrid.from_arrays(rows, grid.resolution, grid.origin, grid.config)
        return part.to_image()[::-1]  # to_image flips the rows; by_rows flips the whole

    return by_rows(block, grid.log_odds, np.uint8, flip=True, channels=channels)
