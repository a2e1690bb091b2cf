"""Floor texture mapping: the colours of the floor, from RGB-D frames, on the run's map grid.

This module owns the last stage of ``slam run`` (and ``slam texture RUN_DIR``), top to bottom:

1. **Frame pairing** (:func:`pair_frames`, :func:`plan_frames`): every ``frame_stride``-th RGB
   frame whose PNG exists is paired with the disparity frame nearest in time (among those whose
   PNG exists) when they are at most ``pair_tolerance_s`` apart; frames outside the trajectory's
   time span are skipped (poses are never extrapolated). Every skipped frame is counted by reason.
2. **Poses**: the robot pose at the disparity frame's time and at the RGB frame's time, linearly
   interpolated from the trajectory (:func:`slam.geometry.interpolate_poses`).
3. **Projection and floor extraction** (numba kernel :func:`accumulate_frame`, one fused pass over
   the disparity image): disparity → depth (course formula) → optical point (intrinsics of
   :class:`~slam.kinect.KinectModel`, cx ≈ 315.8 column, cy ≈ 242.9 row) → world point (camera
   extrinsics, pose at the disparity time). Points with a depth in ``[min_depth, max_depth]`` and
   a height within ``±floor_height`` of the floor plane are floor.
4. **Colour**: the floor point is projected back into the depth camera at the pose of the RGB
   frame's time (motion compensation: the two frames are up to tens of milliseconds apart) and the
   course's RGB alignment formula gives the RGB pixel, read at the nearest pixel.
5. **Accumulation** per map cell (``grid[iy, ix]``, lower-left corner of cell ``(ix, iy)`` at
   ``origin + (ix, iy)·resolution``, the grid of ``map.npz``): ``mean`` keeps the running mean of
   every floor sample, ``latest`` the mean of the most recent frame that saw the cell.
6. **Outputs** (:func:`write_outputs`): ``texture.npz`` (``rgb``, ``count``, ``resolution``,
   ``origin``), ``texture.png`` (same pixels as ``map.png``: +y up, same scale) and
   ``texture_overlay.png`` (the texture over the occupancy map).
7. **Evaluation** against a simulated dataset's ground truth (:func:`evaluate_texture`): mean
   absolute colour error over the true floor cells that were coloured, and coverage of the *swept*
   floor (see :func:`swept_cells` and docs/texture.md for the exact definition).

Bad frames (missing or unreadable PNG, wrong image size, more timestamps than files) are skipped
with one :class:`TextureWarning` per reason and counted in the metrics; they never stop a run.
"""

from __future__ import annotations

import json
import math
import os
import re
import time
import warnings
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from slam.config import Config, TextureConfig
from slam.errors import DataError
from slam.geometry import interpolate_poses, inverse, transform_points
from slam.io.atomic import atomic_path, write_text
from slam.io.log import Log, RgbdIndex
from slam.kinect import KinectModel
from slam.mapping import OccupancyGrid

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

TEXTURE_MODES = ("mean", "latest")
"""Accumulation modes (``texture.mode``)."""

SKIP_REASONS: dict[str, str] = {
    "missing_rgb": "RGB PNG missing",
    "corrupt_rgb": "RGB PNG unreadable or of the wrong size",
    "corrupt_disparity": "disparity PNG unreadable or of the wrong size",
    "no_disparity": "no disparity frame (with a PNG) within the pairing tolerance",
    "outside_trajectory": "frame time outside the trajectory's time span",
}
"""Why an RGB frame can be skipped, as counted under ``texture.skipped`` in ``metrics.json``."""

UNSEEN_COLOR = (0, 0, 0)
"""RGB colour of cells no floor pixel fell in (``texture.png``)."""


class TextureWarning(UserWarning):
    """A texture-mapping problem that was skipped over (bad frames, missing image folders)."""


def kinect_model(config: TextureConfig) -> KinectModel:
    """The Kinect model with the camera extrinsics of ``config`` (intrinsics and formulas fixed)."""
    return KinectModel(
        x=config.camera_x,
        y=config.camera_y,
        z=config.camera_z,
        roll=config.camera_roll,
        pitch=config.camera_pitch,
        yaw=config.camera_yaw,
    )


# ------------------------------------------------------------------------------ frame pairing


@dataclass
class FramePlan:
    """Which RGB frames are used with which disparity frame, and why the others are not."""

    rgb: I64
    """0-based RGB frame indices to use, in time order."""
    disparity: I64
    """0-based disparity frame paired with each of them."""
    rgb_time: F64
    """Times of the RGB frames used (s)."""
    disparity_time: F64
    """Times of their disparity frames (s)."""
    considered: int
    """RGB frames considered (every ``frame_stride``-th of the log)."""
    skipped: dict[str, int] = field(default_factory=dict)
    """RGB frames skipped, by reason (keys of :data:`SKIP_REASONS`)."""
    examples: dict[str, str] = field(default_factory=dict)
    """One example (file or time) per skip reason, for the warnings."""
    count_mismatch: dict[str, dict[str, int]] = field(default_factory=dict)
    """Streams whose folder holds a different number of PNGs than the log has timestamps."""

    def skip(self, reason: str, count: int, example: str) -> None:
        """Count ``count`` RGB frames skipped for ``reason``."""
        if count <= 0:
            return
        self.skipped[reason] = self.skipped.get(reason, 0) + int(count)
        self.examples.setdefault(reason, example)


