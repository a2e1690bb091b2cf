"""The localizer: tracking, global localization and recovery behind one ``update`` per scan.

:class:`Localizer` is in one of three phases:

``global``
    No pose yet (no initial pose was given): the exact histogram filter over the map's free
    (x, y, θ) cells (:mod:`slam.localize.histogram`) steps after every ``global_update_distance``
    of travel or ``global_update_angle`` of rotation. When one mode holds ``global_mode_share`` of
    the mass, ``global_particles`` particles are drawn from the mode's states and MCL takes over.
``tracking``
    Monte Carlo localization (:mod:`slam.localize.mcl`) with KLD-sampling, one update after every
    ``update_distance`` / ``update_angle``. The short- and long-term averages of the particles'
    match quality (:mod:`slam.localize.recovery`) watch for a lost or kidnapped robot.
``recovering``
    The robot is lost: MCL keeps running, and the histogram filter restarts from a uniform
    belief over the whole map in the background. When it converges, MCL continues if its
    estimate lies in the mode (a false alarm), else it is re-seeded from the mode.

Between updates the pose follows the odometry from the last update. A pose counts as
*localized* in the tracking phase when the particles' standard deviations are at most
``localized_std_xy`` and ``localized_std_theta``.

Inputs are a :class:`slam.Scan` and the odometry pose of the robot at the scan, in any fixed
frame (:meth:`Localizer.update`, the same inputs as :meth:`slam.Slam.update`); the localizer
thins the scan's returns to ``localize.beams`` (MCL), ``localize.refine_beams`` (the pose) and
``localize.global_beams`` (histogram), evenly spread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.config import Config, config_for
from slam.errors import DataError, UsageError
from slam.geometry import compose, relative, spread_picks
from slam.localize.histogram import Mode, PoseHistogram
from slam.localize.kernels import refine_pose
from slam.localize.kld import KldCounter
from slam.localize.maps import LikelihoodMap
from slam.localize.mcl import MotionModel, ParticleSet
from slam.localize.recovery import LostMonitor
from slam.localize.sensor import BeamModel
from slam.mapping import OccupancyGrid
from slam.scans import Scan

F64 = NDArray[np.float64]

PHASES = ("global", "tracking", "recovering")
"""The localizer's phases (see the module docstring)."""


@dataclass(frozen=True)
class InitialPose:
    """A starting guess: the pose and the standard deviations of the initial cloud."""

    pose: F64
    sigma_xy: float
    sigma_theta: float


@dataclass
class LocalizationEstimate:
    """What :meth:`Localizer.update` returns for one scan."""

    time: float
    """Scan time (s)."""
    pose: F64
    """``(3,)`` pose estimate in the map frame."""
    covariance: F64
    """``(3, 3)`` covariance of the particles at the last update (the histogram mode's spread
    in the global phase)."""
    phase: str
    """``global``, ``tracking`` or ``recovering``."""
    localized: bool
    """Tracking with a compact particle cloud."""
    updated: bool
    """A filter (MCL or histogram) ran on this scan."""
    particles: int
    """Particles held (0 in the global phase)."""
    quality: float
    """Match quality of the last MCL update at the estimate: the geometric mean per-beam
    likelihood over its largest possible value (1: every return on a wall); NaN before any."""
    mode_share: float
    """Share of the histogram's mass in its mode (NaN when the histogram is not running)."""
    lost: bool = False
    """The robot was declared lost on this scan."""


@dataclass(frozen=True)
class _Beams:
    """One scan's returns, thinned for each use, and its beam model."""

    mcl: tuple[F64, F64]
    global_: tuple[F64, F64]
    refine: tuple[F64, F64]
    model: BeamModel
    table: tuple[F64, float]


def _thin(ex: F64, ey: F64, count: int) -> tuple[F64, F64]:
    if ex.shape[0] <= count:
        return ex, ey
    pick = spread_picks(ex.shape[0], count)
    return np.ascontiguousarray(ex[pick]), np.ascontiguousarray(ey[pick])


