"""Load times of the ECE276A logs (dataset20), best of 3, in seconds.

``dataset20`` times each real file of dataset 20 on its own (encoders, IMU, Kinect index) and one
:func:`load_ece276a` call that reads every file present. Hokuyo20.npz is not in the shared data, so ``hokuyo_synthetic``
times a file of the real size (1081 beams x 4962 scans, float32, documented keys) written to a
temporary folder; it is reported separately and never mixed with the real-file figures.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from benches._util import best_of, data_dir, skip


def _dataset20() -> dict:
    from slam.io.ece276a import load_ece276a, stream_file

    folder = data_dir() / "ece276a"
    if not (folder / "Encoders20.npz").is_file():
        return skip(f"{folder}/Encoders20.npz is absent")
    figures: dict = {}
    for stream in ("encoders", "imu", "kinect"):
        # The loader reads every file present, so time each file alone in a folder that only
        # links to it.
        with tempfile.TemporaryDirectory() as tmp:
            source = stream_file(folder, 20, stream)
            (Path(tmp) / source.name).symlink_to(source)
            seconds, _ = best_of(lambda s=stream, t=tmp: load_ece276a(Path(t), 20, need=(s,)))
        figures[f"{stream}_s"] = round(seconds, 4)
    seconds, log = best_of(lambda: load_ece276a(folder, 20))
    figures["all_present_s"] = round(seconds, 4)
    figures["streams"] = sorted(log.streams())
    figures["encoders"] = len(log.encoders)
    figures["imu"] = len(log.imu)
    return figures


def _hokuyo_synthetic() -> dict:
    from slam.io.ece276a import load_ece276a

    rng = np.random.default_rng(0)
    scans, beams = 4962, 1081
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "Hokuyo20.npz"
        np.savez(
            path,
            angle_min=np.array([[-2.356194490192345]]),
            angle_max=np.array([[2.356194490192345]]),
            angle_increment=np.array([[0.004363323129985824]]),
            range_min=np.array([[0.1]]),
            range_max=np.array([[30.0]]),
            ranges=rng.uniform(0.0, 32.0, size=(beams, scans)).astype(np.float32),
            time_stamps=1298445274.6 + np.arange(scans) / 40.0,
        )
        seconds, log = best_of(lambda: load_ece276a(Path(tmp), 20, need=("scans",)))
        return {
            "load_s": round(seconds, 4),
            "file_mb": round(path.stat().st_size / 1e6, 1),
            "scans": len(log.scans),
            "beams": log.scans.num_beams,
            "invalid_beams": log.scans.invalid_beams,
        }


def benches() -> dict:
    """The benches of this module (see ``tools/bench.py``)."""
    return {"dataset20": _dataset20, "hokuyo_synthetic": _hokuyo_synthetic}
