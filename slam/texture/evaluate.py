"""Evaluation of a texture against a simulated dataset's ground truth (docs/texture.md).

This module owns what "right" means for a texture: the ground truth of a simulated dataset
folder (:class:`GroundTruth`: true path, floor texels, obstacle map), the true colour of any map
cell (:class:`TrueTexture`), the floor the camera swept along the true path (:func:`swept_cells`,
with the kernel :func:`slam.texture.kernels.mark_swept`), and the figures of
:func:`evaluate_texture`: mean absolute colour error over the floor cells seen, coverage of the
swept floor, and both again after the SE(2) alignment of the trajectory to the ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import TextureConfig
from slam.errors import DataError
from slam.geometry import interpolate_poses, inverse, transform_points
from slam.texture.accumulate import TextureMap
from slam.texture.kernels import camera_in_world, camera_parameters, kinect_model, mark_swept
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True)
class GroundTruth:
    """What a simulated dataset knows for sure: the path, the floor texture and the walls."""

    times: F64
    """``(N,)`` times of the true path (s)."""
    poses: F64
    """``(N, 3)`` true robot poses."""
    texture: NDArray[np.uint8]
    """``(Ht, Wt, 3)`` true floor colours (texels)."""
    texture_resolution: float
    """Texel size (m)."""
    texture_origin: F64
    """Lower-left corner of texel ``[0, 0]`` (m)."""
    floor: NDArray[np.bool_]
    """``(Ht, Wt)`` texels that are visible floor (files without a ``floor`` array: every
    non-black texel)."""
    occupancy: NDArray[np.uint8]
    """``(Hm, Wm)`` 1 where an obstacle (extruded from the floor up) stands."""
    map_resolution: float
    """Cell size of ``occupancy`` (m)."""
    map_origin: F64
    """Lower-left corner of cell ``[0, 0]`` of ``occupancy`` (m)."""


def load_ground_truth(folder: Path) -> GroundTruth | None:
    """The ground truth of a simulated dataset folder, or ``None`` when it has none.

    Needs ``groundtruth.tum``, ``groundtruth_texture.npz`` (``rgb``, ``resolution``, ``origin``,
    optional ``floor``: without it every non-black texel is floor) and ``groundtruth_map.npz``
    (``occupancy``, ``resolution``, ``origin``).
    """
    from slam.io.exports import read_npz_arrays
    from slam.io.tum import read_tum

    folder = Path(folder)
    names = ("groundtruth.tum", "groundtruth_texture.npz", "groundtruth_map.npz")
    if not folder.is_dir() or not all((folder / n).is_file() for n in names):
        return None
    times, poses = read_tum(folder / names[0])
    tex = read_npz_arrays(folder / names[1], ("rgb", "resolution", "origin"))
    occ = read_npz_arrays(folder / names[2], ("occupancy", "resolution", "origin"))
    rgb = np.asarray(tex["rgb"])
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise DataError(
            f"{folder / names[1]}: rgb must be (H, W, 3) uint8, found {rgb.dtype} {rgb.shape}"
        )
    floor = np.asarray(tex["floor"], bool) if "floor" in tex else rgb.any(axis=2)
    if floor.shape != rgb.shape[:2]:
        raise DataError(f"{folder / names[1]}: floor {floor.shape} does not match rgb {rgb.shape}")
    return GroundTruth(
        times=times,
        poses=poses,
        texture=rgb,
        floor=floor,
        texture_resolution=float(tex["resolution"]),
        texture_origin=np.asarray(tex["origin"], np.float64).reshape(2),
        occupancy=np.ascontiguousarray(np.asarray(occ["occupancy"]) != 0).astype(np.uint8),
        map_resolution=float(occ["resolution"]),
        map_origin=np.asarray(occ["origin"], np.float64).reshape(2),
    )


class TrueTexture:
    """Box means of the true floor texture: the true colour of a map cell wherever it lies.

    The true colour of a square of side ``resolution`` centred at ``(x, y)`` (axis-aligned in the
    ground-truth frame) is the mean of the texels whose centres fall inside it; the square is
    *floor* when it holds at least one texel and all of them are floor. Summed-area tables make
    each query O(1), for any centres (a map cell, or a cell moved by an alignment).
    """

    def __init__(self, gt: GroundTruth) -> None:
        self.resolution = gt.texture_resolution
        self.origin = gt.texture_origin
        layers = np.concatenate(
            [gt.texture.astype(np.float64), gt.floor[..., None].astype(np.float64)], axis=2
        )
        table = np.zeros((layers.shape[0] + 1, layers.shape[1] + 1, 4))
        table[1:, 1:] = layers.cumsum(axis=0).cumsum(axis=1)
        self.table = table

    def _range(self, lo: F64, hi: F64, axis: int, size: int) -> tuple[I64, I64]:
        # Texel k has its centre at origin + (k + 0.5)·r; keep lo <= centre < hi.
        a = np.ceil((lo - self.origin[axis]) / self.resolution - 0.5).astype(np.int64)
        b = np.ceil((hi - self.origin[axis]) / self.resolution - 0.5).astype(np.int64)
        return np.clip(a, 0, size), np.clip(b, 0, size)

    def cells(self, centres: F64, resolution: float) -> tuple[F64, NDArray[np.bool_]]:
        """True colours ``(N, 3)`` (float RGB) and floor flags ``(N,)`` of squares at ``centres``."""
        centres = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
        half = resolution / 2
        th, tw = self.table.shape[0] - 1, self.table.shape[1] - 1
        c0, c1 = self._range(centres[:, 0] - half, centres[:, 0] + half, 0, tw)
        r0, r1 = self._range(centres[:, 1] - half, centres[:, 1] + half, 1, th)
        t = self.table
        sums = t[r1, c1] - t[r0, c1] - t[r1, c0] + t[r0, c0]
        total = np.maximum(r1 - r0, 0) * np.maximum(c1 - c0, 0)
        is_floor = (total > 0) & (np.abs(sums[:, 3] - total) < 0.5)
        colour = sums[:, :3] / np.maximum(total, 1)[:, None]
        return colour, is_floor

    def on_grid(
        self, shape: tuple[int, int], resolution: float, origin: F64
    ) -> tuple[F64, NDArray[np.bool_]]:
        """:meth:`cells` for every cell of a grid: ``(H, W, 3)`` colours, ``(H, W)`` floor cells."""
        h, w = shape
        xs = origin[0] + (np.arange(w) + 0.5) * resolution
        ys = origin[1] + (np.arange(h) + 0.5) * resolution
        centres = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None]), axis=-1)
        colour, is_floor = self.cells(centres.reshape(-1, 2), resolution)
        return colour.reshape(h, w, 3), is_floor.reshape(h, w)


def swept_cells(
    gt: GroundTruth,
    floor_cells: NDArray[np.bool_],
    resolution: float,
    origin: F64,
    frame_times: F64,
    config: TextureConfig,
) -> NDArray[np.bool_]:
    """The *swept* floor: floor cells the camera saw along the true path at ``frame_times``.

    A floor cell is swept when, from the true camera pose at one of the frame times, its centre
    (on the floor plane) is at an optical depth within ``[min_depth, max_depth]``, projects inside
    the depth image and, through the RGB alignment, inside the RGB image, and the segment from the
    camera to it crosses no obstacle cell of the true map (obstacles rise from the floor above the
    camera, so this 2D test is exact up to the quarter-cell sampling).
    """
    model = kinect_model(config)
    frame_times = np.asarray(frame_times, dtype=np.float64)
    out = np.zeros(floor_cells.shape, dtype=bool)
    if frame_times.size == 0:
        return out
    poses = interpolate_poses(gt.times, gt.poses, frame_times)
    cams = [camera_in_world(model, p) for p in poses]
    rotations = np.ascontiguousarray(np.stack([c[0] for c in cams]))
    positions = np.ascontiguousarray(np.stack([c[1] for c in cams]))
    mark_swept(
        np.ascontiguousarray(floor_cells), float(origin[0]), float(origin[1]), float(resolution),
        gt.occupancy, float(gt.map_origin[0]), float(gt.map_origin[1]), gt.map_resolution,
        rotations, positions, camera_parameters(model, config), out,
    )  # fmt: skip
    return out


def evaluate_texture(
    texture: TextureMap,
    gt: GroundTruth,
    frame_times: F64,
    config: TextureConfig,
    trajectory: Trajectory | None = None,
) -> dict[str, Any]:
    """Colour error and coverage of ``texture`` against the ground truth (docs/texture.md).

    * ``colour_mae``: over the floor cells that were coloured, the mean of the absolute
      differences between the texture's and the true cell colour, averaged over the three
      channels, in levels of 255 (cells compared in place: the map frame is the ground-truth
      frame, both start at the first pose);
    * ``coverage``: the fraction of swept floor cells (:func:`swept_cells` with the frames at
      ``frame_times``) that were coloured;
    * with ``trajectory`` (the estimate the texture was made with) also ``colour_mae_aligned`` and
      ``coverage_aligned``: the same after moving the texture by the SE(2) alignment of the
      trajectory to the ground truth (as for ATE), so that a global drift of the map does not
      count as colour error.
    """
    shape = texture.count.shape
    res = texture.resolution
    truth = TrueTexture(gt)
    true_rgb, floor = truth.on_grid(shape, res, texture.origin)
    coloured = texture.coloured
    seen = floor & coloured
    err = np.abs(texture.rgb[seen].astype(np.float64) - true_rgb[seen]).mean(axis=1)
    swept = swept_cells(gt, floor, res, texture.origin, frame_times, config)
    n_swept = int(swept.sum())
    out: dict[str, Any] = {
        "colour_mae": _rounded(err.mean() if err.size else None, 3),
        "colour_error_p90": _rounded(np.percentile(err, 90) if err.size else None, 3),
        "floor_cells_seen": int(seen.sum()),
        "swept_cells": n_swept,
        "swept_area_m2": round(n_swept * res**2, 3),
        "coverage": _rounded((swept & coloured).sum() / n_swept if n_swept else None, 4),
        "coloured_outside_floor_cells": int((coloured & ~floor).sum()),
    }
    if trajectory is not None and len(trajectory) > 1:
        out.update(_aligned_figures(texture, gt, truth, swept, trajectory))
    return out


def _aligned_figures(
    texture: TextureMap,
    gt: GroundTruth,
    truth: TrueTexture,
    swept: NDArray[np.bool_],
    trajectory: Trajectory,
) -> dict[str, Any]:
    """``alignment``, ``colour_mae_aligned`` and ``coverage_aligned`` of :func:`evaluate_texture`
    (empty when fewer than two poses of the trajectory lie within the ground truth's time span)."""
    from slam.eval.trajectory import align_se2

    res, coloured = texture.resolution, texture.coloured
    times, poses = trajectory.times, trajectory.poses
    inside = (times >= gt.times[0]) & (times <= gt.times[-1])
    if inside.sum() <= 1:
        return {}
    reference = interpolate_poses(gt.times, gt.poses, times[inside])
    transform = align_se2(poses[inside, :2], reference[:, :2])
    iy, ix = np.nonzero(coloured)
    centres = texture.origin + (np.stack([ix, iy], axis=-1) + 0.5) * res
    colour, is_floor = truth.cells(transform_points(transform, centres), res)
    err_a = np.abs(texture.rgb[iy, ix][is_floor].astype(np.float64) - colour[is_floor])
    err_a = err_a.mean(axis=1)
    # Swept cells (ground-truth frame) found back in the texture's frame.
    sy, sx = np.nonzero(swept)
    swept_xy = texture.origin + (np.stack([sx, sy], axis=-1) + 0.5) * res
    back = transform_points(inverse(transform), swept_xy)
    geometry = texture.geometry
    cells = geometry.world_to_cell(back)
    cx, cy = cells[:, 0], cells[:, 1]
    ok = geometry.inside(cy, cx)
    hit = np.zeros(cx.shape, dtype=bool)
    hit[ok] = coloured[cy[ok], cx[ok]]
    return {
        "alignment": [round(float(v), 5) for v in transform],
        "colour_mae_aligned": _rounded(err_a.mean() if err_a.size else None, 3),
        "coverage_aligned": _rounded(hit.mean() if hit.size else None, 4),
    }


def _rounded(value: Any, digits: int) -> float | None:
    return None if value is None else round(float(value), digits)
