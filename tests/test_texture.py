"""Texture stage units: camera numbers through the kernel, pairing, accumulation modes, truth."""

import math

import numpy as np
import pytest

from slam.config import MapConfig, TextureConfig
from slam.errors import ConfigError
from slam.grid_geometry import GridGeometry
from slam.kinect import KinectModel
from slam.mapping import OccupancyGrid
from slam.texture import (
    GroundTruth,
    TextureAccumulator,
    TrueTexture,
    display_scale,
    evaluate_texture,
    kinect_model,
    nearest_frames,
    pair_frames,
    render_overlay,
    render_texture,
    swept_cells,
)

H, W = 480, 640


def _config(**kw) -> TextureConfig:
    return TextureConfig(**kw)


# ------------------------------------------------------------------------- camera model numbers


def test_config_camera_defaults_are_the_kinect_model_defaults():
    m, k = kinect_model(TextureConfig()), KinectModel()
    assert m == k
    assert (m.cx, m.cy) == (315.83800193, 242.94140713)  # column, row: the geometric reading


def test_known_floor_point_projects_to_the_hand_computed_pixel_and_back():
    # Yaw 0 so the numbers are easy: a floor point 1 m ahead of the camera and 0.3 m to its left.
    m = KinectModel(yaw=0.0)
    point = np.array([0.18 + 1.0, 0.005 + 0.3, 0.0])
    # By hand: the camera frame is pitched 0.36 rad down from 0.36 m; the point relative to it is
    # (1.0, 0.3, -0.36): optical x = -0.3, y = 0.36·cos − sin, z = cos + 0.36·sin.
    cp, sp = math.cos(0.36), math.sin(0.36)
    z, y, x = cp + 0.36 * sp, 0.36 * cp - sp, -0.3
    assert z == pytest.approx(1.0627155, abs=1e-7) and y == pytest.approx(-0.0153514, abs=1e-7)
    i, j, depth = m.world_to_pixel(point, np.zeros(3))
    assert j == pytest.approx(585.05108211 * x / z + 315.83800193, abs=1e-9)
    assert i == pytest.approx(585.05108211 * y / z + 242.94140713, abs=1e-9)
    assert (i, j) == (pytest.approx(234.4901, abs=1e-4), pytest.approx(150.6806, abs=1e-4))
    assert depth == pytest.approx(1.0627155, abs=1e-7)
    # Its disparity is 769.995 -> 770 and its colour sits at RGB pixel (230.87, 164.05).
    assert m.depth_to_disparity(depth) == pytest.approx(769.995, abs=1e-3)
    ri, rj = m.rgb_coordinates(i, j, m.depth_to_dd(depth))
    assert (ri, rj) == (pytest.approx(230.8687, abs=1e-4), pytest.approx(164.0468, abs=1e-4))
    np.testing.assert_allclose(m.pixel_to_world(i, j, depth, np.zeros(3)), point, atol=1e-12)

    # Back through the texture kernel: one valid disparity pixel at (234, 151) = 770, a coloured
    # RGB image; the sample lands in the cell of the point with the colour of the aligned pixel.
    disparity = np.full((H, W), 2047, np.uint16)
    disparity[234, 151] = 770
    rgb = np.zeros((H, W, 3), np.uint8)
    ri, rj = m.rgb_coordinates(234, 151, m.disparity_to_dd(770))
    assert (round(float(ri)), round(float(rj))) == (230, 164)
    rgb[230, 164] = (10, 200, 30)
    acc = TextureAccumulator(GridGeometry.of(np.zeros(2), 0.05, (40, 40)), _config(camera_yaw=0.0))
    assert acc.add_frame(disparity, rgb, np.zeros(3), np.zeros(3)) == 1
    iy, ix = np.argwhere(acc.counts > 0)[0]
    back = m.pixel_to_world(234, 151, m.disparity_to_depth(770), np.zeros(3))
    assert np.hypot(*(back[:2] - point[:2])) < 0.003 and abs(back[2]) < 0.003
    assert (ix, iy) == (23, 6)  # x 1.18 in [1.15, 1.20), y 0.305 in [0.30, 0.35)
    np.testing.assert_array_equal(acc.sums[iy, ix], [10, 200, 30])


