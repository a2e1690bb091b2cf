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
lookup per beam instead of an ``exp`` and a ``log``. :meth:`BeamModel.widened_tables` gives one
table per beam for the histogram filter, whose states are cells and heading bins: there the
pose may lie anywhere within the cell and bin, and the Gaussian is widened by half a cell and by
half a bin's sweep at the beam's range.
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

    def widened_tables(
        self, ranges: F64, cell: float, bin_angle: float, size: int = 128
    ) -> tuple[F64, F64]:
        """One table per beam for states of ``cell`` metres and ``bin_angle`` radians.

        Beam ``b`` at range ``r_b`` uses ``σ_b² = σ² + (cell/2)² + (r_b·bin_angle/2)²``; its table
        spans ``d = 0 … 4σ_b``. Returns ``tables (B, size)`` and ``1/step (B,)``.
        """
        ranges = np.asarray(ranges, dtype=np.float64)
        sig = np.sqrt(self.sigma**2 + (cell / 2) ** 2 + (ranges * bin_angle / 2) ** 2)
        span = 4.0 * sig
        d = np.linspace(0.0, 1.0, size)[None, :] * span[:, None]
        gauss = np.exp(-0.5 * (d / sig[:, None]) ** 2) / (sig[:, None] * math.sqrt(2 * math.pi))
        tables = np.log(self.z_hit * gauss + self.z_rand / self.z_range)
        return np.ascontiguousarray(tables), (size - 1) / span
