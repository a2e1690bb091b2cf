"""Global loop search: closures beyond the drifted estimate's reach, verified before they count.

The loop closing of :mod:`slam.graph` looks for a closure only where the filter's estimate puts
an earlier node within ``loops.radius``, and matches within ±``loops.search_xy``: after a long
loop the drift is metres and degrees, and the loop stays open (or a corridor is doubled). This
module adds, in the same pose graph and the same rounds:

1. **Keyframes** every ``backend.keyframe_path`` metres of path, and **submaps** of
   ``backend.submap_length`` metres each (:mod:`slam.backend.submaps`).
2. **Search.** For keyframe ``i`` and a submap that ended at least ``loops.min_path`` back, the
   window is ``window_xy_min + drift_xy · path gap`` (capped by ``window_xy_max``), and likewise
   in rotation: the drift a filter may have accumulated since it last saw that place.
   ``backend.candidates`` submaps are searched by branch-and-bound
   (:func:`slam.kernels.bnb.bnb_search`), exact over the whole window: the nearest relative to
   its window of each earlier pass through the place first (:func:`candidate_order`). In the
   first round, a keyframe that no closure holds within ``agree_path`` of path (no local one,
   none found within the window) also searches beyond the window, out to
   ``window_xy_min + far_drift_xy · path gap`` (capped by ``far_window_xy_max``):
   ``backend.far_candidates`` of those submaps, taken in turn keyframe by keyframe. A loop long
   enough to drift further than the window (fr-clinic started at a third of its log: 31 m
   after 750 m of path) stays open without it, and the submaps nearest such a drifted estimate
   are the wrong stretch of the right pass; where closures hold the place, a match tens of
   metres away is an alias of a repeated structure, and nothing is searched.
3. **Verification.** The best pose must score ``min_score``; refined by Levenberg-Marquardt
   against the submap's distance field it must stay within two search cells, and of the beams
   that land on the submap's known cells ``backend.min_fit`` must lie within
   ``loops.fit_distance`` of its surfaces, those being at least ``backend.min_overlap`` of all
   the scan's beams (:func:`_fitting`), and the match must be unique: moved ``loops.unique_shift``
   in any direction the scan fits clearly worse (:func:`slam.graph.unique_fit`; a corridor's
   scan fits as well a metre along it, and two such matches from neighbouring keyframes agree
   with each other, step 4), and moved up to ``loops.pass_shift`` on the map of the earlier pass
   around the matched node it fits worse too (:func:`slam.graph.fits_elsewhere_on_pass`: a
   door further along a corridor whose doors repeat; aliases of a repeated structure are
   consistent with each other as well). A submap that a local closure already joins to the
   keyframe's neighbourhood is searched like any other; its match is dropped when it puts the
   keyframe where that local closure does, or fits the submap no better than where the local
   closure puts it (:func:`_held_locally`). The local search looks only ±``loops.search_xy``
   around a drifted estimate and can close a loop wrongly; a search skipped behind such a
   closure left the loop open (aces' ROS bag, seed 1: the start's junction 1.9 m off after the
   first large loop, docs/accuracy.md "Odometry a few per cent off").
4. **Consistency.** A closure counts only when another closure, found from a different
   keyframe within ``agree_path`` metres of path (and to a submap as near), implies the same
   correction of the trajectory (``agree_xy``, ``agree_th``, plus the drift allowed between
   them): a single match in a corridor or a symmetric room is not enough.
5. **χ² gate.** The verified closures enter the optimisation without a robust kernel (metres
   off the drifted estimate, a Cauchy kernel would never pull them in); a global closure whose
   error then exceeds ``chi2_gate`` under its own information is dropped and the graph solved
   again without it, every loop edge robust, from the pulled-in poses.

The edges then join the local ones of :func:`slam.graph._detect`, and the optimisation, the
keyframes and the do-no-harm rule are those of :func:`slam.graph.close_loops`.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from slam.backend.submaps import SubmapCache, stretches, world_hits
from slam.config import Config
from slam.geometry import (
    compose,
    inverse,
    path_along,
    relative,
    spread_picks,
    wrap_angle,
)
from slam.graph import (
    FirstRound,
    LoopResult,
    _edge_information,
    chain_looseness,
    fits_elsewhere_on_pass,
    keyframe_edges,
    loop_rounds,
    node_hits,
    optimize,
    pass_window,
    unique_fit,
)
from slam.kernels.bnb import bnb_search
from slam.kernels.field import match_one, normal_equations
from slam.kernels.graph import edge_error, fit_counts
from slam.kernels.threads import in_threads, threads
from slam.mapping import likelihood_tables
from slam.scans import ScanHits

F64 = NDArray[np.float64]


def keyframes(path: F64, spacing: float) -> NDArray[np.int64]:
    """Node indices about ``spacing`` metres of path apart (the first node included)."""
    return np.unique(np.searchsorted(path, np.arange(0.0, path[-1] + 1e-9, spacing)))


def _search_points(seq, step: int, config: Config) -> tuple[F64, F64]:
    bc = config.backend
    hx, hy = world_hits(seq, step, np.zeros(3), bc.submap_range)
    if hx.size > bc.points:
        pick = spread_picks(hx.size, bc.points)
        hx, hy = hx[pick], hy[pick]
    return np.ascontiguousarray(hx), np.ascontiguousarray(hy)


class _Stretches(NamedTuple):
    """The submaps of one round as the search sees them (nodes at their current poses)."""

    subs: list[tuple[int, int]]
    """Node range ``[lo, hi)`` of every submap."""
    centre: F64
    """``(S, 2)`` mean position of each submap's nodes."""
    spread: F64
    """``(S,)`` largest distance of a submap's node from its centre."""
    end_path: F64
    """``(S,)`` path position of each submap's last node."""
    mid_path: F64
    """``(S,)`` path position halfway through each submap."""
    closed_sub: NDArray[np.int64]
    """The submap that holds the earlier node of every local closure."""
    closed_node: NDArray[np.int64]
    """The keyframe (node) of every local closure."""
    closed_pose: F64
    """``(K, 3)`` the pose every local closure matched its keyframe at."""

    @classmethod
    def of(cls, x: F64, path: F64, length: float, local: list) -> _Stretches:
        """The submaps of ``length`` metres of ``path`` at the node poses ``x``; ``local``: the
        local closures ``(j, i, z, info)``."""
        subs = stretches(path, length)
        centre = np.array([x[lo:hi, :2].mean(axis=0) for lo, hi in subs])
        spread = np.array(
            [np.hypot(*(x[lo:hi, :2] - centre[s]).T).max() for s, (lo, hi) in enumerate(subs)]
        )
        sub_of = np.zeros(x.shape[0], dtype=np.int64)
        for s, (lo, hi) in enumerate(subs):
            sub_of[lo:hi] = s
        return cls(
            subs,
            centre,
            spread,
            np.array([path[hi - 1] for _, hi in subs]),
            np.array([0.5 * (path[lo] + path[hi - 1]) for lo, hi in subs]),
            np.array([sub_of[j] for j, _, _, _ in local], dtype=np.int64),
            np.array([i for _, i, _, _ in local], dtype=np.int64),
            np.array([compose(x[j], z) for j, _, z, _ in local]).reshape(-1, 3),
        )

    def placed(self, joined: NDArray[np.bool_], i: int, x: F64, path: F64) -> tuple[F64, F64]:
        """Where the ``joined`` local closures put keyframe ``i`` (``(K, 3)``, each closure's
        match carried to ``i`` along the trajectory ``x``) and the path (m) between each
        closure's keyframe and ``i``."""
        nodes = self.closed_node[joined]
        poses = compose(self.closed_pose[joined], relative(x[nodes], x[i]))
        return poses.reshape(-1, 3), np.abs(path[nodes] - path[i])


