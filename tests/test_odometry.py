"""Odometry: exact poses on synthetic encoder/IMU sequences, the IMU-gap rule, real dataset20."""

import warnings

import numpy as np
import pytest

from slam.config import RobotConfig
from slam.io.log import EncoderStream, ImuStream
from slam.odometry import (
    OdometryWarning,
    dead_reckon_ece276a,
    integrate_arcs,
    poses_at,
    wheel_travel,
)

M = RobotConfig().meters_per_tick


def _encoders(n, right_ticks, left_ticks, dt=0.025, t0=100.0):
    counts = np.zeros((4, n), dtype=np.int16)
    counts[0, 1:] = right_ticks
    counts[2, 1:] = right_ticks
    counts[1, 1:] = left_ticks
    counts[3, 1:] = left_ticks
    return EncoderStream(t0 + dt * np.arange(n), counts)


def _imu(rate, t0=99.0, t1=200.0, hz=100.0):
    t = np.arange(t0, t1, 1.0 / hz)
    w = np.zeros((3, t.size))
    w[2] = rate
    return ImuStream(t, w, np.zeros((3, t.size)))


def test_wheel_travel_uses_mean_of_wheel_pairs():
    enc = EncoderStream(
        np.array([0.0, 0.025]), np.array([[0, 4], [0, 2], [0, 6], [0, 8]], np.int16)
    )
    right, left = wheel_travel(enc, RobotConfig())
    assert right[1] == pytest.approx(5 * M)
    assert left[1] == pytest.approx(5 * M)
    assert right[0] == 0.0


def test_straight_line_is_exact():
    enc = _encoders(401, 10, 10)
    times, poses = dead_reckon_ece276a(enc, _imu(0.0), RobotConfig(imu_lowpass_hz=0.0))
    assert poses.shape == (401, 3)
    np.testing.assert_allclose(poses[:, 0], 10 * M * np.arange(401), atol=1e-12)
    np.testing.assert_allclose(poses[:, 1:], 0.0, atol=1e-12)
    assert times[0] == 100.0


@pytest.mark.parametrize("lowpass", [0.0, 10.0])
def test_constant_turn_lies_on_the_exact_circle(lowpass):
    n, ticks, rate, dt = 401, 12, 0.5, 0.025
    enc = _encoders(n, ticks, ticks, dt=dt)
    _, poses = dead_reckon_ece276a(enc, _imu(rate), RobotConfig(imu_lowpass_hz=lowpass))
    v = ticks * M / dt
    radius = v / rate
    t = dt * np.arange(n)
    theta = rate * t
    expected = np.stack([radius * np.sin(theta), radius * (1 - np.cos(theta))], axis=1)
    np.testing.assert_allclose(poses[:, :2], expected, atol=1e-9)
    np.testing.assert_allclose(np.unwrap(poses[:, 2]), theta, atol=1e-9)


def test_integrate_arcs_quarter_circle():
    # four arcs of length pi/2 turning pi/2 each: a unit circle, back to the start
    d = np.array([0.0] + [np.pi / 2] * 4)
    dth = np.array([0.0] + [np.pi / 2] * 4)
    poses = integrate_arcs(d, dth)
    np.testing.assert_allclose(poses[1], [1.0, 1.0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(poses[4, :2], [0.0, 0.0], atol=1e-12)


def test_imu_gap_falls_back_to_wheels_with_a_warning():
    enc = _encoders(401, 10, 10)  # 100.0 .. 110.0 s
    imu = _imu(0.0, t0=99.0, t1=108.0)  # ends 2 s early
    with pytest.warns(OdometryWarning, match=r"outside the IMU's time range"):
        _, poses = dead_reckon_ece276a(enc, imu, RobotConfig(imu_lowpass_hz=0.0))
    np.testing.assert_allclose(poses[-1], [400 * 10 * M, 0.0, 0.0], atol=1e-12)


def test_wheel_yaw_after_the_imu_end_turns_the_robot():
    enc = _encoders(401, 12, 8)  # differential ticks: wheels say the robot turns left
    imu = _imu(0.0, t0=99.0, t1=105.0)  # IMU says straight, then ends
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OdometryWarning)
        _, poses = dead_reckon_ece276a(enc, imu, RobotConfig(imu_lowpass_hz=0.0))
    wheel_rate = (12 - 8) * M / RobotConfig().track_width  # rad per interval
    # intervals fully after 105.1 s use the wheels
    first_wheel_interval = int(np.ceil((105.1 - 100.0) / 0.025)) + 1
    turned = np.unwrap(poses[:, 2])[-1]
    assert turned == pytest.approx(wheel_rate * (401 - first_wheel_interval), rel=0.02)


def test_poses_at_warns_when_clamping():
    t = np.array([0.0, 1.0])
    p = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    with pytest.warns(OdometryWarning, match="1 scan times"):
        q = poses_at(t, p, np.array([0.5, 2.0]), what="scan")
    np.testing.assert_allclose(q, [[0.5, 0.0, 0.0], [1.0, 0.0, 0.0]])


def test_dataset20_dead_reckoning(ece276a_dir):
    e = np.load(ece276a_dir / "Encoders20.npz")
    i = np.load(ece276a_dir / "Imu20.npz")
    enc = EncoderStream(e["time_stamps"], e["counts"])
    imu = ImuStream(i["time_stamps"], i["angular_velocity"], i["linear_acceleration"])
    with pytest.warns(OdometryWarning, match="58 encoder intervals"):
        times, poses = dead_reckon_ece276a(enc, imu, RobotConfig())
    assert poses.shape == (4956, 3)
    length = np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T))
    assert length == pytest.approx(96.6, abs=0.1)
