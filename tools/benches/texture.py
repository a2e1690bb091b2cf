"""Texture-mapping benches: frames per second of the whole stage and of its parts.

* ``demo_ground_truth_path`` — the texture of the demo dataset (``slam run demo``'s data, taken
  from the cache, generated there on first use) along its true path on a 40 m map at 0.05 m:
  frames/s of the stage (PNG decoding in ``texture.read_threads`` threads + the projection
  kernel), CPU milliseconds per frame, and the acceptance figures (colour error, coverage).
* ``demo_phases`` — the same frames, one thread, split by phase: CPU milliseconds per frame of
  decoding the RGB PNG, decoding the disparity PNG (:mod:`slam.io.png`) and the projection /
  accumulation kernel (the stage runs them in ``read_threads`` threads at once).
* ``demo_slam_run`` — ``slam run demo`` with the defaults (texture on, recording off): the texture
  along the SLAM trajectory, scored against the true floor as the run's ``metrics.json`` scores it
  (colour error and coverage, and both once the map's offset from the true frame is aligned away),
  with the run's ATE and that offset.
* ``kernel_frame`` — the projection/accumulation kernel alone on one in-memory frame pair of a
  flat floor (307 200 pixels), best of 20.
* ``png_decode`` — reading one RGB and one disparity PNG of the demo (``RgbdIndex.load_*``),
  best of 20.

The machine's load average is reported with each figure: the shared 2-core machine is rarely idle.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from benches._util import best_of, data_dir


def _demo_log():
    from slam.io.datadir import resolve_cache_dir
    from slam.io.ece276a import load_ece276a
    from slam.sim.demo import DEMO_NUMBER, ensure_demo

    folder = ensure_demo(resolve_cache_dir())
    return folder, load_ece276a(folder, DEMO_NUMBER, need=("kinect",), name="demo")


def demo_ground_truth_path() -> dict:
    """The whole stage on the demo along the true path, with its accuracy figures."""
    import warnings

    from slam.config import MapConfig, TextureConfig
    from slam.mapping import OccupancyGrid
    from slam.texture import build_texture, evaluate_texture, load_ground_truth, warm_up
    from slam.trajectory import Trajectory

    folder, log = _demo_log()
    gt = load_ground_truth(Path(folder))
    config = TextureConfig()
    warm_up()
    load = os.getloadavg()[0]
    cpu = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = build_texture(
            log.rgbd, Trajectory(gt.times, gt.poses), OccupancyGrid(MapConfig()), config
        )
    cpu = time.process_time() - cpu
    used = int(result.used.sum())
    start = time.perf_counter()
    figures = evaluate_texture(result.texture, gt, result.plan.disparity_time[result.used], config)
    return {
        "frames_used": used,
        "frames_skipped": int(sum(result.plan.skipped.values())),
        "wall_s": round(result.wall_s, 3),
        "frames_per_s": round(used / result.wall_s, 1),
        "cpu_ms_per_frame": round(1000 * cpu / max(used, 1), 2),
        "read_threads": config.read_threads,
        "colour_mae": figures["colour_mae"],
        "coverage": figures["coverage"],
        "swept_area_m2": figures["swept_area_m2"],
        "evaluation_s": round(time.perf_counter() - start, 3),
        "load_average_at_start": round(load, 2),
    }


def demo_slam_run() -> dict:
    """``slam run demo`` as a user runs it (recording off): the texture's figures along the SLAM
    trajectory, from the run's ``metrics.json``."""
    import json
    import math
    import tempfile

    from slam.config import load_config
    from slam.pipeline import RunRequest, run

    _demo_log()  # the dataset generated beforehand, so that the run only runs
    config = load_config("demo", None, ["viz.record=false"])
    with tempfile.TemporaryDirectory(prefix="slam-bench-texture-") as tmp:
        folder = run(
            RunRequest(name="demo", config=config, data_dir=data_dir(), out=Path(tmp) / "run")
        )
        metrics = json.loads((folder / "metrics.json").read_text())
    truth = metrics["texture"]["ground_truth"]
    dx, dy, dtheta = truth["alignment"]
    return {
        "ate_rmse": round(metrics["ate_rmse"], 4),
        "colour_mae": truth["colour_mae"],
        "coverage": truth["coverage"],
        "colour_mae_aligned": truth["colour_mae_aligned"],
        "coverage_aligned": truth["coverage_aligned"],
        "map_offset_m": round(math.hypot(dx, dy), 4),
        "map_offset_deg": round(abs(math.degrees(dtheta)), 3),
        "frames_used": metrics["texture"]["frames_used"],
    }


