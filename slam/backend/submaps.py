"""Submaps: stretches of ``backend.submap_length`` metres of path, as grids a search can use.

A submap is the set of node scans whose path position lies in one stretch, taken at the nodes'
current poses. It is built twice, on demand: as a branch-and-bound pyramid
(:func:`slam.kernels.bnb.max_pyramid` of the hits' likelihood at ``backend.resolution``) for the
global search, and as a one-particle distance-field map (:class:`slam.mapping.ParticleMaps`,
kept as the field alone: :func:`compact_view`) for the Levenberg-Marquardt refinement and the
fit check of :mod:`slam.graph`. Both are kept in a cache that the search's threads share
(:class:`SubmapCache`): a submap is built once per round however many keyframes, on whichever
thread, ask for it, as long as it stays within the cache's budget of megabytes (the least
recently used dropped first).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from slam.config import Config
from slam.kernels.bnb import max_pyramid, splat_likelihood
from slam.kernels.field import FieldView
from slam.scans import ScanHits

F64 = NDArray[np.float64]
V = TypeVar("V")

SUBMAP_CACHE_MB = 96.0
"""Megabytes of submaps a :class:`SubmapCache` keeps (pyramids and field views together), the
least recently used dropped first. A round's submaps took at most 47 MB per cache on intel and
about 100 MB on mit-killian (seed 0; a pyramid ~1 MB, a compact field view ~0.3 MB). Kept by
count instead (16 of each kind), intel's loop closing built 902 submaps where 597 now do (one
thread), and took 7.4-7.8 s where it now takes 6.6-7.5 s (mit-killian 12.6-13.0 s, now
9.8-10.2 s; the same closures and poses, bit for bit)."""


@dataclass
class Pyramid:
    """A submap's branch-and-bound grid: ``levels`` of ``(H, W)`` max blocks."""

    levels: NDArray[np.float32]
    origin: tuple[float, float]
    resolution: float


def stretches(path: F64, length: float) -> list[tuple[int, int]]:
    """Node ranges ``[lo, hi)`` of consecutive ``length``-metre stretches of ``path``."""
    edges = np.searchsorted(path, np.arange(0.0, path[-1] + length, length), "left")
    edges = np.unique(np.append(edges, path.size))
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def world_hits(seq, step: int, pose: F64, max_range: float, beams: int = 0) -> tuple[F64, F64]:
    """World-frame hits of scan ``step`` at ``pose`` within ``max_range`` of the sensor."""
    hx, hy = seq.hits(step, beams)
    keep = hx * hx + hy * hy <= max_range * max_range
    hx, hy = hx[keep], hy[keep]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return pose[0] + c * hx - s * hy, pose[1] + s * hx + c * hy


