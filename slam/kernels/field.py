"""Distance-field kernels for per-particle maps stored as shared, copy-on-write tiles.

Each particle's map is a truncated Euclidean distance field: cell ``c`` holds the distance from
its centre to the nearest laser hit ever inserted in that particle's map, capped at ``dmax``.
Hits keep their exact (sub-cell) positions, so the field locates walls more finely than the cell
size, and bilinear interpolation gives a smooth distance with a gradient that points away from
the nearest surface, which is what the Gauss-Newton scan matcher follows.

Storage (the layout GMapping uses for its particle maps, made flat for numba):

* ``pool[t]`` is a ``T × T`` tile of distances; ``refcount[t]`` counts the particles using it;
  free tiles are on the stack ``free_stack[:free_top[0]]``;
* ``tables[p, ty, tx]`` is the tile of particle ``p`` at tile coordinates ``(tx, ty)``, or -1
  for unknown space (distance ``dmax``);
* resampling copies only the small tables (children share their parent's tiles); a particle that
  writes to a shared tile copies it first (copy on write), so maps diverge only where particles
  learned something different.

Cell ``(ix, iy)`` has its lower-left corner at ``(ox + ix·res, oy + iy·res)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def cell_distance(
    pool: np.ndarray, table: np.ndarray, tile: int, ix: int, iy: int, dmax: float
) -> float:
    """Distance stored at cell ``(ix, iy)`` of one particle's map (``dmax`` where unknown)."""
    if ix < 0 or iy < 0:
        return dmax
    tx = ix // tile
    ty = iy // tile
    if ty >= table.shape[0] or tx >= table.shape[1]:
        return dmax
    t = table[ty, tx]
    if t < 0:
        return dmax
    return pool[t, iy - ty * tile, ix - tx * tile]


@njit(cache=True)
def distance_at(
    pool: np.ndarray,
    table: np.ndarray,
    tile: int,
    ox: float,
    oy: float,
    res: float,
    dmax: float,
    x: float,
    y: float,
) -> tuple[float, float, float]:
    """Bilinearly interpolated distance at world point ``(x, y)`` and its gradient."""
    gx = (x - ox) / res - 0.5
    gy = (y - oy) / res - 0.5
    fx0 = np.floor(gx)
    fy0 = np.floor(gy)
    ix = int(fx0)
    iy = int(fy0)
    fx = gx - fx0
    fy = gy - fy0
    tx = ix // tile if ix >= 0 else -1
    ty = iy // tile if iy >= 0 else -1
    lx = ix - tx * tile
    ly = iy - ty * tile
    if (
        tx >= 0
        and ty >= 0
        and lx < tile - 1
        and ly < tile - 1
        and ty < table.shape[0]
        and tx < table.shape[1]
    ):
        t = table[ty, tx]
        if t < 0:
            return dmax, 0.0, 0.0
        d00 = pool[t, ly, lx]
        d10 = pool[t, ly, lx + 1]
        d01 = pool[t, ly + 1, lx]
        d11 = pool[t, ly + 1, lx + 1]
    else:
        d00 = cell_distance(pool, table, tile, ix, iy, dmax)
        d10 = cell_distance(pool, table, tile, ix + 1, iy, dmax)
        d01 = cell_distance(pool, table, tile, ix, iy + 1, dmax)
        d11 = cell_distance(pool, table, tile, ix + 1, iy + 1, dmax)
    d = (1.0 - fy) * ((1.0 - fx) * d00 + fx * d10) + fy * ((1.0 - fx) * d01 + fx * d11)
    ddx = ((1.0 - fy) * (d10 - d00) + fy * (d11 - d01)) / res
    ddy = ((1.0 - fx) * (d01 - d00) + fx * (d11 - d10)) / res
    return d, ddx, ddy


