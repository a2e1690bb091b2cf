"""Simulated sensors against ground truth: the acceptance checks of the simulator.

Noise switched off: dead reckoning (the project's odometry) reproduces the demo's true path within
1 cm, lidar endpoints from true poses fall on occupied cells, Kinect floor pixels projected
through the Kinect model land on the right floor colour. Noise switched on: the noise has the
documented size.
"""

import numpy as np
import pytest

from slam.cli import main
from slam.config import load_config
from slam.geometry import interpolate_poses, wrap_angle
from slam.io.ece276a import load_ece276a
from slam.io.tum import read_tum
from slam.kinect import KinectModel
from slam.odometry import dead_reckon_ece276a
from slam.sim.dataset import SimOptions, generate_dataset
from slam.sim.render import KinectRenderer
from slam.sim.scenarios import SCENARIOS, generate_scene
from slam.sim.sensors import (
    GRAVITY,
    LidarSpec,
    NoiseConfig,
    WheelSpec,
    kinect_times,
    measure_ranges,
    sample_times,
    simulate_encoders,
    simulate_imu,
)
from slam.sim.world import FREE

OFF = NoiseConfig.off()


@pytest.fixture(scope="module")
def small_exact(tmp_path_factory):
    """Noise-free ``small`` dataset, 12 s, Kinect at 2 Hz, written by the CLI."""
    out = tmp_path_factory.mktemp("sim") / "small"
    code = main(
        ["sim", "small", "--out", str(out), "--noise-free", "--duration", "12", "--rgbd-rate", "2",
         "--quiet"]
    )  # fmt: skip
    assert code == 0
    return out


@pytest.fixture(scope="module")
def demo_exact(tmp_path_factory):
    """Noise-free demo (the full 124 s path) without Kinect frames."""
    out = tmp_path_factory.mktemp("sim") / "demo"
    generate_dataset(out, SimOptions(scenario="demo", seed=20, rgbd=False, noise=OFF))
    return out


@pytest.fixture(scope="module")
def small_scene():
    return generate_scene(SCENARIOS["small"], np.random.default_rng(3), t0=1000.0)


def test_noise_free_dead_reckoning_reproduces_the_whole_demo_path(demo_exact):
    log = load_ece276a(demo_exact, 20, need=("encoders", "imu"))
    robot = load_config("demo").robot  # the demo's shipped config: IMU yaw, 10 Hz low-pass
    times, poses = dead_reckon_ece276a(log.encoders, log.imu, robot)
    gt_t, gt = read_tum(demo_exact / "groundtruth.tum")
    gap = np.abs(gt_t[np.clip(np.searchsorted(gt_t, times), 0, gt_t.size - 1)] - times)
    gap = np.minimum(gap, np.abs(gt_t[np.clip(np.searchsorted(gt_t, times) - 1, 0, None)] - times))
    assert gap.max() < 1.5e-6  # the TUM file holds every encoder time (to the µs)
    truth = interpolate_poses(gt_t, gt, times)
    err = np.hypot(poses[:, 0] - truth[:, 0], poses[:, 1] - truth[:, 1])
    length = np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))
    assert length > 60.0 and times[-1] - times[0] > 120.0
    assert err.max() < 0.01
    assert np.abs(wrap_angle(poses[:, 2] - truth[:, 2])).max() < 0.002


def test_encoder_ticks_are_the_quantised_wheel_travel(small_scene):
    traj = small_scene.trajectory
    wheels = WheelSpec()
    times = sample_times(np.random.default_rng(0), traj.t0 + 0.01, traj.t_end, 40.0, 0.0)
    counts = simulate_encoders(traj, times, np.random.default_rng(0), OFF, wheels)
    assert counts.dtype == np.int16 and counts.shape == (4, times.size) and not counts[:, 0].any()
    cum = np.cumsum(counts.astype(np.int64), axis=1) * wheels.meters_per_tick
    d = traj.distance_at(times) - traj.distance_at(times[:1])
    th = traj.heading_at(times) - traj.heading_at(times[:1])
    right = d + wheels.track_width / 2 * th
    left = d - wheels.track_width / 2 * th
    tick = wheels.meters_per_tick
    for row, side in ((0, right), (2, right), (1, left), (3, left)):
        assert np.abs(cum[row] - side).max() < tick + 1e-9
    assert counts.max() <= 16  # 1 m/s at 40 Hz is 11 ticks per interval


