"""Distance-field kernels for per-particle maps stored as shared, copy-on-write tiles.

Each particle's map is a truncated distance field with two layers. For every cell within ``dmax``
of a laser hit, the hit ``h`` nearest to the cell centre ``c`` is selected; ``dist`` keeps the
Euclidean distance ``|c − h|`` (which hit is nearest, and whether a new hit adds anything) and
``surface`` the distance the scan matcher reads. Cells with no hit within ``dmax`` hold ``dmax``
in ``dist`` and NaN (unknown) in ``surface``. What ``surface`` holds is ``rbpf.field``:

* ``"distance"`` (the default): the Euclidean distance again, an unsigned field;
* ``"plane"``: the signed point-to-plane distance ``(c − h)·n``, with ``n`` the surface normal at
  the hit (estimated from the neighbouring beams, pointing towards the sensor). A cell more than
  one cell size away from its hit along the surface (past the end of a wall, beside an isolated
  return) gets the offset beyond that blended in, ``sign(p)·sqrt(p² + (|t| − res)²)`` with ``p``
  the plane distance and ``t`` the tangential offset, so a return never stands for a wall it did
  not see.

Why the signed, planar option: the plane distance is a linear function of position across a
straight wall, so bilinear interpolation reproduces it exactly and its zero crossing lies on the
wall, to sub-cell precision. An unsigned distance field, interpolated, has its minimum at the cell
centre nearest the wall instead, which biases scan matching by up to half a cell. The gradient of
the plane distance is the surface normal, so the Gauss-Newton matcher behaves like point-to-plane
ICP.

Storage (the layout GMapping uses for its particle maps, made flat for numba):

* ``dist[t]`` and ``surface[t]`` are the two ``T × T`` layers of tile ``t``; ``refcount[t]``
  counts the particles using it. The unsigned field keeps one layer (``TilePool.one_layer``:
  ``dist`` is ``surface``, which holds the same values where a hit is near, and NaN is read as
  ``dmax``): the same map in half the memory, and half the bytes every insertion and copy
  moves; free tiles are on the stack ``free_stack[:free_top[0]]``;
* ``tables[p, ty, tx]`` is the tile of particle ``p`` at tile coordinates ``(tx, ty)``, or -1
  for unknown space;
* resampling copies only the small tables (children share their parent's tiles); a particle that
  writes to a shared tile copies it first (copy on write), so maps diverge only where particles
  learned something different.

The matching kernels read a map through one :class:`FieldView` (the ``surface`` layer, the tile
table(s), the tile shift and the grid's origin and inverse resolution). Cell ``(ix, iy)`` has its
lower-left corner at ``(ox + ix·res, oy + iy·res)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from slam.kernels.cells import cell_index
from slam.kernels.linalg import solve_sym3
from slam.kernels.vacancy import vacated_near


class FieldView(NamedTuple):
    """A tiled distance field as the matching kernels read it (numba takes it as one argument).

    ``table`` is one particle's ``(n_tiles_y, n_tiles_x)`` tile table, or for
    :func:`match_particles` the ``(P, n_tiles_y, n_tiles_x)`` tables of every particle.
    """

    surface: np.ndarray
    """``(tiles, T, T)`` float32: the ``surface`` layer of the tile pool (NaN: unknown)."""
    table: np.ndarray
    """int32 tile indices (-1: no tile, unknown space)."""
    shift: int
    """``log2(T)``: tiles are ``2**shift`` cells wide."""
    ox: float
    """World x of the lower-left corner of cell (0, 0) (m)."""
    oy: float
    """World y of the lower-left corner of cell (0, 0) (m)."""
    inv_res: float
    """``1 / resolution`` (cells per metre)."""
    vacated: np.ndarray = np.zeros((0, 0), np.uint8)
    """Where later rays went through the maps' hits: the ``vacated`` layer of a vacancy grid
    (:mod:`slam.kernels.vacancy`; a return whose nearest hit is vacated counts as unexplained).
    Empty (the default): none. Its geometry follows (fields of their own: numba's parallel
    loops do not take a tuple nested in a tuple)."""
    vac_ox: float = 0.0
    """World x of the lower-left corner of the vacancy grid's cell (0, 0) (m)."""
    vac_oy: float = 0.0
    """World y of the lower-left corner of the vacancy grid's cell (0, 0) (m)."""
    vac_res: float = 1.0
    """The vacancy grid's cell size (m)."""


class TilePool(NamedTuple):
    """Every particle's map as the insertion kernels write it (numba takes it as one argument)."""

    dist: np.ndarray
    """``(tiles, T, T)`` float32 Euclidean distance to the nearest hit (``dmax``: none near)."""
    surface: np.ndarray
    """``(tiles, T, T)`` float32 distance the matcher reads (NaN: unknown)."""
    refcount: np.ndarray
    """``(tiles,)`` int32 particles using each tile."""
    free_stack: np.ndarray
    """``(tiles,)`` int32 free tiles, ``free_stack[:free_top[0]]``."""
    free_top: np.ndarray
    """``(1,)`` int64 number of free tiles."""
    tables: np.ndarray
    """``(P, n_tiles_y, n_tiles_x)`` int32 tile of each particle at each tile position (-1)."""
    spans: np.ndarray
    """``(n_tiles_y, 2)`` int64: in each row of ``tables``, the first and the last column where
    any particle's table may hold a tile (first > last: none); outside them every entry is -1."""
    shift: int
    """``log2(T)``."""
    ox: float
    """World x of the lower-left corner of cell (0, 0) (m)."""
    oy: float
    """World y of the lower-left corner of cell (0, 0) (m)."""
    res: float
    """Cell size (m)."""
    dmax: float
    """Distance cap (m): cells farther from every hit are unknown."""
    one_layer: bool
    """``dist`` is ``surface`` (the unsigned field): a NaN there reads as ``float32(dmax)``,
    what the ``dist`` layer would hold."""


VACATED = 1e6
"""The field value :func:`beam_geometry` gives a beam whose nearest hit was seen through: beyond
every likelihood table, so the cost of a beam far from every hit."""