def _same_place(a: F64, b: F64, drift: float, config: Config) -> bool:
    """Whether two closures that put one keyframe at ``a`` and ``b`` agree, ``drift`` metres of
    path apart (``agree_xy``, ``agree_th``, plus the drift allowed over that path)."""
    bc, lc = config.backend, config.loops
    if np.hypot(*(a[:2] - b[:2])) > bc.agree_xy + lc.seq_sigma_rel * drift:
        return False
    return abs(wrap_angle(a[2] - b[2])) <= bc.agree_th + bc.drift_th * drift


class _Search(NamedTuple):
    """What the search from every keyframe reads (one round): the scans, the nodes at their
    current poses and path positions, the configuration, the shared submap cache and the
    submaps as :class:`_Stretches`."""

    seq: Any
    steps: NDArray[np.int64]
    x: F64
    path: F64
    config: Config
    cache: SubmapCache
    st: _Stretches
    passes: SubmapCache | None
    """The maps of the earlier passes (``loops.pass_path``; None without the test)."""


def detect_global(
    seq,
    steps,
    x: F64,
    path: F64,
    config: Config,
    local: list = (),
    table: ScanHits | None = None,
    far: bool = True,
) -> tuple[list, int]:
    """Verified global closures ``(j, i, z, info)`` along ``x`` and the searches made.

    See the module docstring (steps 1-3); :func:`consistent` is step 4. A match to a submap
    that a local closure ``local`` (edges of :func:`slam.graph._detect`) already joins to a node
    within ``keyframe_path`` of the keyframe is kept only where that closure does not already
    hold the loop (:func:`_held_locally`). ``table``: the nodes' hits (:func:`slam.graph.node_hits`;
    computed here when not given). Then, with ``far`` and ``backend.far_drift_xy``, the
    keyframes that no closure holds within ``backend.agree_path`` of path search beyond the
    drift window (module docstring, step 2).

    Keyframes are independent: ranges of them are searched on the kernel threads
    (:func:`slam.kernels.threads.in_threads`), which share one :class:`SubmapCache` (a submap
    is built once however many ranges search it), and the closures are joined in keyframe
    order, so the result does not depend on the thread count.
    """
    bc = config.backend
    if table is None:
        table = node_hits(seq, steps, config)
    frames = keyframes(path, bc.keyframe_path)
    turns = np.arange(frames.size)
    st = _Stretches.of(x, path, bc.submap_length, list(local))
    cache = SubmapCache(seq, steps, x, config, table=table)
    passes = None
    if config.loops.pass_path > 0.0:
        passes = SubmapCache(seq, steps, x, config, table=table)
    search = partial(_search_keyframes, _Search(seq, steps, x, path, config, cache, st, passes))
    edges, searched = _in_ranges(search, frames, turns, False)
    if far and bc.far_drift_xy > 0 and bc.far_candidates > 0:
        held = np.concatenate([st.closed_node, [i for _, i, _, _ in edges]]).astype(np.int64)
        unheld = _far_from(path[frames], path[held], bc.agree_path)
        beyond, more = _in_ranges(search, frames[unheld], turns[unheld], True)
        edges, searched = edges + beyond, searched + more
    return edges, searched


