"""Simulated Kinect frames: disparity and RGB images rendered from the world at a robot pose.

Camera rays of the :class:`~slam.kinect.KinectModel` are cast against the floor plane (z = 0) and
the obstacles (cells of the grid extruded to ``world.wall_height``): per frame, the first obstacle
along a fine fan of horizontal directions is found by grid traversal, then every pixel compares its
floor intersection with that obstacle distance (numba kernels in :mod:`slam.sim.kernels`).

* The **disparity** image inverts the course's depth formula: ``d = (1.03/depth − 3.31)/−0.00304``
  rounded to an integer, 2047 where the depth is outside ``[min_depth, max_depth]``.
* The **RGB** image follows the course's alignment formula: RGB pixel ``(ri, rj)`` shows the surface
  seen by depth pixel ``(i, j)`` with ``(ri, rj) = rgb_coordinates(i, j, dd(i, j))``. Floor pixels
  take the nearest texel of the floor texture, obstacles a plain colour per kind (darker on faces
  of constant y).

Noise (disparity jitter and holes, RGB pixel noise and exposure) comes from tables of random
numbers drawn once by the caller's generator and read from per-frame random offsets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.kinect import KinectModel, robot_to_world
from slam.sim.kernels import render_disparity, render_rgb
from slam.sim.world import LABEL_COLORS, OUTSIDE_COLOR, World

AZIMUTH_SAMPLES = 2048
"""Horizontal directions traced per frame (≈0.03° apart over the camera's field of view)."""


@dataclass(frozen=True)
class FrameNoise:
    """Noise of one Kinect frame: offsets into the shared random tables and the exposure gain."""

    noise_offset: int = 0
    hole_offset: int = 0
    gain: float = 1.0


class KinectRenderer:
    """Renders disparity and RGB frames of ``world`` seen by ``model``."""

    def __init__(
        self,
        world: World,
        model: KinectModel | None = None,
        noise_table: NDArray[np.float32] | None = None,
        hole_table: NDArray[np.float32] | None = None,
        disparity_sigma: float = 0.0,
        hole_prob: float = 0.0,
        rgb_sigma: float = 0.0,
    ) -> None:
        self.world = world
        self.model = model = model if model is not None else KinectModel()
        self.noise = noise_table if noise_table is not None else np.zeros(1, np.float32)
        self.holes = hole_table if hole_table is not None else np.ones(1, np.float32)
        self.disparity_sigma = float(disparity_sigma)
        self.hole_prob = float(hole_prob)
        self.rgb_sigma = float(rgb_sigma)
        m = model
        self._intr = np.array([m.fx, m.fy, m.cx, m.cy, float(m.height), float(m.width)])
        self._disp = np.array(
            [
                m.disparity_scale,
                m.disparity_offset,
                m.depth_numerator,
                m.min_depth,
                m.max_depth,
                float(m.invalid_disparity),
            ]
        )
        self._align = np.array(
            [m.rgb_gain, m.rgb_row_offset, m.rgb_row_dd, m.rgb_col_offset, m.rgb_norm,
             m.depth_numerator]
        )  # fmt: skip
        self._colors = np.ascontiguousarray(LABEL_COLORS)
        self._outside = np.ascontiguousarray(OUTSIDE_COLOR)

    def camera(self, pose: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
        """World rotation (optical → world) and position of the camera at robot ``pose``."""
        pose = np.asarray(pose, dtype=np.float64)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        rot = rz @ self.model.rotation
        cam = robot_to_world(self.model.translation, pose)
        return np.ascontiguousarray(rot), np.ascontiguousarray(cam)

    def disparity(
        self, pose: NDArray[np.float64], noise: FrameNoise = FrameNoise()
    ) -> tuple[NDArray[np.uint16], NDArray[np.float64], NDArray[np.int8]]:
        """Disparity image (uint16), true depth (m, inf where nothing) and hit kind (0 floor,
        1 obstacle, -1 nothing) at robot ``pose``."""
        rot, cam = self.camera(pose)
        w = self.world
        return render_disparity(
            w.labels, w.origin[0], w.origin[1], w.resolution, rot, cam, self._intr, self._disp,
            w.wall_height, AZIMUTH_SAMPLES, self.noise, noise.noise_offset, self.disparity_sigma,
            self.holes, noise.hole_offset, self.hole_prob,
        )  # fmt: skip

    def rgb(self, pose: NDArray[np.float64], noise: FrameNoise = FrameNoise()) -> NDArray[np.uint8]:
        """RGB image ``(H, W, 3)`` uint8 (RGB order) at robot ``pose``."""
        rot, cam = self.camera(pose)
        w = self.world
        return render_rgb(
            w.labels, w.origin[0], w.origin[1], w.resolution, rot, cam, self._intr, self._align,
            w.texture, w.texture_origin[0], w.texture_origin[1], w.texture_resolution,
            self._outside, self._colors, w.wall_height, AZIMUTH_SAMPLES, noise.gain, self.noise,
            noise.noise_offset, self.rgb_sigma,
        )  # fmt: skip
