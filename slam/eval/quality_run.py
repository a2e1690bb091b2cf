"""Map quality of a run folder: re-read its log, score it, print it, draw ``quality.png``.

The metric itself is :mod:`slam.eval.quality` (pure); this module owns what surrounds it:

* :func:`resolve_run_log` finds the log a run folder came from (``demo``, a registry dataset,
  or the file/folder path :func:`quality_stage` recorded in ``metrics.json`` as
  ``log_source``), and :func:`evaluate_run` re-reads its scans through
  :mod:`slam.io.sources`, as ``slam run`` does;
* :func:`quality_stage` scores a run at the end of ``slam run`` (``quality.enabled``);
* :func:`render_quality` draws ``quality.png``; :func:`format_quality` the printed table.
"""

from __future__ import annotations

import io
import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from slam.config import Config, load_config
from slam.errors import DataError, SlamError
from slam.eval.quality import QualityResult, Rays, map_quality, scan_rays, select_scans, summary
from slam.io.atomic import write_png
from slam.io.log import Log, ScanStream

if TYPE_CHECKING:
    from slam.io.registry import Dataset
    from slam.io.rosbag import BagOptions
    from slam.io.sources import DatasetRef
    from slam.trajectory import Trajectory

F64 = NDArray[np.float64]

PICTURE = "quality.png"
"""The picture :func:`evaluate_run` and :func:`quality_stage` write into the run folder."""
PICTURE_MIN_SIDE = 1200
"""The picture's long side is at least this many pixels (small maps are enlarged) ..."""
PICTURE_MAX_SIDE = 3000
"""... and at most this many (big buildings are reduced)."""
MAX_DRAWN_CONFLICTS = 300_000
"""Conflicting endpoints drawn at most (evenly thinned beyond)."""


def rays_of(scans: ScanStream, config: Config) -> tuple[F64, Rays]:
    """Times and rays of the scans a run with ``config`` processed (``filter.every``,
    ``filter.max_scans``; the lidar's range semantics as :class:`ScanSequence` resolves them)."""
    idx = select_scans(len(scans), config.filter.every, config.filter.max_scans)
    # the same scans as a slice: a view of the log's ranges (scan_rays reads them a block at a
    # time), not a copy of them
    rows = slice(0, int(idx[-1]) + 1 if idx.size else 0, max(int(config.filter.every), 1))
    lidar = config.lidar
    range_max = lidar.range_max if lidar.range_max is not None else scans.range_max
    no_return = lidar.no_return if lidar.no_return is not None else scans.no_return
    range_min = lidar.range_min if lidar.range_min is not None else scans.range_min
    angles = scans.angles if scans.angles.ndim == 1 else scans.angles[rows]
    rays = scan_rays(
        scans.ranges[rows], angles, scans.laser_offset, range_min, range_max, no_return,
        config.map.free_range_no_return,
    )  # fmt: skip
    return np.asarray(scans.time[idx], dtype=np.float64), rays


def poses_at_scans(
    traj_times: F64, traj_poses: F64, scan_times: F64, where: Path
) -> tuple[F64, NDArray[np.bool_]]:
    """Robot pose at each scan: the trajectory's rows themselves when they are one per scan (the
    times agree to 1e-5 s), else interpolated at the scan times (``odometry`` runs on ECE276A
    logs write one pose per encoder reading). Returns the poses and which scans have one."""
    if traj_times.shape == scan_times.shape and np.all(np.abs(traj_times - scan_times) <= 1e-5):
        return traj_poses, np.ones(scan_times.shape, dtype=bool)
    from slam.geometry import interpolate_poses

    order = np.argsort(traj_times, kind="stable")
    t, p = traj_times[order], traj_poses[order]
    inside = (scan_times >= t[0]) & (scan_times <= t[-1])
    if not inside.any():
        raise DataError(
            f"{where}: its {t.size} poses ({t[0]:.3f}..{t[-1]:.3f} s) cover none of the log's "
            f"{scan_times.size} scans ({scan_times.min():.3f}..{scan_times.max():.3f} s): "
            "is it the same log?"
        )
    return interpolate_poses(t, p, scan_times[inside]), inside