def _far_from(at: F64, marks: F64, reach: float) -> NDArray[np.bool_]:
    """Whether each path position of ``at`` lies further than ``reach`` from every one of
    ``marks`` (all of them when there is none)."""
    if marks.size == 0:
        return np.ones(at.shape, dtype=bool)
    marks = np.sort(marks)
    k = np.searchsorted(marks, at)
    below = marks[np.maximum(k - 1, 0)]
    above = marks[np.minimum(k, marks.size - 1)]
    return np.minimum(np.abs(at - below), np.abs(above - at)) > reach


def _in_ranges(
    search: Callable, frames: NDArray[np.int64], turns: NDArray[np.int64], beyond: bool
) -> tuple[list, int]:
    """``search`` (:func:`_search_keyframes` but for its last three arguments) over ranges of
    the keyframes ``frames`` on the kernel threads: the closures in keyframe order and the
    searches made."""
    cuts = np.linspace(0, frames.size, 4 * threads() + 1).round().astype(np.int64)
    parts = in_threads(
        [
            partial(search, frames[a:b], turns[a:b], beyond)
            for a, b in zip(cuts[:-1], cuts[1:], strict=True)
            if b > a
        ]
    )
    return [edge for part, _ in parts for edge in part], sum(n for _, n in parts)


def _search_keyframes(
    search: _Search, frames: NDArray[np.int64], turns: NDArray[np.int64], beyond: bool
) -> tuple[list, int]:
    """:func:`detect_global`'s search from the keyframes ``frames`` (``turns``: their numbers
    among all keyframes, for :func:`candidate_order`): their verified closures and the searches
    made; within the drift window (``backend.drift_xy``), or with ``beyond`` the
    ``backend.far_candidates`` submaps beyond it (``backend.far_drift_xy``)."""
    seq, steps, x, path, config, cache, st, passes = search
    bc, lc, rc = config.backend, config.loops, config.rbpf
    luts, step_inv = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    edges, searched = [], 0
    for i, turn in zip(frames, turns, strict=True):
        subs, wxy, wth = _candidates(st, x, path, int(i), int(turn), beyond, config)
        if subs.size == 0:
            continue
        px, py = _search_points(seq, int(steps[i]), config)
        if px.size < lc.min_beams:
            continue
        far = float(np.sqrt((px * px + py * py).max()))
        th_step = float(np.clip(bc.resolution / max(far, 1.0), 0.002, 0.05))
        ex, ey = seq.hits(int(steps[i]), rc.match_beams)
        for s, window_xy, window_th in zip(subs.tolist(), wxy, wth, strict=True):
            near = np.abs(path[st.closed_node] - path[i]) <= bc.keyframe_path
            joined = near & (st.closed_sub == s)
            lo, hi = st.subs[s]
            pyr = cache.pyramid(lo, hi)
            if pyr is None:
                continue
            searched += 1
            found = bnb_search(
                pyr.levels, pyr.origin[0], pyr.origin[1], pyr.resolution, px, py,
                x[i, 0], x[i, 1], x[i, 2], float(window_xy), float(window_th), th_step,
                bc.min_score,
            )  # fmt: skip
            if found[3] < 0:
                continue
            view = cache.field_view(lo, hi)
            iterations = rc.max_iterations * lc.match_iteration_factor
            refined, _, _ = match_one(
                view, found[:3].copy(), ex, ey, luts, step_inv, iterations, rc.tolerance, 1
            )
            if np.hypot(*(refined[:2] - found[:2])) > 2.0 * bc.resolution:
                continue
            close = _fitting(view, refined, ex, ey, config)
            if close is None or not unique_fit(view, refined, ex, ey, close, lc):
                continue
            j = lo + int(np.argmin(np.hypot(*(x[lo:hi, :2] - refined[:2]).T)))
            if passes is not None:
                plo, phi = pass_window(path, j, int(i), lc)
                if fits_elsewhere_on_pass(passes.field_view(plo, phi), refined, ex, ey, lc):
                    continue
            if joined.any() and _held_locally(
                st, joined, view, (ex, ey), refined, close, int(i), x, path, config
            ):
                continue
            hessian, gradient = np.zeros((3, 3)), np.zeros(3)
            normal_equations(
                view, *refined, ex, ey, luts[-1, 0], luts[-1, 1], step_inv, hessian, gradient
            )
            edges.append(
                (j, int(i), relative(x[j], refined), _edge_information(hessian, refined, lc, rc))
            )
    return edges, searched


