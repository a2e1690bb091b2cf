"""Particle-filter SLAM, the filter itself: one step per scan, as named parts.

Both methods are the Bayes filter of the architecture: **predict** (sample the odometry motion
model for every particle), **weight** (a sensor model scores the scan at each particle's pose),
**resample** (systematic, when the effective sample size ``N_eff = 1/Σw²`` falls below a fraction
of the particle count) and **map** (integrate the scan). A filter object holds that state and
advances it by :meth:`~RbpfFilter.step`; :meth:`~RbpfFilter.finish` hands a :class:`FilterOutput`
to the post-filter stages (:mod:`slam.stages`: loop closing, re-registration, placement of the
scans between updates, the final map). :class:`slam.online.Slam` drives both.

``classic`` — the course's method, faithfully (:class:`ClassicFilter`)
    One shared log-odds map. Each particle's score is the map correlation: the number of scan
    endpoints on occupied cells, maximised over a local grid of pose offsets (the starter code's
    ``mapCorrelation`` search); weights are a softmax of the scores. The map is updated with
    Bresenham rays from the best particle, and the trajectory is the per-step best pose.

``rbpf`` — the default, a Rao-Blackwellised filter in the manner of GMapping (:class:`RbpfFilter`)
    Every particle carries its own map (a truncated distance field in copy-on-write tiles, see
    :mod:`slam.mapping`). An update runs only when the :class:`UpdateRule` says so (after
    ``rbpf.update_distance`` of travel, ``rbpf.update_angle`` of rotation, or a while of slow
    motion); then each particle's sampled pose is refined by scan matching against its own map
    (Levenberg-Marquardt on the likelihood field, wide to narrow sigmas: the scan-matching
    proposal), weighted by the likelihood of the scan at the refined pose, and the scan's hits are
    added to its map. Resampling is adaptive (``N_eff``); the :class:`Lineage` records who
    descends from whom. The filter's output is the ancestry of the best particle at the end — the
    path that particle's map was built from; the stages turn it into the final trajectory and map.

Kernels (:mod:`slam.kernels`) hold the loops over particles and beams; this module orchestrates,
and draws all noise from the run's one ``numpy.random.Generator``, so a seed fixes the result
whatever the number of threads.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import statistics
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import Config, RbpfConfig
from slam.geometry import compose, relative, transform_points, wrap_angle
from slam.kernels.motion import sample_motion
from slam.kernels.resample import effective_sample_size, systematic_resample
from slam.kernels.scan import correlation_search
from slam.kernels.vacancy import LIVE, SEEN_THROUGH, VacancyView
from slam.mapping import (
    MatchResult,
    OccupancyGrid,
    ParticleMaps,
    VacancyGrid,
    likelihood_tables,
)
from slam.scans import ScanSequence

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class UpdateRule:
    """When the ``rbpf`` filter updates, and how much evidence an update carries.

    GMapping's linear/angular/temporal rule: an update after ``distance`` of travel or ``angle``
    of rotation since the last update; or, once ``interval_s`` has passed, after any motion beyond
    ``min_motion`` (m, and rad) — a slow robot is still corrected often, a standing one is never
    re-weighted with the same view (which would make the weights overconfident).
    """

    distance: float
    """Travel that triggers an update (m)."""
    angle: float
    """Rotation that triggers an update (rad)."""
    interval_s: float
    """Time after which any motion beyond ``min_motion`` triggers an update (s); 0: never."""
    min_motion: float
    """Least motion for the interval clause (m, and rad)."""

    @classmethod
    def from_config(cls, rc: RbpfConfig) -> UpdateRule:
        """The rule of the ``[rbpf]`` section."""
        return cls(rc.update_distance, rc.update_angle, rc.update_interval_s, rc.update_min_motion)

    def due(self, moved: F64, elapsed: float) -> bool:
        """Whether to update after the odometry motion ``moved`` ``(dx, dy, dθ)`` and ``elapsed``
        seconds since the last update."""
        dist = float(np.hypot(moved[0], moved[1]))
        turn = abs(float(moved[2]))
        if dist >= self.distance or turn >= self.angle:
            return True
        if self.interval_s > 0 and elapsed >= self.interval_s:
            return dist >= self.min_motion or turn >= self.min_motion
        return False

    def evidence_share(self, moved: F64) -> float:
        """Share of a full update's evidence an update carries: ``min(1, max(d/D, |θ|/Θ))``.

        Scans taken a few centimetres apart mostly repeat each other; weighting every one of them
        fully would count the same evidence many times and deplete the particles. Scaling the
        log-likelihood by the motion since the last update (relative to ``distance`` ``D`` and
        ``angle`` ``Θ``) makes the evidence grow with motion, whatever the update rate.
        """
        dist = float(np.hypot(moved[0], moved[1])) / self.distance
        turn = abs(float(moved[2])) / self.angle
        return min(1.0, max(dist, turn))


class Lineage:
    """The particles' ancestry over the filter's updates.

    Update ``u`` (at processed scan ``steps[u]``) stores every particle's pose and the index of
    its parent among the particles of update ``u − 1`` (after the resampling between them).
    :meth:`ancestry` follows one particle back to the first update: the path its map was built
    from.
    """

    def __init__(self, poses: F64, step: int = 0) -> None:
        count = poses.shape[0]
        self._steps: list[int] = [int(step)]
        self._poses: list[F64] = [np.array(poses, dtype=np.float64)]
        self._parents: list[NDArray[np.int64]] = [np.arange(count, dtype=np.int64)]

    def __len__(self) -> int:
        return len(self._steps)

    @property
    def particles(self) -> int:
        """Particles per update."""
        return int(self._poses[0].shape[0])

    @property
    def steps(self) -> NDArray[np.int64]:
        """``(U,)`` processed-scan number of each update."""
        return np.asarray(self._steps, dtype=np.int64)

    def record(self, step: int, poses: F64, parents: NDArray[np.int64]) -> None:
        """Add update ``step``: the particles' ``poses`` and each one's ``parents`` index."""
        parents = np.asarray(parents, dtype=np.int64)
        if poses.shape != (self.particles, 3) or parents.shape != (self.particles,):
            raise ValueError(
                f"lineage: expected ({self.particles}, 3) poses and ({self.particles},) parents, "
                f"found {poses.shape} and {parents.shape}"
            )
        if step <= self._steps[-1]:
            raise ValueError(f"lineage: update steps must increase, {step} after {self._steps[-1]}")
        self._steps.append(int(step))
        self._poses.append(np.array(poses, dtype=np.float64))
        self._parents.append(parents)

    def ancestry(self, particle: int) -> F64:
        """``(U, 3)`` poses of ``particle`` of the last update and of its ancestors, oldest first."""
        out = np.empty((len(self), 3))
        for u in range(len(self) - 1, -1, -1):
            out[u] = self._poses[u][particle]
            particle = int(self._parents[u][particle])
        return out


@dataclass
class StepOutcome:
    """What one filter step did (the filter's view; :class:`slam.online.Slam` reports it)."""

    step: int
    """Number of the processed scan (0-based)."""
    pose: F64
    """``(3,)`` current estimate: the pose of :attr:`RbpfFilter.best` (the highest weight at the
    last update; after a resampling, its first copy)."""
    particles: F64
    """``(P, 3)`` particle poses after the step (between ``rbpf`` updates: at the last update)."""
    weights: F64
    """``(P,)`` normalised weights as the step computed them (before a resampling)."""
    n_eff: float
    """Effective sample size after weighting."""
    max_weight: float
    """Largest normalised weight."""
    updated: bool
    """Whether the filter ran an update on this scan."""
    resampled: bool
    """Whether the particles were resampled on this scan."""
    motion: F64 | None = None
    """``rbpf`` between updates: odometry motion since the last update (the estimate moves the
    particles by it)."""
    hits: tuple[F64, F64] | None = None
    """Robot-frame hits the step weighed the scan with (``None``: it did not use the scan)."""


@dataclass
class FilterOutput:
    """What a filter hands to the post-filter stages: nodes, diagnostics, maybe the final parts.

    The stages (:mod:`slam.stages`) refine ``node_poses``, place every scan (``poses``) and build
    the map (``grid``); a filter that already has them (``classic``) fills them in itself.
    """

    scans: ScanSequence
    """Every processed scan with its odometry."""
    steps: NDArray[np.int64]
    """``(U,)`` processed-scan numbers of the nodes (the filter's updates)."""
    node_poses: F64
    """``(U, 3)`` pose of each node."""
    n_eff: F64
    """``(N,)`` effective sample size per processed scan."""
    max_weight: F64
    """``(N,)`` largest normalised weight per processed scan."""
    stats: dict[str, Any] = field(default_factory=dict)
    """Counters: updates, resamplings, particle-map memory, matching fallbacks, stage figures."""
    poses: F64 | None = None
    """``(N, 3)`` pose of every processed scan, once placed."""
    grid: OccupancyGrid | None = None
    """The output occupancy grid, once built."""


def normalise(logw: F64) -> F64:
    """Normalised weights from log-weights (shifted by their maximum first)."""
    w = np.exp(logw - logw.max())
    return w / w.sum()


def cloud_covariance(particles: F64, weights: F64) -> F64:
    """``(3, 3)`` weighted covariance of a particle cloud ``(P, 3)`` about its weighted mean
    (the heading's mean is circular and deviations from it are wrapped)."""
    w = np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    mean_xy = w @ particles[:, :2]
    mean_theta = np.arctan2(w @ np.sin(particles[:, 2]), w @ np.cos(particles[:, 2]))
    deviation = particles - np.array([mean_xy[0], mean_xy[1], mean_theta])
    deviation[:, 2] = wrap_angle(deviation[:, 2])
    return (deviation * w[:, None]).T @ deviation


def integrate_scan(grid: OccupancyGrid, seq: ScanSequence, k: int, pose: F64) -> None:
    """Bresenham log-odds update of ``grid`` with scan ``k`` taken at robot ``pose``."""
    cfg = grid.config
    ends, hit = seq.rays(k, cfg.free_range_no_return, cfg.free_beam_stride)
    sensor = compose(pose, seq.laser_offset)
    grid.integrate(sensor[:2], transform_points(pose, ends), hit)


def vacancy_grid(config: Config, center: F64, resolution: float) -> VacancyGrid | None:
    """The ``rbpf`` filter's vacancy grid around ``center``: cells twice the particle maps'
    ``resolution``, rays counted up to ``rbpf.dmax`` short of their ends (None:
    ``rbpf.vacate_after = 0``)."""
    rc = config.rbpf
    if rc.vacate_after == 0:
        return None
    return VacancyGrid(
        2.0 * resolution, (float(center[0]), float(center[1])), rc.vacate_after, rc.dmax,
        config.map.initial_size_m, config.map.grow_margin_m,
    )  # fmt: skip


def observe_scan(grid: VacancyGrid, seq: ScanSequence, k: int, pose: F64) -> None:
    """Scan ``k`` taken at robot ``pose`` into the vacancy ``grid``: its rays (returns and
    readings past the laser's range) and its returns with their surface normals."""
    ends, _ = seq.rays(k, 0.0)
    hx, hy, nx, ny = seq.hits_with_normals(k)
    sensor = compose(pose, seq.laser_offset)
    hits = transform_points(pose, np.stack([hx, hy], axis=1))
    normals = np.arctan2(ny, nx) + pose[2]
    grid.observe(sensor[:2], transform_points(pose, ends), hits, normals)


def hits_for_insert(
    seq: ScanSequence, k: int, max_beams: int, normals: bool
) -> tuple[F64, F64, F64, F64]:
    """Hits of scan ``k`` to insert into particle maps, with normals only if the field is signed."""
    if normals:
        return seq.hits_with_normals(k, max_beams)
    hx, hy = seq.hits(k, max_beams)
    return hx, hy, hx, hy  # the unsigned field ignores normals


def scan_reach(seq: ScanSequence, k: int) -> float:
    """Distance (m) of the farthest hit of scan ``k`` from the robot (0 without hits)."""
    hx, hy = seq.hits(k)
    return float(np.sqrt((hx * hx + hy * hy).max())) if hx.size else 0.0


def particle_maps(
    config: Config, center: F64, particles: int, resolution: float = 0.0
) -> ParticleMaps:
    """Empty ``rbpf`` particle maps around ``center`` (geometry from ``[rbpf]`` and ``[map]``;
    ``resolution``, when given, instead of the filter's cell size)."""
    rc = config.rbpf
    return ParticleMaps(
        particles,
        resolution or rc.resolution or config.map.resolution,
        rc.dmax,
        tile=rc.tile,
        center=(float(center[0]), float(center[1])),
        size_m=config.map.initial_size_m,
        grow_margin_m=config.map.grow_margin_m,
        signed=rc.field == "plane",
    )


class RbpfFilter:
    """The ``rbpf`` method's state and its step (see the module docstring).

    Made on the first scan of ``scans`` (which builds the initial map every particle shares);
    :meth:`step` then processes each further scan appended to ``scans``.
    """

    def __init__(self, scans: ScanSequence, config: Config, rng: np.random.Generator) -> None:
        fc, rc = config.filter, config.rbpf
        self.scans = scans
        self.config = config
        self.rng = rng
        self.rule = UpdateRule.from_config(rc)
        self.alphas = np.asarray(fc.motion_alphas, np.float64)
        self.floor = np.asarray(fc.motion_floor, np.float64)
        self.luts = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
        p = fc.particles
        start = scans.odometry[0]
        self.maps = particle_maps(config, start, p)
        self.vacancy = vacancy_grid(config, start, self.maps.geometry.resolution)
        """Which hits later rays went through (None: ``rbpf.vacate_after = 0``)."""
        self._reach = (-1, 0.0)  # (scan, its reach) of the last _make_room
        self.particles = np.tile(start, (p, 1))
        self.logw = np.zeros(p)
        self.weights = np.full(p, 1.0 / p)
        # the first scan builds the initial map, shared by every particle
        self._insert(0, self.particles[:1])
        self.maps.share_from(0)
        self._observe(0, start)
        self.lineage = Lineage(self.particles)
        self.mapped = bool(scans.hits(0)[0].size)
        """Whether a scan with a return has built the map yet (scan 0 unless the laser started
        blind: then the first scan that sees, :meth:`_first_map`)."""
        self.blind = 0
        """Updates that were due at a scan without a single return, and so were none."""
        self.parents = np.arange(p)
        """Parent of each current particle among those of the last lineage record."""
        self.best = 0
        """The particle the estimate follows: the highest weight at the last update, or after a
        resampling the first copy of it (the weights are then uniform, and any index would do
        for ``argmax``)."""
        self.last_odometry = start
        self.last_update = 0
        self.n_eff_log = [float(p)]
        self.max_weight_log = [1.0 / p]
        self.resamples = 0
        self.fallbacks = 0
        self.retries = 0
        self.probes = 0
        self.travelled = 0.0
        """The odometry's travel (m) over the updates so far (what ``rbpf.probe_evidence_per_m``
        is taken of)."""
        self.gross_turns = 0
        """Updates whose best first match turned the predicted heading by at least the basin
        probe's smallest rotation (the evidence that opens the probe,
        ``rbpf.probe_evidence_per_m``)."""
        self.gross_shifts = 0
        """Updates whose best first match moved the predicted position by at least the
        translational probe's smallest shift (the evidence that opens it)."""
        self.shift_probes = 0
        """Firings of the translational probe."""
        self.recent_best: list[float] = []
        """Best per-beam log-likelihood of the first match of the last ``rbpf.retry_window``
        updates (the basin probe's reference)."""
        self.recent_loglik: list[float] = []
        """Best per-beam log-likelihood of the last ``rbpf.retry_window`` updates."""
        self.peak_tiles = self.maps.tiles_in_use
        self.peak_map_bytes = self.maps.memory_bytes()
        self.first = StepOutcome(0, start, self.particles, self.weights, p, 1.0 / p, True, False)
        """The outcome of scan 0 (the initial map)."""

    @functools.cached_property
    def probe_yaws(self) -> F64:
        """The basin probe's turns of the best particle's predicted pose (rad):
        ``rbpf.probe_yaw``, then the same turns the other way."""
        yaws = np.asarray(self.config.rbpf.probe_yaw, dtype=np.float64)
        return np.concatenate([yaws, -yaws])

    @property
    def probe_open(self) -> bool:
        """Whether the basin probe may fire at the next update: ``rbpf.probe_gain`` is set and
        the updates so far show an odometry that errs by the probe's rotations
        (``rbpf.probe_evidence_per_m``, ``rbpf.probe_evidence_count``)."""
        return self._evidence(self.gross_turns)

    @property
    def shift_probe_open(self) -> bool:
        """Whether the translational probe may fire at the next update: shifts to try
        (``rbpf.probe_shift``) and the same rule as :attr:`probe_open` over the updates whose
        first match moved the predicted position by the smallest of them."""
        return bool(self.config.rbpf.probe_shift) and self._evidence(self.gross_shifts)

    def _evidence(self, events: int) -> bool:
        """Whether ``events`` gross odometry errors so far open a probe: ``rbpf.probe_gain``
        set, at least ``rbpf.probe_evidence_count`` of them and ``rbpf.probe_evidence_per_m``
        per metre of the odometry's travel (0: always)."""
        rc = self.config.rbpf
        if rc.probe_gain <= 0:
            return False
        if rc.probe_evidence_per_m <= 0:
            return True
        return (
            events >= rc.probe_evidence_count and events >= rc.probe_evidence_per_m * self.travelled
        )

    def _make_room(self, k: int, poses: F64) -> None:
        """Grow the maps to hold scan ``k`` seen from any of ``poses`` (an update asks twice:
        for the proposal and for the insertion; the scan's reach is computed once)."""
        if self._reach[0] != k:
            self._reach = (k, scan_reach(self.scans, k))
        r = self._reach[1] + self.config.rbpf.dmax + 1.0
        lo = poses[:, :2].min(axis=0) - r
        hi = poses[:, :2].max(axis=0) + r
        self.maps.ensure_contains(lo[0], lo[1], hi[0], hi[1])

    def _vacancy_view(self) -> VacancyView | None:
        """The vacancy grid as the matcher reads it (None: no grid)."""
        return None if self.vacancy is None else self.vacancy.view()

    def _vacancy_stats(self) -> dict[str, float | int]:
        """The vacancy grid's size and counts at the end, for ``metrics.json`` (none without)."""
        if self.vacancy is None:
            return {}
        state = self.vacancy.layers[0]
        return {
            "vacancy_grid_mb": round(self.vacancy.memory_bytes() / 2**20, 1),
            "vacancy_live_hits": int(np.count_nonzero(state == LIVE)),
            "vacancy_gone_hits": int(np.count_nonzero(state == SEEN_THROUGH)),
        }

    def _observe(self, k: int, pose: F64) -> None:
        """Scan ``k`` at ``pose`` into the vacancy grid (when there is one)."""
        if self.vacancy is not None:
            observe_scan(self.vacancy, self.scans, k, pose)

    def _insert(self, k: int, poses: F64) -> None:
        rc = self.config.rbpf
        hx, hy, nx, ny = hits_for_insert(self.scans, k, rc.insert_beams, self.maps.signed)
        self._make_room(k, poses)
        self.maps.insert(np.ascontiguousarray(poses), hx, hy, nx, ny, rc.skip_insert_below)

    def step(self, k: int, scan_period: float) -> StepOutcome:
        """Process scan ``k``: an update (predict → propose → weight → map → resample) when the
        update rule says so, else the estimate moves by odometry. ``scan_period`` is the nominal
        time between scans (the rule's clock counts scans since the last update)."""
        moved = relative(self.last_odometry, self.scans.odometry[k])
        elapsed = (k - self.last_update) * scan_period
        if not self.rule.due(moved, elapsed):
            return self._carry(k, moved)
        hits = self.scans.hits(k, self.config.rbpf.match_beams)
        if hits[0].size == 0:
            # not one return: nothing to weigh the particles by (a matcher would draw them
            # metres apart around an empty fit); the odometry carries them to the next scan
            self.blind += 1
            return self._carry(k, moved)
        if not self.mapped:
            return self._first_map(k, moved)
        predicted = self.predict(moved)
        match = self.propose(k, predicted, moved, hits)
        n_eff, max_weight = self.weight(match, moved)
        self.map(k)
        resampled = self.resample(n_eff)
        self.last_odometry = self.scans.odometry[k]
        self.last_update = k
        return StepOutcome(
            k, self.particles[self.best], self.particles, self.weights, n_eff, max_weight, True,
            resampled, hits=hits,
        )  # fmt: skip

    def _carry(self, k: int, moved: F64) -> StepOutcome:
        """The outcome of scan ``k`` that is no update: the estimate moves on by ``moved``, the
        odometry since the last update."""
        self.n_eff_log.append(self.n_eff_log[-1])
        self.max_weight_log.append(self.max_weight_log[-1])
        pose = compose(self.particles[self.best], moved)
        return StepOutcome(
            k, pose, self.particles, self.weights, self.n_eff_log[-1],
            self.max_weight_log[-1], False, False, motion=moved,
        )  # fmt: skip

    def _first_map(self, k: int, moved: F64) -> StepOutcome:
        """Scan ``k``, the first with a return after scans with none (a laser that starts
        blind): it builds the map, as scan 0 does in a run that starts seeing, at the
        odometry's pose; every particle is still the same pose, and nothing is weighed."""
        self.particles = compose(self.particles, moved)
        self.map(k)
        self.mapped = True
        self.parents = np.arange(self.particles.shape[0])
        self.n_eff_log.append(self.n_eff_log[-1])
        self.max_weight_log.append(self.max_weight_log[-1])
        self.last_odometry = self.scans.odometry[k]
        self.last_update = k
        return StepOutcome(
            k, self.particles[self.best], self.particles, self.weights, self.n_eff_log[-1],
            self.max_weight_log[-1], True, False,
        )  # fmt: skip

    def predict(self, moved: F64) -> F64:
        """Sample the odometry motion model for every particle; the predicted poses."""
        noise = self.rng.standard_normal((self.particles.shape[0], 3))
        return sample_motion(self.particles, moved, noise, self.alphas, self.floor)

    def propose(self, k: int, predicted: F64, moved: F64, hits: tuple[F64, F64]) -> MatchResult:
        """The scan-matching proposal: match every predicted pose against its particle's map,
        then draw each particle around its match (:func:`sample_around`)."""
        rc = self.config.rbpf
        self._make_room(k, predicted)
        probe_open, shift_open = self.probe_open, self.shift_probe_open
        match = self.maps.match(
            predicted, hits[0], hits[1], self.luts, rc.max_iterations, rc.tolerance,
            rc.min_inliers, rc.coarse_stride, self.probe_yaws if probe_open else None,
            vacancy=self._vacancy_view(),
        )  # fmt: skip
        probe, match.probe = match.probe, None
        b = int(np.argmax(match.loglik))
        turn = abs(float(wrap_angle(match.poses[b, 2] - predicted[b, 2])))
        shift = float(np.hypot(*(match.poses[b, :2] - predicted[b, :2])))
        retries = self.retries
        match = self._retry(predicted, hits, match)
        # the kernel probed from the best particle of the first match: still the one to probe
        # from unless a retry changed the matches
        probe = probe if self.retries == retries else None
        typical = self._typical()  # the recent updates' fit, before this one joins them
        match = self._probe(predicted, hits, match, probe, probe_open)
        if shift_open:
            match = self._shift_probe(predicted, hits, match, typical)
        self.travelled += math.hypot(float(moved[0]), float(moved[1]))
        self.gross_turns += int(turn >= min(rc.probe_yaw))
        self.gross_shifts += int(bool(rc.probe_shift) and shift >= min(rc.probe_shift, default=0))
        self.particles = match.poses
        fused = rc.proposal_mean == "fused"
        motion_cov = None
        if fused or (rc.proposal_spread > 0 and rc.proposal_motion_prior):
            motion_cov = motion_covariance(predicted, moved, self.alphas, self.floor)
        if fused:
            self.particles = fuse_with_prediction(
                match.poses, predicted, match.hessian, rc.temperature, motion_cov
            )
        if rc.proposal_spread > 0:
            self.particles = sample_around(
                self.particles, match.hessian, rc.temperature,
                motion_cov if rc.proposal_motion_prior else None, rc.proposal_spread, self.rng,
            )  # fmt: skip
        self.fallbacks += int(np.count_nonzero(match.inliers < rc.min_inliers))
        return match

    def _retry(self, predicted: F64, hits: tuple[F64, F64], match: MatchResult) -> MatchResult:
        """``match``, or, when its best per-beam log-likelihood is ``rbpf.retry_ratio`` times
        worse than the recent median, the best per particle of it and the matches from the
        predicted poses rotated by ±``rbpf.retry_yaw`` (no random draw: a run that never retries
        is the run without the rule)."""
        rc = self.config.rbpf
        beams = max(hits[0].size, 1)
        best = float(match.loglik.max()) / beams
        recent = self.recent_loglik
        if (
            rc.retry_ratio > 0
            and len(recent) >= 5
            and best < rc.retry_ratio * statistics.median(recent)
        ):
            self.retries += 1
            for yaw in rc.retry_yaw:
                for sign in (1.0, -1.0):
                    self._keep_better(match, predicted, sign * yaw, hits)
            best = float(match.loglik.max()) / beams
        recent.append(best)
        if len(recent) > rc.retry_window:
            del recent[0]
        return match

    def _probe(
        self,
        predicted: F64,
        hits: tuple[F64, F64],
        match: MatchResult,
        probe: MatchResult | None = None,
        probe_open: bool = True,
    ) -> MatchResult:
        """``match``, or, when the best particle's match is in the wrong basin of rotation, the
        best per particle of it and of the matches from the predicted poses rotated the way that
        found the better basin.

        The test is direct, not a threshold on how bad the match looks (a scan entering new
        space looks as bad as a rotated one): the best particle's predicted pose is matched
        again against its own map from starts rotated by ±``rbpf.probe_yaw``. The odometry got
        the rotation wrong by more than the matcher's basin when one of them scores a per-beam
        log-likelihood ``rbpf.probe_gain`` above the first match *and* closes at least half of
        the first match's shortfall from the median of the last ``rbpf.retry_window`` updates
        (the rotated start explains the scan about as well as the recent updates did; a scan
        that no start explains — new space, a wide hall's far beams — is left alone). Then every
        particle is matched again from its predicted pose rotated by that start's angle, each
        keeping the better match. No random draw: a run whose probes never fire is the run
        without them.

        ``probe``: the rotated starts' matches when already made (by the proposal's kernel call,
        :meth:`ParticleMaps.match` given :attr:`probe_yaws`, in their order). ``probe_open``:
        :attr:`probe_open` before this update (closed, the probe only keeps its reference).
        """
        rc = self.config.rbpf
        if rc.probe_gain <= 0:
            return match
        beams = max(hits[0].size, 1)
        b = int(np.argmax(match.loglik))
        first = float(match.loglik[b]) / beams
        typical = self._typical()
        typical = first if typical is None else typical
        recent = self.recent_best
        recent.append(first)
        if len(recent) > rc.retry_window:
            del recent[0]
        if not probe_open:
            return match
        yaws = self.probe_yaws
        if probe is None:
            starts = np.repeat(predicted[b : b + 1], yaws.size, axis=0)
            starts[:, 2] = wrap_angle(starts[:, 2] + yaws)
            probe = match_from_starts(
                self.maps, b, starts, hits, self.luts, rc, self._vacancy_view()
            )
        j = self._winner(probe, beams, first, typical)
        if j is None:
            return match
        self.probes += 1
        self._keep_better(match, predicted, float(yaws[j]), hits)
        return match

    def _winner(self, probe: MatchResult, beams: int, first: float, typical: float) -> int | None:
        """The probe's start that fires, or None: the best-scoring start on enough known cells,
        when its per-beam log-likelihood is ``rbpf.probe_gain`` above the first match's
        (``first``) and closes at least half of its shortfall from ``typical``."""
        rc = self.config.rbpf
        score = np.where(probe.inliers >= rc.min_inliers, probe.loglik, -np.inf)
        j = int(np.argmax(score))
        gain = float(score[j]) / beams - first
        if gain < rc.probe_gain or gain < 0.5 * (typical - first):
            return None
        return j

    def _typical(self) -> float | None:
        """The median best per-beam log-likelihood of the last ``rbpf.retry_window`` first
        matches (the probes' reference), or None before five updates."""
        recent = self.recent_best
        return statistics.median(recent) if len(recent) >= 5 else None

    def _shift_probe(
        self, predicted: F64, hits: tuple[F64, F64], match: MatchResult, typical: float | None
    ) -> MatchResult:
        """``match``, or, when the best particle's match falls short of ``typical`` (the recent
        updates' per-beam log-likelihood) by more than ``rbpf.probe_gain`` and a start shifted
        along its heading explains the scan better, the best per particle of it and of the
        matches from the predicted poses shifted that far along their own headings.

        The rotation probe's test (:meth:`_probe`) for the distance instead of the heading: the
        best particle's predicted pose is matched again from starts shifted by
        ±``rbpf.probe_shift``; one of them fires when it scores ``probe_gain`` per beam above
        the match and closes at least half of the shortfall. Only a match that falls short is
        probed, so the extra matches are made where they can matter. No random draw."""
        rc = self.config.rbpf
        beams = max(hits[0].size, 1)
        b = int(np.argmax(match.loglik))
        first = float(match.loglik[b]) / beams
        if typical is None or first >= typical - rc.probe_gain:
            return match
        th = float(predicted[b, 2])
        shifts = np.concatenate([np.asarray(rc.probe_shift), -np.asarray(rc.probe_shift)])
        starts = np.repeat(predicted[b : b + 1], shifts.size, axis=0)
        starts[:, 0] += shifts * math.cos(th)
        starts[:, 1] += shifts * math.sin(th)
        probe = match_from_starts(self.maps, b, starts, hits, self.luts, rc, self._vacancy_view())
        j = self._winner(probe, beams, first, typical)
        if j is None:
            return match
        self.shift_probes += 1
        start = predicted.copy()
        start[:, 0] += shifts[j] * np.cos(predicted[:, 2])
        start[:, 1] += shifts[j] * np.sin(predicted[:, 2])
        self._keep_better_from(match, start, hits)
        return match

    def _keep_better(
        self, match: MatchResult, predicted: F64, yaw: float, hits: tuple[F64, F64]
    ) -> None:
        """Match every particle again from its predicted pose turned by ``yaw`` and keep, in
        ``match``, the new match where it scores higher on enough known cells."""
        start = predicted.copy()
        start[:, 2] = wrap_angle(start[:, 2] + yaw)
        self._keep_better_from(match, start, hits)

    def _keep_better_from(self, match: MatchResult, start: F64, hits: tuple[F64, F64]) -> None:
        """Match every particle again from its pose in ``start`` and keep, in ``match``, the
        new match where it scores higher on enough known cells."""
        rc = self.config.rbpf
        alt = self.maps.match(
            start, hits[0], hits[1], self.luts, rc.max_iterations, rc.tolerance, rc.min_inliers,
            rc.coarse_stride, vacancy=self._vacancy_view(),
        )  # fmt: skip
        better = (alt.loglik > match.loglik) & (alt.inliers >= rc.min_inliers)
        match.poses[better] = alt.poses[better]
        match.loglik[better] = alt.loglik[better]
        match.inliers[better] = alt.inliers[better]
        match.hessian[better] = alt.hessian[better]

    def weight(self, match: MatchResult, moved: F64) -> tuple[float, float]:
        """Weight by the scan's (tempered, evidence-shared) log-likelihood; ``N_eff`` and the
        largest weight."""
        rc = self.config.rbpf
        share = self.rule.evidence_share(moved)
        self.logw = self.logw + share * match.loglik / rc.temperature
        self.logw -= self.logw.max()
        self.weights = normalise(self.logw)
        n_eff = effective_sample_size(self.weights)
        max_weight = float(self.weights[int(np.argmax(self.weights))])
        self.n_eff_log.append(n_eff)
        self.max_weight_log.append(max_weight)
        return n_eff, max_weight

    def map(self, k: int) -> None:
        """Every particle adds scan ``k`` to its own map; the lineage records the update (before
        a resampling, so that children share a map that holds the scan); the vacancy grid
        takes the scan at the pose of the particle with the highest weight."""
        self._insert(k, self.particles)
        self.lineage.record(k, self.particles, self.parents)
        self._observe(k, self.particles[int(np.argmax(self.weights))])

    def resample(self, n_eff: float) -> bool:
        """Systematic resampling when ``N_eff`` is below ``resample_threshold`` of the count."""
        p = self.particles.shape[0]
        resampled = n_eff < self.config.filter.resample_threshold * p
        self.best = int(np.argmax(self.weights))
        if resampled:
            idx = systematic_resample(self.weights, self.rng.random())
            copies = np.flatnonzero(idx == self.best)  # a weight of at least 1/p: one at least
            self.best = int(copies[0]) if copies.size else 0
            self.particles = self.particles[idx]
            self.maps.resample(idx)
            self.logw = np.zeros(p)
            self.weights = np.full(p, 1.0 / p)
            self.parents = idx
            self.resamples += 1
        else:
            self.parents = np.arange(p)
        self.peak_tiles = max(self.peak_tiles, self.maps.tiles_in_use)
        self.peak_map_bytes = max(self.peak_map_bytes, self.maps.memory_bytes())
        return resampled

    def best_ancestry(self) -> tuple[NDArray[np.int64], F64]:
        """The updates' scan numbers and the poses of the best particle's ancestry at them
        (:attr:`best`, found in the last lineage record through :attr:`parents`: a resampling
        after it reorders the particles)."""
        return self.lineage.steps, self.lineage.ancestry(int(self.parents[self.best]))

    def finish(self) -> FilterOutput:
        """The nodes: the updates' poses along the ancestry of the best particle."""
        steps, nodes = self.best_ancestry()
        return FilterOutput(
            scans=self.scans,
            steps=steps,
            node_poses=nodes,
            n_eff=np.asarray(self.n_eff_log, dtype=np.float64),
            max_weight=np.asarray(self.max_weight_log, dtype=np.float64),
            stats={
                "updates": int(len(steps)),
                "resamples": self.resamples,
                "match_fallbacks": self.fallbacks,
                "match_retries": self.retries,
                "basin_probes": self.probes,
                "gross_turns": self.gross_turns,
                "shift_probes": self.shift_probes,
                "gross_shifts": self.gross_shifts,
                "peak_tiles": int(self.peak_tiles),
                "peak_particle_map_mb": round(self.peak_map_bytes / 2**20, 1),
                **self._vacancy_stats(),
                **({"blind_updates": self.blind} if self.blind else {}),
            },
        )


class ClassicFilter:
    """The ``classic`` method's state and its step (see the module docstring)."""

    def __init__(self, scans: ScanSequence, config: Config, rng: np.random.Generator) -> None:
        fc, cc = config.filter, config.classic
        self.scans = scans
        self.config = config
        self.rng = rng
        p = fc.particles
        self.alphas = np.asarray(fc.motion_alphas, np.float64)
        self.floor = np.asarray(cc.motion_floor, np.float64)
        self.yaw_offsets = cc.yaw_step * np.arange(
            -cc.yaw_steps, cc.yaw_steps + 1, dtype=np.float64
        )
        self.particles = np.tile(scans.odometry[0], (p, 1))
        self.logw = np.zeros(p)
        self.weights = np.full(p, 1.0 / p)
        map_config = dataclasses.replace(config.map, log_odds_miss=cc.log_odds_miss)
        start = self.particles[0]
        self.grid = OccupancyGrid(map_config, center=(float(start[0]), float(start[1])))
        integrate_scan(self.grid, scans, 0, start)
        self.poses = [start.copy()]
        self.n_eff_log = [float(p)]
        self.max_weight_log = [1.0 / p]
        self.resamples = 0
        self._corr = np.empty(p, dtype=np.int64)
        self._offsets = np.empty((p, 3))
        self.first = StepOutcome(0, start, self.particles, self.weights, p, 1.0 / p, True, False)
        """The outcome of scan 0 (the initial map)."""

    def step(self, k: int, scan_period: float = 0.0) -> StepOutcome:
        """Process scan ``k``: predict → weight (map correlation) → map (from the best particle)
        → resample. Every scan is an update; ``scan_period`` is not used."""
        increment = relative(self.scans.odometry[k - 1], self.scans.odometry[k])
        self.predict(increment)
        hits = self.scans.hits(k, self.config.classic.beams)
        n_eff, best = self.weight(hits)
        pose = self.particles[best]
        self.poses.append(pose.copy())
        integrate_scan(self.grid, self.scans, k, pose)
        weights = self.weights
        resampled = self.resample(n_eff)
        # the record shows the weights the step computed, next to the particles after it
        return StepOutcome(
            k, pose, self.particles, weights, n_eff, float(weights[best]), True, resampled,
            hits=hits,
        )  # fmt: skip

    def predict(self, increment: F64) -> None:
        """Sample the odometry motion model for every particle."""
        noise = self.rng.standard_normal((self.particles.shape[0], 3))
        self.particles = sample_motion(self.particles, increment, noise, self.alphas, self.floor)

    def weight(self, hits: tuple[F64, F64]) -> tuple[float, int]:
        """Map correlation with a local pose search, softmax of the scores; ``N_eff`` and the
        index of the best particle."""
        cc, grid = self.config.classic, self.grid
        correlation_search(
            grid.occupied(), float(grid.origin[0]), float(grid.origin[1]), grid.resolution,
            self.particles, hits[0], hits[1], cc.xy_radius, self.yaw_offsets, self._corr,
            self._offsets,
        )  # fmt: skip
        if cc.snap_to_best:
            self.particles = self.particles + self._offsets
            self.particles[:, 2] = wrap_angle(self.particles[:, 2])
        self.logw = self.logw + self._corr / cc.temperature
        self.logw -= self.logw.max()
        self.weights = normalise(self.logw)
        n_eff = effective_sample_size(self.weights)
        best = int(np.argmax(self.weights))
        self.n_eff_log.append(n_eff)
        self.max_weight_log.append(float(self.weights[best]))
        return n_eff, best

    def resample(self, n_eff: float) -> bool:
        """Systematic resampling when ``N_eff`` is below ``resample_threshold`` of the count."""
        p = self.particles.shape[0]
        if n_eff >= self.config.filter.resample_threshold * p:
            return False
        idx = systematic_resample(self.weights, self.rng.random())
        self.particles = self.particles[idx]
        self.logw = np.zeros(p)
        self.resamples += 1
        return True

    def finish(self) -> FilterOutput:
        """Every scan is a node at its best particle's pose; the map is the shared grid."""
        poses = np.asarray(self.poses, dtype=np.float64).reshape(-1, 3)
        return FilterOutput(
            scans=self.scans,
            steps=np.arange(len(self.scans), dtype=np.int64),
            node_poses=poses,
            n_eff=np.asarray(self.n_eff_log, dtype=np.float64),
            max_weight=np.asarray(self.max_weight_log, dtype=np.float64),
            stats={"updates": len(self.scans), "resamples": self.resamples},
            poses=poses,
            grid=self.grid.cropped(self.config.map.crop_margin_m),
        )


def make_filter(
    scans: ScanSequence, config: Config, rng: np.random.Generator
) -> RbpfFilter | ClassicFilter:
    """The filter of ``config.filter.method``, started on the first scan of ``scans``."""
    if config.filter.method == "rbpf":
        return RbpfFilter(scans, config, rng)
    if config.filter.method == "classic":
        return ClassicFilter(scans, config, rng)
    raise ValueError(f"no particle filter for method {config.filter.method!r}")


def match_from_starts(
    maps: ParticleMaps,
    particle: int,
    starts: F64,
    hits: tuple[F64, F64],
    luts: tuple[F64, float],
    rc: RbpfConfig,
    vacancy: VacancyView | None = None,
) -> MatchResult:
    """Match one scan (robot-frame ``hits``) from several ``starts`` ``(S, 3)`` against the map
    of one ``particle``, with the proposal's matcher and settings (``rc``) and ``vacancy``."""
    return maps.match(
        starts, hits[0], hits[1], luts, rc.max_iterations, rc.tolerance, rc.min_inliers,
        rc.coarse_stride, particle=particle, vacancy=vacancy,
    )  # fmt: skip


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


def fuse_with_prediction(
    matched: F64, predicted: F64, hessian: F64, temperature: float, motion_cov: F64
) -> F64:
    """The mean of the Gaussian product of the tempered scan likelihood at each particle's match
    (information ``H / T`` around ``matched``) and the odometry model around its predicted pose
    (covariance ``Σ_m``): ``x_m + (H/T + Σ_m⁻¹)⁻¹ Σ_m⁻¹ (x_p − x_m)``, headings wrapped
    (``rbpf.proposal_mean = "fused"``). A particle whose match was not trusted has
    ``matched == predicted`` and stays there."""
    prior = np.linalg.inv(motion_cov)
    gain = np.linalg.solve(hessian / temperature + prior, prior)
    d = predicted - matched
    d[:, 2] = wrap_angle(d[:, 2])
    out = matched + np.einsum("pij,pj->pi", gain, d)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


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
