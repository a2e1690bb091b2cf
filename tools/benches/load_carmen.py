"""Load times of the CARMEN benchmark logs (intel, aces, fr079), best of 3, in seconds.

Each bench times one :func:`slam.io.carmen.load_carmen` call on the shared gzip file with the
dataset's shipped lidar config (decompression, parsing and validation included) and reports the
scan and beam counts it read, so a speed figure always comes with what was loaded.
"""

from __future__ import annotations

from collections.abc import Callable

from benches._util import best_of, data_dir, skip


def _load(name: str) -> Callable[[], dict]:
    def bench() -> dict:
        from slam.config import load_config
        from slam.io.carmen import load_carmen

        path = data_dir() / "carmen" / f"{name}.clf.gz"
        if not path.is_file():
            return skip(f"{path} is absent")
        lidar = load_config(name).lidar
        seconds, log = best_of(lambda: load_carmen(path, name=name, lidar=lidar))
        return {
            "load_s": round(seconds, 4),
            "file_mb": round(path.stat().st_size / 1e6, 2),
            "scans": len(log.scans),
            "beams": log.scans.num_beams,
            "odom": len(log.odometry) if log.odometry is not None else 0,
            "scans_per_s": round(len(log.scans) / seconds),
        }

    return bench


def benches() -> dict[str, Callable[[], dict]]:
    """One bench per log."""
    return {name: _load(name) for name in ("intel", "aces", "fr079")}
