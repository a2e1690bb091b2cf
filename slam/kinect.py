"""The Kinect camera model of the ECE276A robot: intrinsics, extrinsics, disparity and RGB alignment.

This module owns every formula that links a Kinect pixel to a point in the world, for whole images
at once (all functions broadcast over arrays):

* **Disparity → depth** (course formula): for the uint16 disparity ``d`` at depth pixel ``(i, j)``
  (``i`` row, ``j`` column), ``dd = -0.00304 · d + 3.31`` and ``depth = 1.03 / dd`` metres.
  :meth:`KinectModel.depth_to_disparity` is the exact inverse; the sensor's "no measurement" value
  is 2047 (``dd < 0``, so it never decodes to a positive depth).
* **RGB alignment** (course formula): the colour of depth pixel ``(i, j)`` is found in the RGB image
  at ``rgb_i = (526.37 i + 19276 − 7877.07 dd) / 585.051`` and ``rgb_j = (526.37 j + 16662) /
  585.051``. The inverse (RGB pixel → depth pixel) needs ``dd`` and is
  :meth:`KinectModel.depth_pixel_from_rgb`.
* **Intrinsics**: ``f = 585.05108211`` px. Images are 480 rows × 640 columns and the course's K
  holds the two numbers 242.94 and 315.84; the geometrically consistent reading is
  ``cx = 315.838`` (column, 3.7 px from the centre column 319.5) and ``cy = 242.941`` (row, 3.4 px
  from the centre row 239.5). The swapped reading of the course starter code would put the principal
  point 76 px off-centre both ways, giving a lopsided 22.6°/31.3° horizontal field of view instead of
  the Kinect's symmetric ≈57°. ``tests/test_kinect.py`` checks this with numbers.
* **Frames**: optical frame z forward, x right, y down; robot frame x forward, y left, z up with
  z = 0 on the floor; the camera sits at ``(0.18, 0.005, 0.36)`` m with roll 0, pitch 0.36 rad (a
  positive pitch tilts the optical axis down towards the floor) and yaw 0.021 rad, all configurable.
  The world frame is the planar robot pose ``(x, y, θ)`` lifted to 3D (rotation about z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

BODY_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Axis permutation from the optical frame (x right, y down, z forward) to a camera body frame
with the robot's axis convention (x forward, y left, z up)."""


