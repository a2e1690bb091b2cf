"""Kernels of the vacancy grid: the hits that later rays went through.

The particle maps are distance fields of hits: a hit stays in them for good. A person walking
ahead of the robot, a door that opens, a bed pushed along a corridor leave hits where nothing
stands any more, and the matcher then fits the new returns on them to where they stood before:
behind where they are now, which pulls the robot back (fr-clinic's corridor, docs/accuracy.md).
The vacancy grid keeps the evidence that a hit is gone, shared by every particle and written
along the best particle's poses (:class:`slam.mapping.VacancyGrid`):

* a cell a return falls in is a live hit (``state`` 1), with the surface normal of that return;
* a ray that passes through a live hit, at least a margin short of its own end and at least
  ``min_cos`` off the hit's surface (a ray grazing a wall does not count), is a miss; after
  ``after`` misses with no new return in the cell, the hit is seen through (``state`` 2);
* ``vacated`` marks the cells whose window (``window`` cells to each side) holds a seen-through
  hit and no live one: a hit the particle maps hold near such a cell is one that later scans saw
  through, whichever particle's map it is in (their poses differ by centimetres).

The matcher reads ``vacated`` at the hit nearest to a return (the endpoint moved back along the
field's gradient by its distance, :func:`slam.kernels.field.mark_gone`) and counts such a
return as one that no surface explains. A ray's margin is measured to where it enters a cell,
so a hit may lie up to a cell's diagonal closer to the ray's end than the margin says. Cells follow :mod:`slam.kernels.cells`, rows going up
in y.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from slam.kernels.cells import cell_index

LIVE = 1
"""``state`` of a cell a return fell in, and no later ray went through since."""
SEEN_THROUGH = 2
"""``state`` of a cell whose hit later rays went through."""


class VacancyView(NamedTuple):
    """The vacancy grid as the matcher reads it (:meth:`slam.mapping.VacancyGrid.view`; the
    kernels take its fields inside :class:`slam.kernels.field.FieldView`)."""

    vacated: np.ndarray
    """``(rows, cols)`` uint8: 1 where the window around the cell holds a seen-through hit and no
    live one."""
    ox: float
    """World x of the lower-left corner of cell (0, 0) (m)."""
    oy: float
    """World y of the lower-left corner of cell (0, 0) (m)."""
    res: float
    """Cell size (m)."""


class VacancyCells(NamedTuple):
    """The vacancy grid's layers as :func:`observe` writes them (numba takes it as one argument)."""

    state: np.ndarray
    """``(rows, cols)`` uint8: 0 no return yet, :data:`LIVE`, :data:`SEEN_THROUGH`."""
    misses: np.ndarray
    """``(rows, cols)`` uint8: rays through the live hit since its last return."""
    normal: np.ndarray
    """``(rows, cols)`` uint8: the live hit's surface normal, ``round(angle·128/π) mod 256``."""
    vacated: np.ndarray
    """``(rows, cols)`` uint8: the matcher's layer (:class:`VacancyView`)."""
    ox: float
    """World x of the lower-left corner of cell (0, 0) (m)."""
    oy: float
    """World y of the lower-left corner of cell (0, 0) (m)."""
    res: float
    """Cell size (m)."""
    window: int
    """Cells to each side of a cell that its ``vacated`` flag looks at."""


@njit(cache=True)
def observe(
    cells: VacancyCells,
    sensor: np.ndarray,
    rays: np.ndarray,
    hits: np.ndarray,
    min_cos: float,
    after: int,
) -> None:
    """One scan into the vacancy grid: its rays' misses, then its returns.

    ``sensor`` is the laser's world position ``(2,)``; ``rays`` is ``(3, N)``: each ray's world
    unit direction ``(ux, uy)`` and the length it counts misses over (its range less the margin,
    :meth:`slam.mapping.VacancyGrid.observe`); ``hits`` is ``(3, K)``: the returns' world
    positions and surface normals' angles (rad). Every cell is inside the grid (the caller grows
    it first); cells outside are skipped all the same.
    """
    sx, sy = sensor[0], sensor[1]
    for k in range(rays.shape[1]):
        _ray_misses(cells, sx, sy, rays[0, k], rays[1, k], rays[2, k], min_cos, after)
    rows, cols = cells.state.shape
    for k in range(hits.shape[1]):
        ix = cell_index(hits[0, k], cells.ox, cells.res)
        iy = cell_index(hits[1, k], cells.oy, cells.res)
        if ix < 0 or iy < 0 or ix >= cols or iy >= rows:
            continue
        cells.misses[iy, ix] = 0
        cells.normal[iy, ix] = np.uint8(int(round(hits[2, k] * 128.0 / math.pi)) & 255)
        if cells.state[iy, ix] != LIVE:
            cells.state[iy, ix] = LIVE
            _refresh(cells, ix, iy)