class MatchSettings(NamedTuple):
    """How the scan matcher runs (numba takes it as one argument)."""

    luts: np.ndarray
    """``(levels, 2, size)`` likelihood tables, wide sigma to narrow
    (:func:`slam.mapping.likelihood_tables`)."""
    step_inv: float
    """``1 / step`` of the tables."""
    max_iter: int
    """Levenberg-Marquardt iterations per level at most."""
    tolerance: float
    """A level ends when a step moves less than this (m or rad)."""
    coarse_stride: int
    """The levels before the last use every ``coarse_stride``-th beam."""
    min_inliers: float
    """Least fraction of beams on known cells for a match to be trusted."""


class MatchOutput(NamedTuple):
    """Where :func:`match_particles` writes, one row per particle."""

    poses: np.ndarray
    """``(P, 3)`` refined poses (the predicted pose where the match was not trusted)."""
    loglik: np.ndarray
    """``(P,)`` log-likelihood of the scan at each refined pose (narrowest table)."""
    inliers: np.ndarray
    """``(P,)`` fraction of beams on known cells."""
    hessian: np.ndarray
    """``(P, 3, 3)`` Gauss-Newton Hessian of the negative log-likelihood at each refined pose."""


@njit(cache=True, inline="always")
def cell_distance(
    pool: np.ndarray, table: np.ndarray, shift: int, ix: int, iy: int, dmax: float
) -> float:
    """Distance stored at cell ``(ix, iy)`` of one particle's map (``dmax`` where no tile
    covers it; a NaN stored, a one-layer pool's cell with no hit near, reads as the
    ``float32(dmax)`` the ``dist`` layer holds there).

    Tiles are ``2**shift`` cells wide (shifts and masks are much cheaper than divisions here).
    """
    if ix < 0 or iy < 0:
        return dmax
    tx = ix >> shift
    ty = iy >> shift
    if ty >= table.shape[0] or tx >= table.shape[1]:
        return dmax
    t = table[ty, tx]
    if t < 0:
        return dmax
    mask = (1 << shift) - 1
    d = pool[t, iy & mask, ix & mask]
    if d != d:
        return np.float32(dmax)
    return d


@njit(cache=True, inline="always")
def surface_at(view: FieldView, x: float, y: float) -> tuple[float, float, float]:
    """Bilinearly interpolated ``surface`` distance at ``(x, y)`` and its gradient.

    ``view.table`` is one particle's tile table. Returns NaN (and a zero gradient) where any of
    the four cells around the point is unknown.
    """
    inv_res = view.inv_res
    gx = (x - view.ox) * inv_res - 0.5
    gy = (y - view.oy) * inv_res - 0.5
    if gx < 0.0 or gy < 0.0:
        return np.nan, 0.0, 0.0
    d, ddx, ddy = _interpolate(view.surface, view.table, view.shift, gx, gy, inv_res)
    if np.isnan(d):
        return np.nan, 0.0, 0.0
    return d, ddx, ddy


@njit(cache=True, inline="always")
def _interpolate(
    surface: np.ndarray, table: np.ndarray, shift: int, gx: float, gy: float, inv_res: float
) -> tuple[float, float, float]:
    """The bilinear value and gradient of :func:`surface_at` at grid coordinates ``(gx, gy)``
    (``≥ 0``, in cells from the centre of cell (0, 0)); a NaN value where a corner is unknown.

    The indices are unsigned: numba then omits the negative-index wraparound it adds to every
    signed index (they are never negative here), which makes the field lookups ~8 % faster."""
    ix = int(gx)  # truncation is the floor for non-negative values, and much cheaper
    iy = int(gy)
    fx = gx - ix
    fy = gy - iy
    mask = (1 << shift) - 1
    lx = ix & mask
    ly = iy & mask
    if lx < mask and ly < mask:
        tx = ix >> shift
        ty = iy >> shift
        if ty >= table.shape[0] or tx >= table.shape[1]:
            return np.nan, 0.0, 0.0
        t = table[np.uint64(ty), np.uint64(tx)]
        if t < 0:
            return np.nan, 0.0, 0.0
        ut, uy, ux, one = np.uint64(t), np.uint64(ly), np.uint64(lx), np.uint64(1)
        d00 = surface[ut, uy, ux]
        d10 = surface[ut, uy, ux + one]
        d01 = surface[ut, uy + one, ux]
        d11 = surface[ut, uy + one, ux + one]
    else:
        d00 = _cell(surface, table, shift, ix, iy)
        d10 = _cell(surface, table, shift, ix + 1, iy)
        d01 = _cell(surface, table, shift, ix, iy + 1)
        d11 = _cell(surface, table, shift, ix + 1, iy + 1)
    d = (1.0 - fy) * ((1.0 - fx) * d00 + fx * d10) + fy * ((1.0 - fx) * d01 + fx * d11)
    ddx = ((1.0 - fy) * (d10 - d00) + fy * (d11 - d01)) * inv_res
    ddy = ((1.0 - fx) * (d01 - d00) + fx * (d11 - d10)) * inv_res
    return d, ddx, ddy


@njit(cache=True, inline="always")
def _cell(layer: np.ndarray, table: np.ndarray, shift: int, ix: int, iy: int) -> float:
    """``layer`` at cell ``(ix, iy)`` (``≥ 0``) of one particle's map, NaN where unknown."""
    tx = ix >> shift
    ty = iy >> shift
    if ty >= table.shape[0] or tx >= table.shape[1]:
        return np.nan
    t = table[np.uint64(ty), np.uint64(tx)]
    if t < 0:
        return np.nan
    mask = (1 << shift) - 1
    return layer[np.uint64(t), np.uint64(iy & mask), np.uint64(ix & mask)]


@njit(cache=True, inline="always")
def table_lookup(row: np.ndarray, step_inv: float, d: float) -> float:
    """Linear interpolation in a table sampled at ``d = 0, 1/step_inv, 2/step_inv, ...``
    (``d ≥ 0``; the last entry beyond the table)."""
    u = d * step_inv
    last = row.shape[0] - 1
    if u >= last:
        return row[last]
    i = int(u)
    f = u - i
    return row[i] + f * (row[i + 1] - row[i])


