"""Map quality without ground truth: does each stretch of a run agree with the rest of the map?

A user's own log has no relations and no reference trajectory, yet a map that failed shows it:
where the robot came back to a place, the walls it saw the second time do not lie where it saw
them the first time (a loop that did not close leaves a *doubled corridor*). The naive check,
"how many scan endpoints lie on the final map's surfaces", cannot see this: each pass's
endpoints lie on its own copy of the wall, and both copies are in the map. So the score compares
every stretch of the run with the map built from the **other** stretches only (revisit agreement,
in the spirit of the map-consistency measures of Filatov et al. 2017 and the relation-free
checks Kümmerle et al. 2009 discuss), and judges each laser return of the stretch:

* **agree**: a surface of the others' map lies within ``tolerance_m`` of the endpoint;
* **conflict (free)**: no surface near it, and the endpoint lies in space the others saw free;
* **conflict (through)**: no surface near it, and the beam passed through the others' surface
  before it ended (the stretch sees *through* a wall the others saw);
* **unknown**: the others never observed that place (first visits: not judged).

``score = agree / (agree + conflicts)`` per stretch and over the run; ``coverage`` is the share
of returns that could be judged (how much of the run revisits what other stretches saw).

**Stretches** are consecutive scans covering ``stretch_m`` metres of the estimated path; "the
others" of a stretch are the scans more than ``separation_m`` of path before its first or after
its last scan, so a stretch is never judged against the scans it was matched to.

**Cost.** The others' map is integer counts (hits, misses) per cell of all rays; the stretches
are visited in order and the scans within ``separation_m`` of the current one are subtracted
from the counts (and added back, from the counts kept when they were subtracted, when the window
moves on), so every ray is cast twice: for the counts and to subtract it (and, on a grid too
large to allocate whole, first to find the tiles to allocate: :mod:`slam.kernels.quality`). The
definition and its parameters are in docs/evaluation.md, "Map quality without ground truth".
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import MapConfig, QualityConfig
from slam.errors import DataError
from slam.eval.relations import DEFAULT_TOLERANCE_S, match_times, relation_errors
from slam.geometry import path_along, row_trig
from slam.io.relations import Relations
from slam.kernels.quality import (
    AGREE,
    CONFLICT_FREE,
    CONFLICT_THROUGH,
    FREE,
    HIT,
    ISOLATED,
    NO_RAY,
    TILE,
    UNKNOWN,
    CountMap,
    Judging,
    KeptPatches,
    ScanRays,
    add_kept,
    classify_beams,
    count_rays,
    counts_over,
    map_shades,
    ray_bounds,
)

F64 = NDArray[np.float64]

NEIGHBOUR_GAP_M = 0.1
"""Two neighbouring returns trace one surface when closer than this (m) ..."""
NEIGHBOUR_RELATIVE_GAP = 0.02
"""... plus this fraction of the range (the rule of :func:`slam.particle_filter.surface_normals`)."""
MAX_CELLS = 100_000_000
"""Largest count grid the score allocates (two int32 layers: 800 MB); beyond, coarsen."""
UNSEEN_SHADE = 190
"""Grey level of cells no ray reached, in :attr:`QualityResult.shades`."""


@dataclass(frozen=True)
class Rays:
    """The rays of the scans to score, in the robot frame (see :mod:`slam.kernels.quality`)."""

    ex: NDArray[np.float32]
    """``(N, B)`` x of each ray's end (m), robot frame; 0 where no ray (``kind`` says which)."""
    ey: NDArray[np.float32]
    """``(N, B)`` y of each ray's end (m)."""
    kind: NDArray[np.int8]
    """``(N, B)`` :data:`~slam.kernels.quality.HIT`, ``FREE`` or ``NO_RAY``."""
    laser_xy: tuple[float, float]
    """Laser position in the robot frame (m)."""

    def __len__(self) -> int:
        return int(self.kind.shape[0])


RAY_ROWS = 2048
"""Scans turned into rays at a time: the float64 intermediates of a block, not of the whole
log (a 20-minute log of 48,000 scans × 1081 beams held 1.2 GB of them at once)."""


