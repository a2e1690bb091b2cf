"""Resampling kernels: effective sample size and systematic resampling."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def effective_sample_size(weights: np.ndarray) -> float:
    """``N_eff = 1 / Σ w²`` of normalised weights (``N`` for uniform weights, 1 for a single one)."""
    total = 0.0
    for w in weights:
        total += w * w
    return 1.0 / total if total > 0.0 else 0.0


@njit(cache=True)
def systematic_resample(weights: np.ndarray, u0: float) -> np.ndarray:
    """Indices of ``N`` draws with one random offset ``u0 ∈ [0, 1)`` and stride ``1/N``.

    Particle ``i`` is copied ``floor(N w_i)`` or ``ceil(N w_i)`` times (low variance). ``weights``
    must be normalised; ``u0`` is drawn by the caller so the kernel stays deterministic.
    """
    n = weights.shape[0]
    out = np.empty(n, dtype=np.int64)
    cumulative = weights[0]
    i = 0
    for m in range(n):
        u = (u0 + m) / n
        while u > cumulative and i < n - 1:
            i += 1
            cumulative += weights[i]
        out[m] = i
    return out
