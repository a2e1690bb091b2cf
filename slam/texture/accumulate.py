"""Accumulation: the per-cell colours of the floor, frame pair by frame pair, on the map's grid.

This module owns the texture itself: :class:`TextureAccumulator` (colour sums per map cell,
``grid[iy, ix]`` with the lower-left corner of cell ``(ix, iy)`` at ``origin + (ix, iy)·resolution``,
the grid of ``map.npz``), the two accumulation modes (``mean``: the running mean of every floor
sample; ``latest``: the mean of the most recent frame that saw the cell), the resulting
:class:`TextureMap`, and :func:`build_texture`, which pairs the frames of a log
(:mod:`slam.texture.pairing`), decodes their PNGs (:mod:`slam.io.png`) and adds them with the
kernel (:func:`slam.texture.kernels.accumulate_frame`) in ``read_threads`` threads, and counts
the unreadable ones.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.config import TextureConfig
from slam.errors import DataError
from slam.grid_geometry import GridGeometry
from slam.io.log import RgbdIndex
from slam.kinect import KinectModel
from slam.mapping import OccupancyGrid
from slam.texture.kernels import (
    accumulate_frame,
    camera_in_world,
    camera_parameters,
    depth_table,
    kinect_model,
)
from slam.texture.pairing import FramePlan, frame_poses, plan_frames, warn_skips
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]

UNSEEN_COLOR = (0, 0, 0)
"""RGB colour of cells no floor pixel fell in (``texture.png``)."""


class TextureAccumulator:
    """Per-cell colour sums over a map grid, fed one RGB-D frame pair at a time."""

    def __init__(
        self, geometry: GridGeometry, config: TextureConfig, model: KinectModel | None = None
    ) -> None:
        self.config = config
        self.model = model if model is not None else kinect_model(config)
        self.geometry = geometry
        self.resolution = geometry.resolution
        self.origin = np.asarray(geometry.origin, dtype=np.float64)
        shape = geometry.shape
        self.sums = np.zeros((*shape, 3), dtype=np.int64)
        self.counts = np.zeros(shape, dtype=np.int32)
        self.stamps = np.full(shape, -1, dtype=np.int32)
        self.frames = 0
        self.samples = 0
        self._camera = camera_parameters(self.model, config)
        self._depth = depth_table(self.model, config)

    def add_frame(
        self,
        disparity: NDArray[np.uint16],
        rgb: NDArray[np.uint8],
        disparity_pose: F64,
        rgb_pose: F64,
    ) -> int:
        """Add one frame pair seen from these robot poses; return the floor samples added."""
        disparity, rgb = np.ascontiguousarray(disparity), np.ascontiguousarray(rgb)
        rot_d, cam_d = camera_in_world(self.model, disparity_pose)
        pose_r = rgb_pose if self.config.motion_compensation else disparity_pose
        rot_r, cam_r = camera_in_world(self.model, pose_r)
        # Disparity optical frame -> RGB-time optical frame: o' = R_rᵀ (R_d o + c_d − c_r).
        rot_rel = np.ascontiguousarray(rot_r.T @ rot_d)
        t_rel = rot_r.T @ (cam_d - cam_r)
        added = accumulate_frame(
            disparity, rgb, self.config.pixel_stride, self._camera, self._depth, rot_d, cam_d,
            rot_rel, t_rel, float(self.origin[0]), float(self.origin[1]), self.resolution,
            self.sums, self.counts, self.stamps, self.frames, self.config.mode == "latest",
        )  # fmt: skip
        self.frames += 1
        self.samples += int(added)
        return int(added)

    def merge(self, other: TextureAccumulator) -> None:
        """Add the sums of ``other`` (mode ``mean``, same grid) into this accumulator: integer
        sums, so the result is the same whichever frames each accumulator saw."""
        self.sums += other.sums
        self.counts += other.counts
        self.frames += other.frames
        self.samples += other.samples

    def texture(self) -> TextureMap:
        """The texture accumulated so far."""
        return TextureMap.from_sums(self.sums, self.counts, self.resolution, self.origin)


@dataclass
class TextureMap:
    """A floor texture on a map grid: ``rgb[iy, ix]`` and the samples behind each colour."""

    rgb: NDArray[np.uint8]
    """``(H, W, 3)`` RGB colour per cell (:data:`UNSEEN_COLOR` where ``count == 0``)."""
    count: NDArray[np.int32]
    """``(H, W)`` floor samples averaged into the cell's colour."""
    resolution: float
    """Cell size (m)."""
    origin: F64
    """World ``(x, y)`` of the lower-left corner of cell ``(0, 0)``."""

    @property
    def geometry(self) -> GridGeometry:
        """Where the texture lies (the map's grid)."""
        return GridGeometry.of(self.origin, self.resolution, self.count.shape)

    @classmethod
    def from_sums(
        cls, sums: NDArray, counts: NDArray[np.int32], resolution: float, origin: F64
    ) -> TextureMap:
        """Mean colours of accumulated sums (rounded to the nearest level)."""
        seen = counts > 0
        rgb = np.empty(sums.shape, dtype=np.uint8)
        rgb[...] = UNSEEN_COLOR
        mean = sums[seen] / counts[seen][:, None]
        rgb[seen] = np.clip(np.floor(mean + 0.5), 0, 255).astype(np.uint8)
        return cls(rgb, counts.copy(), float(resolution), np.asarray(origin, np.float64).copy())

    @property
    def coloured(self) -> NDArray[np.bool_]:
        """Cells with at least one floor sample."""
        return self.count > 0