def test_imu_measures_turn_rate_centripetal_acceleration_and_gravity(small_scene):
    traj = small_scene.trajectory
    t = sample_times(np.random.default_rng(0), traj.t0, traj.t_end, 100.0, 0.0)
    gyro, accel = simulate_imu(traj, t, np.random.default_rng(0), OFF)
    np.testing.assert_array_equal(gyro[2], traj.yaw_rate_at(t))
    np.testing.assert_array_equal(gyro[:2], 0.0)
    np.testing.assert_allclose(accel[1], traj.speed_at(t) * traj.yaw_rate_at(t) / GRAVITY)
    np.testing.assert_array_equal(accel[2], 1.0)
    assert np.abs(accel[0]).max() <= 0.6 / GRAVITY + 1e-9  # braking limit 0.6 m/s^2
    noisy, _ = simulate_imu(traj, t, np.random.default_rng(1), NoiseConfig())
    resid = noisy[2] - gyro[2]
    assert 0.003 < np.std(resid - np.mean(resid)) < 0.005  # 0.004 rad/s white noise


def test_scan_endpoints_from_true_poses_fall_on_occupied_cells(small_exact):
    log = load_ece276a(small_exact, 20, need=("scans",))
    scans = log.scans
    assert len(scans) == 480 and scans.num_beams == 1081 and scans.invalid_beams == 0
    gt_t, gt = read_tum(small_exact / "groundtruth.tum")
    poses = interpolate_poses(gt_t, gt, scans.time)
    lidar = LidarSpec()
    x0 = poses[:, 0] + lidar.x * np.cos(poses[:, 2])
    y0 = poses[:, 1] + lidar.x * np.sin(poses[:, 2])
    ang = poses[:, 2:3] + scans.angles[None, :]
    r = scans.ranges.astype(np.float64)
    hit = r < scans.no_return
    assert hit.mean() > 0.99
    x = x0[:, None] + r * np.cos(ang)
    y = y0[:, None] + r * np.sin(ang)
    world = np.load(small_exact / "groundtruth_map.npz")
    occ, res, origin = world["occupancy"], float(world["resolution"]), world["origin"]
    col = np.floor((x[hit] - origin[0]) / res).astype(int)
    row = np.floor((y[hit] - origin[1]) / res).astype(int)
    on_occupied = occ[row, col] == 1
    assert on_occupied.mean() >= 0.99
    # The cell just before each endpoint (5 cm back along the beam) is free for most beams.
    xb = x[hit] - 0.05 * np.cos(ang[hit])
    yb = y[hit] - 0.05 * np.sin(ang[hit])
    before = occ[
        np.floor((yb - origin[1]) / res).astype(int), np.floor((xb - origin[0]) / res).astype(int)
    ]
    assert (before == 0).mean() > 0.95


def test_floor_pixels_land_on_the_right_texture_colour(small_exact):
    log = load_ece276a(small_exact, 20, need=("kinect",))
    rgbd = log.rgbd
    np.testing.assert_array_equal(rgbd.rgb_time, rgbd.disparity_time)  # noise-free: synchronous
    gt_t, gt = read_tum(small_exact / "groundtruth.tum")
    tex = np.load(small_exact / "groundtruth_texture.npz")
    texture, t_res, t_origin = tex["rgb"], float(tex["resolution"]), tex["origin"]
    model = KinectModel()
    matched = total = 0
    for k in range(0, len(rgbd.disparity_time), 4):
        pose = interpolate_poses(gt_t, gt, rgbd.disparity_time[k : k + 1])[0]
        disparity = rgbd.load_disparity(k)
        rgb = rgbd.load_rgb(k)
        points, valid = model.disparity_to_world(disparity, pose)
        # Floor pixels: within 3 cm of z = 0 (the disparity quantisation moves floor points by a
        # few mm vertically; wall bases pass a looser threshold and are not floor).
        i, j = np.nonzero(valid & (np.abs(points[..., 2]) < 0.03))
        ri, rj = model.rgb_coordinates(i, j, model.disparity_to_dd(disparity[i, j]))
        ri, rj = np.rint(ri).astype(int), np.rint(rj).astype(int)
        inside = (ri >= 0) & (ri < 480) & (rj >= 0) & (rj < 640)
        p = points[i[inside], j[inside]]
        tc = np.floor((p[:, 0] - t_origin[0]) / t_res).astype(int)
        tr = np.floor((p[:, 1] - t_origin[1]) / t_res).astype(int)
        diff = np.abs(rgb[ri[inside], rj[inside]].astype(int) - texture[tr, tc].astype(int))
        matched += int(np.count_nonzero(diff.max(axis=1) <= 2))
        total += int(inside.sum())
    assert total > 100_000
    assert matched / total >= 0.95


def test_rendered_disparity_is_the_coded_true_depth(small_scene):
    renderer = KinectRenderer(small_scene.world)
    pose = small_scene.trajectory.pose_at(np.array([small_scene.trajectory.t0 + 10.0]))[0]
    disparity, depth, kind = renderer.disparity(pose)
    model = KinectModel()
    np.testing.assert_array_equal(
        disparity, model.encode_disparity(np.where(kind >= 0, depth, np.nan))
    )
    assert (kind == 0).mean() > 0.4 and (kind == 1).any()
    # Floor depth is the analytic plane intersection.
    i, j = model.pixel_grid()
    rays = model.pixel_rays(i, j) @ renderer.camera(pose)[0].T
    floor = kind == 0
    np.testing.assert_allclose(depth[floor], model.z / -rays[..., 2][floor], rtol=1e-12)


