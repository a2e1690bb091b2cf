"""What `slam.Slam` and `slam.Scan` make of a user's bad or unusual input: one clear error naming
the argument, or — for a scan that sees nothing — the odometry carrying the estimate on."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from synthetic_logs import path as room_path
from synthetic_logs import ray_cast

import slam
from slam.errors import DataError, UsageError
from slam.geometry import relative

ANGLES = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 271)


def scan_at(pose: np.ndarray, t: float, ranges: np.ndarray | None = None) -> slam.Scan:
    """The synthetic room seen from ``pose``, or ``ranges`` (a laser on the robot's centre)."""
    r = ray_cast(pose, ANGLES) if ranges is None else ranges
    return slam.Scan(t, r, ANGLES, laser_offset=(0.0, 0.0, 0.0))


def largest_error(blind: set[int], n: int = 30, config: slam.Config | None = None) -> float:
    """Feed ``n`` scans of the room with exact odometry, those in ``blind`` all NaN; the largest
    distance of an estimate from the odometry's pose."""
    s = slam.Slam(config, seed=0)
    poses = room_path(n)
    worst = 0.0
    for k, pose in enumerate(poses):
        ranges = np.full(ANGLES.size, np.nan) if k in blind else None
        est = s.update(scan_at(pose, 0.1 * k, ranges), odometry=pose)
        worst = max(worst, float(np.hypot(*relative(pose, est.pose)[:2])))
    s.finish()
    return worst


def test_scans_without_a_return_leave_the_estimate_on_the_odometry():
    """The bug: a due update at a scan without a single return drew every particle around an
    empty fit with the proposal's unit ridge (σ 1.7 m, 1.7 rad): with exact odometry and every
    scan blind the estimate was 6.7 m off, 6.1 m with the first four blind and 1.4 m with three
    in the middle. Now such a scan is no update, and a laser that starts blind builds the map at
    its first return: the runs are as good as the one that sees every scan (0.052 m)."""
    seeing = largest_error(set())
    assert seeing < 0.1
    assert largest_error(set(range(30))) < 1e-9
    assert largest_error({0, 1, 2, 3}) < seeing + 0.01  # the map starts at scan 4
    assert largest_error({10, 11, 12}) < seeing + 0.01  # a blind stretch in the middle
    s = slam.Slam(seed=0)
    poses = room_path(10)
    for k, pose in enumerate(poses):
        s.update(scan_at(pose, 0.1 * k, np.full(ANGLES.size, np.nan) if k < 6 else None), pose)
    assert s.finish().stats["blind_updates"] >= 1


def test_a_zero_reading_is_no_return():
    """Many drivers write 0 for "no reading": with range_min unset (0) such readings were hits
    at the laser itself, and a third of them took the estimate 3 m away."""
    scan = scan_at(room_path(3)[0], 0.0).resolved(slam.Config().lidar)
    ranges = scan.ranges.copy()
    ranges[::3] = 0.0
    zeros = slam.Scan(0.0, ranges, ANGLES, laser_offset=(0.0, 0.0, 0.0))
    ex, _ = zeros.resolved(slam.Config().lidar).hits()
    assert ex.size == ANGLES.size - len(range(0, ANGLES.size, 3))


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: slam.Scan(None, [1.0], [0.0]), "scan: time must be a finite number of seconds, found None"),
        (lambda: slam.Scan(0.0, "abc", [0.0]), "scan at t=0.000000: ranges must be numbers, found 'abc'"),
        (lambda: slam.Scan(0.0, np.ones((2, 3)), np.zeros((2, 3))), "ranges must be a 1-D array (one value per beam), found shape (2, 3)"),
        (lambda: slam.Scan(0.0, 1.0, 0.0), "ranges must be a 1-D array (one value per beam), found shape ()"),
        (lambda: slam.Scan(0.0, np.ones(271), np.degrees(ANGLES)), "angles must be radians spanning at most 2π (360°), found -135 .. 135 (degrees?"),
        (lambda: slam.Scan(0.0, np.ones(3), [0.0, np.inf, 0.1]), "angles must be radians spanning at most 2π (360°), found 0 .. 0.1 and infinities"),
        (lambda: slam.Scan(0.0, np.ones(3), [0, 0.1, 0.2], range_min="x"), "range_min must be a number of metres ≥ 0, found 'x'"),
        (lambda: slam.Scan(0.0, np.ones(3), [0, 0.1, 0.2], range_max=float("nan")), "range_max must be a number of metres ≥ 0, found nan"),
        (lambda: slam.Scan.from_angle_range(0.0, np.ones(3), -1.0, 0.0), "angle_increment is 0: every one of the 3 beams would point the same way"),
        (lambda: slam.Scan.from_angle_range(0.0, np.ones(3), -1.0, float("nan")), "angle_increment must be finite radians, found nan"),
        (lambda: slam.Scan(0.0, np.ones(3), [0, 0.1, 0.2], range_min=5.0, range_max=2.0).resolved(slam.Config().lidar), "no reading can be a return: range_min 5 m is not below range_max 2 m"),
    ],
)  # fmt: skip
def test_a_bad_scan_is_one_error_naming_the_field(make, message):
    with pytest.raises(DataError) as caught:
        make()
    assert message in str(caught.value)