def _candidates(
    st: _Stretches, x: F64, path: F64, i: int, turn: int, beyond: bool, config: Config
) -> tuple[NDArray[np.int64], F64, F64]:
    """The submaps keyframe ``i`` (number ``turn`` among the keyframes) searches, in order, with
    their windows in position (m) and rotation (rad): within the drift window
    ``window_xy_min + drift_xy · path gap``, ``backend.candidates`` of them
    (:func:`candidate_order`); with ``beyond``, ``backend.far_candidates`` of those beyond it
    and within ``window_xy_min + far_drift_xy · path gap``, in turn (the rotation window the
    same)."""
    bc = config.backend
    eligible = np.flatnonzero(st.end_path <= path[i] - config.loops.min_path)
    gap = path[i] - st.mid_path[eligible]
    wxy = np.minimum(bc.window_xy_min + bc.drift_xy * gap, bc.window_xy_max)
    wth = np.minimum(bc.window_th_min + bc.drift_th * gap, bc.window_th_max)
    reach = np.maximum(np.hypot(*(st.centre[eligible] - x[i, :2]).T) - st.spread[eligible], 0.0)
    if beyond:
        wfar = np.minimum(bc.window_xy_min + bc.far_drift_xy * gap, bc.far_window_xy_max)
        pick = (reach > wxy) & (reach <= wfar)
        wxy = wfar
        order = candidate_order(
            eligible[pick], reach[pick] / wxy[pick], 0, "nearest", turn, bc.far_candidates
        )
    else:
        pick = reach <= wxy
        order = candidate_order(
            eligible[pick], reach[pick] / wxy[pick], bc.candidates, bc.candidate_choice
        )
    return eligible[pick][order], wxy[pick][order], wth[pick][order]


