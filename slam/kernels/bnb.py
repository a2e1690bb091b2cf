"""Branch-and-bound scan matching over a multi-resolution grid (Cartographer's global search).

A submap is a dense grid of match likelihoods in ``[0, 1]`` (:func:`splat_likelihood`). Its
*precomputation pyramid* (:func:`max_pyramid`) holds at level ``h`` the maximum of the level-0
grid over the ``2^h × 2^h`` cells whose lower-left corner is the cell itself, so the score of a
scan shifted to the lower-left cell of a ``2^h``-wide block of offsets, looked up at level ``h``,
bounds from above the score of every offset in that block. :func:`bnb_search` scores every block
of the coarsest level for every rotation, then descends depth first into the best blocks,
pruning a block as soon as its bound is not above the best complete match found so far (or the
minimum score): exact over the whole window at a small fraction of the brute-force cost.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def splat_likelihood(
    hx: np.ndarray, hy: np.ndarray, ox: float, oy: float, res: float, sigma: float,
    grid: np.ndarray,
) -> None:  # fmt: skip
    """Raise ``grid`` (rows = y) to ``exp(-d²/2σ²)`` around each hit ``(hx, hy)`` (max, in place).

    ``(ox, oy)`` is the world position of the lower-left corner of cell ``(0, 0)``; the kernel
    reaches ``3σ``. Hits outside the grid are skipped.
    """
    h, w = grid.shape
    r = int(np.ceil(3.0 * sigma / res))
    inv = 1.0 / (2.0 * sigma * sigma)
    for k in range(hx.size):
        fx = (hx[k] - ox) / res
        fy = (hy[k] - oy) / res
        cx = int(np.floor(fx))
        cy = int(np.floor(fy))
        if cx < 0 or cy < 0 or cx >= w or cy >= h:
            continue
        for dy in range(-r, r + 1):
            iy = cy + dy
            if iy < 0 or iy >= h:
                continue
            ddy = (iy + 0.5 - fy) * res
            for dx in range(-r, r + 1):
                ix = cx + dx
                if ix < 0 or ix >= w:
                    continue
                ddx = (ix + 0.5 - fx) * res
                v = np.float32(np.exp(-(ddx * ddx + ddy * ddy) * inv))
                if v > grid[iy, ix]:
                    grid[iy, ix] = v


@njit(cache=True, nogil=True)
def max_pyramid(grid: np.ndarray, levels: int) -> np.ndarray:
    """``(levels, H, W)``: level ``h`` is the max of ``grid`` over ``[x, x+2^h) × [y, y+2^h)``.

    Built level by level (the block max of level ``h`` is the max of four level ``h-1`` values
    ``2^(h-1)`` apart); cells beyond the grid count as 0.
    """
    h, w = grid.shape
    out = np.zeros((levels, h, w), dtype=np.float32)
    for iy in range(h):  # a loop, not `out[0] = grid`: that compiles numba's shape-error message
        for ix in range(w):
            out[0, iy, ix] = grid[iy, ix]
    for lev in range(1, levels):
        s = 1 << (lev - 1)
        prev = out[lev - 1]
        cur = out[lev]
        for iy in range(h):
            for ix in range(w):
                m = prev[iy, ix]
                if ix + s < w and prev[iy, ix + s] > m:
                    m = prev[iy, ix + s]
                if iy + s < h:
                    if prev[iy + s, ix] > m:
                        m = prev[iy + s, ix]
                    if ix + s < w and prev[iy + s, ix + s] > m:
                        m = prev[iy + s, ix + s]
                cur[iy, ix] = m
    return out


@njit(cache=True, inline="always")
def _score(pyramid: np.ndarray, lev: int, bxs: np.ndarray, bys: np.ndarray, a: int, dx: int,
           dy: int) -> float:  # fmt: skip
    """Mean of level ``lev`` at the points of rotation ``a`` shifted by ``(dx, dy)`` cells (the
    arrays indexed whole: no views made per call)."""
    h, w = pyramid.shape[1], pyramid.shape[2]
    n = bxs.shape[1]
    total = 0.0
    for k in range(n):
        ix = bxs[a, k] + dx
        iy = bys[a, k] + dy
        if ix >= 0 and iy >= 0 and ix < w and iy < h:
            total += pyramid[lev, iy, ix]
    return total / n


@njit(cache=True, nogil=True)
def bnb_search(
    pyramid: np.ndarray, ox: float, oy: float, res: float, px: np.ndarray, py: np.ndarray,
    cx: float, cy: float, cth: float, window_xy: float, window_th: float, th_step: float,
    min_score: float,
) -> np.ndarray:  # fmt: skip
    """Best pose of the scan ``(px, py)`` (robot frame) in the window around ``(cx, cy, cth)``.

    Offsets are whole cells within ``±window_xy`` and rotations ``th_step`` apart within
    ``±window_th``. Returns ``[x, y, theta, score]`` (score: mean level-0 likelihood of the
    points); the score is ``-1`` when no pose reaches ``min_score``.

    Long because numba has no recursion over typed stacks worth the name here: the rotated scans,
    the coarsest level's scored blocks and the depth-first descent with its explicit stack
    (arrays of rotation, offset, level and bound) are one loop nest sharing those arrays.
    """
    levels = pyramid.shape[0]
    top = levels - 1
    wc = int(np.ceil(window_xy / res))
    nth = int(np.ceil(window_th / th_step))
    n = px.size
    angles = np.empty(2 * nth + 1)
    for a in range(2 * nth + 1):
        angles[a] = cth + (a - nth) * th_step
    bxs = np.empty((2 * nth + 1, n), dtype=np.int64)
    bys = np.empty((2 * nth + 1, n), dtype=np.int64)
    for a in range(2 * nth + 1):
        c, s = np.cos(angles[a]), np.sin(angles[a])
        for k in range(n):
            wx = cx + c * px[k] - s * py[k]
            wy = cy + s * px[k] + c * py[k]
            bxs[a, k] = int(np.floor((wx - ox) / res))
            bys[a, k] = int(np.floor((wy - oy) / res))
    step = 1 << top
    per_axis = (2 * wc) // step + 1
    count = (2 * nth + 1) * per_axis * per_axis
    cap = count + 8 * levels + 8
    st_a = np.empty(cap, dtype=np.int64)
    st_x = np.empty(cap, dtype=np.int64)
    st_y = np.empty(cap, dtype=np.int64)
    st_h = np.empty(cap, dtype=np.int64)
    st_s = np.empty(cap)
    scores = np.empty(count)
    ca = np.empty(count, dtype=np.int64)
    cxs = np.empty(count, dtype=np.int64)
    cys = np.empty(count, dtype=np.int64)
    m = 0
    for a in range(2 * nth + 1):
        for i in range(per_axis):
            for j in range(per_axis):
                dx = -wc + i * step
                dy = -wc + j * step
                ca[m], cxs[m], cys[m] = a, dx, dy
                scores[m] = _score(pyramid, top, bxs, bys, a, dx, dy)
                m += 1
    order = np.argsort(scores)  # ascending: the best is pushed last, popped first
    sp = 0
    for q in range(count):
        k = order[q]
        if scores[k] > min_score:
            st_a[sp], st_x[sp], st_y[sp], st_h[sp], st_s[sp] = ca[k], cxs[k], cys[k], top, scores[k]
            sp += 1
    best = min_score
    best_a, best_x, best_y = -1, 0, 0
    ch_s = np.empty(4)
    ch_x = np.empty(4, dtype=np.int64)
    ch_y = np.empty(4, dtype=np.int64)
    ch_i = np.empty(4, dtype=np.int64)
    while sp > 0:
        sp -= 1
        a, x0, y0, h, sc = st_a[sp], st_x[sp], st_y[sp], st_h[sp], st_s[sp]
        if sc <= best:
            continue
        if h == 0:
            best, best_a, best_x, best_y = sc, a, x0, y0
            continue
        half = 1 << (h - 1)
        nc = 0
        for ddx in range(2):
            for ddy in range(2):
                x1 = x0 + ddx * half
                y1 = y0 + ddy * half
                if x1 > wc or y1 > wc:
                    continue
                ch_x[nc], ch_y[nc] = x1, y1
                ch_s[nc] = _score(pyramid, h - 1, bxs, bys, a, x1, y1)
                nc += 1
        for q in range(nc):  # ascending by score: an insertion sort of ≤ 4, no allocation
            k = q
            while k > 0 and ch_s[ch_i[k - 1]] > ch_s[q]:
                ch_i[k] = ch_i[k - 1]
                k -= 1
            ch_i[k] = q
        for q in range(nc):
            k = ch_i[q]
            if ch_s[k] > best:
                st_a[sp], st_x[sp], st_y[sp], st_h[sp], st_s[sp] = (
                    a,
                    ch_x[k],
                    ch_y[k],
                    h - 1,
                    ch_s[k],
                )
                sp += 1
    out = np.empty(4)
    if best_a < 0:
        out[0], out[1], out[2], out[3] = cx, cy, cth, -1.0
        return out
    out[0] = cx + best_x * res
    out[1] = cy + best_y * res
    out[2] = angles[best_a]
    out[3] = best
    return out
