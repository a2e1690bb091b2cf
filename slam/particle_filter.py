"""Particle-filter SLAM: the loop that turns scans and odometry into a trajectory and a map.

Both methods are the Bayes filter of the architecture: **predict** (sample the odometry motion
model for every particle), **weight** (a sensor model scores the scan at each particle's pose),
**resample** (systematic, when the effective sample size ``N_eff = 1/Σw²`` falls below a fraction
of the particle count) and **map** (integrate the scan).

``classic`` — the course's method, faithfully
    One shared log-odds map. Each particle's score is the map correlation: the number of scan
    endpoints on occupied cells, maximised over a local grid of pose offsets (the starter code's
    ``mapCorrelation`` search); weights are a softmax of the scores. The map is updated with
    Bresenham rays from the best particle, and the trajectory is the per-step best pose.

``rbpf`` — the default, a Rao-Blackwellised filter in the manner of GMapping
    Every particle carries its own map (a truncated distance field in copy-on-write tiles, see
    :mod:`slam.mapping`). An update runs only after ``rbpf.update_distance`` of travel or
    ``rbpf.update_angle`` of rotation; then each particle's sampled pose is refined by scan
    matching against its own map (Levenberg-Marquardt on the likelihood field, wide to narrow
    sigmas: the scan-matching proposal), weighted by the likelihood of the scan at the refined
    pose, and the scan's hits are added to its map. Resampling is adaptive (``N_eff``). The
    trajectory is the ancestry of the best particle at the end — the path that particle's map was
    built from — and scans between updates get poses from odometry, with the correction found at
    the next update spread along the way. The output occupancy grid is built from that final
    trajectory.

Kernels (:mod:`slam.kernels`) hold the loops over particles and beams; this module orchestrates,
and draws all noise from one ``numpy.random.Generator``, so a seed fixes the result whatever the
number of threads.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from slam.config import Config, RbpfConfig
from slam.errors import DataError
from slam.geometry import compose, relative, spread_corrections, wrap_angle
from slam.io.log import Log
from slam.io.plausibility import DataWarning, check_valid_beams
from slam.kernels.motion import sample_motion
from slam.kernels.resample import effective_sample_size, systematic_resample
from slam.kernels.scan import correlation_search
from slam.mapping import OccupancyGrid, ParticleMaps, likelihood_tables
from slam.odometry import scan_odometry

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ScanSequence:
    """The scans a filter processes, in order, with the odometry pose of each."""

    times: F64
    """``(N,)`` scan times (s)."""
    ranges: NDArray[np.float32]
    """``(N, B)`` ranges (m); NaN for invalid beams."""
    angles: F64
    """``(B,)`` or ``(N, B)`` beam angles in the laser frame (rad)."""
    odometry: F64
    """``(N, 3)`` odometry pose of the robot at each scan."""
    laser_offset: F64
    """``(3,)`` laser pose in the robot frame."""
    range_min: float
    """Shortest valid range (m)."""
    range_max: float
    """Longest range that counts as an obstacle hit (m)."""
    no_return: float
    """Readings at or beyond this mean "no return" (m)."""
    indices: NDArray[np.int64]
    """``(N,)`` index of each scan in the log."""

    def __len__(self) -> int:
        return int(self.times.shape[0])

    @property
    def num_beams(self) -> int:
        """Beams per scan (the widest scan when beam counts vary)."""
        return int(self.ranges.shape[1])

    @classmethod
    def from_log(cls, log: Log, config: Config) -> ScanSequence:
        """Select the scans to process (``filter.every``, ``filter.max_scans``) with odometry.

        :class:`DataError` when no selected scan has a valid beam, a :class:`DataWarning` when
        too many are sparse (:func:`slam.io.plausibility.check_valid_beams`).
        """
        if log.scans is None:
            raise DataError(f"{log.name}: the log has no laser scans to run SLAM on")
        scans = log.scans
        odometry = scan_odometry(log, config.robot)
        idx = np.arange(len(scans), dtype=np.int64)[:: config.filter.every]
        if config.filter.max_scans:
            idx = idx[: config.filter.max_scans]
        if idx.size == 0:
            raise DataError(f"{log.name}: no scans selected (every={config.filter.every})")
        lidar = config.lidar
        range_max = lidar.range_max if lidar.range_max is not None else scans.range_max
        no_return = lidar.no_return if lidar.no_return is not None else scans.no_return
        range_min = lidar.range_min if lidar.range_min is not None else scans.range_min
        angles = scans.angles if scans.angles.ndim == 1 else scans.angles[idx]
        ranges = np.ascontiguousarray(scans.ranges[idx])
        sparse = check_valid_beams(
            log, ranges, range_min, min(range_max, no_return), no_return, config.checks
        )
        if sparse is not None:  # the pipeline records warnings in metrics.json and on stderr
            warnings.warn(sparse, DataWarning, stacklevel=2)
        return cls(
            times=np.asarray(scans.time[idx], np.float64),
            ranges=ranges,
            angles=np.asarray(angles, np.float64),
            odometry=np.ascontiguousarray(odometry[idx]),
            laser_offset=np.asarray(scans.laser_offset, np.float64),
            range_min=float(range_min),
            range_max=float(min(range_max, no_return)),
            no_return=float(no_return),
            indices=idx,
        )

    def scan_period(self) -> float:
        """Nominal time between scans: the median positive time step (robust to CARMEN logs
        whose time stamps go backwards now and then)."""
        steps = np.diff(self.times)
        steps = steps[steps > 0]
        return float(np.median(steps)) if steps.size else 0.0

    def scan_angles(self, k: int) -> F64:
        """Beam angles of scan ``k``."""
        return self.angles if self.angles.ndim == 1 else self.angles[k]

    def endpoints(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Robot-frame endpoints ``(ex, ey)``, each ``(N, B)`` float32, NaN where not a return.

        Computed once for the whole sequence (vectorised) and cached.
        """
        cached = self.__dict__.get("_endpoints")
        if cached is None:
            r = self.ranges
            a = self.angles if self.angles.ndim == 2 else self.angles[None, :]
            ok = np.isfinite(r) & np.isfinite(a) & (r >= self.range_min) & (r < self.range_max)
            lx, ly, lt = self.laser_offset
            rr = np.where(ok, r, np.nan).astype(np.float32)
            ex = (lx + rr * np.cos(lt + a)).astype(np.float32)
            ey = (ly + rr * np.sin(lt + a)).astype(np.float32)
            cached = (ex, ey)
            object.__setattr__(self, "_endpoints", cached)
        return cached

    def hits(self, k: int, max_beams: int = 0) -> tuple[F64, F64]:
        """Robot-frame endpoints ``(ex, ey)`` of the obstacle returns of scan ``k``.

        With ``max_beams`` the returns are thinned to at most that many, evenly spread.
        """
        ex_all, ey_all = self.endpoints()
        valid = np.flatnonzero(~np.isnan(ex_all[k]))
        if max_beams and valid.size > max_beams:
            valid = valid[np.linspace(0, valid.size - 1, max_beams).round().astype(np.int64)]
        return (
            np.ascontiguousarray(ex_all[k, valid], dtype=np.float64),
            np.ascontiguousarray(ey_all[k, valid], dtype=np.float64),
        )

    def hits_with_normals(self, k: int, max_beams: int = 0) -> tuple[F64, F64, F64, F64]:
        """Robot-frame endpoints and unit surface normals ``(ex, ey, nx, ny)`` of scan ``k``.

        See :func:`surface_normals`; normals are estimated before thinning to ``max_beams``.
        """
        ex, ey = self.hits(k)
        lx, ly, _ = self.laser_offset
        nx, ny = surface_normals(ex, ey, lx, ly)
        if max_beams and ex.size > max_beams:
            pick = np.linspace(0, ex.size - 1, max_beams).round().astype(np.int64)
            ex, ey, nx, ny = ex[pick], ey[pick], nx[pick], ny[pick]
        return (
            np.ascontiguousarray(ex),
            np.ascontiguousarray(ey),
            np.ascontiguousarray(nx),
            np.ascontiguousarray(ny),
        )

    def rays(
        self, k: int, free_range_no_return: float, stride: int = 1
    ) -> tuple[F64, NDArray[np.bool_]]:
        """Robot-frame ray ends ``(K, 2)`` and hit flags for occupancy updates of scan ``k``.

        Returns are hits; readings between ``range_max`` and ``no_return`` clear free space up to
        ``range_max``; "no return" readings clear up to ``free_range_no_return`` (0: not at all).
        Only every ``stride``-th non-hit ray is kept (hits are always kept).
        """
        r = self.ranges[k].astype(np.float64)
        a = self.scan_angles(k)
        valid = np.isfinite(r) & np.isfinite(a) & (r >= self.range_min)
        hit = valid & (r < self.range_max)
        length = np.where(r < self.no_return, np.minimum(r, self.range_max), free_range_no_return)
        keep = hit | (valid & (length > 0))
        if stride > 1:
            thin = np.zeros_like(keep)
            thin[::stride] = True
            keep &= hit | thin
        lx, ly, lt = self.laser_offset
        c, s = np.cos(lt + a[keep]), np.sin(lt + a[keep])
        ends = np.stack([lx + length[keep] * c, ly + length[keep] * s], axis=1)
        return ends, hit[keep]