@njit(cache=True, nogil=True)
def normal_equations(
    view: FieldView,
    x: float,
    y: float,
    th: float,
    ex: np.ndarray,
    ey: np.ndarray,
    cost_row: np.ndarray,
    weight_row: np.ndarray,
    step_inv: float,
    h: np.ndarray,
    g: np.ndarray,
    stride: int = 1,
) -> tuple[float, int]:
    """One pass over the beams at pose ``(x, y, th)``: cost, Gauss-Newton system, inliers.

    The cost is the negative log-likelihood of the endpoints ``(ex, ey)`` (robot frame) under the
    likelihood-field model, ``Σ −log(z_hit·exp(−d²/2σ²) + z_rand)`` with ``d`` the field value at
    the endpoint (the cap ``dmax`` where unknown). ``h`` and ``g`` receive the Gauss-Newton
    approximation of its Hessian and its gradient, each beam weighted by its responsibility
    ``γ/σ²`` with ``γ = z_hit·φ / (z_hit·φ + z_rand)``. Both functions of ``|d|`` come from tables
    (``cost_row``, ``weight_row``; see :func:`slam.mapping.likelihood_tables`), which avoids an
    ``exp`` and a ``log`` per beam. Only every ``stride``-th beam is used. Returns the cost and
    the number of beams on known cells.

    Two passes: the field at the endpoints (:func:`beam_geometry`, the view's fields read once,
    interpolated by :func:`surface_at`'s own :func:`_interpolate`; with a vacancy grid, the
    beams whose nearest hit is gone marked at this pose first, :func:`mark_gone`), then the
    tables (:func:`accumulate`).
    """
    every = np.int64(stride)  # one type for the callee whether ``stride`` is given or not
    n = (ex.shape[0] + every - 1) // every
    geo = np.empty((n, 4))
    gone = np.zeros(n, np.uint8)
    mark_gone(gone, view, x, y, th, every, ex, ey)
    beam_geometry(geo, view, x, y, th, every, ex, ey, gone)
    return accumulate(geo, cost_row, weight_row, step_inv, h, g)


@njit(cache=True, _nrt=False)
def beam_geometry(
    geo: np.ndarray,
    view: FieldView,
    x: float,
    y: float,
    th: float,
    stride: int,
    ex: np.ndarray,
    ey: np.ndarray,
    gone: np.ndarray,
) -> None:
    """The field at every ``stride``-th endpoint at pose ``(x, y, th)``, for :func:`accumulate`:
    ``geo[j]`` is the value ``d`` (NaN: unknown), its gradient ``(∂d/∂x, ∂d/∂y)`` and its
    derivative by the heading, of beam ``j·stride``. With a vacancy grid in the view, a beam
    marked in ``gone[j]`` (:func:`mark_gone`: its nearest hit later rays went through,
    :mod:`slam.kernels.vacancy`) reads :data:`VACATED` with no gradient: on a known cell (it
    counts among the inliers: the space is known, as free) at the cost of a beam far from every
    hit.

    Apart from the tables, so that a level of :func:`refine` that starts where the previous one
    ended (with the same stride) reuses it: only the tables change from level to level.
    """
    surface, table, shift = view.surface, view.table, view.shift
    ox, oy, inv_res = view.ox, view.oy, view.inv_res
    vacant = view.vacated.shape[0] > 0
    c = np.cos(th)
    s = np.sin(th)
    for j in range(geo.shape[0]):
        b = j * stride
        rx = c * ex[b] - s * ey[b]
        ry = s * ex[b] + c * ey[b]
        fgx = (x + rx - ox) * inv_res - 0.5
        fgy = (y + ry - oy) * inv_res - 0.5
        if fgx < 0.0 or fgy < 0.0:
            geo[j, 0] = np.nan
        else:
            if vacant and gone[j]:
                # its nearest hit was seen through: known space that no surface explains, the
                # cost of a beam far from every hit and no gradient
                geo[j, 0] = VACATED
                geo[j, 1] = 0.0
                geo[j, 2] = 0.0
                geo[j, 3] = 0.0
                continue
            d, gx, gy = _interpolate(surface, table, shift, fgx, fgy, inv_res)
            geo[j, 0] = d
            geo[j, 1] = gx
            geo[j, 2] = gy
            geo[j, 3] = -gx * ry + gy * rx


@njit(cache=True, _nrt=False)
def mark_gone(gone: np.ndarray, view: FieldView, x: float, y: float, th: float, stride: int,
              ex: np.ndarray, ey: np.ndarray) -> None:  # fmt: skip
    """Mark in ``gone[j]`` the beams ``j·stride`` whose endpoint at pose ``(x, y, th)`` draws on a
    hit that later rays went through (:func:`_through`); nothing without a vacancy grid.

    :func:`refine` marks them where it first reads a level's beams — with ``coarse_stride`` 1
    (the default) once, at the pose the match starts from, for every level; with a larger
    stride again where the last level starts — and keeps the marks over the steps (a step moves
    the endpoints by centimetres; the nearest hit rarely changes), so the vacancy grid is read
    once a beam rather than at every step. A score computed afresh at the final pose
    (:func:`normal_equations`) marks there, and may differ from the match's own."""
    if view.vacated.shape[0] == 0:
        return
    surface, table, shift = view.surface, view.table, view.shift
    ox, oy, inv_res = view.ox, view.oy, view.inv_res
    c = np.cos(th)
    s = np.sin(th)
    for j in range(gone.shape[0]):
        b = j * stride
        wx = x + c * ex[b] - s * ey[b]
        wy = y + s * ex[b] + c * ey[b]
        fgx = (wx - ox) * inv_res - 0.5
        fgy = (wy - oy) * inv_res - 0.5
        gone[j] = 0
        if fgx >= 0.0 and fgy >= 0.0:
            d, gx, gy = _interpolate(surface, table, shift, fgx, fgy, inv_res)
            if d == d and _through(view, wx, wy, d, gx, gy):
                gone[j] = 1


