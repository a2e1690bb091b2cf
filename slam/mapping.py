"""Maps: the dense log-odds occupancy grid and the per-particle tiled distance-field maps.

Both share one cell convention (:class:`~slam.grid_geometry.GridGeometry`, their ``geometry``):
``grid[iy, ix]`` is the cell whose lower-left corner is ``(origin_x + ix·res, origin_y + iy·res)``,
rows going up in y. Images for people are flipped so that +y points up on screen.

* :class:`OccupancyGrid`: what a run outputs (``map.npz``, ``map.png``); Bresenham log-odds
  updates (hit ``+log 4``, miss along the ray, clamped) through :mod:`slam.kernels.grid`; grows
  on demand.
* :class:`ParticleMaps`: one truncated distance field per particle (unsigned, or signed
  point-to-plane with ``rbpf.field = "plane"``), stored as copy-on-write tiles
  (:mod:`slam.kernels.field`), the sensor model of the ``rbpf`` method.
* :class:`VacancyGrid`: which of those maps' hits later rays went through (people, doors), shared
  by the particles (:mod:`slam.kernels.vacancy`); the ``rbpf`` matcher leaves them out.

Both refuse (one :class:`~slam.errors.UsageError` line) to grow an array past the memory budget of
:mod:`slam.budget`: a diverged trajectory must not take the machine down.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.budget import check_memory, growth_limit_share
from slam.config import MapConfig
from slam.grid_geometry import GridGeometry
from slam.io.atomic import write_npz
from slam.kernels.field import (
    FieldView,
    MatchOutput,
    MatchSettings,
    TilePool,
    insert_particles,
    insert_scans,
    insert_serial,
    match_particles,
    match_scans,
    recount_tiles,
    resample_tables,
)
from slam.kernels.grid import integrate_rays
from slam.kernels.vacancy import VacancyCells, VacancyView, observe

F64 = NDArray[np.float64]


def _check_growth(nbytes: float, what: str, width_m: float, height_m: float) -> None:
    """Refuse a map allocation larger than the memory budget (:mod:`slam.budget`: the run's
    ``checks.max_memory_share`` within :func:`slam.budget.growth_share`): the run's up-front
    estimate covers maps around the odometry, so only a trajectory that left that area (a
    diverged filter, corrupt odometry) or a drifting odometry's run that was let go on gets
    here."""
    check_memory(
        nbytes,
        f"{what} of {width_m:.0f} m × {height_m:.0f} m",
        "the trajectory left the area the odometry covers (a diverged filter or corrupt "
        "odometry), or scans reach that far (ranges in millimetres, not metres? set range_max "
        "or lidar.range_max for a laser's longest reading); check the configuration",
        share=growth_limit_share(),
        setting="checks.max_memory_share",
    )


def _grow_extent(lo: float, hi: float, cur_lo: float, cur_hi: float, margin: float):
    new_lo = min(cur_lo, lo - margin) if lo < cur_lo else cur_lo
    new_hi = max(cur_hi, hi + margin) if hi > cur_hi else cur_hi
    return new_lo, new_hi


def growth_steps(
    box: tuple[float, float, float, float],
    extent: tuple[float, float, float, float],
    step: float,
    margin: float,
) -> tuple[int, int, int, int] | None:
    """How many ``step``-sized rows and columns to add ``(left, bottom, right, top)`` so the box
    ``(xmin, ymin, xmax, ymax)`` lies inside ``extent`` (grown by at least ``margin`` on each side
    that must grow), or ``None`` when it already does. The one growth rule of the dense grid, the
    particle maps' tile tables and :func:`slam.stages.build_map`'s plan."""
    xmin, ymin, xmax, ymax = box
    x0, y0, x1, y1 = extent
    if xmin >= x0 and ymin >= y0 and xmax < x1 and ymax < y1:
        return None
    nx0, nx1 = _grow_extent(xmin, xmax, x0, x1, margin)
    ny0, ny1 = _grow_extent(ymin, ymax, y0, y1, margin)
    return (
        int(np.ceil((x0 - nx0) / step)),
        int(np.ceil((y0 - ny0) / step)),
        int(np.ceil((nx1 - x1) / step)),
        int(np.ceil((ny1 - y1) / step)),
    )


WorldRays = tuple[F64, NDArray[np.bool_], NDArray[np.int64], F64]
"""Rays of several scans in the world, scan after scan: ends ``(N, 2)``, which end on an
obstacle return ``(N,)``, the offsets ``(S + 1,)`` (scan ``i``'s rays are
``offsets[i]:offsets[i + 1]``) and the sensors ``(S, 2)``."""


def integrate_scan_rays(log_odds: NDArray[np.float32], views: NDArray[np.int64], origins: F64,
                        resolution: float, rays: WorldRays, config: MapConfig) -> None:  # fmt: skip
    """Bresenham log-odds update of ``log_odds`` with the ``rays`` of several scans, in order,
    with ``config``'s log-odds: scan ``i`` into the rows and columns ``views[i]`` = ``(r0, c0,
    h, w)`` of ``log_odds`` as a grid of ``resolution`` whose cell (0, 0) has its lower-left
    corner at ``origins[i]`` (``h = 0``: skipped; :func:`slam.kernels.grid.integrate_rays`).
    One scan into a whole grid is :meth:`OccupancyGrid.integrate`; :func:`slam.stages.build_map`
    replays a growing grid."""
    ends, hit, offsets, sensors = rays
    integrate_rays(
        log_odds, views, origins, float(resolution), sensors, offsets,
        np.ascontiguousarray(ends[:, 0]), np.ascontiguousarray(ends[:, 1]),
        np.ascontiguousarray(hit), config.log_odds_hit, config.log_odds_miss,
        config.log_odds_min, config.log_odds_max,
    )  # fmt: skip


class OccupancyGrid:
    """A dense log-odds occupancy grid that grows to contain what is integrated into it."""

    def __init__(self, config: MapConfig, center: tuple[float, float] = (0.0, 0.0)) -> None:
        self.config = config
        self.resolution = float(config.resolution)
        cells = max(int(np.ceil(config.initial_size_m / self.resolution)), 1)
        side = cells * self.resolution
        _check_growth(4.0 * cells * cells, "an occupancy grid", side, side)
        self.origin = np.array(
            [center[0] - cells * self.resolution / 2, center[1] - cells * self.resolution / 2]
        )
        self.log_odds = np.zeros((cells, cells), dtype=np.float32)

    @classmethod
    def from_arrays(
        cls, log_odds: NDArray[np.float32], resolution: float, origin: F64, config: MapConfig
    ) -> OccupancyGrid:
        """A grid wrapping existing arrays (e.g. read back from ``map.npz``)."""
        grid = cls.__new__(cls)
        grid.config = config
        grid.resolution = float(resolution)
        grid.origin = np.asarray(origin, dtype=np.float64).copy()
        grid.log_odds = np.ascontiguousarray(log_odds, dtype=np.float32)
        return grid

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, columns)`` of the grid."""
        return self.log_odds.shape  # type: ignore[return-value]

    @property
    def geometry(self) -> GridGeometry:
        """Where the grid lies (origin, resolution, shape; world↔cell)."""
        return GridGeometry.of(self.origin, self.resolution, self.shape)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` covered by the grid (m)."""
        return self.geometry.extent

    def ensure_contains(self, xmin: float, ymin: float, xmax: float, ymax: float) -> None:
        """Grow the grid (by at least ``grow_margin_m``) so the box lies inside it."""
        res = self.resolution
        grow = growth_steps((xmin, ymin, xmax, ymax), self.extent, res, self.config.grow_margin_m)
        if grow is None:
            return
        left, bottom, right, top = grow
        rows, cols = self.shape[0] + bottom + top, self.shape[1] + left + right
        _check_growth(4.0 * rows * cols, "an occupancy grid", cols * res, rows * res)
        self.log_odds = np.pad(self.log_odds, ((bottom, top), (left, right)))
        self.origin = self.origin - np.array([left * res, bottom * res])

    def integrate(self, sensor_xy: F64, endpoints: F64, hit: NDArray[np.bool_]) -> None:
        """Integrate rays from ``sensor_xy`` to world ``endpoints (K, 2)``; ``hit`` marks returns."""
        if endpoints.shape[0] == 0:
            return
        lo = np.minimum(endpoints.min(axis=0), sensor_xy)
        hi = np.maximum(endpoints.max(axis=0), sensor_xy)
        self.ensure_contains(lo[0], lo[1], hi[0], hi[1])
        g = self.geometry
        sensor = np.array([sensor_xy[:2]], dtype=np.float64)
        rays = (endpoints, hit, np.array([0, endpoints.shape[0]]), sensor)
        view = np.array([[0, 0, *g.shape]])
        integrate_scan_rays(
            self.log_odds, view, np.array([g.origin]), g.resolution, rays, self.config
        )

    def cropped(self, margin_m: float = 1.0) -> OccupancyGrid:
        """A copy reduced to the cells that were observed (log-odds ≠ 0) plus a margin."""
        known = self.log_odds != 0
        if not known.any():
            return OccupancyGrid.from_arrays(
                self.log_odds, self.resolution, self.origin, self.config
            )
        rows = np.flatnonzero(known.any(axis=1))
        cols = np.flatnonzero(known.any(axis=0))
        pad = int(np.ceil(margin_m / self.resolution))
        r0 = max(int(rows[0]) - pad, 0)
        r1 = min(int(rows[-1]) + pad + 1, self.shape[0])
        c0 = max(int(cols[0]) - pad, 0)
        c1 = min(int(cols[-1]) + pad + 1, self.shape[1])
        origin = self.origin + np.array([c0, r0]) * self.resolution
        return OccupancyGrid.from_arrays(
            self.log_odds[r0:r1, c0:c1].copy(), self.resolution, origin, self.config
        )

    def coarsened(self, factor: int = 2) -> OccupancyGrid:
        """This grid with cells ``factor`` times as large (same lower-left corner; rows and
        columns padded with unknown cells to a multiple of ``factor``), for pictures that need
        not be fine: a cell holds its block's largest log-odds when that is positive (any
        occupied cell keeps the wall), else its smallest (the freest). Later rays integrate at
        the coarse resolution (``config.resolution`` is the new cell)."""
        if factor < 1:
            raise ValueError(f"coarsened: expected a factor of at least 1, found {factor}")
        rows, cols = self.shape
        pad = ((0, -rows % factor), (0, -cols % factor))
        blocks = np.pad(self.log_odds, pad).reshape(
            (rows + pad[0][1]) // factor, factor, (cols + pad[1][1]) // factor, factor
        )
        high, low = blocks.max(axis=(1, 3)), blocks.min(axis=(1, 3))
        log_odds = np.where(high > 0, high, low).astype(np.float32)
        resolution = self.resolution * factor
        config = dataclasses.replace(self.config, resolution=resolution)
        return OccupancyGrid.from_arrays(log_odds, resolution, self.origin, config)

    def occupied(self) -> NDArray[np.bool_]:
        """Cells whose log-odds exceed the occupied threshold."""
        return self.log_odds > self.config.occupied_threshold

    def probability(self) -> NDArray[np.float32]:
        """Occupancy probability ``1 − 1/(1 + e^l)`` per cell."""
        return (1.0 - 1.0 / (1.0 + np.exp(self.log_odds))).astype(np.float32)

    def to_image(self) -> NDArray[np.uint8]:
        """Greyscale picture: occupied black, free white, unknown mid grey; +y up."""
        p = self.probability()
        img = (255.0 * (1.0 - p)).astype(np.uint8)
        return np.ascontiguousarray(img[::-1])

    def world_to_pixel(self, xy: F64) -> NDArray[np.int64]:
        """Pixel ``(column, row)`` in :meth:`to_image` of world points ``(..., 2)``."""
        return self.geometry.world_to_pixel(xy)

    def save_npz(self, path: Path) -> None:
        """Write ``log_odds``, ``resolution`` and ``origin`` to ``path`` atomically."""
        arrays = {
            "log_odds": self.log_odds,
            "resolution": np.float64(self.resolution),
            "origin": self.origin.astype(np.float64),
        }
        write_npz(Path(path), arrays)


@dataclass
class MatchResult:
    """What scan matching all particles returns."""

    poses: F64
    """``(P, 3)`` refined poses (the predicted pose where the match was not trusted)."""
    loglik: F64
    """``(P,)`` log-likelihood of the scan at each refined pose."""
    inliers: F64
    """``(P,)`` fraction of beams within the distance cap of a known surface."""
    hessian: F64
    """``(P, 3, 3)`` Gauss-Newton Hessian of the negative log-likelihood at each refined pose."""
    probe: MatchResult | None = None
    """The basin probe's matches when :meth:`ParticleMaps.match` was given ``probe_yaws``: one
    row per yaw."""


def likelihood_tables(
    sigmas: F64, z_hit: float, z_rand: float, dmax: float, size: int = 512
) -> tuple[F64, float]:
    """Per-sigma tables of the likelihood-field cost and Gauss-Newton weight over ``|d| ∈ [0, dmax]``.

    ``tables[level, 0, i]`` is ``−log(z_hit·exp(−d²/2σ²) + z_rand)`` and ``tables[level, 1, i]``
    is ``γ/σ²`` with ``γ = z_hit·φ/(z_hit·φ + z_rand)``, at ``d = i·dmax/(size − 1)``; the last
    entry also stands for unknown cells. Returns the tables and ``1/step``.
    """
    d = np.linspace(0.0, dmax, size)
    out = np.empty((len(sigmas), 2, size))
    for level, sigma in enumerate(sigmas):
        phi = z_hit * np.exp(-0.5 * (d / sigma) ** 2)
        out[level, 0] = -np.log(phi + z_rand)
        out[level, 1] = phi / (phi + z_rand) / sigma**2
    return out, (size - 1) / dmax


def tile_spans(tables: NDArray[np.int32]) -> NDArray[np.int64]:
    """Per row of ``(P, rows, cols)`` tile tables, the first and the last column where any
    table holds a tile (``(cols, -1)`` in a row without any): the tightest
    :attr:`~slam.kernels.field.TilePool.spans` of those tables."""
    rows, cols = tables.shape[1:]
    spans = np.tile(np.array([cols, -1], dtype=np.int64), (rows, 1))
    used = (tables >= 0).any(axis=0)
    r, c = np.nonzero(used)
    np.minimum.at(spans[:, 0], r, c)
    np.maximum.at(spans[:, 1], r, c)
    return spans


class ParticleMaps:
    """One truncated distance-field map per particle, as shared copy-on-write tiles.

    Two layers per tile (:mod:`slam.kernels.field`): ``dist``, the Euclidean distance to the
    nearest hit, and ``surface``, what the matcher reads: the signed point-to-plane distance with
    ``signed``, else the Euclidean distance again — then one array is both (``dist is
    surface``), NaN where no hit is near.
    """

    def __init__(
        self,
        particles: int,
        resolution: float,
        dmax: float,
        tile: int = 16,
        center: tuple[float, float] = (0.0, 0.0),
        size_m: float = 40.0,
        grow_margin_m: float = 10.0,
        capacity: int = 1024,
        signed: bool = False,
    ) -> None:
        self.signed = bool(signed)
        self.resolution = float(resolution)
        self.dmax = float(dmax)
        if tile < 2 or tile & (tile - 1):
            raise ValueError(f"tile: expected a power of two, found {tile}")
        self.tile = int(tile)
        self.shift = int(tile).bit_length() - 1
        self.grow_margin_m = float(grow_margin_m)
        tile_m = self.tile * self.resolution
        n = max(int(np.ceil(size_m / tile_m)), 1)
        _check_growth(
            4.0 * particles * n * n, f"{particles} particle-map tables", n * tile_m, n * tile_m
        )
        self.origin = np.array([center[0] - n * tile_m / 2, center[1] - n * tile_m / 2])
        self.tables = np.full((particles, n, n), -1, dtype=np.int32)
        self.spans = tile_spans(self.tables)
        """Per row of the tables, the columns that may hold a tile (kept, not recomputed: a
        superset of :func:`tile_spans`; :class:`~slam.kernels.field.TilePool`)."""
        self._spare: NDArray[np.int32] | None = None
        """The tables before the last resampling: the next one writes into it (no fresh pages)."""
        self.surface = np.empty((capacity, self.tile, self.tile), dtype=np.float32)
        # the unsigned field's two layers hold the same values: one array serves as both
        self.dist = self.surface if not self.signed else np.empty_like(self.surface)
        self.refcount = np.zeros(capacity, dtype=np.int32)
        self.free_stack = np.arange(capacity - 1, -1, -1, dtype=np.int32)
        self.free_top = np.array([capacity], dtype=np.int64)

    @property
    def geometry(self) -> GridGeometry:
        """Where the maps lie: every particle's table covers the same cells."""
        _, nty, ntx = self.tables.shape
        return GridGeometry.of(self.origin, self.resolution, (nty << self.shift, ntx << self.shift))

    @property
    def capacity(self) -> int:
        """Tiles allocated in the pool (used or free)."""
        return int(self.dist.shape[0])

    @property
    def one_layer(self) -> bool:
        """Whether one array holds both layers (the unsigned field: ``dist is surface``)."""
        return self.dist is self.surface

    @property
    def tiles_in_use(self) -> int:
        """Tiles referenced by at least one particle."""
        return self.capacity - int(self.free_top[0])

    def memory_bytes(self) -> int:
        """Bytes held by the pool, the tables and the bookkeeping arrays."""
        return int(
            (0 if self.one_layer else self.dist.nbytes)
            + self.surface.nbytes
            + self.tables.nbytes
            + (0 if self._spare is None else self._spare.nbytes)
            + self.refcount.nbytes
            + self.free_stack.nbytes
        )

    def _grow_pool(self) -> None:
        old = self.capacity
        new = old * 2
        tile_m = self.tile * self.resolution
        _, nty, ntx = self.tables.shape
        layers = 1 if self.one_layer else 2
        _check_growth(
            (new + old) * 4.0 * layers * self.tile * self.tile,  # while the old ones are copied
            f"a pool of {new} particle-map tiles",
            ntx * tile_m,
            nty * tile_m,
        )
        one_layer = self.one_layer
        for name in ("surface",) if one_layer else ("dist", "surface"):
            layer = np.empty((new, self.tile, self.tile), dtype=np.float32)
            layer[:old] = getattr(self, name)
            setattr(self, name, layer)
        if one_layer:
            self.dist = self.surface
        self.refcount = np.concatenate([self.refcount, np.zeros(new - old, np.int32)])
        top = int(self.free_top[0])
        stack = np.empty(new, dtype=np.int32)
        stack[:top] = self.free_stack[:top]
        stack[top : top + new - old] = np.arange(new - 1, old - 1, -1, dtype=np.int32)
        self.free_stack = stack
        self.free_top[0] = top + new - old

    def _extent(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` (m) the tile tables cover."""
        tile_m = self.tile * self.resolution
        _, nty, ntx = self.tables.shape
        x0, y0 = self.origin
        return x0, y0, x0 + ntx * tile_m, y0 + nty * tile_m

    def ensure_contains(self, xmin: float, ymin: float, xmax: float, ymax: float) -> None:
        """Grow every particle's tile table so the box lies inside it."""
        tile_m = self.tile * self.resolution
        _, nty, ntx = self.tables.shape
        grow = growth_steps((xmin, ymin, xmax, ymax), self._extent(), tile_m, self.grow_margin_m)
        if grow is None:
            return
        left, bottom, right, top = grow
        rows, cols = nty + bottom + top, ntx + left + right
        particles = self.tables.shape[0]
        _check_growth(
            8.0 * particles * rows * cols,  # the tables and their copy while resampling
            f"{particles} particle-map tables",
            cols * tile_m,
            rows * tile_m,
        )
        self.tables = np.pad(
            self.tables, ((0, 0), (bottom, top), (left, right)), constant_values=-1
        )
        self.spans = tile_spans(self.tables)
        self._spare = None
        self.origin = self.origin - np.array([left * tile_m, bottom * tile_m])

    def insert(self, poses: F64, hx: F64, hy: F64, nx: F64, ny: F64, skip_below: float) -> None:
        """Insert hits ``(hx, hy)`` with unit normals ``(nx, ny)`` (robot frame) at ``poses``.

        One kernel call, :func:`~slam.kernels.field.insert_particles`, in three steps: which
        hits add something (parallel), copy-on-write of the tiles they touch (serial, cheap),
        then the distance updates (parallel: each particle writes only tiles it owns alone); a
        pool that runs out of tiles on the way grows and the call resumes. One pose (a scan
        placed into one map) takes one serial kernel instead,
        :func:`~slam.kernels.field.insert_serial`, which gives the same maps.
        """
        if hx.shape[0] == 0:
            return
        poses = np.ascontiguousarray(poses)
        hits = np.asarray(np.stack([hx, hy, nx, ny]), dtype=np.float64)
        keep = np.empty((poses.shape[0], hx.shape[0]), dtype=np.bool_)
        if poses.shape[0] == 1:
            start = 0
            while True:
                start = insert_serial(
                    self._pool(), poses, hits, skip_below, self.signed, keep, start
                )
                if start < 0:
                    return
                self._grow_pool()
        stopped = insert_particles(
            self._pool(), poses, hits, skip_below, keep, self.signed, 0, True
        )
        while stopped >= 0:
            self._grow_pool()
            stopped = insert_particles(
                self._pool(), poses, hits, skip_below, keep, self.signed, stopped, False
            )

    def insert_scans(
        self, poses: F64, hits: F64, offsets: NDArray[np.int64], reach: F64, skip_below: float
    ) -> None:
        """Insert several scans, in order, into a one-particle map (a submap of the back end).

        Scan ``k`` is ``hits[:, offsets[k]:offsets[k + 1]]`` (``(4, N)``: robot-frame hits and
        unit normals, every scan's side by side; ``(2, N)``: the hits alone, standing for their
        own normals as in :meth:`insert` for the unsigned field) at ``poses[k]``; before it goes in, the tables
        grow to contain ``poses[k] ± reach[k]`` (a scan without hits is skipped). The same map,
        bit for bit, as :meth:`ensure_contains` and :meth:`insert` scan by scan, in one kernel
        call per stretch of scans that needs no growth
        (:func:`~slam.kernels.field.insert_scans`).
        """
        if self.tables.shape[0] != 1:
            raise ValueError(
                f"insert_scans: expected a one-particle map, found {self.tables.shape[0]}"
            )
        poses = np.ascontiguousarray(poses, dtype=np.float64)
        hits = np.ascontiguousarray(hits, dtype=np.float64)
        offsets = np.ascontiguousarray(offsets, dtype=np.int64)
        boxes = np.stack(
            [poses[:, 0] - reach, poses[:, 1] - reach, poses[:, 0] + reach, poses[:, 1] + reach]
        )
        empty = offsets[1:] == offsets[:-1]
        n = poses.shape[0]
        k = 0
        while k < n:
            xmin, ymin, xmax, ymax = boxes[:, k]
            if not empty[k]:
                self.ensure_contains(xmin, ymin, xmax, ymax)
            x0, y0, x1, y1 = self._extent()
            b = boxes[:, k + 1 :]
            inside = empty[k + 1 :] | (
                (b[0] >= x0) & (b[1] >= y0) & (b[2] < x1) & (b[3] < y1)
            )  # the test of growth_steps: these scans need no growth
            outside = np.flatnonzero(~inside)
            stop = n if outside.size == 0 else k + 1 + int(outside[0])
            start = k
            while True:
                start = insert_scans(
                    self._pool(), poses, hits, offsets, skip_below, self.signed, start, stop
                )
                if start < 0:
                    break
                self._grow_pool()
            k = stop

    def _pool(self) -> TilePool:
        """The tiles as the insertion kernels write them (built anew: growing replaces arrays)."""
        (ox, oy), res = self.geometry.origin, self.resolution
        return TilePool(
            self.dist,
            self.surface,
            self.refcount,
            self.free_stack,
            self.free_top,
            self.tables,
            self.spans,
            self.shift,
            ox,
            oy,
            res,
            self.dmax,
            self.one_layer,
        )

    def share_from(self, particle: int) -> None:
        """Make every particle's map the map of ``particle`` (shared tiles)."""
        self.tables[:] = self.tables[particle]
        self.free_top[0] = recount_tiles(self.tables, self.refcount, self.free_stack)

    def resample(self, indices: NDArray[np.int64]) -> None:
        """Children share their parents' tiles; tiles nobody uses go back to the free stack.
        One kernel (:func:`~slam.kernels.field.resample_tables`): the tables copied in
        parallel, each surviving parent's tiles counted once, times its children.

        The copy goes into the tables the resampling before this one left behind: a fresh array
        of a big building's size (fr-clinic: 37 MB) costs more in page faults than the copy.
        Only the entries within :attr:`spans` are copied: outside them both hold -1."""
        parents = np.ascontiguousarray(indices, dtype=np.int64)
        children = np.bincount(parents, minlength=self.tables.shape[0]).astype(np.int64)
        shape = (parents.shape[0], *self.tables.shape[1:])
        out = self._spare
        if out is None or out.shape != shape:
            out = np.full(shape, -1, dtype=self.tables.dtype)
        self.free_top[0] = resample_tables(
            self.tables, self.spans, parents, children, out, self.refcount, self.free_stack
        )
        self._spare, self.tables = self.tables, out

    def field(self, particle: int | None = None) -> FieldView:
        """The map as the matching kernels read it (:class:`~slam.kernels.field.FieldView`).

        Its table holds every particle's tile tables, or only ``particle``'s when given.
        """
        tables = self.tables if particle is None else self.tables[particle]
        g = self.geometry
        return FieldView(self.surface, tables, self.shift, *g.origin, 1.0 / g.resolution)

    def match(
        self,
        poses: F64,
        ex: F64,
        ey: F64,
        luts: tuple[F64, float],
        max_iter: int,
        tolerance: float,
        min_inliers: float,
        coarse_stride: int = 1,
        probe_yaws: F64 | None = None,
        particle: int | None = None,
        vacancy: VacancyView | None = None,
    ) -> MatchResult:
        """Scan-match every particle's predicted pose against its own map and score it — or,
        with ``particle``, every pose of ``poses`` against that particle's map.

        ``luts`` comes from :func:`likelihood_tables`. With ``probe_yaws`` (rad), the basin probe
        in the same kernel call (:func:`~slam.kernels.field.match_particles`): the predicted
        pose of the particle whose match scores highest, turned by each yaw, matched against
        that particle's map, into the result's ``probe``. With ``vacancy``, returns whose
        nearest hit later rays went through count as unexplained (:class:`VacancyGrid`).
        """
        yaws = _NO_YAWS if probe_yaws is None else np.ascontiguousarray(probe_yaws, np.float64)
        out, probe = _match_result(poses.shape[0]), _match_result(yaws.shape[0])
        view = self.field()
        if vacancy is not None:
            view = view._replace(
                vacated=vacancy.vacated,
                vac_ox=vacancy.ox,
                vac_oy=vacancy.oy,
                vac_res=vacancy.res,
            )
        if particle is not None:  # the kernel reads row p's table for pose p
            one = self.tables[particle : particle + 1]
            view = view._replace(table=np.ascontiguousarray(np.repeat(one, len(poses), axis=0)))
        match_particles(
            view,
            np.ascontiguousarray(poses),
            np.stack([ex, ey]).astype(np.float64, copy=False),
            _settings(luts, max_iter, tolerance, coarse_stride, min_inliers),
            MatchOutput(out.poses, out.loglik, out.inliers, out.hessian),
            yaws,
            MatchOutput(probe.poses, probe.loglik, probe.inliers, probe.hessian),
        )
        if probe_yaws is not None:
            out.probe = probe
        return out

    def register(
        self,
        poses: F64,
        ex: F64,
        ey: F64,
        counts: NDArray[np.int64],
        luts: tuple[F64, float],
        max_iter: int,
        tolerance: float,
        min_inliers: float,
        particle: int = 0,
        coarse_stride: int = 1,
    ) -> F64:
        """Refine many scan poses ``(N, 3)`` against the map of ``particle``.

        Scan ``k``'s endpoints are ``ex[k, :counts[k]]``, ``ey[k, :counts[k]]`` (robot frame).
        """
        out = np.empty_like(poses)
        match_scans(
            self.field(particle),
            np.ascontiguousarray(poses),
            ex,
            ey,
            counts,
            _settings(luts, max_iter, tolerance, coarse_stride, min_inliers),
            out,
        )
        return out