def surface_normals(
    ex: F64, ey: F64, sx: float, sy: float, gap: float = 0.1, relative_gap: float = 0.02
) -> tuple[F64, F64]:
    """Unit normals at scan endpoints ``(ex, ey)`` (in beam order), facing the sensor ``(sx, sy)``.

    The tangent at a point is the chord between its two neighbours when both are close (closer
    than ``gap + relative_gap·range``), else the chord to the one close neighbour; points with no
    close neighbour (isolated returns) face the sensor along their beam.
    """
    n = ex.shape[0]
    bx = sx - ex
    by = sy - ey
    rng = np.hypot(bx, by)
    rng = np.where(rng > 0, rng, 1.0)
    tx = np.zeros(n)
    ty = np.zeros(n)
    if n >= 2:
        dx = np.diff(ex)
        dy = np.diff(ey)
        limit = gap + relative_gap * np.minimum(rng[1:], rng[:-1])
        close = np.hypot(dx, dy) < limit
        # chord to the next neighbour (forward) and from the previous one (backward)
        fwd = np.zeros(n, dtype=bool)
        bwd = np.zeros(n, dtype=bool)
        fwd[:-1] = close
        bwd[1:] = close
        tx[:-1] += np.where(close, dx, 0.0)
        ty[:-1] += np.where(close, dy, 0.0)
        tx[1:] += np.where(close, dx, 0.0)
        ty[1:] += np.where(close, dy, 0.0)
        has = fwd | bwd
    else:
        has = np.zeros(n, dtype=bool)
    norm = np.hypot(tx, ty)
    has &= norm > 1e-9
    norm = np.where(has, norm, 1.0)
    nx = np.where(has, -ty / norm, bx / rng)
    ny = np.where(has, tx / norm, by / rng)
    flip = nx * bx + ny * by < 0
    nx = np.where(flip, -nx, nx)
    ny = np.where(flip, -ny, ny)
    return nx, ny


