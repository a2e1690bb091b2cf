"""Pose-graph kernels: correlative search for loop closures, SE(2) graph linearisation, solver.

A pose graph has one node per pose ``x_k = (x, y, θ)`` and one edge per measured relative motion
``z_ij`` (pose ``j`` in the frame of pose ``i``) with an information matrix ``Ω_ij``. The error of
an edge is ``e = z_ij⁻¹ ⊕ (x_i⁻¹ ⊕ x_j)`` and Gauss-Newton minimises ``Σ ρ(eᵀ Ω e)``.

The linear system ``H Δ = −b`` is solved by conjugate gradients preconditioned with the chain
part of ``H`` (the diagonal blocks and the blocks between consecutive nodes), which is block
tridiagonal and solved exactly by block elimination: with the odometry chain solved exactly,
the iterations only have to propagate the few loop-closure edges.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slam.kernels.field import FieldView, surface_at, table_lookup


@njit(cache=True)
def _mul(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = a b`` for 3×3 blocks (numba's ``@`` needs BLAS from SciPy; these blocks are tiny)."""
    for r in range(3):
        for c in range(3):
            out[r, c] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]


@njit(cache=True)
def _mul_t(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = aᵀ b`` for 3×3 blocks."""
    for r in range(3):
        for c in range(3):
            out[r, c] = a[0, r] * b[0, c] + a[1, r] * b[1, c] + a[2, r] * b[2, c]


@njit(cache=True)
def _vec(a: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """``out = a v`` for a 3×3 block."""
    for r in range(3):
        out[r] = a[r, 0] * v[0] + a[r, 1] * v[1] + a[r, 2] * v[2]


@njit(cache=True)
def _vec_t(a: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """``out = aᵀ v`` for a 3×3 block."""
    for r in range(3):
        out[r] = a[0, r] * v[0] + a[1, r] * v[1] + a[2, r] * v[2]


@njit(cache=True)
def _inv(m: np.ndarray, out: np.ndarray) -> None:
    """``out`` = inverse of a 3×3 matrix by cofactors."""
    a, b, c = m[0, 0], m[0, 1], m[0, 2]
    d, e, f = m[1, 0], m[1, 1], m[1, 2]
    g, h, i = m[2, 0], m[2, 1], m[2, 2]
    co00 = e * i - f * h
    co01 = -(d * i - f * g)
    co02 = d * h - e * g
    det = a * co00 + b * co01 + c * co02
    out[0, 0] = co00 / det
    out[1, 0] = co01 / det
    out[2, 0] = co02 / det
    out[0, 1] = -(b * i - c * h) / det
    out[1, 1] = (a * i - c * g) / det
    out[2, 1] = -(a * h - b * g) / det
    out[0, 2] = (b * f - c * e) / det
    out[1, 2] = -(a * f - c * d) / det
    out[2, 2] = (a * e - b * d) / det


@njit(cache=True)
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """``Σ a·b`` over ``(n, 3)`` arrays, summed in memory order (what ``np.sum(a * b)`` does)."""
    total = 0.0
    for k in range(a.shape[0]):
        for c in range(3):
            total += a[k, c] * b[k, c]
    return total


@njit(
    cache=True, _nrt=False
)  # allocates nothing: no reference counts per call (kernels/quality.py)
def scan_cost(
    view: FieldView,
    x: float,
    y: float,
    th: float,
    ex: np.ndarray,
    ey: np.ndarray,
    cost_row: np.ndarray,
    step_inv: float,
) -> float:
    """Negative log-likelihood of endpoints ``(ex, ey)`` (robot frame) at pose ``(x, y, th)``."""
    c = np.cos(th)
    s = np.sin(th)
    unknown = cost_row[cost_row.shape[0] - 1]
    total = 0.0
    for b in range(ex.shape[0]):
        d, _, _ = surface_at(view, x + c * ex[b] - s * ey[b], y + s * ex[b] + c * ey[b])
        total += unknown if np.isnan(d) else table_lookup(cost_row, step_inv, abs(d))
    return total


@njit(cache=True, nogil=True)
def correlative_search(
    view: FieldView,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    cost_row: np.ndarray,
    step_inv: float,
    xy_range: float,
    xy_step: float,
    th_range: float,
    th_step: float,
) -> np.ndarray:
    """Best pose on a grid around ``pose``: ±``xy_range`` in steps of ``xy_step``, ±``th_range``.

    Brute force over every offset (the wide basin a loop closure needs), scored by
    :func:`scan_cost`. Returns ``(x, y, θ, cost)``.
    """
    nxy = int(round(xy_range / xy_step))
    nth = int(round(th_range / th_step))
    best = np.empty(4)
    best[3] = np.inf
    for k in range(-nth, nth + 1):
        th = pose[2] + k * th_step
        for i in range(-nxy, nxy + 1):
            x = pose[0] + i * xy_step
            for j in range(-nxy, nxy + 1):
                y = pose[1] + j * xy_step
                cost = scan_cost(view, x, y, th, ex, ey, cost_row, step_inv)
                if cost < best[3]:
                    best[0] = x
                    best[1] = y
                    best[2] = th
                    best[3] = cost
    return best


@njit(cache=True)
def edge_error(xi: np.ndarray, xj: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``e = z⁻¹ ⊕ (x_i⁻¹ ⊕ x_j)`` as ``(e_x, e_y, e_θ)``."""
    ci, si = np.cos(xi[2]), np.sin(xi[2])
    dx = xj[0] - xi[0]
    dy = xj[1] - xi[1]
    rx = ci * dx + si * dy - z[0]
    ry = -si * dx + ci * dy - z[1]
    cz, sz = np.cos(z[2]), np.sin(z[2])
    out = np.empty(3)
    out[0] = cz * rx + sz * ry
    out[1] = -sz * rx + cz * ry
    t = xj[2] - xi[2] - z[2]
    out[2] = (t + np.pi) % (2.0 * np.pi) - np.pi
    return out


@njit(cache=True)
def _jacobians(xi: np.ndarray, xj: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ci, si = np.cos(xi[2]), np.sin(xi[2])
    cz, sz = np.cos(z[2]), np.sin(z[2])
    dx = xj[0] - xi[0]
    dy = xj[1] - xi[1]
    # Rz^T Ri^T
    m00 = cz * ci - sz * si
    m01 = cz * si + sz * ci
    m10 = -sz * ci - cz * si
    m11 = -sz * si + cz * ci
    # d(Ri^T dt)/dθi = (-si dx + ci dy, -ci dx - si dy)
    gx = -si * dx + ci * dy
    gy = -ci * dx - si * dy
    a = np.zeros((3, 3))
    b = np.zeros((3, 3))
    a[0, 0] = -m00
    a[0, 1] = -m01
    a[1, 0] = -m10
    a[1, 1] = -m11
    a[0, 2] = cz * gx + sz * gy
    a[1, 2] = -sz * gx + cz * gy
    a[2, 2] = -1.0
    b[0, 0] = m00
    b[0, 1] = m01
    b[1, 0] = m10
    b[1, 1] = m11
    b[2, 2] = 1.0
    return a, b


@njit(cache=True)
def linearize(
    poses: np.ndarray,
    edge_i: np.ndarray,
    edge_j: np.ndarray,
    meas: np.ndarray,
    info: np.ndarray,
    robust: np.ndarray,
    diag: np.ndarray,
    band: np.ndarray,
    far: np.ndarray,
    grad: np.ndarray,
) -> float:
    """Build the Gauss-Newton system of the graph; return the (robust) total cost.

    ``diag[k]`` receives ``H_kk``; ``band[k]`` receives ``H_{k,k+1}``; ``far[e]`` receives the
    off-diagonal block ``H_ij`` of every edge that does not join consecutive nodes (zero for the
    others); ``grad[k]`` receives ``b_k``. Edges with ``robust[e] > 0`` use the Cauchy kernel
    ``ρ(s) = c² log(1 + s/c²)`` with ``c = robust[e]``, i.e. their information is scaled by
    ``1 / (1 + s/c²)`` (iteratively reweighted least squares).
    """
    diag[:] = 0.0
    band[:] = 0.0
    far[:] = 0.0
    grad[:] = 0.0
    total = 0.0
    # 3×3 scratch blocks, filled in place: no array expressions (each costs a compilation)
    wom = np.empty((3, 3))
    at_om = np.empty((3, 3))
    bt_om = np.empty((3, 3))
    block = np.empty((3, 3))
    vec = np.empty(3)
    for e in range(edge_i.shape[0]):
        i = edge_i[e]
        j = edge_j[e]
        err = edge_error(poses[i], poses[j], meas[e])
        om = info[e]
        s = 0.0
        for r in range(3):
            for c in range(3):
                s += err[r] * om[r, c] * err[c]
        w = 1.0
        if robust[e] > 0.0:
            c2 = robust[e] * robust[e]
            w = 1.0 / (1.0 + s / c2)
            total += c2 * np.log(1.0 + s / c2)
        else:
            total += s
        a, b = _jacobians(poses[i], poses[j], meas[e])
        for r in range(3):
            for c in range(3):
                wom[r, c] = w * om[r, c]
        _mul_t(a, wom, at_om)
        _mul_t(b, wom, bt_om)
        _mul(at_om, a, block)
        _add(diag[i], block)
        _mul(bt_om, b, block)
        _add(diag[j], block)
        _mul(at_om, b, block)  # H_ij
        if j == i + 1:
            _add(band[i], block)
        elif i == j + 1:
            _add_t(band[j], block)
        else:
            _add(far[e], block)
        _vec(at_om, err, vec)
        for r in range(3):
            grad[i, r] += vec[r]
        _vec(bt_om, err, vec)
        for r in range(3):
            grad[j, r] += vec[r]
    return total


@njit(cache=True)
def _add(out: np.ndarray, block: np.ndarray) -> None:
    """``out += block`` for 3×3 blocks."""
    for r in range(3):
        for c in range(3):
            out[r, c] += block[r, c]


@njit(cache=True)
def _add_t(out: np.ndarray, block: np.ndarray) -> None:
    """``out += blockᵀ`` for 3×3 blocks."""
    for r in range(3):
        for c in range(3):
            out[r, c] += block[c, r]


@njit(cache=True)
def _chain_factor(diag: np.ndarray, band: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Block LDLᵀ-style elimination of the block-tridiagonal chain part (for the preconditioner)."""
    n = diag.shape[0]
    dinv = np.empty((n, 3, 3))
    _inv(diag[0], dinv[0])
    m = np.empty((3, 3))
    t = np.empty((3, 3))
    d = np.empty((3, 3))
    for k in range(1, n):
        u = band[k - 1]
        _mul(dinv[k - 1], u, m)
        _mul_t(u, m, t)
        for r in range(3):
            for c in range(3):
                d[r, c] = diag[k, r, c] - t[r, c]
        _inv(d, dinv[k])
    return dinv, band


@njit(cache=True)
def _chain_solve(dinv: np.ndarray, band: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Solve ``M y = r`` for the block-tridiagonal ``M`` factored by :func:`_chain_factor`."""
    n = r.shape[0]
    y = np.empty_like(r)
    v = np.empty(3)
    w = np.empty(3)
    # forward: z_k = r_k - U_{k-1}^T D_{k-1}^{-1} z_{k-1}
    for c in range(3):
        y[0, c] = r[0, c]
    for k in range(1, n):
        _vec(dinv[k - 1], y[k - 1], v)
        _vec_t(band[k - 1], v, w)
        for c in range(3):
            y[k, c] = r[k, c] - w[c]
    # backward: x_k = D_k^{-1} (z_k - U_k x_{k+1})
    x = np.empty_like(r)
    _vec(dinv[n - 1], y[n - 1], x[n - 1])
    for k in range(n - 2, -1, -1):
        _vec(band[k], x[k + 1], v)
        for c in range(3):
            w[c] = y[k, c] - v[c]
        _vec(dinv[k], w, x[k])
    return x


@njit(cache=True)
def _matvec(
    diag: np.ndarray,
    band: np.ndarray,
    far: np.ndarray,
    edge_i: np.ndarray,
    edge_j: np.ndarray,
    v: np.ndarray,
) -> np.ndarray:
    n = v.shape[0]
    out = np.empty_like(v)
    t = np.empty(3)
    for k in range(n):
        _vec(diag[k], v[k], out[k])
    for k in range(n - 1):
        _vec(band[k], v[k + 1], t)
        for c in range(3):
            out[k, c] += t[c]
        _vec_t(band[k], v[k], t)
        for c in range(3):
            out[k + 1, c] += t[c]
    for e in range(edge_i.shape[0]):
        i = edge_i[e]
        j = edge_j[e]
        if j == i + 1 or i == j + 1:
            continue
        _vec(far[e], v[j], t)
        for c in range(3):
            out[i, c] += t[c]
        _vec_t(far[e], v[i], t)
        for c in range(3):
            out[j, c] += t[c]
    return out


@njit(cache=True)
def solve_system(
    diag: np.ndarray,
    band: np.ndarray,
    far: np.ndarray,
    edge_i: np.ndarray,
    edge_j: np.ndarray,
    rhs: np.ndarray,
    max_iter: int,
    tolerance: float,
) -> tuple[np.ndarray, int, bool]:
    """Solve ``H x = rhs`` by conjugate gradients preconditioned with the chain part of ``H``.

    Returns the solution, the number of iterations used (none, and NaN everywhere, when the
    system holds a NaN or an infinity: no iteration would make it finite) and whether the
    residual reached ``tolerance`` (a solve cut by ``max_iter`` may have reached it on its last
    iteration, or not). Written with scalar loops over the ``(n, 3)`` arrays instead of array
    expressions: the same arithmetic in the same order, but numba compiles every distinct array
    expression as a function of its own.
    """
    n = rhs.shape[0]
    dinv, _ = _chain_factor(diag, band)
    x = _chain_solve(dinv, band, rhs)
    hx = _matvec(diag, band, far, edge_i, edge_j, x)
    r = np.empty_like(rhs)
    for k in range(n):
        for c in range(3):
            r[k, c] = rhs[k, c] - hx[k, c]
    z = _chain_solve(dinv, band, r)
    p = z.copy()
    rz = _dot(r, z)
    norm0 = np.sqrt(_dot(rhs, rhs)) + 1e-300
    used = 0
    for _ in range(max_iter):
        residual = np.sqrt(_dot(r, r))
        if not (np.isfinite(residual) and np.isfinite(norm0)):
            # a NaN or inf in the system: no iteration would make it finite, and a finite part
            # of the solution would not be one
            for k in range(n):
                for c in range(3):
                    x[k, c] = np.nan
            break
        if residual <= tolerance * norm0:
            break
        used += 1
        hp = _matvec(diag, band, far, edge_i, edge_j, p)
        alpha = rz / _dot(p, hp)
        for k in range(n):
            for c in range(3):
                x[k, c] += alpha * p[k, c]
                r[k, c] -= alpha * hp[k, c]
        z = _chain_solve(dinv, band, r)
        rz_new = _dot(r, z)
        beta = rz_new / rz
        for k in range(n):
            for c in range(3):
                p[k, c] = z[k, c] + beta * p[k, c]
        rz = rz_new
    converged = np.sqrt(_dot(r, r)) <= tolerance * norm0  # False for a NaN
    return x, used, converged


@njit(cache=True, nogil=True)
def fit_counts(
    view: FieldView,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    distance: float,
) -> tuple[int, int]:
    """Beams of a scan at ``pose`` on known cells, and those within ``distance`` of a surface."""
    c = np.cos(pose[2])
    s = np.sin(pose[2])
    known = 0
    close = 0
    for b in range(ex.shape[0]):
        d, _, _ = surface_at(view, pose[0] + c * ex[b] - s * ey[b], pose[1] + s * ex[b] + c * ey[b])
        if not np.isnan(d):
            known += 1
            if abs(d) < distance:
                close += 1
    return known, close


@njit(cache=True, nogil=True)
def shifted_fit(
    view: FieldView,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    distance: float,
    shift: float,
    directions: int,
) -> int:
    """The most beams within ``distance`` of a surface (:func:`fit_counts`) of a scan at ``pose``
    moved ``shift`` metres in any of ``directions`` directions evenly spread over the circle
    (heading unchanged): how well the scan would fit somewhere else nearby. A corridor's scan
    fits about as well a metre along it as where it matched."""
    best = 0
    moved = np.empty(3)
    moved[2] = pose[2]
    for k in range(directions):
        a = 2.0 * np.pi * k / directions
        moved[0] = pose[0] + shift * np.cos(a)
        moved[1] = pose[1] + shift * np.sin(a)
        _, close = fit_counts(view, moved, ex, ey, distance)
        best = max(best, close)
    return best


@njit(cache=True, nogil=True)
def fits_when_shifted(
    view: FieldView,
    pose: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    distance: float,
    shifts: np.ndarray,
    directions: int,
    need: int,
) -> bool:
    """Whether a scan at ``pose`` moved by any of ``shifts`` metres in any of ``directions``
    directions evenly spread over the circle (heading unchanged) has at least ``need`` beams
    within ``distance`` of a surface: :func:`shifted_fit` over several shifts, each placement
    given up as soon as too few beams are left to reach ``need``."""
    c = np.cos(pose[2])
    s = np.sin(pose[2])
    n = ex.shape[0]
    wx = np.empty(n)
    wy = np.empty(n)
    for b in range(n):
        wx[b] = pose[0] + c * ex[b] - s * ey[b]
        wy[b] = pose[1] + s * ex[b] + c * ey[b]
    for shift in shifts:
        for k in range(directions):
            a = 2.0 * np.pi * k / directions
            dx = shift * np.cos(a)
            dy = shift * np.sin(a)
            close = 0
            for b in range(n):
                if close + (n - b) < need:
                    break
                d, _, _ = surface_at(view, wx[b] + dx, wy[b] + dy)
                if not np.isnan(d) and abs(d) < distance:
                    close += 1
                    if close >= need:
                        return True
    return False