@dataclass
class TextureResult:
    """The texture of a run and how it was made."""

    texture: TextureMap
    plan: FramePlan
    used: NDArray[np.bool_]
    """Per planned pair: whether both frames were read and added."""
    samples: int
    wall_s: float
    warnings: list[str]


def warm_up() -> None:
    """Compile (or load from numba's cache) :func:`accumulate_frame` for the frame types
    :class:`~slam.io.log.RgbdIndex` returns, so that timings measure throughput only."""
    config = TextureConfig()
    acc = TextureAccumulator(GridGeometry((0.0, 0.0), 1.0, (1, 1)), config)
    rgb = np.zeros((1, 1, 3), dtype=np.uint8)  # load_rgb's C-contiguous RGB image
    acc.add_frame(np.zeros((1, 1), dtype=np.uint16), rgb, np.zeros(3), np.zeros(3))


def _read_pair(index: RgbdIndex, model: KinectModel, k_rgb: int, k_disp: int) -> tuple:
    """Load one frame pair; ``(rgb, disparity, None, None)`` or ``(.., reason, message)``."""
    try:
        rgb = index.load_rgb(k_rgb)
    except DataError as exc:
        return None, None, "corrupt_rgb", str(exc)
    if rgb.ndim != 3 or rgb.shape != (model.height, model.width, 3):
        path = index.rgb_path(k_rgb)
        return None, None, "corrupt_rgb", f"{path}: expected 480x640x3, found {rgb.shape}"
    try:
        disparity = index.load_disparity(k_disp)
    except DataError as exc:
        return None, None, "corrupt_disparity", str(exc)
    if disparity.shape != (model.height, model.width):
        path = index.disparity_path(k_disp)
        return None, None, "corrupt_disparity", f"{path}: expected 480x640, found {disparity.shape}"
    return rgb, disparity, None, None


def _read_ahead(
    index: RgbdIndex, model: KinectModel, plan: FramePlan, threads: int
) -> Iterator[tuple]:
    """:func:`_read_pair` of every planned pair, in order, decoded by ``threads`` threads that
    keep at most ``2·threads + 2`` pairs ahead of the consumer (decoding releases the GIL)."""
    n = plan.rgb.size
    window = 2 * threads + 2
    with ThreadPoolExecutor(max_workers=threads) as pool:
        pending: deque[Future] = deque()
        submitted = 0
        for _ in range(n):
            while submitted < n and len(pending) < window:
                k_rgb, k_disp = int(plan.rgb[submitted]), int(plan.disparity[submitted])
                pending.append(pool.submit(_read_pair, index, model, k_rgb, k_disp))
                submitted += 1
            yield pending.popleft().result()


