"""Scan kernels: map correlation with a local pose search (the course's classic sensor model)."""

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
