"""The "dataset20 with simulated LiDAR" fixture: real encoder/IMU timing, simulated Hokuyo20.npz."""

import numpy as np
import pytest

from slam.cli import main
from slam.geometry import compose
from slam.io.ece276a import load_ece276a
from slam.io.tum import read_tum
from slam.sim.sensors import LidarSpec

pytestmark = pytest.mark.data


def test_fixture_links_the_real_files_and_simulates_scans_at_encoder_times(
    dataset20_sim_lidar, ece276a_dir
):
    fx = dataset20_sim_lidar
    for name in ("Encoders20.npz", "Imu20.npz", "Kinect20.npz"):
        linked = fx.folder / name
        assert linked.is_file()
        assert linked.resolve().read_bytes() == (ece276a_dir / name).read_bytes()
    log = load_ece276a(fx.folder, 20, need=("encoders", "imu", "scans", "kinect"))
    assert len(log.encoders) == 4956 and len(log.imu) == 12187  # the real streams
    assert len(log.scans) == 4956 and log.scans.num_beams == 1081
    np.testing.assert_array_equal(log.scans.time, log.encoders.time)  # real 40 Hz timing
    assert log.summary()["scans"]["rate_hz"] == pytest.approx(40.0, rel=0.01)
    assert log.meta["rgbd_images"].startswith("missing")  # no images: texture mapping skips


def test_scan_endpoints_fall_on_the_walls_grown_around_the_path(dataset20_sim_lidar):
    fx = dataset20_sim_lidar
    world = fx.world
    log = load_ece276a(fx.folder, 20, need=("scans",))
    lidar = LidarSpec()
    laser = compose(fx.trajectory.poses, np.array([lidar.x, 0.0, 0.0]))
    r = log.scans.ranges.astype(np.float64)
    hit = np.isfinite(r) & (r < log.scans.no_return)
    assert hit.mean() > 0.95
    ang = laser[:, 2:3] + log.scans.angles[None, :]
    x = laser[:, 0:1] + r * np.cos(ang)
    y = laser[:, 1:2] + r * np.sin(ang)
    # Range noise (1 cm below 10 m, 3 cm beyond) scatters endpoints around the wall faces: they
    # lie on an obstacle cell or within 15 cm (5 sigma) of one.
    rows, cols = world.cell_of(x[hit], y[hit])
    dist = world.obstacle_distance()
    near = (world.labels[rows, cols] > 0) | (dist[rows, cols] <= 0.15)
    assert near.mean() >= 0.999
    assert (world.labels[rows, cols] > 0).mean() > 0.5
    # The path keeps its clearance: no pose closer than 0.6 m to an obstacle.
    rows, cols = world.cell_of(fx.trajectory.poses[:, 0], fx.trajectory.poses[:, 1])
    assert dist[rows, cols].min() >= 0.6
    t, poses = read_tum(fx.folder / "groundtruth.tum")
    np.testing.assert_allclose(poses, fx.trajectory.poses, atol=2e-6)


def test_slam_run_dataset20_goes_end_to_end(dataset20_sim_lidar, tmp_path):
    out = tmp_path / "run"
    code = main(
        ["run", "dataset20", "--data-dir", str(dataset20_sim_lidar.data_dir), "--max-scans", "60",
         "--out", str(out), "--quiet"]
    )  # fmt: skip
    assert code == 0
    t, poses = read_tum(out / "trajectory.tum")
    assert len(t) == 60 and np.all(np.isfinite(poses))
    assert (out / "map.png").is_file()
