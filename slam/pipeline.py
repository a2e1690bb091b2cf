"""The ``slam run`` pipeline: find the data, estimate, write the run folder.

``run(request)`` loads the log its NAME stands for (a registry dataset, the simulator's ``demo``,
or a log file/folder given by path: :mod:`slam.io.sources` decides), feeds its scans one by one
to a :class:`slam.online.Slam` (the object an online user has: batch and online runs agree bit
for bit), and writes the run folder atomically (it appears complete or not at all):

* ``config.toml``   — the exact configuration used (re-run with ``--config``);
* ``trajectory.tum`` — one pose per processed scan (per encoder reading for ``odometry`` on
  ECE276A logs), sorted by time; ``trajectory_file_order.tum`` too when the log's clock runs
  backwards (:mod:`slam.io.exports`);
* ``map.npz``, ``map.png`` — log-odds grid (resolution, origin) and a picture with the trajectory;
* ``map.pgm``, ``map.yaml``, ``map_clean.png`` — the map for ROS map_server / nav2 / evo
  (:mod:`slam.io.mapserver`) and the picture without the trajectory;
* ``texture.npz``, ``texture.png``, ``texture_overlay.png`` — the floor texture on the map's
  grid when the log has RGB-D frames (:mod:`slam.texture`, off with ``--no-texture``);
* ``quality.png`` — the map-quality score without ground truth (:mod:`slam.eval.quality_run`,
  ``quality.enabled``), its figures in ``metrics.json`` under ``quality``;
* ``metrics.json``  — sizes, timings (wall, scans/s, real-time factor, peak memory), filter
  diagnostics, and ATE/RPE when the dataset has a ground-truth trajectory.

The recorder and the progress bar watch the ``Slam`` object as observers; the texture stage runs
on its result. :func:`run_dataset` (``slam.run``) is the same pipeline as one Python call.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import resource
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

import slam.jit_background as jit_background
from slam.budget import growth_share, release_free_memory
from slam.config import Config, Override, dumps, load_config, override_list, seed_value
from slam.errors import UsageError
from slam.io import sources
from slam.io.atomic import atomic_dir, check_output_dir, write_png, write_text
from slam.io.exports import clock_warning, write_map_files, write_trajectories
from slam.io.log import Log
from slam.io.plausibility import check_plausibility
from slam.io.rosbag import BagOptions
from slam.io.sources import Source
from slam.jit import compile_seconds, on_compile
from slam.jit_background import reach_stage
from slam.mapping import OccupancyGrid
from slam.observers import Observer

if TYPE_CHECKING:
    from slam.online import Result
    from slam.trajectory import Trajectory

F64 = NDArray[np.float64]


@dataclass
class RunRequest:
    """Everything ``slam run`` was asked to do."""

    name: str
    """Dataset name (registry or ``demo``) or a path to a log file or ECE276A folder."""
    config: Config
    """The resolved configuration."""
    data_dir: Path
    """The data directory."""
    out: Path | None = None
    """Run folder; default ``runs/<name>-<YYYYmmdd-HHMMSS>``."""
    force: bool = False
    """Replace an existing run folder of ``slam run`` (:func:`slam.io.runfolder.is_own_output`)."""
    inputs: tuple[Path, ...] = ()
    """Further files the run reads (the ``--config`` file): ``out`` may not hold them."""
    progress: bool = False
    """Show a progress bar."""
    viewer: bool = False
    """Stream the recording live to a spawned rerun viewer (:mod:`slam.viz`)."""
    bag: BagOptions = field(default_factory=BagOptions)
    """Topics and robot frame to read when ``name`` is a ROS bag or MCAP file."""


def _needs(config: Config) -> tuple[str, ...]:
    if config.filter.method == "odometry":
        return ("encoders", "imu")
    return ("encoders", "imu", "scans")


def load_source(
    name: str, data_dir: Path, config: Config, progress: bool = False, **bag: BagOptions | None
) -> Source:
    """Load the log ``name`` (see :func:`slam.io.sources.resolve`) with the streams the
    configured method needs; ``bag=BagOptions(...)`` chooses a ROS bag's topics."""
    ref = sources.resolve(name, data_dir, where="slam run NAME")
    return sources.load(ref, config, _needs(config), progress, **bag)