def resolve_run_log(run_dir: Path, data_dir: Path, dataset: str | None = None) -> DatasetRef:
    """The log ``run_dir`` was made from, resolved by :func:`slam.io.sources.resolve`.

    ``dataset`` (a registry name, ``demo`` or a path) wins. Else, for a run of a registry
    dataset (its ``config.toml``'s ``dataset`` is a registry name, and the ``log_source`` it
    recorded in ``metrics.json``, if it still exists, is where the registry keeps that dataset),
    that dataset: an ECE276A dataset's ``log_source`` is the folder it shares with the course's
    other datasets, which names none of them. Else the ``log_source``, exactly what the run read
    (a run made from a path records only the file's stem as its ``dataset``, which may be a
    registry name: ``slam run elsewhere/intel.clf`` is re-read from there). Else the
    ``dataset`` (``demo``). A registry dataset is read from ``data_dir``, or from the data
    directory the run read it from when its scans are only there
    (:func:`registry_run_data_dir`). A recorded log that is no longer there is a
    :class:`DataError`, unless that ``dataset`` is ``demo`` or a registry name.
    """
    from slam.io import registry, sources

    run_dir = Path(run_dir)
    config = _run_config(run_dir)
    if dataset is not None:
        return sources.resolve(dataset, data_dir, where="--dataset")
    name = config.dataset
    where = f"{run_dir / 'config.toml'}: dataset"
    recorded = recorded_source(run_dir)
    found = recorded is not None and recorded.exists()
    datasets = registry.load_registry()
    if name in datasets:
        entry = datasets[name]
        read_from = None if recorded is None else registry_run_data_dir(entry, recorded)
        if not found or read_from is not None:  # a run of the registry's dataset
            return sources.resolve(name, _holding_scans(entry, data_dir, read_from), where=where)
    elif name == "demo" and not found:  # found: the demo's folder, or a path named demo
        return sources.resolve(name, data_dir, where=where)
    if found:
        return sources.resolve(
            str(recorded), data_dir, where=f"{run_dir / 'metrics.json'}: log_source"
        )
    if recorded is not None:
        raise DataError(
            f"{run_dir / 'metrics.json'}: log_source {recorded} no longer exists (the log this "
            "run was made from); give the log with --dataset PATH"
        )
    return sources.resolve(
        name, data_dir, where=where, hint="the run recorded no log_source; give --dataset PATH"
    )


def registry_run_data_dir(entry: Dataset, recorded: Path) -> Path | None:
    """The data directory a run of the registry dataset ``entry`` read it from, known by the
    ``log_source`` it recorded (``recorded``: ``<data dir>/ece276a`` for dataset20,
    ``<data dir>/carmen/intel.clf.gz`` for intel); ``None`` when ``recorded`` is not where the
    registry keeps the dataset (a run made from a path whose stem is the dataset's name)."""
    scans = entry.file_for("scans")
    if scans is None:
        return None
    relative = Path(entry.folder if entry.loader == "ece276a" else scans.path).parts
    if len(recorded.parts) <= len(relative) or recorded.parts[-len(relative) :] != relative:
        return None
    return Path(*recorded.parts[: -len(relative)])


def _holding_scans(entry: Dataset, data_dir: Path, other: Path | None) -> Path:
    """``data_dir``, unless the scans of the registry dataset ``entry`` are missing there and
    present under ``other`` (a run made with another ``--data-dir``)."""
    scans = entry.file_for("scans")
    if other is None or scans is None or scans.location(data_dir).exists():
        return data_dir
    return other if scans.location(other).exists() else data_dir


def _run_config(run_dir: Path) -> Config:
    path = run_dir / "config.toml"
    if not path.is_file():
        raise DataError(
            f"{path}: not found (the map-quality score needs the configuration `slam run` "
            "writes to its run folder, to re-read the log)"
        )
    return load_config("", path)


def _recorded(run_dir: Path, key: str) -> Any:
    """``key`` of the run's ``metrics.json`` (``None`` without the file or the key); a file that
    is not a JSON object is one :class:`DataError` naming it (before, it was taken for a run
    that recorded nothing, and the message blamed the dataset)."""
    path = run_dir / "metrics.json"
    if not path.is_file():
        return None
    try:
        metrics = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else str(exc).splitlines()[0]
        message = f"{path}: expected the run's metrics as JSON, cannot read it ({reason})"
        raise DataError(message) from None
    if not isinstance(metrics, dict):
        raise DataError(f"{path}: expected a JSON object, found {type(metrics).__name__}")
    return metrics.get(key)


def recorded_source(run_dir: Path) -> Path | None:
    """The ``log_source`` a run recorded in its ``metrics.json`` (``None`` when absent)."""
    value = _recorded(run_dir, "log_source")
    return Path(value) if isinstance(value, str) and value else None