class SubmapCache:
    """The submaps of one round (poses fixed), built when first asked for and kept while they
    fit in ``budget_mb`` megabytes (the least recently used dropped first; the newest is always
    kept).

    Thread-safe: the global search's threads share one cache. A submap asked for while another
    thread builds it is waited for, not built again; building is deterministic, so what a
    caller gets never depends on which thread built it or on what was evicted (only the time).
    """

    def __init__(
        self,
        seq,
        steps: NDArray[np.int64],
        poses: F64,
        config: Config,
        budget_mb: float = SUBMAP_CACHE_MB,
        table: ScanHits | None = None,
    ):
        self.seq, self.steps, self.poses, self.config = seq, steps, poses, config
        self.table = table  # the nodes' hits for the field maps (slam.graph.node_hits)
        self.budget = budget_mb * 1e6
        self._store: OrderedDict[tuple[str, int, int], tuple[object, int]] = OrderedDict()
        self.held = 0
        """Bytes of the submaps kept now."""
        self._lock = threading.Lock()
        self._building: dict[tuple[str, int, int], threading.Event] = {}
        self.builds = 0
        """Submaps built so far (pyramids and field maps)."""

    def _cached(self, key: tuple[str, int, int], build: Callable[[], V]) -> V:
        """The submap ``key`` (kind, first node, end node), built by ``build`` when it is not
        kept (outside the lock, by one thread at a time)."""
        while True:
            with self._lock:
                if key in self._store:
                    self._store.move_to_end(key)
                    return self._store[key][0]
                pending = self._building.get(key)
                if pending is None:
                    done = self._building[key] = threading.Event()
            if pending is not None:  # another thread builds it: wait, then look again
                pending.wait()
                continue
            try:
                value = build()
                size = _nbytes(value)
                with self._lock:
                    self.builds += 1
                    self._store[key] = (value, size)
                    self.held += size
                    while self.held > self.budget and len(self._store) > 1:
                        self.held -= self._store.popitem(last=False)[1][1]
                return value
            finally:
                with self._lock:
                    del self._building[key]
                done.set()

    def _node_hits(self, lo: int, hi: int) -> tuple[F64, F64]:
        bc, lc = self.config.backend, self.config.loops
        xs, ys = [], []
        for k in range(lo, hi, lc.submap_stride):
            hx, hy = world_hits(
                self.seq, int(self.steps[k]), self.poses[k], bc.submap_range,
                self.config.rbpf.insert_beams,
            )  # fmt: skip
            xs.append(hx)
            ys.append(hy)
        if not xs:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(xs), np.concatenate(ys)

    def pyramid(self, lo: int, hi: int) -> Pyramid | None:
        """The branch-and-bound grid of nodes ``[lo, hi)`` (None without hits)."""
        return self._cached(("pyramid", lo, hi), lambda: self._pyramid(lo, hi))

    def _pyramid(self, lo: int, hi: int) -> Pyramid | None:
        bc = self.config.backend
        hx, hy = self._node_hits(lo, hi)
        if hx.size == 0:
            return None
        res = bc.resolution
        margin = 3.0 * bc.sigma + res
        ox, oy = float(hx.min() - margin), float(hy.min() - margin)
        w = int(np.ceil((hx.max() + margin - ox) / res)) + 1
        h = int(np.ceil((hy.max() + margin - oy) / res)) + 1
        grid = np.zeros((h, w), dtype=np.float32)
        splat_likelihood(hx, hy, ox, oy, res, bc.sigma, grid)
        return Pyramid(max_pyramid(grid, bc.levels), (ox, oy), res)

    def field_view(self, lo: int, hi: int) -> FieldView:
        """The distance field of nodes ``[lo, hi)`` as the matching kernels read it (the map
        :mod:`slam.graph` builds, :func:`compact_view`)."""
        return self._cached(("map", lo, hi), lambda: self._field_view(lo, hi))

    def _field_view(self, lo: int, hi: int) -> FieldView:
        from slam.graph import empty_submap, insert_nodes

        maps = empty_submap(self.poses[lo], self.config)
        nodes = np.arange(lo, hi, self.config.loops.submap_stride)
        insert_nodes(maps, self._hits_table(), nodes, self.poses, self.config)
        return compact_view(maps.field(0))

    def _hits_table(self) -> ScanHits:
        """The nodes' hits the field maps are built from (:func:`slam.graph.node_hits`; made
        once, by the first thread that needs them, when the cache was not given them)."""
        from slam.graph import node_hits

        with self._lock:
            if self.table is None:
                self.table = node_hits(self.seq, self.steps, self.config)
            return self.table


def _nbytes(value: object) -> int:
    """The bytes of a cached submap's arrays (a :class:`Pyramid`, a field view, or None)."""
    if isinstance(value, Pyramid):
        return int(value.levels.nbytes)
    if isinstance(value, tuple):
        return sum(int(a.nbytes) for a in value if isinstance(a, np.ndarray))
    return 0


def compact_view(view: FieldView) -> FieldView:
    """``view`` (one particle's) holding only the tiles its table uses, renumbered in order:
    the same field values at every point, the same bits from the kernels. A submap's pool is
    allocated for ``loops.submap_tiles`` tiles (2 MB) and uses a fraction of them, so the cache
    keeps the field alone."""
    table = view.table
    used = np.unique(table[table >= 0])
    compact = np.full(table.shape, -1, dtype=table.dtype)
    known = table >= 0
    compact[known] = np.searchsorted(used, table[known]).astype(table.dtype)
    return view._replace(surface=np.ascontiguousarray(view.surface[used]), table=compact)