class VacancyGrid:
    """Where the particle maps' hits were later seen through (:mod:`slam.kernels.vacancy`): a
    dense grid of twice the particle maps' cell, four bytes a cell, grown like
    :class:`OccupancyGrid`; one for every particle, written along the best particle's poses.

    A ray counts a miss on a live hit only over its range less ``margin`` + ``margin_share`` of
    it (a return on the same surface, a few centimetres off, must not erase it) and only when it
    crosses the hit's surface at least ``asin(min_cos)`` off it (a ray grazing a wall does not
    erase the wall's far returns).
    """

    MIN_COS = 0.5
    """A miss counts when the ray meets the hit's surface at 30° or more."""
    MARGIN_SHARE = 0.02
    """... and passes the cell at least ``margin`` + 2 % of its range short of its own end."""

    def __init__(
        self,
        resolution: float,
        center: tuple[float, float],
        after: int,
        margin: float,
        size_m: float,
        grow_margin_m: float,
    ) -> None:
        self.resolution, self.grow_margin_m = float(resolution), float(grow_margin_m)
        self.after, self.margin = int(after), float(margin)
        """Misses that make a hit gone; what a ray keeps clear of its own end (m)."""
        cells = max(int(np.ceil(size_m / self.resolution)), 1)
        _check_growth(4.0 * cells * cells, "a vacancy grid", size_m, size_m)
        half = cells * self.resolution / 2
        self.origin = np.array([center[0] - half, center[1] - half])
        self.layers = np.zeros((4, cells, cells), dtype=np.uint8)
        """``state``, ``misses``, ``normal``, ``vacated`` (:class:`VacancyCells`)."""

    @property
    def geometry(self) -> GridGeometry:
        """Where the grid lies (origin, resolution, shape; world↔cell)."""
        return GridGeometry.of(self.origin, self.resolution, self.layers.shape[1:])

    def ensure_contains(self, xmin: float, ymin: float, xmax: float, ymax: float) -> None:
        """Grow the grid (by at least ``grow_margin_m``) so the box lies inside it."""
        res = self.resolution
        box = (xmin, ymin, xmax, ymax)
        grow = growth_steps(box, self.geometry.extent, res, self.grow_margin_m)
        if grow is None:
            return
        left, bottom, right, top = grow
        rows, cols = self.layers.shape[1] + bottom + top, self.layers.shape[2] + left + right
        _check_growth(4.0 * rows * cols, "a vacancy grid", cols * res, rows * res)
        self.layers = np.pad(self.layers, ((0, 0), (bottom, top), (left, right)))
        self.origin = self.origin - np.array([left * res, bottom * res])

    def observe(self, sensor: F64, rays: F64, hits: F64, normals: F64) -> None:
        """One scan seen from world ``sensor`` ``(x, y)``: its rays' world ends ``(N, 2)`` (the
        returns and the readings past the laser's range), then its returns ``(K, 2)`` with their
        surface normals' world angles ``(K,)``."""
        pts = np.concatenate([rays, hits, sensor[None, :2]])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        self.ensure_contains(lo[0], lo[1], hi[0], hi[1])
        d = rays - sensor[None, :2]
        length = np.hypot(d[:, 0], d[:, 1])
        unit = d / np.where(length > 0, length, 1.0)[:, None]
        counted = length * (1.0 - self.MARGIN_SHARE) - self.margin
        g = self.geometry
        state, misses, normal, vacated = self.layers
        cells = VacancyCells(state, misses, normal, vacated, *g.origin, g.resolution, 1)
        observe(
            cells,
            np.ascontiguousarray(sensor[:2], dtype=np.float64),
            np.ascontiguousarray(np.stack([unit[:, 0], unit[:, 1], counted])),
            np.ascontiguousarray(np.stack([hits[:, 0], hits[:, 1], normals])),
            self.MIN_COS,
            self.after,
        )

    def view(self) -> VacancyView:
        """The grid as the matcher reads it."""
        g = self.geometry
        return VacancyView(self.layers[3], *g.origin, g.resolution)

    def memory_bytes(self) -> int:
        """Bytes of the grid's layers."""
        return int(self.layers.nbytes)


_NO_YAWS = np.zeros(0)
"""No basin probe (:meth:`ParticleMaps.match`)."""


def _match_result(n: int) -> MatchResult:
    """Room for ``n`` matches."""
    return MatchResult(np.empty((n, 3)), np.empty(n), np.empty(n), np.empty((n, 3, 3)))


def _settings(
    luts: tuple[F64, float], max_iter: int, tolerance: float, coarse_stride: int, min_inliers: float
) -> MatchSettings:
    """The matcher's settings as its kernels take them (one type whatever the caller passed)."""
    return MatchSettings(
        luts[0], float(luts[1]), int(max_iter), float(tolerance), int(coarse_stride),
        float(min_inliers),
    )  # fmt: skip
