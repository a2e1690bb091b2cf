"""Odometry: wheel encoders and IMU yaw rate to motion; dead reckoning; odometry at scan times.

The ECE276A robot is skid-steered, so its wheels measure forward travel well but yaw badly. The
standard model (the course's) takes the linear displacement from the encoders and the yaw change
from the IMU z gyro:

* per encoder interval ``i`` (from reading ``i-1`` to ``i``), right and left travel are
  ``(FR+RR)/2 · m`` and ``(FL+RL)/2 · m`` with ``m`` metres per tick, and the distance is their mean;
* the yaw change over the interval is the integral of the (zero-phase low-passed) gyro z rate
  between the two reading times;
* the pose advances along the circular arc with that length and heading change: the chord is
  ``d · sin(Δθ/2) / (Δθ/2)`` in the direction ``θ + Δθ/2``, exact for constant speed and turn rate.

The IMU stream ends 1.5–2 s before the encoders on the course logs. Rates are never extrapolated
silently: within ``robot.max_imu_gap_s`` of the IMU's ends the last rate is held; beyond that the
yaw comes from the wheels (``(right − left) / track_width``) and an :class:`OdometryWarning` says
for how many intervals and seconds.

CARMEN logs carry odometry poses already; their motion between scans is the relative pose of
consecutive odometry poses (:func:`scan_odometry`).

Batch and online
    :func:`dead_reckon_ece276a` integrates a whole recorded log: its gyro low-pass runs forward
    and backward (zero phase), which needs the samples after each time. :class:`OdometryIntegrator`
    is the causal form for a robot that feeds readings as they arrive (``Slam.add_encoders``,
    ``Slam.add_imu``): the same arcs and the same IMU-gap rule, with a forward-only low-pass
    (a lag of ``1/(2π f_c)``, 16 ms at 10 Hz) and the pose at a scan extrapolated from the last
    encoder reading instead of interpolated towards the next one. With the low-pass off
    (``robot.imu_lowpass_hz = 0``) both give the same poses at the encoder readings.
"""

from __future__ import annotations

import bisect
import math
import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.config import RobotConfig
from slam.errors import DataError
from slam.geometry import interpolate_poses
from slam.io.log import EncoderStream, ImuStream, Log
from slam.kernels.filters import lowpass_first_order
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]


class OdometryWarning(UserWarning):
    """Odometry had to fall back or clamp (e.g. times outside the IMU's range)."""


def wheel_travel(encoders: EncoderStream, robot: RobotConfig) -> tuple[F64, F64]:
    """Right and left wheel travel (m) of each interval ending at each reading.

    Reading 0's ticks were accumulated before the log's first time stamp, so its travel is zero.
    """
    counts = encoders.counts.astype(np.float64)
    right = 0.5 * (counts[0] + counts[2]) * robot.meters_per_tick
    left = 0.5 * (counts[1] + counts[3]) * robot.meters_per_tick
    right[0] = 0.0
    left[0] = 0.0
    return right, left


def yaw_rate(imu: ImuStream, robot: RobotConfig) -> F64:
    """The gyro z rate, low-passed at ``robot.imu_lowpass_hz`` (0 disables the filter)."""
    rate = np.ascontiguousarray(imu.angular_velocity[2], dtype=np.float64)
    if robot.imu_lowpass_hz > 0:
        rate = lowpass_first_order(rate, np.ascontiguousarray(imu.time), robot.imu_lowpass_hz)
    return rate


def _heading_integral(times: F64, rate: F64, gap: float) -> tuple[F64, F64]:
    """Times and cumulative heading (trapezoid rule), extended by ``gap`` at both ends."""
    steps = 0.5 * (rate[1:] + rate[:-1]) * np.diff(times)
    heading = np.concatenate([[0.0], np.cumsum(steps)])
    t = np.concatenate([[times[0] - gap], times, [times[-1] + gap]])
    h = np.concatenate([[-rate[0] * gap], heading, [heading[-1] + rate[-1] * gap]])
    return t, h


