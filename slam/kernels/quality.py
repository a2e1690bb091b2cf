"""Kernels of the map-quality score (:mod:`slam.eval.quality`): ray counts and beam verdicts.

The score compares each stretch of a run with the map the *other* stretches build. That map is
kept as integer counts per cell, hits (rays that ended in the cell on an obstacle) and misses
(rays that passed through it, or ended there without an echo), so the contribution of any set
of scans can be added and removed again exactly (log-odds, being clamped, cannot be un-added).
Cells follow the project's convention: cell ``(ix, iy)`` has its lower-left corner at
``(ox + ix·res, oy + iy·res)``.

**Layout.** Square tiles of ``T`` × ``T`` cells (``T`` = :data:`TILE`) with both counts side by
side, on a large grid allocated only where some ray passes: ``table[iy // T, ix // T]`` is the
tile's index in ``pool`` (−1: no ray came there, every count 0), and
``pool[t, iy % T, ix % T, layer]`` holds the hits (layer 0) and misses (layer 1). A ray walks
through neighbouring cells; in a plain row-major grid every step in y lands on another memory
page, in tiles the cells it visits share a few pages; and a building's corridors fill a small
part of its bounding box, so the pool is a fraction of a full grid. :func:`counts_over`
allocates every tile of a small grid and, on a large one, the tiles :func:`touched_tiles` finds;
:func:`to_rows` returns plain ``(H, W)`` grids, :func:`map_shades` a one-byte picture.

**Threads.** :func:`touched_tiles`, :func:`count_rays` and :func:`classify_beams` run serial
``nogil`` kernels on a few threads (:func:`~slam.kernels.threads.in_threads`): as
``parallel=True`` kernels the first two took 5.9 s to compile on a fresh cache, serially 1.7 s,
for the same speed. The helpers called per beam take arrays and are compiled without numba's
reference counting (``_nrt=False``: they allocate nothing): with it, every call increments and
decrements the count of each array it is passed, atomically, and that made the serial
:func:`classify_beams` 7 times slower (3.9 s against 0.55 s on the demo's 4,960 scans; a
``parallel=True`` kernel escapes it, as numba passes its loop body arrays without counts).

Rays are given in the robot frame, one row per scan: ``ex[k, j], ey[k, j]`` is where ray ``j``
of scan ``k`` ends, ``kind[k, j]`` is :data:`NO_RAY`, :data:`HIT` (an obstacle return) or
:data:`FREE` (a reading past the obstacle range: clears space only), and ``(lx, ly)`` is the
laser's position in the robot frame. The robot poses are ``poses[k] = (x, y, θ)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial
from itertools import pairwise
from typing import NamedTuple

import numpy as np
from numba import njit

from slam.kernels.cells import cell_index
from slam.kernels.grid import line_start, line_step
from slam.kernels.threads import in_threads, threads


class CountMap(NamedTuple):
    """The tiled counts and where they lie, as the kernels read and write them."""

    table: np.ndarray
    """``(TY, TX)`` int32 tile of each tile position in ``pool`` (-1: no ray came there)."""
    pool: np.ndarray
    """``(tiles, T, T, 2)`` int32 hits (layer 0) and misses (layer 1) per cell."""
    ox: float
    """World x of the lower-left corner of cell (0, 0) (m)."""
    oy: float
    """World y of the lower-left corner of cell (0, 0) (m)."""
    res: float
    """Cell size (m)."""


class ScanRays(NamedTuple):
    """Every scan's rays in the robot frame, with the robot poses (the module docstring)."""

    poses: np.ndarray
    """``(K, 3)`` robot poses."""
    lx: float
    """Laser x in the robot frame (m)."""
    ly: float
    """Laser y in the robot frame (m)."""
    ex: np.ndarray
    """``(K, J)`` ray end x in the robot frame (m)."""
    ey: np.ndarray
    """``(K, J)`` ray end y in the robot frame (m)."""
    kind: np.ndarray
    """``(K, J)`` int8 :data:`NO_RAY`, :data:`HIT` or :data:`FREE`."""


class Judging(NamedTuple):
    """The thresholds of :func:`classify_beams` (its docstring says how each is used)."""

    tolerance: float
    l_hit: float
    l_miss: float
    occupied_above: float
    min_free_rays: int
    min_incidence_sin: float
    max_offset: float
    neighbour_gap: float
    neighbour_relative_gap: float


