"""``slam localize``: localize a recorded log on a saved map and write a run folder.

:func:`localize` loads the map (a ``slam run`` folder or ``map.npz``) and the log, feeds every
selected scan to a :class:`~slam.localize.localizer.Localizer` and writes, atomically (the folder
appears complete or not at all):

* ``trajectory.tum`` — one pose per scan (also while not localized: then the global filter's
  best state, or the tracked pose during a recovery), sorted by time as ``slam run`` writes it
  (:func:`slam.io.exports.write_trajectories`), and ``trajectory_file_order.tum`` in the log's
  order when its clock runs backwards (intel);
* ``localization.npz`` — per scan: ``times``, ``poses``, ``covariances (N, 3, 3)``,
  ``localized``, ``phase`` (0 global, 1 tracking, 2 recovering), ``particles``, ``quality``;
* ``map.png`` — the map with the path; ``recording.rrd`` — the map, the particles and the
  histogram posterior as a heat map (:mod:`slam.viz.localize`), unless ``viz.record`` is off;
* ``metrics.json`` — time to convergence (and distance driven, histogram steps), share of time
  localized, mean match quality, particles used, lost / re-localization counts, speed (wall and
  CPU time, real-time factor), memory;
* ``config.toml`` — the configuration used.

An ``initial`` pose outside the map, or with no known-free cell within its sigma, is refused
before anything is read (:func:`check_initial`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import Config, dumps
from slam.errors import UsageError
from slam.io.atomic import atomic_dir, write_npz, write_text
from slam.io.exports import clock_warning, time_order, write_trajectories
from slam.localize.localizer import PHASES, Localizer
from slam.localize.maps import LikelihoodMap, load_map
from slam.scans import LogScans, Scan
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]


@dataclass
class LocalizeRequest:
    """Everything ``slam localize`` was asked to do."""

    name: str
    """The log: a dataset name of the registry, ``demo``, or a path."""
    map_path: Path
    """A ``slam run`` folder or a ``map.npz`` file."""
    config: Config
    data_dir: Path
    initial: tuple[float, ...] | None = None
    """``(x, y, θ)`` or ``(x, y, θ, σ)``; ``None``: global localization."""
    out: Path | None = None
    force: bool = False
    """Replace an existing localization folder (only one of ``slam localize``)."""
    inputs: tuple[Path, ...] = ()
    """Further files the run reads (the ``--config`` file): ``out`` may not hold them."""
    progress: bool = False


@dataclass
class LocalizationTrace:
    """Per-scan results of a localization run."""

    times: F64
    poses: F64
    covariances: F64
    localized: NDArray[np.bool_]
    phase: NDArray[np.int8]
    particles: NDArray[np.int32]
    quality: F64
    updated: NDArray[np.bool_]
    lost: NDArray[np.bool_]


LOW_LOCALIZED_SHARE = 0.5
"""A run localized on fewer of its scans than this share is warned about: the map may be of
another building, or the start pose wrong ..."""

LOW_MATCH_QUALITY = 0.3
"""... and so is one whose mean match quality is below this (intel, aces and fr079 on their
own maps: 0.80–0.94; aces on intel's map 0.08), however localized its particles say it is."""


def map_doubt(metrics: dict[str, Any], map_path: Path | str) -> str | None:
    """The warning of a run that never converged, that stayed localized on few of its scans
    after it first converged (:data:`LOW_LOCALIZED_SHARE`; a global localization takes a while
    to converge, which is no doubt) or whose scans fit the map poorly (:data:`LOW_MATCH_QUALITY`),
    else ``None``."""
    share, quality = metrics["localized_share_after_convergence"], metrics["mean_match_quality"]
    if share >= LOW_LOCALIZED_SHARE and quality is not None and quality >= LOW_MATCH_QUALITY:
        return None
    shown = "none" if quality is None else f"{quality:.2f}"
    where = "after it first converged" if metrics["converged"] else "(it never converged)"
    return (
        f"localized on {100 * share:.1f} % of the scans {where}, with a mean match quality of "
        f"{shown} (on its own building's map a log scores 0.8–0.94): is {map_path} a map of this "
        "log's building, and the start pose right?"
    )


def parse_initial(text: str) -> tuple[float, ...]:
    """``"x,y,theta[,sigma]"`` as numbers (``UsageError`` naming what was wrong)."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (3, 4):
        raise UsageError(
            f"--initial {text!r}: expected x,y,theta or x,y,theta,sigma (metres, radians), "
            f"found {len(parts)} values"
        )
    values = []
    for name, part in zip(("x", "y", "theta", "sigma"), parts, strict=False):
        try:
            value = float(part)
        except ValueError:
            raise UsageError(
                f"--initial {text!r}: {name} must be a number, found {part!r}"
            ) from None
        if not math.isfinite(value):
            raise UsageError(f"--initial {text!r}: {name} must be finite, found {part!r}")
        values.append(value)
    if len(values) == 4 and not values[3] > 0:
        raise UsageError(f"--initial {text!r}: sigma must be > 0 m, found {parts[3]!r}")
    if abs(values[2]) > 2 * math.pi:
        raise UsageError(
            f"--initial {text!r}: theta must be radians within ±2π, found {parts[2]} (degrees? "
            f"{math.radians(values[2]):.4g} rad)"
        )
    return tuple(values)


def format_initial(initial: Sequence[float]) -> str:
    """``initial`` as ``--initial`` takes it (``x,y,theta[,sigma]``)."""
    return ",".join(f"{v:g}" for v in initial)


def check_initial(lmap: LikelihoodMap, initial: Sequence[float], sigma_xy: float) -> None:
    """Refuse (``UsageError``, one line naming ``--initial``, the pose and the map's extent) an
    initial pose ``(x, y, θ[, σ])`` outside ``lmap`` or with no known-free cell of the map within
    ``σ`` (``sigma_xy`` when ``initial`` has none) of ``(x, y)``: the particles drawn around it
    could never match a scan, and the run would end with nothing localized."""
    x, y = float(initial[0]), float(initial[1])
    sigma = float(initial[3]) if len(initial) > 3 else float(sigma_xy)
    res = lmap.resolution
    (x0, y0), (rows, cols) = lmap.origin, lmap.shape
    x1, y1 = x0 + cols * res, y0 + rows * res
    extent = f"x {x0:.2f} to {x1:.2f} m, y {y0:.2f} to {y1:.2f} m"
    head = f"--initial {format_initial(initial)!r}: the pose ({x:g}, {y:g})"
    if not (x0 <= x <= x1 and y0 <= y <= y1):
        raise UsageError(
            f"{head} lies outside the map ({extent}): expected a pose in the map's frame, "
            "or --global"
        )
    ix, dx = _cells_within(x, x0, res, sigma, cols)
    iy, dy = _cells_within(y, y0, res, sigma, rows)
    near = dy[:, None] ** 2 + dx[None, :] ** 2 <= sigma**2
    if not np.any(lmap.free[np.ix_(iy, ix)] & near):
        raise UsageError(
            f"{head} has no known-free cell of the map within {sigma:g} m (its sigma); the map "
            f"spans {extent}: expected a pose in its free space, or --global"
        )


def _cells_within(
    c: float, lo: float, res: float, sigma: float, count: int
) -> tuple[NDArray[np.int64], F64]:
    """Along one axis of a grid starting at ``lo`` (cells of ``res``, ``count`` of them): the
    cells within ``sigma`` of ``c`` and the distance from ``c`` to each (0 in its own cell)."""
    first = max(math.floor((c - sigma - lo) / res), 0)
    last = min(math.floor((c + sigma - lo) / res), count - 1)
    cells = np.arange(first, last + 1, dtype=np.int64)
    gap = np.maximum(np.maximum(lo + cells * res - c, c - (lo + (cells + 1) * res)), 0.0)
    return cells, gap


def run_localizer(
    localizer: Localizer,
    scans: Sequence[tuple[Scan, F64]],
    recorder: Any = None,
    progress: bool = False,
) -> LocalizationTrace:
    """Feed ``(scan, odometry pose)`` pairs (a :class:`slam.scans.LogScans`, or a list such as
    :func:`splice` makes) to ``localizer``; return the per-scan trace."""
    n = len(scans)
    times = np.empty(n)
    poses = np.empty((n, 3))
    cov = np.empty((n, 3, 3))
    localized = np.zeros(n, dtype=bool)
    phase = np.zeros(n, dtype=np.int8)
    particles = np.zeros(n, dtype=np.int32)
    quality = np.full(n, np.nan)
    updated = np.zeros(n, dtype=bool)
    lost = np.zeros(n, dtype=bool)
    detail = recorder.config.detail_every if recorder is not None else 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, desc="localize", unit="scan", dynamic_ncols=True, mininterval=0.25)
    for i, (scan, odometry) in enumerate(scans):
        steps_before = localizer.counters["histogram_steps"]
        est = localizer.update(scan, odometry)
        times[i] = est.time
        poses[i], cov[i] = est.pose, est.covariance
        localized[i], phase[i] = est.localized, PHASES.index(est.phase)
        particles[i], quality[i] = est.particles, est.quality
        updated[i], lost[i] = est.updated, est.lost
        if recorder is not None:
            show = detail and i % detail == 0 and est.particles > 0
            stepped = localizer.counters["histogram_steps"] != steps_before
            recorder.on_step(
                i, est.time, est.pose, est.particles, est.quality, est.localized,
                localizer.particles.poses if show else None,
                localizer.particles.weights if show else None,
                localizer.histogram if stepped else None,
            )  # fmt: skip
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return LocalizationTrace(times, poses, cov, localized, phase, particles, quality, updated, lost)


def trace_metrics(trace: LocalizationTrace, odometry: F64) -> dict[str, Any]:
    """Convergence, localized share, quality and particle figures of a trace (``odometry`` the
    ``(N, 3)`` odometry poses of the same scans, for the distance driven)."""
    times = trace.times
    n = times.shape[0]
    steps = np.hypot(*np.diff(odometry[:, :2], axis=0).T) if n > 1 else np.zeros(0)
    driven = np.concatenate([[0.0], np.cumsum(steps)])
    first = int(np.argmax(trace.localized)) if trace.localized.any() else -1
    duration = float(times.max() - times.min()) if n > 1 else 0.0
    # in time order: where the clock runs backwards (intel), file order counts its steps twice
    order = time_order(times)
    gaps = np.diff(times[order])
    localized_time = float(np.sum(gaps[trace.localized[order][:-1]])) if n > 1 else 0.0
    tracking = trace.particles > 0
    quality = trace.quality[trace.updated & np.isfinite(trace.quality)]
    out: dict[str, Any] = {
        "scans": int(n),
        "duration_s": round(duration, 3),
        "converged": first >= 0,
        # the span of the log's clock the localizer had seen when it converged (file order)
        "time_to_convergence_s": round(float(np.ptp(times[: first + 1])), 3)
        if first >= 0
        else None,
        "distance_to_convergence_m": round(float(driven[first]), 3) if first >= 0 else None,
        "localized_share": round(float(trace.localized.mean()), 4) if n else 0.0,
        "localized_share_after_convergence": (
            round(float(trace.localized[first:].mean()), 4) if first >= 0 else 0.0
        ),
        "localized_time_s": round(localized_time, 3),
        "mean_match_quality": round(float(quality.mean()), 4) if quality.size else None,
        "particles_mean": round(float(trace.particles[tracking].mean()), 1)
        if tracking.any()
        else 0,
        "particles_max": int(trace.particles.max()) if n else 0,
        "lost_events": int(trace.lost.sum()),
        "path_length_m": round(float(driven[-1]) if n else 0.0, 3),
    }
    return out


def write_trace(folder: Path, trace: LocalizationTrace) -> None:
    """``trajectory.tum`` sorted by time, ``trajectory_file_order.tum`` when the clock runs
    backwards (both as ``slam run`` writes them) and ``localization.npz`` (file order) of
    ``trace`` into ``folder``."""
    write_trajectories(folder, Trajectory(trace.times, trace.poses))
    arrays = {"times": trace.times, "poses": trace.poses, "covariances": trace.covariances,
              "localized": trace.localized, "phase": trace.phase,
              "particles": trace.particles, "quality": trace.quality}  # fmt: skip
    write_npz(folder / "localization.npz", arrays)


def splice(
    scans: LogScans, first: tuple[int, int], second: tuple[int, int]
) -> list[tuple[Scan, F64]]:
    """A kidnapping: selected scans ``first[0]:first[1]`` of ``scans``, then
    ``second[0]:second[1]``, the second stretch's times shifted to follow the first by one scan
    period and its odometry moved to continue the first's (the wheels do not notice the jump;
    the laser does)."""
    from slam.geometry import compose, relative

    a = range(*first)
    b = range(*second)
    if len(a) == 0 or len(b) == 0 or b.start < 1:
        raise UsageError(f"splice: expected two non-empty stretches, found {first} and {second}")
    times = scans.times
    shift = times[a[-1]] + scans.scan_period() - times[b[0]]
    odometry = compose(
        scans.odometry[a[-1]], relative(scans.odometry[b[0] - 1], scans.odometry[list(b)])
    )
    out = [(scans.scan(i), scans.odometry[i]) for i in a]
    for j, i in enumerate(b):
        scan = scans.scan(i)
        out.append((dataclasses.replace(scan, time=scan.time + shift), odometry[j]))
    return out


def localize(request: LocalizeRequest) -> Path:
    """Run ``slam localize`` end to end; return the run folder."""
    from slam.io import sources
    from slam.io.atomic import check_output_dir, write_png
    from slam.io.plausibility import check_plausibility
    from slam.pipeline import _needs, _peak_rss_mb, default_run_dir, render_map

    config = request.config
    ref = sources.resolve(request.name, request.data_dir, where="slam localize LOG")
    out = request.out or default_run_dir(f"{ref.config_name}-localize")
    inputs = (*request.inputs, request.data_dir, ref.path, request.map_path)
    check_output_dir(out, "localize", request.force, inputs)  # before loading anything
    lmap: LikelihoodMap = load_map(request.map_path)
    localizer = Localizer(lmap, config, initial=request.initial)
    if request.initial is not None:  # before the log is read
        check_initial(lmap, request.initial, config.localize.initial_sigma_xy)
    with atomic_dir(out, overwrite=request.force, kind="localize", inputs=inputs) as tmp:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            source = sources.load(ref, config, _needs(config), request.progress)
            config = source.configured(config)
            doubts = check_plausibility(source.log, config)
            scans = LogScans.from_log(source.log, config)
        messages = doubts + sorted({str(w.message) for w in caught})
        recorder = None
        if config.viz.record:
            from slam.viz.localize import LocalizeRecorder

            recorder = LocalizeRecorder(
                tmp / "recording.rrd", config.viz, lmap, f"slam localize {source.log.name}"
            )
        wall0, cpu0 = time.perf_counter(), time.process_time()
        trace = run_localizer(localizer, scans, recorder=recorder, progress=request.progress)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        metrics: dict[str, Any] = {
            "dataset": source.log.name,
            "map": os.path.abspath(request.map_path),
            "mode": "global" if request.initial is None else "initial pose",
            "initial": None if request.initial is None else list(request.initial),
            "seed": config.filter.seed,
        }
        metrics.update(trace_metrics(trace, scans.odometry))
        metrics.update(
            histogram_steps=localizer.counters["histogram_steps"],
            mcl_updates=localizer.counters["mcl_updates"],
            relocalizations=localizer.counters["reseeds"],
            false_alarms=localizer.counters["false_alarms"],
            estimate_wall_s=round(wall, 3),
            estimate_cpu_s=round(cpu, 3),
            scans_per_s=round(len(trace.times) / wall, 1) if wall > 0 else None,
            real_time_factor=round(metrics["duration_s"] / wall, 2) if wall > 0 else None,
            map_shape=list(lmap.shape),
            map_resolution=lmap.resolution,
            map_memory_mb=round(lmap.memory_bytes() / 2**20, 2),
        )
        if localizer.counters["histogram_steps"]:
            hist = localizer.histogram
            metrics["histogram"] = {
                "resolution": hist.resolution,
                "headings": hist.headings,
                "states": hist.state_count,
                "memory_mb": round(hist.memory_bytes() / 2**20, 2),
            }
        clock = clock_warning(trace.times)
        messages += [clock] if clock else []
        doubt = map_doubt(metrics, request.map_path)
        messages += [doubt] if doubt else []
        metrics["warnings"] = messages
        write_text(tmp / "config.toml", dumps(config))
        write_trace(tmp, trace)
        write_png(tmp / "map.png", render_map(lmap.grid, trace.poses))
        if recorder is not None:
            metrics["recording"] = recorder.finish(trace.poses)
        metrics["peak_rss_mb"] = _peak_rss_mb()
        write_text(tmp / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    for message in messages:
        print(f"slam: warning: {message}", file=sys.stderr, flush=True)
    return out