def _floor_frame(model: KinectModel) -> tuple[np.ndarray, np.ndarray]:
    """Disparity of a flat floor (with a box 1.2 m ahead standing on it) and a random RGB image."""
    i, j = model.pixel_grid()
    rays = model.pixel_rays(i, j) @ model.rotation.T
    with np.errstate(divide="ignore"):
        depth = np.where(rays[..., 2] < 0, model.z / -rays[..., 2], np.inf)
    depth[200:260, 300:360] = 0.6  # an obstacle face, ≥ 0.13 m above the floor
    rgb = np.random.default_rng(5).integers(0, 256, (H, W, 3), dtype=np.uint8)
    return model.encode_disparity(depth), rgb


def _reference(model, config, disparity, rgb, pose_d, pose_r, shape, res, origin):
    """The accumulation written with the vectorised Kinect model (slow, obviously right)."""
    depth = model.disparity_to_depth(disparity)
    ok = np.isfinite(depth) & (depth >= config.min_depth) & (depth <= config.max_depth)
    i, j = np.nonzero(ok)
    world = model.pixel_to_world(i.astype(float), j.astype(float), depth[ok], pose_d)
    floor = np.abs(world[:, 2]) <= config.floor_height
    world = world[floor]
    cell = np.floor((world[:, :2] - origin) / res).astype(int)
    i2, j2, d2 = model.world_to_pixel(world, pose_r)
    ri, rj = model.rgb_coordinates(i2, j2, model.depth_to_dd(d2))
    ri, rj = np.floor(ri + 0.5).astype(int), np.floor(rj + 0.5).astype(int)
    keep = (cell[:, 0] >= 0) & (cell[:, 1] >= 0) & (cell[:, 0] < shape[1]) & (cell[:, 1] < shape[0])
    keep &= (d2 > 0) & (ri >= 0) & (rj >= 0) & (ri < H) & (rj < W)
    sums = np.zeros((*shape, 3))
    counts = np.zeros(shape, np.int64)
    np.add.at(sums, (cell[keep, 1], cell[keep, 0]), rgb[ri[keep], rj[keep]].astype(float))
    np.add.at(counts, (cell[keep, 1], cell[keep, 0]), 1)
    return sums, counts


def test_kernel_matches_the_vectorised_camera_model_with_motion_compensation():
    config = TextureConfig()
    model = kinect_model(config)
    disparity, rgb = _floor_frame(model)
    pose_d = np.array([1.0, -0.5, 0.4])
    pose_r = np.array([1.012, -0.497, 0.409])  # 12 ms later, moving and turning
    origin, res, shape = np.array([-2.0, -3.0]), 0.05, (120, 140)
    acc = TextureAccumulator(GridGeometry.of(origin, res, shape), config)
    added = acc.add_frame(disparity, rgb, pose_d, pose_r)
    sums, counts = _reference(model, config, disparity, rgb, pose_d, pose_r, shape, res, origin)
    assert added == counts.sum() > 150_000  # the floor fills most of the image
    np.testing.assert_array_equal(acc.counts, counts)
    np.testing.assert_allclose(acc.sums, sums)
    # Without compensation the colours come from the disparity pose: same cells, other colours.
    flat = TextureAccumulator(
        GridGeometry.of(origin, res, shape), TextureConfig(motion_compensation=False)
    )
    flat.add_frame(disparity, rgb, pose_d, pose_r)
    np.testing.assert_array_equal(flat.counts, counts)
    assert not np.allclose(flat.sums, sums)
    sums0, _ = _reference(model, config, disparity, rgb, pose_d, pose_d, shape, res, origin)
    np.testing.assert_allclose(flat.sums, sums0)


