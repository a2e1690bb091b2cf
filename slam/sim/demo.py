"""The demo dataset: a simulated dataset20-scale log generated once into the cache.

``slam run demo`` calls :func:`ensure_demo` with the cache folder (``$SLAM_CACHE_DIR``, else
``$XDG_CACHE_HOME/slam``, else ``~/.cache/slam``; never the data directory). The first call generates the dataset (≈124 s of
encoders, IMU, 4960 lidar scans, Kinect frames, plus ground truth) and renames it into place when
complete; later calls return the existing folder. The folder name carries the generator version,
seed and Kinect rate, so a new generator never reuses an old cache.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

from slam.io.atomic import rename_noreplace
from slam.io.runfolder import OWNER_FILE, clean_stale_partials, make_partial, remove_owned_tree
from slam.sim.dataset import RGBD_RATE_HZ, SIM_VERSION, SimOptions, write_dataset

DEMO_NUMBER = 20
"""The ``NN`` of the demo's files (``Encoders20.npz``, ...)."""
DEMO_SEED = 20
"""Seed of the demo's world, route and sensor noise."""
DEMO_VERSION = f"v{SIM_VERSION}-seed{DEMO_SEED}"
"""Tag of the demo folder: changes whenever the generator's output changes."""


def demo_options(rgbd: bool = True) -> SimOptions:
    """The options the demo is generated with."""
    return SimOptions(
        scenario="demo", seed=DEMO_SEED, number=DEMO_NUMBER, rgbd=rgbd, rgbd_rate=RGBD_RATE_HZ
    )


def demo_dir(cache_dir: Path, rgbd: bool = True) -> Path:
    """Folder of the demo dataset under ``cache_dir`` (with or without Kinect frames)."""
    rate = f"rgbd{RGBD_RATE_HZ:g}hz" if rgbd else "nordgbd"
    return Path(cache_dir) / f"demo-{DEMO_VERSION}-{rate}"


def ensure_demo(cache_dir: Path, *, progress: bool = False, rgbd: bool = True) -> Path:
    """The folder of the demo dataset under ``cache_dir``, generated on first use.

    With ``rgbd=False`` a complete demo with Kinect frames is reused when present; otherwise a
    lighter one without them is generated. Generation happens in a temporary sibling folder that
    is renamed into place only when complete, so an interrupted run leaves nothing half-written and
    two processes generating at once both end up with one complete folder. A generation killed
    outright (SIGKILL) leaves a partial folder with its owner record, removed by the next call
    (:func:`slam.io.runfolder.clean_stale_partials`).
    """
    cache_dir = Path(cache_dir)
    full = demo_dir(cache_dir, rgbd=True)
    if full.is_dir():
        return full
    target = full if rgbd else demo_dir(cache_dir, rgbd=False)
    if target.is_dir():
        return target
    cache_dir.mkdir(parents=True, exist_ok=True)
    if progress:
        print(
            f"slam: generating the demo dataset (first use) into {target}",
            file=sys.stderr,
            flush=True,
        )
    clean_stale_partials(cache_dir)  # of generations killed before they finished
    staging = make_partial(cache_dir, target.name)
    try:
        from slam.sim.dataset import simulate_log

        write_dataset(simulate_log(demo_options(rgbd)), staging, progress=progress)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(staging / OWNER_FILE)
        try:
            rename_noreplace(staging, target)
        except FileExistsError:
            # Another process finished first: its folder is complete, keep it.
            if not target.is_dir():
                raise
    finally:
        remove_owned_tree(staging)
    return target