def scan_rays(
    ranges: NDArray[np.floating],
    angles: F64,
    laser_offset: F64,
    range_min: float,
    range_max: float,
    no_return: float,
    free_range_no_return: float = 0.0,
) -> Rays:
    """The rays of scans ``ranges (N, B)`` as the occupancy map casts them.

    ``angles`` is ``(B,)`` or ``(N, B)`` (laser frame). Readings below ``range_max`` are obstacle
    returns; readings from ``range_max`` up to ``no_return`` clear space up to ``range_max``;
    "no return" readings clear space up to ``free_range_no_return`` (0: no ray), exactly as
    :meth:`slam.particle_filter.ScanSequence.rays` does. Computed :data:`RAY_ROWS` scans at a
    time.
    """
    r_all = np.asarray(ranges)
    a_all = np.asarray(angles, dtype=np.float64)
    a_all = a_all[None, :] if a_all.ndim == 1 else a_all
    n, beams = r_all.shape if r_all.ndim == 2 else (0, a_all.shape[-1])
    ex = np.empty((n, beams), dtype=np.float32)
    ey = np.empty((n, beams), dtype=np.float32)
    kind = np.empty((n, beams), dtype=np.int8)
    range_max = min(float(range_max), float(no_return))
    lx, ly, lt = (float(v) for v in laser_offset)
    shared = a_all.shape[0] == 1
    trig = row_trig(lt + a_all) if shared else None  # once for the scans of one laser
    for first in range(0, n, RAY_ROWS):
        rows = slice(first, min(first + RAY_ROWS, n))
        r = np.asarray(r_all[rows], dtype=np.float64)
        a = a_all if shared else a_all[rows]
        valid = np.isfinite(r) & np.isfinite(a) & (r >= range_min) & (r > 0)  # 0: no reading
        hit = valid & (r < range_max)
        length = np.where(r < no_return, np.minimum(r, range_max), free_range_no_return)
        ray = hit | (valid & (length > 0))
        kind[rows] = np.where(hit, HIT, np.where(ray, FREE, NO_RAY))
        cos, sin = trig if trig is not None else row_trig(lt + a)
        ex[rows] = np.where(ray, lx + length * cos, 0.0)
        ey[rows] = np.where(ray, ly + length * sin, 0.0)
    return Rays(ex, ey, kind, (lx, ly))


def within_range(rays: Rays, max_range: float, in_place: bool = False) -> Rays:
    """The rays cut at ``max_range`` from the laser: a longer ray clears space up to there and is
    no longer a return (far free space and far returns are placed too loosely to judge with: a
    0.3° heading error moves a point 10 cm at 20 m). ``rays`` itself when none is longer; else
    copies (``in_place``: ``rays``' own arrays, cut), worked through :data:`RAY_ROWS` scans at a
    time."""
    lx, ly = rays.laser_xy
    out: Rays | None = rays if in_place else None
    for first in range(0, len(rays), RAY_ROWS):
        rows = slice(first, first + RAY_ROWS)
        dx = rays.ex[rows] - np.float32(lx)
        dy = rays.ey[rows] - np.float32(ly)
        length = np.hypot(dx, dy)
        far = (rays.kind[rows] != NO_RAY) & (length > max_range)
        if not far.any():
            continue
        if out is None:
            out = Rays(rays.ex.copy(), rays.ey.copy(), rays.kind.copy(), rays.laser_xy)
        shrink = np.where(far, np.float32(max_range) / np.where(far, length, 1), 1)
        shrink = shrink.astype(np.float32)
        out.ex[rows] = (np.float32(lx) + dx * shrink).astype(np.float32)
        out.ey[rows] = (np.float32(ly) + dy * shrink).astype(np.float32)
        out.kind[rows] = np.where(far, FREE, rays.kind[rows])
    return rays if out is None else out