def _held_locally(
    st: _Stretches,
    joined: NDArray[np.bool_],
    view,
    scan: tuple[F64, F64],
    pose: F64,
    close: int,
    i: int,
    x: F64,
    path: F64,
    config: Config,
) -> bool:
    """Whether the ``joined`` local closures already hold the loop that a global match of
    keyframe ``i``'s ``scan`` at ``pose`` (``close`` of its beams within ``loops.fit_distance``
    of the surfaces of the submap ``view``) would close: one of them puts the keyframe where the
    match does (:func:`_same_place`), or the scan fits the submap at least as well where one of
    them puts it (as many beams within ``loops.fit_distance``). A local closure can be wrong —
    the local search looks only ±``loops.search_xy`` around a drifted estimate — and a match
    that fits better is then kept to compete with it."""
    placed, drift = st.placed(joined, i, x, path)
    if any(_same_place(p, pose, d, config) for p, d in zip(placed, drift, strict=True)):
        return True
    fit_distance = config.loops.fit_distance
    return any(fit_counts(view, p, *scan, fit_distance)[1] >= close for p in placed)


def candidate_order(
    submaps: NDArray[np.int64],
    ratio: F64,
    count: int,
    choice: str = "nearest",
    turn: int = 0,
    in_turn: int = 0,
) -> NDArray[np.int64]:
    """Which of the ``submaps`` (ascending indices, their keyframe's distance relative to their
    window ``ratio``) a keyframe searches, in order: at most ``count`` positions into
    ``submaps``. ``nearest``: the smallest ratios. ``per_pass``: first the smallest ratio of
    each pass — a run of consecutive submap indices, one pass of the robot through the place —
    by ratio, then the other submaps by ratio. After a long loop the drifted estimate lies
    nearer the passes it made recently than the true place lies to its own (wider) window, and
    three neighbouring submaps of one recent pass would take every search.

    Then ``in_turn`` more from the submaps not chosen (nearest relative to their window first),
    the keyframe numbered ``turn`` taking the ``turn · in_turn``-th of them on (cyclically), so
    that consecutive keyframes search different ones: after a long loop the submaps nearest the
    drifted estimate can be the wrong stretch of the right pass."""
    order = np.argsort(ratio, kind="stable")
    if choice == "nearest" or order.size <= 1:
        ranked = order
    else:
        passes = np.cumsum(np.r_[0, np.diff(submaps) != 1])
        _, first = np.unique(passes[order], return_index=True)
        lead = order[np.sort(first)]
        rest = np.setdiff1d(order, lead, assume_unique=True)
        ranked = np.concatenate([lead, rest[np.argsort(ratio[rest], kind="stable")]])
    chosen, others = ranked[:count], ranked[count:]
    if in_turn <= 0 or others.size == 0:
        return chosen
    take = (turn * in_turn + np.arange(min(in_turn, others.size))) % others.size
    return np.concatenate([chosen, others[take]])


def _fitting(view, pose: F64, ex: F64, ey: F64, config: Config) -> int | None:
    """The beams of scan ``(ex, ey)`` at ``pose`` within ``loops.fit_distance`` of the surfaces
    of the submap ``view`` when the scan fits it (module docstring, step 3), else ``None``.

    Of the beams that land on the submap's known cells, ``backend.min_fit`` must lie within
    ``loops.fit_distance`` of its surfaces, and those must be ``backend.min_overlap`` of all the
    scan's beams (and ``loops.min_beams``). A submap covers ``submap_length`` metres of path: a
    scan taken from elsewhere (the other end of a hall, the other direction of a corridor) sees
    much that the submap never saw, and counting those beams against the match rejects true
    returns; a wrong match puts the beams that do land on the submap off its surfaces.
    """
    bc, lc = config.backend, config.loops
    known, close = fit_counts(view, pose, ex, ey, lc.fit_distance)
    if close >= bc.min_fit * known and close >= bc.min_overlap * ex.size and close >= lc.min_beams:
        return close
    return None


