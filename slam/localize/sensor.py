"""The beam model of localization: the likelihood field of Thrun et al. (ch. 6.4) as a mixture.

A return at range ``z`` whose endpoint lies ``d`` from the nearest wall has the density

    ``p(z) = z_hit · N(d; 0, σ²) + z_rand / z_range``      (per metre of range),

and a reading with no return (at or beyond ``range_max``) has the probability mass ``z_max``.
The three weights sum to 1, and ``N`` is the normalised Gaussian ``exp(−d²/2σ²)/(σ√(2π))``: along
a beam that meets a wall head-on at ``z*`` the endpoint's distance is ``d = |z − z*|``, so the
density integrates to ``z_hit + z_rand`` over ``[0, z_range]`` and the mixture, with the point
mass, to 1 (checked by ``tests/test_localize_units.py``). Readings without a return carry the same
``z_max`` at every pose, so they do not change the weights; the filters use the returns only.

The functions of ``d`` are tabulated (:meth:`BeamModel.log_table`) so the kernels do one table
lookup per beam instead of an ``exp`` and a ``log``. For the histogram filter, whose states are
cells and heading bins, :meth:`BeamModel.widened_sigma` widens the Gaussian by half a cell and
by half a bin's sweep at the beam's range (the pose may lie anywhere within its state).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

TABLE_SIZE = 1024
"""Samples of a tabulated function of the distance."""


@dataclass(frozen=True)
class BeamModel:
    """Mixture weights, the Gaussian's width and the sensor's range."""

    z_hit: float
    z_rand: float
    z_max: float
    sigma: float
    """Standard deviation of the hit term (m)."""
    z_range: float
    """Longest return of the sensor (m): the uniform term's support ``[0, z_range]``."""

    def log_density(self, d: F64, sigma: float | None = None) -> F64:
        """``log(z_hit·N(d; 0, σ²) + z_rand/z_range)`` (``σ`` defaults to :attr:`sigma`)."""
        s = self.sigma if sigma is None else sigma
        d = np.asarray(d, dtype=np.float64)
        gauss = np.exp(-0.5 * (d / s) ** 2) / (s * math.sqrt(2.0 * math.pi))
        return np.log(self.z_hit * gauss + self.z_rand / self.z_range)

    def log_table(self, d_max: float, size: int = TABLE_SIZE) -> tuple[F64, float]:
        """:meth:`log_density` at ``d = 0 … d_max`` (``size`` samples) and ``1/step``."""
        d = np.linspace(0.0, d_max, size)
        return np.ascontiguousarray(self.log_density(d)), (size - 1) / d_max

    def peak_log_density(self) -> float:
        """The largest per-beam log-likelihood (an endpoint exactly on a wall)."""
        return float(self.log_density(np.zeros(1))[0])

    def widened_sigma(self, ranges: F64, cell: float, bin_angle: float) -> F64:
        """Gaussian width for states of ``cell`` metres and ``bin_angle`` radians: the pose may
        lie anywhere in its cell and bin, so a return at range ``r`` may land half a cell and
        half a bin's sweep ``r·bin_angle/2`` away: ``σ_b² = σ² + (cell/2)² + (r·bin_angle/2)²``."""
        ranges = np.asarray(ranges, dtype=np.float64)
        return np.sqrt(self.sigma**2 + (cell / 2) ** 2 + (ranges * bin_angle / 2) ** 2)
