"""The shared ROS 1 bags of intel and aces: the loader against the CARMEN logs rebuilt from
them, ROS 2 (sqlite3, MCAP) conversions, and a short ``slam run`` on a bag read back by evo."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_rosbag import assert_same_log

from slam.cli import main
from slam.config import load_config
from slam.io.carmen import load_carmen
from slam.io.mapserver import read_map_yaml, trinary
from slam.io.rosbag import BagOptions, load_bag
from slam.io.tum import read_tum

LOGS = ("intel", "aces")


def _bag(carmen_dir: Path, name: str) -> Path:
    path = carmen_dir / "bags" / f"{name}.orig.bag"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    return path


@pytest.mark.parametrize("name", LOGS)
def test_bag_holds_the_carmen_streams_in_time_order(carmen_dir, name):
    bag = load_bag(_bag(carmen_dir, name))
    clf = load_carmen(carmen_dir / f"{name}.clf.gz", name=name, lidar=load_config(name).lidar)
    order = np.argsort(clf.scans.time, kind="stable")
    s, c = bag.scans, clf.scans
    np.testing.assert_array_equal(s.time, c.time[order])
    np.testing.assert_array_equal(s.ranges, c.ranges[order])  # NaN where CARMEN has NaN
    np.testing.assert_allclose(s.angles, c.angles, atol=1e-6)  # float32 angle_min/increment
    np.testing.assert_array_equal(s.laser_offset, c.laser_offset)  # tf_static: (0, 0, 0)
    assert bag.meta["laser_offset_source"] == "tf_static"
    assert s.no_return == c.no_return or (name == "aces" and s.no_return == 50.0)
    np.testing.assert_array_equal(bag.odometry.time, clf.odometry.time)
    np.testing.assert_allclose(bag.odometry.poses, clf.odometry.poses, atol=1e-9)
    assert s.non_monotonic == 0 and c.non_monotonic == (631 if name == "intel" else 0)


@pytest.fixture(scope="module", params=LOGS)
def converted(request, carmen_dir, tmp_path_factory):
    """``(name, ROS 1 bag, {storage: ROS 2 bag folder})`` made by ``rosbags-convert``."""
    name = request.param
    bag = _bag(carmen_dir, name)
    convert = shutil.which("rosbags-convert", path=str(Path(sys.executable).parent))
    assert convert, "rosbags-convert is installed with rosbags"
    out = tmp_path_factory.mktemp(f"{name}-ros2")
    folders = {}
    for storage in ("sqlite3", "mcap"):
        dst = out / f"{name}_{storage}"
        subprocess.run([convert, "--src", str(bag), "--dst", str(dst), "--dst-storage", storage],
                       check=True, capture_output=True)  # fmt: skip
        folders[storage] = dst
    return name, bag, folders


def test_ros2_conversions_load_to_the_identical_log(converted):
    name, bag, folders = converted
    ros1 = load_bag(bag)
    for storage, folder in folders.items():
        ros2 = load_bag(folder)
        assert ros2.meta["format"] == "rosbag2" and ros2.name == f"{name}_{storage}"
        assert ros2.meta["fast_decoder"] == "odom=True, scan=True"
        assert_same_log(ros1, ros2)
    bare = load_bag(next(folders["mcap"].glob("*.mcap")))  # the storage file on its own
    assert bare.meta["format"] == "mcap"
    assert_same_log(ros1, bare)


@pytest.fixture(scope="module")
def bag_run(carmen_dir, tmp_path_factory) -> Path:
    """``slam run intel.orig.bag`` on its first 300 scans."""
    out = tmp_path_factory.mktemp("bagrun") / "intel-bag"
    code = main(["run", str(_bag(carmen_dir, "intel")), "--out", str(out), "--max-scans", "300",
                 "--quiet", "--no-record"])  # fmt: skip
    assert code == 0
    return out


def test_bag_run_writes_map_server_files_and_uses_no_shipped_config(bag_run):
    names = {p.name for p in bag_run.iterdir()}
    assert {"map.pgm", "map.yaml", "map_clean.png", "map.png", "map.npz"} <= names
    assert "trajectory_file_order.tum" not in names  # bag order is time order
    config = (bag_run / "config.toml").read_text()
    assert 'dataset = "intel.orig"' in config
    assert "# fov_deg unset" in config and "# no_return unset" in config  # not configs/intel
    metrics = json.loads((bag_run / "metrics.json").read_text())
    assert metrics["poses"] == 300 and metrics["dataset"] == "intel.orig"
    with np.load(bag_run / "map.npz") as z:
        expected = trinary(z["log_odds"])
        origin = z["origin"]
    grid = read_map_yaml(bag_run / "map.yaml")
    np.testing.assert_array_equal(grid.occupancy, expected)
    np.testing.assert_array_equal(grid.origin, [origin[0], origin[1], 0.0])
    assert grid.occupied().sum() > 500


def test_eval_reports_the_map_yaml(bag_run, carmen_dir, capsys):
    relations = carmen_dir / "relations" / "intel.relations"
    assert main(["eval", str(bag_run), "--relations", str(relations), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["map"]["occupied_cells"] == int(
        read_map_yaml(bag_run / "map.yaml").occupied().sum()
    )
    assert report["relations"]["count"] == 4  # the relations within the first 300 scans


def test_evo_reads_the_run_folder(bag_run, tmp_path):
    if importlib.util.find_spec("evo") is None:
        pytest.skip("evo is not installed (it is a dev dependency: uv sync --group dev)")
    from evo.tools import file_interface

    traj = file_interface.read_tum_trajectory_file(str(bag_run / "trajectory.tum"))
    traj.check()  # raises on timestamps that are not ascending
    times, poses = read_tum(bag_run / "trajectory.tum")
    np.testing.assert_allclose(traj.timestamps, times)
    np.testing.assert_allclose(traj.positions_xyz[:, :2], poses[:, :2], atol=1e-6)

    evo_traj = shutil.which("evo_traj", path=str(Path(sys.executable).parent))
    assert evo_traj, "evo installs the evo_traj command"
    plot = tmp_path / "traj.png"
    env = {**os.environ, "MPLBACKEND": "Agg"}  # headless
    done = subprocess.run(
        [evo_traj, "tum", str(bag_run / "trajectory.tum"), "--ros_map_yaml",
         str(bag_run / "map.yaml"), "--save_plot", str(plot), "--plot_mode", "xy"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert "300 poses" in done.stdout
    assert any(p.name.startswith("traj") and p.suffix == ".png" for p in tmp_path.iterdir())


@pytest.mark.parametrize(("name", "differ"), [("intel", 561), ("aces", 154)])
def test_odom_sync_latest_reproduces_the_carmen_scan_odometry(carmen_dir, name, differ):
    """CARMEN's FLASER lines carry the last ODOM pose before the scan: --odom-sync latest gives
    the same pose except at the scans whose stamps jump (intel's clock) or tie an ODOM stamp."""
    bag = load_bag(_bag(carmen_dir, name), options=BagOptions(odom_sync="latest"))
    clf = load_carmen(carmen_dir / f"{name}.clf.gz", name=name, lidar=load_config(name).lidar)
    order = np.argsort(clf.scans.time, kind="stable")
    gap = np.hypot(*(bag.scans.odometry[:, :2] - clf.scans.odometry[order, :2]).T)
    assert np.count_nonzero(gap > 1e-6) == differ
