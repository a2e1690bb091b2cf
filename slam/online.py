"""The ``Slam`` object: the package's public face, fed one scan at a time.

::

    import slam
    s = slam.Slam(slam.load_config("intel"), seed=0)
    for scan, odom in my_robot():                  # slam.Scan values and odometry poses
        est = s.update(scan, odometry=odom)        # slam.Estimate: pose, covariance, n_eff, ...
    result = s.finish()                            # slam.Result: trajectory, grid, diagnostics

:meth:`Slam.update` appends the scan to the run's :class:`~slam.scans.ScanSequence` and advances
the filter by one step (:mod:`slam.particle_filter`); observers (progress bar, rerun recorder,
:mod:`slam.observers`) see every step. :meth:`Slam.finish` ends the filter and runs the
post-filter stages (:mod:`slam.stages`). ``slam run`` feeds recorded logs through this same object
(:mod:`slam.pipeline`), so a batch run and an online run of the same scans agree bit for bit.

Robots without an odometry pose (the ECE276A robot: wheel encoders and a gyro) feed their
readings instead — :meth:`Slam.add_encoders` and :meth:`Slam.add_imu`, or ``encoders=`` and
``imu=`` of :meth:`Slam.update` — and a causal integrator (:class:`slam.odometry.OdometryIntegrator`)
gives the odometry at each scan; a robot with neither feeds its scans alone, and laser odometry
(:class:`slam.laser_odometry.LaserOdometry`) stands in. docs/api.md describes the whole interface.
"""

from __future__ import annotations

import bisect
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.budget import growth_share
from slam.config import Config, config_for
from slam.errors import ConfigError, DataError, UsageError
from slam.geometry import compose, transform_points
from slam.mapping import OccupancyGrid
from slam.observers import CompositeObserver, Observer, StepRecord
from slam.particle_filter import (
    ClassicFilter,
    RbpfFilter,
    StepOutcome,
    cloud_covariance,
    integrate_scan,
    make_filter,
)
from slam.scans import Scan, ScanSequence, odometry_pose
from slam.stages import Stage, build_map, default_stages, run_stages
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]

DETAIL_BEAMS = 720
"""Endpoints an observer's detail record carries on scans the filter did not weigh."""


@dataclass(frozen=True, eq=False)
class Estimate:
    """The filter's state after one :meth:`Slam.update`."""

    step: int
    """Number of the processed scan (0-based)."""
    scan_index: int
    """The scan's index in its log (:attr:`Scan.index`, else ``step``)."""
    time: float
    """Scan time (s)."""
    pose: F64
    """``(3,)`` current pose: the particle with the highest weight at the last update (after a
    resampling, its first copy: the weights are then equal); between ``rbpf`` updates moved on by
    odometry."""
    n_eff: float
    """Effective sample size ``1/Σw²`` after weighting."""
    max_weight: float
    """Largest normalised weight."""
    updated: bool
    """Whether the filter weighed this scan (``rbpf`` updates only after enough motion)."""
    resampled: bool
    """Whether the particles were resampled on this scan."""
    weights: F64
    """``(P,)`` normalised particle weights (uniform right after a resampling)."""
    _cloud: tuple[F64, F64 | None] = field(repr=False)
    """The particles as the filter holds them (a copy) and the odometry motion since (None:
    none): :attr:`particles` is made from them when first read."""

    @cached_property
    def particles(self) -> F64:
        """``(P, 3)`` particle poses (between ``rbpf`` updates moved on by odometry)."""
        base, motion = self._cloud
        return base if motion is None else compose(base, motion)

    @property
    def covariance(self) -> F64:
        """``(3, 3)`` weighted covariance of the particle cloud (x, y, θ)."""
        return cloud_covariance(self.particles, self.weights)


