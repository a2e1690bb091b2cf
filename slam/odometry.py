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
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from slam.config import RobotConfig
from slam.errors import DataError
from slam.geometry import interpolate_poses
from slam.io.log import EncoderStream, ImuStream, Log
from slam.kernels.filters import lowpass_first_order

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
) -> tuple[F64, F64]:
    """Dead-reckoned robot poses at every encoder reading, starting at the origin.

    Returns ``(times (N,), poses (N, 3))``. See the module docstring for the model and for what
    happens outside the IMU's time range.
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
        return times, integrate_arcs(distance, wheel_dtheta)

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
    return times, integrate_arcs(distance, dtheta)


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
        times, poses = dead_reckon_ece276a(log.encoders, log.imu, robot)
        return poses_at(times, poses, log.scans.time, what="scan")
    if log.odometry is not None:
        order = np.argsort(log.odometry.time, kind="stable")
        return poses_at(
            log.odometry.time[order], log.odometry.poses[order], log.scans.time, what="scan"
        )
    raise DataError(f"{log.name}: the log has no odometry (no encoders, no ODOM messages)")


def odometry_trajectory(log: Log, robot: RobotConfig) -> tuple[F64, F64]:
    """The dead-reckoning trajectory of a log, at its natural rate.

    One pose per encoder reading when the log has encoders (ECE276A), else one pose per scan
    (CARMEN, scans in file order with their own time stamps), else one per odometry message.
    """
    if log.encoders is not None:
        return dead_reckon_ece276a(log.encoders, log.imu, robot)
    if log.scans is not None:
        return np.asarray(log.scans.time, np.float64), scan_odometry(log, robot)
    if log.odometry is not None:
        return np.asarray(log.odometry.time, np.float64), np.asarray(log.odometry.poses)
    raise DataError(f"{log.name}: the log has no odometry (no encoders, scans or ODOM messages)")
