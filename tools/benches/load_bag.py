"""Reading the ROS 1 bags of the CARMEN benchmark logs (intel, aces): time and memory.

Each bench loads ``<data>/carmen/bags/<log>.orig.bag`` with :func:`slam.io.rosbag.load_bag` (no
configuration: geometry and mounting come from the messages and tf_static):

* ``load_s``: best of 3 wall times of the whole load (open, index, one pass, arrays);
* ``peak_alloc_mb``: the most memory the load held at once, traced by :mod:`tracemalloc` (numpy
  buffers included) on a load after a warm-up one, so module imports are not counted;
* ``arrays_mb``: the bytes of the arrays of the returned ``Log``; ``memory_ratio`` is
  ``peak_alloc_mb / arrays_mb`` (the issue's bound: at most 2).
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable

import numpy as np
from benches._util import best_of, data_dir, skip


def _array_bytes(log) -> int:
    total = 0
    for stream in log.streams().values():
        for value in vars(stream).values():
            if isinstance(value, np.ndarray):
                total += value.nbytes
    return total


def _load(name: str) -> Callable[[], dict]:
    def bench() -> dict:
        from slam.io.rosbag import load_bag

        path = data_dir() / "carmen" / "bags" / f"{name}.orig.bag"
        if not path.is_file():
            return skip(f"{path} is absent")
        seconds, log = best_of(lambda: load_bag(path))
        del log
        tracemalloc.start()
        log = load_bag(path)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        arrays = _array_bytes(log)
        return {
            "load_s": round(seconds, 3),
            "file_mb": round(path.stat().st_size / 1e6, 2),
            "scans": len(log.scans),
            "beams": log.scans.num_beams,
            "odom": len(log.odometry),
            "peak_alloc_mb": round(peak / 1e6, 2),
            "arrays_mb": round(arrays / 1e6, 2),
            "memory_ratio": round(peak / arrays, 2),
            "fast_decoder": log.meta["fast_decoder"],
        }

    return bench


def benches() -> dict[str, Callable[[], dict]]:
    """One bench per bag."""
    return {name: _load(name) for name in ("intel", "aces")}