def demo_phases() -> dict:
    """CPU time per frame of each phase of the stage, one frame pair after the other."""
    from slam.config import MapConfig, TextureConfig
    from slam.mapping import OccupancyGrid
    from slam.texture import (
        TextureAccumulator,
        frame_poses,
        load_ground_truth,
        plan_frames,
        warm_up,
    )
    from slam.trajectory import Trajectory

    folder, log = _demo_log()
    gt = load_ground_truth(Path(folder))
    index, config = log.rgbd, TextureConfig()
    warm_up()
    index.load_disparity(0), index.load_rgb(0)  # the decoder's kernel: compiled or loaded
    plan = plan_frames(index, config, (float(gt.times.min()), float(gt.times.max())))
    pose_d, pose_r = frame_poses(plan, Trajectory(gt.times, gt.poses))
    grid = OccupancyGrid(MapConfig())
    acc = TextureAccumulator(grid.geometry, config)
    load = os.getloadavg()[0]
    spent = {"rgb_decode": 0.0, "disparity_decode": 0.0, "kernel": 0.0}
    n = plan.rgb.size
    for k in range(n):
        t0 = time.process_time()
        rgb = index.load_rgb(int(plan.rgb[k]))
        t1 = time.process_time()
        disparity = index.load_disparity(int(plan.disparity[k]))
        t2 = time.process_time()
        acc.add_frame(disparity, rgb, pose_d[k], pose_r[k])
        t3 = time.process_time()
        spent["rgb_decode"] += t1 - t0
        spent["disparity_decode"] += t2 - t1
        spent["kernel"] += t3 - t2
    out = {f"{name}_cpu_ms_per_frame": round(1000 * s / n, 2) for name, s in spent.items()}
    out["total_cpu_ms_per_frame"] = round(1000 * sum(spent.values()) / n, 2)
    out["frames"] = int(n)
    out["floor_samples_per_frame"] = round(acc.samples / n)
    out["load_average_at_start"] = round(load, 2)
    return out


def kernel_frame() -> dict:
    """The kernel alone on one analytic floor frame."""
    from slam.config import TextureConfig
    from slam.grid_geometry import GridGeometry
    from slam.kinect import KinectModel
    from slam.texture import TextureAccumulator

    model = KinectModel()
    i, j = model.pixel_grid()
    rays = model.pixel_rays(i, j) @ model.rotation.T
    with np.errstate(divide="ignore"):
        depth = np.where(rays[..., 2] < 0, model.z / -rays[..., 2], np.inf)
    disparity = model.encode_disparity(depth)
    rgb = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    acc = TextureAccumulator(GridGeometry((-20.0, -20.0), 0.05, (800, 800)), TextureConfig())
    pose_d, pose_r = np.array([1.0, 2.0, 0.3]), np.array([1.01, 2.0, 0.31])
    acc.add_frame(disparity, rgb, pose_d, pose_r)  # compile / load from cache
    load = os.getloadavg()[0]
    seconds, added = best_of(lambda: acc.add_frame(disparity, rgb, pose_d, pose_r), 20)
    return {
        "kernel_ms": round(seconds * 1000, 3),
        "floor_samples": int(added),
        "ns_per_pixel": round(seconds * 1e9 / disparity.size, 2),
        "load_average_at_start": round(load, 2),
    }


def png_decode() -> dict:
    """Decoding one RGB and one disparity PNG of the demo."""
    _, log = _demo_log()
    index = log.rgbd
    load = os.getloadavg()[0]
    rgb_s, _ = best_of(lambda: index.load_rgb(100), 20)
    disp_s, _ = best_of(lambda: index.load_disparity(100), 20)
    return {
        "rgb_png_ms": round(rgb_s * 1000, 3),
        "disparity_png_ms": round(disp_s * 1000, 3),
        "load_average_at_start": round(load, 2),
    }


def benches() -> dict:
    """The texture benches."""
    return {
        "demo_ground_truth_path": demo_ground_truth_path,
        "demo_phases": demo_phases,
        "demo_slam_run": demo_slam_run,
        "kernel_frame": kernel_frame,
        "png_decode": png_decode,
    }
