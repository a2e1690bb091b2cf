#!/usr/bin/env python3
"""Regenerate the golden recording ``data/reference/viz/scripted-run.rrd``.

The recording comes from a scripted run fed straight to :class:`slam.viz.recorder.RunRecorder`
(no filter, no simulator, so the reference changes only when the recording format does): 40
scans along a circle of radius 2 m, 8 particles, 36-beam scans, a small occupancy map with a
wall (the final map; the snapshots are the recorder's preview of the logged scans), a 4×4
texture, a ground-truth circle. The recording id and the scans/s clock are fixed, log time is
off, batches do not depend on timing: the same code writes the same content.
``tests/test_viz_golden.py`` rebuilds it and compares with ``rerun rrd compare``; after an
intended change of the recording layout run

    uv run python tools/make_viz_reference.py

and commit the new file (about 140 KB).
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "data" / "reference" / "viz" / "scripted-run.rrd"
RECORDING_ID = "slam-viz-golden"
STEPS = 40


class FakeClock:
    """A clock that advances 10 ms per reading (100 scans/s at one reading per scan)."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        self.now += 0.01
        return self.now


def scripted_poses(steps: int = STEPS) -> np.ndarray:
    """``(steps, 3)`` poses on a circle of radius 2 m, heading along the circle."""
    a = np.linspace(0.0, np.pi, steps)
    return np.stack([2.0 * np.cos(a), 2.0 * np.sin(a), a + np.pi / 2], axis=1)


def write_reference(path: Path) -> Path:
    """Write the scripted recording to ``path`` (a ``.rrd`` file); return ``path``."""
    import rerun as rr

    from slam.config import MapConfig, VizConfig
    from slam.mapping import OccupancyGrid
    from slam.observers import StepRecord
    from slam.trajectory import Trajectory
    from slam.viz.recorder import RunRecorder

    viz = VizConfig(map_every=10, detail_every=5, scan_points=24, map_levels=16)
    map_config = MapConfig(resolution=0.1, initial_size_m=6.0)
    recorder = RunRecorder(
        path,
        viz,
        map_config=map_config,
        name="golden",
        recording_id=RECORDING_ID,
        clock=FakeClock(),
        batch_seconds=math.inf,
        batcher_config=rr.ChunkBatcherConfig.NEVER(),
    )
    poses = scripted_poses()
    times = 1000.0 + 0.1 * np.arange(STEPS)
    recorder.log_ground_truth(Trajectory(times, poses + np.array([0.02, -0.02, 0.0])))
    grid = OccupancyGrid(map_config, center=(0.0, 1.0))
    wall = np.stack([np.linspace(-2.5, 2.5, 36), np.full(36, 2.6)], axis=1)
    offsets = np.linspace(-0.05, 0.05, 8)
    for k in range(STEPS):
        pose = poses[k]
        grid.integrate(pose[:2], wall, np.ones(36, dtype=bool))
        record = StepRecord(
            step=k,
            scan_index=k,
            time=float(times[k]),
            pose=pose.copy(),
            n_eff=8.0 - (k % 7) * 0.5,
            max_weight=0.125 + (k % 7) * 0.02,
            updated=k % 2 == 0,
            resampled=k % 7 == 6,
        )
        if k % viz.detail_every == 0:
            record.particles = pose + np.stack([offsets, -offsets, offsets / 10], axis=1)
            record.weights = np.linspace(1.0, 2.0, 8) / np.linspace(1.0, 2.0, 8).sum()
            record.endpoints = wall.copy()
        recorder.on_step(record)
    with tempfile.TemporaryDirectory() as folder:
        rgb = np.arange(48, dtype=np.uint8).reshape(4, 4, 3) * 5
        count = np.ones((4, 4), dtype=np.int32)
        count[0, 0] = 0
        np.savez(
            Path(folder) / "texture.npz",
            rgb=rgb,
            count=count,
            resolution=np.float64(0.5),
            origin=np.array([-1.0, 0.0]),
        )
        recorder.finish(Trajectory(times, poses), grid, Path(folder))
    return path


def main() -> int:
    """Write the reference recording into ``data/reference/viz/``."""
    REFERENCE.parent.mkdir(parents=True, exist_ok=True)
    write_reference(REFERENCE)
    print(f"wrote {REFERENCE.relative_to(ROOT)} ({REFERENCE.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