def integrate_arcs(distance: F64, dtheta: F64, start: F64 | None = None) -> F64:
    """Chain arcs (length ``distance[i]``, heading change ``dtheta[i]``) into poses.

    ``poses[0]`` is ``start`` (default the origin) and ``distance[0]``/``dtheta[0]`` are ignored,
    matching the encoder convention (reading 0 closes no interval).
    """
    n = distance.shape[0]
    theta0 = 0.0 if start is None else float(start[2])
    dth = dtheta.copy()
    dth[0] = 0.0
    theta = theta0 + np.cumsum(dth)
    half = 0.5 * dth
    chord = distance * np.sinc(half / np.pi)  # np.sinc(x) = sin(πx)/(πx)
    heading_mid = theta - half
    steps_x = chord * np.cos(heading_mid)
    steps_y = chord * np.sin(heading_mid)
    steps_x[0] = 0.0
    steps_y[0] = 0.0
    poses = np.empty((n, 3))
    poses[:, 0] = np.cumsum(steps_x)
    poses[:, 1] = np.cumsum(steps_y)
    poses[:, 2] = np.arctan2(np.sin(theta), np.cos(theta))
    if start is not None:
        poses[:, 0] += start[0]
        poses[:, 1] += start[1]
    return poses


def dead_reckon_ece276a(
    encoders: EncoderStream, imu: ImuStream | None, robot: RobotConfig
) -> Trajectory:
    """Dead-reckoned robot poses at every encoder reading, starting at the origin.

    See the module docstring for the model and for what happens outside the IMU's time range.
    """
    times = np.asarray(encoders.time, dtype=np.float64)
    if times.shape[0] == 0:
        raise DataError("encoders: no readings to integrate")
    right, left = wheel_travel(encoders, robot)
    distance = 0.5 * (right + left)
    wheel_dtheta = (right - left) / robot.track_width
    if robot.yaw_source == "encoders" or imu is None:
        if robot.yaw_source == "imu":
            warnings.warn(
                "odometry: no IMU stream, yaw comes from the wheels (skid-steer: unreliable)",
                OdometryWarning,
                stacklevel=2,
            )
        return Trajectory(times, integrate_arcs(distance, wheel_dtheta))

    if len(imu) < 2:
        raise DataError(f"IMU: need at least 2 samples to integrate yaw, found {len(imu)}")
    gap = robot.max_imu_gap_s
    t_ext, h_ext = _heading_integral(np.asarray(imu.time, np.float64), yaw_rate(imu, robot), gap)
    covered = (times >= t_ext[0]) & (times <= t_ext[-1])
    heading = np.interp(times, t_ext, h_ext)
    dtheta = np.empty_like(distance)
    dtheta[0] = 0.0
    dtheta[1:] = np.diff(heading)
    interval_ok = np.ones_like(covered)
    interval_ok[1:] = covered[1:] & covered[:-1]
    interval_ok[0] = True
    if not np.all(interval_ok):
        bad = ~interval_ok
        dtheta[bad] = wheel_dtheta[bad]
        seconds = float(np.sum(np.diff(times)[bad[1:]]))
        warnings.warn(
            f"odometry: {int(bad.sum())} encoder intervals ({seconds:.2f} s) lie outside the IMU's "
            f"time range [{imu.time[0]:.3f}, {imu.time[-1]:.3f}] (+/- {gap} s); their yaw comes "
            "from the wheels",
            OdometryWarning,
            stacklevel=2,
        )
    return Trajectory(times, integrate_arcs(distance, dtheta))


def poses_at(times: F64, poses: F64, query: F64, what: str = "poses") -> F64:
    """Poses interpolated at ``query`` times; queries outside ``times`` are clamped, with a warning."""
    query = np.asarray(query, dtype=np.float64)
    outside = (query < times[0]) | (query > times[-1])
    if np.any(outside):
        warnings.warn(
            f"odometry: {int(outside.sum())} {what} times lie outside the odometry's time range "
            f"[{times[0]:.3f}, {times[-1]:.3f}]; their poses are held at the nearest end",
            OdometryWarning,
            stacklevel=2,
        )
    return interpolate_poses(times, poses, query)


def has_odometry(log: Log) -> bool:
    """Whether ``log`` holds any odometry: poses with its scans, encoders, or odometry messages."""
    if log.scans is not None and log.scans.odometry is not None:
        return True
    return log.encoders is not None or (log.odometry is not None and len(log.odometry.time) > 0)


