"""numba kernels of localization: scan likelihoods, KLD-sampling, the (x, y, θ) histogram filter.

* :func:`particle_loglik` — the likelihood-field beam model summed over a scan's returns, for
  every particle (parallel over particles; each writes only its own entry, so the result does
  not depend on the number of threads);
* (low-variance resampling of any number of draws is :func:`slam.kernels.resample.systematic_draws`);
* :func:`kld_count` — how many of a stream of samples KLD-sampling keeps (Fox 2003), with the
  bins seen so far carried between calls;
* :func:`state_loglik`, :func:`heading_mix`, :func:`shift_columns`, :func:`shift_rows` — the
  histogram filter's
  update and prediction over the free states of a coarse (x, y, θ) grid.

Cell conventions are those of :mod:`slam.mapping`: ``array[iy, ix]``, lower-left corner of cell
``(ix, iy)`` at ``(ox + ix·res, oy + iy·res)``. No Python objects, no I/O, no randomness: random
numbers are drawn by the caller.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from slam.kernels.field import table_lookup
from slam.kernels.linalg import solve_sym3

FAR = 1.0e9
"""Distance returned for points outside the map (the tables saturate there)."""


class DistanceView(NamedTuple):
    """A dense distance field as the kernels read it (numba takes it as one argument)."""

    distance: np.ndarray
    """``(H, W)`` float32 distance (m) from each cell centre to the nearest occupied cell."""
    ox: float
    """World x of the lower-left corner of cell (0, 0) (m)."""
    oy: float
    """World y of the lower-left corner of cell (0, 0) (m)."""
    inv_res: float
    """``1 / resolution`` (cells per metre)."""


@njit(cache=True, inline="always")
def distance_bilinear(view: DistanceView, x: float, y: float) -> float:
    """Bilinearly interpolated distance field at world ``(x, y)`` (between cell centres);
    :data:`FAR` outside the map."""
    dist = view.distance
    gx = (x - view.ox) * view.inv_res - 0.5
    gy = (y - view.oy) * view.inv_res - 0.5
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
    view: DistanceView,
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
            d = distance_bilinear(view, wx, wy)
            acc += table_lookup(table, step_inv, d)
        out[i] = acc


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
    grids: np.ndarray,
    far: np.ndarray,
    level: np.ndarray,
    offset_r: np.ndarray,
    offset_c: np.ndarray,
    free_r: np.ndarray,
    free_c: np.ndarray,
    quantum: float,
    out: np.ndarray,
) -> None:
    """``out[h, f] = Σ_b log p_b(z_b | cell f, heading h)`` over the free states.

    ``grids[l, py, px]`` is the fine log-likelihood grid of width level ``l`` decimated by the
    coarse factor ``k`` from phase ``(py, px)``, in units of ``quantum`` above its value far from
    any wall ``far[l]``: ``grids[l, py, px, r, c] = (L_l[k·r + py, k·c + px] − far[l]) /
    quantum`` (reads off the grid count 0). Return ``b`` seen from heading ``h`` lands
    ``offset_r[h, b]`` fine rows and ``offset_c[h, b]`` fine columns from a coarse cell's first
    fine cell, so over all cells it reads one decimated grid at a fixed shift: the inner loop
    walks the free cells in row-major order through nearly contiguous memory, without a bounds
    test when the whole shifted block of states lies inside the grid. Parallel over headings;
    every heading writes its own row.
    """
    k = grids.shape[1]
    rows = grids.shape[3]
    cols = grids.shape[4]
    heads = offset_r.shape[0]
    beams = offset_r.shape[1]
    cells = free_r.shape[0]
    lo_r = free_r.min()
    hi_r = free_r.max()
    lo_c = free_c.min()
    hi_c = free_c.max()
    base = 0.0
    for b in range(beams):
        base += far[level[b]]
    for h in prange(heads):
        acc = np.zeros(cells, dtype=np.int32)
        for b in range(beams):
            orow = offset_r[h, b]
            ocol = offset_c[h, b]
            qy = orow // k
            qx = ocol // k
            g = grids[level[b], orow - qy * k, ocol - qx * k]
            if lo_r + qy >= 0 and hi_r + qy < rows and lo_c + qx >= 0 and hi_c + qx < cols:
                for i in range(cells):
                    acc[i] += g[free_r[i] + qy, free_c[i] + qx]
                continue
            for i in range(cells):
                r = free_r[i] + qy
                c = free_c[i] + qx
                if 0 <= r < rows and 0 <= c < cols:
                    acc[i] += g[r, c]
        row = out[h]
        for i in range(cells):
            row[i] = base + acc[i] * quantum


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
    left as it is: zero). Parallel over headings; each reads whole source layers in order.
    """
    heads = belief.shape[0]
    cells = free_r.shape[0]
    for h in prange(heads):
        dst = out[h]
        for i in range(cells):
            dst[free_r[i], free_c[i]] = 0.0
        for k in range(weights.shape[0]):
            w = weights[k]
            if w == 0.0:
                continue
            src = belief[(h - first_shift - k) % heads]
            for i in range(cells):
                r = free_r[i]
                c = free_c[i]
                dst[r, c] += w * src[r, c]