def test_height_threshold_depth_range_and_pixel_stride():
    model = KinectModel()
    disparity, rgb = _floor_frame(model)
    shape, res, origin = (120, 140), 0.05, np.array([-1.0, -3.5])
    full = TextureAccumulator(GridGeometry.of(origin, res, shape), TextureConfig())
    n_full = full.add_frame(disparity, rgb, np.zeros(3), np.zeros(3))
    near = TextureAccumulator(GridGeometry.of(origin, res, shape), TextureConfig(max_depth=2.0))
    n_near = near.add_frame(disparity, rgb, np.zeros(3), np.zeros(3))
    assert 0 < n_near < n_full

    # Every sample of the near map has an optical depth ≤ 2 m (its cell centre: ≤ 2 m + half a
    # cell diagonal); the full map reaches 4 m.
    def depths(acc):
        iy, ix = np.nonzero(acc.counts)
        centres = origin + (np.stack([ix, iy], axis=1) + 0.5) * res
        points = np.column_stack([centres, np.zeros(len(centres))])
        return model.world_to_pixel(points, np.zeros(3))[2]

    assert depths(near).max() < 2.0 + 0.036 and depths(full).max() > 3.9
    # The box face at 0.6 m is not floor: nothing is added in front of it from its pixels.
    box = np.full_like(disparity, 2047)
    box[200:260, 300:360] = disparity[200:260, 300:360]
    only_box = TextureAccumulator(GridGeometry.of(origin, res, shape), TextureConfig())
    assert only_box.add_frame(box, rgb, np.zeros(3), np.zeros(3)) == 0
    stride = TextureAccumulator(GridGeometry.of(origin, res, shape), TextureConfig(pixel_stride=2))
    n_stride = stride.add_frame(disparity, rgb, np.zeros(3), np.zeros(3))
    assert n_stride == pytest.approx(n_full / 4, rel=0.01)


def test_mean_and_latest_modes():
    model = KinectModel()
    disparity, _ = _floor_frame(model)
    red = np.zeros((H, W, 3), np.uint8)
    red[..., 0] = 200
    blue = np.zeros((H, W, 3), np.uint8)
    blue[..., 2] = 100
    shape, res, origin = (120, 140), 0.05, np.array([-1.0, -3.5])
    textures = {}
    for mode in ("mean", "latest"):
        acc = TextureAccumulator(GridGeometry.of(origin, res, shape), TextureConfig(mode=mode))
        acc.add_frame(disparity, red, np.zeros(3), np.zeros(3))
        acc.add_frame(disparity, blue, np.zeros(3), np.zeros(3))
        textures[mode] = acc.texture()
    mean, latest = textures["mean"], textures["latest"]
    seen = mean.coloured
    np.testing.assert_array_equal(seen, latest.coloured)
    np.testing.assert_array_equal(mean.rgb[seen], np.tile([100, 0, 50], (seen.sum(), 1)))
    np.testing.assert_array_equal(latest.rgb[seen], np.tile([0, 0, 100], (seen.sum(), 1)))
    np.testing.assert_array_equal(mean.count[seen], 2 * latest.count[seen])
    assert (mean.rgb[~seen] == 0).all()


def test_texture_config_is_validated():
    for bad in (
        {"mode": "median"},
        {"floor_height": 0.0},
        {"min_depth": 3.0, "max_depth": 2.0},
        {"pair_tolerance_s": -0.1},
        {"frame_stride": 0},
        {"pixel_stride": 0},
    ):
        with pytest.raises(ConfigError, match="texture\\."):
            TextureConfig(**bad)


# ------------------------------------------------------------------------------ frame pairing


