"""KLD-sampling (Fox 2003): as many particles as the posterior's spread needs.

Fox bounds the number of samples ``n`` for which, with probability ``1 − δ``, the Kullback-Leibler
distance between the sample-based estimate and the true posterior stays below ``ε``, when the
posterior occupies ``k`` bins of a fixed histogram over the state space. With the Wilson-Hilferty
approximation of the chi-square quantile,

    ``n = (k − 1)/(2ε) · (1 − 2/(9(k − 1)) + sqrt(2/(9(k − 1))) · z_{1−δ})³``,

``z_{1−δ}`` the upper ``1 − δ`` quantile of the standard normal. The sampler draws particles one
by one (resampling and predicting each), counts the distinct ``(x, y, θ)`` bins the new
particles fall into, and stops as soon as ``n`` reaches the bound of the bins seen so far:
a concentrated cloud keeps few particles, a spread one many.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from slam.localize.kernels import kld_count

F64 = NDArray[np.float64]


def normal_quantile(p: float) -> float:
    """The ``p`` quantile of the standard normal distribution."""
    return NormalDist().inv_cdf(p)


def kld_bound(k: int, epsilon: float, delta: float) -> float:
    """Fox's bound on the sample count for ``k`` occupied bins (0 for ``k ≤ 1``)."""
    if k <= 1:
        return 0.0
    z = normal_quantile(1.0 - delta)
    a = 2.0 / (9.0 * (k - 1))
    return (k - 1) / (2.0 * epsilon) * (1.0 - a + math.sqrt(a) * z) ** 3


class KldCounter:
    """The bins seen so far of one KLD-sampling pass; feed samples with :meth:`feed`."""

    def __init__(
        self,
        bin_xy: float,
        bin_theta: float,
        epsilon: float,
        delta: float,
        n_min: int,
        n_max: int,
    ) -> None:
        self.bin_xy = float(bin_xy)
        self.bin_theta = float(bin_theta)
        self.epsilon = float(epsilon)
        self.z = normal_quantile(1.0 - delta)
        self.n_min = int(n_min)
        self.n_max = int(n_max)
        size = 1 << max(int(2 * self.n_max).bit_length(), 4)
        self._keys = np.empty((size, 3), dtype=np.int64)
        self._used = np.zeros(size, dtype=np.bool_)
        self._state = np.zeros(1, dtype=np.int64)

    def reset(self) -> None:
        """Forget the bins (a new pass)."""
        self._used[:] = False
        self._state[0] = 0

    @property
    def bins(self) -> int:
        """Distinct bins seen in this pass."""
        return int(self._state[0])

    def feed(self, poses: F64, start: int = 0) -> int:
        """Count ``poses[start:]`` (the samples so far are ``poses[:start]``, already fed);
        return the number of samples to keep, or −1 if more are needed."""
        return int(
            kld_count(
                poses,
                start,
                self.bin_xy,
                self.bin_theta,
                self.epsilon,
                self.z,
                self.n_min,
                self.n_max,
                self._keys,
                self._used,
                self._state,
            )  # fmt: skip
        )
