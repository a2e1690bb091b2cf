"""The cell rule of every grid kernel, in one place.

Cell ``(ix, iy)`` of a grid with origin ``(ox, oy)`` (the lower-left corner of cell ``(0, 0)``)
and cell size ``res`` covers ``[ox + ix·res, ox + (ix + 1)·res) × [oy + iy·res, oy + (iy + 1)·res)``,
so the cell of a world coordinate is ``⌊(x − ox) / res⌋``. The array form for Python callers is
:meth:`slam.grid_geometry.GridGeometry.world_to_cell`; both divide (rather than multiply by
``1/res``), so they agree to the bit. Two hot loops over camera pixels multiply by a precomputed
``1/res`` instead (:func:`slam.texture.kernels.accumulate_frame`, the simulator's
:func:`slam.sim.kernels.render_rgb`); that rounds differently near cell borders, so it is a rule of its own
there and not this one.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always")
def cell_index(x: float, origin: float, res: float) -> int:
    """Index of the cell containing coordinate ``x`` along one axis: ``⌊(x − origin) / res⌋``."""
    return int(math.floor((x - origin) / res))