def recorded_bag_options(run_dir: Path) -> BagOptions | None:
    """The bag options (``--scan-topic``, ``--odom-topic``, ``--base-frame``, ``--odom-sync``)
    a run of a ROS bag recorded in its ``metrics.json``, so that its scans are read again as the
    run read them (``None``: not a bag's run, or recorded before the options were)."""
    from slam.io.rosbag import BagOptions

    path = run_dir / "metrics.json"
    value = _recorded(run_dir, "bag_options")
    if not isinstance(value, dict):
        return None
    try:
        return BagOptions(**value)
    except (TypeError, ValueError, SlamError) as exc:
        raise DataError(f"{path}: bag_options: {exc}") from None


def score_scans(
    trajectory: Trajectory, scans: ScanStream, config: Config, where: Path
) -> QualityResult:
    """Score ``trajectory`` with the scans of its log."""
    scan_times, rays = rays_of(scans, config)
    poses, inside = poses_at_scans(trajectory.times, trajectory.poses, scan_times, where)
    if not inside.all():
        rays = Rays(rays.ex[inside], rays.ey[inside], rays.kind[inside], rays.laser_xy)
        scan_times = scan_times[inside]
    return map_quality(scan_times, poses, rays, config.quality, config.map, own_rays=True)


def evaluate_run(
    run_dir: Path, log: DatasetRef, trajectory: Trajectory | None = None
) -> tuple[dict[str, Any], QualityResult]:
    """Score the run folder ``run_dir`` (its ``trajectory.tum``, or ``trajectory`` when given,
    and its ``config.toml``) with the scans of ``log``; return the JSON summary and the result.
    Writes nothing."""
    from slam.io import sources
    from slam.io.tum import read_tum

    run_dir = Path(run_dir)
    config = _run_config(run_dir)
    if trajectory is None:
        trajectory = read_tum(run_dir / "trajectory.tum")
    bag = recorded_bag_options(run_dir) if log.kind is sources.Kind.BAG else None
    scans = sources.load(log, config, need=("scans",), bag=bag).log.scans
    if scans is None or len(scans) == 0:
        raise DataError(f"{log.path}: the log has no laser scans to score the map with")
    result = score_scans(trajectory, scans, config, run_dir / "trajectory.tum")
    return summary(result), result


def quality_stage(log: Log, trajectory: Trajectory, config: Config, out_dir: Path) -> dict:
    """The end of ``slam run``: score the run's map when ``quality.enabled`` and the log has
    scans, write ``quality.png``; return the metrics to add (``quality``, and ``log_source``, so
    that ``slam eval`` can find the log of a run made from a path). A score that cannot be
    computed is a warning, never a failed run."""
    import warnings

    metrics: dict[str, Any] = {}
    if log.source is not None:  # absolute, links kept: a data directory reached through a link
        metrics["log_source"] = os.path.abspath(log.source)  # still names the dataset's place
    if not config.quality.enabled or log.scans is None or len(trajectory) == 0:
        return metrics
    try:
        result = score_scans(as_written(trajectory), log.scans, config, out_dir / "trajectory.tum")
    except DataError as exc:
        warnings.warn(f"map quality not computed: {exc}", stacklevel=2)
        return metrics
    report = summary(result)
    report.pop("per_stretch")  # metrics.json stays small; `slam eval` lists every stretch
    write_png(out_dir / PICTURE, render_quality(result))
    report["picture"] = PICTURE
    metrics["quality"] = report
    doubt = low_score_warning(report, config.quality.warn_below)
    if doubt:
        warnings.warn(doubt, stacklevel=2)
    return metrics


def low_score_warning(report: dict[str, Any], warn_below: float) -> str | None:
    """The warning ``slam run`` gives when its map's score (``report``, :func:`summary`'s) is
    below ``warn_below`` (``quality.warn_below``; 0: never), naming the worst stretches' times;
    ``None`` otherwise (also when nothing could be judged)."""
    score = report.get("score")
    if score is None or not math.isfinite(score) or score >= warn_below:
        return None
    worst = ", ".join(f"{w['time_s'][0]:.0f}-{w['time_s'][1]:.0f} s" for w in report["worst"][:3])
    where = f"; the worst stretches at {worst} (marked on map.png and {PICTURE})" if worst else ""
    return (
        f"map quality {score:.3f} is below quality.warn_below = {warn_below:g}: stretches of the "
        "map contradict each other (a loop left open or closed wrongly, or the filter lost track)"
        f"{where}; `slam eval RUN` ranks the stretches (docs/evaluation.md), and "
        "docs/troubleshooting.md says what to check"
    )


def as_written(trajectory: Trajectory) -> Trajectory:
    """The trajectory as ``trajectory.tum`` holds it (microseconds and micrometres, the heading
    through its quaternion), so the score ``slam run`` writes equals what ``slam eval`` finds."""
    from slam.geometry import quaternion_to_yaw
    from slam.io.tum import format_tum
    from slam.trajectory import Trajectory

    data = np.loadtxt(io.StringIO(format_tum(trajectory)), comments="#", ndmin=2)
    poses = np.stack([data[:, 1], data[:, 2], quaternion_to_yaw(data[:, 4:8])], 1)
    return Trajectory(data[:, 0], poses)