@dataclass
class StepRecord:
    """What an observer sees after each processed scan."""

    step: int
    """Number of the processed scan (0-based)."""
    scan_index: int
    """Index of the scan in the log."""
    time: float
    """Scan time (s)."""
    pose: F64
    """Current estimate: the pose of the highest-weight particle."""
    n_eff: float
    """Effective sample size after weighting."""
    max_weight: float
    """Largest normalised weight."""
    updated: bool
    """Whether the filter ran an update on this scan (``rbpf`` skips scans between updates)."""
    resampled: bool
    """Whether the particles were resampled on this scan."""
    particles: F64 | None = None
    """``(P, 3)`` particle poses (only on detail steps)."""
    weights: F64 | None = None
    """``(P,)`` normalised weights (only on detail steps)."""
    endpoints: F64 | None = None
    """``(K, 2)`` world positions of the scan's returns from ``pose`` (only on detail steps)."""


class Observer(Protocol):
    """Receives the filter's progress: progress bars, the rerun recorder, tests."""

    detail_every: int
    """Steps between records carrying particles and endpoints (0: never)."""
    map_every: int
    """Steps between map snapshots (0: never)."""

    def on_step(self, record: StepRecord) -> None:
        """Called after every processed scan."""

    def on_map(self, step: int, time: float, grid: OccupancyGrid) -> None:
        """Called every ``map_every`` steps with the current map."""


