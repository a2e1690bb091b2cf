"""The texture stage's files: ``texture.npz``, ``texture.png`` and ``texture_overlay.png``.

This module owns how a :class:`~slam.texture.accumulate.TextureMap` is stored and drawn:
``texture.npz`` holds ``rgb``, ``count``, ``resolution`` and ``origin`` (the grid of ``map.npz``);
the pictures have the pixels of ``map.png`` (+y up, the same scale, :func:`display_scale`). Every
file is written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.io.atomic import write_npz, write_png
from slam.mapping import OccupancyGrid
from slam.texture.accumulate import TextureMap


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


def write_outputs(out_dir: Path, texture: TextureMap, grid: OccupancyGrid) -> None:
    """Write ``texture.npz``, ``texture.png`` and ``texture_overlay.png`` (each atomically)."""
    out_dir = Path(out_dir)
    arrays = {
        "rgb": texture.rgb,
        "count": texture.count,
        "resolution": np.float64(texture.resolution),
        "origin": texture.origin.astype(np.float64),
    }
    write_npz(out_dir / "texture.npz", arrays)
    write_png(out_dir / "texture.png", render_texture(texture))
    write_png(out_dir / "texture_overlay.png", render_overlay(texture, grid))
