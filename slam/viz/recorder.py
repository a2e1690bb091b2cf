"""The recorder of ``slam run``: a filter observer that writes ``recording.rrd`` as the run goes.

:class:`RunRecorder` implements :class:`slam.observers.Observer`. Timelines: ``scan`` (the
number of the processed scan, 0-based) and ``time`` (the scan's log timestamp). Entities (paths in
:mod:`slam.viz.blueprint`):

=========================  ========================================  ===========================
entity                     content                                   rows
=========================  ========================================  ===========================
``world``                  transform flipping y (+y up on screen)     static
``world/trajectory/live``  ``LineStrips2D``: segment previous→current  one per processed scan
``world/robot``            ``Arrows2D``: current pose and heading      one per processed scan
``metrics/n_eff``          ``Scalars``                                one per processed scan
``metrics/max_weight``     ``Scalars``                                one per processed scan
``world/particles``        ``Points2D`` coloured by weight            every ``detail_every`` scans
``world/scan``             ``Points2D``: ≤ ``scan_points`` endpoints   every ``detail_every`` scans
``metrics/scans_per_s``    ``Scalars``: rate over the last window      every ``detail_every`` scans
``world/map``              ``Image`` + transform (observed cells)     every ``map_every`` scans
                                                                      (preview), the final map
``world/trajectory/final`` ``LineStrips2D``: the run's trajectory     once, at the last scan
``world/ground_truth``     ``LineStrips2D``                           static, when known
``world/texture``          ``Image`` (RGBA) + transform               static, when texture.npz exists
=========================  ========================================  ===========================

Decimation keeps recording cheap (≤ 10 % of a run's wall time, measured by ``tools/benches/viz.py``):
per scan only four small rows, buffered and sent as columns every 0.25 s; particles, endpoints
and rates every ``detail_every`` scans; map snapshots (cropped to observed cells, grey levels
quantised) every ``map_every`` scans.

The map snapshots are a *preview*: the recorder integrates the logged scan endpoints (at most
``scan_points`` rays every ``detail_every`` scans, from the estimated pose) into its own log-odds
grid. It does not ask the filter for its live map (``map_every = 0`` as an observer): keeping that
map costs a full-resolution ray casting of every beam at every filter update, about 0.4 ms per
update, more than everything else the recorder does (measured on the demo). Maps handed to
:meth:`RunRecorder.on_map` by other callers are logged as snapshots all the same. The final
map, logged by :meth:`RunRecorder.finish`, is the run's own map (``map.npz``).
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from slam.budget import release_free_memory
from slam.config import Config, MapConfig, VizConfig
from slam.errors import UsageError
from slam.mapping import OccupancyGrid
from slam.observers import StepRecord
from slam.trajectory import Trajectory
from slam.viz import blueprint as bp
from slam.viz.images import PlacedImage, as_image, as_png, occupancy_image, texture_image
from slam.viz.stream import (
    close_stream,
    disconnect,
    open_stream,
    set_time,
    spawn_viewer,
    time_columns,
)

F64 = NDArray[np.float64]

RECORDING_NAME = "recording.rrd"
"""File name of the recording in a run folder."""

BATCH_ROWS = 1024
"""Buffered rows are sent every this many scans, or every ``batch_seconds`` (0.25 s) of wall
time, whichever comes first: few calls into rerun, and a live viewer lags by ≤ 0.25 s."""

RATE_WINDOW = 10
"""scans/s is measured over the last this-many ``detail_every`` windows (smooths skipped scans)."""

GROUND_TRUTH_POINTS = 5000
"""The ground-truth line keeps at most this many points (evenly spread)."""

_RED = (220, 40, 40)
_BLUE = (40, 110, 230)
_GREEN = (60, 170, 60)
_ORANGE = (240, 150, 20)


def log_placed(
    rec: rr.RecordingStream,
    path: str,
    image: PlacedImage,
    draw_order: float,
    static: bool = False,
) -> None:
    """Log ``image`` at ``path`` with the transform that places its pixels in the world: a grey
    picture (an occupancy map) as a PNG (:func:`~slam.viz.images.as_png`), a colour one (the
    texture) as it is."""
    x, y = image.corner
    grey = image.pixels.ndim == 2
    rec.log(
        path,
        rr.Transform3D(translation=[x, y, 0.0], scale=[image.cell, image.cell, 1.0]),
        as_png(image.pixels, draw_order) if grey else as_image(image.pixels, draw_order),
        static=static,
    )


def thin(points: F64, limit: int) -> F64:
    """At most ``limit`` rows of ``points``, evenly spread."""
    if points.shape[0] <= limit:
        return points
    return points[np.linspace(0, points.shape[0] - 1, limit).astype(np.int64)]


def weight_colours(weights: F64) -> NDArray[np.uint8]:
    """Particle colours: pale blue for the lightest to dark red for the heaviest weight."""
    w = np.asarray(weights, dtype=np.float64)
    span = float(w.max() - w.min())
    s = (w - w.min()) / span if span > 0 else np.ones_like(w)
    lo = np.array([150.0, 190.0, 255.0])
    hi = np.array([170.0, 0.0, 40.0])
    return (lo + s[:, None] * (hi - lo)).astype(np.uint8)


def log_track_styles(
    rec: rr.RecordingStream, series: Iterable[tuple[str, str]], scan: bool = False
) -> None:
    """Static styles of the entities a pose track uses (live and final trajectory, robot arrow,
    particles, the scan endpoints when ``scan``) and one line style per ``(path, label)`` of
    ``series``, so that per-step rows carry only positions and values."""
    ui = rr.Radius.ui_points
    line, points = rr.LineStrips2D.from_fields, rr.Points2D.from_fields
    styles = [
        (bp.TRAJECTORY, line(colors=[_RED], radii=ui(1.5), draw_order=30.0)),
        (bp.TRAJECTORY_FINAL, line(colors=[_BLUE], radii=ui(1.5), draw_order=31.0)),
        (bp.SCAN, points(colors=[_ORANGE], radii=ui(1.5), draw_order=20.0)),
        (bp.ROBOT, rr.Arrows2D.from_fields(colors=[_RED], radii=ui(2.5), draw_order=40.0)),
        (bp.PARTICLES, points(radii=ui(2.0), draw_order=35.0)),
    ]
    for path, style in styles:
        if scan or path != bp.SCAN:
            rec.log(path, style, static=True)
    for path, label in series:
        rec.log(path, rr.SeriesLines(names=label, widths=1.5), static=True)


def send_track(
    rec: rr.RecordingStream,
    rows: F64,
    last_xy: F64 | None,
    scalars: Iterable[tuple[str, int]],
) -> None:
    """Send buffered pose rows (columns step, time, x, y, theta, …) as columns: per row a
    trajectory segment from the previous position (``last_xy`` before the first row; none: the
    first segment has length 0), the robot arrow, and for each ``(path, column)`` of
    ``scalars`` that column's values."""
    index = time_columns(rows[:, 0].astype(np.int64), rows[:, 1])
    xy = rows[:, 2:4]
    prev = np.vstack([xy[:1] if last_xy is None else last_xy[None], xy[:-1]])
    segments = rr.LineStrips2D.columns(strips=np.stack([prev, xy], axis=1))
    rec.send_columns(bp.TRAJECTORY, indexes=index, columns=segments)
    heading = 0.5 * np.stack([np.cos(rows[:, 4]), np.sin(rows[:, 4])], axis=1)
    arrows = rr.Arrows2D.columns(origins=xy, vectors=heading)
    rec.send_columns(bp.ROBOT, indexes=index, columns=arrows)
    for path, column in scalars:
        rec.send_columns(path, indexes=index, columns=rr.Scalars.columns(scalars=rows[:, column]))


