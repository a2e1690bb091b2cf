"""Signal-filtering kernels (time series): first-order low-pass over irregular sampling."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def lowpass_first_order(values: np.ndarray, times: np.ndarray, cutoff_hz: float) -> np.ndarray:
    """Zero-phase first-order low-pass of ``values`` sampled at (irregular) ``times``.

    A forward pass and a backward pass of the exponential filter ``y += a (x - y)`` with
    ``a = dt / (RC + dt)``, ``RC = 1 / (2π f_c)``: the backward pass cancels the forward pass's lag,
    which matters offline because a lagged yaw rate turns into a heading error.
    """
    n = values.shape[0]
    out = np.empty(n)
    if n == 0:
        return out
    rc = 1.0 / (2.0 * np.pi * cutoff_hz)
    y = values[0]
    out[0] = y
    for i in range(1, n):
        dt = times[i] - times[i - 1]
        a = dt / (rc + dt) if dt > 0.0 else 0.0
        y += a * (values[i] - y)
        out[i] = y
    y = out[n - 1]
    for i in range(n - 2, -1, -1):
        dt = times[i + 1] - times[i]
        a = dt / (rc + dt) if dt > 0.0 else 0.0
        y += a * (out[i] - y)
        out[i] = y
    return out