@njit(cache=True, inline="always")
def _through(view: FieldView, wx: float, wy: float, d: float, gx: float, gy: float) -> bool:
    """Whether the hit nearest to the endpoint ``(wx, wy)`` — the endpoint moved back by its
    field value ``d`` against the field's gradient ``(gx, gy)`` — is vacated."""
    norm = np.sqrt(gx * gx + gy * gy)
    if norm > 1e-9:
        wx -= d * gx / norm
        wy -= d * gy / norm
    return vacated_near(view.vacated, view.vac_ox, view.vac_oy, view.vac_res, wx, wy)


@njit(cache=True, _nrt=False)
def accumulate(
    geo: np.ndarray,
    cost_row: np.ndarray,
    weight_row: np.ndarray,
    step_inv: float,
    h: np.ndarray,
    g: np.ndarray,
) -> tuple[float, int]:
    """Cost, Gauss-Newton system and inliers of :func:`normal_equations` from the beams'
    :func:`beam_geometry` ``geo``: :func:`scan_cost`, then :func:`gauss_newton_system` (two
    loops over ``geo``, which sits in the first-level cache; each sum is the same operations in
    the same order as in one loop, so the same bits)."""
    cost, inliers = scan_cost(geo, cost_row, step_inv)
    gauss_newton_system(geo, weight_row, step_inv, h, g)
    return cost, inliers


@njit(cache=True, _nrt=False)
def scan_cost(geo: np.ndarray, cost_row: np.ndarray, step_inv: float) -> tuple[float, int]:
    """The cost and inliers of :func:`accumulate` alone: what :func:`refine` needs to accept or
    reject a step (about half its steps are rejected, and a rejected step's system is never
    used). :func:`table_lookup` written out, as in :func:`gauss_newton_system`."""
    last_c = cost_row.shape[0] - 1
    unknown = cost_row[last_c]
    cost = 0.0
    inliers = 0
    for j in range(geo.shape[0]):
        d = geo[j, 0]
        if np.isnan(d):
            cost += unknown
            continue
        u = abs(d) * step_inv
        i = int(u)
        f = u - i
        ui = np.uint64(i)  # ≥ 0: no negative-index wraparound (see _interpolate)
        if u >= last_c:
            cost += cost_row[last_c]
        else:
            cost += cost_row[ui] + f * (cost_row[ui + np.uint64(1)] - cost_row[ui])
        inliers += 1
    return cost, inliers


@njit(cache=True, _nrt=False)
def gauss_newton_system(
    geo: np.ndarray, weight_row: np.ndarray, step_inv: float, h: np.ndarray, g: np.ndarray
) -> None:
    """The Gauss-Newton system of :func:`accumulate` into ``h`` and ``g``: each known beam
    weighted by its responsibility (``weight_row`` at ``|d|``)."""
    last_w = weight_row.shape[0] - 1
    # accumulate in scalars (kept in registers), write the arrays once at the end
    h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    g0 = g1 = g2 = 0.0
    for j in range(geo.shape[0]):
        d = geo[j, 0]
        if np.isnan(d):
            continue
        gx = geo[j, 1]
        gy = geo[j, 2]
        j2 = geo[j, 3]
        u = abs(d) * step_inv
        i = int(u)
        f = u - i
        ui = np.uint64(i)
        if u >= last_w:
            wgt = weight_row[last_w]
        else:
            wgt = weight_row[ui] + f * (weight_row[ui + np.uint64(1)] - weight_row[ui])
        wgx = wgt * gx
        wgy = wgt * gy
        wj2 = wgt * j2
        h00 += wgx * gx
        h01 += wgx * gy
        h02 += wgx * j2
        h11 += wgy * gy
        h12 += wgy * j2
        h22 += wj2 * j2
        g0 += wgx * d
        g1 += wgy * d
        g2 += wj2 * d
    h[0, 0] = h00
    h[0, 1] = h01
    h[0, 2] = h02
    h[1, 0] = h01
    h[1, 1] = h11
    h[1, 2] = h12
    h[2, 0] = h02
    h[2, 1] = h12
    h[2, 2] = h22
    g[0] = g0
    g[1] = g1
    g[2] = g2


@njit(cache=True, nogil=True)
def match_one(
    view: FieldView,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    luts: np.ndarray,
    step_inv: float,
    max_iter: int,
    tolerance: float,
    coarse_stride: int,
) -> tuple[np.ndarray, float, int]:
    """Refine ``pose`` so the endpoints ``(ex, ey)`` (robot frame) fit the field.

    Levenberg-Marquardt on the negative log-likelihood (see :func:`normal_equations`), level by
    level through the likelihood tables ``luts[level]`` (wide sigma to narrow) so the first levels
    pull in from further away; the wide levels, which only need to bring the pose into the narrow
    basin, use every ``coarse_stride``-th beam (:func:`refine`). Returns the refined pose (heading
    wrapped to ``[-π, π)``), its cost at the last level and its inliers.
    """
    settings = MatchSettings(luts, step_inv, max_iter, tolerance, coarse_stride, 0.0)
    x, y, th, cost, inliers = refine(view, pose, ex, ey, settings, np.zeros((3, 3)))
    out = np.empty(3)
    out[0] = x
    out[1] = y
    out[2] = (th + np.pi) % (2.0 * np.pi) - np.pi
    return out, cost, inliers


