"""The texture stage: what ``slam run`` calls after estimation, and ``slam texture RUN_DIR``.

This module owns the stage's contract with the rest of the toolkit: when it applies (a log with
RGB-D frames and image folders, a map, ``texture.enabled``), the figures it adds to
``metrics.json`` under ``"texture"`` (with the ground-truth evaluation when the log's folder is a
simulated dataset), and recomputing the texture of a finished run folder from its
``trajectory.tum``, ``map.npz`` and ``config.toml`` (the dataset found through
:func:`slam.io.sources.resolve`). The work itself is done by :mod:`slam.texture.accumulate`,
:mod:`slam.texture.evaluate` and :mod:`slam.texture.outputs`.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import TEXTURE_MODES, Config
from slam.errors import DataError, UsageError
from slam.io.atomic import write_text
from slam.io.log import Log
from slam.mapping import OccupancyGrid
from slam.texture.accumulate import build_texture
from slam.texture.evaluate import evaluate_texture, load_ground_truth
from slam.texture.outputs import write_outputs
from slam.texture.pairing import TextureWarning
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]


def images_missing(log: Log) -> str | None:
    """Why the log's RGB-D images cannot be used at all (folders absent), or ``None``."""
    status = str(log.meta.get("rgbd_images", "present"))
    if status.startswith("missing"):
        return status
    index = log.rgbd
    if index is not None:
        absent = [str(d) for d in (index.rgb_dir, index.disparity_dir) if not Path(d).is_dir()]
        if absent:
            return "missing: " + ", ".join(absent)
    return None


def texture_stage(
    log: Log,
    trajectory: Trajectory,
    grid: OccupancyGrid,
    config: Config,
    out_dir: Path,
    progress: bool = False,
    require_frames: bool = False,
) -> dict[str, Any]:
    """Compute the texture of ``log`` along ``trajectory`` on ``grid``, write the outputs into
    ``out_dir`` and return the figures for ``metrics.json`` (with the ground-truth evaluation when
    the log's folder is a simulated dataset).

    When the image folders are missing nothing is written and the figures say why. With
    ``require_frames`` a texture of no frame at all is a :class:`DataError`, before anything is
    written (``slam texture``: an empty texture would replace the run's).
    """
    tc = config.texture
    index = log.rgbd
    if index is None:
        return {"skipped": "the log has no RGB-D frames"}
    why = images_missing(log)
    if why is not None:
        message = f"texture: skipped, RGB-D image folders {why}"
        warnings.warn(message, TextureWarning, stacklevel=2)
        return {"skipped": message}
    cpu = time.process_time()
    result = build_texture(index, trajectory, grid, tc, progress)
    cpu = time.process_time() - cpu  # every thread of the process, the decoding ones included
    plan = result.plan
    used = int(result.used.sum())
    if require_frames and used == 0:
        span = (
            f"{float(index.rgb_time.min()):.3f}..{float(index.rgb_time.max()):.3f} s"
            if index.rgb_time.size
            else "none"
        )
        raise DataError(
            f"{log.source or log.name}: no RGB-D frame of its {index.rgb_time.size} (times "
            f"{span}) could be used along the run's trajectory "
            f"({float(trajectory.times.min()):.3f}..{float(trajectory.times.max()):.3f} s; "
            f"skipped: {', '.join(f'{k} {v}' for k, v in sorted(plan.skipped.items())) or 'none'}"
            "): is it the log of this run? Nothing was written"
        )
    write_outputs(out_dir, result.texture, grid)
    gaps = np.abs(plan.rgb_time[result.used] - plan.disparity_time[result.used])
    coloured = int(result.texture.coloured.sum())
    metrics: dict[str, Any] = {
        "mode": tc.mode,
        "rgb_frames": int(index.rgb_time.size),
        "disparity_frames": int(index.disparity_time.size),
        "frames_considered": plan.considered,
        "frames_used": used,
        "frames_skipped": int(sum(plan.skipped.values())),
        "skipped": dict(sorted(plan.skipped.items())),
        "pair_gap_mean_s": round(float(gaps.mean()), 4) if gaps.size else None,
        "pair_gap_max_s": round(float(gaps.max()), 4) if gaps.size else None,
        "floor_samples": result.samples,
        "coloured_cells": coloured,
        "coloured_area_m2": round(coloured * grid.resolution**2, 3),
        "wall_s": round(result.wall_s, 3),
        "frames_per_s": round(used / result.wall_s, 1) if result.wall_s > 0 else None,
        "cpu_s": round(cpu, 3),
    }
    if plan.count_mismatch:
        metrics["count_mismatch"] = plan.count_mismatch
    source = Path(log.source) if log.source is not None else None
    gt = load_ground_truth(source) if source is not None else None
    if gt is not None:
        metrics["ground_truth"] = evaluate_texture(
            result.texture, gt, plan.disparity_time[result.used], tc, trajectory
        )
    return metrics