TILE = 16
"""Side of a tile of the count layout (cells)."""
SHIFT = 4
"""``log2(TILE)``."""

NO_RAY = 0
"""``kind`` of a beam that casts no ray (invalid reading, or "no return")."""
HIT = 1
"""``kind`` of an obstacle return: the end cell is a hit, the cells before it misses."""
FREE = 2
"""``kind`` of a reading beyond the obstacle range: every cell of the ray is a miss."""

ISOLATED = -2
"""Verdict of a return with no neighbouring return close to it (a leg, a cable, a mixed pixel:
nothing that traces a surface), not judged."""
UNCHECKED = -1
"""Verdict of a beam that is not an obstacle return (not judged)."""
UNKNOWN = 0
"""Verdict: the other stretches saw neither a surface near the endpoint nor free space there."""
AGREE = 1
"""Verdict: a surface of the other stretches lies within the tolerance of the endpoint."""
CONFLICT_FREE = 2
"""Verdict: the endpoint lies in space the other stretches saw as free, no surface near it."""
CONFLICT_THROUGH = 3
"""Verdict: no surface near the endpoint, and the beam passed through a surface of the others."""


def empty_counts(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """``(table, pool)`` of zero counts with every tile of a ``height × width`` grid allocated."""
    ty = -(-height // TILE)
    tx = -(-width // TILE)
    table = np.arange(ty * tx, dtype=np.int32).reshape(ty, tx)
    return table, np.zeros((ty * tx, TILE, TILE, 2), dtype=np.int32)


DENSE_BYTES = 32 << 20
"""A grid whose counts take at most this many bytes is allocated whole (:func:`counts_over`):
finding the tiles some ray touches (:func:`touched_tiles`) walks every ray once more, which on a
small grid costs more time than the memory it saves is worth."""


def counts_over(
    tiles_y: int, tiles_x: int, ox: float, oy: float, res: float, rays: ScanRays
) -> tuple[np.ndarray, np.ndarray]:
    """``(table, pool)`` of zero counts for ``rays`` over a grid of ``tiles_y × tiles_x`` tiles:
    every tile when that takes at most :data:`DENSE_BYTES`, else only the tiles some ray passes
    through or ends in (:func:`touched_tiles`). Every count the rays add lands in an allocated
    tile either way, and a tile no ray touched counts nothing, as a missing one does: the same
    verdicts and pictures."""
    if tiles_y * tiles_x * TILE * TILE * 2 * 4 <= DENSE_BYTES:
        return counts_for(np.ones((tiles_y, tiles_x), dtype=np.bool_))
    return counts_for(touched_tiles(tiles_y, tiles_x, ox, oy, res, rays))


def counts_for(touched: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(table, pool)`` of zero counts with the ``touched`` tiles ``(TY, TX)`` allocated."""
    table = np.full(touched.shape, -1, dtype=np.int32)
    table[touched] = np.arange(int(touched.sum()), dtype=np.int32)
    return table, np.zeros((int(touched.sum()), TILE, TILE, 2), dtype=np.int32)


def to_rows(table: np.ndarray, pool: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plain ``(H, W)`` hit and miss grids (rows up in y) of tiled counts."""
    ty, tx = table.shape
    padded = np.concatenate([pool, np.zeros((1, TILE, TILE, 2), np.int32)])
    tiles = padded[np.where(table < 0, pool.shape[0], table)]  # (TY, TX, T, T, 2)
    plain = tiles.transpose(0, 2, 1, 3, 4).reshape(ty * TILE, tx * TILE, 2)
    return np.ascontiguousarray(plain[..., 0]), np.ascontiguousarray(plain[..., 1])


@njit(cache=True, inline="always")
def _hits(table, pool, x, y):
    t = table[y >> SHIFT, x >> SHIFT]
    return 0 if t < 0 else pool[t, y & (TILE - 1), x & (TILE - 1), 0]


@njit(cache=True, inline="always")
def _misses(table, pool, x, y):
    t = table[y >> SHIFT, x >> SHIFT]
    return 0 if t < 0 else pool[t, y & (TILE - 1), x & (TILE - 1), 1]


@njit(cache=True, inline="always")
def _add(table, pool, x, y, layer, value):
    pool[table[y >> SHIFT, x >> SHIFT], y & (TILE - 1), x & (TILE - 1), layer] += value


@njit(cache=True, _nrt=False)
def _world(poses, k, c, s, x, y):
    """The point ``(x, y)`` of scan ``k``'s robot frame in the world frame (``c``, ``s``: cosine
    and sine of its heading)."""
    return poses[k, 0] + c * x - s * y, poses[k, 1] + s * x + c * y


@njit(cache=True, _nrt=False)
def _laser(poses, k, lx, ly):
    """``(c, s, sx, sy)``: cosine and sine of scan ``k``'s heading and the world position of the
    laser (``(lx, ly)`` in the robot frame)."""
    c = math.cos(poses[k, 2])
    s = math.sin(poses[k, 2])
    sx, sy = _world(poses, k, c, s, lx, ly)
    return c, s, sx, sy


BLOCK_SCANS = 128
"""Scans per block of :func:`count_rays` (a block's rays are counted in a dense patch of cells
covering them, by one thread; see :func:`count_rays`)."""


@njit(cache=True, _nrt=False)
def _block_box(rays, k0, k1, ox, oy, res, w, h):
    """``(x0, y0, x1, y1)``: the cells (half-open, clipped to the ``w × h`` grid) holding every
    laser position and ray end of scans ``k0 .. k1 − 1``, hence every cell their rays cross."""
    poses, lx, ly, ex, ey, kind = rays
    bx0, by0, bx1, by1 = w, h, 0, 0
    for k in range(k0, k1):
        c, s, sx, sy = _laser(poses, k, lx, ly)
        for j in range(-1, kind.shape[1]):
            if j >= 0 and kind[k, j] == NO_RAY:
                continue
            if j < 0:
                x = cell_index(sx, ox, res)
                y = cell_index(sy, oy, res)
            else:
                wx, wy = _world(poses, k, c, s, ex[k, j], ey[k, j])
                x = cell_index(wx, ox, res)
                y = cell_index(wy, oy, res)
            bx0 = min(bx0, max(x, 0))
            by0 = min(by0, max(y, 0))
            bx1 = max(bx1, min(x + 1, w))
            by1 = max(by1, min(y + 1, h))
    return bx0, by0, max(bx1, bx0), max(by1, by0)


@njit(cache=True, _nrt=False)
def _walk_scan(rays, k, ox, oy, res, w, h, patch, px0, py0, mask):
    """Walk the rays of scan ``k`` cell by cell (Bresenham) over the ``w × h`` grid: every cell a
    ray passes through gets a miss (end cell excluded), the end cell a hit for a :data:`HIT` ray
    and a miss for a :data:`FREE` ray, as the occupancy map does; cells outside the grid are
    skipped. With an empty ``mask`` the counts go to ``patch[layer, y − py0, x − px0]``
    (layer 0 hits, 1 misses), else the tile of every cell is marked in ``mask``."""
    poses, lx, ly, ex, ey, kind = rays
    marking = mask.size > 0
    c, s, sx, sy = _laser(poses, k, lx, ly)
    x0 = cell_index(sx, ox, res)
    y0 = cell_index(sy, oy, res)
    for j in range(kind.shape[1]):
        what = kind[k, j]
        if what == NO_RAY:
            continue
        wx, wy = _world(poses, k, c, s, ex[k, j], ey[k, j])
        x1 = cell_index(wx, ox, res)
        y1 = cell_index(wy, oy, res)
        dx, dy, stepx, stepy, err = line_start(x0, y0, x1, y1)
        x, y = x0, y0
        for _ in range(max(dx, dy)):
            if 0 <= x < w and 0 <= y < h:
                if marking:
                    mask[y >> SHIFT, x >> SHIFT] = True
                else:
                    patch[1, y - py0, x - px0] += 1
            x, y, err = line_step(x, y, err, dx, dy, stepx, stepy)
        if 0 <= x1 < w and 0 <= y1 < h:
            if marking:
                mask[y1 >> SHIFT, x1 >> SHIFT] = True
            else:
                patch[0 if what == HIT else 1, y1 - py0, x1 - px0] += 1


def touched_tiles(
    tiles_y: int, tiles_x: int, ox: float, oy: float, res: float, rays: ScanRays
) -> np.ndarray:
    """``(TY, TX)`` mask of the tiles holding a cell some ray passes through or ends in (the
    cells :func:`count_rays` updates: the same walk, :func:`_walk_scan`). Parallel over chunks
    of scans, each marking its own mask; the masks are or-ed (the result does not depend on the
    number of threads)."""
    n = rays.poses.shape[0]
    chunks = max(1, min(threads(), n))
    masks = np.zeros((chunks, tiles_y, tiles_x), dtype=np.bool_)
    in_threads(
        [
            partial(
                _touch,
                tiles_y,
                tiles_x,
                ox,
                oy,
                res,
                rays,
                n * c // chunks,
                n * (c + 1) // chunks,
                masks[c],
            )
            for c in range(chunks)
        ]
    )
    return np.logical_or.reduce(masks, axis=0)


@njit(cache=True, nogil=True)
def _touch(tiles_y, tiles_x, ox, oy, res, rays, k0, k1, mask):
    """Mark in ``mask`` the tiles the rays of scans ``k0 .. k1 − 1`` pass through or end in."""
    no_patch = np.zeros((2, 0, 0), dtype=np.int32)
    zero = np.int64(0)  # not a literal: one specialisation of _walk_scan
    for k in range(k0, k1):
        _walk_scan(rays, k, ox, oy, res, tiles_x * TILE, tiles_y * TILE, no_patch, zero, zero, mask)


KeptPatches = dict[int, tuple[int, int, int, np.ndarray]]
"""The patches :func:`count_rays` keeps: ``kept[a] = (b, x0, y0, patch)``, the counts of the
rays of scans ``a .. b − 1`` in a dense patch whose cell ``(0, 0)`` is grid cell ``(x0, y0)``."""


def count_rays(
    counts: CountMap,
    rays: ScanRays,
    k0: int,
    k1: int,
    sign: int,
    cuts: Sequence[int] = (),
    kept: KeptPatches | None = None,
) -> None:
    """Add ``sign`` (+1 or −1) to the counts of the rays of scans ``k0 .. k1 − 1``.

    Every cell a ray passes through gets a miss (Bresenham, end cell excluded); the end cell gets
    a hit for a :data:`HIT` ray and a miss for a :data:`FREE` ray, as the occupancy map does.
    Cells outside the grid are skipped (the caller sizes the grid to hold every ray; the cells
    inside must lie in allocated tiles, :func:`counts_over`).

    Parallel without races: the scans are cut into blocks of at most :data:`BLOCK_SCANS`, also
    at every scan number of ``cuts``; a round gives one block to each thread, which counts its
    rays in a dense patch of its own covering them (:func:`_block_box`: the robot's path over the
    block and the sensor's reach, not the map); the patches are then added to the tiles one
    after the other, in block order. Counts are integers, so the result is exact and the same
    whatever the number of threads. With ``kept`` each block's patch is kept there, so that
    :func:`add_kept` can add it again (or take it out again) without walking its rays: what the
    map-quality score does with the scans of a window it gives back.
    """
    table, pool, ox, oy, res = counts
    h = table.shape[0] * TILE
    w = table.shape[1] * TILE
    inner = sorted({int(c) for c in cuts if k0 < c < k1})
    starts = [a for lo, hi in pairwise([k0, *inner, k1]) for a in range(lo, hi, BLOCK_SCANS)]
    stops = [*starts[1:], k1]
    per_round = threads()
    for r0 in range(0, len(starts), per_round):
        blocks = [
            partial(_count_block, rays, a, b, ox, oy, res, w, h)
            for a, b in zip(starts[r0 : r0 + per_round], stops[r0 : r0 + per_round], strict=True)
        ]
        done = in_threads(blocks)
        # serially, in block order: a patch is small next to its walk
        for a, b, (x0, y0, patch) in zip(starts[r0:], stops[r0:], done, strict=False):
            _add_patch(table, pool, patch, x0, y0, sign)
            if kept is not None:
                kept[a] = (b, x0, y0, patch)


def add_kept(counts: CountMap, kept: KeptPatches, k0: int, k1: int, sign: int) -> None:
    """Add ``sign`` times the counts of scans ``k0 .. k1 − 1`` from the patches :func:`count_rays`
    kept (and forget them): the same counts as ``count_rays(counts, rays, k0, k1, sign)``
    without walking the rays again. ``k0`` and ``k1`` must be ends of kept blocks (``cuts``
    of :func:`count_rays`); else a :class:`KeyError` (the scan where no kept block starts) or
    a :class:`ValueError` (a block that runs past ``k1``), the blocks before it given back."""
    table, pool = counts.table, counts.pool
    k = k0
    while k < k1:
        b, x0, y0, patch = kept[k]
        if b > k1:
            raise ValueError(f"add_kept: the block of scans {k}..{b - 1} runs past scan {k1}")
        _add_patch(table, pool, patch, x0, y0, sign)
        del kept[k]
        k = b


@njit(cache=True, nogil=True)
def _count_block(rays, k0, k1, ox, oy, res, w, h):
    """``(x0, y0, patch)``: the counts of the rays of scans ``k0 .. k1 − 1`` in a dense patch
    (layer, y − y0, x − x0) covering them (:func:`_block_box`)."""
    x0, y0, x1, y1 = _block_box(rays, k0, k1, ox, oy, res, w, h)
    patch = np.zeros((2, y1 - y0, x1 - x0), dtype=np.int32)
    no_mask = np.zeros((0, 0), dtype=np.bool_)
    for k in range(k0, k1):
        _walk_scan(rays, k, ox, oy, res, w, h, patch, x0, y0, no_mask)
    return x0, y0, patch


@njit(cache=True, nogil=True)
def _add_patch(table, pool, patch, x0, y0, sign):
    """Add ``sign`` times the counts of ``patch`` (from :func:`_count_block`) to the tiles."""
    for yy in range(patch.shape[1]):
        for xx in range(patch.shape[2]):
            for layer in range(2):
                v = patch[layer, yy, xx]
                if v != 0:
                    _add(table, pool, x0 + xx, y0 + yy, layer, sign * v)


@njit(cache=True, _nrt=False)
def _occupied(table, pool, x, y, l_hit, l_miss, occupied_above):
    n_hit = _hits(table, pool, x, y)
    return n_hit > 0 and n_hit * l_hit + _misses(table, pool, x, y) * l_miss > occupied_above


@njit(cache=True, _nrt=False)
def _solid(table, pool, x, y):
    n_hit = _hits(table, pool, x, y)
    return n_hit > 0 and n_hit >= _misses(table, pool, x, y)


@njit(cache=True, _nrt=False)
def _free(table, pool, x, y, l_hit, l_miss, min_free_rays):
    n_miss = _misses(table, pool, x, y)
    return n_miss >= min_free_rays and _hits(table, pool, x, y) * l_hit + n_miss * l_miss < 0.0


@njit(cache=True, _nrt=False)
def _near_surface(table, pool, x, y, disc, w, h, l_hit, l_miss, occupied_above):
    for d in range(disc.shape[0]):
        cx = x + disc[d, 0]
        cy = y + disc[d, 1]
        if (
            0 <= cx < w
            and 0 <= cy < h
            and _occupied(table, pool, cx, cy, l_hit, l_miss, occupied_above)
        ):
            return True
    return False


@njit(cache=True, _nrt=False)
def _near_hit(table, pool, x, y, disc, w, h):
    for d in range(disc.shape[0]):
        cx = x + disc[d, 0]
        cy = y + disc[d, 1]
        if 0 <= cx < w and 0 <= cy < h and _hits(table, pool, cx, cy) > 0:
            return True
    return False


@njit(cache=True, _nrt=False)
def _incidence_sin(poses, ex, ey, kind, k, j, sx, sy, wx, wy, c, s, gap, relative_gap):
    """|sin| of the angle between beam ``j`` and the surface the scan's neighbouring returns
    trace (1: the beam meets it head on, 0: it grazes it); −1 when no neighbour is close."""
    nb = kind.shape[1]
    rng = math.hypot(wx - sx, wy - sy)
    limit = gap + relative_gap * rng
    tx = 0.0
    ty = 0.0
    found = False
    for nj in (j - 1, j + 1):
        if nj < 0 or nj >= nb or kind[k, nj] != HIT:
            continue
        nx, ny = _world(poses, k, c, s, ex[k, nj], ey[k, nj])
        ddx = nx - wx
        ddy = ny - wy
        if math.hypot(ddx, ddy) < limit:
            if nj < j:
                ddx, ddy = -ddx, -ddy
            tx += ddx
            ty += ddy
            found = True
    norm = math.hypot(tx, ty)
    if not found or norm < 1e-9 or rng < 1e-9:
        return -1.0
    ux = (wx - sx) / rng
    uy = (wy - sy) / rng
    return abs(ux * ty - uy * tx) / norm


@njit(cache=True, _nrt=False)
def _through(table, pool, x0, y0, x1, y1, r, stop, w, h):
    """Distance along the ray from cell ``(x0, y0)`` to cell ``(x1, y1)`` (``r`` metres long) of
    the first solid cell it crosses (Bresenham) before ``stop`` metres, or −1. Solid: at least
    as many rays ended in the cell as passed through it (a cell a door frame's corner only
    partly fills is crossed by more rays than end in it, and is not solid)."""
    dx, dy, stepx, stepy, err = line_start(x0, y0, x1, y1)
    n = max(dx, dy)
    x, y = x0, y0
    for i in range(n):
        along = r * i / n
        if along >= stop:
            break
        if 0 <= x < w and 0 <= y < h and _solid(table, pool, x, y):
            return along
        x, y, err = line_step(x, y, err, dx, dy, stepx, stepy)
    return -1.0


def classify_beams(
    counts: CountMap,
    rays: ScanRays,
    k0: int,
    k1: int,
    disc: np.ndarray,
    judging: Judging,
    verdict: np.ndarray,
    offset: np.ndarray,
) -> None:
    """Judge each obstacle return of scans ``k0 .. k1 − 1`` against the counts (the map of the
    *other* stretches); write ``verdict[k, j]`` and the signed ``offset[k, j]`` (m).

    A return with no neighbouring return close to it (within ``neighbour_gap +
    neighbour_relative_gap·r``) traces no surface and is :data:`ISOLATED` (not judged). For
    another return ending at cell ``e``, ``r`` metres from the laser along unit direction ``u``:

    * :data:`AGREE` when a cell within ``tolerance`` of ``e`` (the offsets ``disc``) is occupied
      in the others' map; offset 0;
    * else :data:`CONFLICT_THROUGH` when the ray crossed a solid cell at ``s < r − r_excl``
      along it, ``r_excl = tolerance / sin β`` (β: incidence on the surface the scan's own
      neighbouring returns trace; a beam that grazes it, ``sin β < min_incidence_sin``, is not
      tested this way); offset ``r − s > 0`` (behind the others' wall);
    * else :data:`CONFLICT_FREE` when ``e`` is a free cell of the others, no cell within
      ``tolerance`` of it holds a single hit of theirs, and the cell at ``e + tolerance·u`` was
      observed by them too (a wall face the others only skimmed is cleared by their grazing rays
      in a thin band, but some of their rays still ended there, and the inside of the wall
      behind it was never observed); offset ``−d``,
      ``d`` how far past ``e`` along the beam the first occupied cell lies (NaN beyond
      ``max_offset``);
    * else :data:`UNKNOWN` (the others did not observe that place); offset NaN.

    A cell is occupied when it has hits and ``hits·l_hit + misses·l_miss > occupied_above``,
    solid when it has hits and ``hits ≥ misses``, free when it has at least ``min_free_rays``
    misses and that sum is negative. Beams that are not
    returns get :data:`UNCHECKED`. The thresholds are the fields of ``judging``. Chunks of scans
    on a few threads (:func:`~slam.kernels.threads.in_threads`; each writes only its own rows,
    the counts are only read), so the verdicts do not depend on the number of threads.
    """
    n = k1 - k0
    chunks = max(1, min(threads(), n))
    in_threads(
        [
            partial(
                _classify,
                counts,
                rays,
                k0 + n * c // chunks,
                k0 + n * (c + 1) // chunks,
                disc,
                judging,
                verdict,
                offset,
            )
            for c in range(chunks)
        ]
    )


@njit(cache=True, nogil=True)
def _classify(counts, rays, k0, k1, disc, judging, verdict, offset):
    """:func:`classify_beams` for scans ``k0 .. k1 − 1``. Long because the four tests share the
    beam's geometry."""
    table, pool, ox, oy, res = counts
    poses, lx, ly, ex, ey, kind = rays
    tolerance, l_hit, l_miss, occupied_above, min_free_rays = judging[:5]
    min_incidence_sin, max_offset, neighbour_gap, neighbour_relative_gap = judging[5:]
    h = table.shape[0] * TILE
    w = table.shape[1] * TILE
    nb = kind.shape[1]
    for k in range(k0, k1):
        c, s, sx, sy = _laser(poses, k, lx, ly)
        x0 = cell_index(sx, ox, res)
        y0 = cell_index(sy, oy, res)
        for j in range(nb):
            offset[k, j] = np.nan
            if kind[k, j] != HIT:
                verdict[k, j] = UNCHECKED
                continue
            wx, wy = _world(poses, k, c, s, ex[k, j], ey[k, j])
            x1 = cell_index(wx, ox, res)
            y1 = cell_index(wy, oy, res)
            if not (0 <= x1 < w and 0 <= y1 < h):
                verdict[k, j] = UNKNOWN
                continue
            sin_b = _incidence_sin(
                poses, ex, ey, kind, k, j, sx, sy, wx, wy, c, s,
                neighbour_gap, neighbour_relative_gap,
            )  # fmt: skip
            if sin_b < 0.0:
                verdict[k, j] = ISOLATED
                continue
            if _near_surface(table, pool, x1, y1, disc, w, h, l_hit, l_miss, occupied_above):
                verdict[k, j] = AGREE
                offset[k, j] = 0.0
                continue
            r = math.hypot(wx - sx, wy - sy)
            ux = (wx - sx) / r if r > 1e-9 else 0.0
            uy = (wy - sy) / r if r > 1e-9 else 0.0
            if sin_b >= min_incidence_sin:
                through = _through(table, pool, x0, y0, x1, y1, r, r - tolerance / sin_b, w, h)
                if through >= 0.0:
                    verdict[k, j] = CONFLICT_THROUGH
                    offset[k, j] = r - through
                    continue
            bx = cell_index(wx + ux * tolerance, ox, res)
            by = cell_index(wy + uy * tolerance, oy, res)
            if not (
                _free(table, pool, x1, y1, l_hit, l_miss, min_free_rays)
                and not _near_hit(table, pool, x1, y1, disc, w, h)
                and 0 <= bx < w
                and 0 <= by < h
                and (
                    _hits(table, pool, bx, by) > 0 or _misses(table, pool, bx, by) >= min_free_rays
                )
            ):
                verdict[k, j] = UNKNOWN
                continue
            verdict[k, j] = CONFLICT_FREE
            # How far in front of the others' surface: march on along the beam in half cells.
            step = 0.5 * res
            for i in range(1, int(max_offset / step) + 1):
                qx = cell_index(wx + ux * step * i, ox, res)
                qy = cell_index(wy + uy * step * i, oy, res)
                if not (0 <= qx < w and 0 <= qy < h):
                    break
                if _occupied(table, pool, qx, qy, l_hit, l_miss, occupied_above):
                    offset[k, j] = -step * i
                    break


@njit(cache=True)
def map_shades(
    table: np.ndarray, pool: np.ndarray, l_hit: float, l_miss: float, unknown: int
) -> np.ndarray:
    """The counts as a picture: ``(H, W)`` uint8, rows up in y, ``255·(1 − p)`` with ``p`` the
    occupancy probability of the unclamped log-odds ``hits·l_hit + misses·l_miss`` (clipped to
    ±6), and ``unknown`` where no ray came. One byte per cell instead of the counts' eight."""
    ty, tx = table.shape
    out = np.empty((ty * TILE, tx * TILE), dtype=np.uint8)
    for y in range(ty * TILE):
        for x in range(tx * TILE):
            n_hit = _hits(table, pool, x, y)
            n_miss = _misses(table, pool, x, y)
            if n_hit == 0 and n_miss == 0:
                out[y, x] = unknown
                continue
            lo = min(max(n_hit * l_hit + n_miss * l_miss, -6.0), 6.0)
            out[y, x] = int(255.0 / (1.0 + math.exp(lo)) + 0.5)
    return out


@njit(cache=True)
def ray_bounds(poses: np.ndarray, lx: float, ly: float, ex: np.ndarray, ey: np.ndarray,
               kind: np.ndarray) -> np.ndarray:  # fmt: skip
    """``(xmin, ymin, xmax, ymax)`` of every ray end and laser position (world frame)."""
    out = np.array([np.inf, np.inf, -np.inf, -np.inf])
    for k in range(poses.shape[0]):
        c = math.cos(poses[k, 2])
        s = math.sin(poses[k, 2])
        for j in range(-1, kind.shape[1]):
            if j >= 0 and kind[k, j] == NO_RAY:
                continue
            px = lx if j < 0 else ex[k, j]
            py = ly if j < 0 else ey[k, j]
            wx, wy = _world(poses, k, c, s, px, py)
            out[0] = min(out[0], wx)
            out[1] = min(out[1], wy)
            out[2] = max(out[2], wx)
            out[3] = max(out[3], wy)
    return out