def select_scans(count: int, every: int = 1, max_scans: int = 0) -> NDArray[np.int64]:
    """Indices of the scans a run processed (``filter.every``, ``filter.max_scans``)."""
    idx = np.arange(count, dtype=np.int64)[:: max(int(every), 1)]
    return idx[:max_scans] if max_scans else idx


def stretch_bounds(poses: F64, stretch_m: float) -> NDArray[np.int64]:
    """Start rows of the stretches, then ``N``: a stretch ends where the path since its first pose
    reaches ``stretch_m``; a last remainder shorter than half of that joins the stretch before."""
    n = poses.shape[0]
    path = path_along(poses)
    starts = [0]
    while True:
        k = int(np.searchsorted(path, path[starts[-1]] + stretch_m, side="left"))
        if k >= n:
            break
        starts.append(k)
    if len(starts) > 1 and path[-1] - path[starts[-1]] < 0.5 * stretch_m:
        starts.pop()
    return np.asarray([*starts, n], dtype=np.int64)


@dataclass(frozen=True)
class StretchScore:
    """The verdicts of one stretch of the run."""

    index: int
    first: int
    """First row (scan) of the stretch."""
    last: int
    """Last row (inclusive)."""
    t_start: float
    """Time of the first scan (s, the log's clock)."""
    t_end: float
    """Time of the last scan."""
    path_start: float
    """Path length from the start of the run to the first scan (m)."""
    path_end: float
    robot_xy: tuple[float, float]
    """Robot position halfway through the stretch (m)."""
    place_xy: tuple[float, float]
    """Median of the conflicting endpoints (where the map disagrees), else ``robot_xy``."""
    returns: int
    """Obstacle returns of the stretch."""
    agree: int
    conflict_free: int
    conflict_through: int
    unknown: int
    isolated: int
    """Returns with no close neighbour (not judged)."""
    offset_m: float
    """Median distance (m) from a conflicting endpoint to the others' surface along its beam
    (NaN when none was found within ``max_offset_m``): how far this stretch's walls lie from
    the others' walls."""

    @property
    def conflicts(self) -> int:
        """Returns in conflict with the other stretches."""
        return self.conflict_free + self.conflict_through

    @property
    def checked(self) -> int:
        """Returns that could be judged (agree or conflict)."""
        return self.agree + self.conflicts

    @property
    def score(self) -> float:
        """``agree / checked`` (NaN when nothing could be judged)."""
        return self.agree / self.checked if self.checked else math.nan


