"""Loop closing: a pose graph over the filter's final trajectory, with scan-matched loop edges.

A Rao-Blackwellised filter closes a loop only if one of its particles happens to have drifted
the right way when the robot comes back; on long corridors that is a gamble. This stage makes it
deterministic, the way graph-based SLAM does, without changing what the filter did:

1. **Nodes** are the filter's update poses (the best particle's ancestry).
2. **Sequential edges** join consecutive nodes with the filter's own relative motion, trusted to
   ``seq_sigma_xy + seq_sigma_rel · distance`` (and likewise in rotation).
3. **Loop edges**: for every ``stride``-th node ``i``, the nearest earlier node ``j`` that is
   within ``radius`` in space but at least ``min_path`` back along the path is a candidate. Scan
   ``i`` is registered against a submap built from the earlier nodes around ``j`` — first a
   brute-force correlative search (±``search_xy``, ±``search_th``: a basin far wider than the
   filter's matcher), then Levenberg-Marquardt — and the match is accepted only if at least
   ``min_fit`` of its beams land within ``fit_distance`` of the submap's surfaces. The accepted
   pose of ``i`` relative to ``j`` becomes an edge with a Cauchy robust kernel.
4. **Optimisation**: Gauss-Newton on ``Σ ρ(eᵀΩe)`` (:mod:`slam.kernels.graph`), node 0 fixed;
   detection and optimisation run ``rounds`` times (a closed loop brings further ones in reach).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.config import Config, LoopConfig
from slam.geometry import relative, wrap_angle
from slam.kernels.field import match_one
from slam.kernels.graph import correlative_search, fit_counts, linearize, solve_system
from slam.mapping import ParticleMaps, likelihood_tables

F64 = NDArray[np.float64]


@dataclass
class LoopResult:
    """The optimised node poses and what the stage did."""

    poses: F64
    """``(U, 3)`` optimised poses of the nodes."""
    candidates: int
    """Loop candidates examined (over all rounds)."""
    accepted: int
    """Loop edges accepted (in the last round's graph)."""
    correction_max_m: float
    """Largest change of a node's position (m)."""


def _submap(seq, steps: NDArray[np.int64], poses: F64, members: NDArray[np.int64], config: Config):
    rc = config.rbpf
    center = poses[members, :2].mean(axis=0)
    maps = ParticleMaps(
        1,
        rc.resolution or config.map.resolution,
        rc.dmax,
        tile=rc.tile,
        center=(float(center[0]), float(center[1])),
        size_m=20.0,
        grow_margin_m=5.0,
        capacity=256,
    )
    for m in members:
        hx, hy = seq.hits(int(steps[m]), rc.insert_beams)
        if hx.size == 0:
            continue
        reach = float(np.sqrt((hx * hx + hy * hy).max())) + rc.dmax + 1.0
        p = poses[m]
        maps.ensure_contains(p[0] - reach, p[1] - reach, p[0] + reach, p[1] + reach)
        maps.insert(np.ascontiguousarray(p[None, :]), hx, hy, hx, hy, rc.skip_insert_below)
    return maps


def _candidates(poses: F64, path: F64, lc: LoopConfig) -> list[tuple[int, int]]:
    out = []
    for i in range(0, poses.shape[0], lc.stride):
        earlier = np.flatnonzero(path[i] - path[: i + 1] >= lc.min_path)
        if earlier.size == 0:
            continue
        dist = np.hypot(*(poses[earlier, :2] - poses[i, :2]).T)
        k = int(np.argmin(dist))
        if dist[k] <= lc.radius:
            out.append((int(earlier[k]), i))
    return out


def _detect(seq, steps, poses, path, config: Config) -> tuple[list, int]:
    """Loop edges ``(j, i, z)`` found by registering node ``i``'s scan against a submap at ``j``."""
    lc, rc = config.loops, config.rbpf
    luts, step_inv = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    coarse, coarse_inv = likelihood_tables(
        np.array([lc.search_sigma]), rc.z_hit, rc.z_rand, rc.dmax
    )
    edges = []
    candidates = _candidates(poses, path, lc)
    for j, i in candidates:
        near = np.flatnonzero(
            (path[i] - path >= lc.min_path / 2)
            & (np.hypot(*(poses[:, :2] - poses[j, :2]).T) <= lc.submap_radius)
        )
        if near.size == 0:
            continue
        near = near[np.argsort(np.abs(near - j))][: lc.submap_nodes]
        maps = _submap(seq, steps, poses, np.sort(near), config)
        ex, ey = seq.hits(int(steps[i]), rc.match_beams)
        if ex.size < lc.min_beams:
            continue
        args = (maps.plane, maps.tables[0], maps.shift, float(maps.origin[0]),
                float(maps.origin[1]), 1.0 / maps.resolution)  # fmt: skip
        thin = slice(None, None, max(1, ex.size // 60))
        start = correlative_search(
            *args, poses[i], ex[thin].copy(), ey[thin].copy(), coarse[0, 0], coarse_inv,
            lc.search_xy, lc.search_step, lc.search_th, lc.search_th_step,
        )  # fmt: skip
        refined, _, _ = match_one(
            *args, start[:3].copy(), ex, ey, luts, step_inv, rc.max_iterations * 2,
            rc.tolerance, 1,
        )  # fmt: skip
        _, close = fit_counts(*args, refined, ex, ey, lc.fit_distance)
        if close < lc.min_fit * ex.size or close < lc.min_beams:
            continue
        edges.append((j, i, relative(poses[j], refined)))
    return edges, len(candidates)


def _information(sigma_xy: float, sigma_th: float) -> F64:
    return np.diag([1.0 / sigma_xy**2, 1.0 / sigma_xy**2, 1.0 / sigma_th**2])


def optimize(poses: F64, edges: list, lc: LoopConfig) -> F64:
    """Gauss-Newton on the chain of ``poses`` plus loop ``edges``; node 0 stays fixed."""
    n = poses.shape[0]
    seq_z = relative(poses[:-1], poses[1:])
    dist = np.hypot(seq_z[:, 0], seq_z[:, 1])
    ei = [np.arange(n - 1)]
    ej = [np.arange(1, n)]
    meas = [seq_z]
    info = np.concatenate(
        [
            np.stack(
                [
                    _information(
                        lc.seq_sigma_xy + lc.seq_sigma_rel * d,
                        lc.seq_sigma_th + lc.seq_sigma_rel * abs(t),
                    )
                    for d, t in zip(dist, seq_z[:, 2], strict=True)
                ]
            ).reshape(-1, 3, 3),
            np.tile(_information(lc.sigma_xy, lc.sigma_th), (len(edges), 1, 1)),
        ]
    )
    robust = np.concatenate([np.zeros(n - 1), np.full(len(edges), lc.robust)])
    if edges:
        ei.append(np.array([e[0] for e in edges]))
        ej.append(np.array([e[1] for e in edges]))
        meas.append(np.stack([e[2] for e in edges]))
    edge_i = np.concatenate(ei).astype(np.int64)
    edge_j = np.concatenate(ej).astype(np.int64)
    z = np.ascontiguousarray(np.concatenate(meas))
    x = poses.copy()
    diag = np.zeros((n, 3, 3))
    band = np.zeros((max(n - 1, 1), 3, 3))
    far = np.zeros((edge_i.size, 3, 3))
    grad = np.zeros((n, 3))
    for _ in range(lc.iterations):
        linearize(x, edge_i, edge_j, z, info, robust, diag, band, far, grad)
        diag[0] += np.eye(3) * 1e9  # node 0 fixed
        delta, _ = solve_system(diag, band, far, edge_i, edge_j, -grad, 500, 1e-10)
        x += delta
        x[:, 2] = wrap_angle(x[:, 2])
        if np.abs(delta[:, :2]).max() < 1e-4 and np.abs(delta[:, 2]).max() < 1e-5:
            break
    return x


def close_loops(seq, steps: NDArray[np.int64], poses: F64, config: Config) -> LoopResult:
    """Detect loop closures along ``poses`` (the nodes at scans ``steps``) and optimise."""
    lc = config.loops
    step_len = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    path = np.concatenate([[0.0], np.cumsum(step_len)])
    x = poses.copy()
    examined = 0
    edges: list = []
    for _ in range(lc.rounds):
        edges, count = _detect(seq, steps, x, path, config)
        examined += count
        if not edges:
            break
        x = optimize(poses, edges, lc)
    moved = float(np.hypot(*(x[:, :2] - poses[:, :2]).T).max()) if len(x) else 0.0
    return LoopResult(x, examined, len(edges), moved)