def test_nearest_frames_ties_unsorted_and_single():
    idx, gap = nearest_frames(np.array([0.0, 1.0, 1.5, 9.0]), np.array([2.0, 1.0, 0.0]))
    np.testing.assert_array_equal(idx, [2, 1, 1, 0])  # the tie at 1.5 goes to the earlier time
    np.testing.assert_allclose(gap, [0.0, 0.0, 0.5, 7.0])
    idx, gap = nearest_frames(np.array([3.0]), np.array([1.0]))
    assert idx.tolist() == [0] and gap.tolist() == [2.0]


def test_pair_frames_tolerance_stride_missing_and_trajectory_span():
    rgb_t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    disp_t = np.array([0.01, 0.09, 0.22, 0.45, 0.62, 0.71])
    plan = pair_frames(rgb_t, disp_t, 0.03)
    # 0.3 is 0.08 from 0.22 and 0.15 from 0.45; 0.4 is 0.05 from 0.45; 0.5 is 0.05 away.
    assert plan.rgb.tolist() == [0, 1, 2, 6, 7]
    assert plan.disparity.tolist() == [0, 1, 2, 4, 5]
    assert plan.skipped == {"no_disparity": 3} and plan.considered == 8
    plan = pair_frames(rgb_t, disp_t, 0.03, stride=2)
    assert plan.rgb.tolist() == [0, 2, 6] and plan.considered == 4
    rgb_ok = np.array([True, False, True, True, True, True, True, True])
    disp_ok = np.array([True, True, False, True, True, True])
    plan = pair_frames(rgb_t, disp_t, 0.03, rgb_available=rgb_ok, disparity_available=disp_ok)
    # Without disparity 0.22, RGB 0.2 has no partner within 30 ms (0.09 is 0.11 away).
    assert plan.rgb.tolist() == [0, 6, 7]
    assert plan.skipped == {"missing_rgb": 1, "no_disparity": 4}
    plan = pair_frames(rgb_t, disp_t, 0.03, time_range=(0.05, 0.65))
    assert plan.rgb.tolist() == [1, 2, 6]  # 0.6 pairs with 0.62, inside; 0.0 and 0.7 are not
    assert plan.skipped == {"no_disparity": 3, "outside_trajectory": 2}
    np.testing.assert_allclose(plan.rgb_time - plan.disparity_time, [0.01, -0.02, -0.02])


# --------------------------------------------------------------------------------- evaluation


def _ground_truth(
    texture, floor, occupancy=None, path=((0.0, 0.0, 0.0), (10.0, 0.0, 0.0)), origin=(0.0, 0.0)
):
    path = np.asarray(path, dtype=float)
    occ = np.zeros((100, 100), np.uint8) if occupancy is None else occupancy
    return GroundTruth(
        times=np.arange(path.shape[0], dtype=float),
        poses=path,
        texture=texture,
        floor=floor,
        texture_resolution=0.02,
        texture_origin=np.asarray(origin, dtype=float),
        occupancy=occ,
        map_resolution=0.05,
        map_origin=np.array([-1.0, -2.5]),
    )


def test_true_texture_cell_means_and_floor_cells():
    # Texels of 0.02 m from (0.004, 0.004): centres 0.014, 0.034, 0.054, 0.074, 0.094, ...
    # Cells of 0.05 m from (0, 0): cell 0 holds texels 0, 1 and cell 1 texels 2, 3, 4.
    tex = np.zeros((10, 10, 3), np.uint8)
    tex[:, :, 0] = (np.arange(10) * 10)[None, :]  # red grows with the column
    floor = np.ones((10, 10), bool)
    floor[4, 4] = False
    truth = TrueTexture(_ground_truth(tex, floor, origin=(0.004, 0.004)))
    colour, is_floor = truth.on_grid((5, 5), 0.05, np.zeros(2))
    assert colour[0, 0, 0] == pytest.approx(5.0)  # texels 0, 1 -> (0 + 10) / 2
    assert colour[0, 1, 0] == pytest.approx(30.0)  # texels 2, 3, 4 -> (20 + 30 + 40) / 3
    assert colour[0, 3, 0] == pytest.approx(80.0)  # texels 7, 8, 9 (centres 0.154 .. 0.194)
    assert is_floor[0, 0] and not is_floor[1, 1]  # texel (4, 4) lies in cell (1, 1)
    assert is_floor[0, 1] and is_floor[3, 3]
    assert not is_floor[4, 4]  # beyond the texture: no texels
    # A square moved half a cell holds other texels: x in [0.025, 0.075) -> texels 1, 2, 3.
    c, f = truth.cells(np.array([[0.05, 0.025]]), 0.05)
    assert c[0, 0] == pytest.approx(20.0) and f[0]


