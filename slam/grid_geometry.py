"""Where a grid lies in the world: :class:`GridGeometry` (resolution, origin, shape, world↔cell).

Every grid of the package (the occupancy grid, the particle maps, the simulator's obstacle grid
and floor texture, the texture map) follows one convention: ``array[iy, ix]`` is the cell whose
lower-left corner is ``origin + (ix, iy)·resolution``, rows going up in y. The cell of a world
point is ``⌊(p − origin) / resolution⌋`` (:func:`slam.kernels.cells.cell_index` in the kernels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Rect = tuple[float, float, float, float]
"""``(x0, y0, x1, y1)`` in metres."""


@dataclass(frozen=True)
class GridGeometry:
    """Geometry of a grid: origin (lower-left corner of cell (0, 0)), resolution and shape."""

    origin: tuple[float, float]
    """World ``(x, y)`` of the lower-left corner of cell ``(0, 0)`` (m)."""
    resolution: float
    """Cell size (m)."""
    shape: tuple[int, int]
    """``(rows, columns)``."""

    @classmethod
    def of(cls, origin: ArrayLike, resolution: float, shape: tuple[int, ...]) -> GridGeometry:
        """The geometry of a grid with these parts (``origin`` any 2-sequence, ``shape`` an array's
        shape: its first two entries)."""
        o = np.asarray(origin, dtype=np.float64).reshape(2)
        return cls((float(o[0]), float(o[1])), float(resolution), (int(shape[0]), int(shape[1])))

    @property
    def extent(self) -> Rect:
        """``(xmin, ymin, xmax, ymax)`` covered by the grid (m)."""
        ox, oy = self.origin
        return (ox, oy, ox + self.shape[1] * self.resolution, oy + self.shape[0] * self.resolution)

    def world_to_cell(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Cell indices ``(..., 2)`` as ``(ix, iy)`` of world points ``(..., 2)`` (may fall outside
        the grid)."""
        xy = np.asarray(xy)
        row, col = self.cell_of(xy[..., 0], xy[..., 1])
        return np.stack([col, row], axis=-1)

    def cell_of(self, x: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Row and column of the cells containing world points (may fall outside the grid)."""
        return _index(y, self.origin[1], self.resolution), _index(
            x, self.origin[0], self.resolution
        )

    def inside(self, row: NDArray[np.int64], col: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Which ``(row, col)`` lie inside the grid."""
        return (row >= 0) & (col >= 0) & (row < self.shape[0]) & (col < self.shape[1])

    def world_to_pixel(self, xy: ArrayLike) -> NDArray[np.int64]:
        """Pixel ``(column, row)`` of world points ``(..., 2)`` in the grid's picture (+y up, so
        row 0 is the top row of cells)."""
        cells = self.world_to_cell(xy)
        return np.stack([cells[..., 0], self.shape[0] - 1 - cells[..., 1]], axis=-1)

    def centres(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """World x of column centres ``(W,)`` and y of row centres ``(H,)``."""
        xs = self.origin[0] + (np.arange(self.shape[1]) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(self.shape[0]) + 0.5) * self.resolution
        return xs, ys

    def to_pixels(self, xy: ArrayLike) -> NDArray[np.float64]:
        """World points ``(N, 2)`` → continuous (column, row) coordinates of cell centres."""
        return (np.asarray(xy) - np.asarray(self.origin)) / self.resolution - 0.5

    def slices(self, rect: Rect) -> tuple[slice, slice]:
        """Row and column slices of the cells whose centres lie inside ``rect``."""
        x0, y0, x1, y1 = rect
        ox, oy = self.origin
        r = self.resolution
        c0 = max(0, math.ceil((x0 - ox) / r - 0.5))
        c1 = min(self.shape[1], math.floor((x1 - ox) / r - 0.5) + 1)
        r0 = max(0, math.ceil((y0 - oy) / r - 0.5))
        r1 = min(self.shape[0], math.floor((y1 - oy) / r - 0.5) + 1)
        return slice(r0, max(r0, r1)), slice(c0, max(c0, c1))


def _index(v: ArrayLike, origin: float, resolution: float) -> NDArray[np.int64]:
    """``⌊(v − origin) / resolution⌋`` (the array twin of :func:`slam.kernels.cells.cell_index`)."""
    return np.floor((np.asarray(v) - origin) / resolution).astype(np.int64)


def covering(bounds: Rect, resolution: float, margin: float) -> GridGeometry:
    """A grid covering ``bounds`` plus ``margin``, its origin on a multiple of ``resolution``."""
    x0, y0, x1, y1 = bounds
    ox = math.floor((x0 - margin) / resolution) * resolution
    oy = math.floor((y0 - margin) / resolution) * resolution
    cols = math.ceil((x1 + margin - ox) / resolution)
    rows = math.ceil((y1 + margin - oy) / resolution)
    return GridGeometry((round(ox, 9), round(oy, 9)), resolution, (rows, cols))