def test_lidar_noise_dropouts_and_no_return():
    rng = np.random.default_rng(0)
    lidar = LidarSpec()
    true = np.concatenate([np.full(200_000, 3.0), np.full(200_000, 15.0), np.full(1000, np.inf)])
    incidence = np.ones_like(true)
    measured = measure_ranges(true[None], incidence[None], rng, NoiseConfig(), lidar)[0]
    assert measured.dtype == np.float32
    near, far, none = measured[:200_000], measured[200_000:400_000], measured[400_000:]
    dropped_near = near < lidar.range_min
    assert 0.001 < dropped_near.mean() < 0.003  # 0.2 % head-on dropouts
    assert np.all(near[dropped_near] < 0.02)  # error codes of a few millimetres
    good = near[~dropped_near] - 3.0 - lidar.penetration
    assert abs(np.std(good) - 0.01) < 0.0005 and abs(np.mean(good)) < 0.0005
    good_far = far[far >= lidar.range_min] - 15.0 - lidar.penetration
    assert abs(np.std(good_far) - 0.03) < 0.0015
    assert np.all(none[none >= lidar.range_min] == 30.0)  # nothing within 30 m: range_max
    grazing = measure_ranges(
        np.full((1, 100_000), 3.0), np.full((1, 100_000), 0.05), rng, NoiseConfig(), lidar
    )[0]
    assert (grazing < lidar.range_min).mean() > 0.2  # grazing beams drop out far more often
    exact = measure_ranges(true[None], incidence[None], rng, OFF, lidar)[0]
    np.testing.assert_array_equal(exact[:200_000], np.float32(3.0 + lidar.penetration))
    np.testing.assert_array_equal(exact[400_000:], np.float32(30.0))


def test_kinect_frame_times_like_the_real_logs():
    noise = NoiseConfig()
    disparity, rgb = kinect_times(np.random.default_rng(0), 0.0, 120.0, 20.0, noise)
    n = 2401
    assert 0.97 * n < disparity.size < n and 0.92 * n < rgb.size < 0.98 * n  # some dropped
    assert np.all(np.diff(disparity) > 0) and np.all(np.diff(rgb) > 0)
    exact_d, exact_r = kinect_times(np.random.default_rng(0), 0.0, 120.0, 20.0, OFF)
    np.testing.assert_array_equal(exact_d, exact_r)
    np.testing.assert_allclose(np.diff(exact_d), 0.05, atol=1e-9)


def test_scene_start_is_free_and_the_robot_starts_at_rest(small_scene):
    traj = small_scene.trajectory
    np.testing.assert_array_equal(traj.pose_at(np.array([traj.t0, traj.t0 + 0.5])), 0.0)
    row, col = small_scene.world.cell_of(0.0, 0.0)
    assert small_scene.world.labels[row, col] == FREE


def test_the_lidar_measured_in_blocks_is_the_whole_log_measured_at_once(small_scene, monkeypatch):
    """Scans simulated a block of rows at a time (noise, dropout chances and codes each drawn in
    one whole-log order) are the scans of one whole-log pass to the bit, and the generator ends
    in the same state; traced at its peak, the pass holds about 13 bytes a reading beyond the
    ray cast of a block (the whole-log pass held about 60)."""
    import tracemalloc

    import slam.sim.sensors as sensors

    traj = small_scene.trajectory
    times = np.linspace(traj.t0 + 1.0, traj.t_end - 1.0, 3000)

    def scans(rows: int) -> tuple[np.ndarray, float]:
        monkeypatch.setattr(sensors, "LIDAR_ROWS", rows)
        rng = np.random.default_rng(11)
        out = sensors.simulate_lidar(small_scene.world, traj, times, rng, NoiseConfig())
        return out, rng.random()

    whole, after = scans(10**9)
    assert np.count_nonzero(whole < 0.02) > 100  # dropouts drawn
    for rows in (1, 7, 256):
        blocked, after_blocked = scans(rows)
        assert blocked.tobytes() == whole.tobytes() and after_blocked == after
    # a dropout's code is a reading like any other: never beyond range_max, however short
    short = sensors.measure_ranges(
        np.array([[np.inf, 3.0]]), np.array([0.0, 1.0]), np.random.default_rng(0),
        NoiseConfig(lidar_dropout=1.0), LidarSpec(range_max=0.01),
    )  # fmt: skip
    assert short.max() <= np.float32(0.01)
    monkeypatch.setattr(sensors, "LIDAR_ROWS", 256)
    tracemalloc.start()
    try:
        sensors.simulate_lidar(
            small_scene.world, traj, times, np.random.default_rng(11), NoiseConfig()
        )
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak / whole.size < 20.0, f"{peak / whole.size:.1f} bytes a reading"