def run_stage(
    log: Log, estimate: Any, config: Config, out_dir: Path, progress: bool = False
) -> dict[str, Any]:
    """The texture stage as ``slam run`` calls it, on a :class:`slam.online.Result` (its
    ``trajectory`` and ``grid``): ``{"texture": figures}``, or ``{}`` when the stage does not apply (disabled, or no
    RGB-D stream); without a map (dead reckoning without scans) the figures say it was skipped."""
    grid = getattr(estimate, "grid", None)
    if not config.texture.enabled or log.rgbd is None:
        return {}
    if grid is None:
        return {"texture": {"skipped": "no occupancy map to put the texture on"}}
    figures = texture_stage(log, estimate.trajectory, grid, config, out_dir, progress)
    return {"texture": figures}


def update_metrics(path: Path, figures: dict[str, Any]) -> None:
    """Replace the ``"texture"`` key of the ``metrics.json`` at ``path`` (atomically)."""
    path = Path(path)
    try:
        metrics = json.loads(path.read_text()) if path.is_file() else {}
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot read metrics ({exc})") from None
    if not isinstance(metrics, dict):
        raise DataError(f"{path}: expected a JSON object, found {type(metrics).__name__}")
    metrics["texture"] = figures
    write_text(path, json.dumps(metrics, indent=2) + "\n")


RUN_FILES = ("config.toml", "trajectory.tum", "map.npz")
"""What ``slam texture RUN_DIR`` reads from a run folder."""


def recompute_run(
    run_dir: Path,
    data_dir: Path,
    *,
    mode: str | None = None,
    dataset: str | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Recompute the texture of a finished run from its ``trajectory.tum`` and ``map.npz`` and the
    dataset named in its ``config.toml`` (or ``dataset``); rewrite ``texture.npz``,
    ``texture.png``, ``texture_overlay.png`` and the ``"texture"`` key of ``metrics.json``, each
    atomically. Returns the texture figures.
    """
    from slam.config import load_config
    from slam.io import sources
    from slam.io.tum import read_tum

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise DataError(f"{run_dir}: run folder not found")
    missing = [n for n in RUN_FILES if not (run_dir / n).is_file()]
    if missing:
        raise DataError(
            f"{run_dir}: not a finished run folder, missing {', '.join(missing)} "
            "(expected the output of `slam run`)"
        )
    config = load_config("", run_dir / "config.toml")
    if mode is not None:
        if mode not in TEXTURE_MODES:
            raise UsageError(f"--mode: expected one of {', '.join(TEXTURE_MODES)}, found {mode!r}")
        config = dataclasses.replace(config, texture=dataclasses.replace(config.texture, mode=mode))
    name = dataset or config.dataset
    if not name:
        raise DataError(f"{run_dir / 'config.toml'}: no 'dataset' key; give --dataset")
    where = "--dataset" if dataset else f"{run_dir / 'config.toml'}: dataset"
    hint = "" if dataset else "give the dataset with --dataset NAME_OR_PATH"
    ref = sources.resolve(name, data_dir, where=where, hint=hint)
    trajectory = read_tum(run_dir / "trajectory.tum")
    grid = read_map(run_dir / "map.npz", config)
    from slam.io.runfolder import get_kind, is_own_output

    if not is_own_output(run_dir, "run"):  # the texture files would replace a user's own
        raise DataError(
            f"{run_dir}: not a folder `slam run` made (no {get_kind('run').marker}): slam texture "
            "writes texture.npz, texture.png, texture_overlay.png and metrics.json into a run "
            "folder and replaces nothing it did not make (a run folder of a version before the "
            "marker: create an empty .slam-run in it)"
        )
    log = sources.load(ref, config, need=("kinect",), progress=progress).log
    if log.rgbd is None:
        raise DataError(f"dataset {name}: no Kinect frames (KinectNN.npz)")
    why = images_missing(log)
    if why is not None:
        raise DataError(f"dataset {name}: RGB-D image folders {why}")
    figures = texture_stage(log, trajectory, grid, config, run_dir, progress, require_frames=True)
    update_metrics(run_dir / "metrics.json", figures)
    return figures


def read_map(path: Path, config: Config) -> OccupancyGrid:
    """The occupancy grid of a run's ``map.npz`` (:func:`slam.io.exports.read_map_npz`: one
    :class:`DataError` naming the file and the key when it is damaged)."""
    from slam.io.exports import read_map_npz

    log_odds, resolution, origin = read_map_npz(path)
    return OccupancyGrid.from_arrays(log_odds, resolution, origin, config.map)
