"""Monte Carlo localization (Thrun et al. table 8.2, with KLD-sampling, table 8.4).

One update, after the robot has moved ``update_distance`` or turned ``update_angle``:

1. **resample + predict** (KLD-sampling): particles are drawn from the previous weighted set by
   low-variance (systematic) resampling, taken in a random order so that every prefix of the
   draws is an even sample of the set, and each is moved by the odometry increment with the
   filter's motion model (:func:`slam.kernels.motion.sample_motion`, ``filter.motion_alphas``).
   Drawing stops at Fox's bound for the number of ``(x, y, θ)`` bins the moved particles occupy
   (:mod:`slam.localize.kld`).
2. **weight**: ``w ∝ exp(log p(z | x) / T)``, the likelihood-field beam model over the scan's
   returns (:mod:`slam.localize.sensor`), tempered by ``localize.temperature`` because
   neighbouring beams are not independent.
3. **estimate**: the weighted mean pose (circular mean of the headings) and the weighted
   covariance of the particles.

All random numbers come from the caller's generator, drawn here in Python; the kernels only
compute, so a seed fixes the result whatever the number of threads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.geometry import wrap_angle
from slam.kernels.motion import sample_motion
from slam.kernels.resample import systematic_draws
from slam.localize.kernels import particle_loglik
from slam.localize.kld import KldCounter
from slam.localize.maps import LikelihoodMap

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class MotionModel:
    """The odometry motion model's parameters (``filter.motion_alphas``, ``filter.motion_floor``)."""

    alphas: F64
    floor: F64


def weighted_mean_pose(poses: F64, weights: F64) -> tuple[F64, F64]:
    """Weighted mean ``(3,)`` (circular in θ) and covariance ``(3, 3)`` of ``poses``."""
    mean = np.empty(3)
    mean[:2] = weights @ poses[:, :2]
    mean[2] = np.arctan2(weights @ np.sin(poses[:, 2]), weights @ np.cos(poses[:, 2]))
    delta = poses - mean
    delta[:, 2] = wrap_angle(delta[:, 2])
    cov = (delta * weights[:, None]).T @ delta
    return mean, cov


class ParticleSet:
    """The particles, their weights and the last update's likelihoods; they are weighed on the
    map's wall-surface field ``subdivision`` times finer than the map
    (:meth:`~slam.localize.maps.LikelihoodMap.surface_view`)."""

    def __init__(
        self,
        lmap: LikelihoodMap,
        motion: MotionModel,
        kld: KldCounter,
        temperature: float,
        rng: np.random.Generator,
        subdivision: int = 1,
    ) -> None:
        self.map = lmap
        self.view = lmap.surface_view(subdivision)
        self.motion = motion
        self.kld = kld
        self.temperature = float(temperature)
        self.rng = rng
        self.poses = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self.loglik = np.zeros(0)
        self._fresh = True  # no weights yet: the next predict moves every particle as it is

    def __len__(self) -> int:
        return int(self.poses.shape[0])

    # -- initialisation
    def set_particles(self, poses: F64) -> None:
        """Start from ``poses`` with equal weights."""
        self.poses = np.ascontiguousarray(poses, dtype=np.float64)
        self.poses[:, 2] = wrap_angle(self.poses[:, 2])
        self.weights = np.full(len(self), 1.0 / len(self))
        self.loglik = np.zeros(len(self))
        self._fresh = True

    def set_gaussian(self, pose: F64, sigma_xy: float, sigma_theta: float, count: int) -> None:
        """Start from ``count`` particles drawn around ``pose``."""
        noise = self.rng.standard_normal((count, 3)) * np.array([sigma_xy, sigma_xy, sigma_theta])
        self.set_particles(np.asarray(pose, dtype=np.float64)[None, :] + noise)

    # -- the filter
    def predict(self, increment: F64) -> None:
        """Resample (low variance, KLD-sized) and move the particles by ``increment``.

        Right after :meth:`set_particles` every particle is moved as it is (its weights are
        equal: resampling would only lose particles).
        """
        increment = np.asarray(increment, dtype=np.float64)
        alphas, floor = self.motion.alphas, self.motion.floor
        if self._fresh:
            noise = self.rng.standard_normal((len(self), 3))
            self.poses = sample_motion(self.poses, increment, noise, alphas, floor)
            self._fresh = False
            return
        n_max = self.kld.n_max
        order = self.rng.permutation(n_max)
        picks = systematic_draws(self.weights, n_max, float(self.rng.random()))[order]
        self.kld.reset()
        moved = np.empty((0, 3))
        kept = -1
        chunk = min(n_max, max(2 * len(self), self.kld.n_min))
        while kept < 0:
            start = moved.shape[0]
            stop = min(n_max, start + chunk)
            noise = self.rng.standard_normal((stop - start, 3))
            part = sample_motion(self.poses[picks[start:stop]], increment, noise, alphas, floor)
            moved = np.concatenate([moved, part]) if start else part
            kept = self.kld.feed(moved, start)
            chunk *= 2
        self.poses = np.ascontiguousarray(moved[:kept])

    def likelihood(self, ex: F64, ey: F64, table: tuple[F64, float]) -> F64:
        """``log p(z | x)`` of the returns ``(ex, ey)`` (robot frame) at every particle."""
        return self.likelihood_at(self.poses, ex, ey, table)

    def inject(self, pose: F64, cov: F64, share: float) -> int:
        """Replace ``ceil(share·n)`` particles (the last ones: the draws are in random order) by
        draws from ``N(pose, cov)``; return how many."""
        n = len(self)
        count = min(n, int(np.ceil(share * n)))
        if count == 0:
            return 0
        chol = np.linalg.cholesky(cov + np.eye(3) * 1e-12)
        draws = (
            np.asarray(pose, np.float64)[None, :] + self.rng.standard_normal((count, 3)) @ chol.T
        )
        draws[:, 2] = wrap_angle(draws[:, 2])
        self.poses[n - count :] = draws
        return count

    def likelihood_at(self, poses: F64, ex: F64, ey: F64, table: tuple[F64, float]) -> F64:
        """``log p(z | x)`` of the returns at the given ``poses`` (not the particles)."""
        out = np.empty(poses.shape[0])
        particle_loglik(
            self.view, np.ascontiguousarray(poses, dtype=np.float64), ex, ey, table[0],
            table[1], out,
        )  # fmt: skip
        return out

    def weigh(self, ex: F64, ey: F64, table: tuple[F64, float]) -> F64:
        """Weight the particles by the scan; return their log-likelihoods."""
        self.loglik = self.likelihood(ex, ey, table)
        logw = self.loglik / self.temperature
        w = np.exp(logw - logw.max())
        self.weights = w / w.sum()
        return self.loglik

    def estimate(self) -> tuple[F64, F64]:
        """Weighted mean pose and covariance."""
        return weighted_mean_pose(self.poses, self.weights)