def never_moves(poses: F64) -> bool:
    """Whether odometry ``poses`` ``(N, 3)`` (N ≥ 2) are all the same pose: no odometry at all,
    as a log whose scan lines carry zeros has."""
    return len(poses) > 1 and not np.any(poses != poses[0])


def moving_stream(log: Log) -> bool:
    """Whether ``log`` has odometry messages that move (what stands in for scan poses that
    never do)."""
    stream = log.odometry
    return stream is not None and len(stream.time) > 1 and not never_moves(stream.poses)


def scan_odometry(log: Log, robot: RobotConfig) -> F64:
    """Odometry pose ``(N, 3)`` of the robot at each scan of ``log`` (in file order).

    CARMEN scans carry their odometry pose; ECE276A scans get the dead-reckoned encoder + IMU
    pose interpolated at the scan time; otherwise the log's odometry stream is interpolated.
    """
    if log.scans is None:
        raise DataError(f"{log.name}: the log has no laser scans")
    if log.scans.odometry is not None:
        return np.asarray(log.scans.odometry, dtype=np.float64)
    if log.encoders is not None:
        odometry = dead_reckon_ece276a(log.encoders, log.imu, robot)
        return poses_at(odometry.times, odometry.poses, log.scans.time, what="scan")
    if log.odometry is not None:
        order = np.argsort(log.odometry.time, kind="stable")
        return poses_at(
            log.odometry.time[order], log.odometry.poses[order], log.scans.time, what="scan"
        )
    raise DataError(
        f"{log.source or log.name}: the log has no odometry (no encoders, no ODOM messages); "
        'robot.odometry = "auto" or "laser" runs on the laser\'s scan matching instead'
    )


def odometry_trajectory(log: Log, robot: RobotConfig) -> Trajectory:
    """The dead-reckoning trajectory of a log, at its natural rate.

    One pose per encoder reading when the log has encoders (ECE276A), else one pose per scan
    (CARMEN, scans in file order with their own time stamps), else one per odometry message.
    """
    if log.encoders is not None:
        return dead_reckon_ece276a(log.encoders, log.imu, robot)
    if log.scans is not None:
        return Trajectory(log.scans.time, scan_odometry(log, robot))
    if log.odometry is not None:
        return Trajectory(log.odometry.time, log.odometry.poses)
    raise DataError(f"{log.name}: the log has no odometry (no encoders, scans or ODOM messages)")


def _readings(values: ArrayLike, what: str, unit: str, ndim: int = 1) -> F64:
    """``values`` as a float64 array of at least one dimension and at most ``ndim``, every
    value finite; else :class:`DataError` naming ``what`` (``encoders: time``)."""
    try:
        array = np.atleast_1d(np.asarray(values, dtype=np.float64))
    except (TypeError, ValueError):
        raise DataError(f"{what}: expected numbers ({unit}), found {values!r:.60}") from None
    if array.ndim > ndim:
        raise DataError(f"{what}: expected at most {ndim} dimension(s), found shape {array.shape}")
    bad = ~np.isfinite(array)
    if bad.any():
        raise DataError(
            f"{what}: expected finite {unit}, found {array[bad].ravel()[0]} at index "
            f"{int(np.flatnonzero(bad.ravel())[0])}"
        )
    return array