def rotation_rpy(roll: float, pitch: float, yaw: float) -> F64:
    """``Rz(yaw) · Ry(pitch) · Rx(roll)``: rotation of a body frame with these Euler angles."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


@dataclass(frozen=True)
class KinectModel:
    """Kinect v1 of the ECE276A robot: depth (IR) camera, disparity coding and RGB alignment."""

    fx: float = 585.05108211
    """Focal length along image columns (px)."""
    fy: float = 585.05108211
    """Focal length along image rows (px)."""
    cx: float = 315.83800193
    """Principal point column (px); see the module docstring for why it is not 242.94."""
    cy: float = 242.94140713
    """Principal point row (px)."""
    width: int = 640
    """Image columns."""
    height: int = 480
    """Image rows."""
    x: float = 0.18
    """Camera position ahead of the robot centre (m)."""
    y: float = 0.005
    """Camera position to the left of the robot centre (m)."""
    z: float = 0.36
    """Camera height above the floor (m)."""
    roll: float = 0.0
    """Camera roll about its forward axis (rad)."""
    pitch: float = 0.36
    """Camera pitch (rad); positive looks down."""
    yaw: float = 0.021
    """Camera yaw relative to the robot heading (rad); positive looks left."""
    disparity_scale: float = -0.00304
    """``dd = disparity_scale · d + disparity_offset``."""
    disparity_offset: float = 3.31
    """See :attr:`disparity_scale`."""
    depth_numerator: float = 1.03
    """``depth = depth_numerator / dd`` (m)."""
    rgb_gain: float = 526.37
    """RGB alignment: ``rgb = (rgb_gain · pixel + offset …) / rgb_norm``."""
    rgb_row_offset: float = 19276.0
    """Constant of the RGB row formula."""
    rgb_row_dd: float = 7877.07
    """``dd`` coefficient of the RGB row formula (the stereo shift)."""
    rgb_col_offset: float = 16662.0
    """Constant of the RGB column formula."""
    rgb_norm: float = 585.051
    """Common divisor of the RGB formulas."""
    invalid_disparity: int = 2047
    """Disparity value written where the sensor has no measurement."""
    min_depth: float = 0.4
    """Shortest depth the sensor measures (m)."""
    max_depth: float = 6.0
    """Longest depth the sensor reports (m); farther surfaces read as :attr:`invalid_disparity`."""

    # ----------------------------------------------------------------- intrinsics and extrinsics
    @property
    def intrinsics(self) -> F64:
        """The 3×3 matrix K mapping optical-frame rays to ``(column, row, 1)``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def rotation(self) -> F64:
        """Rotation from the optical frame to the robot frame (3×3)."""
        return rotation_rpy(self.roll, self.pitch, self.yaw) @ BODY_FROM_OPTICAL

    @property
    def translation(self) -> F64:
        """Camera position in the robot frame (m)."""
        return np.array([self.x, self.y, self.z])

    def pixel_grid(self) -> tuple[F64, F64]:
        """Row and column index images ``(height, width)`` of the depth camera."""
        i, j = np.mgrid[0 : self.height, 0 : self.width]
        return i.astype(np.float64), j.astype(np.float64)

    # -------------------------------------------------------------------------- disparity/depth
    def disparity_to_dd(self, disparity: ArrayLike) -> F64:
        """The course's intermediate ``dd`` of raw disparity values."""
        d = np.asarray(disparity, dtype=np.float64)
        return self.disparity_scale * d + self.disparity_offset

    def dd_to_depth(self, dd: ArrayLike) -> F64:
        """Depth (m) of ``dd`` values; NaN where ``dd ≤ 0`` (no measurement)."""
        dd = np.asarray(dd, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(dd > 0.0, self.depth_numerator / dd, np.nan)

    def depth_to_dd(self, depth: ArrayLike) -> F64:
        """``dd`` of depths (m): the inverse of :meth:`dd_to_depth`."""
        depth = np.asarray(depth, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.depth_numerator / depth

    def disparity_to_depth(self, disparity: ArrayLike) -> F64:
        """Depth (m) of raw disparity values; NaN where they code no measurement."""
        return self.dd_to_depth(self.disparity_to_dd(disparity))

    def depth_to_disparity(self, depth: ArrayLike) -> F64:
        """Continuous disparity whose depth is ``depth``: the exact inverse of the course formula."""
        return (self.depth_to_dd(depth) - self.disparity_offset) / self.disparity_scale

    def encode_disparity(self, depth: ArrayLike) -> NDArray[np.uint16]:
        """The uint16 disparity a Kinect writes for ``depth`` (m): rounded, 2047 out of range/NaN."""
        depth = np.asarray(depth, dtype=np.float64)
        valid = np.isfinite(depth) & (depth >= self.min_depth) & (depth <= self.max_depth)
        d = np.where(valid, self.depth_to_disparity(np.where(valid, depth, 1.0)), 0.0)
        out = np.rint(d).astype(np.int64)
        out[~valid] = self.invalid_disparity
        return np.clip(out, 0, 65535).astype(np.uint16)

    # ------------------------------------------------------------------------------ RGB alignment
    def rgb_coordinates(self, i: ArrayLike, j: ArrayLike, dd: ArrayLike) -> tuple[F64, F64]:
        """RGB image row and column holding the colour of depth pixel ``(i, j)`` with ``dd``."""
        i = np.asarray(i, dtype=np.float64)
        j = np.asarray(j, dtype=np.float64)
        dd = np.asarray(dd, dtype=np.float64)
        rgb_i = (self.rgb_gain * i + self.rgb_row_offset - self.rgb_row_dd * dd) / self.rgb_norm
        rgb_j = (self.rgb_gain * j + self.rgb_col_offset) / self.rgb_norm
        return rgb_i, rgb_j

    def depth_pixel_from_rgb(
        self, rgb_i: ArrayLike, rgb_j: ArrayLike, dd: ArrayLike
    ) -> tuple[F64, F64]:
        """Depth pixel ``(i, j)`` whose colour sits at RGB pixel ``(rgb_i, rgb_j)`` (inverse)."""
        rgb_i = np.asarray(rgb_i, dtype=np.float64)
        rgb_j = np.asarray(rgb_j, dtype=np.float64)
        dd = np.asarray(dd, dtype=np.float64)
        i = (self.rgb_norm * rgb_i - self.rgb_row_offset + self.rgb_row_dd * dd) / self.rgb_gain
        j = (self.rgb_norm * rgb_j - self.rgb_col_offset) / self.rgb_gain
        return i, j

    # ------------------------------------------------------------------------------- projection
    def pixel_rays(self, i: ArrayLike, j: ArrayLike) -> F64:
        """Optical-frame rays ``(..., 3)`` through pixels ``(i, j)``, scaled to unit depth (z = 1)."""
        i = np.asarray(i, dtype=np.float64)
        j = np.asarray(j, dtype=np.float64)
        x = (j - self.cx) / self.fx
        y = (i - self.cy) / self.fy
        return np.stack([x, y, np.ones_like(x)], axis=-1)

    def pixel_to_optical(self, i: ArrayLike, j: ArrayLike, depth: ArrayLike) -> F64:
        """Points ``(..., 3)`` in the optical frame seen at pixels ``(i, j)`` with ``depth`` (m)."""
        depth = np.asarray(depth, dtype=np.float64)
        return self.pixel_rays(i, j) * depth[..., None]

    def optical_to_pixel(self, points: ArrayLike) -> tuple[F64, F64, F64]:
        """Row, column and depth of optical-frame points; depth ≤ 0 means behind the camera."""
        p = np.asarray(points, dtype=np.float64)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            j = self.fx * p[..., 0] / z + self.cx
            i = self.fy * p[..., 1] / z + self.cy
        return i, j, z

    def optical_to_robot(self, points: ArrayLike) -> F64:
        """Optical-frame points ``(..., 3)`` → robot frame."""
        p = np.asarray(points, dtype=np.float64)
        return p @ self.rotation.T + self.translation

    def robot_to_optical(self, points: ArrayLike) -> F64:
        """Robot-frame points ``(..., 3)`` → optical frame."""
        p = np.asarray(points, dtype=np.float64)
        return (p - self.translation) @ self.rotation

    def pixel_to_world(self, i: ArrayLike, j: ArrayLike, depth: ArrayLike, pose: ArrayLike) -> F64:
        """World points ``(..., 3)`` seen at pixels ``(i, j)`` with ``depth`` from robot ``pose``."""
        return robot_to_world(self.optical_to_robot(self.pixel_to_optical(i, j, depth)), pose)

    def world_to_pixel(self, points: ArrayLike, pose: ArrayLike) -> tuple[F64, F64, F64]:
        """Row, column and depth at which world points appear from robot ``pose``."""
        return self.optical_to_pixel(self.robot_to_optical(world_to_robot(points, pose)))

    def disparity_to_world(
        self, disparity: ArrayLike, pose: ArrayLike
    ) -> tuple[F64, NDArray[np.bool_]]:
        """World points ``(H, W, 3)`` of a whole disparity image from ``pose``, and the valid mask.

        Pixels with no measurement or a depth outside ``[min_depth, max_depth]`` are invalid (their
        points are NaN).
        """
        d = np.asarray(disparity)
        depth = self.disparity_to_depth(d)
        valid = np.isfinite(depth) & (depth >= self.min_depth) & (depth <= self.max_depth)
        i, j = np.indices(d.shape, dtype=np.float64)
        points = self.pixel_to_world(i, j, np.where(valid, depth, np.nan), pose)
        return points, valid

    def field_of_view_deg(self) -> tuple[float, float, float, float]:
        """Left, right, up and down half-angles of the depth image (degrees)."""
        left = math.degrees(math.atan((self.cx + 0.5) / self.fx))
        right = math.degrees(math.atan((self.width - 0.5 - self.cx) / self.fx))
        up = math.degrees(math.atan((self.cy + 0.5) / self.fy))
        down = math.degrees(math.atan((self.height - 0.5 - self.cy) / self.fy))
        return left, right, up, down


def robot_to_world(points: ArrayLike, pose: ArrayLike) -> F64:
    """Robot-frame 3D points ``(..., 3)`` → world frame, for a planar pose ``(x, y, θ)``."""
    p = np.asarray(points, dtype=np.float64)
    pose = np.asarray(pose, dtype=np.float64)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out = np.empty_like(p)
    out[..., 0] = pose[0] + c * p[..., 0] - s * p[..., 1]
    out[..., 1] = pose[1] + s * p[..., 0] + c * p[..., 1]
    out[..., 2] = p[..., 2]
    return out


def world_to_robot(points: ArrayLike, pose: ArrayLike) -> F64:
    """World 3D points ``(..., 3)`` → robot frame of the planar pose ``(x, y, θ)``."""
    p = np.asarray(points, dtype=np.float64)
    pose = np.asarray(pose, dtype=np.float64)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx = p[..., 0] - pose[0]
    dy = p[..., 1] - pose[1]
    out = np.empty_like(p)
    out[..., 0] = c * dx + s * dy
    out[..., 1] = -s * dx + c * dy
    out[..., 2] = p[..., 2]
    return out
