"""Test fixture "dataset20 with simulated LiDAR": real encoders, IMU and Kinect times, fake laser.

The real ``Hokuyo20.npz`` is not available here, so :func:`assemble_dataset20_with_sim_lidar`
links the real ``Encoders20.npz``, ``Imu20.npz`` and ``Kinect20.npz`` into a folder of the caller's
choosing (a temporary folder: never the repository) and writes a ``Hokuyo20.npz`` simulated at the
real encoder time stamps along the dead-reckoned path, inside a building grown around that path
(:func:`slam.sim.world.world_around_path`: corridors containing the path, walls and clutter at a
clearance from it, a loop wherever the path loops). ``slam run dataset20 --data-dir <data_dir>``
then exercises the real code path end to end with real encoder and IMU timing.

The map-quality scene of the tests and the bench (:func:`demo_loop`, :func:`open_the_loop`): the
demo building with its true trajectory, and that trajectory with the loop left open.
"""

from __future__ import annotations

import math
import os
import shutil
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from slam.config import RobotConfig
from slam.errors import DataError
from slam.geometry import compose, relative
from slam.io.ece276a import load_ece276a, stream_file
from slam.io.tum import write_tum
from slam.odometry import OdometryWarning, dead_reckon_ece276a
from slam.sim.dataset import SimOptions, hokuyo_arrays, map_arrays, save_npz, simulate_log
from slam.sim.sensors import LidarSpec, NoiseConfig, measure_ranges, mount_laser, true_ranges
from slam.sim.world import World, world_around_path
from slam.trajectory import Trajectory

if TYPE_CHECKING:
    from slam.eval.quality import Rays

REAL_FILES = ("Encoders20.npz", "Imu20.npz", "Kinect20.npz")
"""The real files of dataset20 the fixture links beside its simulated ``Hokuyo20.npz``."""


@dataclass(frozen=True)
class SimLidarDataset:
    """Where the assembled dataset lives and what was simulated."""

    data_dir: Path
    """Data directory to pass as ``--data-dir`` (holds ``ece276a/``)."""
    world: World
    """The building the laser was simulated in."""
    trajectory: Trajectory
    """Robot poses at the scan times (the real encoder time stamps): the dead-reckoned path the
    building was grown around."""

    @property
    def folder(self) -> Path:
        """``data_dir / "ece276a"``: the linked real files and the simulated ``Hokuyo20.npz``."""
        return self.data_dir / "ece276a"


def _link(src: Path, dst: Path) -> None:
    try:
        os.symlink(src.resolve(), dst)
    except OSError:
        shutil.copyfile(src, dst)


def assemble_dataset20_with_sim_lidar(
    ece276a_dir: Path, data_dir: Path, *, seed: int = 0, noise: NoiseConfig | None = None
) -> SimLidarDataset:
    """Assemble dataset20 with a simulated ``Hokuyo20.npz`` under ``data_dir / "ece276a"``.

    ``ece276a_dir`` holds the real files (``<data dir>/ece276a``); they are symlinked (copied where
    links are impossible) into ``data_dir``, which must not be inside the repository. The scans
    are at the real encoder times (4956 scans at 40 Hz), from the dead-reckoned poses (encoder
    speed + IMU yaw, :func:`slam.odometry.dead_reckon_ece276a`), with the simulator's default lidar
    noise unless ``noise`` says otherwise. ``groundtruth.tum`` (those poses) and
    ``groundtruth_map.npz`` are written beside them.
    """
    ece276a_dir = Path(ece276a_dir)
    missing = [name for name in REAL_FILES if not (ece276a_dir / name).is_file()]
    if missing:
        raise DataError(
            f"{ece276a_dir}: missing {', '.join(missing)}; the dataset20 fixture needs the real "
            "Encoders20.npz, Imu20.npz and Kinect20.npz"
        )
    folder = Path(data_dir) / "ece276a"
    folder.mkdir(parents=True, exist_ok=True)
    for name in REAL_FILES:
        target = folder / name
        if not target.exists():
            _link(ece276a_dir / name, target)

    log = load_ece276a(ece276a_dir, 20, need=("encoders", "imu"))
    assert log.encoders is not None
    with warnings.catch_warnings():
        # The real IMU stops ~1.7 s before the encoders; the wheels carry the yaw there.
        warnings.simplefilter("ignore", OdometryWarning)
        trajectory = dead_reckon_ece276a(log.encoders, log.imu, RobotConfig())
    times, poses = trajectory.times, trajectory.poses

    rng = np.random.default_rng(seed)
    world = world_around_path(rng, poses[:, :2])
    noise = NoiseConfig() if noise is None else noise
    lidar = LidarSpec()
    ranges, incidence = true_ranges(world, mount_laser(poses, lidar), lidar)
    ranges = measure_ranges(ranges, incidence, rng, noise, lidar)

    save_npz(stream_file(folder, 20, "scans"), hokuyo_arrays(lidar, times, ranges))
    write_tum(folder / "groundtruth.tum", trajectory)
    save_npz(folder / "groundtruth_map.npz", map_arrays(world))
    return SimLidarDataset(Path(data_dir), world, trajectory)


def demo_loop() -> tuple[np.ndarray, np.ndarray, Rays]:
    """The simulator's demo building (124 s, 4960 scans, one loop around the ring and back past
    the start): the scan times, the true poses at them and the rays of every scan."""
    from slam.eval.quality import scan_rays

    log = simulate_log(SimOptions(scenario="demo", rgbd=False))
    lidar = log.options.lidar
    times = log.lidar_time
    truth = log.scene.trajectory.pose_at(times)
    rays = scan_rays(log.ranges, lidar.angles(), np.array([lidar.x, 0.0, 0.0]),
                     lidar.range_min, lidar.range_max, lidar.range_max)  # fmt: skip
    return times, truth, rays


def open_the_loop(poses: np.ndarray, start: int, yaw_deg: float, scale: float) -> np.ndarray:
    """The trajectory with a growing drift after row ``start``: every later step is scaled by
    ``scale`` and turned so that the heading error reaches ``yaw_deg`` at the end (a loop that
    did not close: the second pass lays its walls beside the first pass's)."""
    steps = relative(poses[:-1], poses[1:])
    length = np.hypot(steps[:, 0], steps[:, 1])
    tail = length[start:].sum()
    out = poses.copy()
    for k in range(start, len(poses) - 1):
        step = steps[k].copy()
        step[:2] *= scale
        step[2] += math.radians(yaw_deg) * length[k] / tail
        out[k + 1] = compose(out[k], step)
    return out