def consistent(edges: list, x: F64, path: F64, config: Config) -> list:
    """The closures of ``edges`` that another closure from a different keyframe agrees with.

    Only closures whose keyframes lie within ``backend.agree_path`` of each other along the path
    can agree, so each closure is compared with those (found by the keyframes' path, sorted)
    instead of every other: the same closures kept, in time that grows with the closures
    nearby (900 closures along 10 km of path: 0.42 → 0.07 s)."""
    bc = config.backend
    if len(edges) < 2:
        return []
    matched = [compose(x[j], z) for j, _, z, _ in edges]
    moves = [compose(m, inverse(x[i])) for m, (_, i, _, _) in zip(matched, edges, strict=True)]
    at = np.array([path[i] for _, i, _, _ in edges])
    order = np.argsort(at, kind="stable")
    ordered = at[order]
    keep = []
    for k, (jk, ik, _, _) in enumerate(edges):
        # a window a little wider than agree_path; the exact test is below
        lo = np.searchsorted(ordered, path[ik] - bc.agree_path * (1 + 1e-9) - 1e-9, "left")
        hi = np.searchsorted(ordered, path[ik] + bc.agree_path * (1 + 1e-9) + 1e-9, "right")
        for m in np.sort(order[lo:hi]):
            jm, im = edges[m][0], edges[m][1]
            if im == ik:
                continue
            gap_i, gap_j = abs(path[ik] - path[im]), abs(path[jk] - path[jm])
            if gap_i > bc.agree_path or gap_j > bc.agree_path:
                continue
            moved = compose(moves[k], x[im])  # keyframe m corrected by closure k
            if not _same_place(moved, matched[m], gap_i + gap_j, config):
                continue
            keep.append(edges[k])
            break
    return keep


def _chi2(keys_x: F64, edge: tuple) -> float:
    e = edge_error(keys_x[edge[0]], keys_x[edge[1]], np.asarray(edge[2], dtype=np.float64))
    return float(e @ edge[3] @ e)


def close_loops_global(
    seq,
    steps: NDArray[np.int64],
    poses: F64,
    config: Config,
    path: F64 | None = None,
    loose_nodes: NDArray[np.bool_] | None = None,
    first: FirstRound | None = None,
) -> LoopResult:
    """:func:`slam.graph.close_loops` with the global closures added (module docstring).

    ``path`` is each node's distance along the trajectory (default: summed from ``poses``;
    a caller that passes a piece of a trajectory gives the whole one's). ``candidates`` counts
    the local candidates and the global searches; ``accepted`` the loop edges of the last
    round's graph, local and global. ``loose_nodes``: the chain is looser around them
    (:func:`slam.graph.chain_looseness`). ``first`` keeps (or gives) the first round's local
    and global closures (:class:`slam.graph.FirstRound`).
    """
    lc, bc = config.loops, config.backend
    if path is None:
        path = path_along(poses)
    table = node_hits(seq, steps, config)
    rounds = [0]

    def one_round(
        x: F64, keys: NDArray[np.int64], key_of: NDArray[np.int64], local: list
    ) -> tuple[list, F64 | None, int]:
        # beyond the drift window in the first round only: once it has pulled a long loop in,
        # the next round finds that loop's closures within the window
        rounds[0] += 1
        detect = partial(detect_global, seq, steps, x, path, config, local, table, rounds[0] == 1)
        if rounds[0] == 1 and first is not None:
            glob, searched = first.found("global", (seq, steps, poses, path, config), detect)
        else:
            glob, searched = detect()
        glob = consistent(glob, x, path, config)
        if not local and not glob:
            return [], None, searched
        local_edges = keyframe_edges(local, x, keys, key_of)
        global_edges = keyframe_edges(glob, x, keys, key_of)
        edges = local_edges + global_edges
        loose = chain_looseness(loose_nodes, keys, lc.flex_factor)
        start = None
        if global_edges:  # pull the verified global closures in, then gate them
            # without a robust kernel: their error at the drifted estimate is metres, which a
            # Cauchy kernel would treat as an outlier and never pull in
            robust = np.array([lc.robust] * len(local_edges) + [0.0] * len(global_edges))
            pulled = optimize(poses[keys], edges, lc, robust, loose=loose)
            passed = [e for e in global_edges if _chi2(pulled, e) <= bc.chi2_gate]
            edges = local_edges + passed
            if len(passed) == len(global_edges):
                return edges, pulled, searched  # every closure agrees: nothing to redo
            start = pulled if passed else None
        new_keys = optimize(poses[keys], edges, lc, start=start, loose=loose)
        return edges, new_keys, searched

    return loop_rounds(seq, steps, poses, path, table, config, one_round, first)