def default_run_dir(name: str) -> Path:
    """``runs/<name>-<YYYYmmdd-HHMMSS>`` (with a numeric suffix if it already exists or another
    live run is writing it), ``name`` being the dataset's configuration name (the file or folder
    name up to its first dot)."""
    from slam.io.runfolder import live_writers

    base = Path("runs") / f"{name or 'run'}-{datetime.now():%Y%m%d-%H%M%S}"
    candidate, k = base, 1
    while os.path.lexists(candidate) or live_writers(candidate.parent, candidate.name):
        k += 1
        candidate = base.with_name(f"{base.name}-{k}")
    return candidate


WORST_COLOUR = (160, 0, 160)
"""BGR of the worst stretches' marks on ``map.png`` (the purple of ``quality.png``)."""


def render_map(
    grid: OccupancyGrid,
    trajectory: F64,
    ground_truth: F64 | None = None,
    worst: list[dict[str, Any]] | None = None,
    times: F64 | None = None,
) -> NDArray[np.uint8]:
    """``map.png``: occupancy in grey, the estimated trajectory in red, ground truth in green;
    with ``worst`` (the map-quality score's worst stretches, the ``worst`` entries of its report:
    :func:`slam.eval.quality.summary`) each of them too, in purple: its part of the path
    (``times``: the trajectory's, to find it by its ``log_time``), a circle where its returns
    conflict with the rest of the map (``place_xy``) and a label with its rank, its time since
    the start and its score, as ``quality.png`` marks them."""
    import cv2

    from slam.rowwise import grid_image

    img = grid_image(grid, channels=3)  # grid.to_image() in three channels, by blocks
    scale = max(1, int(round(800 / max(img.shape[:2]))))
    if scale > 1:
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)

    def pixels(xy: F64) -> NDArray[np.int32]:
        return (grid.world_to_pixel(np.asarray(xy)[..., :2]) * scale + scale // 2).astype(np.int32)

    def polyline(poses: F64, colour: tuple[int, int, int]) -> None:
        cv2.polylines(img, [pixels(poses).reshape(-1, 1, 2)], False, colour, 1, cv2.LINE_AA)

    if ground_truth is not None:
        polyline(ground_truth, (60, 170, 60))
    polyline(trajectory, (40, 40, 220))
    start = pixels(trajectory[0])
    cv2.circle(img, (int(start[0]), int(start[1])), 4, (220, 120, 20), -1)
    if worst:
        _mark_worst(img, pixels, trajectory, times, worst)
    return img


def _mark_worst(
    img: NDArray[np.uint8],
    pixels: Callable[[F64], NDArray[np.int32]],
    trajectory: F64,
    times: F64 | None,
    worst: list[dict[str, Any]],
) -> None:
    """:func:`render_map`'s marks of the worst stretches (path, circle, label on top);
    ``pixels``: world ``(..., 2)`` to the picture's pixels."""
    import cv2

    from slam.eval.quality_run import draw_label

    unit = max(1, int(round(max(img.shape[:2]) / 1000)))  # line and letter size
    radius = 18 * unit
    for mark in worst:
        if times is not None:
            lo, hi = mark["log_time"]
            stretch = pixels(trajectory[(times >= lo) & (times <= hi)])
            if len(stretch) > 1:
                cv2.polylines(
                    img, [stretch.reshape(-1, 1, 2)], False, WORST_COLOUR, 2 * unit, cv2.LINE_AA
                )
        cx, cy = (int(v) for v in pixels(np.array(mark["place_xy"])))
        cv2.circle(img, (cx, cy), radius, (255, 255, 255), 3 * unit + 2, cv2.LINE_AA)
        cv2.circle(img, (cx, cy), radius, WORST_COLOUR, 2 * unit, cv2.LINE_AA)
    placed: list[tuple[int, int, int, int]] = []
    for mark in worst:  # labels last, on top of every mark
        cx, cy = (int(v) for v in pixels(np.array(mark["place_xy"])))
        a, b = mark["time_s"]
        score = mark["score"]
        text = f"#{mark['rank']} {a:.0f}-{b:.0f} s" + ("" if score is None else f"  {score:.2f}")
        org = (cx + radius + 6, cy + 5 * unit)
        draw_label(img, text, org, WORST_COLOUR, unit, placed, flip_gap=2 * radius + 12)


def _peak_rss_mb() -> float:
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)