@dataclass
class SlamResult:
    """What a SLAM run produces."""

    times: F64
    """``(N,)`` times of the processed scans."""
    poses: F64
    """``(N, 3)`` final trajectory, one pose per processed scan."""
    scan_indices: NDArray[np.int64]
    """``(N,)`` log index of each processed scan."""
    grid: OccupancyGrid
    """The occupancy grid."""
    n_eff: F64
    """``(N,)`` effective sample size per processed scan."""
    max_weight: F64
    """``(N,)`` largest normalised weight per processed scan."""
    stats: dict = field(default_factory=dict)
    """Counters: updates, resamplings, particle-map memory, matching fallbacks."""


def _normalise(logw: F64) -> F64:
    w = np.exp(logw - logw.max())
    return w / w.sum()


def _world(pose: F64, ex: F64, ey: F64) -> F64:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.stack([pose[0] + c * ex - s * ey, pose[1] + s * ex + c * ey], axis=1)


def integrate_scan(grid: OccupancyGrid, seq: ScanSequence, k: int, pose: F64) -> None:
    """Bresenham log-odds update of ``grid`` with scan ``k`` taken at robot ``pose``."""
    cfg = grid.config
    ends, hit = seq.rays(k, cfg.free_range_no_return, cfg.free_beam_stride)
    sensor = compose(pose, seq.laser_offset)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    world = np.stack(
        [pose[0] + c * ends[:, 0] - s * ends[:, 1], pose[1] + s * ends[:, 0] + c * ends[:, 1]],
        axis=1,
    )
    grid.integrate(sensor[:2], world, hit)


def build_map(
    seq: ScanSequence, poses: F64, steps: NDArray[np.int64], config: Config
) -> OccupancyGrid:
    """Occupancy grid of the scans ``steps`` of ``seq`` taken at ``poses[steps]``."""
    grid = OccupancyGrid(config.map, center=(float(poses[0, 0]), float(poses[0, 1])))
    span = np.concatenate([poses[:, :2].min(axis=0) - 1.0, poses[:, :2].max(axis=0) + 1.0])
    grid.ensure_contains(*span)
    for k in steps:
        integrate_scan(grid, seq, int(k), poses[k])
    return grid.cropped(config.map.crop_margin_m)


def _notify(
    observer: Observer | None,
    step: int,
    seq: ScanSequence,
    pose: F64,
    n_eff: float,
    max_weight: float,
    updated: bool,
    resampled: bool,
    particles: F64,
    weights: F64,
    hit_xy: tuple[F64, F64] | None,
) -> None:
    if observer is None:
        return
    record = StepRecord(
        step=step,
        scan_index=int(seq.indices[step]),
        time=float(seq.times[step]),
        pose=pose.copy(),
        n_eff=float(n_eff),
        max_weight=float(max_weight),
        updated=updated,
        resampled=resampled,
    )
    if observer.detail_every and step % observer.detail_every == 0:
        record.particles = particles.copy()
        record.weights = weights.copy()
        ex, ey = hit_xy if hit_xy is not None else seq.hits(step, 720)
        record.endpoints = _world(pose, ex, ey)
    observer.on_step(record)


