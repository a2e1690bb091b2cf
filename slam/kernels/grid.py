"""Grid kernels: Bresenham rays and the log-odds occupancy update of a dense grid.

Grid convention (shared by every map in the toolkit): ``grid[iy, ix]`` is the cell whose
lower-left corner is ``(ox + ix·res, oy + iy·res)``; rows go up in y, columns along x.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam.kernels.cells import cell_index


@njit(cache=True)
def line_start(x0: int, y0: int, x1: int, y1: int) -> tuple[int, int, int, int, int]:
    """``(dx, dy, stepx, stepy, err)`` that start the Bresenham walk from cell ``(x0, y0)`` to
    ``(x1, y1)``: lengths and directions along both axes and the initial error term; the walk
    takes ``max(dx, dy)`` steps of :func:`line_step`."""
    dx = abs(x1 - x0)
    dy = abs(y1 - y0)
    stepx = 1 if x1 >= x0 else -1
    stepy = 1 if y1 >= y0 else -1
    err = 2 * dy - dx if dx >= dy else 2 * dx - dy
    return dx, dy, stepx, stepy, err


@njit(cache=True)
def line_step(
    x: int, y: int, err: int, dx: int, dy: int, stepx: int, stepy: int
) -> tuple[int, int, int]:
    """The next cell ``(x, y)`` of the walk :func:`line_start` began, and the new error term: one
    cell along the major axis, and one along the other when the error term says so (the classic
    all-octant Bresenham)."""
    if dx >= dy:
        if err > 0:
            y += stepy
            err -= 2 * dx
        err += 2 * dy
        x += stepx
    else:
        if err > 0:
            x += stepx
            err -= 2 * dy
        err += 2 * dx
        y += stepy
    return x, y, err


@njit(cache=True)
def bresenham(x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """Cells ``(K, 2)`` of the integer line from ``(x0, y0)`` to ``(x1, y1)``, both ends included.

    The classic all-octant Bresenham (:func:`line_start`, :func:`line_step`): one cell per step
    along the major axis, in order from the start to the end.
    """
    dx, dy, stepx, stepy, err = line_start(x0, y0, x1, y1)
    n = max(dx, dy) + 1
    out = np.empty((n, 2), dtype=np.int64)
    x, y = x0, y0
    for k in range(n):
        out[k, 0] = x
        out[k, 1] = y
        x, y, err = line_step(x, y, err, dx, dy, stepx, stepy)
    return out


@njit(cache=True, _nrt=False)
def _add_clamped(grid, ix, iy, value, lo, hi):
    v = grid[iy, ix] + value
    if v < lo:
        v = lo
    elif v > hi:
        v = hi
    grid[iy, ix] = v


@njit(cache=True)
def integrate_rays(
    log_odds: np.ndarray,
    views: np.ndarray,
    origins: np.ndarray,
    res: float,
    sensors: np.ndarray,
    offsets: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    hit: np.ndarray,
    l_hit: float,
    l_miss: float,
    l_min: float,
    l_max: float,
) -> int:
    """Log-odds update of ``log_odds`` for the rays of one scan or several, one after the other.

    Scan ``i`` has the rays ``offsets[i]:offsets[i + 1]`` from its sensor ``sensors[i]`` to the
    endpoints ``(ex, ey)``; it updates the rows ``r0:r0 + h`` and columns ``c0:c0 + w`` of
    ``log_odds`` (``views[i]`` = ``(r0, c0, h, w)``; ``h = 0``: skipped) as a grid whose cell
    (0, 0) has its lower-left corner at ``origins[i]`` (one scan into a whole grid:
    ``(0, 0, *log_odds.shape)``; :func:`slam.stages.build_map` replays a growing grid in
    parts of its final one). Every cell a ray passes through gets ``l_miss``; the end cell gets
    ``l_hit`` when ``hit[k]`` (an obstacle return) and ``l_miss`` otherwise (a ray cut at the
    free-space limit). Values are clamped to ``[l_min, l_max]``. Cells outside the part are
    skipped (callers grow the grid first). Returns the number of cells updated.
    """
    count = 0
    for i in range(views.shape[0]):
        r0, c0, h, w = views[i, 0], views[i, 1], views[i, 2], views[i, 3]
        if h == 0:
            continue
        a, b = offsets[i], offsets[i + 1]
        count += _integrate_part(
            log_odds, r0, c0, h, w, origins[i, 0], origins[i, 1], res, sensors[i, 0],
            sensors[i, 1], ex[a:b], ey[a:b], hit[a:b], l_hit, l_miss, l_min, l_max,
        )  # fmt: skip
    return count


@njit(cache=True)
def _integrate_part(
    log_odds, r0, c0, h, w, ox, oy, res, sx, sy, ex, ey, hit, l_hit, l_miss, l_min, l_max
):
    """One scan of :func:`integrate_rays`: into the ``h × w`` cells of ``log_odds`` from row
    ``r0`` and column ``c0``, addressed in place (a slice would be another compiled layout)."""
    x0 = cell_index(sx, ox, res)
    y0 = cell_index(sy, oy, res)
    count = 0
    for k in range(ex.shape[0]):
        x1 = cell_index(ex[k], ox, res)
        y1 = cell_index(ey[k], oy, res)
        dx, dy, stepx, stepy, err = line_start(x0, y0, x1, y1)
        x, y = x0, y0
        for _ in range(max(dx, dy)):
            if 0 <= x < w and 0 <= y < h:
                _add_clamped(log_odds, c0 + x, r0 + y, l_miss, l_min, l_max)
                count += 1
            x, y, err = line_step(x, y, err, dx, dy, stepx, stepy)
        if 0 <= x1 < w and 0 <= y1 < h:
            _add_clamped(log_odds, c0 + x1, r0 + y1, l_hit if hit[k] else l_miss, l_min, l_max)
            count += 1
    return count