@njit(cache=True, parallel=True)
def shift_columns(
    belief: np.ndarray,
    cells_r: np.ndarray,
    cells_c: np.ndarray,
    col_first: np.ndarray,
    col_weights: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out[h, r, c] = Σ_j wc[h, j] · belief[h, r, c − c0[h] − j]`` at the cells
    ``(cells_r, cells_c)`` (sources off the grid count 0): the column half of the translation,
    at every cell the row half will read (states and the cells above and below them within the
    row kernel's reach), not only at states."""
    heads, rows, cols = belief.shape
    nc = col_weights.shape[1]
    for h in prange(heads):
        src = belief[h]
        dst = out[h]
        c0 = col_first[h]
        for i in range(cells_r.shape[0]):
            r = cells_r[i]
            c = cells_c[i]
            acc = 0.0
            for j in range(nc):
                sc = c - c0 - j
                if 0 <= sc < cols:
                    acc += col_weights[h, j] * src[r, sc]
            dst[r, c] = acc


@njit(cache=True, parallel=True)
def shift_rows(
    belief: np.ndarray,
    free_r: np.ndarray,
    free_c: np.ndarray,
    row_first: np.ndarray,
    row_weights: np.ndarray,
    keep: float,
    floor: float,
    out: np.ndarray,
) -> None:
    """``out[h, r, c] = keep · Σ_i wr[h, i] · belief[h, r − r0[h] − i, c] + floor`` at the free
    cells only (the rest of ``out`` is left as it is: zero): the row half of the translation,
    with a share ``1 − keep`` of the mass spread evenly (``floor`` per state)."""
    heads, rows, cols = belief.shape
    nr = row_weights.shape[1]
    for h in prange(heads):
        for f in range(free_r.shape[0]):
            r = free_r[f]
            c = free_c[f]
            acc = 0.0
            for i in range(nr):
                sr = r - row_first[h] - i
                if 0 <= sr < rows:
                    acc += row_weights[h, i] * belief[h, sr, c]
            out[h, r, c] = keep * acc + floor


@njit(cache=True, inline="always")
def distance_gradient(view: DistanceView, x: float, y: float) -> tuple[float, float, float]:
    """Bilinear distance at ``(x, y)`` and its gradient; :data:`FAR` (zero gradient) outside."""
    dist = view.distance
    inv_res = view.inv_res
    gx = (x - view.ox) * inv_res - 0.5
    gy = (y - view.oy) * inv_res - 0.5
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


@njit(cache=True, _nrt=False)
def _refine_system(
    view: DistanceView,
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
        d, gx, gy = distance_gradient(view, x + rx, y + ry)
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
def refine_pose(
    view: DistanceView,
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
    cost = _refine_system(view, x, y, th, ex, ey, inv_var, outlier, hg)
    damping = 1e-3
    for _ in range(iterations):
        # (H + λ·diag(H))·δ = −g for the packed system hg
        scale = 1.0 + damping
        a00, a11, a22 = hg[0] * scale + 1e-12, hg[3] * scale + 1e-12, hg[5] * scale + 1e-12
        dx, dy, dt, ok = solve_sym3(
            a00, hg[1], hg[2], a11, hg[4], a22, -hg[6], -hg[7], -hg[8], 1e-30
        )
        if not ok:
            break
        new_cost = _refine_system(view, x + dx, y + dy, th + dt, ex, ey, inv_var, outlier, trial)
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


@njit(cache=True, parallel=True)
def apply_likelihood(
    belief: np.ndarray,
    free_r: np.ndarray,
    free_c: np.ndarray,
    loglik: np.ndarray,
    inv_temperature: float,
) -> float:
    """``bel(x) ← bel(x) · exp((ℓ(x) − ℓ_max)/T)`` at the free states; returns the new total.

    ``ℓ_max`` is the largest log-likelihood among states with mass (so the best of them keeps
    its mass and nothing underflows to an all-zero belief). The total is summed per heading and
    then over headings in order, so it does not depend on the number of threads.
    """
    heads = loglik.shape[0]
    cells = loglik.shape[1]
    best = np.full(heads, -np.inf)
    for h in prange(heads):
        m = -np.inf
        for i in range(cells):
            if belief[h, free_r[i], free_c[i]] > 0.0 and loglik[h, i] > m:
                m = loglik[h, i]
        best[h] = m
    top = best.max()
    partial = np.zeros(heads)
    for h in prange(heads):
        acc = 0.0
        for i in range(cells):
            r = free_r[i]
            c = free_c[i]
            v = belief[h, r, c]
            if v > 0.0:
                v *= math.exp((loglik[h, i] - top) * inv_temperature)
                belief[h, r, c] = v
                acc += v
        partial[h] = acc
    total = 0.0
    for h in range(heads):
        total += partial[h]
    return total