def run(request: RunRequest) -> Path:
    """Run ``slam run`` end to end; return the run folder."""
    folder = execute(request).folder
    assert folder is not None
    return folder


def execute(request: RunRequest) -> Result:
    """Run ``slam run`` end to end; return the result (with its metrics and run folder).

    The run folder is assembled in a partial sibling from the start (so observers such as a
    recorder can write into it while the filter runs) and renamed into place only when every
    output is written (:func:`slam.io.atomic.atomic_dir`: ``--force`` replaces only a run folder
    of ``slam run`` that holds none of the run's inputs; a folder that appears meanwhile is
    never replaced).
    """
    config = request.config
    ref = sources.resolve(request.name, request.data_dir, where="slam run NAME")
    out = request.out or default_run_dir(ref.config_name)
    inputs = (*request.inputs, request.data_dir, ref.path)
    check_output_dir(out, "run", request.force, inputs)  # before loading anything
    wall_start, compiled = time.perf_counter(), compile_seconds()
    jit_background.start()  # the later stages' kernels compile while the log loads
    with (
        atomic_dir(out, overwrite=request.force, kind="run", inputs=inputs) as tmp,
        contextlib.ExitStack() as on_failure,  # runs before the partial folder is removed
    ):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            reach_stage("load")
            source = sources.load(ref, config, _needs(config), request.progress, request.bag)
            config = source.configured(config)  # a measured beam step: config.toml records it
            doubts = check_plausibility(source.log, config)  # time base, odometry jumps
            recorder = None
            if config.viz.record or request.viewer:  # rerun's import costs 0.5-1.3 s
                from slam.viz.recorder import start_recording

                recorder = start_recording(tmp, config, source.ground_truth, request.viewer)
            if recorder is not None:  # a failed run closes its recording before it goes
                on_failure.push(lambda kind, *_: recorder.abort() if kind is not None else None)
            observers = [recorder] if recorder is not None else []
            result = _estimate(source, config, request.progress, observers)
            release_free_memory()  # the filter's and the stages' freed blocks, before the outputs
            from slam.texture import run_stage

            reach_stage("texture")
            result.metrics.update(run_stage(source.log, result, config, tmp, request.progress))
            from slam.eval.quality_run import quality_stage

            reach_stage("quality")
            result.metrics.update(quality_stage(source.log, result.trajectory, config, tmp))
            release_free_memory()
        reach_stage("outputs")
        messages = doubts + sorted({str(w.message) for w in caught})
        clock = clock_warning(result.trajectory.times)
        messages += [clock] if clock else []
        messages += source.notes
        metrics = result.metrics
        metrics["warnings"] = messages
        if source.log.kind == "rosbag":  # what slam eval needs to read the same scans again
            metrics["bag_options"] = dataclasses.asdict(request.bag)
        _evaluate(result, source)
        write_text(tmp / "config.toml", dumps(config))
        write_trajectories(tmp, result.trajectory)  # sorted by time; file order if it differs
        if result.grid is not None:
            result.grid.save_npz(tmp / "map.npz")
            grid = result.grid
            write_map_files(tmp, grid.log_odds, grid.resolution, grid.origin)  # map_server, clean
            release_free_memory()  # the pictures' blocks, before map.png's three channels
            gt = None if source.ground_truth is None else source.ground_truth.poses
            worst = metrics.get("quality", {}).get("worst")  # the score's worst stretches, marked
            picture = render_map(result.grid, result.poses, gt, worst, result.trajectory.times)
            write_png(tmp / "map.png", picture)
            del picture
        if recorder is not None:  # last: the recording logs the texture when there is one
            release_free_memory()  # the pictures' blocks, before the final map's snapshot
            metrics["recording"] = recorder.finish(result.trajectory, result.grid, tmp)
        metrics["compile_s"] = round(compile_seconds() - compiled, 3)
        metrics["compile_background"] = jit_background.report()
        jit_background.stop()
        metrics["wall_s"] = round(time.perf_counter() - wall_start, 3)
        metrics["peak_rss_mb"] = _peak_rss_mb()
        write_text(tmp / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    for message in messages:
        print(f"slam: warning: {message}", file=sys.stderr, flush=True)
    result.folder = out
    return result


def _evaluate(result: Result, source: Source) -> None:
    """ATE and RPE against the dataset's ground truth, when it has one, into the metrics."""
    if source.ground_truth is not None:
        from slam.eval.trajectory import evaluate_against_reference

        ev = evaluate_against_reference(
            result.trajectory,
            source.ground_truth,
            estimate_name=f"{source.log.name} trajectory",
            reference_name=f"its ground truth ({sources.GROUND_TRUTH_FILE})",
        )
        result.metrics["ate_rmse"] = ev["ate_rmse"]
        result.metrics["ground_truth"] = ev


RUN_OPTIONS = {
    "method": "filter.method",
    "particles": "filter.particles",
    "every": "filter.every",
    "max_scans": "filter.max_scans",
}
"""Keyword options of :func:`run_dataset`, and the configuration key each one sets."""


def run_dataset(
    name: str,
    config: Config | None = None,
    *,
    seed: int | None = None,
    data_dir: Path | str | None = None,
    out: Path | str | None = None,
    force: bool = False,
    progress: bool = False,
    overrides: Sequence[str] = (),
    **options: Any,
) -> Result:
    """``slam.run``: run SLAM on a dataset in one call and return the :class:`~slam.online.Result`.

    ``name`` is a registry dataset, ``"demo"`` or a path to a log, as for ``slam run``; ``config``
    defaults to the dataset's (:func:`slam.config.load_config`); ``seed``, the ``options``
    (``method``, ``particles``, ``every``, ``max_scans``) and ``overrides`` (``"section.key=value"``
    strings, like ``--set``) change it. With ``out`` the run folder is written as ``slam run``
    writes it (recording and texture as configured); without, nothing is written and the result's
    ``metrics`` hold the sizes, timings and (with ground truth) the ATE.
    """
    from slam.io.datadir import resolve_data_dir

    if not isinstance(name, str | os.PathLike):
        raise UsageError(
            f"slam.run: expected a dataset name or a log's path, found {type(name).__name__} "
            "(to run your own arrays, feed them to slam.Slam scan by scan: docs/api.md)"
        )
    unknown = sorted(set(options) - set(RUN_OPTIONS))
    if unknown:
        raise UsageError(
            f"slam.run: unknown option(s) {', '.join(unknown)}; expected {', '.join(RUN_OPTIONS)}"
        )
    overrides = override_list(overrides)  # a str would be read character by character
    settings = [
        Override(
            f'{RUN_OPTIONS[key]}="{value}"'
            if isinstance(value, str)
            else f"{RUN_OPTIONS[key]}={value}",
            f"slam.run({key}={value!r})",
        )
        for key, value in options.items()
    ]
    if seed is not None:
        value = seed_value("slam.run", seed)
        settings.append(Override(f"filter.seed={value}", f"slam.run(seed={seed!r})"))
    folder = resolve_data_dir(None if data_dir is None else Path(data_dir))
    ref = sources.resolve(name, folder, where="slam.run")
    base = config if config is not None else dataset_config(ref)
    # "": the dataset's file is in base already (re-reading it would undo the caller's config)
    config = load_config("", None, [*settings, *overrides], base=base)
    if out is not None:
        request = RunRequest(name, config, folder, out=Path(out), force=force, progress=progress)
        return execute(request)
    source = sources.load(ref, config, _needs(config), progress)
    config = source.configured(config)
    doubts = check_plausibility(source.log, config)  # time base, odometry jumps
    result = _estimate(source, config, progress, [])
    result.metrics["warnings"] = doubts + list(source.notes)
    _evaluate(result, source)
    return result


def dataset_config(ref: sources.DatasetRef) -> Config:
    """The configuration of the dataset ``ref`` as ``slam run`` resolves it: its shipped
    ``configs/<name>.toml`` when one applies (never for a bag), the defaults otherwise; either
    way named after it."""
    import dataclasses

    if ref.shipped_config:
        return load_config(ref.config_name)
    return dataclasses.replace(load_config(""), dataset=ref.config_name)


def _estimate(source: Source, config: Config, progress: bool, observers: list[Observer]) -> Result:
    """Run the configured method; ``observers`` also watch the filter (with the progress bar)."""
    log = source.log
    method = config.filter.method
    base: dict[str, Any] = {"dataset": log.name, "method": method, "seed": config.filter.seed}
    if method == "odometry":
        return _dead_reckoning(log, config, base)

    from slam.observers import ProgressObserver
    from slam.online import Slam
    from slam.scans import LogScans

    scans = LogScans.from_log(log, config)
    if scans.odometry_sync is not None:
        base["odometry_sync"] = scans.odometry_sync.as_dict()
    base["odometry_source"] = scans.odometry_source
    if scans.laser_odometry is not None:
        base["laser_odometry"] = scans.laser_odometry
    if source.beam_geometry is not None:
        base["beam_geometry"] = source.beam_geometry
    beams = int(log.scans.ranges.shape[1])  # type: ignore[union-attr]
    _check_memory(
        log.name, len(scans), beams, scans.odometry, scans.range_max, config,
        scans.odometry_source == "laser",
    )  # fmt: skip
    bar = ProgressObserver(len(scans), enabled=progress, label=f"{log.name} {method}")
    start, compiled = time.perf_counter(), compile_seconds()
    try:
        with on_compile(bar.compiling):
            reach_stage("filter")
            slam = Slam(
                config, observers=[bar, *observers], scan_period=scans.scan_period(),
                odometry_source=scans.odometry_source,
            )  # fmt: skip
            for scan, odometry in scans:
                slam.update(scan, odometry=odometry)
            reach_stage("finish")  # loop closing, re-registration, final map
            result = slam.finish()
    finally:
        bar.close()
    compile_s = compile_seconds() - compiled  # numba compiling kernels: not the filter's time
    wall = time.perf_counter() - start - compile_s
    trajectory, grid = result.trajectory, result.grid
    duration = trajectory.duration() if len(trajectory) > 1 else 0.0
    assert grid is not None and result.n_eff is not None
    base.update(
        poses=len(trajectory),
        scans=len(scans),
        particles=config.filter.particles,
        duration_s=round(duration, 3),
        path_length_m=round(trajectory.path_length(), 3),
        estimate_wall_s=round(wall, 3),
        estimate_compile_s=round(compile_s, 3),
        estimate_parts_s={name: round(s, 3) for name, s in result.seconds.items()},
        scans_per_s=round(len(scans) / wall, 1) if wall > 0 else None,
        real_time_factor=round(duration / wall, 2) if wall > 0 else None,
        n_eff_mean=round(float(result.n_eff.mean()), 2),
        n_eff_min=round(float(result.n_eff.min()), 2),
        resampling_count=int(result.stats.get("resamples", 0)),
        filter=result.stats,
        map_shape=list(grid.shape),
        map_resolution=grid.resolution,
        map_origin=[float(v) for v in grid.origin],
    )
    result.metrics = base
    return result


def _check_memory(
    name: str,
    scans: int,
    beams: int,
    poses: F64,
    range_max: float,
    config: Config,
    laser_odometry: bool = False,
) -> None:
    """Refuse, before the maps are allocated, a run that would not fit in memory even with maps
    of their smallest size; the message names the odometry's extent, which sets the maps' size
    (with ``laser_odometry``, that it may have run away where scans fitted nowhere).

    Maps over the whole of the odometry's extent may not fit where the run would: a drifting
    odometry spans more than the map will (mit-killian's 599 × 521 m for a 275 × 216 m map,
    4.4 GiB estimated where the run peaks at 0.7 GiB). That is one :class:`DataWarning`, and
    the run goes on: the maps grow as the trajectory needs, and a growth past the same limit is
    an error then (:func:`slam.mapping._check_growth`, within :func:`slam.budget.growth_share`)."""
    from slam.budget import check_run_memory, format_bytes, memory_limit, run_memory
    from slam.io.plausibility import DataWarning

    span = poses[:, :2].max(axis=0) - poses[:, :2].min(axis=0)
    components = run_memory(config, scans, beams, float(span[0]), float(span[1]), range_max)
    extent = f"{name} (its odometry spans {span[0]:.1f} m × {span[1]:.1f} m"
    if laser_odometry:
        extent += (
            "; laser odometry that fits no scan for a while can run away: "
            'docs/slam.md, "A robot without odometry"'
        )
    share = config.checks.max_memory_share
    total, limit = sum(components.values()), memory_limit(share)
    if total <= limit:
        return
    smallest = run_memory(config, scans, beams, 0.0, 0.0, range_max)
    check_run_memory(f"{extent}; with maps of their smallest size)", smallest, config)
    warnings.warn(
        f"{extent}): maps over all of it would need about {format_bytes(total)}, more than the "
        f"limit of {format_bytes(limit)} (checks.max_memory_share); going on: the maps grow only "
        "as far as the trajectory needs (a drifting odometry spans more), and a map whose growth "
        "alone would pass the limit stops the run",
        DataWarning,
        stacklevel=2,
    )


def _up_to_scan(trajectory: Trajectory, log: Log, last: int) -> Trajectory:
    """``trajectory`` (from :func:`slam.odometry.odometry_trajectory`) cut after scan ``last``:
    one pose per scan (CARMEN) keeps the first ``last + 1``; encoder-rate poses (ECE276A) keep
    those up to that scan's time."""
    from slam.trajectory import Trajectory

    if log.encoders is None:
        return Trajectory(trajectory.times[: last + 1], trajectory.poses[: last + 1])
    keep = trajectory.times <= log.scans.time[last]  # type: ignore[union-attr]
    return Trajectory(trajectory.times[keep], trajectory.poses[keep])


def _dead_reckoning(log: Log, config: Config, base: dict[str, Any]) -> Result:
    """``method = "odometry"``: the odometry trajectory at its natural rate (a log without
    odometry: its laser odometry, one pose per scan), and the map of the scans at their odometry
    poses."""
    from slam.odometry import odometry_trajectory
    from slam.online import Result
    from slam.scans import LogScans, ScanSequence
    from slam.stages import build_map
    from slam.trajectory import Trajectory

    start = time.perf_counter()
    grid = None
    if log.scans is None:
        trajectory = odometry_trajectory(log, config.robot)
    else:
        scans = LogScans.from_log(log, config)
        seq = ScanSequence.from_scans(scans)
        base["odometry_source"] = scans.odometry_source
        if scans.odometry_source == "laser":  # no odometry of the log's: the laser's, per scan
            trajectory = Trajectory(scans.times, scans.odometry)
        else:
            trajectory = odometry_trajectory(log, config.robot)
        if config.filter.max_scans:  # the trajectory ends with the last scan the run processes
            trajectory = _up_to_scan(trajectory, log, int(seq.indices[-1]))
        reach = float(seq.scan(0).range_max)  # type: ignore[arg-type]
        _check_memory(log.name, len(seq), seq.num_beams, seq.odometry, reach, config)
        with growth_share(config.checks.max_memory_share):  # as Slam's maps are checked
            grid = build_map(seq, seq.odometry, np.arange(len(seq)), config)
    wall = time.perf_counter() - start
    base.update(
        poses=len(trajectory),
        duration_s=round(trajectory.duration(), 3),
        path_length_m=round(trajectory.path_length(), 3),
        estimate_wall_s=round(wall, 3),
    )
    return Result(trajectory, grid, metrics=base)