@dataclass(eq=False)
class Result:
    """What a run produces: the trajectory, the map and the filter's diagnostics."""

    trajectory: Trajectory
    """One pose per processed scan (``scan_indices``: their log indices); for dead reckoning
    (``method = "odometry"``) one per odometry reading."""
    grid: OccupancyGrid | None
    """The occupancy grid (``None`` for dead reckoning of a log without scans)."""
    n_eff: F64 | None = None
    """``(N,)`` effective sample size per processed scan (``None`` without a filter)."""
    max_weight: F64 | None = None
    """``(N,)`` largest normalised weight per processed scan."""
    stats: dict[str, Any] = field(default_factory=dict)
    """Filter and stage counters: updates, resamplings, particle-map memory, loop closures."""
    seconds: dict[str, float] = field(default_factory=dict)
    """Wall time (s) of the parts of the run: ``"filter"`` (every :meth:`Slam.update`'s filter
    step), then each post-filter stage by its name, in order; numba compiling a kernel counts
    in the part that first called it (nothing on a warm cache)."""
    metrics: dict[str, Any] = field(default_factory=dict)
    """What ``metrics.json`` holds (sizes, timings, ATE...), filled by :func:`slam.run`."""
    folder: Path | None = None
    """The run folder, when :func:`slam.run` wrote one."""

    @property
    def times(self) -> F64:
        """``(N,)`` trajectory times (s)."""
        return self.trajectory.times

    @property
    def poses(self) -> F64:
        """``(N, 3)`` trajectory poses."""
        return self.trajectory.poses


class _RunningMedian:
    """The median of the positive time steps between the scans seen so far (a causal stand-in
    for the nominal scan period of a recorded log)."""

    def __init__(self) -> None:
        self._steps: list[float] = []
        self._last: float | None = None

    def add(self, time: float) -> None:
        if self._last is not None and time > self._last:
            bisect.insort(self._steps, time - self._last)
        self._last = time

    @property
    def value(self) -> float:
        n = len(self._steps)
        if n == 0:
            return 0.0
        mid = n // 2
        return self._steps[mid] if n % 2 else 0.5 * (self._steps[mid - 1] + self._steps[mid])


