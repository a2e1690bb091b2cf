"""Shared fixtures: the data directory (tests that need real logs skip without it)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

os.environ.setdefault("RERUN_ANALYTICS", "0")
os.environ.setdefault("RERUN_TELEMETRY", "0")

# Property tests draw the same examples on every run (the suite is deterministic, like the
# toolkit); `SLAM_HYPOTHESIS_PROFILE=explore` (or `--hypothesis-profile=explore`) draws fresh ones to hunt for new failures.
settings.register_profile("default", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("SLAM_HYPOTHESIS_PROFILE", "default"))


def _shared_data_dir() -> Path | None:
    env = os.environ.get("SLAM_DATA_DIR")
    if env and Path(env).is_dir():
        return Path(env)
    return None


def _logs_in(data_dir: Path, folder: str, probe: str, what: str) -> Path:
    """``data_dir / folder``; skips the test when the file ``probe`` is not in it (``what``: the
    logs that are then unavailable)."""
    path = data_dir / folder
    if not (path / probe).is_file():
        pytest.skip(f"{path}/{probe} is absent: {what} unavailable")
    return path


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """The real data directory (``$SLAM_DATA_DIR``); skips the test when it is absent."""
    path = _shared_data_dir()
    if path is None:
        pytest.skip("SLAM_DATA_DIR is not set or is not a folder: real logs unavailable")
    return path


@pytest.fixture(scope="session")
def ece276a_dir(data_dir: Path) -> Path:
    """``<data dir>/ece276a`` with the real encoder, IMU and Kinect files."""
    return _logs_in(data_dir, "ece276a", "Encoders20.npz", "ECE276A logs")


@pytest.fixture(scope="session")
def carmen_dir(data_dir: Path) -> Path:
    """``<data dir>/carmen`` with the CARMEN logs and relations."""
    return _logs_in(data_dir, "carmen", "intel.clf.gz", "CARMEN logs")


@pytest.fixture(scope="session")
def dataset20_sim_lidar(ece276a_dir: Path, tmp_path_factory: pytest.TempPathFactory):
    """dataset20 with simulated LiDAR: the real encoders, IMU and Kinect times linked into a
    temporary data directory plus a ``Hokuyo20.npz`` simulated along their dead-reckoned path
    (:func:`slam.sim.fixtures.assemble_dataset20_with_sim_lidar`); skips without the real data.
    ``.data_dir`` is the ``--data-dir`` for ``slam run dataset20``."""
    from slam.sim.fixtures import assemble_dataset20_with_sim_lidar

    return assemble_dataset20_with_sim_lidar(ece276a_dir, tmp_path_factory.mktemp("dataset20sim"))