def nearest_frames(query: F64, times: F64) -> tuple[I64, F64]:
    """Index into ``times`` of the nearest time to each query and the signed gap ``query − time``.

    ``times`` need not be sorted; ties go to the earlier frame. ``times`` must not be empty.
    """
    query = np.asarray(query, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    order = np.argsort(times, kind="stable")
    sorted_t = times[order]
    right = np.clip(np.searchsorted(sorted_t, query), 1, max(sorted_t.size - 1, 1))
    left = right - 1
    if sorted_t.size == 1:
        pick = np.zeros(query.shape, dtype=np.int64)
    else:
        pick = np.where(
            np.abs(query - sorted_t[left]) <= np.abs(sorted_t[right] - query), left, right
        )
    index = order[pick]
    return index.astype(np.int64), query - times[index]


def pair_frames(
    rgb_time: F64,
    disparity_time: F64,
    tolerance: float,
    *,
    stride: int = 1,
    rgb_available: NDArray[np.bool_] | None = None,
    disparity_available: NDArray[np.bool_] | None = None,
    time_range: tuple[float, float] | None = None,
) -> FramePlan:
    """Pair every ``stride``-th RGB frame with the nearest available disparity frame in time.

    ``*_available`` mark frames whose PNG exists (default: all). An RGB frame is skipped when its
    PNG is missing (``missing_rgb``), when no available disparity frame is within ``tolerance``
    seconds (``no_disparity``), or when either time falls outside ``time_range`` (the
    trajectory's span; ``outside_trajectory``).
    """
    rgb_time = np.asarray(rgb_time, dtype=np.float64)
    disparity_time = np.asarray(disparity_time, dtype=np.float64)
    candidates = np.arange(0, rgb_time.size, max(int(stride), 1), dtype=np.int64)
    candidates = candidates[np.argsort(rgb_time[candidates], kind="stable")]
    plan = FramePlan(
        rgb=np.zeros(0, np.int64),
        disparity=np.zeros(0, np.int64),
        rgb_time=np.zeros(0),
        disparity_time=np.zeros(0),
        considered=int(candidates.size),
    )
    if rgb_available is not None:
        present = np.asarray(rgb_available, dtype=bool)[candidates]
        missing = candidates[~present]
        plan.skip(
            "missing_rgb", missing.size, f"RGB frame {missing[0] + 1}" if missing.size else ""
        )
        candidates = candidates[present]
    usable = np.arange(disparity_time.size, dtype=np.int64)
    if disparity_available is not None:
        usable = usable[np.asarray(disparity_available, dtype=bool)]
    if usable.size == 0:
        plan.skip("no_disparity", candidates.size, "no disparity PNG at all")
        return plan
    near, gap = nearest_frames(rgb_time[candidates], disparity_time[usable])
    paired = usable[near]
    ok = np.abs(gap) <= tolerance
    if (~ok).any():
        worst = candidates[~ok][0]
        plan.skip(
            "no_disparity",
            int((~ok).sum()),
            f"RGB frame {worst + 1}: nearest disparity {abs(gap[~ok][0]):.3f} s away",
        )
    candidates, paired = candidates[ok], paired[ok]
    if time_range is not None:
        lo, hi = time_range
        t_r, t_d = rgb_time[candidates], disparity_time[paired]
        inside = (t_r >= lo) & (t_r <= hi) & (t_d >= lo) & (t_d <= hi)
        if (~inside).any():
            first = candidates[~inside][0]
            plan.skip(
                "outside_trajectory",
                int((~inside).sum()),
                f"RGB frame {first + 1} at t={rgb_time[first]:.3f} s, trajectory "
                f"{lo:.3f}..{hi:.3f} s",
            )
        candidates, paired = candidates[inside], paired[inside]
    plan.rgb = candidates
    plan.disparity = paired
    plan.rgb_time = rgb_time[candidates]
    plan.disparity_time = disparity_time[paired]
    return plan


def frame_numbers(directory: Path, pattern: str) -> set[int]:
    """The frame numbers ``k`` (1-based) whose file ``pattern.format(k)`` exists in ``directory``."""
    prefix, _, suffix = pattern.partition("{}")
    regex = re.compile(re.escape(prefix) + r"([0-9]+)" + re.escape(suffix) + r"\Z")
    found: set[int] = set()
    try:
        with os.scandir(directory) as entries:
            for entry in entries:
                match = regex.match(entry.name)
                if match:
                    found.add(int(match.group(1)))
    except OSError:
        return set()
    return found


def plan_frames(
    index: RgbdIndex, config: TextureConfig, time_range: tuple[float, float] | None
) -> FramePlan:
    """Pair the frames of ``index`` (see :func:`pair_frames`), checking which PNGs exist.

    A folder holding a different number of PNGs than the log has timestamps is recorded in
    ``count_mismatch`` (frames are matched by number: frame ``k`` is ``…_k.png`` at the ``k``-th
    timestamp; timestamps without a file are skipped as missing, extra files are ignored).
    """
    streams = (
        ("rgb", index.rgb_dir, index.rgb_pattern, index.rgb_time.size),
        ("disparity", index.disparity_dir, index.disparity_pattern, index.disparity_time.size),
    )
    available: dict[str, NDArray[np.bool_]] = {}
    mismatch: dict[str, dict[str, int]] = {}
    for name, directory, pattern, n in streams:
        numbers = frame_numbers(directory, pattern)
        mask = np.zeros(n, dtype=bool)
        inside = [k - 1 for k in numbers if 1 <= k <= n]
        mask[inside] = True
        available[name] = mask
        if len(numbers) != n:
            mismatch[name] = {"files": len(numbers), "timestamps": int(n)}
    plan = pair_frames(
        index.rgb_time,
        index.disparity_time,
        config.pair_tolerance_s,
        stride=config.frame_stride,
        rgb_available=available["rgb"],
        disparity_available=available["disparity"],
        time_range=time_range,
    )
    if "missing_rgb" in plan.skipped:  # name the first missing file in the warning
        strided = np.arange(0, index.rgb_time.size, config.frame_stride)
        plan.examples["missing_rgb"] = str(
            index.rgb_path(int(strided[~available["rgb"][strided]][0]))
        )
    plan.count_mismatch = mismatch
    return plan


# ----------------------------------------------------------------------------------- kernel


def kernel_parameters(model: KinectModel, config: TextureConfig) -> F64:
    """The scalars :func:`accumulate_frame` and :func:`mark_swept` need, in their order."""
    return np.array(
        [
            model.fx,
            model.fy,
            model.cx,
            model.cy,
            model.disparity_scale,
            model.disparity_offset,
            model.depth_numerator,
            config.min_depth,
            config.max_depth,
            config.floor_height,
            model.rgb_gain,
            model.rgb_row_offset,
            model.rgb_row_dd,
            model.rgb_col_offset,
            model.rgb_norm,
        ],
        dtype=np.float64,
    )


def depth_table(model: KinectModel, config: TextureConfig) -> F64:
    """Depth (m) of every raw disparity value, 0 where it is no measurement or outside
    ``[min_depth, max_depth]``; values past the table's end are all invalid."""
    depth = model.disparity_to_depth(np.arange(65536, dtype=np.float64))
    valid = np.isfinite(depth) & (depth >= config.min_depth) & (depth <= config.max_depth)
    table = np.where(valid, depth, 0.0)
    last = np.flatnonzero(valid)
    return np.ascontiguousarray(table[: last[-1] + 1 if last.size else 0])


@njit(cache=True, error_model="numpy")
def accumulate_frame(disparity, rgb, stride, params, depth_lut, rot_d, cam_d, rot_rel, t_rel,
                     origin_x, origin_y, resolution, sums, counts, stamps, frame_id,
                     latest):  # fmt: skip
    """Add the floor pixels of one RGB-D frame pair to the per-cell colour sums.

    For each ``stride``-th pixel ``(i, j)`` of ``disparity`` with raw value ``d``: depth
    ``depth_lut[d]`` (the course formula ``1.03 / (−0.00304·d + 3.31)``, 0 when invalid or out of
    range, see :func:`depth_table`); optical point ``o = ((j − cx)/fx, (i − cy)/fy, 1)·depth``;
    world point ``rot_d · o + cam_d`` (camera pose at the disparity time), floor when
    ``|z| ≤ params[9]``. The point in the optical frame of the RGB time is ``o' = rot_rel · o +
    t_rel``; its depth pixel is ``(i', j') = (fy·o'y/o'z + cy, fx·o'x/o'z + cx)`` with
    ``dd' = 1.03/o'z``, and its RGB pixel ``((g·i' + c_i − k·dd')/n, (g·j' + c_j)/n)``
    (``params[10:15]`` = ``g, c_i, k, c_j, n``), read at the nearest pixel. The colour is added to
    ``sums[iy, ix]`` and ``counts[iy, ix]`` of the cell holding the world point; with ``latest`` a
    cell first seen in this frame (``stamps != frame_id``) is reset first. Returns the samples added.
    """
    fx, fy, cx, cy = params[0], params[1], params[2], params[3]
    numer, floor_h = params[6], params[9]
    g, c_i, k_dd, c_j = params[10], params[11], params[12], params[13]
    inv_fx, inv_fy, inv_nrm = 1.0 / fx, 1.0 / fy, 1.0 / params[14]
    h, w = disparity.shape[0], disparity.shape[1]
    rh, rw = rgb.shape[0], rgb.shape[1]
    gh, gw = counts.shape[0], counts.shape[1]
    n_lut = depth_lut.shape[0]
    inv_res = 1.0 / resolution
    added = 0
    for i in range(0, h, stride):
        yn = (i - cy) * inv_fy
        for j in range(0, w, stride):
            d = disparity[i, j]
            if d >= n_lut:
                continue
            depth = depth_lut[d]
            if depth <= 0.0:
                continue
            xo = (j - cx) * inv_fx * depth
            yo = yn * depth
            zo = depth
            pz = rot_d[2, 0] * xo + rot_d[2, 1] * yo + rot_d[2, 2] * zo + cam_d[2]
            if abs(pz) > floor_h:
                continue
            px = rot_d[0, 0] * xo + rot_d[0, 1] * yo + rot_d[0, 2] * zo + cam_d[0]
            py = rot_d[1, 0] * xo + rot_d[1, 1] * yo + rot_d[1, 2] * zo + cam_d[1]
            ix = int(math.floor((px - origin_x) * inv_res))
            iy = int(math.floor((py - origin_y) * inv_res))
            if ix < 0 or iy < 0 or ix >= gw or iy >= gh:
                continue
            oz = rot_rel[2, 0] * xo + rot_rel[2, 1] * yo + rot_rel[2, 2] * zo + t_rel[2]
            if oz <= 0.0:
                continue
            ox = rot_rel[0, 0] * xo + rot_rel[0, 1] * yo + rot_rel[0, 2] * zo + t_rel[0]
            oy = rot_rel[1, 0] * xo + rot_rel[1, 1] * yo + rot_rel[1, 2] * zo + t_rel[1]
            inv_oz = 1.0 / oz
            ic = fy * oy * inv_oz + cy
            jc = fx * ox * inv_oz + cx
            ri = int(math.floor((g * ic + c_i - k_dd * numer * inv_oz) * inv_nrm + 0.5))
            rj = int(math.floor((g * jc + c_j) * inv_nrm + 0.5))
            if ri < 0 or rj < 0 or ri >= rh or rj >= rw:
                continue
            if latest and stamps[iy, ix] != frame_id:
                stamps[iy, ix] = frame_id
                sums[iy, ix, 0] = 0.0
                sums[iy, ix, 1] = 0.0
                sums[iy, ix, 2] = 0.0
                counts[iy, ix] = 0
            sums[iy, ix, 0] += rgb[ri, rj, 0]
            sums[iy, ix, 1] += rgb[ri, rj, 1]
            sums[iy, ix, 2] += rgb[ri, rj, 2]
            counts[iy, ix] += 1
            added += 1
    return added


# ------------------------------------------------------------------------------ accumulation


def camera_in_world(model: KinectModel, pose: F64) -> tuple[F64, F64]:
    """Rotation (optical → world) and position of the camera at robot ``pose`` ``(x, y, θ)``."""
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rotation = rz @ model.rotation
    t = model.translation
    position = np.array([pose[0] + c * t[0] - s * t[1], pose[1] + s * t[0] + c * t[1], t[2]])
    return np.ascontiguousarray(rotation), position


class TextureAccumulator:
    """Per-cell colour sums over a map grid, fed one RGB-D frame pair at a time."""

    def __init__(
        self,
        shape: tuple[int, int],
        resolution: float,
        origin: F64,
        config: TextureConfig,
        model: KinectModel | None = None,
    ) -> None:
        self.config = config
        self.model = model if model is not None else kinect_model(config)
        self.resolution = float(resolution)
        self.origin = np.asarray(origin, dtype=np.float64).copy()
        self.sums = np.zeros((*shape, 3), dtype=np.float64)
        self.counts = np.zeros(shape, dtype=np.int32)
        self.stamps = np.full(shape, -1, dtype=np.int32)
        self.frames = 0
        self.samples = 0
        self._params = kernel_parameters(self.model, config)
        self._depth = depth_table(self.model, config)

    def add_frame(
        self,
        disparity: NDArray[np.uint16],
        rgb: NDArray[np.uint8],
        disparity_pose: F64,
        rgb_pose: F64,
    ) -> int:
        """Add one frame pair seen from these robot poses; return the floor samples added."""
        rot_d, cam_d = camera_in_world(self.model, disparity_pose)
        pose_r = rgb_pose if self.config.motion_compensation else disparity_pose
        rot_r, cam_r = camera_in_world(self.model, pose_r)
        # Disparity optical frame -> RGB-time optical frame: o' = R_rᵀ (R_d o + c_d − c_r).
        rot_rel = np.ascontiguousarray(rot_r.T @ rot_d)
        t_rel = rot_r.T @ (cam_d - cam_r)
        added = accumulate_frame(
            disparity, rgb, self.config.pixel_stride, self._params, self._depth, rot_d, cam_d,
            rot_rel, t_rel, float(self.origin[0]), float(self.origin[1]), self.resolution,
            self.sums, self.counts, self.stamps, self.frames, self.config.mode == "latest",
        )  # fmt: skip
        self.frames += 1
        self.samples += int(added)
        return int(added)

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
    origin: F64

    @classmethod
    def from_sums(
        cls, sums: F64, counts: NDArray[np.int32], resolution: float, origin: F64
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
    acc = TextureAccumulator((1, 1), 1.0, np.zeros(2), config)
    rgb = np.zeros((1, 1, 3), dtype=np.uint8)[:, :, ::-1]  # load_rgb's BGR→RGB view
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


def build_texture(
    index: RgbdIndex,
    times: F64,
    poses: F64,
    grid: OccupancyGrid,
    config: TextureConfig,
    progress: bool = False,
) -> TextureResult:
    """Texture of the frames of ``index`` seen along the trajectory ``(times, poses)`` on ``grid``.

    Frames are decoded ``config.read_threads`` at a time ahead of the accumulation. Skipped frames
    are counted in the result's plan and reported as :class:`TextureWarning` (one per reason).
    """
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    warm_up()
    start = time.perf_counter()
    time_range = (float(times.min()), float(times.max())) if times.size else (0.0, -1.0)
    plan = plan_frames(index, config, time_range)
    model = kinect_model(config)
    acc = TextureAccumulator(grid.shape, grid.resolution, grid.origin, config, model)
    n = plan.rgb.size
    used = np.zeros(n, dtype=bool)
    if n:
        pose_d = interpolate_poses(times, poses, plan.disparity_time)
        pose_r = interpolate_poses(times, poses, plan.rgb_time)
    bar = None
    if progress and n:
        from tqdm import tqdm

        bar = tqdm(total=n, desc="texture", unit="frame", leave=False)
    window = 2 * config.read_threads + 2
    with ThreadPoolExecutor(max_workers=config.read_threads) as pool:
        pending: deque[Future] = deque()
        submitted = 0
        for k in range(n):
            while submitted < n and len(pending) < window:
                pending.append(
                    pool.submit(
                        _read_pair,
                        index,
                        model,
                        int(plan.rgb[submitted]),
                        int(plan.disparity[submitted]),
                    )
                )
                submitted += 1
            rgb, disparity, reason, message = pending.popleft().result()
            if reason is not None:
                plan.skip(reason, 1, message)
            else:
                acc.add_frame(disparity, rgb, pose_d[k], pose_r[k])
                used[k] = True
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    messages = _warn_skips(plan, index)
    return TextureResult(
        texture=acc.texture(),
        plan=plan,
        used=used,
        samples=acc.samples,
        wall_s=time.perf_counter() - start,
        warnings=messages,
    )


def _warn_skips(plan: FramePlan, index: RgbdIndex) -> list[str]:
    """One :class:`TextureWarning` per skip reason and per count mismatch; return their texts."""
    messages = []
    for stream, info in plan.count_mismatch.items():
        folder = index.rgb_dir if stream == "rgb" else index.disparity_dir
        messages.append(
            f"texture: {folder} holds {info['files']} {stream} PNGs but the log has "
            f"{info['timestamps']} {stream} timestamps; frames are matched by number"
        )
    for reason, count in plan.skipped.items():
        messages.append(
            f"texture: skipped {count} RGB frame(s): {SKIP_REASONS[reason]} "
            f"(e.g. {plan.examples.get(reason, '')})"
        )
    for message in messages:
        warnings.warn(message, TextureWarning, stacklevel=3)
    return messages


# ------------------------------------------------------------------------------- ground truth


@dataclass(frozen=True)
class GroundTruth:
    """What a simulated dataset knows for sure: the path, the floor texture and the walls."""

    times: F64
    poses: F64
    texture: NDArray[np.uint8]
    """``(Ht, Wt, 3)`` true floor colours (texels)."""
    floor: NDArray[np.bool_]
    """``(Ht, Wt)`` texels that are visible floor."""
    texture_resolution: float
    texture_origin: F64
    occupancy: NDArray[np.uint8]
    """``(Hm, Wm)`` 1 where an obstacle (extruded from the floor up) stands."""
    map_resolution: float
    map_origin: F64


def _load_npz(path: Path, keys: tuple[str, ...]) -> dict[str, NDArray[Any]]:
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in keys if k not in data.files]
            if missing:
                raise DataError(
                    f"{path}: missing key(s) {', '.join(missing)}; found {', '.join(data.files)}"
                )
            return {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read ({exc})") from None


def load_ground_truth(folder: Path) -> GroundTruth | None:
    """The ground truth of a simulated dataset folder, or ``None`` when it has none.

    Needs ``groundtruth.tum``, ``groundtruth_texture.npz`` (``rgb``, ``resolution``, ``origin``,
    optional ``floor``: without it every non-black texel is floor) and ``groundtruth_map.npz``
    (``occupancy``, ``resolution``, ``origin``).
    """
    from slam.io.tum import read_tum

    folder = Path(folder)
    names = ("groundtruth.tum", "groundtruth_texture.npz", "groundtruth_map.npz")
    if not folder.is_dir() or not all((folder / n).is_file() for n in names):
        return None
    times, poses = read_tum(folder / names[0])
    tex = _load_npz(folder / names[1], ("rgb", "resolution", "origin"))
    occ = _load_npz(folder / names[2], ("occupancy", "resolution", "origin"))
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


@njit(cache=True)
def _line_of_sight(occ, occ_ox, occ_oy, occ_res, x0, y0, x1, y1):
    """No obstacle cell of ``occ`` on the segment (sampled every quarter cell)."""
    length = math.hypot(x1 - x0, y1 - y0)
    steps = int(length / (0.25 * occ_res)) + 1
    oh, ow = occ.shape[0], occ.shape[1]
    for s in range(steps + 1):
        t = s / steps
        cx = int(math.floor((x0 + t * (x1 - x0) - occ_ox) / occ_res))
        cy = int(math.floor((y0 + t * (y1 - y0) - occ_oy) / occ_res))
        if 0 <= cx < ow and 0 <= cy < oh and occ[cy, cx] != 0:
            return False
    return True


@njit(cache=True)
def mark_swept(floor_cells, origin_x, origin_y, resolution, occ, occ_ox, occ_oy, occ_res,
               rotations, positions, params, height, width, out):  # fmt: skip
    """Mark in ``out`` the floor cells whose centre one of the cameras sees (see :func:`swept_cells`).

    ``rotations (F, 3, 3)`` (optical → world) and ``positions (F, 3)`` are the cameras; ``params``
    as for :func:`accumulate_frame`.
    """
    fx, fy, cx, cy = params[0], params[1], params[2], params[3]
    numer, min_depth, max_depth = params[6], params[7], params[8]
    g, c_i, k_dd, c_j, nrm = params[10], params[11], params[12], params[13], params[14]
    gh, gw = floor_cells.shape[0], floor_cells.shape[1]
    for f in range(rotations.shape[0]):
        r = rotations[f]
        px, py, pz = positions[f, 0], positions[f, 1], positions[f, 2]
        x_lo = int(math.floor((px - max_depth - origin_x) / resolution))
        x_hi = int(math.floor((px + max_depth - origin_x) / resolution))
        y_lo = int(math.floor((py - max_depth - origin_y) / resolution))
        y_hi = int(math.floor((py + max_depth - origin_y) / resolution))
        for iy in range(max(y_lo, 0), min(y_hi + 1, gh)):
            y = origin_y + (iy + 0.5) * resolution
            for ix in range(max(x_lo, 0), min(x_hi + 1, gw)):
                if out[iy, ix] or not floor_cells[iy, ix]:
                    continue
                x = origin_x + (ix + 0.5) * resolution
                qx, qy, qz = x - px, y - py, -pz
                oz = r[0, 2] * qx + r[1, 2] * qy + r[2, 2] * qz
                if oz < min_depth or oz > max_depth:
                    continue
                ox = r[0, 0] * qx + r[1, 0] * qy + r[2, 0] * qz
                oy = r[0, 1] * qx + r[1, 1] * qy + r[2, 1] * qz
                i = fy * oy / oz + cy
                j = fx * ox / oz + cx
                if i < -0.5 or j < -0.5 or i >= height - 0.5 or j >= width - 0.5:
                    continue
                ri = int(math.floor((g * i + c_i - k_dd * (numer / oz)) / nrm + 0.5))
                rj = int(math.floor((g * j + c_j) / nrm + 0.5))
                if ri < 0 or rj < 0 or ri >= height or rj >= width:
                    continue
                if _line_of_sight(occ, occ_ox, occ_oy, occ_res, px, py, x, y):
                    out[iy, ix] = True


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
        rotations, positions, kernel_parameters(model, config), model.height, model.width, out,
    )  # fmt: skip
    return out


def evaluate_texture(
    texture: TextureMap,
    gt: GroundTruth,
    frame_times: F64,
    config: TextureConfig,
    trajectory: tuple[F64, F64] | None = None,
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
    if trajectory is not None and len(trajectory[0]) > 1:
        from slam.eval.trajectory import align_se2

        times, poses = (np.asarray(a, dtype=np.float64) for a in trajectory)
        inside = (times >= gt.times[0]) & (times <= gt.times[-1])
        if inside.sum() > 1:
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
            cells = np.floor((back - texture.origin) / res)
            cx, cy = cells[:, 0].astype(np.int64), cells[:, 1].astype(np.int64)
            ok = (cx >= 0) & (cy >= 0) & (cx < shape[1]) & (cy < shape[0])
            hit = np.zeros(cx.shape, dtype=bool)
            hit[ok] = coloured[cy[ok], cx[ok]]
            out["alignment"] = [round(float(v), 5) for v in transform]
            out["colour_mae_aligned"] = _rounded(err_a.mean() if err_a.size else None, 3)
            out["coverage_aligned"] = _rounded(hit.mean() if hit.size else None, 4)
    return out


def _rounded(value: Any, digits: int) -> float | None:
    return None if value is None else round(float(value), digits)


# ------------------------------------------------------------------------------------ outputs


def display_scale(shape: tuple[int, int]) -> int:
    """Pixels per cell of the run's pictures: the rule of ``map.png`` (about 800 px wide)."""
    return max(1, int(round(800 / max(shape))))


def _upscale(img: NDArray[np.uint8], scale: int) -> NDArray[np.uint8]:
    if scale == 1:
        return img
    return np.ascontiguousarray(np.repeat(np.repeat(img, scale, axis=0), scale, axis=1))


def render_texture(texture: TextureMap) -> NDArray[np.uint8]:
    """``texture.png`` as a BGR image: +y up, same size and scale as ``map.png``."""
    img = np.ascontiguousarray(texture.rgb[::-1, :, ::-1])
    return _upscale(img, display_scale(texture.count.shape))


def render_overlay(texture: TextureMap, grid: OccupancyGrid) -> NDArray[np.uint8]:
    """``texture_overlay.png`` (BGR): the occupancy picture with coloured cells painted over the
    free ones and obstacles kept dark on top."""
    grey = grid.to_image()
    img = np.repeat(grey[:, :, None], 3, axis=2)
    coloured = texture.coloured[::-1] & ~grid.occupied()[::-1]
    img[coloured] = texture.rgb[::-1, :, ::-1][coloured]
    return _upscale(np.ascontiguousarray(img), display_scale(texture.count.shape))


def _write_png(path: Path, image: NDArray[np.uint8]) -> None:
    import cv2

    ok, data = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - OpenCV failure
        raise OSError(f"{path}: PNG encoding failed")
    with atomic_path(path) as tmp:
        tmp.write_bytes(data.tobytes())


def write_outputs(out_dir: Path, texture: TextureMap, grid: OccupancyGrid) -> None:
    """Write ``texture.npz``, ``texture.png`` and ``texture_overlay.png`` (each atomically)."""
    out_dir = Path(out_dir)
    with atomic_path(out_dir / "texture.npz") as tmp:
        np.savez_compressed(
            tmp,
            rgb=texture.rgb,
            count=texture.count,
            resolution=np.float64(texture.resolution),
            origin=texture.origin.astype(np.float64),
        )
    _write_png(out_dir / "texture.png", render_texture(texture))
    _write_png(out_dir / "texture_overlay.png", render_overlay(texture, grid))


# -------------------------------------------------------------------------------------- stage


def images_missing(log: Log) -> str | None:
    """Why the log's RGB-D images cannot be used at all (folders absent), or ``None``."""
    status = str(log.meta.get("rgbd_images", "present"))
    if status.startswith("missing"):
        return status
    index = log.rgbd
    if index is not None:
        absent = [str(d) for d in (index.rgb_dir, index.disparity_dir) if not Path(d).is_dir()]
        if absent:
            return "missing: " + ", ".join(absent)
    return None


def texture_stage(
    log: Log,
    times: F64,
    poses: F64,
    grid: OccupancyGrid,
    config: Config,
    out_dir: Path,
    progress: bool = False,
) -> dict[str, Any]:
    """Compute the texture of ``log`` along ``(times, poses)`` on ``grid``, write the outputs into
    ``out_dir`` and return the figures for ``metrics.json`` (with the ground-truth evaluation when
    the log's folder is a simulated dataset).

    When the image folders are missing nothing is written and the figures say why.
    """
    tc = config.texture
    index = log.rgbd
    if index is None:
        return {"skipped": "the log has no RGB-D frames"}
    why = images_missing(log)
    if why is not None:
        message = f"texture: skipped, RGB-D image folders {why}"
        warnings.warn(message, TextureWarning, stacklevel=2)
        return {"skipped": message}
    result = build_texture(index, times, poses, grid, tc, progress)
    write_outputs(out_dir, result.texture, grid)
    plan = result.plan
    used = int(result.used.sum())
    gaps = np.abs(plan.rgb_time[result.used] - plan.disparity_time[result.used])
    coloured = int(result.texture.coloured.sum())
    metrics: dict[str, Any] = {
        "mode": tc.mode,
        "rgb_frames": int(index.rgb_time.size),
        "disparity_frames": int(index.disparity_time.size),
        "frames_considered": plan.considered,
        "frames_used": used,
        "frames_skipped": int(sum(plan.skipped.values())),
        "skipped": dict(sorted(plan.skipped.items())),
        "pair_gap_mean_s": round(float(gaps.mean()), 4) if gaps.size else None,
        "pair_gap_max_s": round(float(gaps.max()), 4) if gaps.size else None,
        "floor_samples": result.samples,
        "coloured_cells": coloured,
        "coloured_area_m2": round(coloured * grid.resolution**2, 3),
        "wall_s": round(result.wall_s, 3),
        "frames_per_s": round(used / result.wall_s, 1) if result.wall_s > 0 else None,
    }
    if plan.count_mismatch:
        metrics["count_mismatch"] = plan.count_mismatch
    source = Path(log.source) if log.source is not None else None
    gt = load_ground_truth(source) if source is not None else None
    if gt is not None:
        metrics["ground_truth"] = evaluate_texture(
            result.texture, gt, plan.disparity_time[result.used], tc, (times, poses)
        )
    return metrics


def run_stage(
    log: Log, estimate: Any, config: Config, out_dir: Path, progress: bool = False
) -> dict[str, Any]:
    """The texture stage as ``slam run`` calls it, on an estimate with ``times``, ``poses`` and
    ``grid``: ``{"texture": figures}``, or ``{}`` when the stage does not apply (disabled, or no
    RGB-D stream); without a map (dead reckoning without scans) the figures say it was skipped."""
    grid = getattr(estimate, "grid", None)
    if not config.texture.enabled or log.rgbd is None:
        return {}
    if grid is None:
        return {"texture": {"skipped": "no occupancy map to put the texture on"}}
    figures = texture_stage(log, estimate.times, estimate.poses, grid, config, out_dir, progress)
    return {"texture": figures}


def update_metrics(path: Path, figures: dict[str, Any]) -> None:
    """Replace the ``"texture"`` key of the ``metrics.json`` at ``path`` (atomically)."""
    path = Path(path)
    try:
        metrics = json.loads(path.read_text()) if path.is_file() else {}
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read metrics ({exc})") from None
    if not isinstance(metrics, dict):
        raise DataError(f"{path}: expected a JSON object, found {type(metrics).__name__}")
    metrics["texture"] = figures
    write_text(path, json.dumps(metrics, indent=2) + "\n")


# ------------------------------------------------------------------------- finished runs


RUN_FILES = ("config.toml", "trajectory.tum", "map.npz")
"""What ``slam texture RUN_DIR`` reads from a run folder."""


def recompute_run(
    run_dir: Path,
    data_dir: Path,
    *,
    mode: str | None = None,
    dataset: str | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Recompute the texture of a finished run from its ``trajectory.tum`` and ``map.npz`` and the
    dataset named in its ``config.toml`` (or ``dataset``); rewrite ``texture.npz``,
    ``texture.png``, ``texture_overlay.png`` and the ``"texture"`` key of ``metrics.json``, each
    atomically. Returns the texture figures.
    """
    import dataclasses

    from slam.config import load_config
    from slam.errors import UsageError
    from slam.io import sources
    from slam.io.tum import read_tum

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise DataError(f"{run_dir}: run folder not found")
    missing = [n for n in RUN_FILES if not (run_dir / n).is_file()]
    if missing:
        raise DataError(
            f"{run_dir}: not a finished run folder, missing {', '.join(missing)} "
            "(expected the output of `slam run`)"
        )
    config = load_config("", run_dir / "config.toml")
    if mode is not None:
        if mode not in TEXTURE_MODES:
            raise UsageError(f"--mode: expected one of {', '.join(TEXTURE_MODES)}, found {mode!r}")
        config = dataclasses.replace(config, texture=dataclasses.replace(config.texture, mode=mode))
    name = dataset or config.dataset
    if not name:
        raise DataError(f"{run_dir / 'config.toml'}: no 'dataset' key; give --dataset")
    where = "--dataset" if dataset else f"{run_dir / 'config.toml'}: dataset"
    hint = "" if dataset else "give the dataset with --dataset NAME_OR_PATH"
    ref = sources.resolve(name, data_dir, where=where, hint=hint)
    times, poses = read_tum(run_dir / "trajectory.tum")
    arrays = _load_npz(run_dir / "map.npz", ("log_odds", "resolution", "origin"))
    log_odds = np.asarray(arrays["log_odds"], dtype=np.float32)
    if log_odds.ndim != 2:
        raise DataError(f"{run_dir / 'map.npz'}: log_odds must be 2-D, found {log_odds.shape}")
    resolution, origin = np.asarray(arrays["resolution"]), np.asarray(arrays["origin"])
    if resolution.size != 1 or origin.size != 2:
        raise DataError(
            f"{run_dir / 'map.npz'}: expected a scalar resolution and a 2-element origin, found "
            f"resolution of shape {resolution.shape} and origin of shape {origin.shape}"
        )
    grid = OccupancyGrid.from_arrays(
        log_odds, float(resolution.reshape(())), origin.reshape(2), config.map
    )
    log = sources.load(ref, config, need=("kinect",), progress=progress).log
    if log.rgbd is None:
        raise DataError(f"dataset {name}: no Kinect frames (KinectNN.npz)")
    why = images_missing(log)
    if why is not None:
        raise DataError(f"dataset {name}: RGB-D image folders {why}")
    figures = texture_stage(log, times, poses, grid, config, run_dir, progress)
    update_metrics(run_dir / "metrics.json", figures)
    return figures