class OdometryIntegrator:
    """Causal dead reckoning of the ECE276A robot from readings fed as they arrive.

    Feed gyro samples with :meth:`add_imu` and encoder readings with :meth:`add_encoders`, each
    stream in time order; :meth:`pose_at` gives the pose at a scan time from what has arrived so
    far. The model is :func:`dead_reckon_ece276a`'s (see the module docstring for the differences:
    forward-only low-pass, extrapolation past the last encoder reading).
    """

    def __init__(self, robot: RobotConfig) -> None:
        self.robot = robot
        self._rc = 1.0 / (2.0 * math.pi * robot.imu_lowpass_hz) if robot.imu_lowpass_hz > 0 else 0.0
        # the gyro: sample times, low-passed rates and the heading integral at each sample
        self._imu_times: list[float] = []
        self._rates: list[float] = []
        self._headings: list[float] = []
        # the encoders: reading times and poses (heading unwrapped), the IMU heading at each
        self._times: list[float] = []
        self._poses: list[tuple[float, float, float]] = []
        self._imu_heading: float | None = None
        self._speed = 0.0
        self._turn_rate = 0.0
        self._last_interval = 0.0
        self.wheel_yaw_intervals = 0
        """Encoder intervals whose yaw came from the wheels (outside the IMU's time range)."""
        self._turns = [0.0, 0.0]  # the gyro's and the wheels' total |turn| where both are read
        self._unit_warned = False

    def add_imu(self, time: ArrayLike, gyro_z: ArrayLike) -> None:
        """Add gyro z samples (rad/s) taken at ``time`` (s); scalars or arrays."""
        times = _readings(time, "IMU: time", "seconds")
        rates = _readings(gyro_z, "IMU: gyro_z", "rad/s")
        if times.shape != rates.shape:
            raise DataError(f"IMU: {times.size} sample times for {rates.size} gyro readings")
        for t, x in zip(times.tolist(), rates.tolist(), strict=True):
            if not self._imu_times:
                self._imu_times.append(t)
                self._rates.append(x)
                self._headings.append(0.0)
                continue
            last = self._imu_times[-1]
            if t < last:
                raise DataError(f"IMU: sample at {t:.6f} s comes after one at {last:.6f} s")
            dt = t - last
            y = self._rates[-1]
            if self._rc > 0:
                a = dt / (self._rc + dt) if dt > 0.0 else 0.0
                y_new = y + a * (x - y)
            else:
                y_new = x
            self._imu_times.append(t)
            self._headings.append(self._headings[-1] + 0.5 * (y_new + y) * dt)
            self._rates.append(y_new)

    def _heading_at(self, t: float) -> float | None:
        """The gyro's heading integral at ``t``, or ``None`` outside its range (± the gap)."""
        times, gap = self._imu_times, self.robot.max_imu_gap_s
        if self.robot.yaw_source != "imu" or not times:
            return None
        if t < times[0] - gap or t > times[-1] + gap:
            return None
        if t >= times[-1]:
            return self._headings[-1] + self._rates[-1] * (t - times[-1])
        if t <= times[0]:
            return self._headings[0] - self._rates[0] * (times[0] - t)
        j = bisect.bisect_right(times, t) - 1
        slope = (self._headings[j + 1] - self._headings[j]) / (times[j + 1] - times[j])
        return slope * (t - times[j]) + self._headings[j]

    @property
    def has_imu(self) -> bool:
        """Whether a gyro sample has been fed."""
        return bool(self._imu_times)

    @property
    def has_encoders(self) -> bool:
        """Whether an encoder reading has been fed."""
        return bool(self._times)

    def gyro_heading(self, t: float) -> float | None:
        """The gyro's heading integral at ``t`` (rad, from its first sample) from the samples
        at or before ``t`` only: the last one's integral moved on at its (low-passed) rate, or
        ``None`` before the first sample or more than ``robot.max_imu_gap_s`` after the last
        one at or before ``t``. Causal, so a batch fed the whole IMU stream and an online run
        fed the samples up to each scan give the same value (laser odometry's turns,
        :mod:`slam.laser_odometry`)."""
        times = self._imu_times
        j = bisect.bisect_right(times, t) - 1
        if j < 0 or t - times[j] > self.robot.max_imu_gap_s:
            return None
        return self._headings[j] + self._rates[j] * (t - times[j])

    def add_encoders(self, time: ArrayLike, counts: ArrayLike) -> None:
        """Add encoder readings: ``counts`` ``(4,)`` or ``(4, K)`` ticks (FR, FL, RR, RL) since
        the previous reading, taken at ``time`` (s). The first reading ever only starts the clock
        (its ticks were counted before it)."""
        times = _readings(time, "encoders: time", "seconds")
        ticks = _readings(counts, "encoders: counts", "ticks", ndim=2)
        if ticks.ndim == 1 and ticks.size == 4:
            ticks = ticks.reshape(4, 1)
        if ticks.ndim != 2 or ticks.shape[0] != 4:
            turned = " (readings as rows? pass counts.T)" if ticks.shape[-1] == 4 else ""
            raise DataError(
                "encoders: counts must be (4,) or (4, K) ticks (FR, FL, RR, RL), found shape "
                f"{ticks.shape}{turned}"
            )
        if ticks.shape[1] != times.size:
            raise DataError(f"encoders: {times.size} reading times for {ticks.shape[1]} readings")
        m, track = self.robot.meters_per_tick, self.robot.track_width
        for i, t in enumerate(times.tolist()):
            heading = self._heading_at(t)
            if not self._times:
                self._times.append(t)
                self._poses.append((0.0, 0.0, 0.0))
                self._imu_heading = heading
                continue
            last = self._times[-1]
            if t < last:
                raise DataError(f"encoders: reading at {t:.6f} s comes after one at {last:.6f} s")
            right = 0.5 * (ticks[0, i] + ticks[2, i]) * m
            left = 0.5 * (ticks[1, i] + ticks[3, i]) * m
            distance = 0.5 * (right + left)
            dt = t - last
            if heading is not None and self._imu_heading is not None:
                dtheta = heading - self._imu_heading
                self._watch_gyro_unit(abs(dtheta), abs(right - left) / track)
            else:
                dtheta = (right - left) / track
                self._count_wheel_yaw()
            self._imu_heading = heading
            self._poses.append(_advance(self._poses[-1], distance, dtheta))
            self._times.append(t)
            self._speed = distance / dt if dt > 0 else 0.0
            self._turn_rate = dtheta / dt if dt > 0 else 0.0
            self._last_interval = dt

    def _watch_gyro_unit(self, gyro: float, wheels: float) -> None:
        """Warn once when the gyro has turned the robot ten times as far as its wheels, after the
        wheels turned 2 rad: a gyro read in degrees per second (57 times; the course's logs
        0.45–0.48), the check :func:`slam.io.plausibility.gyro_unit` makes on a whole log."""
        self._turns[0] += gyro
        self._turns[1] += wheels
        g, w = self._turns
        if not self._unit_warned and w >= 2.0 and g >= 10.0 * w:
            self._unit_warned = True
            warnings.warn(
                f"odometry: the gyro has turned the robot {g / w:.0f} times as far as its wheels "
                f"({g:.0f} rad against {w:.1f} rad): expected rad/s (degrees per second? "
                "multiply by π/180)",
                OdometryWarning,
                stacklevel=4,
            )

    def _count_wheel_yaw(self) -> None:
        if self.robot.yaw_source == "imu" and self.wheel_yaw_intervals == 0:
            warnings.warn(
                "odometry: encoder intervals outside the IMU's time range (or before any IMU "
                "sample); their yaw comes from the wheels",
                OdometryWarning,
                stacklevel=4,
            )
        self.wheel_yaw_intervals += 1

    def pose_at(self, t: float) -> F64:
        """The robot's pose at time ``t`` from the readings so far.

        Between readings the poses are interpolated; before the first one it is the start pose;
        past the last one the robot moves on at the last interval's speed (heading from the gyro
        when it covers ``t``) for at most one interval, then stands.
        """
        if not self._times:
            raise DataError(f"odometry: no encoder reading before the scan at {t:.6f} s")
        times, poses = self._times, self._poses
        if t <= times[0]:
            return _wrapped(poses[0])
        if t < times[-1]:
            j = bisect.bisect_right(times, t) - 1
            f = (t - times[j]) / (times[j + 1] - times[j])
            a, b = poses[j], poses[j + 1]
            return _wrapped(tuple(a[n] + f * (b[n] - a[n]) for n in range(3)))  # type: ignore[arg-type]
        ahead = min(t - times[-1], self._last_interval)
        heading, then = self._heading_at(times[-1] + ahead), self._imu_heading
        turn = (
            heading - then if heading is not None and then is not None else self._turn_rate * ahead
        )
        return _wrapped(_advance(poses[-1], self._speed * ahead, turn))


def _advance(
    pose: tuple[float, float, float], distance: float, dtheta: float
) -> tuple[float, float, float]:
    """``pose`` (heading unwrapped) moved along an arc of length ``distance`` turning ``dtheta``
    (the rule of :func:`integrate_arcs`)."""
    x, y, theta = pose
    half = 0.5 * dtheta
    chord = distance * float(np.sinc(half / np.pi))
    theta_new = theta + dtheta
    mid = theta_new - half  # as integrate_arcs computes it, so both agree to the last bit
    return (x + chord * math.cos(mid), y + chord * math.sin(mid), theta_new)


def _wrapped(pose: tuple[float, float, float]) -> F64:
    return np.array([pose[0], pose[1], math.atan2(math.sin(pose[2]), math.cos(pose[2]))])