ABORT_FLUSH_S = 2.0
"""Longest wait for rerun to flush the recording of a failed run (:meth:`RunRecorder.abort`)."""


class RunRecorder:
    """Observer that records a run for the rerun viewer (file and/or live viewer).

    ``clock`` measures the scans/s series (wall time; tests pass a fake clock to get
    reproducible recordings). ``spent_s`` accumulates the time spent logging. Reproducible files
    also need batches that do not depend on wall time: ``batch_seconds=math.inf`` and
    ``batcher_config=rr.ChunkBatcherConfig.NEVER()``.
    """

    def __init__(
        self,
        path: Path | None,
        config: VizConfig,
        *,
        map_config: MapConfig | None = None,
        name: str = "slam run",
        viewer_url: str | None = None,
        recording_id: str | None = None,
        clock: Callable[[], float] = time.perf_counter,
        batch_seconds: float = 0.25,
        batcher_config: rr.ChunkBatcherConfig | None = None,
    ) -> None:
        self.path = None if path is None else Path(path)
        self.config = config
        self.detail_every = config.detail_every
        self.map_every = 0  # the filter's live map costs too much: see the module docstring
        self._next_map = config.map_every
        self._map_config = map_config or MapConfig()
        self._preview: OccupancyGrid | None = None
        self.clock = clock
        self.spent_s = 0.0
        self.steps = 0
        self.maps = 0
        self._last_xy: F64 | None = None
        self._rows: list[tuple[float, ...]] = []
        self._particles: list[tuple[int, float, F64, NDArray[np.uint8]]] = []
        self._scans: list[tuple[int, float, F64]] = []
        self._rates: list[tuple[int, float, float]] = []
        self._last: tuple[int, float] = (0, 0.0)
        self._rate_marks: deque[tuple[int, float]] = deque(maxlen=RATE_WINDOW)
        start = time.perf_counter()
        self.rec = open_stream(
            self.path,
            name=name,
            viewer_url=viewer_url,
            recording_id=recording_id,
            blueprint=bp.run_blueprint(),
            batcher_config=batcher_config,
        )
        self.batch_seconds = batch_seconds
        self._sent_at = time.perf_counter()
        self._log_styles()
        self.spent_s += time.perf_counter() - start

    def _log_styles(self) -> None:
        """Static transform and styles, so that per-step rows carry only positions."""
        self.rec.log(bp.WORLD, bp.world_flip(), static=True)
        log_track_styles(
            self.rec,
            ((bp.N_EFF, "N_eff"), (bp.MAX_WEIGHT, "max weight"), (bp.SCANS_PER_S, "scans/s")),
            scan=True,
        )

    # -- the Observer protocol
    def on_step(self, record: StepRecord) -> None:
        """Buffer the scan's rows; they are sent in batches of :data:`BATCH_ROWS` scans."""
        start = time.perf_counter()
        step, stamp = record.step, record.time
        self._rows.append((step, stamp, *record.pose[:3], record.n_eff, record.max_weight))
        if record.particles is not None and record.weights is not None:
            colours = weight_colours(record.weights)
            self._particles.append((step, stamp, record.particles[:, :2].copy(), colours))
        if record.endpoints is not None:
            points = thin(record.endpoints, self.config.scan_points)
            self._scans.append((step, stamp, points))
            if self.config.map_every:
                self._integrate(record.pose, points)
                if step >= self._next_map and self._preview is not None:
                    self._log_map(step, stamp, self._preview)
        if self.detail_every and step % self.detail_every == 0:
            now = self.clock()
            marks = self._rate_marks
            if marks and now > marks[0][1]:
                self._rates.append((step, stamp, (step - marks[0][0]) / (now - marks[0][1])))
            marks.append((step, now))
        self._last = (step, stamp)
        self.steps += 1
        rows = len(self._rows)
        if rows >= BATCH_ROWS or (rows >= 16 and start - self._sent_at >= self.batch_seconds):
            self._send_rows()
            self._sent_at = start
        self.spent_s += time.perf_counter() - start

    def _send_rows(self) -> None:
        """Send the buffered rows, one ``send_columns`` per entity: per scan a trajectory
        segment, the pose, N_eff and max weight; particles, scan endpoints and rates."""
        rec = self.rec
        if self._rows:
            rows = np.asarray(self._rows, dtype=np.float64)
            self._rows = []
            send_track(rec, rows, self._last_xy, ((bp.N_EFF, 5), (bp.MAX_WEIGHT, 6)))
            self._last_xy = rows[-1, 2:4].copy()
        if self._particles:
            steps, stamps, points, colours = zip(*self._particles, strict=True)
            self._particles = []
            columns = rr.Points2D.columns(
                positions=np.concatenate(points), colors=np.concatenate(colours)
            ).partition([len(p) for p in points])
            rec.send_columns(bp.PARTICLES, indexes=time_columns(steps, stamps), columns=columns)
        if self._scans:
            steps, stamps, points = zip(*self._scans, strict=True)
            self._scans = []
            columns = rr.Points2D.columns(positions=np.concatenate(points)).partition(
                [len(p) for p in points]
            )
            rec.send_columns(bp.SCAN, indexes=time_columns(steps, stamps), columns=columns)
        if self._rates:
            steps, stamps, rates = zip(*self._rates, strict=True)
            self._rates = []
            rec.send_columns(
                bp.SCANS_PER_S,
                indexes=time_columns(steps, stamps),
                columns=rr.Scalars.columns(scalars=np.asarray(rates)),
            )

    def _integrate(self, pose: F64, endpoints: F64) -> None:
        """Add one logged scan (rays from the robot to its endpoints) to the preview map;
        coarsen the map while it has more than ``viz.preview_cells`` cells."""
        if self._preview is None:
            self._preview = OccupancyGrid(self._map_config, center=(pose[0], pose[1]))
        hit = np.ones(endpoints.shape[0], dtype=np.bool_)
        self._preview.integrate(np.asarray(pose[:2], dtype=np.float64), endpoints, hit)
        while self._preview.log_odds.size > self.config.preview_cells:
            self._preview = self._preview.coarsened(2)

    def _log_map(self, step: int, time_s: float, grid: OccupancyGrid) -> None:
        """Log a snapshot of ``grid``; then hand the heap's freed pages back: on a large
        building each snapshot's picture and its serialised copy are tens of MB, which the C
        heap would otherwise keep (mit-killian's default run: peak 952 → 848–865 MB with this,
        :meth:`on_filter_end` and the pipeline's own trims; 0.1 s for its 88 snapshots; then
        769–846 MB with the preview's cell budget, ``viz.preview_cells``, and 719–729 MB with
        the maps logged as PNG; docs/viz.md)."""
        image = occupancy_image(grid, self.config.map_levels)
        if image is not None:
            set_time(self.rec, step, time_s)
            log_placed(self.rec, bp.MAP, image, draw_order=0.0)
            self.maps += 1
            self._next_map = (step // self.config.map_every + 1) * self.config.map_every
            del image
            release_free_memory()

    def on_filter_end(self) -> None:
        """Let go of the preview map: it only feeds the snapshots logged during the filter
        (the final map comes from :meth:`finish`), and on a large building it is the size of the
        final grid (mit-killian: 121 MB, held through the stages after the filter before)."""
        self._preview = None

    def on_map(self, step: int, time_s: float, grid: OccupancyGrid) -> None:
        """Log ``grid`` as a snapshot when ``viz.map_every`` scans have passed since the last."""
        if not self.config.map_every or step < self._next_map:
            return
        start = time.perf_counter()
        self._log_map(step, time_s, grid)
        self.spent_s += time.perf_counter() - start

    # -- before and after the filter
    def log_ground_truth(self, trajectory: Trajectory) -> None:
        """The true trajectory (static), when the dataset has one."""
        start = time.perf_counter()
        xy = thin(trajectory.poses[:, :2], GROUND_TRUTH_POINTS)
        self.rec.log(
            bp.GROUND_TRUTH,
            rr.LineStrips2D([xy], colors=[_GREEN], radii=rr.Radius.ui_points(1.5), draw_order=25.0),
            static=True,
        )
        self.spent_s += time.perf_counter() - start

    def finish(
        self,
        trajectory: Trajectory,
        grid: OccupancyGrid | None,
        run_folder: Path | None = None,
    ) -> dict[str, Any]:
        """Log the final trajectory, the final map and the texture (if ``texture.npz`` exists in
        ``run_folder``) at the last scan, close the file; return figures for ``metrics.json``."""
        start = time.perf_counter()
        self._send_rows()
        rec = self.rec
        times = trajectory.times
        if self.steps:
            step, stamp = self._last
        else:
            step, stamp = max(len(times) - 1, 0), float(times[-1]) if len(times) else None
        set_time(rec, step, stamp)
        if len(trajectory):
            rec.log(bp.TRAJECTORY_FINAL, rr.LineStrips2D([trajectory.poses[:, :2]]))
        if grid is not None:
            image = occupancy_image(grid, self.config.map_levels)
            if image is not None:
                log_placed(rec, bp.MAP, image, draw_order=0.0)
                self.maps += 1
        texture = texture_image(run_folder) if run_folder is not None else None
        if texture is not None:
            log_placed(rec, bp.TEXTURE, texture, draw_order=-10.0, static=True)
        close_stream(rec, self.path)
        self.spent_s += time.perf_counter() - start
        out: dict[str, Any] = {
            "steps": self.steps,
            "maps": self.maps,
            "texture": texture is not None,
            "log_s": round(self.spent_s, 3),
        }
        if self.path is not None and self.path.is_file():
            out["file"] = self.path.name
            out["size_mb"] = round(self.path.stat().st_size / 2**20, 2)
        return out

    def abort(self) -> None:
        """Close the stream of a run that failed (its folder is about to be removed): without
        this rerun's threads kept the file open and, at the interpreter's exit, flushed into a
        folder that no longer existed or a full disk — an ERROR line on stderr, or a process
        that did not exit in 300 s (twice in three CI runs, on a full 64 KiB tmpfs). The flush
        is bounded (:data:`ABORT_FLUSH_S`), the disconnect too
        (:func:`slam.viz.stream.disconnect`), and their errors are the run's failure already,
        not news."""
        with contextlib.suppress(Exception):
            self.rec.flush(timeout_sec=ABORT_FLUSH_S)
        disconnect(self.rec, raising=False)


_LIVE_VIEWERS: list = []
"""Viewer processes spawned by this process (kept so that they are never garbage collected)."""


def start_recording(
    folder: Path,
    config: Config,
    ground_truth: Trajectory | None = None,
    viewer: bool = False,
) -> RunRecorder | None:
    """The recorder of a ``slam run`` writing ``folder/recording.rrd`` (``viz.record``) and/or
    streaming to a newly spawned viewer (``viewer``); ``None`` when neither is asked for.

    ``ground_truth``, the true trajectory, is logged right away. A viewer that cannot start (no
    display) is one warning on stderr; the run goes on without it (and still writes
    ``recording.rrd`` unless ``viz.record`` is off).
    """
    if not config.viz.record and not viewer:
        return None
    url = None
    if viewer:
        try:
            process, url = spawn_viewer()
            _LIVE_VIEWERS.append(process)  # it outlives the run: no "still running" warning
        except UsageError as exc:
            then = (
                "the run goes on and writes recording.rrd: open it later with "
                "'slam view RUN_DIR --web'"
                if config.viz.record
                else "the run goes on without a live view (--no-record: no recording either)"
            )
            print(f"slam: warning: {exc}; {then}", file=sys.stderr, flush=True)
            if not config.viz.record:
                return None
    path = Path(folder) / RECORDING_NAME if config.viz.record else None
    name = f"slam run {config.dataset or Path(folder).name} ({config.filter.method})"
    recorder = RunRecorder(path, config.viz, map_config=config.map, name=name, viewer_url=url)
    if ground_truth is not None:
        recorder.log_ground_truth(ground_truth)
    return recorder