def run_classic(seq: ScanSequence, config: Config, observer: Observer | None = None) -> SlamResult:
    """The course's particle filter (see the module docstring)."""
    fc, cc = config.filter, config.classic
    rng = np.random.default_rng(fc.seed)
    n = len(seq)
    p = fc.particles
    alphas = np.asarray(fc.motion_alphas, np.float64)
    floor = np.asarray(cc.motion_floor, np.float64)
    yaw_offsets = cc.yaw_step * np.arange(-cc.yaw_steps, cc.yaw_steps + 1, dtype=np.float64)
    particles = np.tile(seq.odometry[0], (p, 1))
    logw = np.zeros(p)
    map_config = dataclasses.replace(config.map, log_odds_miss=cc.log_odds_miss)
    grid = OccupancyGrid(map_config, center=(float(particles[0, 0]), float(particles[0, 1])))
    integrate_scan(grid, seq, 0, particles[0])
    poses = np.empty((n, 3))
    poses[0] = particles[0]
    n_eff_log = np.full(n, float(p))
    max_w_log = np.full(n, 1.0 / p)
    resamples = 0
    corr = np.empty(p, dtype=np.int64)
    offsets = np.empty((p, 3))
    weights = np.full(p, 1.0 / p)
    _notify(observer, 0, seq, poses[0], p, 1.0 / p, True, False, particles, weights, None)
    for k in range(1, n):
        # predict
        increment = relative(seq.odometry[k - 1], seq.odometry[k])
        noise = rng.standard_normal((p, 3))
        particles = sample_motion(particles, increment, noise, alphas, floor)
        # weight: map correlation with a local search
        ex, ey = seq.hits(k, cc.beams)
        occupied = grid.occupied()
        correlation_search(
            occupied,
            float(grid.origin[0]),
            float(grid.origin[1]),
            grid.resolution,
            particles,
            ex,
            ey,
            cc.xy_radius,
            yaw_offsets,
            corr,
            offsets,
        )
        if cc.snap_to_best:
            particles = particles + offsets
            particles[:, 2] = wrap_angle(particles[:, 2])
        logw = logw + corr / cc.temperature
        logw -= logw.max()
        weights = _normalise(logw)
        n_eff = effective_sample_size(weights)
        best = int(np.argmax(weights))
        poses[k] = particles[best]
        n_eff_log[k] = n_eff
        max_w_log[k] = weights[best]
        # map from the best particle
        integrate_scan(grid, seq, k, particles[best])
        # resample
        resampled = n_eff < fc.resample_threshold * p
        if resampled:
            idx = systematic_resample(weights, rng.random())
            particles = particles[idx]
            logw = np.zeros(p)
            resamples += 1
        _notify(
            observer, k, seq, poses[k], n_eff, weights[best], True, resampled,
            particles, weights, (ex, ey),
        )  # fmt: skip
        if observer is not None and observer.map_every and k % observer.map_every == 0:
            observer.on_map(k, float(seq.times[k]), grid)
    return SlamResult(
        times=seq.times.copy(),
        poses=poses,
        scan_indices=seq.indices.copy(),
        grid=grid.cropped(config.map.crop_margin_m),
        n_eff=n_eff_log,
        max_weight=max_w_log,
        stats={"updates": n, "resamples": resamples},
    )


def motion_covariance(poses: F64, increment: F64, alphas: F64, floor: F64) -> F64:
    """World-frame covariance ``(P, 3, 3)`` of the odometry motion model for ``increment``.

    The same standard deviations as :func:`slam.kernels.motion.sample_motion` (robot frame),
    rotated into the world frame by each particle's heading.
    """
    d = float(np.hypot(increment[0], increment[1]))
    a = abs(float(increment[2]))
    sx = alphas[0] * d + alphas[1] * a + floor[0]
    sy = alphas[2] * d + alphas[1] * a + floor[1]
    st = alphas[3] * a + alphas[4] * d + floor[2]
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    cov = np.zeros((poses.shape[0], 3, 3))
    cov[:, 0, 0] = c * c * sx**2 + s * s * sy**2
    cov[:, 1, 1] = s * s * sx**2 + c * c * sy**2
    cov[:, 0, 1] = cov[:, 1, 0] = c * s * (sx**2 - sy**2)
    cov[:, 2, 2] = st**2
    return cov