def _accumulate_in_order(
    index: RgbdIndex, plan: FramePlan, acc: TextureAccumulator, poses: tuple, bar, threads: int
) -> list[tuple]:
    """Mode ``latest``: frames decoded ahead by ``threads`` threads, added one by one in time
    order (the most recent frame wins, so the order matters). Returns the skips per frame."""
    outcomes: list[tuple] = []
    pose_d, pose_r = poses
    for k, (rgb, disparity, reason, message) in enumerate(
        _read_ahead(index, acc.model, plan, threads)
    ):
        if reason is None:
            acc.add_frame(disparity, rgb, pose_d[k], pose_r[k])
        outcomes.append((reason, message))
        if bar is not None:
            bar.update(1)
    return outcomes


def _accumulate_parallel(
    index: RgbdIndex, plan: FramePlan, acc: TextureAccumulator, poses: tuple, bar, threads: int
) -> list[tuple]:
    """Mode ``mean``: ``threads`` workers each decode and add every ``threads``-th frame into an
    accumulator of their own (PNG decoding and the kernel both release the GIL), merged into
    ``acc`` at the end: the sums are integers, so the texture is the same as frame by frame.
    Returns the skips per frame, in frame order."""
    n = plan.rgb.size
    pose_d, pose_r = poses
    outcomes: list[tuple] = [(None, None)] * n
    parts = [TextureAccumulator(acc.geometry, acc.config, acc.model) for _ in range(threads)]
    lock = threading.Lock()

    def work(w: int) -> None:
        part = parts[w]
        for k in range(w, n, threads):
            rgb, disparity, reason, message = _read_pair(
                index, part.model, int(plan.rgb[k]), int(plan.disparity[k])
            )
            if reason is None:
                part.add_frame(disparity, rgb, pose_d[k], pose_r[k])
            outcomes[k] = (reason, message)
            if bar is not None:
                with lock:
                    bar.update(1)

    with ThreadPoolExecutor(max_workers=threads) as pool:
        for future in [pool.submit(work, w) for w in range(threads)]:
            future.result()
    for part in parts:
        acc.merge(part)
    return outcomes


def build_texture(
    index: RgbdIndex,
    trajectory: Trajectory,
    grid: OccupancyGrid,
    config: TextureConfig,
    progress: bool = False,
) -> TextureResult:
    """Texture of the frames of ``index`` seen along ``trajectory`` on ``grid``.

    ``config.read_threads`` threads decode the frames; in mode ``mean`` each also accumulates its
    share of them (:func:`_accumulate_parallel`), in mode ``latest`` the frames are added in time
    order as they are decoded. Skipped frames are counted in the result's plan and reported as
    :class:`~slam.texture.pairing.TextureWarning` (one per reason).
    """
    times = trajectory.times
    warm_up()
    start = time.perf_counter()
    time_range = (float(times.min()), float(times.max())) if times.size else (0.0, -1.0)
    plan = plan_frames(index, config, time_range)
    model = kinect_model(config)
    acc = TextureAccumulator(grid.geometry, config, model)
    n = plan.rgb.size
    outcomes: list[tuple] = []
    bar = None
    if progress and n:
        from tqdm import tqdm

        bar = tqdm(total=n, desc="texture", unit="frame", leave=False)
    if n:
        poses = frame_poses(plan, trajectory)
        threads = max(1, min(config.read_threads, n))
        if config.mode == "mean":
            outcomes = _accumulate_parallel(index, plan, acc, poses, bar, threads)
        else:
            outcomes = _accumulate_in_order(index, plan, acc, poses, bar, threads)
    if bar is not None:
        bar.close()
    used = np.zeros(n, dtype=bool)
    for k, (reason, message) in enumerate(outcomes):
        if reason is None:
            used[k] = True
        else:
            plan.skip(reason, 1, message)
    messages = warn_skips(plan, index)
    return TextureResult(
        texture=acc.texture(),
        plan=plan,
        used=used,
        samples=acc.samples,
        wall_s=time.perf_counter() - start,
        warnings=messages,
    )
