"""Resampling kernels: effective sample size and systematic (low-variance) draws."""

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
    return systematic_draws(weights, weights.shape[0], u0)


@njit(cache=True)
def systematic_draws(weights: np.ndarray, count: int, u0: float) -> np.ndarray:
    """Indices of ``count`` low-variance draws from normalised ``weights``: one random offset
    ``u0 ∈ [0, 1)``, stride ``1/count`` (particle ``i`` is drawn ``⌊count·w_i⌋`` or
    ``⌈count·w_i⌉`` times; :func:`systematic_resample` is ``count = N``)."""
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