def sample_around(
    poses: F64,
    hessian: F64,
    temperature: float,
    motion_cov: F64 | None,
    spread: float,
    rng: np.random.Generator,
) -> F64:
    """Draw one pose per particle around its matched pose: the scan-matching proposal.

    The proposal combines the (tempered) scan likelihood, whose Gauss-Newton Hessian at the
    match is ``H``, with the odometry motion model ``Σ_m`` (Grisetti et al. 2007's Gaussian
    approximation of the optimal proposal): ``Σ = spread · (H / T + Σ_m⁻¹)⁻¹``. Where the scan
    constrains the pose (walls in every direction) the spread is small; along a corridor, where
    it does not, the spread is the odometry's, so particles explore the along-corridor position
    that a later loop closure will decide. Without ``motion_cov`` the proposal is the tempered
    scan likelihood alone, ``spread · T · (H + I)⁻¹``.
    """
    if motion_cov is None:
        # scan likelihood only, with a small ridge where the scan constrains nothing
        info = (hessian + np.eye(3)) / temperature
    else:
        info = hessian / temperature + np.linalg.inv(motion_cov)
    cov = spread * np.linalg.inv(info)
    cov = 0.5 * (cov + np.transpose(cov, (0, 2, 1)))
    chol = np.linalg.cholesky(cov + np.eye(3) * 1e-12)
    noise = rng.standard_normal((poses.shape[0], 3))
    out = poses + np.einsum("pij,pj->pi", chol, noise)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def _update_due(moved: F64, elapsed: float, rc: RbpfConfig) -> bool:
    """Whether the filter updates on a scan (GMapping's linear/angular/temporal update rule).

    After ``update_distance`` of travel or ``update_angle`` of rotation since the last update;
    or, once ``update_interval_s`` has passed, after any motion beyond ``update_min_motion``
    (m, and rad): a slow robot is still corrected often, a standing one is never re-weighted with
    the same view (which would make the weights overconfident).
    """
    dist = float(np.hypot(moved[0], moved[1]))
    turn = abs(float(moved[2]))
    if dist >= rc.update_distance or turn >= rc.update_angle:
        return True
    if rc.update_interval_s > 0 and elapsed >= rc.update_interval_s:
        return dist >= rc.update_min_motion or turn >= rc.update_min_motion
    return False


def _evidence_share(moved: F64, rc: RbpfConfig) -> float:
    """Share of a full update's evidence an update carries: ``min(1, max(d/D, |θ|/Θ))``.

    Scans taken a few centimetres apart mostly repeat each other; weighting every one of them
    fully would count the same evidence many times and deplete the particles. Scaling the
    log-likelihood by the motion since the last update (relative to ``update_distance`` ``D`` and
    ``update_angle`` ``Θ``) makes the evidence grow with motion, whatever the update rate.
    """
    dist = float(np.hypot(moved[0], moved[1])) / rc.update_distance
    turn = abs(float(moved[2])) / rc.update_angle
    return min(1.0, max(dist, turn))


def _interpolate_between_updates(
    seq: ScanSequence, update_steps: NDArray[np.int64], update_poses: F64
) -> F64:
    """Poses of every scan from the poses at update scans and odometry in between.

    A scan between updates ``a`` and ``b`` is placed by odometry from both ends and the two are
    blended by the fraction of odometry motion covered, so the correction found at ``b`` is
    spread over the stretch instead of appearing as a jump.
    """
    odo = seq.odometry
    step = np.zeros(len(seq))
    delta = relative(odo[:-1], odo[1:])
    step[1:] = np.hypot(delta[:, 0], delta[:, 1]) + 0.2 * np.abs(delta[:, 2])
    return spread_corrections(odo, update_steps, update_poses, np.cumsum(step))


