"""Scan kernels: map correlation with a local pose search (the course's classic sensor model), and
the returns of many scans thinned at once (the registration's beams)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from slam.kernels.cells import cell_index


@njit(cache=True, _nrt=False)
def correlation(
    occupied: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
) -> int:
    """Number of endpoints ``(ex, ey)`` (robot frame) that fall on occupied cells at ``pose``."""
    h, w = occupied.shape
    c = np.cos(pose[2])
    s = np.sin(pose[2])
    count = 0
    for b in range(ex.shape[0]):
        ix = cell_index(pose[0] + c * ex[b] - s * ey[b], ox, res)
        iy = cell_index(pose[1] + s * ex[b] + c * ey[b], oy, res)
        if 0 <= ix < w and 0 <= iy < h and occupied[iy, ix]:
            count += 1
    return count


@njit(cache=True, parallel=True)
def correlation_search(
    occupied: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    poses: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    xy_radius: int,
    yaw_offsets: np.ndarray,
    out_corr: np.ndarray,
    out_offsets: np.ndarray,
) -> None:
    """Best map correlation of every particle over a local grid of pose offsets.

    For each particle and each yaw offset, the endpoints are projected once; the correlation for
    every ``(dx, dy)`` shift of ``-xy_radius..xy_radius`` cells is accumulated by shifting cell
    indices (the course's ``mapCorrelation`` grid). ``out_corr[p]`` is the maximum count and
    ``out_offsets[p]`` the ``(dx, dy, dθ)`` in metres/radians that achieves it (ties: the smallest
    shift, scanned from the centre outwards by magnitude).
    """
    h, w = occupied.shape
    side = 2 * xy_radius + 1
    for p in prange(poses.shape[0]):
        counts = np.zeros((side, side), dtype=np.int64)
        best = -1
        best_cost = 1e18
        bx = 0.0
        by = 0.0
        bt = 0.0
        for k in range(yaw_offsets.shape[0]):
            th = poses[p, 2] + yaw_offsets[k]
            c = np.cos(th)
            s = np.sin(th)
            counts[:, :] = 0
            for b in range(ex.shape[0]):
                ix = cell_index(poses[p, 0] + c * ex[b] - s * ey[b], ox, res)
                iy = cell_index(poses[p, 1] + s * ex[b] + c * ey[b], oy, res)
                for j in range(side):
                    yy = iy + j - xy_radius
                    if yy < 0 or yy >= h:
                        continue
                    for i in range(side):
                        xx = ix + i - xy_radius
                        if 0 <= xx < w and occupied[yy, xx]:
                            counts[j, i] += 1
            for j in range(side):
                for i in range(side):
                    cost = (i - xy_radius) ** 2 + (j - xy_radius) ** 2 + abs(yaw_offsets[k])
                    v = counts[j, i]
                    if v > best or (v == best and cost < best_cost):
                        best = v
                        best_cost = cost
                        bx = (i - xy_radius) * res
                        by = (j - xy_radius) * res
                        bt = yaw_offsets[k]
        out_corr[p] = best
        out_offsets[p, 0] = bx
        out_offsets[p, 1] = by
        out_offsets[p, 2] = bt


@njit(cache=True, nogil=True)
def thin_returns(
    all_x: np.ndarray,
    all_y: np.ndarray,
    width: int,
    ex: np.ndarray,
    ey: np.ndarray,
    counts: np.ndarray,
) -> None:
    """Each row's returns (the entries of ``all_x``, ``all_y`` ``(S, W)`` that are not NaN), in
    beam order, at most ``width`` of them, into ``ex``, ``ey`` ``(S, width)`` float64 (zero
    beyond the row's ``counts``). A row with more returns keeps those at
    ``np.linspace(0, n − 1, width).round()`` (``j · (n − 1) / (width − 1)`` rounded half to
    even, the last exactly ``n − 1``; one return, the first, when ``width`` is 1): the returns
    :meth:`slam.scans.Scan.hits` keeps, in one pass instead of a dozen array operations."""
    found = np.empty(all_x.shape[1], dtype=np.int64)
    for s in range(all_x.shape[0]):
        n = 0
        for j in range(all_x.shape[1]):
            if not np.isnan(all_x[s, j]):
                found[n] = j
                n += 1
        kept = min(n, width)
        for j in range(kept):
            if n <= width:
                k = found[j]
            elif j == width - 1 and width > 1:
                k = found[n - 1]
            elif width > 1:
                k = found[np.int64(np.rint(j * ((n - 1) / (width - 1))))]
            else:
                k = found[0]
            ex[s, j] = all_x[s, k]
            ey[s, j] = all_y[s, k]
        for j in range(kept, width):
            ex[s, j] = 0.0
            ey[s, j] = 0.0
        counts[s] = kept
