"""numba kernels of localization: scan likelihoods, KLD-sampling, the (x, y, θ) histogram filter.

* :func:`particle_loglik` — the likelihood-field beam model summed over a scan's returns, for
  every particle (parallel over particles; each writes only its own entry, so the result does
  not depend on the number of threads);
* :func:`systematic_draws` — low-variance (systematic) resampling of any number of draws;
* :func:`kld_count` — how many of a stream of samples KLD-sampling keeps (Fox 2003), with the
  bins seen so far carried between calls;
* :func:`state_loglik`, :func:`heading_mix`, :func:`translate_blur` — the histogram filter's
  update and prediction over the free states of a coarse (x, y, θ) grid.

Cell conventions are those of :mod:`slam.mapping`: ``array[iy, ix]``, lower-left corner of cell
``(ix, iy)`` at ``(ox + ix·res, oy + iy·res)``. No Python objects, no I/O, no randomness: random
numbers are drawn by the caller.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

FAR = 1.0e9
"""Distance returned for points outside the map (the tables saturate there)."""


@njit(cache=True, inline="always")
def table_lookup(table: np.ndarray, step_inv: float, d: float) -> float:
    """Linear interpolation in ``table`` sampled at ``d = 0, 1/step_inv, ...`` (saturating)."""
    u = d * step_inv
    last = table.shape[0] - 1
    if u >= last:
        return table[last]
    i = int(u)
    f = u - i
    return table[i] + f * (table[i + 1] - table[i])


@njit(cache=True, inline="always")
def distance_bilinear(
    dist: np.ndarray, ox: float, oy: float, inv_res: float, x: float, y: float
) -> float:
    """Bilinearly interpolated distance field at world ``(x, y)`` (between cell centres);
    :data:`FAR` outside the map."""
    gx = (x - ox) * inv_res - 0.5
    gy = (y - oy) * inv_res - 0.5
    rows = dist.shape[0]
    cols = dist.shape[1]
    if gx < 0.0 or gy < 0.0 or gx >= cols - 1 or gy >= rows - 1:
        return FAR
    ix = int(gx)
    iy = int(gy)
    fx = gx - ix
    fy = gy - iy
    d0 = dist[iy, ix] + fx * (dist[iy, ix + 1] - dist[iy, ix])
    d1 = dist[iy + 1, ix] + fx * (dist[iy + 1, ix + 1] - dist[iy + 1, ix])
    return d0 + fy * (d1 - d0)


@njit(cache=True, parallel=True)
def particle_loglik(
    dist: np.ndarray,
    ox: float,
    oy: float,
    inv_res: float,
    poses: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    table: np.ndarray,
    step_inv: float,
    out: np.ndarray,
) -> None:
    """``out[i] = Σ_b log p(z_b | pose_i)`` for the robot-frame returns ``(ex, ey)``.

    ``p`` is the likelihood-field mixture tabulated over the endpoint's distance to the nearest
    wall (``table``, see :func:`slam.localize.sensor.BeamModel.log_table`), the distance
    interpolated bilinearly between cell centres.
    """
    n = poses.shape[0]
    beams = ex.shape[0]
    for i in prange(n):
        x = poses[i, 0]
        y = poses[i, 1]
        c = math.cos(poses[i, 2])
        s = math.sin(poses[i, 2])
        acc = 0.0
        for b in range(beams):
            wx = x + c * ex[b] - s * ey[b]
            wy = y + s * ex[b] + c * ey[b]
            d = distance_bilinear(dist, ox, oy, inv_res, wx, wy)
            acc += table_lookup(table, step_inv, d)
        out[i] = acc


@njit(cache=True)
def systematic_draws(weights: np.ndarray, count: int, u0: float) -> np.ndarray:
    """Indices of ``count`` low-variance draws from normalised ``weights``: one random offset
    ``u0 ∈ [0, 1)``, stride ``1/count`` (particle ``i`` is drawn ``⌊count·w_i⌋`` or
    ``⌈count·w_i⌉`` times)."""
    n = weights.shape[0]
    out = np.empty(count, dtype=np.int64)
    cumulative = weights[0]
    i = 0
    for m in range(count):
        u = (u0 + m) / count
        while u > cumulative and i < n - 1:
            i += 1
            cumulative += weights[i]
        out[m] = i
    return out


@njit(cache=True)
def kld_bound_kernel(k: int, epsilon: float, z: float) -> float:
    """Fox's bound ``(k−1)/(2ε)·(1 − 2/(9(k−1)) + sqrt(2/(9(k−1)))·z)³`` (0 for ``k ≤ 1``)."""
    if k <= 1:
        return 0.0
    a = 2.0 / (9.0 * (k - 1))
    return (k - 1) / (2.0 * epsilon) * (1.0 - a + math.sqrt(a) * z) ** 3