@njit(cache=True)
def refine(
    view: FieldView,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    settings: MatchSettings,
    h: np.ndarray,
) -> tuple[float, float, float, float, int]:
    """The levels of :func:`match_one`: the refined pose ``(x, y, θ)`` (heading not wrapped), its
    cost under the last table and its inliers; ``h`` receives the Gauss-Newton Hessian there
    (the last level uses every beam, so it is :func:`normal_equations`' at that pose).

    Each iteration costs one pass over the beams: a step that does not lower the cost is undone
    and the damping raised (its cost alone was computed, :func:`scan_cost`; the Gauss-Newton
    system only for a step taken); a level ends when a step moves less than
    ``settings.tolerance``. A level that uses the beams of the previous one starts from that
    level's field values at the pose it ended at (:func:`beam_geometry`), so only its tables are
    read again. With a vacancy grid, the beams whose nearest hit is gone are marked where a
    level first reads its beams (:func:`mark_gone`) and stay marked over its steps.
    """
    luts, step_inv, max_iter = settings.luts, settings.step_inv, settings.max_iter
    tolerance, coarse_stride = settings.tolerance, settings.coarse_stride
    x, y, th = pose[0], pose[1], pose[2]
    g = np.zeros(3)
    hd = np.zeros((3, 3))
    cost = 0.0
    inliers = 0
    last = luts.shape[0] - 1
    geo = np.empty((ex.shape[0], 4))  # the field at the beams at the current pose
    trial = np.empty((ex.shape[0], 4))  # ... at the pose tried
    gone = np.zeros(ex.shape[0], np.uint8)  # beams whose nearest hit is gone (this level)
    known = 0  # stride of the beams in ``geo`` (0: none yet)
    for level in range(luts.shape[0]):
        cost_row = luts[level, 0]
        weight_row = luts[level, 1]
        stride = 1 if level == last else coarse_stride
        n = (ex.shape[0] + stride - 1) // stride
        if known != stride:  # else the previous level ended at this pose with these beams
            mark_gone(gone[:n], view, x, y, th, stride, ex, ey)
            beam_geometry(geo[:n], view, x, y, th, stride, ex, ey, gone)
            known = stride
        cost, inliers = accumulate(geo[:n], cost_row, weight_row, step_inv, h, g)
        lam = 1e-3
        for _ in range(max_iter):
            for a in range(3):
                for b in range(3):
                    hd[a, b] = h[a, b]
            for k in range(3):
                hd[k, k] += lam * h[k, k] + 1e-9
            s0, s1, s2, _ = solve_sym3(
                hd[0, 0], hd[0, 1], hd[0, 2], hd[1, 1], hd[1, 2], hd[2, 2], g[0], g[1], g[2], 1e-18
            )  # a singular system gives a zero step, which does not lower the cost
            nx = x - s0
            ny = y - s1
            nth = th - s2
            beam_geometry(trial[:n], view, nx, ny, nth, stride, ex, ey, gone)
            new_cost, new_inliers = scan_cost(trial[:n], cost_row, step_inv)
            if new_cost < cost:  # the step is taken: its system too
                gauss_newton_system(trial[:n], weight_row, step_inv, h, g)
                x, y, th, cost, inliers = nx, ny, nth, new_cost, new_inliers
                geo, trial = trial, geo
                lam = max(lam * 0.3, 1e-7)
                if abs(s0) < tolerance and abs(s1) < tolerance and abs(s2) < tolerance:
                    break
            else:
                lam *= 10.0
                if lam > 1e3:
                    break
    return x, y, th, cost, inliers


@njit(cache=True, parallel=True)
def match_particles(
    view: FieldView,
    poses: np.ndarray,
    ends: np.ndarray,
    settings: MatchSettings,
    out: MatchOutput,
    yaws: np.ndarray,
    probe: MatchOutput,
) -> None:
    """Scan-match every particle against its own map (the proposal), then score it; then the
    basin probe's matches, in the same call.

    ``ends`` is ``(2, B)``: the scan's endpoints ``(ex, ey)`` in the robot frame; ``view.table``
    holds every particle's tile table. For each particle: refine its predicted pose with
    :func:`refine`; if fewer than ``settings.min_inliers`` of the beams then fall on known cells
    the match is not trusted and the predicted pose is kept. ``out.loglik`` is the
    log-likelihood of the scan at the final pose under the last (narrowest) table;
    ``out.inliers`` the fraction of beams on known cells; ``out.hessian`` the Gauss-Newton
    Hessian of the negative log-likelihood there (its inverse is the covariance of the match,
    the spread of the proposal).

    Then, for the particle ``b`` with the highest ``out.loglik`` (the first of equals), its
    predicted pose turned by each of ``yaws`` (heading wrapped to ``[-π, π)``) is matched the
    same way against its map into row ``s`` of ``probe`` (``rbpf.probe_yaw``, the basin probe
    of :class:`slam.particle_filter.RbpfFilter`: one kernel call instead of two). Empty
    ``yaws``: no probe.
    """
    for p in prange(poses.shape[0]):
        _match_particle(view, np.int64(p), poses[p], ends, settings, out, np.int64(p))
    if yaws.shape[0] == 0 or poses.shape[0] == 0:
        return
    b = 0
    for p in range(1, poses.shape[0]):
        if out.loglik[p] > out.loglik[b]:
            b = p
    starts = np.empty((yaws.shape[0], 3))
    for s in range(yaws.shape[0]):
        starts[s, 0] = poses[b, 0]
        starts[s, 1] = poses[b, 1]
        starts[s, 2] = (poses[b, 2] + yaws[s] + np.pi) % (2.0 * np.pi) - np.pi
    for s in prange(yaws.shape[0]):
        _match_particle(view, np.int64(b), starts[s], ends, settings, probe, np.int64(s))