@dataclass
class QualityResult:
    """What :func:`map_quality` computes: the stretches, the verdict of every beam, the map."""

    stretches: list[StretchScore]
    verdict: NDArray[np.int8]
    """``(N, B)`` verdict of every beam (:mod:`slam.kernels.quality` codes)."""
    shades: NDArray[np.uint8]
    """``(H, W)`` the whole run's map as grey levels (:func:`~slam.kernels.quality.map_shades`;
    :data:`UNSEEN_SHADE` where no ray came), rows up in y."""
    origin: F64
    """World position of the lower-left corner of cell (0, 0) (m)."""
    resolution: float
    poses: F64
    """``(N, 3)`` the robot poses scored."""
    times: F64
    """``(N,)`` their times."""
    rays: Rays
    config: QualityConfig
    map_config: MapConfig
    wall_s: float
    """Wall time of :func:`map_quality` (s)."""
    cpu_s: float
    """Processor time of :func:`map_quality` (s; its kernels run on one thread)."""

    def totals(self) -> dict[str, int]:
        """Counts of each verdict over the run."""
        agree = sum(s.agree for s in self.stretches)
        free = sum(s.conflict_free for s in self.stretches)
        through = sum(s.conflict_through for s in self.stretches)
        unknown = sum(s.unknown for s in self.stretches)
        isolated = sum(s.isolated for s in self.stretches)
        return {
            "returns": sum(s.returns for s in self.stretches),
            "checked": agree + free + through,
            "agree": agree,
            "conflict_free": free,
            "conflict_through": through,
            "unknown": unknown,
            "isolated": isolated,
        }

    @property
    def score(self) -> float:
        """Share of the judged returns that agree, over the whole run (NaN if none)."""
        t = self.totals()
        return t["agree"] / t["checked"] if t["checked"] else math.nan

    def judged(self) -> list[StretchScore]:
        """Stretches with at least ``min_checked`` judged returns, and at least ``min_coverage``
        of their returns judged (the ones that are ranked): a stretch that revisits almost
        nothing is judged on a few returns at the edge of what the others saw."""
        c = self.config
        return [
            s
            for s in self.stretches
            if s.checked >= c.min_checked and s.checked >= c.min_coverage * s.returns
        ]

    def worst(self) -> list[StretchScore]:
        """The ``worst`` judged stretches, lowest score first (ties: more conflicts first), one
        per episode: a stretch next to one already chosen (index ± 1) is left out."""
        ranked = sorted(self.judged(), key=lambda s: (s.score, -s.conflicts, s.index))
        chosen: list[StretchScore] = []
        taken: set[int] = set()
        for s in ranked:
            if len(chosen) == self.config.worst:
                break
            if s.index - 1 in taken or s.index + 1 in taken:
                continue
            chosen.append(s)
            taken.add(s.index)
        return chosen

    def flagged(self) -> list[StretchScore]:
        """Judged stretches whose score is below ``flag_below``."""
        return [s for s in self.judged() if s.score < self.config.flag_below]

    def score_over(self, first: int, last: int) -> tuple[float, int]:
        """The share of the judged returns that agree over the scans ``first`` to ``last``
        (inclusive; NaN if none) and how many were judged: another run's stretch scored on this
        run's verdicts, scan for scan, whatever this run's own stretches are."""
        v = self.verdict[first : last + 1]
        checked = int(np.count_nonzero(v >= AGREE))
        agree = int(np.count_nonzero(v == AGREE))
        return (agree / checked if checked else math.nan), checked

    def conflict_points(self) -> F64:
        """World positions ``(M, 2)`` of every conflicting endpoint."""
        rows, beams = np.nonzero(self.verdict >= CONFLICT_FREE)
        return np.zeros((0, 2)) if rows.size == 0 else self._world(rows, beams)

    def _world(self, rows: NDArray[np.int64], beams: NDArray[np.int64]) -> F64:
        p = self.poses[rows]
        ex = self.rays.ex[rows, beams].astype(np.float64)
        ey = self.rays.ey[rows, beams].astype(np.float64)
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        return np.stack([p[:, 0] + c * ex - s * ey, p[:, 1] + s * ex + c * ey], axis=1)


def _grid_frame(poses: F64, rays: Rays, resolution: float) -> tuple[F64, tuple[int, int]]:
    """Origin and shape of a grid holding every ray end and every laser position."""
    lx, ly = rays.laser_xy
    box = ray_bounds(poses, lx, ly, rays.ex, rays.ey, rays.kind)
    lo, hi = box[:2], box[2:]
    origin = np.floor(lo / resolution) * resolution - 2 * resolution
    cells = np.ceil((hi - origin) / resolution).astype(np.int64) + 3
    width, height = int(cells[0]), int(cells[1])
    if width * height > MAX_CELLS:
        raise DataError(
            f"quality.resolution: a {resolution:g} m grid over {hi[0] - lo[0]:.0f} × "
            f"{hi[1] - lo[1]:.0f} m needs {width * height:,} cells (at most {MAX_CELLS:,}); "
            "set a coarser quality.resolution"
        )
    return origin, (height, width)


def _disc(tolerance: float, resolution: float) -> NDArray[np.int64]:
    """Cell offsets ``(K, 2)`` whose centres lie within ``tolerance`` of a cell's centre,
    nearest first."""
    reach = int(math.floor(tolerance / resolution))
    d = np.arange(-reach, reach + 1)
    dx, dy = np.meshgrid(d, d)
    d2 = (dx**2 + dy**2).ravel()
    keep = d2 * resolution**2 <= tolerance**2 * (1 + 1e-9)
    order = np.argsort(d2[keep], kind="stable")  # nearest first: most searches stop at once
    offsets = np.stack([dx.ravel()[keep], dy.ravel()[keep]], axis=1)[order]
    return np.ascontiguousarray(offsets, dtype=np.int64)


