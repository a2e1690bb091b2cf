"""The one small dense solver of the numba kernels: a symmetric 3×3 system in closed form.

The Gauss-Newton and Levenberg-Marquardt steps of the scan matchers (:mod:`slam.kernels.field`,
:mod:`slam.localize.kernels`) solve a symmetric 3×3 system per iteration, inside loops over
particles or scans; a closed form in scalars keeps that free of allocations and of LAPACK.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def solve_sym3(
    a: float,
    b: float,
    c: float,
    d: float,
    e: float,
    f: float,
    g0: float,
    g1: float,
    g2: float,
    tiny: float,
) -> tuple[float, float, float, bool]:
    """Solve ``[[a, b, c], [b, d, e], [c, e, f]] x = (g0, g1, g2)`` by the adjugate.

    Returns ``(x0, x1, x2, True)``, or ``(0, 0, 0, False)`` when the determinant's magnitude is
    below ``tiny`` (a singular or degenerate system: the caller takes no step).
    """
    det = a * (d * f - e * e) - b * (b * f - c * e) + c * (b * e - c * d)
    if abs(det) < tiny:
        return 0.0, 0.0, 0.0, False
    i00 = d * f - e * e
    i01 = c * e - b * f
    i02 = b * e - c * d
    i11 = a * f - c * c
    i12 = b * c - a * e
    i22 = a * d - b * b
    x0 = (i00 * g0 + i01 * g1 + i02 * g2) / det
    x1 = (i01 * g0 + i11 * g1 + i12 * g2) / det
    x2 = (i02 * g0 + i12 * g1 + i22 * g2) / det
    return x0, x1, x2, True
