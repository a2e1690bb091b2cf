"""The Trajectory value type and its TUM files."""

from __future__ import annotations

import numpy as np
import pytest

from slam.io.tum import format_tum, read_tum, write_tum
from slam.trajectory import Trajectory


def test_trajectory_validates_shapes_and_values():
    with pytest.raises(ValueError, match="3 times for 2 poses"):
        Trajectory(np.arange(3.0), np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"poses: expected shape \(N, 3\), found \(2, 2\)"):
        Trajectory(np.arange(2.0), np.zeros((2, 2)))
    poses = np.zeros((3, 3))
    poses[1, 2] = np.nan
    with pytest.raises(ValueError, match="pose 1 has a NaN"):
        Trajectory(np.arange(3.0), poses)
    with pytest.raises(ValueError, match="pose 2 has a NaN"):
        Trajectory(np.array([0.0, 1.0, np.inf]), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"scan_indices: expected shape \(3,\)"):
        Trajectory(np.arange(3.0), np.zeros((3, 3)), np.arange(2))


def test_trajectory_length_unpacking_and_path():
    poses = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [3.0, 0.0, 1.0]])
    traj = Trajectory([0.0, 1.0, 2.0], poses, [5, 6, 7])
    assert len(traj) == 3 and traj.scan_indices.dtype == np.int64
    times, got = traj  # the older (times, poses) form
    np.testing.assert_array_equal(times, [0.0, 1.0, 2.0])
    assert got is traj.poses
    assert traj.path_length() == pytest.approx(9.0)
    assert traj.duration() == pytest.approx(2.0)
    assert Trajectory(np.zeros(1), np.zeros((1, 3))).path_length() == 0.0


def test_sorted_by_time_is_stable_and_keeps_indices():
    traj = Trajectory([2.0, 1.0, 1.0, 0.5], np.arange(12.0).reshape(4, 3), [10, 11, 12, 13])
    ordered = traj.sorted_by_time()
    np.testing.assert_array_equal(ordered.times, [0.5, 1.0, 1.0, 2.0])
    np.testing.assert_array_equal(ordered.scan_indices, [13, 11, 12, 10])
    assert ordered.sorted_by_time() is ordered


def test_at_interpolates_in_time_order_and_clamps():
    # in file order (times go backwards once), headings across ±π
    traj = Trajectory(
        [2.0, 0.0, 4.0],
        [[2.0, 0.0, np.pi - 0.1], [0.0, 0.0, np.pi - 0.3], [4.0, 2.0, -np.pi + 0.1]],
    )
    out = traj.at([1.0, 3.0, -5.0, 9.0])
    np.testing.assert_allclose(out[:2, :2], [[1.0, 0.0], [3.0, 1.0]])
    assert np.cos(out[1, 2] - np.pi) == pytest.approx(1.0)  # halfway between π-0.1 and π+0.1
    np.testing.assert_allclose(out[2, :2], [0.0, 0.0])  # clamped to the first pose
    np.testing.assert_allclose(out[3, :2], [4.0, 2.0])


def test_tum_round_trip(tmp_path):
    traj = Trajectory([10.0, 10.5], [[1.0, 2.0, 0.5], [1.5, 2.5, -3.0]])
    write_tum(tmp_path / "t.tum", traj)
    back = read_tum(tmp_path / "t.tum")
    assert isinstance(back, Trajectory)
    np.testing.assert_allclose(back.times, traj.times)
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-6)
    assert format_tum(traj).splitlines()[1].startswith("10.000000 1.000000 2.000000 0.000000")