@njit(cache=True)
def _match_particle(
    view: FieldView,
    p: int,
    pose: np.ndarray,
    ends: np.ndarray,
    settings: MatchSettings,
    out: MatchOutput,
    row: int,
) -> None:
    """:func:`match_particles` for ``pose`` against particle ``p``'s map, into row ``row`` of
    ``out`` (a serial function: the parallel loops only call it, which keeps numba's parallel
    regions, slow to compile, tiny).

    The score and Hessian at the refined pose are those of the matcher's last evaluation when
    that was at the very pose reported (the wrapped heading has the same bits); else (a heading
    wrapping changed, an untrusted match) one more pass computes them.
    """
    luts = settings.luts
    ex, ey = ends[0], ends[1]
    nbeams = max(ex.shape[0], 1)
    own = FieldView(
        view.surface, view.table[p], view.shift, view.ox, view.oy, view.inv_res, view.vacated,
        view.vac_ox, view.vac_oy, view.vac_res,
    )  # fmt: skip
    h = np.zeros((3, 3))
    x, y, th, cost, inliers = refine(own, pose, ex, ey, settings, h)
    frac = inliers / nbeams
    wrapped = (th + np.pi) % (2.0 * np.pi) - np.pi
    if frac < settings.min_inliers:
        x, y, wrapped = pose[0], pose[1], pose[2]
    if frac < settings.min_inliers or wrapped != th or th == 0.0:  # (-0.0 wraps to 0.0)
        fine = luts[luts.shape[0] - 1]
        cost, _ = normal_equations(
            own, x, y, wrapped, ex, ey, fine[0], fine[1], settings.step_inv, h, np.zeros(3),
            np.int64(1),
        )  # fmt: skip
    for a in range(3):
        for b in range(3):
            out.hessian[row, a, b] = h[a, b]
    out.poses[row, 0] = x
    out.poses[row, 1] = y
    out.poses[row, 2] = wrapped
    out.inliers[row] = frac
    out.loglik[row] = -cost


@njit(cache=True, parallel=True)
def insert_particles(
    pool: TilePool,
    poses: np.ndarray,
    hits: np.ndarray,
    skip_below: float,
    keep: np.ndarray,
    signed: bool,
    start: int,
    select: bool,
) -> int:
    """Insert the hits ``hits`` ``(4, K)`` — robot-frame ``(hx, hy)`` and unit normals
    ``(nx, ny)`` — into every particle's map at ``poses``, in three steps (one kernel call):

    1. (when ``select``) mark in ``keep[p, k]`` the hits that add something to particle ``p``'s
       map, in parallel (:func:`_select_particle`): a hit adds nothing when the cell it falls in
       already knows a hit about as close (within ``skip_below``) as this one, or when the
       previous hit of the same scan fell in the same cell, so re-observed walls neither copy
       tiles nor move the field;
    2. give each particle, from ``start`` on, exclusive tiles under the footprint of its kept
       hits, serially (:func:`_claim_particle`: a missing tile is allocated, a shared one copied
       — copy on write);
    3. write the kept hits into those tiles, in parallel (:func:`_splat_particle`: each particle
       writes only tiles it owns alone).

    Returns -1 when done, or the particle that ran out of free tiles in step 2 (step 3 not
    done): the caller grows the pool and calls again from it with ``select`` false.
    """
    if select:
        for p in prange(poses.shape[0]):
            _select_particle(pool, poses, np.int64(p), hits[0], hits[1], skip_below, keep)
    for p in range(start, poses.shape[0]):
        if not _claim_particle(pool, poses, p, hits[0], hits[1], keep):
            return p
    for p in prange(poses.shape[0]):
        _splat_particle(pool, poses, np.int64(p), hits, keep, signed)
    return -1


@njit(cache=True, _nrt=False)
def _select_particle(
    pool: TilePool,
    poses: np.ndarray,
    p: int,
    hx: np.ndarray,
    hy: np.ndarray,
    skip_below: float,
    keep: np.ndarray,
) -> None:
    """Step 1 of :func:`insert_particles` for particle ``p``. The hit's distance to its cell's centre (a
    ``hypot``) is computed only where the cell's stored distance does not decide alone: at most
    ``skip_below`` (no hit adds anything), beyond ``res + skip_below`` (any hit in the cell is
    closer) — the same decisions, bit for bit."""
    dist, shift, dmax = pool.dist, pool.shift, pool.dmax
    ox, oy, res = pool.ox, pool.oy, pool.res
    table = pool.tables[p]
    sure = res + skip_below  # a cell farther than this from its hits gains by any hit in it
    c = np.cos(poses[p, 2])
    s = np.sin(poses[p, 2])
    last_x = -(1 << 30)
    last_y = -(1 << 30)
    for k in range(hx.shape[0]):
        wx = poses[p, 0] + c * hx[k] - s * hy[k]
        wy = poses[p, 1] + s * hx[k] + c * hy[k]
        cx = cell_index(wx, ox, res)
        cy = cell_index(wy, oy, res)
        if cx == last_x and cy == last_y:
            keep[p, k] = False
            continue
        last_x = cx
        last_y = cy
        known = cell_distance(dist, table, shift, cx, cy, dmax)
        if known <= skip_below:  # the hit's own distance is ≥ 0: nothing closer to add
            keep[p, k] = False
        elif known > sure and np.isfinite(wx + wy):  # its own distance is < res: closer
            keep[p, k] = True
        else:
            own = np.hypot(ox + (cx + 0.5) * res - wx, oy + (cy + 0.5) * res - wy)
            keep[p, k] = known > own + skip_below


@njit(cache=True, _nrt=False)
def _claim_particle(
    pool: TilePool,
    poses: np.ndarray,
    p: int,
    hx: np.ndarray,
    hy: np.ndarray,
    keep: np.ndarray,
) -> bool:
    """Step 2 of :func:`insert_particles` for particle ``p``; ``False`` when the pool ran out of free tiles
    (the tiles claimed so far stay claimed: claiming again from ``p`` skips them)."""
    dist, surface, refcount = pool.dist, pool.surface, pool.refcount
    free_stack, free_top, shift = pool.free_stack, pool.free_top, pool.shift
    ox, oy, res, dmax = pool.ox, pool.oy, pool.res, pool.dmax
    spans = pool.spans
    radius = int(np.ceil(dmax / res))
    ntile_y = pool.tables.shape[1]
    ntile_x = pool.tables.shape[2]
    table = pool.tables[p]
    c = np.cos(poses[p, 2])
    s = np.sin(poses[p, 2])
    for k in range(hx.shape[0]):
        if keep[p, k]:  # a hit that adds something: its footprint
            wx = poses[p, 0] + c * hx[k] - s * hy[k]
            wy = poses[p, 1] + s * hx[k] + c * hy[k]
            cx = cell_index(wx, ox, res)
            cy = cell_index(wy, oy, res)
            ty0 = max(cy - radius, 0) >> shift
            ty1 = min(cy + radius, (ntile_y << shift) - 1) >> shift
            tx0 = max(cx - radius, 0) >> shift
            tx1 = min(cx + radius, (ntile_x << shift) - 1) >> shift
            for ty in range(ty0, ty1 + 1):
                for tx in range(tx0, tx1 + 1):
                    t = table[ty, tx]
                    if t >= 0 and refcount[t] == 1:
                        continue
                    if free_top[0] == 0:
                        return False
                    free_top[0] -= 1
                    new = free_stack[free_top[0]]
                    if t < 0:
                        _fill_tile(dist, surface, new, dmax, pool.one_layer)
                        spans[ty, 0] = min(spans[ty, 0], tx)
                        spans[ty, 1] = max(spans[ty, 1], tx)
                    else:
                        _copy_tile(dist, surface, t, new, pool.one_layer)
                        refcount[t] -= 1
                    refcount[new] = 1
                    table[ty, tx] = new
    return True