def run_rbpf(seq: ScanSequence, config: Config, observer: Observer | None = None) -> SlamResult:
    """The default method (see the module docstring)."""
    fc, rc = config.filter, config.rbpf
    rng = np.random.default_rng(fc.seed)
    n = len(seq)
    p = fc.particles
    alphas = np.asarray(fc.motion_alphas, np.float64)
    floor = np.asarray(fc.motion_floor, np.float64)
    luts = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    start = seq.odometry[0]
    maps = ParticleMaps(
        p,
        rc.resolution or config.map.resolution,
        rc.dmax,
        tile=rc.tile,
        center=(float(start[0]), float(start[1])),
        size_m=config.map.initial_size_m,
        grow_margin_m=config.map.grow_margin_m,
        signed=rc.field == "plane",
    )
    particles = np.tile(start, (p, 1))
    logw = np.zeros(p)
    weights = np.full(p, 1.0 / p)

    def reach(k: int) -> float:
        hx, hy = seq.hits(k)
        return float(np.sqrt((hx * hx + hy * hy).max())) if hx.size else 0.0

    def insert(k: int, poses: F64) -> None:
        hx, hy, nx, ny = _hits_for_insert(seq, k, rc.insert_beams, maps.signed)
        r = reach(k) + rc.dmax + 1.0
        lo = poses[:, :2].min(axis=0) - r
        hi = poses[:, :2].max(axis=0) + r
        maps.ensure_contains(lo[0], lo[1], hi[0], hi[1])
        maps.insert(np.ascontiguousarray(poses), hx, hy, nx, ny, rc.skip_insert_below)

    # the first scan builds the initial map, shared by every particle
    insert(0, particles[:1])
    maps.share_from(0)

    update_steps = [0]
    update_particles = [particles.copy()]
    update_parents = [np.arange(p)]
    parents_next = np.arange(p)
    n_eff_log = np.full(n, float(p))
    max_w_log = np.full(n, 1.0 / p)
    resamples = 0
    fallbacks = 0
    peak_tiles = maps.tiles_in_use
    peak_map_bytes = maps.memory_bytes()
    last_odo = seq.odometry[0]
    live = None
    if observer is not None and observer.map_every:
        live = OccupancyGrid(config.map, center=(float(start[0]), float(start[1])))
        integrate_scan(live, seq, 0, start)
    _notify(observer, 0, seq, start, p, 1.0 / p, True, False, particles, weights, None)

    period = seq.scan_period()
    last_k = 0
    for k in range(1, n):
        moved = relative(last_odo, seq.odometry[k])
        best = int(np.argmax(weights))
        if not _update_due(moved, (k - last_k) * period, rc):
            n_eff_log[k] = n_eff_log[k - 1]
            max_w_log[k] = max_w_log[k - 1]
            if observer is not None:
                current = compose(particles[best], moved)
                _notify(
                    observer, k, seq, current, n_eff_log[k], max_w_log[k], False, False,
                    particles, weights, None,
                )  # fmt: skip
            continue
        # predict
        noise = rng.standard_normal((p, 3))
        predicted = sample_motion(particles, moved, noise, alphas, floor)
        # proposal: scan matching of every particle against its own map, then weight
        ex, ey = seq.hits(k, rc.match_beams)
        r = reach(k) + rc.dmax + 1.0
        lo = predicted[:, :2].min(axis=0) - r
        hi = predicted[:, :2].max(axis=0) + r
        maps.ensure_contains(lo[0], lo[1], hi[0], hi[1])
        match = maps.match(
            predicted, ex, ey, luts, rc.max_iterations, rc.tolerance, rc.min_inliers,
            rc.coarse_stride,
        )  # fmt: skip
        particles = match.poses
        share = _evidence_share(moved, rc)
        if rc.proposal_spread > 0:
            motion_cov = (
                motion_covariance(predicted, moved, alphas, floor)
                if rc.proposal_motion_prior
                else None
            )
            particles = sample_around(
                particles, match.hessian, rc.temperature, motion_cov, rc.proposal_spread, rng
            )
        fallbacks += int(np.count_nonzero(match.inliers < rc.min_inliers))
        logw = logw + share * match.loglik / rc.temperature
        logw -= logw.max()
        weights = _normalise(logw)
        n_eff = effective_sample_size(weights)
        best = int(np.argmax(weights))
        n_eff_log[k] = n_eff
        max_w_log[k] = weights[best]
        # map: every particle adds the scan to its own map
        insert(k, particles)
        update_steps.append(k)
        update_particles.append(particles.copy())
        update_parents.append(parents_next)
        # resample
        resampled = n_eff < fc.resample_threshold * p
        if resampled:
            idx = systematic_resample(weights, rng.random())
            particles = particles[idx]
            maps.resample(idx)
            logw = np.zeros(p)
            weights = np.full(p, 1.0 / p)
            parents_next = idx
            resamples += 1
        else:
            parents_next = np.arange(p)
        peak_tiles = max(peak_tiles, maps.tiles_in_use)
        peak_map_bytes = max(peak_map_bytes, maps.memory_bytes())
        last_odo = seq.odometry[k]
        last_k = k
        best_now = int(np.argmax(weights))
        if live is not None:
            integrate_scan(live, seq, k, particles[best_now])
        _notify(
            observer, k, seq, particles[best_now], n_eff, max_w_log[k], True, resampled,
            particles, weights, (ex, ey),
        )  # fmt: skip
        if live is not None and observer is not None and k % observer.map_every == 0:
            observer.on_map(k, float(seq.times[k]), live)

    # the final trajectory: ancestry of the best particle
    best = int(np.argmax(weights))
    steps = np.asarray(update_steps, dtype=np.int64)
    lineage = np.empty((len(steps), 3))
    for u in range(len(steps) - 1, -1, -1):
        lineage[u] = update_particles[u][best]
        best = int(update_parents[u][best])
    loop_stats: dict = {}
    if config.loops.enabled and len(steps) > 1:
        from slam.graph import close_loops

        closed = close_loops(seq, steps, lineage, config)
        lineage = closed.poses
        loop_stats = {
            "loop_candidates": closed.candidates,
            "loop_closures": closed.accepted,
            "loop_correction_max_m": round(closed.correction_max_m, 3),
        }
    for _ in range(rc.refine_passes):
        lineage = refine_trajectory(seq, lineage, steps, config)
    poses = _interpolate_between_updates(seq, steps, lineage)
    grid = build_map(seq, poses, steps, config)
    return SlamResult(
        times=seq.times.copy(),
        poses=poses,
        scan_indices=seq.indices.copy(),
        grid=grid,
        n_eff=n_eff_log,
        max_weight=max_w_log,
        stats={
            "updates": int(len(steps)),
            "resamples": resamples,
            "match_fallbacks": fallbacks,
            "peak_tiles": int(peak_tiles),
            "peak_particle_map_mb": round(peak_map_bytes / 2**20, 1),
            **loop_stats,
        },
    )


