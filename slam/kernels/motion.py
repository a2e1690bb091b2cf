"""Motion kernels: sampling the differential-drive (odometry increment) motion model."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def sample_motion(
    poses: np.ndarray,
    increment: np.ndarray,
    noise: np.ndarray,
    alphas: np.ndarray,
    floor: np.ndarray,
) -> np.ndarray:
    """Move every particle by the odometry ``increment`` ``(dx, dy, dθ)`` plus scaled noise.

    The increment is expressed in the robot frame at the previous pose. Noise follows the
    odometry model of Thrun et al. with standard deviations proportional to the motion:
    ``σ_x = a0·|d| + a1·|dθ| + f0``, ``σ_y = a2·|d| + a1·|dθ| + f1``, ``σ_θ = a3·|dθ| + a4·|d| + f2``
    with ``d = hypot(dx, dy)``. ``noise`` is ``(P, 3)`` standard normal drawn by the caller.
    Returns the new poses ``(P, 3)``.
    """
    p = poses.shape[0]
    out = np.empty_like(poses)
    d = np.hypot(increment[0], increment[1])
    a = abs(increment[2])
    sx = alphas[0] * d + alphas[1] * a + floor[0]
    sy = alphas[2] * d + alphas[1] * a + floor[1]
    st = alphas[3] * a + alphas[4] * d + floor[2]
    for i in range(p):
        dx = increment[0] + sx * noise[i, 0]
        dy = increment[1] + sy * noise[i, 1]
        dt = increment[2] + st * noise[i, 2]
        c = np.cos(poses[i, 2])
        s = np.sin(poses[i, 2])
        out[i, 0] = poses[i, 0] + c * dx - s * dy
        out[i, 1] = poses[i, 1] + s * dx + c * dy
        th = poses[i, 2] + dt
        out[i, 2] = (th + np.pi) % (2.0 * np.pi) - np.pi
    return out