def test_swept_cells_respect_depth_range_field_of_view_and_walls():
    floor_tex = np.zeros((400, 400, 3), np.uint8)
    floor = np.ones((400, 400), bool)  # 8 x 8 m of floor from (0, 0)
    occ = np.zeros((200, 200), np.uint8)  # 10 x 10 m from (-1, -2.5) at 0.05
    occ[:, int((5.0 + 1.0) / 0.05)] = 1  # a wall at x in [5.0, 5.05)
    gt = _ground_truth(floor_tex, floor, occ, path=((1.0, 4.0, 0.0), (1.0, 4.0, 0.0)))
    truth = TrueTexture(gt)
    shape, res, origin = (160, 160), 0.05, np.zeros(2)
    _, floor_cells = truth.on_grid(shape, res, origin)
    config = TextureConfig(max_depth=6.0, camera_yaw=0.0)
    swept = swept_cells(gt, floor_cells, res, origin, np.array([0.5]), config)

    def at(x, y):
        return swept[int(y / res), int(x / res)]

    assert at(2.5, 4.0)  # 1.3 m ahead of the camera
    assert not at(0.5, 4.0)  # behind
    assert not at(1.4, 4.0)  # below the lower edge of the image (too close)
    assert at(4.5, 4.6) and not at(4.5, 7.5)  # inside / outside the ±28.6° field of view
    assert not at(5.5, 4.0)  # behind the wall
    # The nearest floor seen: the image's last row looks 0.36 rad + atan((479.5 − cy)/fy) down.
    m = KinectModel()
    near = 1.0 + 0.18 + 0.36 / math.tan(0.36 + math.atan((479.5 - m.cy) / m.fy))
    assert near == pytest.approx(1.571, abs=1e-3)
    _, xs = np.nonzero(swept)
    assert abs((xs.min() + 0.5) * res - near) < res
    assert (xs.max() + 1) * res == pytest.approx(5.0)  # up to the wall


def test_swept_cells_do_not_depend_on_the_thread_count():
    """Grid rows are marked in parallel (:func:`slam.texture.kernels.mark_swept`): one thread
    and two give the same cells, for a camera turning along a path with a wall in view."""
    import numba

    floor_tex = np.zeros((400, 400, 3), np.uint8)
    floor = np.ones((400, 400), bool)
    occ = np.zeros((200, 200), np.uint8)
    occ[:, int((5.0 + 1.0) / 0.05)] = 1
    path = ((1.0, 2.0, 0.0), (1.5, 5.0, 1.2))
    gt = _ground_truth(floor_tex, floor, occ, path=path)
    shape, res, origin = (160, 160), 0.05, np.zeros(2)
    _, floor_cells = TrueTexture(gt).on_grid(shape, res, origin)
    config = TextureConfig(max_depth=6.0, camera_yaw=0.0)
    frames = np.linspace(0.0, 1.0, 9)
    before = numba.get_num_threads()
    try:
        swept = []
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(threads)
            swept.append(swept_cells(gt, floor_cells, res, origin, frames, config))
    finally:
        numba.set_num_threads(before)
    assert swept[0].sum() > 500
    np.testing.assert_array_equal(swept[0], swept[1])