def test_odometry_comes_from_one_source_per_run():
    """The bug: odometry= poses and encoder readings were mixed without a word, and the
    trajectory jumped between their frames (docs/api.md calls mixing a UsageError)."""
    poses = room_path(3)
    counts = np.ones((4, 1))
    s = slam.Slam(seed=0)
    s.update(scan_at(poses[0], 0.0), odometry=poses[0])
    s.add_encoders(0.05, counts)
    with pytest.raises(UsageError, match="encoder readings were fed after scans given odometry="):
        s.update(scan_at(poses[1], 0.1))
    s = slam.Slam(seed=0)
    s.add_encoders(0.0, counts)
    with pytest.raises(UsageError, match="odometry= was given, and encoder readings were fed"):
        s.update(scan_at(poses[0], 0.1), odometry=poses[0])
    # in any order: odometry=, then encoders fed, then odometry= again
    s = slam.Slam(seed=0)
    s.update(scan_at(poses[0], 0.0), odometry=poses[0])
    s.add_encoders(0.05, counts)
    with pytest.raises(UsageError, match="odometry= was given, and encoder readings were fed"):
        s.update(scan_at(poses[1], 0.1), odometry=poses[1])


@pytest.mark.filterwarnings("ignore:odometry. encoder intervals outside the IMU")
def test_a_refused_update_leaves_the_run_as_it_was():
    """The bug: the readings of a refused update's encoders= were fed before the checks, so
    retrying the call counted them twice."""
    poses = room_path(4)
    ticks = np.full((4, 1), 100.0)

    def run(retry: bool) -> np.ndarray:
        s = slam.Slam(seed=0)
        s.update(scan_at(poses[0], 0.0), encoders=(0.0, ticks))
        if retry:  # a scan whose limits are wrong, with the next readings
            bad = slam.Scan(0.1, ray_cast(poses[1], ANGLES), ANGLES, laser_offset=(0, 0, 0),
                            range_min=5.0, range_max=1.0)  # fmt: skip
            with pytest.raises(DataError, match="range_min 5 m is not below range_max 1 m"):
                s.update(bad, encoders=(0.1, ticks))
        s.update(scan_at(poses[1], 0.1), encoders=(0.1, ticks))
        return s.finish().poses

    np.testing.assert_array_equal(run(True), run(False))


def test_an_odometry_jump_is_refused_as_slam_run_refuses_it():
    poses = room_path(3)
    s = slam.Slam(seed=0)
    s.update(scan_at(poses[0], 0.0), odometry=poses[0])
    s.update(scan_at(poses[1], 0.1), odometry=poses[1])
    with pytest.raises(DataError, match=r"t=0.200000: odometry moves 100.1 m .* checks.max_speed"):
        s.update(scan_at(poses[2], 0.2), odometry=poses[2] + [100.0, 0.0, 0.0])
    for bad in ("1,2,3", {"x": 1}):
        with pytest.raises(DataError, match="odometry must be a finite pose"):
            s.update(scan_at(poses[2], 0.2), odometry=bad)


@pytest.mark.parametrize(
    ("feed", "message"),
    [
        (lambda s: s.add_encoders([0.0, 0.1, 0.2], np.ones((3, 4))), "encoders: counts must be (4,) or (4, K) ticks (FR, FL, RR, RL), found shape (3, 4) (readings as rows? pass counts.T)"),
        (lambda s: s.add_encoders(0.0, [1, 2, 3]), "encoders: counts must be (4,) or (4, K) ticks (FR, FL, RR, RL), found shape (3,)"),
        (lambda s: s.add_encoders([0.0, np.nan], np.ones((4, 2))), "encoders: time: expected finite seconds, found nan at index 1"),
        (lambda s: s.add_encoders(0.0, [1, np.nan, 1, 1]), "encoders: counts: expected finite ticks, found nan at index 1"),
        (lambda s: s.add_imu([0.0, 0.01], [0.1, np.nan]), "IMU: gyro_z: expected finite rad/s, found nan at index 1"),
        (lambda s: s.add_imu("soon", 0.1), "IMU: time: expected numbers (seconds), found 'soon'"),
    ],
)  # fmt: skip
def test_bad_encoder_and_imu_readings_are_named_where_they_enter(feed, message):
    with pytest.raises(DataError) as caught:
        feed(slam.Slam(seed=0))
    assert message in str(caught.value)


def test_bad_constructor_arguments_are_refused_at_once():
    with pytest.raises(UsageError, match="scan_period: expected seconds ≥ 0, found '0.1'"):
        slam.Slam(scan_period="0.1")  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="observers: expected slam.observers.Observer objects"):
        slam.Slam(observers=[object()])  # type: ignore[list-item]
    with pytest.raises(UsageError, match="stages: expected slam.stages.Stage objects"):
        slam.Slam(stages=[object()])  # type: ignore[list-item]


def test_slam_run_names_what_it_takes():
    with pytest.raises(
        UsageError, match="slam.run: expected a dataset name or a log's path, found ndarray"
    ):
        slam.run(np.zeros((10, 3)))  # type: ignore[arg-type]


def test_a_gyro_in_degrees_per_second_is_warned_about_online():
    """The audit's case: gyro samples in deg/s fed to the encoder odometry ended 3 m from the
    truth without a word; the integrator now warns once the gyro has turned 10 times as far as
    the wheels."""
    from slam.odometry import OdometryIntegrator, OdometryWarning

    robot = slam.Config().robot
    ticks = round(0.25 * robot.track_width / 40 / robot.meters_per_tick)  # 0.5 rad/s in place
    counts = np.array([ticks, -ticks, ticks, -ticks], dtype=float)
    for rate, warned in ((0.5, False), (np.degrees(0.5), True)):
        odometry = OdometryIntegrator(robot)
        odometry.add_imu(np.arange(0.0, 8.0, 0.01), np.full(800, rate))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for k in range(300):
                odometry.add_encoders(k / 40, counts)
        said = [str(w.message) for w in caught if issubclass(w.category, OdometryWarning)]
        assert len(said) == int(warned), said
        if warned:
            assert said[0].startswith("odometry: the gyro has turned the robot ")
            assert "expected rad/s (degrees per second?" in said[0]
