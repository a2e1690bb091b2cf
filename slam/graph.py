"""Loop closing: a pose graph over the filter's final trajectory, with scan-matched loop edges.

A Rao-Blackwellised filter closes a loop only if one of its particles happens to have drifted
the right way when the robot comes back; on long corridors that is a gamble. This stage makes it
deterministic, the way graph-based SLAM does, without changing what the filter did:

1. **Nodes** are the filter's update poses (the best particle's ancestry).
2. **Sequential edges** join consecutive nodes with the filter's own relative motion, trusted to
   ``seq_sigma_xy + seq_sigma_rel · distance`` (and likewise in rotation).
3. **Loop edges**: for every ``stride``-th node ``i``, the nearest earlier node ``j`` that is
   within ``radius`` in space but at least ``min_path`` back along the path is a candidate. Scan
   ``i`` is registered against a submap of the nodes within ``submap_path`` of ``j`` along the
   path (a locally consistent stretch; a drifted later visit would blur a map of the whole past)
   — a brute-force correlative search (±``search_xy``, ±``search_th``: a basin far wider than
   the filter's matcher) unless the scan already fits, then Levenberg-Marquardt — and the match
   is accepted only if it stayed inside the searched window, at least ``min_fit`` of its
   beams land within ``fit_distance`` of the submap's surfaces, and the scan moved
   ``unique_shift`` in any direction would fit clearly worse (:func:`unique_fit`: a corridor's
   scan fits as well a metre along it). The accepted pose of ``i`` relative to ``j`` becomes an
   edge with a Cauchy robust kernel.
4. **Optimisation**: Gauss-Newton on ``Σ ρ(eᵀΩe)`` (:mod:`slam.kernels.graph`), node 0 fixed;
   detection and optimisation run ``rounds`` times (a closed loop brings further ones in reach).
5. **Do no harm**: loop edges are about as precise as the filter's own relative poses (a few
   cm); if the optimisation moves no node by ``min_correction`` or more, the filter had already
   closed its loops and its trajectory is kept as it is.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

import numpy as np
from numpy.typing import NDArray

from slam.config import Config, LoopConfig
from slam.geometry import compose, path_along, relative, spread_corrections, wrap_angle
from slam.kernels.field import FieldView, match_one, normal_equations
from slam.kernels.graph import (
    correlative_search,
    fit_counts,
    fits_when_shifted,
    linearize,
    shifted_fit,
    solve_system,
)
from slam.kernels.threads import in_threads, threads
from slam.mapping import ParticleMaps, likelihood_tables
from slam.scans import ScanHits

if TYPE_CHECKING:
    from slam.backend.submaps import SubmapCache

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


def empty_submap(center: F64, config: Config) -> ParticleMaps:
    """A one-particle map around ``center`` (the filter's field settings, ``loops.submap_*``): a
    loop submap, or the local map of laser odometry."""
    rc, lc = config.rbpf, config.loops
    return ParticleMaps(
        1,
        rc.resolution or config.map.resolution,
        rc.dmax,
        tile=rc.tile,
        center=(float(center[0]), float(center[1])),
        size_m=lc.submap_size,
        grow_margin_m=lc.submap_grow_margin,
        capacity=lc.submap_tiles,
    )


def node_hits(seq, steps: NDArray[np.int64], config: Config) -> ScanHits:
    """The hits the submaps are built from: every node's scan thinned to ``rbpf.insert_beams``
    (computed once for all rounds of the stage)."""
    return seq.hit_table(steps, config.rbpf.insert_beams)


def insert_nodes(
    maps: ParticleMaps, table: ScanHits, nodes: NDArray[np.int64], poses: F64, config: Config
) -> None:
    """Insert the scans of ``nodes`` (rows of ``table``, :func:`node_hits`) at their ``poses``
    into the submap ``maps``, in order (:meth:`~slam.mapping.ParticleMaps.insert_scans`)."""
    rc = config.rbpf
    hits, offsets, reach = table.take(nodes)
    maps.insert_scans(poses[nodes], hits, offsets, reach + rc.dmax + 1.0, rc.skip_insert_below)


def _candidates(poses: F64, path: F64, lc: LoopConfig) -> list[tuple[int, int]]:
    """``(j, i)`` for every ``lc.stride``-th node ``i`` whose nearest node ``j`` among those at
    least ``lc.min_path`` behind it along ``path`` lies within ``lc.radius`` (the lowest index
    of equally near ones, as :func:`numpy.argmin` takes).

    The nodes the path has left far enough behind go into cells a little wider than the radius
    as it leaves them, and a node looks at its own cell and the eight around it, where every
    node within the radius lies: the pairs of comparing it with every earlier node, in time
    that grows with the nodes nearby instead of all of them (17,000 nodes along mit-killian's
    path: 1.03 → 0.07 s a call, a call a round).
    """
    if not (np.isfinite(poses[:, :2]).all() and np.isfinite(path).all()):
        return candidates_every_node(poses, path, lc)  # no cell for a pose that is not a number
    cell = lc.radius * 1.01  # wider than the radius, whatever the rounding of the division
    grid: dict[tuple[int, int], list[int]] = {}
    behind = 0  # nodes [0, behind) are at least min_path behind node i along the path
    out = []
    for i in range(0, poses.shape[0], lc.stride):
        lo, hi = behind, i + 1  # the same test as before, on a path that never decreases
        while lo < hi:
            mid = (lo + hi) // 2
            if path[i] - path[mid] >= lc.min_path:
                lo = mid + 1
            else:
                hi = mid
        for k in range(behind, lo):
            key = (int(np.floor(poses[k, 0] / cell)), int(np.floor(poses[k, 1] / cell)))
            grid.setdefault(key, []).append(k)
        behind = lo
        cx, cy = int(np.floor(poses[i, 0] / cell)), int(np.floor(poses[i, 1] / cell))
        near = [
            k for dx in (-1, 0, 1) for dy in (-1, 0, 1) for k in grid.get((cx + dx, cy + dy), ())
        ]
        if not near:
            continue
        earlier = np.array(sorted(near))
        dist = np.hypot(*(poses[earlier, :2] - poses[i, :2]).T)
        k = int(np.argmin(dist))
        if dist[k] <= lc.radius:
            out.append((int(earlier[k]), i))
    return out


def candidates_every_node(poses: F64, path: F64, lc: LoopConfig) -> list[tuple[int, int]]:
    """:func:`_candidates` by comparing each keyframe with every earlier node: the rule itself,
    for poses that are not all finite (no cell holds them) and for the tests."""
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


def _submap_window(path: F64, j: int, i: int, lc: LoopConfig) -> tuple[int, int]:
    """Nodes ``[lo, hi)`` of candidate ``(j, i)``'s submap: within ``submap_path`` of ``j`` along
    the path and at least ``min_path / 2`` behind ``i``."""
    lo = int(np.searchsorted(path, path[j] - lc.submap_path))
    hi = int(
        np.searchsorted(path, min(path[j] + lc.submap_path, path[i] - lc.min_path / 2), "right")
    )
    return lo, hi


def window_chunks(windows: list[tuple[int, int]], parts: int) -> list[tuple[int, int]]:
    """``[a, b)`` ranges of about equal length that cover ``windows`` in order, cut only where the
    window changes, so that consecutive candidates sharing a submap stay in one range."""
    n = len(windows)
    cuts = [0]
    for p in range(1, parts):
        k = max(cuts[-1], (n * p) // parts)
        while 0 < k < n and windows[k] == windows[k - 1]:
            k += 1
        if cuts[-1] < k < n:
            cuts.append(k)
    cuts.append(n)
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True) if b > a]


def _detect(
    seq, steps, poses, path, config: Config, table: ScanHits | None = None
) -> tuple[list, int]:
    """Loop edges ``(j, i, z)``: node ``i``'s scan registered against a submap around node ``j``.

    The submap holds the nodes within ``submap_path`` of ``j`` along the path that are at least
    ``min_path / 2`` behind ``i`` — a stretch of trajectory that is locally consistent, so a
    drifted later visit of the same place does not blur it, and never ``i``'s own neighbours.
    Consecutive candidates with the same submap share it. When the scan already fits where it
    is, the brute-force search is skipped and only Levenberg-Marquardt runs. A match counts when
    enough beams fit, it stayed inside the searched window and it is unique
    (:func:`unique_fit`). ``table`` holds the nodes' hits (:func:`node_hits`; computed here
    when not given).

    The candidates are independent: they are matched in ranges on the kernel threads
    (:func:`slam.kernels.threads.in_threads`), cut where the submap changes
    (:func:`window_chunks`), and the edges are joined in candidate order, so the result does not
    depend on the number of threads.
    """
    if table is None:
        table = node_hits(seq, steps, config)
    lc = config.loops
    candidates = _candidates(poses, path, lc)
    windows = [_submap_window(path, j, i, lc) for j, i in candidates]
    context = MatchContext.of(config)
    passes = None
    if lc.pass_path > 0.0:  # the earlier passes' maps, shared by the threads
        from slam.backend.submaps import SubmapCache

        passes = SubmapCache(seq, steps, poses, config, table=table)
    ranges = window_chunks(windows, 4 * threads())
    parts = in_threads(
        [
            partial(
                _detect_range,
                seq,
                steps,
                poses,
                config,
                table,
                context,
                candidates[a:b],
                windows[a:b],
                path,
                passes,
            )
            for a, b in ranges
        ]
    )
    return [edge for part in parts for edge in part], len(candidates)


class MatchContext(NamedTuple):
    """The likelihood tables a match on a one-particle map uses (the filter's levels, the
    search's coarse one): loop closing, and laser odometry (:mod:`slam.laser_odometry`)."""

    luts: F64
    step_inv: float
    coarse: F64
    coarse_inv: float
    iterations: int

    @classmethod
    def of(cls, config: Config) -> MatchContext:
        """The tables of ``config``'s ``[rbpf]`` and ``[loops]`` settings."""
        lc, rc = config.loops, config.rbpf
        luts, step_inv = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
        coarse, coarse_inv = likelihood_tables(
            np.array([lc.search_sigma]), rc.z_hit, rc.z_rand, rc.dmax
        )
        return cls(
            luts, step_inv, coarse, coarse_inv, rc.max_iterations * lc.match_iteration_factor
        )


def _detect_range(
    seq,
    steps,
    poses: F64,
    config: Config,
    table: ScanHits,
    context: MatchContext,
    candidates: list[tuple[int, int]],
    windows: list[tuple[int, int]],
    path: F64,
    passes: SubmapCache | None = None,
) -> list:
    """The loop edges of ``candidates`` (their submaps ``windows``): :func:`_detect`'s work on one
    range of candidates, a submap built once for consecutive candidates that share it. With
    ``loops.pass_path``, ``passes`` (a :class:`slam.backend.submaps.SubmapCache`) gives the maps
    of the earlier passes (:func:`pass_window` along ``path``)."""
    lc, rc = config.loops, config.rbpf
    luts, step_inv = context.luts, context.step_inv
    edges = []
    maps, window = None, (-1, -1)
    for (j, i), (lo, hi) in zip(candidates, windows, strict=True):
        if (lo, hi) != window:
            maps, window = empty_submap(poses[j], config), (lo, hi)
            insert_nodes(maps, table, np.arange(lo, hi, lc.submap_stride), poses, config)
        ex, ey = seq.hits(int(steps[i]), rc.match_beams)
        if ex.size < lc.min_beams:
            continue
        view = maps.field(0)
        start = poses[i]
        _, close = fit_counts(view, start, ex, ey, lc.fit_distance)
        if close < lc.min_fit * ex.size:
            thin = slice(None, None, max(1, ex.size // lc.search_beams))
            start = correlative_search(
                view, poses[i], ex[thin].copy(), ey[thin].copy(), context.coarse[0, 0],
                context.coarse_inv, lc.search_xy, lc.search_step, lc.search_th,
                lc.search_th_step,
            )[:3].copy()  # fmt: skip
        refined, _, _ = match_one(
            view, start, ex, ey, luts, step_inv, context.iterations, rc.tolerance, 1
        )
        shift = refined - poses[i]
        if np.hypot(shift[0], shift[1]) > lc.search_xy or abs(wrap_angle(shift[2])) > lc.search_th:
            continue  # slid out of the searched window (along a corridor): unverified
        _, close = fit_counts(view, refined, ex, ey, lc.fit_distance)
        if close < lc.min_fit * ex.size or close < lc.min_beams:
            continue
        if not unique_fit(view, refined, ex, ey, close, lc):
            continue
        if passes is not None:
            plo, phi = pass_window(path, j, i, lc)
            if fits_elsewhere_on_pass(passes.field_view(plo, phi), refined, ex, ey, lc):
                continue
        hessian, gradient = np.zeros((3, 3)), np.zeros(3)
        normal_equations(
            view, *refined, ex, ey, luts[-1, 0], luts[-1, 1], step_inv, hessian, gradient
        )
        edges.append(
            (j, i, relative(poses[j], refined), _edge_information(hessian, refined, lc, rc))
        )
    return edges


UNIQUE_DIRECTIONS = 16
"""Directions :func:`unique_fit` moves a matched scan in (every 22.5°)."""


def unique_fit(view: FieldView, pose: F64, ex: F64, ey: F64, close: int, lc: LoopConfig) -> bool:
    """Whether scan ``(ex, ey)``, ``close`` of whose beams lie within ``lc.fit_distance`` of the
    surfaces of the submap ``view`` at ``pose``, fits there uniquely: moved ``lc.unique_shift``
    in any of :data:`UNIQUE_DIRECTIONS` directions it must fit fewer than ``lc.unique_ratio ·
    close`` beams (:func:`~slam.kernels.graph.shifted_fit`; always true with ``unique_shift``
    0). A scan of a corridor whose ends it does not see fits about as well a metre along it: a
    closure made of it says where across the corridor the robot was, not where along it, and
    pulls the loop to wherever the drifted estimate happened to put it."""
    if lc.unique_shift <= 0.0:
        return True
    moved = shifted_fit(view, pose, ex, ey, lc.fit_distance, lc.unique_shift, UNIQUE_DIRECTIONS)
    return moved < lc.unique_ratio * close


PASS_DIRECTIONS = 32
"""Directions :func:`fits_elsewhere_on_pass` moves a matched scan in (every 11.25°)."""


def pass_window(path: F64, j: int, i: int, lc: LoopConfig) -> tuple[int, int]:
    """Nodes ``[lo, hi)`` of the earlier pass around node ``j`` (``loops.pass_path`` of path either
    side, at least ``min_path / 2`` behind node ``i``), its ends on a grid of a third of
    ``pass_path`` so that neighbouring candidates share one map."""
    grid = lc.pass_path / 3.0
    start = np.floor((path[j] - lc.pass_path) / grid) * grid
    stop = min(np.ceil((path[j] + lc.pass_path) / grid) * grid, path[i] - lc.min_path / 2)
    return int(np.searchsorted(path, start)), int(np.searchsorted(path, stop, "right"))


def fits_elsewhere_on_pass(view: FieldView, pose: F64, ex: F64, ey: F64, lc: LoopConfig) -> bool:
    """Whether scan ``(ex, ey)``, matched at ``pose``, fits the map of the earlier pass ``view``
    (:func:`pass_window`) about as well somewhere else: moved ``unique_shift`` to ``pass_shift``
    metres in any of :data:`PASS_DIRECTIONS` directions, at least ``unique_ratio`` of the beams
    within ``fit_distance`` of a surface at ``pose`` (the criterion of :func:`unique_fit`, over
    the wider map and further). Always false with ``pass_path`` 0."""
    if lc.pass_path <= 0.0:
        return False
    _, close = fit_counts(view, pose, ex, ey, lc.fit_distance)
    need = int(np.ceil(lc.unique_ratio * max(close, 1)))
    first = max(lc.unique_shift, lc.pass_shift_step)
    shifts = np.arange(first, lc.pass_shift + 1e-9, lc.pass_shift_step)
    return fits_when_shifted(view, pose, ex, ey, lc.fit_distance, shifts, PASS_DIRECTIONS, need)


def _edge_information(hessian: F64, matched: F64, lc: LoopConfig, rc) -> F64:
    """Information of a loop edge: the match's tempered Hessian, with a covariance floor.

    The Hessian is that of the scan's negative log-likelihood with respect to the matched world
    pose; divided by the filter's temperature (beams are not independent) it is the inverse
    covariance of the match. A floor (``sigma_xy``, ``sigma_th``) keeps a long, clean scan from
    claiming millimetres. The result is expressed in the matched pose's frame, where the edge
    error lives, so a corridor's unobserved axis keeps its small information.
    """
    cov = np.linalg.inv(hessian / rc.temperature + np.eye(3) * 1e-6)
    cov += np.diag([lc.sigma_xy**2, lc.sigma_xy**2, lc.sigma_th**2])
    c, s = np.cos(matched[2]), np.sin(matched[2])
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # world → matched frame
    cov_edge = rot @ cov @ rot.T
    info = np.linalg.inv(cov_edge)
    return 0.5 * (info + info.T)


def _chain_information(seq_z: F64, lc: LoopConfig, loose: F64 | None = None) -> F64:
    """``(E, 3, 3)`` diagonal information of the sequential edges ``seq_z``, each edge's sigmas
    multiplied by ``loose[k]`` when given (:func:`chain_looseness`)."""
    sigma_xy = lc.seq_sigma_xy + lc.seq_sigma_rel * np.hypot(seq_z[:, 0], seq_z[:, 1])
    sigma_th = lc.seq_sigma_th + lc.seq_sigma_rel * np.abs(seq_z[:, 2])
    if loose is not None:
        sigma_xy, sigma_th = sigma_xy * loose, sigma_th * loose
    info = np.zeros((seq_z.shape[0], 3, 3))
    info[:, 0, 0] = info[:, 1, 1] = 1.0 / sigma_xy**2
    info[:, 2, 2] = 1.0 / sigma_th**2
    return info


def chain_looseness(
    loose_nodes: NDArray[np.bool_] | None, keys: NDArray[np.int64], factor: float
) -> F64 | None:
    """``(K - 1,)`` multiple of the sigmas of each chain edge between the keyframes ``keys``:
    ``factor`` where a node from one keyframe to the next is in ``loose_nodes`` (``(U,)``, the
    nodes of the stretches the map-quality score flagged, :class:`slam.stages.Repair`), else 1;
    ``None`` when no node is."""
    if loose_nodes is None or not loose_nodes.any() or len(keys) < 2:
        return None
    counts = np.concatenate([[0], np.cumsum(loose_nodes)])  # loose nodes before each index
    inside = counts[keys[1:] + 1] - counts[keys[:-1]] > 0
    return np.where(inside, factor, 1.0)


class PoseGraph(NamedTuple):
    """The edges of a pose graph: edge ``k`` joins node ``i[k]`` to node ``j[k]``."""

    i: NDArray[np.int64]
    """``(E,)`` first node of every edge."""
    j: NDArray[np.int64]
    """``(E,)`` second node of every edge."""
    z: F64
    """``(E, 3)`` C-contiguous measured pose of node ``j`` in the frame of node ``i``."""
    info: F64
    """``(E, 3, 3)`` information of every measurement."""
    robust: F64
    """``(E,)`` robust-kernel (Cauchy) scale of every edge; 0: none."""


def chain_graph(
    poses: F64, edges: list, robust: F64, lc: LoopConfig, loose: F64 | None = None
) -> PoseGraph:
    """The pose graph of the chain of ``poses`` (each pose to the next, measuring their relative
    pose with :func:`_chain_information`, its sigmas times ``loose`` where given, no robust
    kernel) followed by the loop ``edges`` ``(i, j, z, info)``, loop edge ``k`` with robust scale
    ``robust[k]``. A loop edge whose measurement or information is not finite is left out, with
    a warning: one NaN in the system would make every optimised pose NaN."""
    n = poses.shape[0]
    finite = [bool(np.isfinite(e[2]).all() and np.isfinite(e[3]).all()) for e in edges]
    if not all(finite):
        warnings.warn(
            f"pose graph of {n} nodes: {finite.count(False)} of its {len(edges)} loop edges have "
            "a measurement or an information that is not finite (NaN or infinity); they are "
            "left out of the optimisation",
            stacklevel=3,
        )
        robust = np.asarray(robust, dtype=np.float64)[np.array(finite, dtype=bool)]
        edges = [e for e, ok in zip(edges, finite, strict=True) if ok]
    seq_z = relative(poses[:-1], poses[1:])
    loop_info = np.array([e[3] for e in edges], dtype=np.float64).reshape(-1, 3, 3)
    return PoseGraph(
        i=np.concatenate([np.arange(n - 1), [e[0] for e in edges]]).astype(np.int64),
        j=np.concatenate([np.arange(1, n), [e[1] for e in edges]]).astype(np.int64),
        z=np.ascontiguousarray(
            np.concatenate([seq_z, np.array([e[2] for e in edges]).reshape(-1, 3)])
        ),
        info=np.concatenate([_chain_information(seq_z, lc, loose), loop_info]),
        robust=np.concatenate([np.zeros(n - 1), np.asarray(robust, dtype=np.float64)]),
    )


def optimize(
    poses: F64,
    edges: list,
    lc: LoopConfig,
    robust: F64 | None = None,
    start: F64 | None = None,
    loose: F64 | None = None,
) -> F64:
    """Gauss-Newton on the :func:`chain_graph` of ``poses`` and loop ``edges`` (node 0 stays
    fixed), every loop edge with robust scale ``lc.robust`` unless ``robust`` gives one per edge
    (0: none), the iterations starting from ``start`` (default: ``poses``), the chain's sigmas
    times ``loose`` where given (:func:`chain_looseness`)."""
    if robust is None:
        robust = np.full(len(edges), lc.robust)
    x = (poses if start is None else start).copy()
    return gauss_newton(x, chain_graph(poses, edges, robust, lc, loose), lc)


def gauss_newton(
    x: F64, graph: PoseGraph, lc: LoopConfig, priors: tuple[F64, F64] | None = None
) -> F64:
    """Gauss-Newton on the pose ``graph`` from ``x`` (modified in place and returned): node 0
    fixed — or, with ``priors`` ``(poses, information)``, every node held to its pose in
    ``poses`` with that ``(3, 3)`` information instead — at most ``lc.iterations`` steps, until a
    step moves no node more than ``lc.converged_xy`` / ``lc.converged_th``.

    Warns when a step's conjugate gradients stop at ``lc.solver_iterations`` before
    ``lc.solver_tolerance`` (the poses may then be off), and when the system is not finite: the
    steps then stop and ``x`` keeps the last finite estimate."""
    n = x.shape[0]
    diag = np.zeros((n, 3, 3))
    band = np.zeros((max(n - 1, 1), 3, 3))
    far = np.zeros((graph.i.size, 3, 3))
    grad = np.zeros((n, 3))
    capped = 0
    for _ in range(lc.iterations):
        linearize(x, graph.i, graph.j, graph.z, graph.info, graph.robust, diag, band, far, grad)
        if priors is None:
            diag[0] += np.eye(3) * 1e9  # node 0 fixed
        else:
            d = x - priors[0]
            d[:, 2] = wrap_angle(d[:, 2])
            diag += priors[1]
            grad += d @ priors[1]
        delta, _, converged = solve_system(
            diag, band, far, graph.i, graph.j, -grad, lc.solver_iterations, lc.solver_tolerance
        )
        if not np.isfinite(delta).all():
            warnings.warn(
                f"pose graph of {n} nodes: its system holds a NaN or an infinity; the "
                "optimisation stops at its last finite estimate",
                stacklevel=3,
            )
            break
        capped += not converged
        x += delta
        x[:, 2] = wrap_angle(x[:, 2])
        if (
            np.abs(delta[:, :2]).max() < lc.converged_xy
            and np.abs(delta[:, 2]).max() < lc.converged_th
        ):
            break
    if capped:
        warnings.warn(
            f"pose graph of {n} nodes: in {capped} Gauss-Newton steps the conjugate gradients "
            f"stopped at loops.solver_iterations = {lc.solver_iterations} before "
            f"loops.solver_tolerance = {lc.solver_tolerance:g}; the optimised poses may be off "
            "(raise loops.solver_iterations)",
            stacklevel=3,
        )
    return x


def smooth_with_odometry(
    poses: F64,
    odometry: F64,
    reg: tuple[float, float],
    odo: tuple[float, float, float],
    lc: LoopConfig,
) -> F64:
    """Every pose of ``poses`` ``(N, 3)`` pulled towards the odometry's shape between neighbours:
    :func:`gauss_newton` on the chain of odometry edges ``o_k⁻¹ ⊕ o_{k+1}`` (sigmas ``odo``: along
    and across the robot's heading at ``o_k`` in metres — the edge's own frame —, and in heading
    in radians) with every pose held to ``poses`` (sigmas ``reg``: metres, radians). The chain's
    system is block-tridiagonal, which :func:`solve_system`'s preconditioner solves exactly; the
    priors sit on its diagonal, so no node needs fixing."""
    n = poses.shape[0]
    if n < 2:
        return poses.copy()
    i = np.arange(n - 1, dtype=np.int64)
    info = np.zeros((n - 1, 3, 3))
    info[:, 0, 0] = 1.0 / odo[0] ** 2
    info[:, 1, 1] = 1.0 / odo[1] ** 2
    info[:, 2, 2] = 1.0 / odo[2] ** 2
    graph = PoseGraph(
        i, i + 1, np.ascontiguousarray(relative(odometry[:-1], odometry[1:])), info, np.zeros(n - 1)
    )
    prior = np.diag([1.0 / reg[0] ** 2, 1.0 / reg[0] ** 2, 1.0 / reg[1] ** 2])
    return gauss_newton(poses.copy(), graph, lc, priors=(poses, prior))


def graph_keyframes(n: int, stride: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The pose graph's keyframes among ``n >= 1`` nodes, every ``stride``-th node and the last,
    and for every node the index (into the keyframes) of the keyframe at or after it."""
    keys = np.arange(0, n, stride)
    if keys[-1] != n - 1:
        keys = np.append(keys, n - 1)
    return keys, np.searchsorted(keys, np.arange(n))


def keyframe_edges(
    found: list, x: F64, keys: NDArray[np.int64], key_of: NDArray[np.int64]
) -> list[tuple[int, int, F64, F64]]:
    """The loop closures ``found`` (``(j, i, z, info)``: node ``i`` matched at ``z`` relative to
    node ``j``) as edges between keyframes ``(kj, ki, z', info)`` of :func:`graph_keyframes`.

    Closures are looked for at keyframes, so ``i`` is one; ``j`` moves to its nearest keyframe
    and the measurement becomes node ``i``'s matched pose relative to that keyframe's pose in
    ``x``."""
    edges = []
    for j, i, z, info in found:
        kj = int(key_of[j])
        if kj > 0 and abs(int(keys[kj - 1]) - j) < abs(int(keys[kj]) - j):
            kj -= 1
        ki = int(np.searchsorted(keys, i))
        matched_i = compose(x[j], z)  # node i's pose found by the loop match
        edges.append((kj, ki, relative(x[keys[kj]], matched_i), info))
    return edges


LoopRound = Callable[
    [F64, NDArray[np.int64], NDArray[np.int64], list], tuple[list, F64 | None, int]
]
"""One round of loop closing, given the current node poses ``x``, :func:`graph_keyframes` and
the round's local closures (:func:`_detect` along ``x``): ``(keyframe edges, optimised keyframe
poses or None when no closure was found, further candidates examined)``."""


T = TypeVar("T")


class FirstRound:
    """What the first round of a loop closing found, kept for a later loop closing over the same
    nodes (:class:`slam.stages.Repair` runs the stage again from the filter's output with a
    looser chain: the chain's looseness acts in the optimisation only, so its first round finds
    the same closures; on mit-killian that round's searches are 3.6 s of 9 s).

    :meth:`found` computes a kind of result the first time and returns it again while the
    inputs are the same: the scans ``seq`` (the same object), the nodes' steps, poses and path
    (equal arrays) and the configuration (equal); other inputs drop what was kept."""

    def __init__(self) -> None:
        self._inputs: tuple | None = None
        self._found: dict[str, Any] = {}

    def found(self, kind: str, inputs: tuple, compute: Callable[[], T]) -> T:
        """``compute()``'s result for ``kind`` on ``inputs`` ``(seq, steps, poses, path,
        config)``, computed once."""
        if not self._same(inputs):
            seq, steps, poses, path, config = inputs
            self._inputs = (seq, steps.copy(), poses.copy(), path.copy(), config)
            self._found = {}
        if kind not in self._found:
            self._found[kind] = compute()
        return self._found[kind]

    def _same(self, inputs: tuple) -> bool:
        if self._inputs is None:
            return False
        seq, steps, poses, path, config = inputs
        kept_seq, kept_steps, kept_poses, kept_path, kept_config = self._inputs
        return (
            seq is kept_seq
            and np.array_equal(steps, kept_steps)
            and np.array_equal(poses, kept_poses)
            and np.array_equal(path, kept_path)
            and config == kept_config
        )


def loop_rounds(
    seq,
    steps,
    poses: F64,
    path: F64,
    table: ScanHits,
    config: Config,
    one_round: LoopRound,
    first: FirstRound | None = None,
) -> LoopResult:
    """Run up to ``loops.rounds`` rounds over the nodes ``poses`` (at scans ``steps``; ``path``:
    each node's distance along the trajectory, ``table``: their hits, :func:`node_hits`), each
    detecting the local closures along the current estimate (:func:`_detect`) and handing them
    to ``one_round``, spreading each round's keyframe corrections to the nodes in between, until
    a round finds nothing; then the do-no-harm rule (module docstring, step 5). The frame of
    :func:`close_loops` and :func:`slam.backend.global_loops.close_loops_global`. ``first``
    keeps the first round's local closures for a later run over the same nodes."""
    lc = config.loops
    keys, key_of = graph_keyframes(poses.shape[0], lc.stride)
    x = poses.copy()
    examined = 0
    edges: list = []
    for round_ in range(lc.rounds):
        detect = partial(_detect, seq, steps, x, path, config, table)
        if round_ == 0 and first is not None:
            local, count = first.found("local", (seq, steps, poses, path, config), detect)
        else:
            local, count = detect()
        found, new_keys, more = one_round(x, keys, key_of, local)
        examined += count + more
        if new_keys is None:
            break
        edges = found
        x = spread_corrections(poses, keys, new_keys, path)
    moved = float(np.hypot(*(x[:, :2] - poses[:, :2]).T).max()) if len(x) else 0.0
    if moved < lc.min_correction:
        # the filter's trajectory already agrees with its loop closures within their noise
        return LoopResult(poses.copy(), examined, len(edges), 0.0)
    return LoopResult(x, examined, len(edges), moved)


def close_loops(
    seq,
    steps: NDArray[np.int64],
    poses: F64,
    config: Config,
    loose_nodes: NDArray[np.bool_] | None = None,
    first: FirstRound | None = None,
) -> LoopResult:
    """Detect loop closures along ``poses`` (the nodes at scans ``steps``) and optimise.

    The graph's nodes are keyframes — every ``stride``-th node, where loop closures are looked
    for, plus the last; the nodes in between follow their keyframes' corrections. The chain's
    sigmas are ``loops.flex_factor`` times larger between keyframes around ``loose_nodes``
    (:func:`chain_looseness`). ``first`` keeps (or gives) the first round's closures
    (:class:`FirstRound`).
    """
    lc = config.loops

    def one_round(
        x: F64, keys: NDArray[np.int64], key_of: NDArray[np.int64], found: list
    ) -> tuple[list, F64 | None, int]:
        if not found:
            return [], None, 0
        edges = keyframe_edges(found, x, keys, key_of)
        loose = chain_looseness(loose_nodes, keys, lc.flex_factor)
        return edges, optimize(poses[keys], edges, lc, loose=loose), 0

    path, table = path_along(poses), node_hits(seq, steps, config)
    return loop_rounds(seq, steps, poses, path, table, config, one_round, first)