@njit(cache=True)
def kld_count(
    poses: np.ndarray,
    start: int,
    bin_xy: float,
    bin_theta: float,
    epsilon: float,
    z: float,
    n_min: int,
    n_max: int,
    keys: np.ndarray,
    used: np.ndarray,
    state: np.ndarray,
) -> int:
    """KLD-sampling over the samples ``poses[start:]`` (drawn in order): how many to keep.

    Each sample falls into an ``(x, y, θ)`` bin; ``k`` counts the distinct bins so far; sampling
    stops at the first ``n`` with ``n ≥ n_min`` and ``n ≥`` :func:`kld_bound_kernel` ``(k)``, or
    at ``n_max``. ``keys (T, 3)``/``used (T,)`` are an open-addressing hash set of bins (``T`` a
    power of two above ``n_max``) and ``state = [k]`` — carried between calls, so a caller can
    feed the samples in chunks. Returns ``n`` (counting from sample 0), or −1 if the chunk ran
    out first.
    """
    mask = used.shape[0] - 1
    k = state[0]
    for m in range(start, poses.shape[0]):
        bx = int(math.floor(poses[m, 0] / bin_xy))
        by = int(math.floor(poses[m, 1] / bin_xy))
        bt = int(math.floor((poses[m, 2] + math.pi) / bin_theta))
        h = ((bx * 73856093) ^ (by * 19349663) ^ (bt * 83492791)) & mask
        while True:
            if not used[h]:
                used[h] = True
                keys[h, 0] = bx
                keys[h, 1] = by
                keys[h, 2] = bt
                k += 1
                break
            if keys[h, 0] == bx and keys[h, 1] == by and keys[h, 2] == bt:
                break
            h = (h + 1) & mask
        n = m + 1
        if n >= n_max or (n >= n_min and n >= kld_bound_kernel(k, epsilon, z)):
            state[0] = k
            return n
    state[0] = k
    return -1