@njit(cache=True)
def normal_equations(
    pool: np.ndarray,
    table: np.ndarray,
    tile: int,
    ox: float,
    oy: float,
    res: float,
    dmax: float,
    x: float,
    y: float,
    th: float,
    ex: np.ndarray,
    ey: np.ndarray,
    sigma: float,
    z_hit: float,
    z_rand: float,
    h: np.ndarray,
    g: np.ndarray,
) -> tuple[float, int]:
    """One pass over the beams at pose ``(x, y, th)``: cost, Gauss-Newton system, inliers.

    The cost is the negative log-likelihood ``Σ −log(z_hit·exp(−d²/2σ²) + z_rand)`` of the
    endpoints ``(ex, ey)`` (robot frame) in the distance field. ``h`` and ``g`` receive the
    Gauss-Newton approximation of its Hessian and its gradient, each beam weighted by its
    responsibility ``γ = z_hit·φ / (z_hit·φ + z_rand)``. Returns the cost and the number of beams
    closer than ``dmax`` to a known surface.
    """
    inv = 0.5 / (sigma * sigma)
    inv_var = 1.0 / (sigma * sigma)
    c = np.cos(th)
    s = np.sin(th)
    h[:, :] = 0.0
    g[:] = 0.0
    cost = 0.0
    inliers = 0
    for b in range(ex.shape[0]):
        rx = c * ex[b] - s * ey[b]
        ry = s * ex[b] + c * ey[b]
        d, gx, gy = distance_at(pool, table, tile, ox, oy, res, dmax, x + rx, y + ry)
        phi = z_hit * np.exp(-d * d * inv)
        cost -= np.log(phi + z_rand)
        if d >= dmax:
            continue
        inliers += 1
        wgt = phi / (phi + z_rand) * inv_var
        j2 = -gx * ry + gy * rx
        h[0, 0] += wgt * gx * gx
        h[0, 1] += wgt * gx * gy
        h[0, 2] += wgt * gx * j2
        h[1, 1] += wgt * gy * gy
        h[1, 2] += wgt * gy * j2
        h[2, 2] += wgt * j2 * j2
        g[0] += wgt * d * gx
        g[1] += wgt * d * gy
        g[2] += wgt * d * j2
    h[1, 0] = h[0, 1]
    h[2, 0] = h[0, 2]
    h[2, 1] = h[1, 2]
    return cost, inliers


@njit(cache=True)
def _solve3(h: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Solve the symmetric 3×3 system ``h x = g`` by Cramer's rule (zeros if singular)."""
    a, b, c = h[0, 0], h[0, 1], h[0, 2]
    d, e, f = h[1, 1], h[1, 2], h[2, 2]
    det = a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)
    out = np.zeros(3)
    if abs(det) < 1e-18:
        return out
    i00 = d * f - e * e
    i01 = c * e - b * f
    i02 = b * e - c * d
    i11 = a * f - c * c
    i12 = b * c - a * e
    i22 = a * d - b * b
    out[0] = (i00 * g[0] + i01 * g[1] + i02 * g[2]) / det
    out[1] = (i01 * g[0] + i11 * g[1] + i12 * g[2]) / det
    out[2] = (i02 * g[0] + i12 * g[1] + i22 * g[2]) / det
    return out


@njit(cache=True)
def match_one(
    pool: np.ndarray,
    table: np.ndarray,
    tile: int,
    ox: float,
    oy: float,
    res: float,
    dmax: float,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    sigmas: np.ndarray,
    z_hit: float,
    z_rand: float,
    max_iter: int,
) -> tuple[np.ndarray, float, int]:
    """Refine ``pose`` so the endpoints ``(ex, ey)`` (robot frame) fit the distance field.

    Levenberg-Marquardt on the negative log-likelihood (see :func:`normal_equations`), level by
    level through ``sigmas`` from wide to narrow so the first levels pull in from further away.
    Each iteration costs one pass over the beams: a step that does not lower the cost is undone
    and the damping raised. Returns the refined pose, its cost at the last sigma and its inliers.
    """
    x, y, th = pose[0], pose[1], pose[2]
    h = np.zeros((3, 3))
    g = np.zeros(3)
    hc = np.zeros((3, 3))
    gc = np.zeros(3)
    hd = np.zeros((3, 3))
    cost = 0.0
    inliers = 0
    for level in range(sigmas.shape[0]):
        sigma = sigmas[level]
        cost, inliers = normal_equations(
            pool, table, tile, ox, oy, res, dmax, x, y, th, ex, ey, sigma, z_hit, z_rand, h, g
        )
        lam = 1e-3
        for _ in range(max_iter):
            hd[:, :] = h
            for k in range(3):
                hd[k, k] += lam * h[k, k] + 1e-9
            step = _solve3(hd, g)
            nx = x - step[0]
            ny = y - step[1]
            nth = th - step[2]
            new_cost, new_inliers = normal_equations(
                pool, table, tile, ox, oy, res, dmax, nx, ny, nth, ex, ey, sigma, z_hit, z_rand,
                hc, gc,
            )  # fmt: skip
            if new_cost < cost:
                x, y, th, cost, inliers = nx, ny, nth, new_cost, new_inliers
                h[:, :] = hc
                g[:] = gc
                lam = max(lam * 0.3, 1e-7)
                if abs(step[0]) < 5e-4 and abs(step[1]) < 5e-4 and abs(step[2]) < 5e-4:
                    break
            else:
                lam *= 10.0
                if lam > 1e3:
                    break
    out = np.empty(3)
    out[0] = x
    out[1] = y
    out[2] = (th + np.pi) % (2.0 * np.pi) - np.pi
    return out, cost, inliers


