"""Issue 13's verification and proposal rules on synthetic data: the global closure's fit over the
submap's known cells (:func:`slam.backend.global_loops._fitting`) and the filter's rotated retry of a
failed match (:meth:`slam.particle_filter.RbpfFilter._retry`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from slam.backend.global_loops import _fitting
from slam.config import Config
from slam.graph import empty_submap
from slam.kernels.graph import fit_counts
from slam.mapping import MatchResult
from slam.particle_filter import RbpfFilter


def _walls(x0: float, x1: float, y1: float = 6.0) -> np.ndarray:
    """Points of the walls of a 10 m x 6 m room that lie in ``x0 <= x < x1``, ``y <= y1``."""
    t = np.linspace(0.0, 1.0, 400)
    pts = np.vstack([np.c_[t * 10, 0 * t], np.c_[t * 10, 0 * t + 6], np.c_[0 * t, t * 6],
                     np.c_[0 * t + 10, t * 6]])  # fmt: skip
    return pts[(pts[:, 0] >= x0) & (pts[:, 0] < x1) & (pts[:, 1] <= y1)]


def _submap(points: np.ndarray, config: Config):
    maps = empty_submap(np.zeros(3), config)
    maps.ensure_contains(-2.0, -2.0, 12.0, 8.0)
    hx, hy = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
    maps.insert(np.zeros((1, 3)), hx, hy, hx, hy, 0.0)
    return maps.field(0)


def _scan(points: np.ndarray, n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    pick = np.linspace(0, len(points) - 1, n).round().astype(int)
    return np.ascontiguousarray(points[pick, 0]), np.ascontiguousarray(points[pick, 1])


def test_fit_counts_only_the_beams_on_the_submap():
    """A scan of the whole room against a submap of its left 30 %: most beams fall where the
    submap never saw, but those on it lie on its surfaces; shifted by 0.25 m, they do not."""
    config = Config()
    view = _submap(_walls(0.0, 3.0), config)
    ex, ey = _scan(_walls(0.0, 10.0))
    known, close = fit_counts(view, np.zeros(3), ex, ey, config.loops.fit_distance)
    assert close < config.backend.min_fit * ex.size  # the all-beams rule would refuse it
    assert close >= 0.9 * known and close >= config.backend.min_overlap * ex.size
    assert _fitting(view, np.zeros(3), ex, ey, config) is not None
    assert _fitting(view, np.array([0.25, 0.25, 0.0]), ex, ey, config) is None
    assert _fitting(view, np.array([0.0, 0.0, 0.1]), ex, ey, config) is None


def test_fit_needs_overlap():
    """Beams on the submap that are a small share of the scan do not make a closure."""
    config = Config()
    view = _submap(_walls(0.0, 0.5, 3.0), config)
    ex, ey = _scan(_walls(0.0, 10.0))
    known, close = fit_counts(view, np.zeros(3), ex, ey, config.loops.fit_distance)
    assert close >= config.backend.min_fit * known
    assert close < config.backend.min_overlap * ex.size
    assert _fitting(view, np.zeros(3), ex, ey, config) is None


class _Maps:
    """A stand-in for the particle maps: a match converges to the true heading 0 only from a
    start within 0.1 rad of it, else it stays where it started, with a worse likelihood."""

    def __init__(self) -> None:
        self.calls = 0

    def match(self, poses, ex, ey, luts, iterations, tolerance, min_inliers, stride, vacancy=None):
        assert vacancy is None  # the filter made below keeps no vacancy grid
        self.calls += 1
        out = poses.copy()
        near = np.abs(poses[:, 2]) < 0.1
        out[near, 2] = 0.0
        loglik = -ex.size * (0.05 + np.abs(out[:, 2]))
        n = poses.shape[0]
        return MatchResult(out, loglik, np.ones(n), np.tile(np.eye(3), (n, 1, 1)))


def _filter(ratio: float) -> RbpfFilter:
    f = RbpfFilter.__new__(RbpfFilter)
    config = Config()
    f.config = dataclasses.replace(config, rbpf=dataclasses.replace(config.rbpf, retry_ratio=ratio))
    f.maps, f.luts, f.retries, f.vacancy = _Maps(), None, 0, None
    f.recent_loglik = [-0.05] * 10
    return f


def test_retry_recovers_a_rotation_beyond_the_basin():
    """Predicted 0.3 rad off (outside the stand-in's 0.1 rad basin): the first match fails, the
    update is retried from ±0.15 and ±0.3 rad and every particle lands on the true heading."""
    f = _filter(3.0)
    predicted = np.array([[0.0, 0.0, 0.3], [0.0, 0.0, 0.32], [0.0, 0.0, -0.28]])
    hits = (np.ones(100), np.zeros(100))
    first = f.maps.match(predicted, *hits, None, 5, 1e-3, 0.3, 1)
    got = f._retry(predicted, hits, first)
    assert f.retries == 1 and f.maps.calls == 1 + 4
    np.testing.assert_allclose(got.poses[:, 2], 0.0)
    np.testing.assert_allclose(f.recent_loglik[-1], -0.05)
    assert len(f.recent_loglik) == 11


def test_no_retry_for_a_good_match_or_when_disabled():
    """A match as good as the recent ones is kept as it is (no extra matching); ratio 0 never
    retries."""
    for ratio, predicted in (
        (3.0, np.array([[0.0, 0.0, 0.05]])),
        (0.0, np.array([[0.0, 0.0, 0.3]])),
    ):
        f = _filter(ratio)
        hits = (np.ones(100), np.zeros(100))
        first = f.maps.match(predicted, *hits, None, 5, 1e-3, 0.3, 1)
        kept = first.poses.copy()
        got = f._retry(predicted, hits, first)
        assert f.retries == 0 and f.maps.calls == 1
        np.testing.assert_array_equal(got.poses, kept)
