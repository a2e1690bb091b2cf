"""Simulator benches: generating the demo dataset, whole and per stream.

* ``demo_full`` — ``slam sim demo`` with its defaults (124 s, 4960 scans of 1081 beams, Kinect at
  the default rate) into a temporary folder: total wall time, CPU time and the time of each stream
  (scene, encoders, IMU, lidar, Kinect rendering, PNG writing overlapped in 2 threads).
* ``demo_rgbd_20hz`` — the same at the course logs' Kinect rate (20 Hz).
* ``kinect_frame`` — one disparity and one RGB frame: render and PNG-encode times (best of 5).
* ``noise_free_accuracy`` — the acceptance figures of the noise-free demo (docs/sim.md).

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


def noise_free_accuracy() -> dict:
    """The acceptance figures on the noise-free demo (Kinect at 2 Hz to keep it short): dead
    reckoning vs ground truth, scan endpoints on occupied cells, floor pixels on the right colour."""
    from slam.config import load_config
    from slam.geometry import wrap_angle
    from slam.io.ece276a import load_ece276a
    from slam.io.tum import read_tum
    from slam.kinect import KinectModel
    from slam.odometry import dead_reckon_ece276a
    from slam.sim.dataset import SimOptions, generate_dataset
    from slam.sim.sensors import LidarSpec, NoiseConfig

    tmp = Path(tempfile.mkdtemp(prefix="slam-sim-acc-"))
    try:
        folder = tmp / "demo"
        generate_dataset(
            folder, SimOptions(scenario="demo", seed=20, rgbd_rate=2.0, noise=NoiseConfig.off())
        )
        log = load_ece276a(folder, 20, need=("encoders", "imu", "scans", "kinect"))
        reference = read_tum(folder / "groundtruth.tum")
        odometry = dead_reckon_ece276a(log.encoders, log.imu, load_config("demo").robot)
        times, poses = odometry.times, odometry.poses
        truth = reference.at(times)
        err = np.hypot(*(poses[:, :2] - truth[:, :2]).T)
        length = odometry.with_poses(truth).path_length()

        with np.load(folder / "groundtruth_map.npz") as f:
            occ, res, origin = f["occupancy"], float(f["resolution"]), f["origin"]
        scan_poses = reference.at(log.scans.time)
        lx = scan_poses[:, 0] + LidarSpec().x * np.cos(scan_poses[:, 2])
        ly = scan_poses[:, 1] + LidarSpec().x * np.sin(scan_poses[:, 2])
        r = log.scans.ranges.astype(np.float64)
        hit = r < log.scans.no_return
        ang = scan_poses[:, 2:3] + log.scans.angles[None, :]
        col = np.floor((lx[:, None] + r * np.cos(ang) - origin[0]) / res)[hit].astype(int)
        row = np.floor((ly[:, None] + r * np.sin(ang) - origin[1]) / res)[hit].astype(int)
        on_occupied = float(np.mean(occ[row, col] == 1))

        with np.load(folder / "groundtruth_texture.npz") as f:
            texture, t_res, t_origin = f["rgb"], float(f["resolution"]), f["origin"]
        model = KinectModel()
        rgbd = log.rgbd
        matched = total = 0
        for k in range(len(rgbd.disparity_time)):
            pose = reference.at(rgbd.disparity_time[k : k + 1])[0]
            disparity, rgb = rgbd.load_disparity(k), rgbd.load_rgb(k)
            points, valid = model.disparity_to_world(disparity, pose)
            i, j = np.nonzero(valid & (np.abs(points[..., 2]) < 0.03))
            ri, rj = model.rgb_coordinates(i, j, model.disparity_to_dd(disparity[i, j]))
            ri, rj = np.rint(ri).astype(int), np.rint(rj).astype(int)
            ok = (ri >= 0) & (ri < 480) & (rj >= 0) & (rj < 640)
            p = points[i[ok], j[ok]]
            tc = np.floor((p[:, 0] - t_origin[0]) / t_res).astype(int)
            tr = np.floor((p[:, 1] - t_origin[1]) / t_res).astype(int)
            diff = np.abs(rgb[ri[ok], rj[ok]].astype(int) - texture[tr, tc].astype(int))
            matched += int(np.count_nonzero(diff.max(axis=1) <= 2))
            total += int(ok.sum())
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {
        "path_length_m": round(length, 2),
        "dead_reckoning_max_error_m": round(float(err.max()), 5),
        "dead_reckoning_final_error_m": round(float(err[-1]), 5),
        "dead_reckoning_max_yaw_error_rad": round(
            float(np.abs(wrap_angle(poses[:, 2] - truth[:, 2])).max()), 6
        ),
        "scan_endpoints_on_occupied": round(on_occupied, 5),
        "floor_pixels": total,
        "floor_pixels_right_colour": round(matched / max(total, 1), 4),
    }


def benches() -> dict:
    """The simulator's benches."""
    return {
        "demo_full": demo_full,
        "demo_rgbd_20hz": demo_rgbd_20hz,
        "kinect_frame": kinect_frame,
        "noise_free_accuracy": noise_free_accuracy,
    }