class Localizer:
    """Localize a robot on a saved map, one scan at a time (see the module docstring).

    ``map`` is a :class:`LikelihoodMap` or an :class:`~slam.mapping.OccupancyGrid`; ``config``
    the configuration (its ``[localize]`` and ``[filter]`` sections; default: the defaults);
    ``initial`` a starting pose ``(x, y, θ)`` or ``(x, y, θ, σ_xy)`` in the map frame (then
    tracking starts at once, particles drawn around it with ``σ_xy`` or
    ``localize.initial_sigma_xy`` and ``localize.initial_sigma_theta``) or ``None`` (global
    localization); ``seed`` replaces ``filter.seed``.
    """

    def __init__(
        self,
        map: LikelihoodMap | OccupancyGrid,
        config: Config | None = None,
        *,
        initial: InitialPose | ArrayLike | None = None,
        seed: int | None = None,
    ) -> None:
        config = config_for("Localizer", config, seed)
        if not isinstance(map, LikelihoodMap | OccupancyGrid):
            raise UsageError(
                f"Localizer(map): expected a map (slam.load_map(RUN_DIR)) or an OccupancyGrid, "
                f"found {type(map).__name__}"
            )
        self.config = config
        self.map = map if isinstance(map, LikelihoodMap) else LikelihoodMap.from_grid(map)
        cfg = config.localize
        self.rng = np.random.default_rng(config.filter.seed)
        self.motion = MotionModel(
            np.asarray(config.filter.motion_alphas, np.float64),
            np.asarray(config.filter.motion_floor, np.float64),
        )
        kld = KldCounter(
            cfg.kld_bin_xy, cfg.kld_bin_theta, cfg.kld_epsilon, cfg.kld_delta,
            cfg.min_particles, cfg.max_particles,
        )  # fmt: skip
        self.map.surface(cfg.subdivision, self.config.checks.max_memory_share)  # within budget
        self.particles = ParticleSet(
            self.map, self.motion, kld, cfg.temperature, self.rng, cfg.subdivision
        )
        self.monitor = LostMonitor(
            cfg.alpha_slow, cfg.alpha_fast, cfg.lost_ratio, cfg.monitor_warmup
        )
        self._histogram: PoseHistogram | None = None
        self._models: dict[float, tuple[BeamModel, tuple[F64, float]]] = {}
        self.initial = self._initial(initial)
        self.phase = "global" if self.initial is None else "tracking"
        self._started = False
        self._laser: Any = None
        """Laser odometry (:mod:`slam.laser_odometry`) when :meth:`update` gets no odometry."""
        self._gyro: Any = None
        """The gyro samples fed (:meth:`add_imu`), which turn the laser odometry."""
        self._odom_mcl = np.zeros(3)
        self._odom_hist = np.zeros(3)
        self._mcl_pose = np.zeros(3)
        self._mcl_cov = np.zeros((3, 3))
        self._quality = math.nan
        self._mode: Mode | None = None
        self.counters = {"mcl_updates": 0, "histogram_steps": 0, "lost": 0, "reseeds": 0,
                         "false_alarms": 0, "scan_to_scan": 0, "weak_modes": 0}  # fmt: skip
        self._pose = np.zeros(3)
        self._odom_prev = np.zeros(3)

    def _initial(self, initial: InitialPose | ArrayLike | None) -> InitialPose | None:
        if initial is None or isinstance(initial, InitialPose):
            return initial
        values = np.asarray(initial, dtype=np.float64).reshape(-1)
        if values.shape[0] not in (3, 4) or not np.all(np.isfinite(values)):
            raise UsageError(
                f"initial pose: expected x, y, theta[, sigma] (finite numbers), found {initial!r}"
            )
        cfg = self.config.localize
        sigma = float(values[3]) if values.shape[0] == 4 else cfg.initial_sigma_xy
        if not sigma > 0:
            raise UsageError(f"initial pose: sigma must be > 0 m, found {sigma:g}")
        return InitialPose(values[:3].copy(), sigma, cfg.initial_sigma_theta)

    @property
    def histogram(self) -> PoseHistogram:
        """The global histogram filter (made on first use: it is the largest allocation)."""
        if self._histogram is None:
            self._histogram = PoseHistogram(
                self.map, self.config.localize, self.motion, self.config.checks.max_memory_share
            )
        return self._histogram

    def _model(self, z_range: float) -> tuple[BeamModel, tuple[F64, float]]:
        cached = self._models.get(z_range)
        if cached is None:
            cfg = self.config.localize
            model = BeamModel(cfg.z_hit, cfg.z_rand, cfg.z_max, cfg.sigma_hit, z_range)
            cached = (model, model.log_table(cfg.field_max))
            self._models[z_range] = cached
        return cached

    # -- one scan
    def add_imu(self, time: ArrayLike, gyro_z: ArrayLike) -> None:
        """Feed gyro z samples (rad/s) at ``time`` (s), up to each scan's time and from the first
        scan on: the laser odometry of a robot without odometry turns with them
        (``robot.laser_odometry_gyro``), as ``slam localize`` does on a log with an IMU."""
        if self._gyro is None:
            from slam.odometry import OdometryIntegrator

            self._gyro = OdometryIntegrator(self.config.robot)
        self._gyro.add_imu(time, gyro_z)

    def update(
        self,
        scan: Scan,
        odometry: ArrayLike | None = None,
        *,
        imu: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> LocalizationEstimate:
        """Process one scan taken at the odometry pose ``odometry`` ``(x, y, θ)`` (any fixed
        frame; only its increments are used); return the estimate after it. A robot without
        odometry gives none for any scan: laser odometry (:mod:`slam.laser_odometry`) stands in,
        turning with the gyro where ``imu=(times, gyro_z)`` feeds the samples since the previous
        scan (:meth:`add_imu`), unless ``robot.odometry = "log"``.

        What the scan leaves out (range semantics, laser offset) comes from ``[lidar]``, as for
        :meth:`slam.Slam.update`.
        """
        if not isinstance(scan, Scan):
            raise UsageError(f"Localizer.update: expected a slam.Scan, found {type(scan).__name__}")
        if imu is not None:
            self.add_imu(*imu)
        if odometry is None:
            odometry = self._laser_odometry(scan.resolved(self.config.lidar))
        elif self._laser is not None:
            from slam.laser_odometry import refuse_given

            raise refuse_given("Localizer.update")
        pose = np.asarray(odometry, dtype=np.float64).reshape(-1)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise DataError(
                f"scan at t={scan.time:.6f}: odometry must be a finite pose (x, y, theta), "
                f"found {odometry!r}"
            )
        scan = scan.resolved(self.config.lidar)
        if not math.isfinite(scan.range_max):  # type: ignore[arg-type]
            raise UsageError(
                f"scan at t={scan.time:.6f}: the beam model needs the sensor's longest range; "
                "give the scan a range_max or set lidar.range_max"
            )
        ex, ey = scan.hits()
        return self.update_hits(scan.time, ex, ey, pose, float(scan.range_max))  # type: ignore[arg-type]

    def _laser_odometry(self, scan: Scan) -> F64:
        """The laser odometry's pose at ``scan`` (:meth:`update` without odometry)."""
        if self._laser is None:
            from slam.laser_odometry import start_for_update

            self._laser = start_for_update(
                self.config, "Localizer.update", self._started, "give odometry=", self._gyro
            )
        return self._laser.pose_at(scan)

    def update_hits(
        self, time: float, ex: ArrayLike, ey: ArrayLike, odometry: ArrayLike, z_range: float
    ) -> LocalizationEstimate:
        """:meth:`update` for a scan given as its robot-frame returns ``(ex, ey)`` (m), taken at
        the odometry pose ``odometry``; ``z_range`` is the sensor's longest return (m)."""
        ex = np.ascontiguousarray(ex, dtype=np.float64).reshape(-1)
        ey = np.ascontiguousarray(ey, dtype=np.float64).reshape(-1)
        odom = np.asarray(odometry, dtype=np.float64).reshape(3)
        cfg = self.config.localize
        model, table = self._model(float(z_range))
        beams = _Beams(
            _thin(ex, ey, cfg.beams), _thin(ex, ey, cfg.global_beams),
            _thin(ex, ey, cfg.refine_beams), model, table,
        )  # fmt: skip
        updated = lost = False
        if not self._started:
            self._started = True
            self._odom_mcl = self._odom_hist = self._odom_prev = odom
            if self.phase == "tracking":
                init = self.initial
                self.particles.set_gaussian(
                    init.pose, init.sigma_xy, init.sigma_theta, cfg.max_particles
                )
                self._mcl_update(beams, None)
                self._pose = self._best(self._mcl_pose, None, beams)
            else:
                self._histogram_step(beams, None, odom)
            updated = True
        else:
            if self.phase != "global":
                updated, lost = self._track(beams, odom)
            if self.phase != "tracking" and not lost:
                inc = relative(self._odom_hist, odom)
                if self._moved(inc, cfg.global_update_distance, cfg.global_update_angle):
                    self._histogram_step(beams, inc, odom)
                    updated = True
        self._odom_prev = odom
        return self._estimate(time, updated, lost, beams)

    @staticmethod
    def _moved(inc: F64, distance: float, angle: float) -> bool:
        return math.hypot(inc[0], inc[1]) >= distance or abs(inc[2]) >= angle

    def _track(self, beams: _Beams, odom: F64) -> tuple[bool, bool]:
        """The tracking phases' work for one scan; returns ``(updated, lost)``.

        Two candidate poses are refined on the likelihood field (:meth:`_match`): the particles'
        mean moved by the odometry since the last update, and the previous scan's pose moved by
        the odometry since that scan. The one that explains the scan better is the pose (the
        particles' candidate on a tie). Wheel odometry slips, lags in fast turns and, on some
        logs, runs forward while the robot reverses: the scan-to-scan candidate follows the
        laser through such stretches, and at each particle update a share of the particles is
        drawn around the chosen pose, so the filter follows as well when the weights agree.
        """
        cfg = self.config.localize
        predicted = compose(self._mcl_pose, relative(self._odom_mcl, odom))
        chained = compose(self._pose, relative(self._odom_prev, odom))
        self._pose = self._best(predicted, chained, beams)
        inc = relative(self._odom_mcl, odom)
        if not self._moved(inc, cfg.update_distance, cfg.update_angle):
            return False, False
        self._mcl_update(beams, inc, self._pose)
        self._odom_mcl = odom
        self._pose = self._best(self._mcl_pose, self._pose, beams)
        self._quality = self._match_quality(self._pose, beams)
        lost = self.phase == "tracking" and self.monitor.observe(self._quality)
        if lost and cfg.recovery:
            self.counters["lost"] += 1
            self.phase = "recovering"
            spread = math.sqrt(max(np.linalg.eigvalsh(self._mcl_cov[:2, :2]).max(), 0.0))
            self.histogram.reset_around(
                self._pose,
                max(spread, cfg.global_mode_radius),
                max(math.sqrt(max(self._mcl_cov[2, 2], 0.0)), cfg.global_mode_angle),
                cfg.kidnap_prior,
            )
            self._histogram_step(beams, None, odom)
        return True, lost

    def _mcl_update(self, beams: _Beams, inc: F64 | None, matched: F64 | None = None) -> None:
        """Predict (unless ``inc`` is None), weight, estimate.

        With ``matched`` (the scan-matched pose), ``localize.inject_share`` of the predicted
        particles are replaced by draws around it (sensor resetting): when the wheels mislead
        the prediction, the weights can still find the pose the scan supports.
        """
        ps = self.particles
        ex, ey = beams.mcl
        if inc is not None:
            ps.predict(inc)
            share = self.config.localize.inject_share
            if matched is not None and share > 0:
                ps.inject(matched, self._mcl_cov, share)
        ps.weigh(ex, ey, beams.table)
        self._mcl_pose, self._mcl_cov = ps.estimate()
        self.counters["mcl_updates"] += 1

    def _match_quality(self, pose: F64, beams: _Beams) -> float:
        """Geometric mean per-beam likelihood of the scan at ``pose`` over its largest possible
        value (1: every return on a wall)."""
        ex, ey = beams.mcl
        at = self.particles.likelihood_at(np.asarray(pose)[None, :], ex, ey, beams.table)[0]
        return float(math.exp(at / max(ex.shape[0], 1) - beams.model.peak_log_density()))

    def _match(self, start: F64, beams: _Beams) -> tuple[F64, float]:
        """The most likely pose near ``start`` (``refine_iterations`` Levenberg-Marquardt steps
        on the likelihood field) and its cost (``start`` itself with ``refine_iterations = 0``)."""
        cfg = self.config.localize
        ex, ey = beams.refine
        model = beams.model
        out = np.array(start, dtype=np.float64)
        peak = model.z_hit / (model.sigma * math.sqrt(2.0 * math.pi))
        cost = refine_pose(
            self.particles.view, np.ascontiguousarray(start, dtype=np.float64), ex, ey, model.sigma,
            model.z_rand / model.z_range / peak, cfg.refine_iterations, 1e-4, out,
        )  # fmt: skip
        return out, float(cost)

    def _best(self, preferred: F64, other: F64 | None, beams: _Beams) -> F64:
        """The better explaining of the two candidates after refinement (``preferred`` on a
        tie)."""
        first, first_cost = self._match(preferred, beams)
        if other is None:
            return first
        second, second_cost = self._match(other, beams)
        if second_cost < first_cost:
            self.counters["scan_to_scan"] += 1
            return second
        return first

    def _histogram_step(self, beams: _Beams, inc: F64 | None, odom: F64) -> None:
        """One histogram step, then the hand-over test (:meth:`_hand_over`)."""
        hist = self.histogram
        if inc is not None:
            hist.predict(inc)
        ex, ey = beams.global_
        hist.update(ex, ey, beams.model)
        self._odom_hist = odom
        self.counters["histogram_steps"] += 1
        self._mode = hist.mode()
        self._hand_over(self._mode, beams, odom)

    def _hand_over(self, mode: Mode, beams: _Beams, odom: F64) -> None:
        """MCL takes over when the histogram's mode holds ``global_mode_share`` of the mass and
        its refined centre explains the scan (match quality ≥ ``relocalize_quality``).

        While recovering, the tracked pose is kept (a false alarm) when it lies in the mode and
        explains the scan no worse than the lost test allows (match quality at least
        ``lost_ratio`` times the long-term average before the alarm: right after it most of the
        mass is the prior around the tracked pose, so lying in the mode alone says nothing), or
        when it explains the scan at least as well as the mode's centre; otherwise the particles
        are drawn anew from the mode's states.
        """
        cfg = self.config.localize
        if mode.share < cfg.global_mode_share:
            return
        recovering = self.phase == "recovering"
        if recovering and self.histogram.contains(mode, self._pose):
            if self._match_quality(self._pose, beams) >= cfg.lost_ratio * self.monitor.w_slow:
                self._resume_tracking(false_alarm=True)
            return  # the mode is the prior's: more steps of the histogram decide
        candidate, cost = self._match(mode.pose, beams)
        if self._match_quality(candidate, beams) < cfg.relocalize_quality:
            self.counters["weak_modes"] += 1
            return
        if recovering and self._match(self._pose, beams)[1] <= cost:
            self._resume_tracking(false_alarm=True)
            return
        self.counters["reseeds"] += 1
        self.particles.set_particles(self.histogram.sample(mode, cfg.global_particles, self.rng))
        self._mcl_update(beams, None)
        self._odom_mcl = odom
        self._pose = self._best(self._mcl_pose, candidate, beams)
        self._quality = self._match_quality(self._pose, beams)
        self._resume_tracking(false_alarm=False)

    def _resume_tracking(self, false_alarm: bool) -> None:
        if false_alarm:
            self.counters["false_alarms"] += 1
        self.phase = "tracking"
        self.monitor.reset()

    def _estimate(
        self, time: float, updated: bool, lost: bool, beams: _Beams
    ) -> LocalizationEstimate:
        cfg = self.config.localize
        share = math.nan
        if self.phase == "global":
            mode = self._mode
            pose = compose(mode.pose, relative(self._odom_hist, self._odom_prev))
            res = self.histogram.resolution
            cov = np.diag([res**2 / 12, res**2 / 12, self.histogram.bin**2 / 12])
            share = mode.share
            count = 0
        else:
            pose = np.array(self._pose)
            cov = self._mcl_cov.copy()
            count = len(self.particles)
            if self.phase == "recovering" and self._mode is not None:
                share = self._mode.share
        localized = (
            self.phase == "tracking"
            and math.sqrt(max(cov[0, 0], cov[1, 1])) <= cfg.localized_std_xy
            and math.sqrt(cov[2, 2]) <= cfg.localized_std_theta
        )
        return LocalizationEstimate(
            time=float(time), pose=pose, covariance=cov, phase=self.phase, localized=localized,
            updated=updated, particles=count, quality=self._quality, mode_share=share, lost=lost,
        )  # fmt: skip