def _hits_for_insert(
    seq: ScanSequence, k: int, max_beams: int, normals: bool
) -> tuple[F64, F64, F64, F64]:
    """Hits of scan ``k`` to insert into particle maps, with normals only if the field is signed."""
    if normals:
        return seq.hits_with_normals(k, max_beams)
    hx, hy = seq.hits(k, max_beams)
    return hx, hy, hx, hy  # the unsigned field ignores normals


def refine_trajectory(
    seq: ScanSequence, poses: F64, steps: NDArray[np.int64], config: Config
) -> F64:
    """Re-register the scans ``steps`` (taken at ``poses``) against the map they build together.

    The filter's lineage carries the jitter of the proposal's sampling (that is what gives the
    filter the diversity to close loops); with the best lineage chosen, one map is built from its
    scans and each of them is registered against that map again, which keeps the global shape and
    removes the jitter. Returns the refined poses ``(len(steps), 3)``.
    """
    rc = config.rbpf
    res = rc.resolution or config.map.resolution
    maps = ParticleMaps(
        1,
        res,
        rc.dmax,
        tile=rc.tile,
        center=(float(poses[0, 0]), float(poses[0, 1])),
        size_m=config.map.initial_size_m,
        grow_margin_m=config.map.grow_margin_m,
        signed=rc.field == "plane",
    )
    reach = 0.0
    for pose, k in zip(poses, steps, strict=True):
        hx, hy, nx, ny = _hits_for_insert(seq, int(k), rc.insert_beams, maps.signed)
        if hx.size == 0:
            continue
        reach = max(reach, float(np.sqrt((hx * hx + hy * hy).max())))
        r = reach + rc.dmax + 1.0
        maps.ensure_contains(pose[0] - r, pose[1] - r, pose[0] + r, pose[1] + r)
        maps.insert(np.ascontiguousarray(pose[None, :]), hx, hy, nx, ny, rc.skip_insert_below)
    width = max(1, min(rc.match_beams or seq.num_beams, seq.num_beams))
    ex = np.zeros((len(steps), width))
    ey = np.zeros((len(steps), width))
    counts = np.zeros(len(steps), dtype=np.int64)
    for i, k in enumerate(steps):
        hx, hy = seq.hits(int(k), width)
        counts[i] = hx.size
        ex[i, : hx.size] = hx
        ey[i, : hy.size] = hy
    luts = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    return maps.register(
        poses, ex, ey, counts, luts, rc.max_iterations, rc.tolerance, rc.min_inliers,
        coarse_stride=rc.coarse_stride,
    )  # fmt: skip


def run_slam(
    seq: ScanSequence, config: Config, observer: Observer | None = None
) -> tuple[SlamResult, float]:
    """Run the configured method; return the result and the wall time (s)."""
    start = time.perf_counter()
    if config.filter.method == "classic":
        result = run_classic(seq, config, observer)
    elif config.filter.method == "rbpf":
        result = run_rbpf(seq, config, observer)
    else:
        raise ValueError(f"run_slam does not handle method {config.filter.method!r}")
    return result, time.perf_counter() - start
