"""Kinect model: intrinsics reading (cx/cy), disparity coding, RGB alignment, frames, projection."""

import math

import numpy as np
import pytest

from slam.kinect import KinectModel, robot_to_world, rotation_rpy, world_to_robot

M = KinectModel()


def test_principal_point_reading_is_the_geometric_one():
    # 480 rows x 640 columns: the image centre is column 319.5, row 239.5.
    assert abs(M.cx - 319.5) < 4.0 and abs(M.cy - 239.5) < 4.0
    # The swapped reading (cx = 242.94 for 640 columns) would be 76 px off-centre both ways.
    assert abs(242.94140713 - 319.5) > 75 and abs(315.83800193 - 239.5) > 75
    left, right, up, down = M.field_of_view_deg()
    # Kinect v1: ~57 deg horizontal, ~43-45 deg vertical, nearly symmetric.
    assert left + right == pytest.approx(57.3, abs=0.3)
    assert up + down == pytest.approx(44.6, abs=0.3)
    assert abs(left - right) < 0.8 and abs(up - down) < 0.8
    swapped = KinectModel(cx=242.94140713, cy=315.83800193)
    s_left, s_right, _, _ = swapped.field_of_view_deg()
    assert abs(s_left - s_right) > 8.0  # 22.6 vs 31.3 deg: not a centred lens


def test_optical_axis_hits_the_floor_at_the_hand_computed_point():
    m = KinectModel(yaw=0.0)
    # Axis pitched 0.36 rad down from 0.36 m: tan(0.36) = 0.376403, sin(0.36) = 0.352274, so the
    # floor hit is 0.36/0.376403 = 0.956422 m ahead of the camera at optical depth 1.021931 m.
    ahead = 0.36 / math.tan(0.36)
    assert ahead == pytest.approx(0.956422, abs=1e-6)
    point_robot = np.array([0.18 + ahead, 0.005, 0.0])
    i, j, depth = m.world_to_pixel(point_robot, np.zeros(3))
    assert i == pytest.approx(242.94140713, abs=1e-9)
    assert j == pytest.approx(315.83800193, abs=1e-9)
    assert depth == pytest.approx(0.36 / math.sin(0.36), abs=1e-12)
    assert depth == pytest.approx(1.021931, abs=1e-6)
    back = m.pixel_to_world(i, j, depth, np.zeros(3))
    np.testing.assert_allclose(back, point_robot, atol=1e-12)


def test_floor_point_left_and_below_centre_with_pose_and_yaw():
    # A floor point projects below the principal point when it is nearer than the axis hit, and
    # to the left (smaller column) when it lies to the robot's left; and back exactly.
    pose = np.array([2.0, -1.0, 0.7])
    point_robot = np.array([0.8, 0.3, 0.0])
    point_world = robot_to_world(point_robot, pose)
    i, j, depth = M.world_to_pixel(point_world, pose)
    assert i > M.cy and j < M.cx and depth > 0
    # Hand check in the camera frame: p_opt = R^T (p - t).
    p_opt = M.rotation.T @ (point_robot - M.translation)
    assert j == pytest.approx(M.fx * p_opt[0] / p_opt[2] + M.cx, abs=1e-9)
    assert i == pytest.approx(M.fy * p_opt[1] / p_opt[2] + M.cy, abs=1e-9)
    back = M.pixel_to_world(i, j, depth, pose)
    np.testing.assert_allclose(back, point_world, atol=1e-12)
    assert back[2] == pytest.approx(0.0, abs=1e-12)


def test_camera_axes_in_the_robot_frame():
    r = M.rotation
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    cp, sp, cy, sy = math.cos(0.36), math.sin(0.36), math.cos(0.021), math.sin(0.021)
    np.testing.assert_allclose(r[:, 2], [cp * cy, cp * sy, -sp], atol=1e-12)  # forward, down
    np.testing.assert_allclose(r[:, 0], [sy, -cy, 0.0], atol=1e-12)  # image right = robot right
    assert r[2, 1] < 0  # image down points down
    np.testing.assert_allclose(rotation_rpy(0, 0, 0), np.eye(3))