def score_colour(score: float) -> tuple[int, int, int]:
    """BGR colour of a stretch score: green at 1, yellow at 0.9, red at 0.6 and below; grey
    when the stretch was not judged."""
    if not math.isfinite(score):
        return (170, 150, 150)
    u = min(max((score - 0.6) / 0.4, 0.0), 1.0)
    if u >= 0.75:  # 0.9 .. 1: yellow to green
        f = (u - 0.75) / 0.25
        return (0, 230, int(round(255 * (1 - f))))
    f = u / 0.75  # 0.6 .. 0.9: red to yellow
    return (0, int(round(230 * f)), 255)


def render_quality(result: QualityResult) -> NDArray[np.uint8]:
    """``quality.png``: the run's map (grey), the conflicting endpoints (red dots), the path
    coloured by each stretch's score, the worst stretches circled and labelled with their times
    and scores, and a legend. The long side is 1200–3000 px.

    Long because it is one drawing, step by step (map, dots, path, marks, legend); splitting it
    would only pass the same dozen local values between helpers.
    """
    import cv2

    from slam.eval.quality import UNSEEN_SHADE

    shades = result.shades
    seen = shades != UNSEEN_SHADE
    rows = np.flatnonzero(seen.any(axis=1))
    cols = np.flatnonzero(seen.any(axis=0))
    pad = int(math.ceil(1.0 / result.resolution))
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, seen.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, seen.shape[1])
    del seen
    grey = shades[r0:r1, c0:c1]
    image = np.ascontiguousarray(grey[::-1])
    h, w = image.shape[:2]
    long_side = max(h, w)
    scale = max(PICTURE_MIN_SIDE / long_side, 1.0) if long_side < PICTURE_MIN_SIDE else 1.0
    scale = (
        min(scale, PICTURE_MAX_SIDE / long_side) if long_side * scale > PICTURE_MAX_SIDE else scale
    )
    size = (max(int(round(w * scale)), 1), max(int(round(h * scale)), 1))
    if scale < 1:  # reducing: keep thin walls dark (a minimum filter first, then average)
        reach = int(math.ceil(1 / scale))
        image = cv2.erode(image, np.ones((reach, reach), np.uint8))
    interpolation = cv2.INTER_NEAREST if scale >= 1 else cv2.INTER_AREA
    image = cv2.cvtColor(cv2.resize(image, size, interpolation=interpolation), cv2.COLOR_GRAY2BGR)
    origin = result.origin + np.array([c0, r0]) * result.resolution
    rows_total = r1 - r0

    def pixels(xy: F64) -> NDArray[np.int32]:
        cell = (np.asarray(xy, dtype=np.float64) - origin) / result.resolution
        px = np.stack([cell[..., 0], rows_total - cell[..., 1]], axis=-1) * scale
        return np.round(px).astype(np.int32)

    unit = max(1, int(round(max(image.shape[:2]) / 1000)))
    conflicts = result.conflict_points()
    if conflicts.shape[0] > MAX_DRAWN_CONFLICTS:
        pick = np.linspace(0, conflicts.shape[0] - 1, MAX_DRAWN_CONFLICTS).astype(np.int64)
        conflicts = conflicts[pick]
    if conflicts.shape[0]:
        px = pixels(conflicts)
        ok = (px[:, 0] >= 0) & (px[:, 0] < size[0]) & (px[:, 1] >= 0) & (px[:, 1] < size[1])
        px = px[ok]
        for d in range(unit):  # dots of `unit` pixels
            for e in range(unit):
                x = np.clip(px[:, 0] + d, 0, size[0] - 1)
                y = np.clip(px[:, 1] + e, 0, size[1] - 1)
                image[y, x] = (40, 40, 230)
    for s in result.stretches:
        path = pixels(result.poses[s.first : s.last + 2, :2]).reshape(-1, 1, 2)
        cv2.polylines(image, [path], False, score_colour(s.score), 2 * unit + 1, cv2.LINE_AA)
    start = pixels(result.poses[0, :2])
    cv2.circle(image, (int(start[0]), int(start[1])), 4 * unit, (200, 110, 20), -1)
    t0 = float(result.times[0])
    placed: list[tuple[int, int, int, int]] = []

    def label(text: str, org: tuple[int, int], colour: tuple[int, int, int]) -> None:
        draw_label(image, text, org, colour, unit, placed, flip_gap=36 * unit + 12)

    worst = result.worst()
    for s in worst:
        path = pixels(result.poses[s.first : s.last + 1, :2]).reshape(-1, 1, 2)
        cv2.polylines(image, [path], False, (160, 0, 160), 2 * unit, cv2.LINE_AA)
        cx, cy = (int(v) for v in pixels(np.array(s.place_xy)))
        radius = 18 * unit
        cv2.circle(image, (cx, cy), radius, (255, 255, 255), 3 * unit + 2, cv2.LINE_AA)
        cv2.circle(image, (cx, cy), radius, (160, 0, 160), 2 * unit, cv2.LINE_AA)
    score = result.score
    lines = [
        f"map quality {score:.3f}" if math.isfinite(score) else "map quality n/a",
        "path: score per stretch (green 1.0, yellow 0.9, red <= 0.6, grey not judged)",
        "red dots: returns in conflict with the other stretches' map",
        "purple: worst stretches (path, circle at the conflicts; #rank, time since start, score)",
    ]
    y = 22 * unit
    for text in lines:
        label(text, (10, y), (20, 20, 20))
        y += 24 * unit
    for rank, s in enumerate(worst, start=1):  # labels last, on top of every mark
        cx, cy = (int(v) for v in pixels(np.array(s.place_xy)))
        text = f"#{rank} {s.t_start - t0:.0f}-{s.t_end - t0:.0f} s  {s.score:.2f}"
        label(text, (cx + 18 * unit + 6, cy + 5 * unit), (120, 0, 120))
    return image