@njit(cache=True, _nrt=False)
def _fill_tile(
    dist: np.ndarray, surface: np.ndarray, tile: int, dmax: float, one_layer: bool
) -> None:
    """Make ``tile`` an empty tile: distance ``dmax``, surface unknown (NaN; only that with
    ``one_layer``).

    Loops rather than ``dist[tile, :, :] = dmax``-style slice assignments: those compile numba's
    shape-mismatch error path (string formatting), seconds of compilation each.
    """
    for r in range(dist.shape[1]):
        for c in range(dist.shape[2]):
            if not one_layer:
                dist[tile, r, c] = dmax
            surface[tile, r, c] = np.nan


@njit(cache=True, _nrt=False)
def _copy_tile(dist: np.ndarray, surface: np.ndarray, src: int, dst: int, one_layer: bool) -> None:
    """Copy tile ``src`` (both layers, or the one) into tile ``dst``."""
    for r in range(dist.shape[1]):
        for c in range(dist.shape[2]):
            if not one_layer:
                dist[dst, r, c] = dist[src, r, c]
            surface[dst, r, c] = surface[src, r, c]


@njit(cache=True, _nrt=False)
def _splat_particle(
    pool: TilePool, poses: np.ndarray, p: int, hits: np.ndarray, keep: np.ndarray, signed: bool
) -> None:
    """Step 3 of :func:`insert_particles` for particle ``p``: every cell within ``dmax`` of a
    kept hit for which this hit is the nearest so far takes its Euclidean distance (``dist``)
    and, in ``surface``, its signed plane distance when ``signed`` (else the Euclidean distance
    again: the unsigned field, written once when ``pool.one_layer``, where a NaN stands for the
    ``float32(dmax)`` of a cell no hit is near).

    Most cells of a hit's square are decided by squared distances alone, with no square root:
    those outside the disc of radius ``dmax`` (whole rows first), and those whose stored
    distance is already smaller. Both tests compare against the squared bound enlarged by a
    relative ``1e-9``, far beyond the rounding of a square root, so every cell they skip is one
    the exact test skips too: the same maps bit for bit (``insert_particles`` on the demo at
    1000 particles 9.6 → 8.2 s). The indices are unsigned (see :func:`_interpolate`)."""
    dist, surface, shift = pool.dist, pool.surface, pool.shift
    ox, oy, res, dmax = pool.ox, pool.oy, pool.res, pool.dmax
    empty = np.float32(dmax)  # what ``dist`` holds where no hit is near
    one_layer = pool.one_layer
    radius = int(np.ceil(dmax / res))
    mask = (1 << shift) - 1
    ny_cells = pool.tables.shape[1] << shift
    nx_cells = pool.tables.shape[2] << shift
    table = pool.tables[p]
    far = dmax * dmax * (1.0 + 1e-9)  # a squared distance beyond this is beyond dmax
    c = np.cos(poses[p, 2])
    s = np.sin(poses[p, 2])
    for k in range(hits.shape[1]):
        if not keep[p, k]:
            continue
        hx, hy, nx, ny = hits[0, k], hits[1, k], hits[2, k], hits[3, k]
        wx = poses[p, 0] + c * hx - s * hy
        wy = poses[p, 1] + s * hx + c * hy
        wnx = c * nx - s * ny
        wny = s * nx + c * ny
        cx = cell_index(wx, ox, res)
        cy = cell_index(wy, oy, res)
        x0 = max(cx - radius, 0)
        x1 = min(cx + radius + 1, nx_cells)
        for iy in range(max(cy - radius, 0), min(cy + radius + 1, ny_cells)):
            ccy = oy + (iy + 0.5) * res - wy
            rest = far - ccy * ccy  # what the row leaves of the disc, squared
            if rest <= 0.0:
                continue
            ty = np.uint64(iy >> shift)
            ly = np.uint64(iy & mask)
            for ix in range(x0, x1):
                ccx = ox + (ix + 0.5) * res - wx
                if ccx * ccx >= rest:
                    continue
                d2 = ccx * ccx + ccy * ccy
                if d2 >= far:
                    continue
                t = np.uint64(table[ty, np.uint64(ix >> shift)])
                lx = np.uint64(ix & mask)
                known = dist[t, ly, lx]
                if known == known and d2 >= np.float64(known) * known * (1.0 + 1e-9):
                    continue  # the cell already knows a hit at least as near
                d = np.sqrt(d2)
                if d >= dmax:
                    continue
                if d < known or (known != known and d < empty):
                    dist[t, ly, lx] = d
                    if not signed:
                        if not one_layer:
                            surface[t, ly, lx] = d
                        continue
                    normal = ccx * wnx + ccy * wny
                    beyond = abs(ccy * wnx - ccx * wny) - res
                    if beyond > 0.0:
                        normal = np.copysign(np.sqrt(normal * normal + beyond * beyond), normal)
                    surface[t, ly, lx] = normal