def test_disparity_depth_numbers_and_inverse():
    # d = 750: dd = 3.31 - 0.00304 * 750 = 1.03, depth = 1 m.
    assert M.disparity_to_dd(750) == pytest.approx(1.03, abs=1e-12)
    assert M.disparity_to_depth(750) == pytest.approx(1.0, abs=1e-12)
    assert M.depth_to_disparity(1.0) == pytest.approx(750.0, abs=1e-9)
    d = np.arange(0, 1088, dtype=np.float64)
    np.testing.assert_allclose(M.depth_to_disparity(M.disparity_to_depth(d)), d, atol=1e-8)
    assert np.isnan(M.disparity_to_depth(2047))  # the Kinect's "no measurement"
    assert np.isnan(M.disparity_to_depth(1100))  # dd < 0


def test_encode_disparity_rounds_and_marks_out_of_range():
    depth = np.array([1.0, 2.0, 0.39, 6.5, np.nan, np.inf])
    coded = M.encode_disparity(depth)
    assert coded.dtype == np.uint16
    assert coded[0] == 750
    assert coded[1] == round((1.03 / 2.0 - 3.31) / -0.00304)  # 919.4 -> 919
    assert coded[1] == 919
    assert list(coded[2:]) == [2047] * 4
    # Quantisation error of the decoded depth is at most half a disparity step.
    z = np.linspace(0.5, 5.0, 200)
    decoded = M.disparity_to_depth(M.encode_disparity(z))
    step = 0.00304 * 1.03 / (1.03 / z) ** 2
    assert np.all(np.abs(decoded - z) <= 0.5 * step * 1.01)


def test_rgb_alignment_numbers_and_inverse():
    ri, rj = M.rgb_coordinates(0.0, 0.0, 1.03)
    assert ri == pytest.approx((19276 - 7877.07 * 1.03) / 585.051, abs=1e-12)
    assert ri == pytest.approx(19.079, abs=1e-3)
    assert rj == pytest.approx(16662 / 585.051, abs=1e-12)
    rng = np.random.default_rng(0)
    i = rng.uniform(0, 479, 100)
    j = rng.uniform(0, 639, 100)
    dd = rng.uniform(0.1, 2.5, 100)
    ri, rj = M.rgb_coordinates(i, j, dd)
    i2, j2 = M.depth_pixel_from_rgb(ri, rj, dd)
    np.testing.assert_allclose(i2, i, atol=1e-9)
    np.testing.assert_allclose(j2, j, atol=1e-9)


def test_projection_round_trip_for_random_points_and_poses():
    rng = np.random.default_rng(1)
    i = rng.uniform(0, 479, 500)
    j = rng.uniform(0, 639, 500)
    depth = rng.uniform(0.4, 6.0, 500)
    pose = np.array([-3.0, 4.0, -2.5])
    world = M.pixel_to_world(i, j, depth, pose)
    i2, j2, d2 = M.world_to_pixel(world, pose)
    np.testing.assert_allclose(i2, i, atol=1e-9)
    np.testing.assert_allclose(j2, j, atol=1e-9)
    np.testing.assert_allclose(d2, depth, atol=1e-12)
    np.testing.assert_allclose(world_to_robot(robot_to_world(world, pose), pose), world, atol=1e-12)


def test_whole_disparity_image_of_a_flat_floor_decodes_to_the_floor():
    # Analytic floor depth per pixel, coded like the sensor, decoded back to world points.
    i, j = M.pixel_grid()
    rays = M.pixel_rays(i, j) @ M.rotation.T
    with np.errstate(divide="ignore"):
        depth = np.where(rays[..., 2] < 0, M.z / -rays[..., 2], np.inf)
    disparity = M.encode_disparity(depth)
    pose = np.array([1.0, 2.0, 0.3])
    points, valid = M.disparity_to_world(disparity, pose)
    assert points.shape == (480, 640, 3)
    assert valid.sum() > 0.6 * valid.size  # the floor fills most of the image
    assert not valid[0].any()  # top rows look beyond max_depth
    # Quantisation moves points along the ray by < half a step: heights stay within 1 cm.
    assert np.abs(points[valid][:, 2]).max() < 0.01
    assert np.all(np.isnan(points[~valid]))
