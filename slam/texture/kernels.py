"""The numba kernels of the texture stage and the camera numbers they take.

This module owns the per-pixel and per-cell loops (docs/texture.md, "How it works" 3–6):

* :func:`accumulate_frame`: one fused pass over a disparity image, disparity → depth (through
  :func:`depth_table`) → optical point → world point → floor test → motion-compensated RGB pixel
  → colour sums of the map cell;
* :func:`mark_swept`: the floor cells a set of true camera poses could see (for the coverage
  figure of :mod:`slam.texture.evaluate`);

and what they are fed: the Kinect model of a configuration (:func:`kinect_model`), the camera's
pose in the world at a robot pose (:func:`camera_in_world`) and the scalars of the projection as
one :class:`CameraParameters` NamedTuple. Kernels allocate nothing and draw nothing random.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from slam.config import TextureConfig
from slam.kernels.cells import cell_index
from slam.kernels.threads import in_threads
from slam.kinect import KinectModel

F64 = NDArray[np.float64]


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


def camera_in_world(model: KinectModel, pose: F64) -> tuple[F64, F64]:
    """Rotation (optical → world) and position of the camera at robot ``pose`` ``(x, y, θ)``."""
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rotation = rz @ model.rotation
    t = model.translation
    position = np.array([pose[0] + c * t[0] - s * t[1], pose[1] + s * t[0] + c * t[1], t[2]])
    return np.ascontiguousarray(rotation), position


class CameraParameters(NamedTuple):
    """The camera and projection numbers of the texture kernels, one argument for numba.

    Intrinsics and the RGB alignment formula come from :class:`~slam.kinect.KinectModel`, the
    depth range and floor band from :class:`~slam.config.TextureConfig`.
    """

    fx: float
    """Focal length along image columns (px)."""
    fy: float
    """Focal length along image rows (px)."""
    cx: float
    """Principal point column (px)."""
    cy: float
    """Principal point row (px)."""
    depth_numerator: float
    """``dd = depth_numerator / depth`` (the course's 1.03)."""
    min_depth: float
    """Nearest depth used (m)."""
    max_depth: float
    """Farthest depth used (m)."""
    floor_height: float
    """Half-height of the floor band around z = 0 (m)."""
    rgb_gain: float
    """``g`` of the RGB alignment ``((g·i + c_i − k·dd)/n, (g·j + c_j)/n)``."""
    rgb_row_offset: float
    """``c_i`` of the RGB alignment."""
    rgb_row_dd: float
    """``k`` of the RGB alignment."""
    rgb_col_offset: float
    """``c_j`` of the RGB alignment."""
    rgb_norm: float
    """``n`` of the RGB alignment."""
    height: int
    """Image rows (depth and RGB images have the same size)."""
    width: int
    """Image columns."""


def camera_parameters(model: KinectModel, config: TextureConfig) -> CameraParameters:
    """The :class:`CameraParameters` of ``model`` with the depth range and floor band of
    ``config`` (floats as float64, sizes as int64: one numba signature whatever the TOML held)."""
    return CameraParameters(
        fx=float(model.fx),
        fy=float(model.fy),
        cx=float(model.cx),
        cy=float(model.cy),
        depth_numerator=float(model.depth_numerator),
        min_depth=float(config.min_depth),
        max_depth=float(config.max_depth),
        floor_height=float(config.floor_height),
        rgb_gain=float(model.rgb_gain),
        rgb_row_offset=float(model.rgb_row_offset),
        rgb_row_dd=float(model.rgb_row_dd),
        rgb_col_offset=float(model.rgb_col_offset),
        rgb_norm=float(model.rgb_norm),
        height=int(model.height),
        width=int(model.width),
    )


def depth_table(model: KinectModel, config: TextureConfig) -> F64:
    """Depth (m) of every raw disparity value, 0 where it is no measurement or outside
    ``[min_depth, max_depth]``; values past the table's end are all invalid."""
    depth = model.disparity_to_depth(np.arange(65536, dtype=np.float64))
    valid = np.isfinite(depth) & (depth >= config.min_depth) & (depth <= config.max_depth)
    table = np.where(valid, depth, 0.0)
    last = np.flatnonzero(valid)
    return np.ascontiguousarray(table[: last[-1] + 1 if last.size else 0])


@njit(cache=True, error_model="numpy", nogil=True)
def accumulate_frame(disparity, rgb, stride, camera, depth_lut, rot_d, cam_d, rot_rel, t_rel,
                     origin_x, origin_y, resolution, sums, counts, stamps, frame_id,
                     latest):  # fmt: skip
    """Add the floor pixels of one RGB-D frame pair to the per-cell colour sums.

    For each ``stride``-th pixel ``(i, j)`` of ``disparity`` with raw value ``d``: depth
    ``depth_lut[d]`` (the course formula ``1.03 / (−0.00304·d + 3.31)``, 0 when invalid or out of
    range, see :func:`depth_table`); optical point ``o = ((j − cx)/fx, (i − cy)/fy, 1)·depth``;
    world point ``rot_d · o + cam_d`` (camera pose at the disparity time), floor when
    ``|z| ≤ camera.floor_height``. The point in the optical frame of the RGB time is ``o' =
    rot_rel · o + t_rel``; its depth pixel is ``(i', j') = (fy·o'y/o'z + cy, fx·o'x/o'z + cx)``
    with ``dd' = 1.03/o'z``, and its RGB pixel ``((g·i' + c_i − k·dd')/n, (g·j' + c_j)/n)`` (the
    ``rgb_*`` fields of ``camera``, a :class:`CameraParameters`), read at the nearest pixel. The
    colour is added to ``sums[iy, ix]`` and ``counts[iy, ix]`` of the cell holding the world
    point; with ``latest`` a cell first seen in this frame (``stamps != frame_id``) is reset first.
    Returns the samples added.

    Rows whose every ray stays outside the floor band over the whole depth range (those above
    the horizon and those whose floor lies beyond ``max_depth``) are skipped without reading a
    pixel: the world height of a ray per metre of depth is linear along a row, so its extremes
    over the row and the depth range are at the four corners (with a 1 µm margin, far above the
    rounding of the per-pixel test, so the skip never drops a floor pixel). ``sums`` are
    integers (int64: exact sums of 8-bit colours, whatever the order). Releases the GIL.
    Long because the whole pixel → cell path is one fused loop: split into calls, numba would
    pass the intermediate points through memory for 307 200 pixels a frame.
    """
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    numer, floor_h = camera.depth_numerator, camera.floor_height
    g, c_i = camera.rgb_gain, camera.rgb_row_offset
    k_dd, c_j = camera.rgb_row_dd, camera.rgb_col_offset
    inv_fx, inv_fy, inv_nrm = 1.0 / fx, 1.0 / fy, 1.0 / camera.rgb_norm
    h, w = disparity.shape[0], disparity.shape[1]
    rh, rw = rgb.shape[0], rgb.shape[1]
    gh, gw = counts.shape[0], counts.shape[1]
    n_lut = depth_lut.shape[0]
    inv_res = 1.0 / resolution
    d_lo, d_hi, margin = camera.min_depth, camera.max_depth, 1e-6
    added = 0
    for i in range(0, h, stride):
        yn = (i - cy) * inv_fy
        # world z per metre of depth at the first and last column of the row
        s0 = rot_d[2, 0] * (0.0 - cx) * inv_fx + rot_d[2, 1] * yn + rot_d[2, 2]
        s1 = rot_d[2, 0] * (w - 1.0 - cx) * inv_fx + rot_d[2, 1] * yn + rot_d[2, 2]
        z_a, z_b = cam_d[2] + d_lo * s0, cam_d[2] + d_hi * s0
        z_c, z_d = cam_d[2] + d_lo * s1, cam_d[2] + d_hi * s1
        if min(min(z_a, z_b), min(z_c, z_d)) > floor_h + margin:
            continue
        if max(max(z_a, z_b), max(z_c, z_d)) < -floor_h - margin:
            continue
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
                sums[iy, ix, 0] = 0
                sums[iy, ix, 1] = 0
                sums[iy, ix, 2] = 0
                counts[iy, ix] = 0
            sums[iy, ix, 0] += rgb[ri, rj, 0]
            sums[iy, ix, 1] += rgb[ri, rj, 1]
            sums[iy, ix, 2] += rgb[ri, rj, 2]
            counts[iy, ix] += 1
            added += 1
    return added


@njit(cache=True, _nrt=False)
def _line_of_sight(occ, occ_ox, occ_oy, occ_res, x0, y0, x1, y1):
    """No obstacle cell of ``occ`` on the segment (sampled every quarter cell)."""
    length = math.hypot(x1 - x0, y1 - y0)
    steps = int(length / (0.25 * occ_res)) + 1
    oh, ow = occ.shape[0], occ.shape[1]
    for s in range(steps + 1):
        t = s / steps
        cx = cell_index(x0 + t * (x1 - x0), occ_ox, occ_res)
        cy = cell_index(y0 + t * (y1 - y0), occ_oy, occ_res)
        if 0 <= cx < ow and 0 <= cy < oh and occ[cy, cx] != 0:
            return False
    return True


def mark_swept(
    floor_cells: np.ndarray,
    origin_x: float,
    origin_y: float,
    resolution: float,
    occ: np.ndarray,
    occ_ox: float,
    occ_oy: float,
    occ_res: float,
    rotations: np.ndarray,
    positions: np.ndarray,
    camera: CameraParameters,
    out: np.ndarray,
) -> None:
    """Mark in ``out`` the floor cells whose centre one of the cameras sees (see
    :func:`slam.texture.evaluate.swept_cells`).

    ``rotations (F, 3, 3)`` (optical → world) and ``positions (F, 3)`` are the cameras; ``camera``
    the :class:`CameraParameters`, as for :func:`accumulate_frame`. Bands of :data:`SWEPT_ROWS`
    rows of the grid on a few threads (:func:`~slam.kernels.threads.in_threads`: a serial
    kernel compiles in a fraction of a ``parallel=True`` one's time); each band writes only its
    own rows, and a cell is marked by whichever camera sees it first, so the result does not
    depend on the thread count.
    """
    in_threads(
        [
            partial(
                _mark_swept_rows,
                floor_cells,
                origin_x,
                origin_y,
                resolution,
                occ,
                occ_ox,
                occ_oy,
                occ_res,
                rotations,
                positions,
                camera,
                out,
                r,
                min(r + SWEPT_ROWS, floor_cells.shape[0]),
            )
            for r in range(0, floor_cells.shape[0], SWEPT_ROWS)
        ]
    )


SWEPT_ROWS = 32
"""Grid rows per call of :func:`_mark_swept_rows` (many bands: the threads share the load)."""


@njit(cache=True, nogil=True)
def _mark_swept_rows(floor_cells, origin_x, origin_y, resolution, occ, occ_ox, occ_oy, occ_res,
                     rotations, positions, camera, out, row0, row1):  # fmt: skip
    """:func:`mark_swept` for the grid rows ``row0 .. row1 − 1``."""
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    numer, min_depth, max_depth = camera.depth_numerator, camera.min_depth, camera.max_depth
    g, c_i = camera.rgb_gain, camera.rgb_row_offset
    k_dd, c_j = camera.rgb_row_dd, camera.rgb_col_offset
    nrm, height, width = camera.rgb_norm, camera.height, camera.width
    gh, gw = floor_cells.shape[0], floor_cells.shape[1]
    frames = rotations.shape[0]
    x_lo = np.empty(frames, np.int64)
    x_hi = np.empty(frames, np.int64)
    y_lo = np.empty(frames, np.int64)
    y_hi = np.empty(frames, np.int64)
    for f in range(frames):
        px, py = positions[f, 0], positions[f, 1]
        x_lo[f] = max(cell_index(px - max_depth, origin_x, resolution), 0)
        x_hi[f] = min(cell_index(px + max_depth, origin_x, resolution) + 1, gw)
        y_lo[f] = max(cell_index(py - max_depth, origin_y, resolution), 0)
        y_hi[f] = min(cell_index(py + max_depth, origin_y, resolution) + 1, gh)
    for iy in range(row0, row1):
        y = origin_y + (iy + 0.5) * resolution
        for f in range(frames):
            if iy < y_lo[f] or iy >= y_hi[f]:
                continue
            r = rotations[f]
            px, py, pz = positions[f, 0], positions[f, 1], positions[f, 2]
            for ix in range(x_lo[f], x_hi[f]):
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