class Slam:
    """Online SLAM: feed scans with :meth:`update`, get the result from :meth:`finish`.

    ``config`` is the run's configuration (default: :class:`~slam.config.Config`'s defaults, the
    ``rbpf`` method); ``seed`` replaces ``filter.seed``. ``observers`` watch every step
    (:class:`slam.observers.Observer`); ``stages`` replace the post-filter stages of the method
    (:func:`slam.stages.default_stages`). ``scan_period`` is the sensor's nominal time between
    scans, the clock of ``rbpf``'s interval update rule; without it the median time step of the
    scans so far stands in (a recorded log's batch run passes the median over the whole log).
    ``odometry_source`` says where the ``odometry=`` poses come from: ``"log"`` dead reckoning
    (wheels, encoders + IMU), ``"laser"`` scan matching (a laser odometry of the caller's, or
    the log's laser odometry in a batch run): the :class:`~slam.stages.Recovery` stage starts
    again only from dead reckoning. Laser odometry that :meth:`update` runs itself sets it.
    """

    def __init__(
        self,
        config: Config | None = None,
        seed: int | None = None,
        *,
        observers: Iterable[Observer] = (),
        stages: Iterable[Stage] | None = None,
        scan_period: float | None = None,
        odometry_source: str = "log",
    ) -> None:
        config = config_for("Slam", config, seed)
        if config.filter.method not in ("rbpf", "classic"):
            raise ConfigError(
                f"filter.method: Slam runs the particle filters 'rbpf' and 'classic', found "
                f"{config.filter.method!r} (dead reckoning: slam.run(..., method='odometry'))"
            )
        if scan_period is not None and (
            isinstance(scan_period, bool)
            or not isinstance(scan_period, int | float | np.number)
            or not scan_period >= 0
        ):
            raise UsageError(f"scan_period: expected seconds ≥ 0, found {scan_period!r}")
        if odometry_source not in ("log", "laser"):
            raise UsageError(
                f"odometry_source: expected 'log' or 'laser', found {odometry_source!r}"
            )
        self.config = config
        self.scans = ScanSequence()
        """Every scan processed so far, with its odometry (what the stages read)."""
        self.scans.odometry_source = odometry_source
        self.stages: list[Stage] = default_stages(config) if stages is None else list(stages)
        for stage in self.stages:
            if not callable(getattr(stage, "run", None)):
                raise UsageError(
                    f"stages: expected slam.stages.Stage objects (with a run method), found "
                    f"{type(stage).__name__}"
                )
        self._observers: list[Observer] = []
        for observer in observers:
            self._check_observer(observer)
            self._observers.append(observer)
        self._observer = CompositeObserver(self._observers) if self._observers else None
        self._scan_period = scan_period
        self._running_period = _RunningMedian()
        self._rng = np.random.default_rng(config.filter.seed)
        self._filter: RbpfFilter | ClassicFilter | None = None
        self._odometry: Any = None
        self._laser: Any = None
        self._live_map: OccupancyGrid | None = None
        self._given = False
        """Whether the scans so far came with ``odometry=`` (encoder readings fed after them
        would be a second odometry, in another frame)."""
        self._finished = False
        self._seconds: dict[str, float] = {"filter": 0.0}

    # -- inputs
    def add_observer(self, observer: Observer) -> None:
        """Let ``observer`` watch the steps from now on."""
        self._check_observer(observer)
        self._observers.append(observer)
        self._observer = CompositeObserver(self._observers)

    @staticmethod
    def _check_observer(observer: object) -> None:
        """Refuse what is no :class:`~slam.observers.Observer` (before the first step needs it)."""
        if not all(callable(getattr(observer, name, None)) for name in ("on_step", "on_map")):
            raise UsageError(
                f"observers: expected slam.observers.Observer objects (on_step, on_map, ...), "
                f"found {type(observer).__name__}"
            )

    @property
    def odometry(self) -> Any:
        """The causal encoder + IMU integrator (:class:`slam.odometry.OdometryIntegrator`),
        made on first use."""
        if self._odometry is None:
            from slam.odometry import OdometryIntegrator

            self._odometry = OdometryIntegrator(self.config.robot)
        return self._odometry

    def add_encoders(self, time: ArrayLike, counts: ArrayLike) -> None:
        """Feed wheel encoder readings (ECE276A robot): ``counts`` ``(4,)`` or ``(4, K)`` ticks
        FR, FL, RR, RL since the previous reading, at ``time`` (s)."""
        self.odometry.add_encoders(time, counts)

    def add_imu(self, time: ArrayLike, gyro_z: ArrayLike) -> None:
        """Feed gyro z samples (rad/s) at ``time`` (s): the yaw of the encoder odometry, or, for a
        robot without wheel odometry, the turns of its laser odometry (fed from the first scan
        on, up to each scan's time)."""
        self.odometry.add_imu(time, gyro_z)

    # -- the filter
    def update(
        self,
        scan: Scan,
        odometry: ArrayLike | None = None,
        *,
        encoders: tuple[ArrayLike, ArrayLike] | None = None,
        imu: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> Estimate:
        """Process one scan; return the estimate after it.

        ``odometry`` is the robot's odometry pose ``(x, y, θ)`` at the scan (any fixed frame: the
        map starts at the first one). Without it the pose comes from the encoder and IMU
        readings fed so far; ``encoders=(times, counts)`` and ``imu=(times, gyro_z)`` feed the
        readings since the previous scan first. A robot without wheel odometry gives no odometry
        for any scan, and laser odometry (:class:`slam.laser_odometry.LaserOdometry`) stands in,
        turning with the gyro where IMU readings are fed (up to each scan's time, before it) —
        unless ``robot.odometry = "log"``, which refuses the scan.
        """
        if self._finished:
            raise UsageError("Slam.update: the run is finished (make a new Slam)")
        if not isinstance(scan, Scan):
            raise UsageError(f"Slam.update: expected a slam.Scan, found {type(scan).__name__}")
        # what can refuse the scan is checked before its readings are fed: a refused update
        # leaves the object as it was
        resolved = scan.resolved(self.config.lidar)
        if odometry is not None:
            if self._laser is not None:
                from slam.laser_odometry import refuse_given

                raise refuse_given("Slam.update")
            if encoders is not None or (self._odometry is not None and self._odometry.has_encoders):
                raise UsageError(
                    f"Slam.update: scan at t={resolved.time:.6f}: odometry= was given, and encoder "
                    "readings were fed: the two are odometries of different frames; give "
                    "odometry= for every scan, or feed the encoders and leave it out"
                )
            odometry = odometry_pose(resolved, odometry)
            self._check_jump(resolved, odometry)
        if imu is not None:
            self.add_imu(*imu)
        if encoders is not None:
            self.add_encoders(*encoders)
        given = odometry is not None
        if not given:
            odometry = self._odometry_at(resolved)
        k = self.scans.append(resolved, odometry)
        self._given = given
        self._running_period.add(scan.time)
        start = time.perf_counter()
        with growth_share(self.config.checks.max_memory_share):
            if self._filter is None:
                self._filter = make_filter(self.scans, self.config, self._rng)
                outcome = self._filter.first
            else:
                period = self._scan_period
                running = self._running_period.value if period is None else period
                outcome = self._filter.step(k, running)
        self._seconds["filter"] += time.perf_counter() - start
        estimate = self._estimate(outcome)
        if self._observer is not None:
            self._notify(self._observer, outcome, estimate)
        return estimate

    def _odometry_at(self, scan: Scan) -> F64:
        """The odometry at ``scan`` when :meth:`update` got none: the encoder + IMU integrator's
        where encoder readings were fed before the first scan, else laser odometry
        (:mod:`slam.laser_odometry`, turning with the gyro where IMU readings were fed) unless
        ``robot.odometry = "log"``; ``robot.odometry = "laser"`` leaves the encoders unread.
        Encoder readings fed after scans given ``odometry=`` are a :class:`UsageError`."""
        readings = self._odometry
        wheels = readings is not None and readings.has_encoders
        if wheels and self.config.robot.odometry == "laser":
            wheels = False  # asked for laser odometry: the encoders are not read
        if self._laser is None and wheels:
            if self._given:
                raise UsageError(
                    f"Slam.update: scan at t={scan.time:.6f}: encoder readings were fed after "
                    "scans given odometry=: the two are odometries of different frames; give "
                    "odometry= for every scan, or feed the encoders and leave it out"
                )
            return readings.pose_at(scan.time)
        if self._laser is None:
            from slam.laser_odometry import start_for_update

            self._laser = start_for_update(
                self.config, "Slam.update", len(self.scans) > 0,
                "give odometry= (a pose) or feed encoders and IMU readings", readings,
            )  # fmt: skip
            self.scans.odometry_source = "laser"
        elif wheels:
            from slam.laser_odometry import refuse_given

            raise refuse_given("Slam.update")
        return self._laser.pose_at(scan)

    def _check_jump(self, scan: Scan, pose: F64) -> None:
        """Refuse an odometry pose that moves faster than ``checks.max_speed`` since the
        previous scan (time steps floored at the scan period), the check ``slam run`` makes
        on a log's odometry (:func:`slam.io.plausibility.first_jump`)."""
        if not len(self.scans) or self.scans.odometry_source == "laser":
            return  # a scan matcher's odometry is no reading that can be corrupt
        max_speed = self.config.checks.max_speed
        previous = self.scans.odometry[-1]
        dt = abs(scan.time - float(self.scans.times[-1]))
        period = self._scan_period or self._running_period.value or 1.0
        distance = float(np.hypot(pose[0] - previous[0], pose[1] - previous[1]))
        if not distance <= max_speed * max(dt, period):
            raise DataError(
                f"Slam.update: scan at t={scan.time:.6f}: odometry moves {distance:.4g} m from "
                f"the previous scan's in {dt:.3g} s, more than checks.max_speed = "
                f"{max_speed:g} m/s: a corrupt reading (raise checks.max_speed for a faster "
                "robot)"
            )

    def _estimate(self, outcome: StepOutcome) -> Estimate:
        k = outcome.step
        weights = outcome.weights
        if outcome.resampled:
            n = outcome.particles.shape[0]
            weights = np.full(n, 1.0 / n)
        return Estimate(
            step=k,
            scan_index=int(self.scans.indices[k]),
            time=float(self.scans.times[k]),
            pose=np.array(outcome.pose, dtype=np.float64),
            n_eff=float(outcome.n_eff),
            max_weight=float(outcome.max_weight),
            updated=outcome.updated,
            resampled=outcome.resampled,
            weights=np.array(weights, dtype=np.float64),
            _cloud=(np.array(outcome.particles, dtype=np.float64), outcome.motion),
        )

    def _notify(self, observer: CompositeObserver, outcome: StepOutcome, est: Estimate) -> None:
        """Send the step's record (with particles and endpoints on detail steps) and, every
        ``map_every`` updates, the current map."""
        k = outcome.step
        record = StepRecord(
            k, est.scan_index, est.time, est.pose.copy(), est.n_eff, est.max_weight, est.updated,
            est.resampled,
        )  # fmt: skip
        if observer.detail_every and k % observer.detail_every == 0:
            record.particles = outcome.particles.copy()
            record.weights = outcome.weights.copy()
            ex, ey = outcome.hits if outcome.hits is not None else self.scans.hits(k, DETAIL_BEAMS)
            record.endpoints = transform_points(record.pose, np.stack([ex, ey], axis=1))
        observer.on_step(record)
        if observer.map_every and outcome.updated:
            grid = self._current_map(outcome)
            if k > 0 and k % observer.map_every == 0:
                observer.on_map(k, record.time, grid)

    def _current_map(self, outcome: StepOutcome) -> OccupancyGrid:
        """The map so far: ``classic``'s own; for ``rbpf`` a grid of the best particle's scans
        kept for observers that ask for maps."""
        if isinstance(self._filter, ClassicFilter):
            return self._filter.grid
        if self._live_map is None:
            start = self.scans.odometry[0]
            self._live_map = OccupancyGrid(self.config.map, center=(start[0], start[1]))
        integrate_scan(self._live_map, self.scans, outcome.step, outcome.pose)
        return self._live_map

    @property
    def steps(self) -> int:
        """Scans processed so far."""
        return len(self.scans)

    def map(self) -> OccupancyGrid:
        """The occupancy grid of the run so far, for a robot that needs a map while it drives.

        ``rbpf``: every update's scan at the pose the best particle's ancestry gives it — the map
        GMapping publishes while it runs; the stages of :meth:`finish` make the final map better.
        It is built anew at each call, from every update's scan (as long as
        :class:`~slam.stages.FinalMap` takes on them: 0.1–2 s at the end of a benchmark log), so
        call it every few seconds, not at every scan. ``classic``: a copy of its own grid. The
        call changes nothing in the run. (Observers that ask for maps get a cheaper preview
        instead, every ``map_every`` updates: each update's scan added once at the pose of that
        moment, never redrawn when the best particle changes.)
        """
        if self._finished:
            raise UsageError("Slam.map: the run is finished (its map is the result's grid)")
        if self._filter is None:
            raise UsageError("Slam.map: no scan was processed (call update() first)")
        if isinstance(self._filter, ClassicFilter):
            grid = self._filter.grid
            return OccupancyGrid.from_arrays(
                grid.log_odds.copy(), grid.resolution, grid.origin, grid.config
            )
        steps, nodes = self._filter.best_ancestry()
        # every scan at its last update's pose: only the nodes are drawn, and the grid's extent,
        # taken over every pose, then spans the nodes (not the origin of the odometry's frame)
        last = np.searchsorted(steps, np.arange(len(self.scans)), side="right") - 1
        return build_map(self.scans, nodes[last], steps, self.config)

    def finish(self) -> Result:
        """End the run: the filter's output through the post-filter stages."""
        if self._finished:
            raise UsageError("Slam.finish: the run is already finished")
        if self._filter is None:
            raise UsageError("Slam.finish: no scan was processed (call update() first)")
        self._finished = True
        start = time.perf_counter()
        with growth_share(self.config.checks.max_memory_share):  # the maps' growth checks
            output = self._filter.finish()
            # the particles' maps are not needed after the filter: the stages build their own
            self._filter = None
            if self._observer is not None:
                self._observer.on_filter_end()
            self._seconds["filter"] += time.perf_counter() - start
            output = run_stages(output, self.stages, self.config, self._seconds)
        if output.poses is None:
            raise UsageError("Slam.finish: the stages placed no scan (keep BetweenUpdates)")
        stats = dict(output.stats)
        if self._odometry is not None and self._odometry.wheel_yaw_intervals:
            stats["odometry_wheel_yaw_intervals"] = self._odometry.wheel_yaw_intervals
        if self._laser is not None:
            stats["laser_odometry"] = self._laser.counts()
        seq = output.scans
        return Result(
            trajectory=Trajectory(seq.times.copy(), output.poses, seq.indices.copy()),
            grid=output.grid,
            n_eff=output.n_eff,
            max_weight=output.max_weight,
            stats=stats,
            seconds=dict(self._seconds),
        )