@njit(cache=True)
def insert_serial(
    pool: TilePool,
    poses: np.ndarray,
    hits: np.ndarray,
    skip_below: float,
    signed: bool,
    keep: np.ndarray,
    start: int,
) -> int:
    """The three steps of :func:`insert_particles` particle by particle in one serial call, for
    few poses (one scan placed into one map): a parallel region's start costs more than the work
    of one pose. ``hits`` as for :func:`insert_particles`. The same result as it (each particle
    writes only tiles it owns alone, and claims in the same order). Returns -1 when done, or the particle that ran out of free tiles (grow the pool and
    call again from there)."""
    for p in range(start, poses.shape[0]):
        _select_particle(pool, poses, p, hits[0], hits[1], skip_below, keep)
        if not _claim_particle(pool, poses, p, hits[0], hits[1], keep):
            return p
        _splat_particle(pool, poses, p, hits, keep, signed)
    return -1


@njit(cache=True, nogil=True)
def insert_scans(
    pool: TilePool,
    poses: np.ndarray,
    hits: np.ndarray,
    offsets: np.ndarray,
    skip_below: float,
    signed: bool,
    start: int,
    stop: int,
) -> int:
    """Scans ``start`` to ``stop - 1`` one after another into a one-particle map, each by
    :func:`insert_serial`: scan ``k``'s hits are ``hits[:, offsets[k]:offsets[k + 1]]``
    (``hits`` as for :func:`insert_particles`, every scan's side by side, or only its first two rows:
    the unsigned field ignores the normals, which then are the hits again) at ``poses[k]``.

    One call for a whole stretch of scans instead of one per scan (the back end builds its
    submaps from thousands): each scan gets its own contiguous copies, so :func:`insert_serial`
    runs on the very arrays a one-scan insertion gives it, and the map is the same bit for bit.
    Returns -1 when done, or the scan that ran out of free tiles (grow the pool and call again
    from there: that scan had not written anything yet).
    """
    for k in range(start, stop):
        a = offsets[k]
        n = offsets[k + 1] - a
        if n == 0:
            continue
        pose = np.empty((1, 3))
        for c in range(3):
            pose[0, c] = poses[k, c]
        own = np.empty((4, n))
        for r in range(4):
            row = r if r < hits.shape[0] else r - 2  # (2, N) hits: the hits again as normals
            for j in range(n):
                own[r, j] = hits[row, a + j]
        keep = np.empty((1, n), dtype=np.bool_)
        if insert_serial(pool, pose, own, skip_below, signed, keep, np.int64(0)) >= 0:
            return k
    return -1


@njit(cache=True)
def recount_tiles(tables: np.ndarray, refcount: np.ndarray, free_stack: np.ndarray) -> int:
    """Recompute tile reference counts from the tables and rebuild the free stack.

    Returns the number of free tiles (the new stack top).
    """
    refcount[:] = 0
    flat = tables.ravel()
    for i in range(flat.shape[0]):
        t = flat[i]
        if t >= 0:
            refcount[t] += 1
    return _rebuild_free_stack(refcount, free_stack)


@njit(cache=True, _nrt=False)
def _rebuild_free_stack(refcount: np.ndarray, free_stack: np.ndarray) -> int:
    """Stack every tile no table references (highest index at the bottom); returns how many."""
    top = 0
    for t in range(refcount.shape[0] - 1, -1, -1):
        if refcount[t] == 0:
            free_stack[top] = t
            top += 1
    return top


@njit(cache=True, parallel=True)
def resample_tables(
    tables: np.ndarray,
    spans: np.ndarray,
    parents: np.ndarray,
    children: np.ndarray,
    out: np.ndarray,
    refcount: np.ndarray,
    free_stack: np.ndarray,
) -> int:
    """The tile tables after a resampling: ``out[p] = tables[parents[p]]``, copied in parallel
    (``children[q]``: how many times ``q`` is in ``parents``);
    the reference counts and the free stack as :func:`recount_tiles` of ``out`` gives them,
    counted from each surviving parent's table once, times its ``children[q]`` (the same
    integers, so the same stack). Returns the number of free tiles (the new stack top).

    Only the entries within each row's ``spans`` (:class:`TilePool`) are copied and counted:
    ``out`` must hold -1 outside them already (a fresh array filled so, or tables an earlier
    resampling left, whose tiles all lay within spans that have only grown since). A big
    building's tables are mostly unknown (fr-clinic: 30 × 439 × 713 entries, 8 % of them tiles,
    the spans about a third): the copy and the count are the resampling's whole cost. The column
    indices are unsigned (see :func:`_interpolate`): the copy compiles to a vector loop.
    """
    n, rows, cols = tables.shape
    for p in prange(out.shape[0]):
        src = parents[p]
        for r in range(rows):
            for c in range(np.uint64(spans[r, 0]), np.uint64(spans[r, 1] + 1)):
                out[p, r, c] = tables[src, r, c]
    for t in range(refcount.shape[0]):
        refcount[t] = 0
    for q in range(n):
        m = children[q]
        if m == 0:
            continue
        for r in range(rows):
            for c in range(np.uint64(spans[r, 0]), np.uint64(spans[r, 1] + 1)):
                t = tables[q, r, c]
                if t >= 0:
                    refcount[t] += m
    return _rebuild_free_stack(refcount, free_stack)


@njit(cache=True, parallel=True)
def match_scans(
    view: FieldView,
    poses: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    counts: np.ndarray,
    settings: MatchSettings,
    out_poses: np.ndarray,
) -> None:
    """Register many scans against one map: scan ``k`` has ``counts[k]`` endpoints in row ``k``.

    Each pose is refined with :func:`match_one`; it is kept unchanged when fewer than
    ``settings.min_inliers`` of its beams then fall on known cells.
    """
    for k in prange(poses.shape[0]):
        n = counts[k]
        kept = poses[k]
        if n > 0:
            refined, _, inliers = match_one(
                view, poses[k], ex[k, :n], ey[k, :n], settings.luts, settings.step_inv,
                settings.max_iter, settings.tolerance, settings.coarse_stride,
            )  # fmt: skip
            if inliers >= settings.min_inliers * n:
                kept = refined
        for a in range(3):
            out_poses[k, a] = kept[a]