def draw_label(
    image: NDArray[np.uint8],
    text: str,
    org: tuple[int, int],
    colour: tuple[int, int, int],
    unit: int,
    placed: list[tuple[int, int, int, int]],
    flip_gap: int = 0,
) -> None:
    """``text`` on a white box at ``org`` (its baseline's left end) in ``image``, letters of
    size ``unit``, moved down until it overlaps no box in ``placed`` (to which its own is added).
    A label that would leave the picture on the right ends ``flip_gap`` pixels left of ``org``
    instead (the other side of the mark it labels; never left of the picture)."""
    import cv2

    font, fscale, thick = cv2.FONT_HERSHEY_SIMPLEX, 0.55 * unit, max(1, unit)
    (tw, th), base = cv2.getTextSize(text, font, fscale, thick)
    x, y = org
    if x + tw + 3 > image.shape[1]:
        x = max(3, org[0] - flip_gap - tw)
    box = (x - 3, y - th - 3, x + tw + 3, y + base + 2)
    while any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed):
        y += th + base + 6
        box = (x - 3, y - th - 3, x + tw + 3, y + base + 2)
    placed.append(box)
    cv2.rectangle(image, box[:2], box[2:], (255, 255, 255), -1)
    cv2.putText(image, text, (x, y), font, fscale, colour, thick, cv2.LINE_AA)


def _fmt(value: Any, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def format_quality(report: dict[str, Any]) -> list[tuple[str, str]]:
    """Rows of the quality part of the ``slam eval`` table."""
    p = report["parameters"]
    rows = [
        (
            "map quality",
            f"score {_fmt(report['score'])} (share of judged returns that agree with the map of "
            f"the other stretches)",
        ),
        (
            "  returns",
            f"{report['returns']} judged {report['checked']} (coverage {_fmt(report['coverage'])}):"
            f" agree {report['agree']}, in free space {report['conflict_free']}, through a "
            f"surface {report['conflict_through']}",
        ),
        (
            "  stretches",
            f"{report['stretches']} of {p['stretch_m']:g} m ({report['judged_stretches']} ranked):"
            f" median score {_fmt(report['median_stretch_score'])}, worst "
            f"{_fmt(report['worst_score'])}, {report['flagged']} below {p['flag_below']:g}",
        ),
    ]
    if report["worst"]:
        rows.append(
            ("  worst", "rank  time (s)        path (m)        place (x, y) m    score  offset")
        )
    for w in report["worst"]:
        t, pm, xy = w["time_s"], w["path_m"], w["place_xy"]
        offset = "n/a" if w["offset_m"] is None else f"{w['offset_m']:.2f} m"
        rows.append(
            (
                "",
                f"#{w['rank']:<4d}{t[0]:7.1f}-{t[1]:<7.1f} {pm[0]:7.1f}-{pm[1]:<7.1f} "
                f"({xy[0]:7.2f}, {xy[1]:7.2f})  {_fmt(w['score'])}  {offset}",
            )
        )
    if "picture" in report:
        rows.append(("  picture", str(report["picture"])))
    return rows
