"""Global localization: the exact histogram filter over (x, y, θ) cells of a saved map.

This is the grid world's Bayes filter (:mod:`slam.discrete`), for real: the states are the cells
of the map at a coarse resolution (``localize.global_resolution``, rounded to a whole number of the map's cells)
times ``localize.global_headings`` heading bins, but only the cells the robot can be in — at
least ``global_min_free`` of their map cells observed free. Every state's probability is computed,
none is sampled, so a symmetric building keeps its symmetric modes until a scan tells them apart.

* **predict** with the odometry increment ``u = (dx, dy, dθ)`` since the last step: the heading
  bins shift by ``dθ``, then every heading layer shifts by its own displacement
  ``R(θ_h − dθ/2)·(dx, dy)``. The noise of the odometry model (``filter.motion_alphas``) plus the
  extent of a state (a uniform spread over one cell and one bin: variance ``cell²/12``,
  ``bin²/12``, and ``(d·bin)²/12`` of lateral travel) become weights over integer shifts, each the
  Gaussian's mass over one cell (:func:`cell_weights`). Mass that lands outside the states is
  the robot driving into a wall: it is dropped, and the belief renormalised.
* **update** with the scan's returns: ``bel(x) ∝ p(z | x)^{1/T} · bel⁻(x)``, ``p`` the beam model
  of :mod:`slam.localize.sensor` with its Gaussian widened for the state's extent.
* **mode**: the states within ``global_mode_radius`` and ``global_mode_angle`` of the most
  probable one; global localization ends when they hold ``global_mode_share`` of the mass.
* **kidnapping**: every prediction also spreads ``localize.kidnap_prior`` of the mass evenly
  over all states (the robot may have been carried anywhere), so no state's probability ever
  becomes exactly 0: a place the robot left the map from, or a true pose an unlucky scan
  ruled out, can always come back.

The kernels (:mod:`slam.localize.kernels`) loop over free cells only; the belief is stored dense
(``(H, R, C)``, zero outside the states) so the prediction can gather from neighbours.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.budget import DEFAULT_MEMORY_SHARE, check_memory
from slam.config import LocalizeConfig
from slam.discrete.filter import normalize
from slam.errors import DataError
from slam.kernels.resample import systematic_draws
from slam.localize.kernels import (
    apply_likelihood,
    heading_mix,
    shift_columns,
    shift_rows,
    state_loglik,
)
from slam.localize.maps import LikelihoodMap
from slam.localize.mcl import MotionModel
from slam.localize.sensor import BeamModel

F64 = NDArray[np.float64]

LEVELS = 9
"""Gaussian widths of the histogram filter's likelihood grids: ``σ_0·√2^l``, ``σ_0`` to
``16·σ_0``."""

QUANTUM = 1.0 / 2048.0
"""The likelihood grids hold ``log p`` in steps of this (int16: half the memory of float32,
and far finer than the differences between states; the widest span, ``log p`` on a wall over
``log p`` far from one at the narrowest width, is about 8.3, 17000 steps)."""

_ERF = np.frompyfunc(math.erf, 1, 1)


def _phi(x: F64) -> F64:
    """Standard normal cumulative distribution."""
    return 0.5 * (1.0 + _ERF(np.asarray(x) / math.sqrt(2.0)).astype(np.float64))


def cell_weights(mean: F64, sigma: F64) -> tuple[NDArray[np.int64], F64]:
    """Mass of ``N(mean_h, sigma_h²)`` over the unit cells ``[o − ½, o + ½)``, for every row ``h``.

    Returns the first integer offset of each row and the weights ``(H, K)`` (rows sum to 1; rows
    shorter than ``K`` padded with zeros).
    """
    mean = np.asarray(mean, dtype=np.float64).reshape(-1)
    sigma = np.maximum(np.asarray(sigma, dtype=np.float64).reshape(-1), 1e-6)
    first = np.floor(mean - 4.0 * sigma + 0.5).astype(np.int64)
    last = np.ceil(mean + 4.0 * sigma - 0.5).astype(np.int64)
    width = int((last - first).max()) + 1
    offsets = first[:, None] + np.arange(width)[None, :]
    upper = _phi((offsets + 0.5 - mean[:, None]) / sigma[:, None])
    lower = _phi((offsets - 0.5 - mean[:, None]) / sigma[:, None])
    weights = np.where(offsets <= last[:, None], upper - lower, 0.0)
    weights /= weights.sum(axis=1, keepdims=True)
    return first, np.ascontiguousarray(weights)


def histogram_memory(headings: int, rows: int, cols: int, factor: int) -> float:
    """Bytes of the histogram filter's arrays: three float64 beliefs (the belief and two
    buffers of the prediction) and the int16 likelihood grids (:data:`LEVELS` widths, every
    phase of the decimation: ``LEVELS`` values per map cell)."""
    return 3.0 * headings * rows * cols * 8 + LEVELS * factor * factor * rows * cols * 2


@dataclass(frozen=True)
class Mode:
    """The most probable state and the mass around it."""

    share: float
    """Probability held by the states within the mode's radius and angle."""
    pose: F64
    """``(3,)`` centre of the most probable state."""
    heading: int
    row: int
    col: int


