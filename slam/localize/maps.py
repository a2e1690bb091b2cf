"""The map a robot localizes in: occupancy from a saved run, and the likelihood field over it.

A :class:`LikelihoodMap` holds what both localization filters read:

* ``occupied`` and ``free`` cell masks (``[iy, ix]``, the convention of :mod:`slam.mapping`:
  cell ``(ix, iy)`` has its lower-left corner at ``origin + (ix, iy)·resolution``);
* ``distance``: the Euclidean distance (m) from every cell centre to the nearest occupied cell
  centre, the *likelihood field* of Thrun et al. (ch. 6.4). It is the exact distance transform of
  the occupied cells (``cv2.distanceTransform``, precise mask), computed once per map: a saved
  map does not change while the robot localizes, unlike the per-particle fields of
  :mod:`slam.kernels.field`, which grow with every scan;
* ``grid``: the occupancy grid itself, for pictures and recordings.

:func:`load_map` reads ``RUN_DIR/map.npz`` (what ``slam run`` writes) or a ``map.npz`` file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

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
    """``(H, W)`` distance from each cell centre to the nearest occupied cell centre (m)."""

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
    def from_grid(cls, grid: OccupancyGrid) -> LikelihoodMap:
        """Masks and distance field of ``grid``: occupied above ``map.occupied_threshold``, free
        where the log-odds are negative (observed, and more often traversed than hit)."""
        import cv2

        occupied = np.ascontiguousarray(grid.log_odds > grid.config.occupied_threshold)
        free = np.ascontiguousarray((grid.log_odds < 0) & ~occupied)
        if not occupied.any():
            raise DataError("map: no occupied cell, nothing to localize against")
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
    ) -> LikelihoodMap:
        """A map from masks (tests, hand-made worlds, map_server files): occupied cells get
        log-odds +10, free −10, the rest 0 (unknown)."""
        occupied = np.asarray(occupied, dtype=bool)
        log_odds = np.where(occupied, 10.0, np.where(np.asarray(free, bool), -10.0, 0.0))
        grid = OccupancyGrid.from_arrays(
            log_odds.astype(np.float32), resolution, np.asarray(origin, np.float64), MapConfig()
        )
        return cls.from_grid(grid)

    def view(self) -> DistanceView:
        """The distance field as the likelihood kernels read it."""
        return DistanceView(
            self.distance, float(self.origin[0]), float(self.origin[1]), 1.0 / self.resolution
        )

    def memory_bytes(self) -> int:
        """Bytes held by the masks, the distance field and the grid."""
        return int(
            self.occupied.nbytes
            + self.free.nbytes
            + self.distance.nbytes
            + self.grid.log_odds.nbytes
        )


def _read_npz(path: Path) -> OccupancyGrid:
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = {"log_odds", "resolution", "origin"} - set(data.files)
            if missing:
                raise DataError(
                    f"{path}: expected keys log_odds, resolution, origin; missing "
                    f"{', '.join(sorted(missing))}"
                )
            log_odds = np.asarray(data["log_odds"])
            resolution = np.asarray(data["resolution"])
            origin = np.asarray(data["origin"])
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: not a readable map.npz ({exc})") from None
    if (
        log_odds.ndim != 2
        or min(log_odds.shape) < 1
        or not np.issubdtype(log_odds.dtype, np.number)
    ):
        raise DataError(
            f"{path}: log_odds must be a 2-D numeric array, found shape {log_odds.shape}"
        )
    if resolution.size != 1 or not float(resolution) > 0 or not np.isfinite(float(resolution)):
        raise DataError(f"{path}: resolution must be one number > 0, found {resolution!r}")
    if origin.shape != (2,) or not np.all(np.isfinite(origin)):
        raise DataError(f"{path}: origin must be 2 finite numbers (x, y), found {origin!r}")
    if not np.all(np.isfinite(log_odds)):
        raise DataError(f"{path}: log_odds holds NaN or infinite values")
    return OccupancyGrid.from_arrays(
        log_odds.astype(np.float32), float(resolution), origin.astype(np.float64), MapConfig()
    )


def load_map(path: Path | str) -> LikelihoodMap:
    """The map at ``path``: a run folder (its ``map.npz``), a ``map.npz`` file, or a ROS
    map_server ``map.yaml`` (with its image; :func:`slam.io.mapserver.read_map_yaml`)."""
    path = Path(path)
    if path.is_dir():
        npz = path / "map.npz"
        if not npz.is_file():
            raise DataError(f"{path}: no map.npz in this folder (expected a slam run folder)")
        return LikelihoodMap.from_grid(_read_npz(npz))
    if not path.exists():
        raise DataError(
            f"{path}: map not found (expected a run folder, a map.npz or a map.yaml file)"
        )
    if path.suffix == ".npz":
        return LikelihoodMap.from_grid(_read_npz(path))
    if path.suffix in (".yaml", ".yml"):
        return _from_map_yaml(path)
    raise DataError(
        f"{path}: unknown map format (expected a run folder, a .npz or a map_server .yaml file)"
    )


def _from_map_yaml(path: Path) -> LikelihoodMap:
    """A map_server map: occupied (100) and free (0) cells become masks; unknown stays unknown."""
    from slam.io.mapserver import read_map_yaml

    m = read_map_yaml(path)
    if abs(float(m.origin[2])) > 1e-9:
        raise DataError(
            f"{path}: origin yaw {float(m.origin[2]):g} rad: expected 0 (maps are axis-aligned "
            "grids here, as map_server writes them)"
        )
    occupancy = np.asarray(m.occupancy)
    occupied = occupancy >= 100  # read_map_yaml already applied the file's thresholds
    free = occupancy == 0
    return LikelihoodMap.from_masks(
        occupied, free, m.resolution, (float(m.origin[0]), float(m.origin[1]))
    )
