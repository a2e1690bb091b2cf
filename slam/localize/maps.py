"""The map a robot localizes in: occupancy from a saved run, and the likelihood field over it.

A :class:`LikelihoodMap` holds what both localization filters read:

* ``occupied`` and ``free`` cell masks (``[iy, ix]``, the convention of :mod:`slam.mapping`:
  cell ``(ix, iy)`` has its lower-left corner at ``origin + (ix, iy)·resolution``);
* ``distance``: the Euclidean distance (m) from every cell centre to the nearest occupied cell
  centre, the *likelihood field* of Thrun et al. (ch. 6.4). It is the exact distance transform of
  the occupied cells (``cv2.distanceTransform``, precise mask), computed once per map: a saved
  map does not change while the robot localizes, unlike the per-particle fields of
  :mod:`slam.kernels.field`, which grow with every scan;
* ``grid``: the occupancy grid itself, for pictures and recordings;
* the *wall surface* field (:meth:`LikelihoodMap.surface_view`), what MCL weighs and the pose
  refinement matches against: the distance to the walls at sub-cell precision, on a grid
  ``subdivision`` times finer than the map (:func:`wall_surface`).

Why the wall surface. A distance field measured to occupied cell *centres* puts every wall on the
cell grid, and where a wall is two cells thick (70 % of intel's occupied cells lie in a fully
occupied 2 × 2 block: a wall on a cell boundary, or the cell behind a wall that returns overshoot
into and no ray clears) its bilinear valley is flat over a whole cell: a return anywhere in it
costs nothing, so the pose along the wall's normal is pinned only to within a cell. The log-odds
hold what the binary mask drops: how often each cell was hit. Each occupied cell's *wall point*
is the log-odds-weighted centroid of the occupied cells of its 3 × 3 neighbourhood (a band of a
saturated cell and an overshoot cell collapses onto one line near the saturated one; a thin
wall stays on its cells); wall points of neighbouring occupied cells are joined by segments,
sampled on the finer grid, and the field is the distance from each fine cell centre to the
nearest sample. Measured on the maps of the default configuration (tools/benches/localize.py,
seed 0), relation error with ``localize.subdivision`` = 2: intel 0.0254 → 0.0230 m (SLAM
0.0223), aces 0.0516 → 0.0451 m, fr079 0.0423 → 0.0375 m. Found on the way (intel): the wall
points drawn into fine cells and measured cell centre to cell centre, 0.0232 m at 2 and 0.0229 m
at 4 (16 times the map's memory); equal weights (the geometric centroid), 0.0238 m at 4;
blurring the cell-centre field by one cell, 0.0267 m. A wall between two fine cell centres is
still a flat valley one fine cell wide (bilinear interpolation of a distance).

:func:`load_map` reads ``RUN_DIR/map.npz`` (what ``slam run`` writes) or a ``map.npz`` file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.budget import DEFAULT_MEMORY_SHARE, check_memory
from slam.config import MapConfig
from slam.errors import DataError
from slam.localize.kernels import DistanceView
from slam.mapping import OccupancyGrid

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class LikelihoodMap:
    """Occupancy masks and the distance field of a saved map (see the module docstring)."""

    grid: OccupancyGrid
    """The occupancy grid (log-odds) the masks come from."""
    occupied: NDArray[np.bool_]
    """``(H, W)`` cells holding an obstacle."""
    free: NDArray[np.bool_]
    """``(H, W)`` cells observed free (where the robot may be)."""
    distance: NDArray[np.float32]
    """``(H, W)`` distance from each cell centre to the nearest occupied cell centre (m): the
    histogram filter's field (its states are cells)."""
    _surfaces: dict[int, NDArray[np.float32]] = field(default_factory=dict, repr=False)

    @property
    def resolution(self) -> float:
        """Cell size (m)."""
        return self.grid.resolution

    @property
    def origin(self) -> F64:
        """World position of the lower-left corner of cell ``(0, 0)`` (m)."""
        return self.grid.origin

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, columns)``."""
        return self.grid.shape

    @classmethod
    def from_grid(cls, grid: OccupancyGrid, source: str = "map") -> LikelihoodMap:
        """Masks and distance field of ``grid``: occupied above ``map.occupied_threshold``, free
        where the log-odds are negative (observed, and more often traversed than hit).
        ``source`` names the map in a message."""
        import cv2

        occupied = np.ascontiguousarray(grid.log_odds > grid.config.occupied_threshold)
        free = np.ascontiguousarray((grid.log_odds < 0) & ~occupied)
        if not occupied.any():
            raise DataError(
                f"{source}: no occupied cell (log-odds above map.occupied_threshold = "
                f"{grid.config.occupied_threshold:g}), nothing to localize against"
            )
        # distanceTransform measures from every non-zero pixel to the nearest zero pixel
        source = np.where(occupied, 0, 255).astype(np.uint8)
        pixels = cv2.distanceTransform(source, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        distance = np.ascontiguousarray(pixels * np.float32(grid.resolution), dtype=np.float32)
        return cls(grid, occupied, free, distance)

    @classmethod
    def from_masks(
        cls,
        occupied: NDArray[np.bool_],
        free: NDArray[np.bool_],
        resolution: float,
        origin: tuple[float, float],
        source: str = "map",
    ) -> LikelihoodMap:
        """A map from masks (tests, hand-made worlds, map_server files): occupied cells get
        log-odds +10, free −10, the rest 0 (unknown). ``source`` names the map in a message."""
        occupied = np.asarray(occupied, dtype=bool)
        if not occupied.any():
            raise DataError(f"{source}: no occupied cell, nothing to localize against")
        log_odds = np.where(occupied, 10.0, np.where(np.asarray(free, bool), -10.0, 0.0))
        grid = OccupancyGrid.from_arrays(
            log_odds.astype(np.float32), resolution, np.asarray(origin, np.float64), MapConfig()
        )
        return cls.from_grid(grid, source)

    def view(self) -> DistanceView:
        """The distance field as the likelihood kernels read it."""
        return DistanceView(
            self.distance, float(self.origin[0]), float(self.origin[1]), 1.0 / self.resolution
        )

    def surface(
        self, subdivision: int, memory_share: float = DEFAULT_MEMORY_SHARE
    ) -> NDArray[np.float32]:
        """The wall-surface distance field on a grid ``subdivision`` times finer than the map
        (:func:`wall_surface`, within ``memory_share`` of the machine's memory; computed on
        first use, then kept)."""
        subdivision = int(subdivision)
        cached = self._surfaces.get(subdivision)
        if cached is None:
            cached = wall_surface(
                self.grid.log_odds, self.occupied, self.grid.config.occupied_threshold,
                self.resolution, subdivision, memory_share,
            )  # fmt: skip
            self._surfaces[subdivision] = cached
        return cached

    def surface_view(self, subdivision: int) -> DistanceView:
        """:meth:`surface` as the likelihood kernels read it (same origin, finer cells)."""
        return DistanceView(
            self.surface(subdivision), float(self.origin[0]), float(self.origin[1]),
            int(subdivision) / self.resolution,
        )  # fmt: skip

    def memory_bytes(self) -> int:
        """Bytes held by the masks, the distance fields and the grid."""
        return int(
            self.occupied.nbytes
            + self.free.nbytes
            + self.distance.nbytes
            + sum(s.nbytes for s in self._surfaces.values())
            + self.grid.log_odds.nbytes
        )


def wall_points(
    log_odds: NDArray[np.floating], occupied: NDArray[np.bool_], threshold: float
) -> tuple[NDArray[np.int64], NDArray[np.int64], F64, F64]:
    """Row and column of every occupied cell and its wall point ``(px, py)`` in cell units
    (cell ``(ix, iy)`` spans ``[ix, ix + 1) × [iy, iy + 1)``): the centroid of the occupied cells
    of its 3 × 3 neighbourhood, each weighted by its log-odds above ``threshold``."""
    h, w = occupied.shape
    weight = np.where(occupied, np.asarray(log_odds, np.float64) - threshold, 0.0)
    weight = np.maximum(weight, 0.0)
    padded = np.pad(weight, 1)
    total = np.zeros((h, w))
    sum_x = np.zeros((h, w))
    sum_y = np.zeros((h, w))
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            v = padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
            total += v
            sum_x += dx * v
            sum_y += dy * v
    rows, cols = np.nonzero(occupied)
    own = total[rows, cols]
    safe = np.where(own > 0, own, 1.0)  # an occupied cell has weight > 0 (above the threshold)
    px = cols + 0.5 + np.where(own > 0, sum_x[rows, cols] / safe, 0.0)
    py = rows + 0.5 + np.where(own > 0, sum_y[rows, cols] / safe, 0.0)
    return rows.astype(np.int64), cols.astype(np.int64), px, py


SURFACE_BYTES_PER_CELL = 14
"""Memory of :func:`wall_surface` per fine cell: the drawn mask (1 byte), OpenCV's labels and
distances (4 + 4) and the field (4), the temporaries bounded by :data:`SURFACE_BLOCK_CELLS`."""

WALL_POINT_BYTES_PER_CELL = 56
"""... and per cell of the map: :func:`wall_points`' float64 and int64 arrays of the map's shape."""

SAMPLE_BYTES = 80
"""... and per sample drawn along the walls (its x, y, pixel and label, and their temporaries;
measured: a 1000 × 1000 map of occupied cells peaks at 1.5 GB, estimated 1.7 GB)."""

SURFACE_BLOCK_CELLS = 1 << 20
"""Fine cells whose distances :func:`wall_surface` computes at once."""


def wall_surface(
    log_odds: NDArray[np.floating],
    occupied: NDArray[np.bool_],
    threshold: float,
    resolution: float,
    subdivision: int,
    memory_share: float = DEFAULT_MEMORY_SHARE,
) -> NDArray[np.float32]:
    """Distance (m) from the centre of every cell of a grid ``subdivision`` times finer than the
    map to the nearest wall, the walls being the segments between the :func:`wall_points` of
    8-neighbouring occupied cells (an isolated cell: its point), sampled at the mid-points of
    ``2·subdivision`` equal parts; each fine cell holding samples keeps their mean, and every fine
    cell centre reads its Euclidean distance to that point of the nearest such cell
    (``cv2.distanceTransformWithLabels``). ``(H·subdivision, W·subdivision)`` float32, the same
    origin as the map. Refused (:class:`~slam.errors.UsageError`) when it would need more than
    ``memory_share`` of the machine's memory (:data:`SURFACE_BYTES_PER_CELL`)."""
    import cv2

    h, w = occupied.shape
    f = int(subdivision)
    samples = int(np.count_nonzero(occupied)) * 5 * 2 * f  # at most: 5 links per wall point
    check_memory(
        SURFACE_BYTES_PER_CELL * h * f * w * f
        + WALL_POINT_BYTES_PER_CELL * h * w
        + SAMPLE_BYTES * samples,
        f"the wall-surface field of a {w}×{h}-cell map at {f}× its resolution "
        f"({w * f}×{h * f} cells)",
        "use a smaller map (crop it to the building) or a lower localize.subdivision",
        share=memory_share,
        setting="checks.max_memory_share",
    )
    rows, cols, px, py = wall_points(log_odds, occupied, threshold)
    index = np.full((h, w), -1, dtype=np.int64)
    index[rows, cols] = np.arange(rows.size)
    starts, ends = [np.arange(rows.size)], [np.arange(rows.size)]
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):  # each neighbour pair once
        r, c = rows + dy, cols + dx
        inside = (r < h) & (c >= 0) & (c < w)
        other = np.full(rows.size, -1, dtype=np.int64)
        other[inside] = index[r[inside], c[inside]]
        linked = other >= 0
        starts.append(np.flatnonzero(linked))
        ends.append(other[linked])
    a, b = np.concatenate(starts), np.concatenate(ends)
    t = ((np.arange(2 * f) + 0.5) / (2 * f))[None, :]  # mid-points: no end counted twice
    x = (px[a, None] + t * (px[b] - px[a])[:, None]) * f
    y = (py[a, None] + t * (py[b] - py[a])[:, None]) * f
    x, y = x.ravel(), y.ravel()
    pixel = np.clip(y.astype(np.int64), 0, h * f - 1) * (w * f) + np.clip(
        x.astype(np.int64), 0, w * f - 1
    )
    # each drawn fine cell keeps the mean of the samples it holds: a point on the walls
    drawn, which = np.unique(pixel, return_inverse=True)
    count = np.bincount(which)
    mean_x = np.bincount(which, weights=x) / count
    mean_y = np.bincount(which, weights=y) / count
    fine = np.full((h * f, w * f), 255, dtype=np.uint8)
    fine.reshape(-1)[drawn] = 0
    # nearest drawn cell of every fine cell (labels number the drawn cells in row-major order,
    # the order of np.unique), then the exact distance to that cell's wall point: a wall
    # between fine cell centres is not moved onto one
    _, labels = cv2.distanceTransformWithLabels(
        fine, cv2.DIST_L2, cv2.DIST_MASK_5, labelType=cv2.DIST_LABEL_PIXEL
    )
    del fine
    out = np.empty((h * f, w * f), dtype=np.float32)
    cx = np.arange(w * f) + 0.5
    block = max(1, SURFACE_BLOCK_CELLS // (w * f))  # rows at a time: bounded temporaries
    for r0 in range(0, h * f, block):
        nearest = labels[r0 : r0 + block].astype(np.int64) - 1
        cy = np.arange(r0, r0 + nearest.shape[0])[:, None] + 0.5
        distance = np.hypot(cx - mean_x[nearest], cy - mean_y[nearest])
        out[r0 : r0 + block] = distance * (resolution / f)
    return out


def _read_npz(path: Path) -> OccupancyGrid:
    """The grid of a ``map.npz`` (:func:`slam.io.exports.read_map_npz`)."""
    from slam.io.exports import read_map_npz

    log_odds, resolution, origin = read_map_npz(path)
    return OccupancyGrid.from_arrays(log_odds, resolution, origin, MapConfig())


def load_map(path: Path | str) -> LikelihoodMap:
    """The map at ``path``: a run folder (its ``map.npz``), a ``map.npz`` file, or a ROS
    map_server ``map.yaml`` (with its image; :func:`slam.io.mapserver.read_map_yaml`)."""
    path = Path(path)
    if path.is_dir():
        npz = path / "map.npz"
        if not npz.is_file():
            yaml = _map_yaml_beside(path, "map")
            beside = f"; give the map_server file: --map {yaml}" if yaml else ""
            raise DataError(
                f"{path}: no map.npz in this folder (expected a slam run folder){beside}"
            )
        return LikelihoodMap.from_grid(_read_npz(npz), str(npz))
    if not path.exists():
        raise DataError(
            f"{path}: map not found (expected a run folder, a map.npz or a map.yaml file)"
        )
    if path.suffix == ".npz":
        return LikelihoodMap.from_grid(_read_npz(path), str(path))
    if path.suffix in (".yaml", ".yml"):
        return _from_map_yaml(path)
    yaml = _map_yaml_beside(path.parent, path.stem)
    beside = f"; the map_server file beside it: --map {yaml}" if yaml else ""
    raise DataError(
        f"{path}: unknown map format (expected a run folder, a .npz or a map_server .yaml "
        f"file){beside}"
    )


def _map_yaml_beside(folder: Path, stem: str) -> Path | None:
    """The map_server file in ``folder`` a user most likely meant: ``<stem>.yaml`` (the image's
    own), else the only ``.yaml`` there whose ``image:`` line names a file beside it; ``None``
    when there is no such file or several."""
    for suffix in (".yaml", ".yml"):
        if (folder / f"{stem}{suffix}").is_file():
            return folder / f"{stem}{suffix}"
    maps = [
        p
        for p in sorted(folder.glob("*.y*ml"))
        if p.is_file() and any(line.lstrip().startswith("image:") for line in _head(p))
    ]
    return maps[0] if len(maps) == 1 else None


def _head(path: Path, lines: int = 20) -> list[str]:
    """The first ``lines`` lines of the text file ``path`` (none when unreadable)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return [f.readline() for _ in range(lines)]
    except OSError:
        return []


def _from_map_yaml(path: Path) -> LikelihoodMap:
    """A map_server map: occupied (100) and free (0) cells become masks; unknown stays unknown."""
    from slam.io.mapserver import read_map_yaml

    m = read_map_yaml(path)
    if abs(float(m.origin[2])) > 1e-4:  # a writer's rounding of 0 passes
        raise DataError(
            f"{path}: origin yaw {float(m.origin[2]):g} rad: expected 0 (maps are axis-aligned "
            "grids here, as map_server writes them)"
        )
    occupancy = np.asarray(m.occupancy)
    occupied = occupancy >= 100  # read_map_yaml already applied the file's thresholds
    free = occupancy == 0
    if not occupied.any():
        raise DataError(
            f"{path}: no occupied cell (no pixel of the image reaches occupied_thresh), nothing "
            "to localize against"
        )
    return LikelihoodMap.from_masks(
        occupied, free, m.resolution, (float(m.origin[0]), float(m.origin[1])), str(path)
    )