@njit(cache=True, parallel=True)
def state_loglik(
    dist: np.ndarray,
    ox: float,
    oy: float,
    inv_res: float,
    cell_x: np.ndarray,
    cell_y: np.ndarray,
    rx: np.ndarray,
    ry: np.ndarray,
    tables: np.ndarray,
    step_inv: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out[h, f] = Σ_b log p_b(z_b | cell f, heading h)`` over the free states.

    ``(cell_x[f], cell_y[f])`` is the centre of free cell ``f``; ``(rx[h, b], ry[h, b])`` the
    robot-frame return ``b`` rotated by heading ``h``; ``tables[b]`` (sampled every
    ``1/step_inv[b]`` m) beam ``b``'s log-likelihood over the distance to the nearest wall, with
    the Gaussian widened for the cell's and heading bin's extent. The distance is the nearest
    cell's (the tables are wider than a cell). Parallel over cells; every state writes its own
    entry.
    """
    heads = rx.shape[0]
    beams = rx.shape[1]
    rows = dist.shape[0]
    cols = dist.shape[1]
    for f in prange(cell_x.shape[0]):
        cx = cell_x[f]
        cy = cell_y[f]
        for h in range(heads):
            acc = 0.0
            for b in range(beams):
                gx = (cx + rx[h, b] - ox) * inv_res
                gy = (cy + ry[h, b] - oy) * inv_res
                if gx < 0.0 or gy < 0.0 or gx >= cols or gy >= rows:
                    d = FAR
                else:
                    d = dist[int(gy), int(gx)]
                acc += table_lookup(tables[b], step_inv[b], d)
            out[h, f] = acc


@njit(cache=True, parallel=True)
def heading_mix(
    belief: np.ndarray,
    free_r: np.ndarray,
    free_c: np.ndarray,
    first_shift: int,
    weights: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out[h] = Σ_k weights[k] · belief[(h − first_shift − k) mod H]`` at the free cells.

    The heading part of the prediction: the rotation ``dθ`` and its noise as weights over
    integer bin shifts ``first_shift + k``. Only free cells are written (the rest of ``out`` is
    left as it is: zero).
    """
    heads = belief.shape[0]
    for f in prange(free_r.shape[0]):
        r = free_r[f]
        c = free_c[f]
        for h in range(heads):
            acc = 0.0
            for k in range(weights.shape[0]):
                src = (h - first_shift - k) % heads
                acc += weights[k] * belief[src, r, c]
            out[h, r, c] = acc


@njit(cache=True, parallel=True)
def translate_blur(
    belief: np.ndarray,
    free_r: np.ndarray,
    free_c: np.ndarray,
    row_first: np.ndarray,
    row_weights: np.ndarray,
    col_first: np.ndarray,
    col_weights: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out[h, r, c] = Σ_i Σ_j wr[h, i]·wc[h, j]·belief[h, r − r0[h] − i, c − c0[h] − j]``.

    The translation part of the prediction: heading ``h``'s displacement and its noise as
    separable weights over integer cell offsets (``row_first``/``col_first`` the first offset).
    A gather: each free destination cell sums its sources; sources off the grid count 0, and
    non-free sources hold 0 already. Only free cells are written.
    """
    heads, rows, cols = belief.shape
    nr = row_weights.shape[1]
    nc = col_weights.shape[1]
    for f in prange(free_r.shape[0]):
        r = free_r[f]
        c = free_c[f]
        for h in range(heads):
            acc = 0.0
            for i in range(nr):
                sr = r - row_first[h] - i
                if sr < 0 or sr >= rows:
                    continue
                wr = row_weights[h, i]
                if wr == 0.0:
                    continue
                line = 0.0
                for j in range(nc):
                    sc = c - col_first[h] - j
                    if 0 <= sc < cols:
                        line += col_weights[h, j] * belief[h, sr, sc]
                acc += wr * line
            out[h, r, c] = acc


@njit(cache=True, inline="always")
def distance_gradient(
    dist: np.ndarray, ox: float, oy: float, inv_res: float, x: float, y: float
) -> tuple[float, float, float]:
    """Bilinear distance at ``(x, y)`` and its gradient; :data:`FAR` (zero gradient) outside."""
    gx = (x - ox) * inv_res - 0.5
    gy = (y - oy) * inv_res - 0.5
    rows = dist.shape[0]
    cols = dist.shape[1]
    if gx < 0.0 or gy < 0.0 or gx >= cols - 1 or gy >= rows - 1:
        return FAR, 0.0, 0.0
    ix = int(gx)
    iy = int(gy)
    fx = gx - ix
    fy = gy - iy
    d00 = dist[iy, ix]
    d10 = dist[iy, ix + 1]
    d01 = dist[iy + 1, ix]
    d11 = dist[iy + 1, ix + 1]
    d = (1.0 - fy) * ((1.0 - fx) * d00 + fx * d10) + fy * ((1.0 - fx) * d01 + fx * d11)
    ddx = ((1.0 - fy) * (d10 - d00) + fy * (d11 - d01)) * inv_res
    ddy = ((1.0 - fx) * (d01 - d00) + fx * (d11 - d10)) * inv_res
    return d, ddx, ddy


@njit(cache=True)
def _refine_system(
    dist: np.ndarray,
    ox: float,
    oy: float,
    inv_res: float,
    x: float,
    y: float,
    th: float,
    ex: np.ndarray,
    ey: np.ndarray,
    inv_var: float,
    outlier: float,
    hg: np.ndarray,
) -> float:
    """Robust cost ``Σ −log(φ_b + outlier)`` at ``(x, y, th)``; ``hg`` receives the weighted
    Gauss-Newton system ``[h00, h01, h02, h11, h12, h22, g0, g1, g2]``."""
    c = math.cos(th)
    s = math.sin(th)
    h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    g0 = g1 = g2 = 0.0
    cost = 0.0
    far = -math.log(outlier)
    for b in range(ex.shape[0]):
        rx = c * ex[b] - s * ey[b]
        ry = s * ex[b] + c * ey[b]
        d, gx, gy = distance_gradient(dist, ox, oy, inv_res, x + rx, y + ry)
        if d >= FAR:
            cost += far
            continue
        phi = math.exp(-0.5 * d * d * inv_var)
        cost -= math.log(phi + outlier)
        w = phi / (phi + outlier) * inv_var
        j2 = -gx * ry + gy * rx
        h00 += w * gx * gx
        h01 += w * gx * gy
        h02 += w * gx * j2
        h11 += w * gy * gy
        h12 += w * gy * j2
        h22 += w * j2 * j2
        g0 += w * gx * d
        g1 += w * gy * d
        g2 += w * j2 * d
    hg[0] = h00
    hg[1] = h01
    hg[2] = h02
    hg[3] = h11
    hg[4] = h12
    hg[5] = h22
    hg[6] = g0
    hg[7] = g1
    hg[8] = g2
    return cost


@njit(cache=True)
def _solve3(hg: np.ndarray, damping: float) -> tuple[float, float, float, bool]:
    """``(H + λ·diag(H))·δ = −g`` for the packed system ``hg`` (Cramer's rule)."""
    a00 = hg[0] * (1.0 + damping) + 1e-12
    a01 = hg[1]
    a02 = hg[2]
    a11 = hg[3] * (1.0 + damping) + 1e-12
    a12 = hg[4]
    a22 = hg[5] * (1.0 + damping) + 1e-12
    b0 = -hg[6]
    b1 = -hg[7]
    b2 = -hg[8]
    det = (
        a00 * (a11 * a22 - a12 * a12)
        - a01 * (a01 * a22 - a12 * a02)
        + a02 * (a01 * a12 - a11 * a02)
    )
    if abs(det) < 1e-30:
        return 0.0, 0.0, 0.0, False
    dx = (
        b0 * (a11 * a22 - a12 * a12) - a01 * (b1 * a22 - a12 * b2) + a02 * (b1 * a12 - a11 * b2)
    ) / det
    dy = (
        a00 * (b1 * a22 - a12 * b2) - b0 * (a01 * a22 - a12 * a02) + a02 * (a01 * b2 - b1 * a02)
    ) / det
    dt = (
        a00 * (a11 * b2 - b1 * a12) - a01 * (a01 * b2 - b1 * a02) + b0 * (a01 * a12 - a11 * a02)
    ) / det
    return dx, dy, dt, True


@njit(cache=True)
def refine_pose(
    dist: np.ndarray,
    ox: float,
    oy: float,
    inv_res: float,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    sigma: float,
    outlier: float,
    iterations: int,
    tolerance: float,
    out: np.ndarray,
) -> int:
    """Levenberg-Marquardt on the likelihood field from ``pose``: the pose nearby that best
    explains the returns ``(ex, ey)``; written to ``out``, returns its cost.

    The cost is the mixture's ``Σ −log(φ_b + outlier)``, ``φ = exp(−d²/2σ²)`` with ``d`` the
    endpoint's distance to the nearest wall and ``outlier`` the uniform term relative to the
    Gaussian's peak; each Gauss-Newton step weights a beam by its responsibility
    ``γ = φ/(φ + outlier)`` (unexplained returns drop out). A step that raises the cost is
    retried with more damping; the search stops when a step moves less than ``tolerance``
    (m, and rad) or after ``iterations`` tries.
    """
    x = pose[0]
    y = pose[1]
    th = pose[2]
    inv_var = 1.0 / (sigma * sigma)
    hg = np.empty(9)
    trial = np.empty(9)
    cost = _refine_system(dist, ox, oy, inv_res, x, y, th, ex, ey, inv_var, outlier, hg)
    damping = 1e-3
    for _ in range(iterations):
        dx, dy, dt, ok = _solve3(hg, damping)
        if not ok:
            break
        new_cost = _refine_system(
            dist, ox, oy, inv_res, x + dx, y + dy, th + dt, ex, ey, inv_var, outlier, trial
        )
        if new_cost < cost:
            x += dx
            y += dy
            th += dt
            cost = new_cost
            hg[:] = trial
            damping = max(damping * 0.3, 1e-6)
            if abs(dx) < tolerance and abs(dy) < tolerance and abs(dt) < tolerance:
                break
        else:
            damping *= 10.0
    out[0] = x
    out[1] = y
    out[2] = (th + math.pi) % (2.0 * math.pi) - math.pi
    return cost