class PoseHistogram:
    """The belief over ``(heading, row, column)`` states of a coarse grid of the map."""

    def __init__(
        self,
        lmap: LikelihoodMap,
        config: LocalizeConfig,
        motion: MotionModel,
        memory_share: float = DEFAULT_MEMORY_SHARE,
    ) -> None:
        # the nearest whole number of map cells (a 0.1 m map: 0.3 m for the default 0.25)
        self.factor = max(1, int(math.floor(config.global_resolution / lmap.resolution + 0.5)))
        self.map = lmap
        self.config = config
        self.motion = motion
        self.resolution = self.factor * lmap.resolution
        self.headings = int(config.global_headings)
        self.bin = 2.0 * math.pi / self.headings
        self.theta = -math.pi + self.bin * np.arange(self.headings)
        h, w = lmap.shape
        rows, cols = -(-h // self.factor), -(-w // self.factor)
        needed = histogram_memory(self.headings, rows, cols, self.factor)
        check_memory(
            needed,
            f"map {w}×{h} cells: the global histogram filter ({self.headings} headings × "
            f"{cols}×{rows} cells of {self.resolution:g} m)",
            "use a coarser localize.global_resolution or fewer localize.global_headings",
            share=memory_share,
            setting="checks.max_memory_share",
        )
        padded = np.zeros((rows * self.factor, cols * self.factor), dtype=np.float64)
        padded[:h, :w] = lmap.free
        share = padded.reshape(rows, self.factor, cols, self.factor).mean(axis=(1, 3))
        self.states = share >= config.global_min_free
        if not self.states.any():
            raise DataError("map: no free cell at the global filter's resolution")
        free_r, free_c = np.nonzero(self.states)
        self.free_r = free_r.astype(np.int64)
        self.free_c = free_c.astype(np.int64)
        self.cell_x = lmap.origin[0] + (self.free_c + 0.5) * self.resolution
        self.cell_y = lmap.origin[1] + (self.free_r + 0.5) * self.resolution
        self.belief = np.zeros((self.headings, rows, cols))
        self._spare = np.zeros_like(self.belief)
        self._dense = np.zeros_like(self.belief)
        self._reach: dict[tuple[int, int], tuple[NDArray, NDArray]] = {}
        self._grids: dict[float, tuple[NDArray[np.float32], F64, F64]] = {}
        self.steps = 0
        self.reset()

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(headings, rows, columns)`` of the belief."""
        return self.belief.shape  # type: ignore[return-value]

    @property
    def state_count(self) -> int:
        """Number of states (free cells × headings)."""
        return int(self.free_r.shape[0]) * self.headings

    def memory_bytes(self) -> int:
        """Bytes held by the belief, its spare buffer and the state lists."""
        grids = sum(g[0].nbytes for g in self._grids.values())
        return int(
            self.belief.nbytes + self._spare.nbytes + self._dense.nbytes + self.states.nbytes
            + 2 * self.free_r.nbytes + 2 * self.cell_x.nbytes + grids
        )  # fmt: skip

    def reset(self) -> None:
        """Uniform belief over every state."""
        self.belief[:] = 0.0
        self.belief[:, self.free_r, self.free_c] = 1.0 / self.state_count
        self.steps = 0

    def reset_around(
        self, pose: F64, sigma_xy: float, sigma_theta: float, elsewhere: float
    ) -> None:
        """A belief that the robot is still near ``pose`` (a Gaussian of ``sigma_xy``,
        ``sigma_theta`` over the states) with probability ``1 − elsewhere``, and anywhere else
        (uniform over every state) with probability ``elsewhere``: the prior of a recovery, where
        being carried away is possible but rarer than a poorly mapped stretch."""
        dx = self.cell_x - pose[0]
        dy = self.cell_y - pose[1]
        near = np.exp(-0.5 * (dx**2 + dy**2) / sigma_xy**2)
        turn = np.remainder(self.theta - pose[2] + math.pi, 2 * math.pi) - math.pi
        heading = np.exp(-0.5 * (turn / sigma_theta) ** 2)
        local = heading[:, None] * near[None, :]
        total = float(local.sum())
        self.reset()
        if total > 0 and elsewhere < 1.0:
            self.belief[:, self.free_r, self.free_c] *= elsewhere
            self.belief[:, self.free_r, self.free_c] += (1.0 - elsewhere) * local / total

    # -- predict
    def predict(self, increment: F64) -> None:
        """Move the belief by the odometry ``increment`` (robot frame) with the motion noise."""
        dx, dy, dth = (float(v) for v in increment)
        d = math.hypot(dx, dy)
        a = abs(dth)
        alphas, floor = self.motion.alphas, self.motion.floor
        sx = alphas[0] * d + alphas[1] * a + floor[0]
        sy = alphas[2] * d + alphas[1] * a + floor[1]
        st = alphas[3] * a + alphas[4] * d + floor[2]
        # heading: the rotation in bins, its noise and a bin's own extent
        sigma_bins = math.sqrt(st**2 + self.bin**2 / 12.0) / self.bin
        first, weights = cell_weights(np.array([dth / self.bin]), np.array([sigma_bins]))
        heading_mix(self.belief, self.free_r, self.free_c, int(first[0]), weights[0], self._spare)
        # translation: each destination heading's displacement, from the mid-turn heading
        mid = self.theta - dth / 2.0
        wx = np.cos(mid) * dx - np.sin(mid) * dy
        wy = np.sin(mid) * dx + np.cos(mid) * dy
        res = self.resolution
        sigma = math.sqrt(max(sx, sy) ** 2 + (d * self.bin) ** 2 / 12.0 + res**2 / 12.0) / res
        spread = np.full(self.headings, sigma)
        row_first, row_w = cell_weights(wy / res, spread)
        col_first, col_w = cell_weights(wx / res, spread)
        reach_r, reach_c = self._row_reach(row_first, row_w.shape[1])
        shift_columns(self._spare, reach_r, reach_c, col_first, col_w, self._dense)
        anywhere = self.config.kidnap_prior
        shift_rows(
            self._dense, self.free_r, self.free_c, row_first, row_w,
            1.0 - anywhere, anywhere / self.state_count, self.belief,
        )  # fmt: skip
        normalize(self.belief, float(self.belief[:, self.free_r, self.free_c].sum()))

    def _row_reach(self, row_first: NDArray[np.int64], width: int) -> tuple[NDArray, NDArray]:
        """The cells the row pass reads: every state's column, from ``width`` rows starting
        ``row_first`` below it (over all headings)."""
        lo, hi = int(row_first.min()), int(row_first.max()) + width - 1
        key = (lo, hi)
        cached = self._reach.get(key)
        if cached is None:
            rows = self.states.shape[0]
            needed = np.zeros_like(self.states)
            for shift in range(lo, hi + 1):  # source row = state row − shift
                if abs(shift) >= rows:
                    continue
                if shift >= 0:
                    needed[: rows - shift] |= self.states[shift:]
                else:
                    needed[-shift:] |= self.states[: rows + shift]
            r, c = np.nonzero(needed)
            cached = (r.astype(np.int64), c.astype(np.int64))
            if len(self._reach) > 64:
                self._reach.clear()
            self._reach[key] = cached
        return cached

    # -- update
    def level_grids(self, model: BeamModel) -> tuple[NDArray[np.int16], F64, F64]:
        """The beam model's log-likelihood over the map at :data:`LEVELS` Gaussian widths
        (from ``σ_0 = sqrt(σ² + (cell/2)²)`` in steps of √2), each decimated by the coarse
        factor from every phase: ``(grids (L, k, k, R, C) int16, far (L,), sigmas (L,))``, the
        grids holding ``log p − far`` in units of :data:`QUANTUM` (``far`` the value far from
        any wall); cached per sensor range."""
        cached = self._grids.get(model.z_range)
        if cached is not None:
            return cached
        k = self.factor
        h, w = self.map.shape
        rows, cols = -(-h // k), -(-w // k)
        sigma0 = math.sqrt(model.sigma**2 + (self.resolution / 2) ** 2)
        sigmas = sigma0 * np.sqrt(2.0) ** np.arange(LEVELS)
        far = np.array([float(model.log_density(np.array([1e9]), s)[0]) for s in sigmas])
        grids = np.empty((LEVELS, k, k, rows, cols), dtype=np.int16)
        for lv, sigma in enumerate(sigmas):
            fine = np.zeros((rows * k, cols * k), dtype=np.float64)
            above = model.log_density(self.map.distance, float(sigma)) - far[lv]
            fine[:h, :w] = above / QUANTUM
            steps = np.clip(np.round(fine), 0, np.iinfo(np.int16).max).astype(np.int16)
            grids[lv] = steps.reshape(rows, k, cols, k).transpose(1, 3, 0, 2)
        cached = (np.ascontiguousarray(grids), far, sigmas)
        self._grids[model.z_range] = cached
        return cached

    def loglik(self, ex: F64, ey: F64, model: BeamModel) -> F64:
        """``(H, F)`` log-likelihood of the returns at every state (free cell ``f``).

        Beam ``b`` uses the level nearest (in ratio) to its
        :meth:`~slam.localize.sensor.BeamModel.widened_sigma` (the widest for the longest
        returns), looked up at the map cell its endpoint falls in.
        """
        grids, far, sigmas = self.level_grids(model)
        wanted = model.widened_sigma(np.hypot(ex, ey), self.resolution, self.bin)
        steps = np.log(wanted / sigmas[0]) / np.log(np.sqrt(2.0))
        level = np.clip(np.round(steps), 0, LEVELS - 1).astype(np.int64)
        c, s = np.cos(self.theta)[:, None], np.sin(self.theta)[:, None]
        rx = c * ex[None, :] - s * ey[None, :]
        ry = s * ex[None, :] + c * ey[None, :]
        # the coarse cell's centre lies k/2 fine cells from its first fine cell
        inv = 1.0 / self.map.resolution
        offset_c = np.floor(self.factor / 2 + rx * inv).astype(np.int64)
        offset_r = np.floor(self.factor / 2 + ry * inv).astype(np.int64)
        out = np.empty((self.headings, self.free_r.shape[0]))
        state_loglik(grids, far, level, offset_r, offset_c, self.free_r, self.free_c, QUANTUM, out)
        return out

    def update(self, ex: F64, ey: F64, model: BeamModel) -> None:
        """Multiply the belief by the scan's tempered likelihood and renormalise."""
        loglik = self.loglik(ex, ey, model)
        total = apply_likelihood(
            self.belief, self.free_r, self.free_c, loglik, 1.0 / self.config.global_temperature
        )
        normalize(self.belief, total)
        self.steps += 1

    # -- the result
    def posterior(self) -> F64:
        """``(R, C)`` probability of each cell (summed over headings)."""
        return self.belief.sum(axis=0)

    def _window(self, heading: int, row: int, col: int) -> tuple[NDArray, slice, slice, NDArray]:
        radius = self.config.global_mode_radius / self.resolution
        reach = int(math.floor(radius))
        rows, cols = self.states.shape
        r0, r1 = max(row - reach, 0), min(row + reach + 1, rows)
        c0, c1 = max(col - reach, 0), min(col + reach + 1, cols)
        rr, cc = np.mgrid[r0:r1, c0:c1]
        disk = (rr - row) ** 2 + (cc - col) ** 2 <= radius**2 + 1e-9
        spread = int(math.floor(self.config.global_mode_angle / self.bin + 1e-9))
        heads = np.unique((heading + np.arange(-spread, spread + 1)) % self.headings)
        return heads, slice(r0, r1), slice(c0, c1), disk

    def mode(self) -> Mode:
        """The most probable state and the share of the mass around it."""
        best = int(np.argmax(self.belief))
        h, r, c = (int(v) for v in np.unravel_index(best, self.belief.shape))
        heads, rows, cols, disk = self._window(h, r, c)
        share = float(self.belief[heads][:, rows, cols][:, disk].sum())
        pose = np.array([
            self.map.origin[0] + (c + 0.5) * self.resolution,
            self.map.origin[1] + (r + 0.5) * self.resolution,
            self.theta[h],
        ])  # fmt: skip
        return Mode(share, pose, h, r, c)

    def contains(self, mode: Mode, pose: F64) -> bool:
        """Whether ``pose`` lies within the mode's radius and angle."""
        dist = math.hypot(pose[0] - mode.pose[0], pose[1] - mode.pose[1])
        turn = abs(math.remainder(float(pose[2]) - float(mode.pose[2]), 2 * math.pi))
        cfg = self.config
        return dist <= cfg.global_mode_radius + self.resolution and turn <= (
            cfg.global_mode_angle + self.bin
        )

    def sample(self, mode: Mode, count: int, rng: np.random.Generator) -> F64:
        """``count`` poses drawn from the mode's states (by their probability), each uniform
        within its cell and heading bin."""
        heads, rows, cols, disk = self._window(mode.heading, mode.row, mode.col)
        hh, rr, cc = np.meshgrid(
            heads, np.arange(rows.start, rows.stop), np.arange(cols.start, cols.stop), indexing="ij"
        )
        inside = np.broadcast_to(disk, hh.shape)
        hh, rr, cc = hh[inside], rr[inside], cc[inside]
        p = self.belief[hh, rr, cc]
        p = p / p.sum()
        pick = systematic_draws(p, count, float(rng.random()))
        jitter = rng.random((count, 3)) - 0.5
        res = self.resolution
        return np.stack([
            self.map.origin[0] + (cc[pick] + 0.5 + jitter[:, 0]) * res,
            self.map.origin[1] + (rr[pick] + 0.5 + jitter[:, 1]) * res,
            self.theta[hh[pick]] + jitter[:, 2] * self.bin,
        ], axis=1)  # fmt: skip
