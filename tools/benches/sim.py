"""Simulator benches: generating the demo dataset, whole and per stream.

* ``demo_full`` — ``slam sim demo`` with its defaults (124 s, 4960 scans of 1081 beams, Kinect at
  the default rate) into a temporary folder: total wall time, CPU time and the time of each stream
  (scene, encoders, IMU, lidar, Kinect rendering, PNG writing overlapped in 2 threads).
* ``demo_rgbd_20hz`` — the same at the course logs' Kinect rate (20 Hz).
* ``kinect_frame`` — one disparity and one RGB frame: render and PNG-encode times (best of 5).

numba kernels are compiled (or loaded from the cache) by a short warm-up run first. The machine's
load average is reported with each figure: the shared 2-core machine is rarely idle.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from benches._util import best_of


def _warm_up() -> None:
    from slam.sim.dataset import SimOptions, generate_dataset

    with tempfile.TemporaryDirectory() as tmp:
        generate_dataset(Path(tmp) / "w", SimOptions(scenario="small", duration=1.0, rgbd_rate=2))


def _size_mb(folder: Path) -> float:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) / 1e6


def _demo(rate: float | None) -> dict:
    from slam.sim.dataset import RGBD_RATE_HZ, SimOptions, generate_dataset

    _warm_up()
    rate = RGBD_RATE_HZ if rate is None else rate
    load = os.getloadavg()[0]
    tmp = Path(tempfile.mkdtemp(prefix="slam-sim-bench-"))
    try:
        cpu = time.process_time()
        start = time.perf_counter()
        summary = generate_dataset(tmp / "demo", SimOptions(scenario="demo", rgbd_rate=rate))
        wall = time.perf_counter() - start
        cpu = time.process_time() - cpu
        size = _size_mb(tmp / "demo")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    timings = {k: round(v, 3) for k, v in summary["timings"].items()}
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 2),
        "rgbd_rate_hz": rate,
        "scans": summary["counts"]["scans"],
        "disparity_frames": summary["counts"]["disparity_frames"],
        "rgb_frames": summary["counts"]["rgb_frames"],
        "dataset_mb": round(size, 1),
        "load_average_at_start": round(load, 2),
        **timings,
    }


def demo_full() -> dict:
    """The full demo at the default Kinect rate."""
    return _demo(None)


def demo_rgbd_20hz() -> dict:
    """The full demo with Kinect frames at 20 Hz."""
    return _demo(20.0)


def kinect_frame() -> dict:
    """Render and encode times of one Kinect frame pair."""
    import cv2

    from slam.sim.dataset import PNG_PARAMS, SimOptions, simulate_log

    _warm_up()
    log = simulate_log(SimOptions(scenario="demo"))
    renderer = log.renderer
    pose = log.scene.trajectory.pose_at(np.array([log.scene.trajectory.t0 + 30.0]))[0]
    disparity_s, (disparity, _, _) = best_of(lambda: renderer.disparity(pose), 5)
    rgb_s, rgb = best_of(lambda: renderer.rgb(pose), 5)
    bgr = np.ascontiguousarray(rgb[:, :, ::-1])
    enc_d_s, (_, buf_d) = best_of(lambda: cv2.imencode(".png", disparity, PNG_PARAMS), 5)
    enc_r_s, (_, buf_r) = best_of(lambda: cv2.imencode(".png", bgr, PNG_PARAMS), 5)
    return {
        "disparity_render_ms": round(disparity_s * 1000, 2),
        "rgb_render_ms": round(rgb_s * 1000, 2),
        "disparity_png_ms": round(enc_d_s * 1000, 2),
        "rgb_png_ms": round(enc_r_s * 1000, 2),
        "disparity_png_kb": round(len(buf_d) / 1000, 1),
        "rgb_png_kb": round(len(buf_r) / 1000, 1),
        "lidar_4960_scans_s": round(log.timings["lidar_s"], 3),
        "load_average_at_start": round(os.getloadavg()[0], 2),
    }


def benches() -> dict:
    """The simulator's benches."""
    return {"demo_full": demo_full, "demo_rgbd_20hz": demo_rgbd_20hz, "kinect_frame": kinect_frame}