def test_evaluate_texture_counts_error_and_coverage():
    tex = np.zeros((250, 250, 3), np.uint8)
    tex[..., 1] = 120
    floor = np.ones((250, 250), bool)
    gt = _ground_truth(tex, floor, path=((1.0, 2.5, 0.0), (1.0, 2.5, 0.0)))
    grid_shape, res, origin = (100, 100), 0.05, np.zeros(2)
    config = TextureConfig(camera_yaw=0.0)
    _, floor_cells = TrueTexture(gt).on_grid(grid_shape, res, origin)
    swept = swept_cells(gt, floor_cells, res, origin, np.array([0.0]), config)
    acc = TextureAccumulator(GridGeometry.of(origin, res, grid_shape), config)
    texture = acc.texture()
    iy, ix = np.nonzero(swept)
    half = iy.size // 2
    texture.count[iy[:half], ix[:half]] = 1
    texture.rgb[iy[:half], ix[:half]] = (6, 126, 3)  # |diff| 6, 6, 3 -> 5 levels
    figures = evaluate_texture(texture, gt, np.array([0.0]), config)
    assert figures["colour_mae"] == pytest.approx(5.0)
    assert figures["swept_cells"] == iy.size
    assert figures["coverage"] == pytest.approx(half / iy.size, abs=1e-4)
    assert figures["floor_cells_seen"] == half


# ------------------------------------------------------------------------------------ pictures


def test_pictures_have_the_size_of_map_png():
    from slam.pipeline import render_map

    grid = OccupancyGrid(MapConfig(initial_size_m=12.0))
    grid.log_odds[100:110, 50:60] = 5.0  # an obstacle
    trajectory = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.0]])
    acc = TextureAccumulator(grid.geometry, TextureConfig())
    texture = acc.texture()
    texture.count[10, 20] = 1
    texture.rgb[10, 20] = (255, 0, 0)  # a red cell near the bottom left
    texture.count[105, 55] = 1
    texture.rgb[105, 55] = (0, 255, 0)  # coloured, but occupied: the overlay keeps it dark
    map_png = render_map(grid, trajectory)
    scale = display_scale(grid.shape)
    assert scale == 3 and map_png.shape[:2] == (720, 720)
    img = render_texture(texture)
    over = render_overlay(texture, grid)
    assert img.shape == over.shape == map_png.shape
    # +y up: row 10 of the grid is image row (240 - 1 - 10) before scaling; BGR order.
    assert img[(239 - 10) * 3 + 1, 20 * 3 + 1].tolist() == [0, 0, 255]
    assert over[(239 - 10) * 3, 20 * 3].tolist() == [0, 0, 255]
    grey = int(grid.to_image()[239 - 105, 55])
    assert grey < 5 and over[(239 - 105) * 3, 55 * 3].tolist() == [grey] * 3
    assert over[0, 0].tolist() == [127, 127, 127]  # unknown stays grey


def test_run_stage_applies_only_with_frames_a_map_and_the_stage_enabled(tmp_path):
    import dataclasses
    from types import SimpleNamespace

    from slam.config import Config
    from slam.io.log import Log, RgbdIndex
    from slam.texture import run_stage

    index = RgbdIndex(np.zeros(0), np.zeros(0), tmp_path, tmp_path, "rgb_{}.png", "d_{}.png")
    estimate = SimpleNamespace(times=np.zeros(1), poses=np.zeros((1, 3)), grid=None)
    config = Config()
    off = dataclasses.replace(config, texture=TextureConfig(enabled=False))
    assert run_stage(Log("x", "ece276a", rgbd=index), estimate, off, tmp_path) == {}
    assert run_stage(Log("x", "ece276a"), estimate, config, tmp_path) == {}
    assert run_stage(Log("x", "ece276a", rgbd=index), estimate, config, tmp_path) == {
        "texture": {"skipped": "no occupancy map to put the texture on"}
    }
    assert not list(tmp_path.iterdir())
