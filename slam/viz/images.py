"""Grids as images placed in world coordinates: the occupancy map and the floor texture.

Both follow the map convention (:mod:`slam.mapping`): ``array[iy, ix]`` is the cell whose lower-left
corner is ``origin + (ix, iy)·resolution``. A recording logs such an array *unflipped* as an
image (the grey occupancy map a PNG, :func:`as_png`; the colour texture an ``rr.Image``,
:func:`as_image`) with a ``Transform3D`` (translation = the lower-left corner of the cropped array,
scale = the cell size): pixel ``(u, v)`` lands on world ``origin + (u, v)·resolution``. The parent
``world`` entity flips the y axis once (see :mod:`slam.viz.blueprint`), so +y points up on screen.

The occupancy picture is cropped to the cells that have been observed (log-odds ≠ 0), and its
grey values are quantised to a few levels: both keep recordings small (PNG compresses the runs).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import rerun as rr
from numpy.typing import NDArray

from slam.mapping import OccupancyGrid
from slam.rowwise import by_rows


@dataclass
class PlacedImage:
    """An image and where its pixel (0, 0) corner lies in the world."""

    pixels: NDArray[np.uint8]
    """``(H, W)`` grey or ``(H, W, 3|4)`` colour, row ``v`` at ``y = corner_y + v·cell``."""
    corner: tuple[float, float]
    """World position of the lower-left corner of pixel (0, 0) (m)."""
    cell: float
    """Side of one pixel (m)."""


def as_image(pixels: NDArray[np.uint8], draw_order: float | None = None) -> rr.Image:
    """``rr.Image`` of ``(H, W)`` grey, ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA uint8 pixels.

    The shape is given explicitly: rerun drops unit dimensions of arrays, which would turn a
    one-row image (a 1D grid world) into a column.
    """
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    h, w = pixels.shape[:2]
    model = {2: "L"}.get(pixels.ndim) or {3: "RGB", 4: "RGBA"}[pixels.shape[2]]
    return rr.Image(
        bytes=pixels.reshape(-1),  # a view: no copy of a large picture before rerun's own
        width=w,
        height=h,
        color_model=model,
        datatype="U8",
        draw_order=draw_order,
    )


PNG_PARAMS = (
    cv2.IMWRITE_PNG_COMPRESSION, 1,
    cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
    cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE,
)  # fmt: skip
"""How the map pictures' PNG is written (:func:`as_png`): zlib's fastest level with run-length
matching and no row filter. A map is long runs of few grey levels: mit-killian's final map
(5206 × 6167) takes 42 ms and 0.53 MB this way, 143 ms and 0.89 MB with OpenCV's default
filters at the same level."""


def as_png(pixels: NDArray[np.uint8], draw_order: float | None = None) -> rr.EncodedImage:
    """``rr.EncodedImage`` of ``(H, W)`` grey uint8 pixels as a PNG (lossless; the viewer
    decodes it).

    The occupancy maps are logged this way: rerun then serialises and writes under a MB of
    PNG instead of the raw picture and its copies. Logging a picture the size of mit-killian's
    final map (5284 × 6208 pixels) raised the resident size by 156 MB as an ``rr.Image`` and by
    62 MB as a PNG (a one-off measurement, OpenCV's default filters); :data:`PNG_PARAMS` keeps
    the encoding at about 40 ms for it.
    """
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    if pixels.ndim != 2:
        raise ValueError(f"as_png: expected (H, W) grey pixels, found shape {pixels.shape}")
    ok, png = cv2.imencode(".png", pixels, list(PNG_PARAMS))
    if not ok:  # cv2 reports no reason; a grey uint8 picture always encodes
        raise ValueError(f"as_png: OpenCV could not encode a {pixels.shape} picture as PNG")
    return rr.EncodedImage(contents=png.tobytes(), media_type="image/png", draw_order=draw_order)


def observed_box(known: NDArray[np.bool_], margin: int = 1) -> tuple[int, int, int, int] | None:
    """``(iy0, iy1, ix0, ix1)`` bounding the True cells (plus ``margin``), or ``None``."""
    rows = np.flatnonzero(known.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(known.any(axis=0))
    h, w = known.shape
    return (
        max(int(rows[0]) - margin, 0),
        min(int(rows[-1]) + 1 + margin, h),
        max(int(cols[0]) - margin, 0),
        min(int(cols[-1]) + 1 + margin, w),
    )


def occupancy_pixels(log_odds: NDArray[np.floating], levels: int) -> NDArray[np.uint8]:
    """Grey values ``255·(1 − p)`` (occupied black, unknown mid grey, free white) on ``levels``
    (computed a block of rows at a time: :func:`slam.rowwise.by_rows`)."""
    step = 255.0 / (levels - 1)

    def block(lo: NDArray[np.floating]) -> NDArray[np.uint8]:
        p = 1.0 - 1.0 / (1.0 + np.exp(np.asarray(lo, dtype=np.float32)))
        grey = 1.0 - p
        return (np.round(grey * (levels - 1)) * step).astype(np.uint8)

    return by_rows(block, np.asarray(log_odds), np.uint8)  # temporaries of a block of rows


def occupancy_image(grid: OccupancyGrid, levels: int = 256) -> PlacedImage | None:
    """The observed part of ``grid`` as a placed grey image (``None`` if nothing was observed)."""
    box = observed_box(grid.log_odds != 0)
    if box is None:
        return None
    iy0, iy1, ix0, ix1 = box
    pixels = occupancy_pixels(grid.log_odds[iy0:iy1, ix0:ix1], levels)
    res = grid.resolution
    corner = (float(grid.origin[0] + ix0 * res), float(grid.origin[1] + iy0 * res))
    return PlacedImage(np.ascontiguousarray(pixels), corner, res)


def texture_image(folder: Path) -> PlacedImage | None:
    """``texture.npz`` of a run folder as a placed RGBA image (cells never seen transparent).

    The file holds ``rgb`` ``(H, W, 3)`` uint8, ``resolution`` and ``origin`` in the map
    convention, and optionally ``count`` (frames that coloured each cell). ``None`` when the
    file is absent or lacks those keys (the texture stage did not run on this log).
    """
    path = Path(folder) / "texture.npz"
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as data:
        if not {"rgb", "resolution", "origin"} <= set(data.files):
            return None
        rgb = np.asarray(data["rgb"])
        seen = np.asarray(data["count"]) > 0 if "count" in data.files else rgb.any(axis=-1)
        res = float(data["resolution"])
        origin = np.asarray(data["origin"], dtype=np.float64).reshape(2)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or seen.shape != rgb.shape[:2]:
        return None
    box = observed_box(seen, margin=0)
    if box is None:
        return None
    iy0, iy1, ix0, ix1 = box
    rgba = np.empty((iy1 - iy0, ix1 - ix0, 4), dtype=np.uint8)
    rgba[..., :3] = rgb[iy0:iy1, ix0:ix1]
    rgba[..., 3] = np.where(seen[iy0:iy1, ix0:ix1], 255, 0)
    corner = (float(origin[0] + ix0 * res), float(origin[1] + iy0 * res))
    return PlacedImage(rgba, corner, res)