@njit(cache=True, parallel=True)
def match_particles(
    pool: np.ndarray,
    tables: np.ndarray,
    tile: int,
    ox: float,
    oy: float,
    res: float,
    dmax: float,
    poses: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    sigmas: np.ndarray,
    z_hit: float,
    z_rand: float,
    max_iter: int,
    min_inliers: float,
    out_poses: np.ndarray,
    out_loglik: np.ndarray,
    out_inliers: np.ndarray,
) -> None:
    """Scan-match every particle against its own map (the proposal), then score it.

    For each particle: refine its predicted pose with :func:`match_one`; if fewer than
    ``min_inliers`` of the beams then lie within ``dmax`` of a known surface the match is not
    trusted and the predicted pose is kept. ``out_loglik`` is the log-likelihood of the scan at
    the final pose with the narrowest sigma; ``out_inliers`` the fraction of beams near a surface.
    """
    sigma = sigmas[sigmas.shape[0] - 1]
    nbeams = max(ex.shape[0], 1)
    for p in prange(poses.shape[0]):
        table = tables[p]
        refined, cost, inliers = match_one(
            pool, table, tile, ox, oy, res, dmax, poses[p], ex, ey, sigmas, z_hit, z_rand, max_iter
        )
        frac = inliers / nbeams
        if frac < min_inliers:
            refined = poses[p].copy()
            h = np.zeros((3, 3))
            g = np.zeros(3)
            cost, inliers = normal_equations(
                pool, table, tile, ox, oy, res, dmax, refined[0], refined[1], refined[2],
                ex, ey, sigma, z_hit, z_rand, h, g,
            )  # fmt: skip
        out_poses[p, 0] = refined[0]
        out_poses[p, 1] = refined[1]
        out_poses[p, 2] = refined[2]
        out_inliers[p] = frac
        out_loglik[p] = -cost


@njit(cache=True)
def insert_hits(
    pool: np.ndarray,
    refcount: np.ndarray,
    free_stack: np.ndarray,
    free_top: np.ndarray,
    tables: np.ndarray,
    tile: int,
    ox: float,
    oy: float,
    res: float,
    dmax: float,
    poses: np.ndarray,
    hx: np.ndarray,
    hy: np.ndarray,
    skip_below: float,
    start: int,
) -> int:
    """Insert hit points ``(hx, hy)`` (robot frame) into every particle's map from ``start`` on.

    A hit adds nothing new, and is skipped, when the cell it falls in already stores a distance
    within ``skip_below`` of the hit's own distance to that cell's centre: a surface point about
    as close is known (this keeps re-observed walls from copying tiles). Otherwise every cell within
    ``dmax`` of the hit takes ``min(current, distance to the hit)``; a shared tile is copied
    before its first write, a missing one is allocated. Returns -1 when done, or the index of the
    particle that ran out of free tiles (the caller grows the pool and calls again from there;
    re-inserting is harmless because the update is a minimum).
    """
    radius = int(np.ceil(dmax / res))
    ntile_y = tables.shape[1]
    ntile_x = tables.shape[2]
    for p in range(start, poses.shape[0]):
        table = tables[p]
        c = np.cos(poses[p, 2])
        s = np.sin(poses[p, 2])
        for k in range(hx.shape[0]):
            wx = poses[p, 0] + c * hx[k] - s * hy[k]
            wy = poses[p, 1] + s * hx[k] + c * hy[k]
            cx = int(np.floor((wx - ox) / res))
            cy = int(np.floor((wy - oy) / res))
            own = np.hypot(ox + (cx + 0.5) * res - wx, oy + (cy + 0.5) * res - wy)
            if cell_distance(pool, table, tile, cx, cy, dmax) <= own + skip_below:
                continue
            for iy in range(cy - radius, cy + radius + 1):
                if iy < 0 or iy >= ntile_y * tile:
                    continue
                ccy = oy + (iy + 0.5) * res - wy
                ty = iy // tile
                for ix in range(cx - radius, cx + radius + 1):
                    if ix < 0 or ix >= ntile_x * tile:
                        continue
                    ccx = ox + (ix + 0.5) * res - wx
                    dist = np.sqrt(ccx * ccx + ccy * ccy)
                    if dist >= dmax:
                        continue
                    tx = ix // tile
                    t = table[ty, tx]
                    if t < 0 or refcount[t] > 1:
                        if free_top[0] == 0:
                            return p
                        free_top[0] -= 1
                        new = free_stack[free_top[0]]
                        if t < 0:
                            pool[new, :, :] = dmax
                        else:
                            pool[new, :, :] = pool[t, :, :]
                            refcount[t] -= 1
                        refcount[new] = 1
                        table[ty, tx] = new
                        t = new
                    ly = iy - ty * tile
                    lx = ix - tx * tile
                    if dist < pool[t, ly, lx]:
                        pool[t, ly, lx] = dist
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
    top = 0
    for t in range(refcount.shape[0] - 1, -1, -1):
        if refcount[t] == 0:
            free_stack[top] = t
            top += 1
    return top
