"""Odometry from the laser alone, for a robot whose log has none.

Owns :class:`LaserOdometry`, the stand-in for wheel odometry when a log carries none (a bag of
laser scans only, a CARMEN log whose poses are all zero, a hand-held laser) or when
``robot.odometry = "laser"`` asks for it. Every scan is matched, by the filter's own matcher
(:func:`slam.kernels.field.match_one`), onto a local map of the last ``robot.laser_odometry_window``
keyframes (its returns within :data:`MAX_RANGE`), starting from the previous scan's pose moved
on by the previous step (a constant velocity per scan, not per second: logs' clocks jitter, and
intel's runs backwards at 631 of its scans). Where that start does not fit the map (fewer than :data:`MIN_FIT` of the returns within
:data:`FIT_DISTANCE` of it: the robot began or stopped turning), a brute-force search of ±
:data:`SEARCH_XY` and ± :data:`SEARCH_TH` around it gives a second start, and the lower-cost
match wins; where neither fits, a search over every heading (a gap in the log, during which the
robot turned), and the best of them is taken where it explains more of the scan than the start
does. A scan that fits nowhere keeps the constant-velocity prediction.

**The gyro.** Where the log has an IMU (a bag's ``sensor_msgs/Imu``, the ECE276A robot's) or
``Slam.add_imu`` feeds one, the prediction turns by the gyro's turn since the previous scan
(:meth:`slam.odometry.OdometryIntegrator.gyro_heading`: the samples at or before each scan only)
instead of the previous scan's turn; the translation stays the previous step's
(``robot.laser_odometry_gyro``). Where that start does not fit and the previous turn's fits
better, the previous turn's is taken, so a gyro that reads wrongly costs no scan its match. A scan whose time is not later than every earlier scan's, and
the one after it, keep the previous turn (intel's clock runs backwards at 631 scans). A gyro
that does not measure the robot's yaw would put every turning scan's start off: once the scans
have turned by more than :data:`GYRO_MIN_TURN` on :data:`GYRO_MIN_STEPS` matched scans, and
until :data:`GYRO_TRUSTED_STEPS`, the gyro's turns on those scans are compared with the
scans': a gyro that reads backwards (mounted
upside down, its frame not saying so: their correlation under −:data:`GYRO_MIN_CORRELATION`),
nothing (a dead gyro, or one whose z axis is not the robot's: its turns' RMS under
:data:`GYRO_MIN_RATIO` of the scans'), or in other units (degrees for radians: over
1 / :data:`GYRO_MIN_RATIO` of the scans', correlated over :data:`GYRO_MIN_CORRELATION`) is set
aside for the rest of the run (:attr:`LaserOdometry.gyro_set_aside_at`; ``slam run`` warns).
Scans that disagree with a good gyro because the laser odometry itself is lost (their turns
then weakly correlated with the gyro's and larger) do not set it aside: the test needs a gyro
an order of magnitude off, and ends once it has agreed for :data:`GYRO_TRUSTED_STEPS` turns.

The poses are causal — each depends on the scans before it only — so a batch run
(:meth:`slam.scans.LogScans.from_log`) and :meth:`slam.online.Slam.update` fed the same scans
without odometry agree bit for bit. They are in the frame of the first scan's robot pose. It is
an odometry, not a SLAM: it drifts and closes no loop; the particle filter and the stages after
it treat it as they treat wheel odometry. docs/slam.md, "A robot without odometry", has what it
gives on the benchmark logs.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from slam.calibration import CalibrationSettings
from slam.config import Config
from slam.errors import UsageError
from slam.geometry import compose, relative, wrap_angle
from slam.graph import MatchContext, empty_submap
from slam.io.log import ImuStream
from slam.kernels.field import FieldView, match_one
from slam.kernels.graph import correlative_search, fit_counts
from slam.mapping import ParticleMaps
from slam.odometry import OdometryIntegrator
from slam.scans import Scan

F64 = NDArray[np.float64]

MAX_RANGE = CalibrationSettings.max_range
"""Returns farther than this (20 m) are not matched, as the odometry's calibration matches
(:class:`slam.calibration.CalibrationSettings`): a local map of a few scans holds a far wall as
returns a metre apart. Measured on the benchmark logs without their odometry (docs/slam.md, "A
robot without odometry"): every return, or those within ``rbpf.dmax`` over the beam step, lose
aces on every seed; within 20 m it holds."""
FIT_DISTANCE = 0.1
"""A pose fits the local map when at least :data:`MIN_FIT` of the scan's returns lie within this
(m) of its surfaces ..."""
MIN_FIT = 0.5
"""... this share (:data:`FIT_DISTANCE`)."""
SEARCH_XY = 0.3
"""The search around a start that does not fit: ± this in x and y (m, in ``loops.search_step``
steps) ..."""
SEARCH_TH = 0.35
"""... and ± this in heading (rad, 20°) ..."""
SEARCH_TH_STEP = 0.0175
"""... in steps of this (rad, 1°), scored with ``loops.search_sigma`` on at most
``loops.search_beams`` returns, as the loop closing's search is."""
GYRO_MIN_TURN = 0.01
"""The gyro's agreement with the scans is measured on the matched scans that turned more than
this since the previous one (rad) ..."""
GYRO_MIN_STEPS = 20
"""... once there are this many, and until there are :data:`GYRO_TRUSTED_STEPS` (a gyro that has
agreed that long is kept: scans that disagree later are the laser odometry's loss) ..."""
GYRO_TRUSTED_STEPS = 50
"""See :data:`GYRO_MIN_STEPS`."""
GYRO_MIN_CORRELATION = 0.5
"""... and the gyro is set aside when its turns' correlation with the scans' is under minus this
(a reversed gyro: −1) ..."""
GYRO_MIN_RATIO = 0.1
"""... or the RMS of its turns is under this share of the scans' (a gyro that reads nothing),
or over its inverse while correlated over :data:`GYRO_MIN_CORRELATION` (degrees for radians:
57)."""


class LaserOdometry:
    """Causal scan-to-local-map odometry (module docstring).

    Feed the scans in time order with :meth:`pose_at`; each call returns the robot's pose at that
    scan. :attr:`matched` counts the scans the matcher placed, :attr:`kept_prediction` those that
    kept the constant-velocity prediction, :attr:`searched` the brute-force searches;
    :attr:`unfit` lists the scans whose start did not fit. With a gyro, :attr:`gyro_turns` counts
    the starts it turned, :attr:`gyro_agreement` compares its turns with the scans' and
    :attr:`gyro_set_aside_at` says where it was set aside; :meth:`counts` gathers them.
    """

    def __init__(self, config: Config, gyro: OdometryIntegrator | None = None) -> None:
        self.config = config
        self.gyro = gyro if config.robot.laser_odometry_gyro else None
        """The gyro (its samples fed to an :class:`~slam.odometry.OdometryIntegrator`), or None."""
        self.gyro_turns = 0
        """Predictions whose turn came from the gyro."""
        self.gyro_set_aside_at: int | None = None
        """The scan (number, from 0) from which the gyro was set aside (module docstring)."""
        self._gyro_headings: list[float | None] = []
        """The gyro's heading at each scan (None: no gyro there, or the scan's time is not
        later than every earlier scan's: a clock that ran backwards, as intel's does)."""
        self._latest = -np.inf
        self._agreement = [0.0, 0.0, 0.0, 0]  # Σ gyro × scan turn, Σ scan², Σ gyro², count
        self.tables = MatchContext.of(config)
        """The matcher's likelihood tables, as the loop closing's matches use them."""
        self.keyframes: deque[tuple[F64, F64]] = deque(maxlen=config.robot.laser_odometry_window)
        self.maps: ParticleMaps | None = None
        self.poses: list[F64] = []
        self.matched = 0
        self.kept_prediction = 0
        self.searched = 0
        self.unfit: list[int] = []
        """The scans (their numbers, from 0) whose start did not fit the local map."""

    def pose_at(self, scan: Scan) -> F64:
        """The robot's pose ``(3,)`` at ``scan`` (resolved: :meth:`slam.scans.Scan.resolved`),
        the scans before it fed already."""
        ex, ey = scan.hits(self.config.rbpf.register_beams)
        near = ex * ex + ey * ey <= MAX_RANGE * MAX_RANGE
        ex, ey = np.ascontiguousarray(ex[near]), np.ascontiguousarray(ey[near])
        heading = None
        in_order = scan.time > self._latest
        self._latest = max(self._latest, scan.time)
        if self.gyro is not None and self.gyro_set_aside_at is None and in_order:
            heading = self.gyro.gyro_heading(scan.time)
        if self.poses:
            matched = self.matched
            start, plain = self._predict(heading), None
            if self._gyro_headings[-1] is not None and heading is not None:
                self.gyro_turns += 1
                plain = self._predict(None)
            pose = self._match(start, ex, ey, plain)
            if self.matched > matched:
                self._weigh_gyro(heading, pose)
        else:
            pose = np.zeros(3)
        self.poses.append(pose)
        self._gyro_headings.append(heading)
        if ex.size and self._is_keyframe(pose):
            self.keyframes.append((pose, np.vstack([ex, ey])))
            self._rebuild()
        return pose.copy()

    def _predict(self, heading: float | None) -> F64:
        """The last pose moved on by the last step (the first scans: not moved), turned by the
        gyro's turn since the last scan instead where both have its ``heading``."""
        last = self.poses[-1]
        moving = len(self.poses) >= 2
        step = relative(self.poses[-2], last) if moving else np.zeros(3)
        before = self._gyro_headings[-1]
        if heading is not None and before is not None:
            step[2] = heading - before
        elif not moving:
            return last.copy()
        return compose(last, step)

    def _weigh_gyro(self, heading: float | None, pose: F64) -> None:
        """Add the matched scan's turn and the gyro's to their agreement; set the gyro aside
        when it disagrees (module docstring)."""
        before = self._gyro_headings[-1]
        if heading is None or before is None:
            return
        turn = float(wrap_angle(pose[2] - self.poses[-1][2]))
        if abs(turn) <= GYRO_MIN_TURN:
            return
        gyro = heading - before
        agreement = self._agreement
        agreement[0] += gyro * turn
        agreement[1] += turn * turn
        agreement[2] += gyro * gyro
        agreement[3] += 1
        if not GYRO_MIN_STEPS <= agreement[3] <= GYRO_TRUSTED_STEPS:
            return
        measured = self.gyro_agreement
        assert measured is not None
        correlation, ratio = measured
        reversed_ = correlation < -GYRO_MIN_CORRELATION
        other_units = ratio > 1.0 / GYRO_MIN_RATIO and correlation > GYRO_MIN_CORRELATION
        if reversed_ or ratio < GYRO_MIN_RATIO or other_units:
            self.gyro_set_aside_at = len(self.poses)

    def counts(self) -> dict[str, float]:
        """The counters for ``metrics.json`` / ``Result.stats``: ``matched``,
        ``kept_prediction``, and with a gyro ``gyro_turns``, ``gyro_correlation`` and
        ``gyro_ratio`` (:attr:`gyro_agreement`, once measured) and ``gyro_set_aside_at`` (where
        it was)."""
        counts: dict[str, float] = {
            "matched": self.matched,
            "kept_prediction": self.kept_prediction,
        }
        if self.gyro is not None:
            counts["gyro_turns"] = self.gyro_turns
            if self.gyro_agreement is not None:
                correlation, ratio = self.gyro_agreement
                counts["gyro_correlation"] = round(correlation, 4)
                counts["gyro_ratio"] = round(ratio, 4)
        if self.gyro_set_aside_at is not None:
            counts["gyro_set_aside_at"] = self.gyro_set_aside_at
        return counts

    @property
    def gyro_agreement(self) -> tuple[float, float] | None:
        """The correlation of the gyro's turns with the matched scans' and the ratio of their
        RMS (both 1 where they agree), over the scans that turned more than
        :data:`GYRO_MIN_TURN`; None before any."""
        products, scans, gyros, count = self._agreement
        if not count:
            return None
        correlation = products / np.sqrt(scans * gyros) if gyros > 0 else 0.0
        return float(correlation), float(np.sqrt(gyros / scans))

    def _match(self, start: F64, ex: F64, ey: F64, plain: F64 | None = None) -> F64:
        """The scan's pose on the local map from ``start`` (module docstring), or ``start``;
        where ``start`` (the gyro's) does not fit and ``plain`` (the previous turn's) fits
        better, from ``plain``."""
        lc = self.config.loops
        if self.maps is None or ex.size < lc.min_beams:
            self.kept_prediction += 1
            return start
        view = self.maps.field(0)
        need = MIN_FIT * ex.size
        _, close_start = fit_counts(view, start, ex, ey, FIT_DISTANCE)
        if close_start < need and plain is not None:
            _, close_plain = fit_counts(view, plain, ex, ey, FIT_DISTANCE)
            if close_plain > close_start:
                start, close_start = plain, close_plain
        starts = [start]
        if close_start < need:
            self.unfit.append(len(self.poses))
            starts.append(self._search(view, start, ex, ey, SEARCH_TH))
        found, close = self._best(view, starts, ex, ey)
        if close < need:
            wide, close_wide = self._best(view, [self._search(view, start, ex, ey, np.pi)], ex, ey)
            if close_wide > close:
                found, close = wide, close_wide
            if close >= lc.min_beams and close > close_start:  # explains more than the start
                self.matched += 1
                return found
        if close < need or close < lc.min_beams:
            self.kept_prediction += 1
            return start
        self.matched += 1
        return found

    def _search(self, view: FieldView, start: F64, ex: F64, ey: F64, th: float) -> F64:
        """The best pose of a grid ± :data:`SEARCH_XY` and ± ``th`` (rad) around ``start``."""
        lc = self.config.loops
        self.searched += 1
        thin = slice(None, None, max(1, ex.size // lc.search_beams))
        t = self.tables
        return correlative_search(
            view, start, ex[thin].copy(), ey[thin].copy(), t.coarse[0, 0], t.coarse_inv,
            SEARCH_XY, lc.search_step, th, SEARCH_TH_STEP,
        )[:3].copy()  # fmt: skip

    def _best(self, view: FieldView, starts: list[F64], ex: F64, ey: F64) -> tuple[F64, int]:
        """The lowest-cost match of the scan from each of ``starts``, and how many of its
        returns lie within :data:`FIT_DISTANCE` of the map there."""
        best, best_cost = starts[0], np.inf
        for start in starts:
            t = self.tables
            found, cost, _ = match_one(
                view, start, ex, ey, t.luts, t.step_inv, t.iterations, self.config.rbpf.tolerance, 1
            )
            if cost < best_cost:
                best, best_cost = found, cost
        _, close = fit_counts(view, best, ex, ey, FIT_DISTANCE)
        return best, close

    def _is_keyframe(self, pose: F64) -> bool:
        """Whether ``pose`` lies far enough from the last keyframe's to be one."""
        if not self.keyframes:
            return True
        robot = self.config.robot
        d = relative(self.keyframes[-1][0], pose)
        return bool(
            np.hypot(d[0], d[1]) >= robot.laser_odometry_keyframe_m
            or abs(wrap_angle(d[2])) >= robot.laser_odometry_keyframe_rad
        )

    def _rebuild(self) -> None:
        """The local map anew from the keyframes in the window (a loop submap's settings)."""
        rc = self.config.rbpf
        maps = empty_submap(self.keyframes[-1][0], self.config)
        poses = np.array([p for p, _ in self.keyframes])
        hits = np.hstack([h for _, h in self.keyframes])
        sizes = [h.shape[1] for _, h in self.keyframes]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        reach = np.array([np.sqrt((h * h).sum(axis=0).max()) for _, h in self.keyframes])
        maps.insert_scans(poses, hits, offsets, reach + rc.dmax + 1.0, rc.skip_insert_below)
        self.maps = maps


def start_for_update(
    config: Config, owner: str, started: bool, ask: str, gyro: OdometryIntegrator | None = None
) -> LaserOdometry:
    """The laser odometry an online ``owner`` (``"Slam.update"``, ``"Localizer.update"``) starts
    when its first scan comes without odometry (turning with ``gyro`` where its IMU samples are
    fed); a :class:`~slam.errors.UsageError` naming what to give instead (``ask``) with
    ``robot.odometry = "log"``, or when earlier scans (``started``) came with odometry."""
    if config.robot.odometry == "log":
        raise UsageError(
            f'{owner}: {ask} (robot.odometry = "log"; "auto" or "laser" match the scans instead)'
        )
    if started:
        raise UsageError(f"{owner}: the earlier scans came with odometry; give it for this one too")
    return LaserOdometry(config, gyro)


def refuse_given(owner: str) -> UsageError:
    """The error of an online ``owner`` given odometry after scans that came without it."""
    return UsageError(
        f"{owner}: the earlier scans came without odometry (laser odometry); give none for this "
        "one either"
    )


def gyro_of(imu: ImuStream | None, config: Config) -> OdometryIntegrator | None:
    """An :class:`~slam.odometry.OdometryIntegrator` fed the z gyro of ``imu`` (samples in time
    order), for :class:`LaserOdometry`; None without an IMU or with
    ``robot.laser_odometry_gyro = false``."""
    if imu is None or len(imu) == 0 or not config.robot.laser_odometry_gyro:
        return None
    order = np.argsort(imu.time, kind="stable")
    gyro = OdometryIntegrator(config.robot)
    gyro.add_imu(np.asarray(imu.time)[order], np.asarray(imu.angular_velocity[2])[order])
    return gyro


def laser_odometry(
    scans: list[Scan], config: Config, imu: ImuStream | None = None
) -> tuple[F64, LaserOdometry]:
    """The :class:`LaserOdometry` pose ``(N, 3)`` at each of ``scans`` (resolved, in time
    order), turning with the gyro of ``imu`` where given (:func:`gyro_of`), and the odometry
    that made them (its counters)."""
    odometry = LaserOdometry(config, gyro_of(imu, config))
    poses = np.array([odometry.pose_at(scan) for scan in scans], dtype=np.float64)
    return poses.reshape(-1, 3), odometry