def judging_for(config: QualityConfig, map_config: MapConfig) -> Judging:
    """The thresholds of :func:`~slam.kernels.quality.classify_beams` from the configuration."""
    return Judging(
        config.tolerance_m, map_config.log_odds_hit, map_config.log_odds_miss,
        map_config.occupied_threshold, config.min_free_rays,
        math.sin(math.radians(config.min_incidence_deg)), config.max_offset_m, NEIGHBOUR_GAP_M,
        NEIGHBOUR_RELATIVE_GAP,
    )  # fmt: skip


def map_quality(
    times: F64,
    poses: F64,
    rays: Rays,
    config: QualityConfig | None = None,
    map_config: MapConfig | None = None,
    own_rays: bool = False,
) -> QualityResult:
    """Score the map the poses ``(N, 3)`` (robot, one per scan) build from ``rays``.

    ``map_config`` supplies the log-odds of a hit and a miss and the occupied threshold, so
    "occupied" means what it means in the run's map (definition: module docstring; parameters:
    docs/evaluation.md). ``own_rays``: made for this call alone, cut in place, not in a copy.
    """
    config = config or QualityConfig()
    map_config = map_config or MapConfig()
    start_clock, start_cpu = time.perf_counter(), time.process_time()
    times = np.ascontiguousarray(times, dtype=np.float64)
    poses = np.ascontiguousarray(poses, dtype=np.float64).reshape(-1, 3)
    n = poses.shape[0]
    if times.shape[0] != n or len(rays) != n:
        raise ValueError(f"{times.shape[0]} times, {n} poses and {len(rays)} scans of rays")
    if n == 0:
        raise DataError("map quality: no scans to score")
    rays = within_range(rays, config.max_range_m, in_place=own_rays)
    res = float(config.resolution)
    origin, shape = _grid_frame(poses, rays, res)
    # no copy of scan_rays' rays (0 where no ray); one of rays that hold NaN there
    ex, ey = (np.nan_to_num(e, nan=0.0) if np.isnan(e).any() else e for e in (rays.ex, rays.ey))
    ex, ey = np.ascontiguousarray(ex), np.ascontiguousarray(ey)
    kind = np.ascontiguousarray(rays.kind)
    lx, ly = rays.laser_xy
    ox, oy = float(origin[0]), float(origin[1])
    tiles = (-(-shape[0] // TILE), -(-shape[1] // TILE))
    scan_rays = ScanRays(poses, float(lx), float(ly), ex, ey, kind)
    table, pool = counts_over(*tiles, ox, oy, res, scan_rays)
    counts = CountMap(table, pool, ox, oy, res)
    count_rays(counts, scan_rays, 0, n, 1)

    bounds = stretch_bounds(poses, config.stretch_m)
    path = path_along(poses)
    windows = _windows(bounds, path, config.separation_m)
    cuts = [end for window in windows for end in window]
    verdict = np.empty(kind.shape, dtype=np.int8)
    offset = np.empty(kind.shape, dtype=np.float32)
    disc = _disc(config.tolerance_m, res)
    judging = judging_for(config, map_config)
    removed = (0, 0)  # rows currently subtracted from the counts
    kept: KeptPatches = {}  # their counts, to give back without walking their rays again
    stretches: list[StretchScore] = []
    for index, (w0, w1) in enumerate(windows):
        a, b = int(bounds[index]), int(bounds[index + 1])
        c0, c1 = removed
        # Window ends only move forward: give back what it left, take out what it reached
        # (cut at every window's ends, so what a window gives back is whole kept blocks).
        add_kept(counts, kept, c0, min(c1, w0), 1)
        count_rays(counts, scan_rays, max(c1, w0), w1, -1, cuts, kept)
        removed = (w0, w1)
        classify_beams(counts, scan_rays, a, b, disc, judging, verdict, offset)
        stretches.append(_stretch(index, a, b, times, poses, path, verdict, offset, rays))
    c0, c1 = removed
    add_kept(counts, kept, c0, c1, 1)
    shades = map_shades(
        table, pool, map_config.log_odds_hit, map_config.log_odds_miss, UNSEEN_SHADE
    )
    del pool, counts
    return QualityResult(
        stretches=stretches,
        verdict=verdict,
        shades=shades,
        origin=origin,
        resolution=res,
        poses=poses,
        times=times,
        rays=rays,
        config=config,
        map_config=map_config,
        wall_s=time.perf_counter() - start_clock,
        cpu_s=time.process_time() - start_cpu,
    )


def _windows(bounds: NDArray[np.int64], path: F64, separation: float) -> list[tuple[int, int]]:
    """``(w0, w1)`` of each stretch of ``bounds``: its scans and those within ``separation`` of
    path before and after it, whose rays the score takes out of the others' map."""
    return [
        (
            int(np.searchsorted(path, path[a] - separation, side="left")),
            int(np.searchsorted(path, path[b - 1] + separation, side="right")),
        )
        for a, b in pairwise(bounds.tolist())
    ]


def _stretch(
    index: int,
    a: int,
    b: int,
    times: F64,
    poses: F64,
    path: F64,
    verdict: NDArray[np.int8],
    offset: NDArray[np.float32],
    rays: Rays,
) -> StretchScore:
    v = verdict[a:b]
    conflict = v >= CONFLICT_FREE
    mid = (a + b - 1) // 2
    robot = (float(poses[mid, 0]), float(poses[mid, 1]))
    place = robot
    if conflict.any():
        rows, beams = np.nonzero(conflict)
        p = poses[a + rows]
        ex = rays.ex[a + rows, beams].astype(np.float64)
        ey = rays.ey[a + rows, beams].astype(np.float64)
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        place = (
            float(np.median(p[:, 0] + c * ex - s * ey)),
            float(np.median(p[:, 1] + s * ex + c * ey)),
        )
    found = offset[a:b][conflict]
    found = found[np.isfinite(found)]
    return StretchScore(
        index=index,
        first=a,
        last=b - 1,
        t_start=float(times[a]),
        t_end=float(times[b - 1]),
        path_start=float(path[a]),
        path_end=float(path[b - 1]),
        robot_xy=robot,
        place_xy=place,
        returns=int(np.count_nonzero(rays.kind[a:b] == HIT)),
        agree=int(np.count_nonzero(v == AGREE)),
        conflict_free=int(np.count_nonzero(v == CONFLICT_FREE)),
        conflict_through=int(np.count_nonzero(v == CONFLICT_THROUGH)),
        unknown=int(np.count_nonzero(v == UNKNOWN)),
        isolated=int(np.count_nonzero(v == ISOLATED)),
        offset_m=float(np.median(np.abs(found))) if found.size else math.nan,
    )


@dataclass(frozen=True)
class StretchRelations:
    """Relation errors (ground truth) gathered per stretch, to check the score against them."""

    count: NDArray[np.int64]
    """``(S,)`` matched relations with an end in the stretch."""
    mean: F64
    """``(S,)`` their mean translational error (m; NaN without relations)."""
    max: F64
    """``(S,)`` their largest translational error (m; NaN without relations)."""


def stretch_relation_errors(
    result: QualityResult, relations: Relations, tolerance: float = DEFAULT_TOLERANCE_S
) -> StretchRelations:
    """The relation metric's errors of the scored trajectory, per stretch: a relation counts for
    the stretch of each of its two ends (once when both lie in the same stretch)."""
    from slam.trajectory import Trajectory

    errors = relation_errors(Trajectory(result.times, result.poses), relations, tolerance)
    firsts = np.array([s.first for s in result.stretches], dtype=np.int64)
    matched = errors.matched_index
    ends = [
        np.searchsorted(firsts, match_times(result.times, t[matched], tolerance), "right") - 1
        for t in (relations.t1, relations.t2)
    ]
    first_end, second_end = ends
    other = first_end != second_end
    stretch_of = np.concatenate([first_end, second_end[other]])
    trans = np.concatenate([errors.trans, errors.trans[other]])
    n = len(result.stretches)
    count = np.zeros(n, dtype=np.int64)
    total = np.zeros(n)
    largest = np.full(n, np.nan)
    np.add.at(count, stretch_of, 1)
    np.add.at(total, stretch_of, trans)
    np.fmax.at(largest, stretch_of, trans)
    mean = np.full(n, np.nan)
    mean[count > 0] = total[count > 0] / count[count > 0]
    return StretchRelations(count, mean, largest)


def rank_correlation(a: F64, b: F64) -> float:
    """Spearman's rank correlation of ``a`` and ``b`` over the pairs where both are finite
    (average ranks for ties; NaN with fewer than three pairs)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3:
        return math.nan

    def ranks(v: F64) -> F64:
        order = np.argsort(v, kind="stable")
        r = np.empty(v.size)
        r[order] = np.arange(v.size, dtype=np.float64)
        _, inverse, counts = np.unique(v, return_inverse=True, return_counts=True)
        sums = np.zeros(counts.size)
        np.add.at(sums, inverse, r)
        return (sums / counts)[inverse]

    ra, rb = ranks(a[ok]), ranks(b[ok])
    if ra.std() == 0 or rb.std() == 0:
        return math.nan
    return float(np.corrcoef(ra, rb)[0, 1])


def _round(value: float, digits: int) -> float | None:
    return None if not math.isfinite(value) else round(float(value), digits)


def stretch_summary(s: StretchScore, t0: float) -> dict[str, Any]:
    """JSON view of a stretch; ``t0`` (the run's first scan time) gives the relative times."""
    return {
        "index": s.index,
        "scans": [s.first, s.last],
        "time_s": [_round(s.t_start - t0, 2), _round(s.t_end - t0, 2)],
        "log_time": [round(s.t_start, 6), round(s.t_end, 6)],
        "path_m": [round(s.path_start, 2), round(s.path_end, 2)],
        "robot_xy": [round(v, 2) for v in s.robot_xy],
        "place_xy": [round(v, 2) for v in s.place_xy],
        "score": _round(s.score, 4),
        "returns": s.returns,
        "checked": s.checked,
        "agree": s.agree,
        "conflict_free": s.conflict_free,
        "conflict_through": s.conflict_through,
        "offset_m": _round(s.offset_m, 3),
    }


def summary(result: QualityResult) -> dict[str, Any]:
    """The JSON-ready report: overall figures, the worst stretches, every stretch, parameters."""
    t0 = float(result.times[0])
    totals = result.totals()
    judged = result.judged()
    scores = np.array([s.score for s in judged]) if judged else np.zeros(0)
    cfg = result.config
    out: dict[str, Any] = {
        "score": _round(result.score, 4),
        "coverage": _round(totals["checked"] / totals["returns"], 4) if totals["returns"] else None,
        "worst_score": _round(float(scores.min()), 4) if scores.size else None,
        "median_stretch_score": _round(float(np.median(scores)), 4) if scores.size else None,
        "flagged": len(result.flagged()),
        "stretches": len(result.stretches),
        "judged_stretches": len(judged),
        **totals,
        "worst": [
            {"rank": rank + 1, **stretch_summary(s, t0)} for rank, s in enumerate(result.worst())
        ],
        "parameters": {
            "resolution": cfg.resolution,
            "stretch_m": cfg.stretch_m,
            "separation_m": cfg.separation_m,
            "max_range_m": cfg.max_range_m,
            "tolerance_m": cfg.tolerance_m,
            "min_free_rays": cfg.min_free_rays,
            "min_incidence_deg": cfg.min_incidence_deg,
            "min_checked": cfg.min_checked,
            "min_coverage": cfg.min_coverage,
            "flag_below": cfg.flag_below,
        },
        "wall_s": round(result.wall_s, 3),
        "cpu_s": round(result.cpu_s, 3),
        "per_stretch": [stretch_summary(s, t0) for s in result.stretches],
    }
    return out