@njit(cache=True, _nrt=False)
def _ray_misses(
    cells: VacancyCells,
    sx: float,
    sy: float,
    ux: float,
    uy: float,
    length: float,
    min_cos: float,
    after: int,
) -> None:
    """Walk the cells a ray crosses over its first ``length`` metres (Amanatides and Woo's
    traversal: each cell once) and count a miss on every live hit it meets steeply enough."""
    if length <= 0.0:
        return
    rows, cols = cells.state.shape
    inv = 1.0 / cells.res
    gx = (sx - cells.ox) * inv  # the sensor in cells (the traversal's own frame) ...
    gy = (sy - cells.oy) * inv
    ix = cell_index(sx, cells.ox, cells.res)  # ... and its cell by the grids' one rule
    iy = cell_index(sy, cells.oy, cells.res)
    end = length * inv  # in cells along the ray
    step_x = 1 if ux > 0.0 else -1
    step_y = 1 if uy > 0.0 else -1
    dtx, tx = _axis_steps(gx, ix, ux)
    dty, ty = _axis_steps(gy, iy, uy)
    t = 0.0
    heading = math.atan2(uy, ux)
    while t <= end:
        if 0 <= ix < cols and 0 <= iy < rows and cells.state[iy, ix] == LIVE:
            normal = cells.normal[iy, ix] * (math.pi / 128.0)
            if abs(math.cos(heading - normal)) >= min_cos:
                m = cells.misses[iy, ix] + 1
                cells.misses[iy, ix] = min(m, 255)
                if m >= after:
                    cells.state[iy, ix] = SEEN_THROUGH
                    _refresh(cells, ix, iy)
        if tx < ty:
            t = tx
            tx += dtx
            ix += step_x
        else:
            t = ty
            ty += dty
            iy += step_y


@njit(cache=True, inline="always")
def _axis_steps(g: float, i: int, u: float) -> tuple[float, float]:
    """Along one axis of the traversal: the ray length (in cells) between two cell borders and
    to the first border, from ``g`` (in cells, in cell ``i``) along direction component ``u``
    (a huge length where the ray runs parallel to the axis)."""
    if u == 0.0:
        return 1e30, 1e30
    step = abs(1.0 / u)
    return step, ((i + 1 - g) if u > 0.0 else (g - i)) * step


@njit(cache=True, _nrt=False)
def _refresh(cells: VacancyCells, ix: int, iy: int) -> None:
    """Recompute ``vacated`` over the window around cell ``(ix, iy)``, whose state changed."""
    w = cells.window
    rows, cols = cells.state.shape
    for cy in range(max(iy - w, 0), min(iy + w + 1, rows)):
        for cx in range(max(ix - w, 0), min(ix + w + 1, cols)):
            seen = False
            live = False
            for y in range(max(cy - w, 0), min(cy + w + 1, rows)):
                for x in range(max(cx - w, 0), min(cx + w + 1, cols)):
                    s = cells.state[y, x]
                    if s == LIVE:
                        live = True
                    elif s == SEEN_THROUGH:
                        seen = True
            cells.vacated[cy, cx] = 1 if seen and not live else 0


@njit(cache=True, inline="always")
def vacated_near(
    vacated: np.ndarray, ox: float, oy: float, res: float, wx: float, wy: float
) -> bool:
    """Whether a ``vacated`` layer (origin ``(ox, oy)``, cells ``res`` wide) marks world point
    ``(wx, wy)`` (False outside it)."""
    rows, cols = vacated.shape
    ix = cell_index(wx, ox, res)
    iy = cell_index(wy, oy, res)
    if ix < 0 or iy < 0 or ix >= cols or iy >= rows:
        return False
    return vacated[iy, ix] != 0
