"""Plausibility of a loaded log: its time base and its odometry (docs/data.md).

The loaders check each file on its own (shapes, dtypes, finite values, rates). What they cannot
see is whether the streams make sense together and over time; this module owns those checks,
run on every log before SLAM (``slam run``) and reported by ``slam data verify``:

Time base (``checks.max_backward_share``, ``checks.min_time_overlap``, ``checks.strict_time``)
    * a stream of two or more readings whose timestamps are all equal is an error;
    * a stream whose timestamps step backwards at more than ``max_backward_share`` of its steps
      (reversed, shuffled) is an error; fewer backward steps are a warning with their count
      (CARMEN logs step back now and then: intel 631 of 13630 scan steps);
    * scans (and Kinect frames) are placed by the encoder odometry and the encoders by the IMU's
      yaw: fewer than ``min_time_overlap`` of their readings within the partner stream's time
      span is an error (the clocks differ: milliseconds, another epoch, +1e18 s).

    ``checks.strict_time = false`` turns these errors into warnings.

Odometry jumps (``checks.max_speed``)
    The robot's odometry between consecutive readings (CARMEN: the pose in each scan line, in
    file order; ECE276A: the wheel travel of each encoder interval) may not move faster than
    ``max_speed``, with time steps floored at the stream's median step (timestamps jitter; a
    backward step counts by its size). A faster step is a corrupt reading (a FLASER line with
    odometry x = 1e9 would make the map allocate exabytes): an error naming the line or reading.

Errors are :class:`~slam.errors.DataError` naming the file; warnings are returned as strings.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.config import ChecksConfig, Config
from slam.errors import DataError
from slam.io.log import Log

F64 = NDArray[np.float64]


class DataWarning(UserWarning):
    """The log is usable but suspicious (sparse scans, backward timestamps)."""


@dataclass(frozen=True)
class _Stream:
    """One time-stamped stream of a log, named for messages."""

    key: str
    """Short name (``scans``, ``encoders``, ...)."""
    label: str
    """File (and key) it came from, e.g. ``.../Hokuyo20.npz: key 'time_stamps'``."""
    time: F64


def _ece_file(log: Log, stream: str) -> Path:
    from slam.io.ece276a import stream_file

    return stream_file(log.source or Path("."), log.meta.get("dataset_number", "NN"), stream)


def _streams(log: Log, kinect: bool = True) -> dict[str, _Stream]:
    """The time-stamped streams of ``log`` with labels naming their files (the Kinect's only
    with ``kinect``: a run that makes no texture does not read them)."""
    out: dict[str, _Stream] = {}
    if log.kind == "ece276a":
        pairs = [
            ("encoders", "encoders", log.encoders, "time_stamps"),
            ("imu", "imu", log.imu, "time_stamps"),
            ("scans", "scans", log.scans, "time_stamps"),
        ]
        for key, stream, data, field in pairs:
            if data is not None:
                label = f"{_ece_file(log, stream)}: key {field!r}"
                out[key] = _Stream(key, label, np.asarray(data.time, np.float64))
        if log.rgbd is not None and kinect:
            file = _ece_file(log, "kinect")
            out["rgb"] = _Stream("rgb", f"{file}: key 'rgb_time_stamps'", log.rgbd.rgb_time)
            out["disparity"] = _Stream(
                "disparity", f"{file}: key 'disparity_time_stamps'", log.rgbd.disparity_time
            )
        return out
    source = log.source or Path(log.name)
    if log.scans is not None:
        out["scans"] = _Stream("scans", f"{source}: scan timestamps", log.scans.time)
    if log.odometry is not None:
        out["odometry"] = _Stream("odometry", f"{source}: ODOM timestamps", log.odometry.time)
    return out


_PAIRS: tuple[tuple[str, str, str], ...] = (
    ("scans", "encoders", "scans are placed by the encoder odometry"),
    ("encoders", "imu", "the encoders' yaw comes from the IMU"),
    ("rgb", "encoders", "frames are placed by the encoder odometry"),
    ("disparity", "encoders", "frames are placed by the encoder odometry"),
)
"""(stream, partner, why): the stream's readings must lie within the partner's time span."""


MAX_CLOCK_STEP_S = 86400.0
"""A stream's clock stepping forward by more than this (s, a day) is a corrupt timestamp: no
log here pauses for longer than minutes (fr-clinic's 163 s before its second scan)."""


def time_base_problems(
    log: Log, checks: ChecksConfig, kinect: bool = True
) -> tuple[list[str], list[str]]:
    """``(errors, warnings)`` about the time base of ``log`` (see the module docstring); the
    Kinect's streams only with ``kinect``."""
    errors: list[str] = []
    warnings: list[str] = []
    streams = _streams(log, kinect)
    for s in streams.values():
        n = s.time.shape[0]
        if n < 2:
            continue
        steps = n - 1
        if float(s.time.max()) == float(s.time.min()):
            errors.append(
                f"{s.label}: all {n} timestamps are equal ({s.time[0]:.6f} s); expected "
                "times that increase"
            )
            continue
        step = np.diff(s.time)
        leap = int(np.argmax(step))
        if step[leap] > MAX_CLOCK_STEP_S:
            errors.append(
                f"{s.label}: the clock steps {step[leap]:.6g} s forward between readings "
                f"{leap} and {leap + 1} (t = {s.time[leap]:.6f} → {s.time[leap + 1]:.6f} s), more "
                f"than {MAX_CLOCK_STEP_S / 86400:g} day: a corrupt timestamp?"
            )
        backward = int(np.count_nonzero(step < 0))
        share = backward / steps
        if share > checks.max_backward_share:
            errors.append(
                f"{s.label}: {backward} of {steps} timestamp steps go backwards ({share:.0%}, "
                f"more than checks.max_backward_share = {checks.max_backward_share:g}); are the "
                "timestamps reversed or shuffled?"
            )
        elif backward:
            warnings.append(
                f"{s.label}: {backward} of {steps} timestamp steps go backwards ({share:.1%}); "
                "the readings are kept in file order"
            )
    for key, partner, why in _PAIRS:
        if key not in streams or partner not in streams:
            continue
        a, b = streams[key], streams[partner]
        lo, hi = float(b.time.min()), float(b.time.max())
        inside = int(np.count_nonzero((a.time >= lo) & (a.time <= hi)))
        share = inside / a.time.shape[0]
        if share < checks.min_time_overlap:
            errors.append(
                f"{a.label}: only {inside} of {a.time.shape[0]} readings ({share:.0%}) lie "
                f"within the time span of {b.label} ({lo:.6f}..{hi:.6f} s; these readings span "
                f"{float(a.time.min()):.6f}..{float(a.time.max()):.6f} s), less than "
                f"checks.min_time_overlap = {checks.min_time_overlap:g}, and {why}: do the two "
                "files share a clock?"
            )
    return errors, warnings


def first_jump(
    time: F64, xy: F64, max_speed: float, bursts: bool = False
) -> tuple[int, float, float] | None:
    """``(k, distance, dt)`` of the first step ``k-1 → k`` faster than ``max_speed``, else ``None``.

    ``dt`` is the step's time difference (absolute), floored at the median positive step; with
    ``bursts`` (a topic whose messages arrive in bursts, as a bag's odometry can: intel's median
    step is 1 ms of its 0.1 s mean) at the mean step if that is longer.
    """
    if time.shape[0] < 2:
        return None
    dt = np.abs(np.diff(time))
    positive = dt[dt > 0]
    floor = float(np.median(positive)) if positive.size else 1.0
    if bursts and positive.size:
        floor = max(floor, float(positive.sum()) / positive.size)
    dist = np.hypot(*np.diff(xy, axis=0).T)
    with np.errstate(over="ignore", invalid="ignore"):
        fast = ~(dist <= max_speed * np.maximum(dt, floor))
    if not fast.any():
        return None
    k = int(np.flatnonzero(fast)[0]) + 1
    return k, float(dist[k - 1]), float(dt[k - 1])


def odometry_jump(log: Log, config: Config) -> str | None:
    """The first implausible odometry step of ``log`` as an error message, else ``None``."""
    max_speed = config.checks.max_speed
    advice = (
        f"more than checks.max_speed = {max_speed:g} m/s: a corrupt reading (raise "
        "checks.max_speed for a faster robot)"
    )
    scans = log.scans
    if scans is not None and scans.odometry is not None:
        found = first_jump(scans.time, scans.odometry[:, :2], max_speed)
        if found is None:
            if config.robot.odometry == "laser" or config.robot.odometry_sync == "scan":
                return None  # the run reads the poses written with the scans, or no odometry
            return _message_jump(log, advice + _SCAN_POSES_HINT, max_speed)
        k, dist, dt = found
        source = log.source or Path(log.name)
        if scans.lines is not None:
            where = f"{source}:{int(scans.lines[k])}: scan odometry"
            since = f"line {int(scans.lines[k - 1])}"
        else:
            where, since = f"{source}: scan {k} odometry", f"scan {k - 1}"
        return f"{where} moves {dist:.4g} m from {since} in {dt:.3g} s ({dist / max(dt, 1e-9):.3g} m/s), {advice}"
    odometry = log.odometry
    if log.kind == "rosbag" and odometry is not None and len(odometry.time) > 1:
        order = np.argsort(odometry.time, kind="stable")  # the odometry topic, in stamp order
        found = first_jump(odometry.time[order], odometry.poses[order, :2], max_speed, True)
        if found is None:
            return None
        k, dist, dt = found
        what = log.meta.get("odom_source") or "odometry"
        return (
            f"{log.source or log.name}: {what} at t={float(odometry.time[order][k]):.6f} moves "
            f"{dist:.4g} m from the reading before in {dt:.3g} s "
            f"({dist / max(dt, 1e-9):.3g} m/s), {advice}"
        )
    if log.kind == "carmen" and config.robot.odometry != "laser":  # raw scans without poses:
        return _message_jump(log, advice, max_speed)  # the ODOM messages are the odometry
    if log.encoders is not None:
        from slam.odometry import wheel_travel

        right, left = wheel_travel(log.encoders, config.robot)
        travel = np.cumsum(0.5 * (np.abs(right) + np.abs(left)))
        xy = np.stack([travel, np.zeros_like(travel)], axis=1)
        found = first_jump(log.encoders.time, xy, max_speed)
        if found is None:
            return None
        k, dist, dt = found
        return (
            f"{_ece_file(log, 'encoders')}: key 'counts', reading {k}: the wheels travel "
            f"{dist:.4g} m in {dt:.3g} s ({dist / max(dt, 1e-9):.3g} m/s), {advice}"
        )
    return None


_SCAN_POSES_HINT = (
    '; robot.odometry_sync = "scan" reads the poses written with the scans instead of these '
    "messages"
)


def _message_jump(log: Log, advice: str, max_speed: float) -> str | None:
    """The first implausible step of a CARMEN log's ``ODOM`` messages (which a run may take for
    its odometry, ``robot.odometry_sync = "auto"``), naming its line, else ``None``."""
    odometry = log.odometry
    if odometry is None or odometry.lines is None or len(odometry) < 2:
        return None
    # messages in bursts (intel's: a median step of 3 ms): steps floored at the mean step
    found = first_jump(odometry.time, odometry.poses[:, :2], max_speed, bursts=True)
    if found is None:
        return None
    k, dist, dt = found
    return (
        f"{log.source or log.name}:{int(odometry.lines[k])}: ODOM moves {dist:.4g} m from line "
        f"{int(odometry.lines[k - 1])} in {dt:.3g} s ({dist / max(dt, 1e-9):.3g} m/s), {advice}"
    )


def check_plausibility(log: Log, config: Config) -> list[str]:
    """Raise :class:`DataError` for the first time-base error or odometry jump of ``log``;
    return the warnings (time-base errors too, with ``checks.strict_time = false``)."""
    # the Kinect's clock matters to the texture only (slam texture checks its frames itself)
    errors, warnings = time_base_problems(log, config.checks, config.texture.enabled)
    if errors and config.checks.strict_time:
        raise DataError(f"{errors[0]} (checks.strict_time = false accepts it)")
    jump = odometry_jump(log, config)
    if jump is not None:
        raise DataError(jump)
    unit = gyro_unit(log, config)
    if unit is not None:
        raise DataError(unit)
    return errors + warnings


GYRO_WHEEL_RATIO = 10.0
"""A gyro that turns the robot this many times as far as its wheels do reads another unit
than rad/s (deg/s: 57 times); skid-steered wheels overstate turns, so the ratio is below 1."""


def gyro_unit(log: Log, config: Config) -> str | None:
    """The error of an ECE276A log whose gyro reads degrees per second: over the encoders' time
    span, the gyro's total turn ``∫|ω| dt`` is :data:`GYRO_WHEEL_RATIO` times the wheels'
    ``Σ|Δθ|`` or more (judged once the wheels turned 2 rad); else ``None``."""
    if log.kind != "ece276a" or log.encoders is None or log.imu is None or len(log.imu) < 2:
        return None
    if config.robot.yaw_source != "imu":  # the gyro is not read (the way around a bad one)
        return None
    from slam.odometry import wheel_travel

    right, left = wheel_travel(log.encoders, config.robot)
    wheels = float(np.abs(right - left).sum()) / config.robot.track_width
    t, rate = log.imu.time, np.asarray(log.imu.angular_velocity[2], dtype=np.float64)
    inside = (t >= log.encoders.time.min()) & (t <= log.encoders.time.max())
    if wheels < 2.0 or np.count_nonzero(inside) < 2:
        return None
    dt = np.diff(t[inside])
    gyro = float(np.sum(np.abs(rate[inside][1:]) * np.where(dt > 0, dt, 0.0)))
    if gyro < GYRO_WHEEL_RATIO * wheels:
        return None
    return (
        f"{_ece_file(log, 'imu')}: key 'angular_velocity': the gyro turns the robot "
        f"{gyro / wheels:.0f} times as far as its wheels ({gyro:.0f} rad against {wheels:.1f} rad "
        "over the encoders' time span): expected rad/s (degrees per second? multiply by π/180)"
    )


def scan_source(log: Log) -> str:
    """The file the scans of ``log`` came from, for messages."""
    if log.kind == "ece276a":
        return str(_ece_file(log, "scans"))
    return str(log.source or log.name)


def check_valid_beams(
    log: Log,
    ranges: NDArray[np.float32],
    range_min: float,
    range_max: float,
    no_return: float,
    checks: ChecksConfig,
) -> str | None:
    """Count the valid beams of the processed scans ``ranges`` (finite readings above 0 in
    ``[range_min, range_max)``: the obstacle hits a scan matcher can use).

    :class:`DataError` naming the file and what its readings are when no scan has one; a warning
    when more than ``checks.max_sparse_scan_share`` of the scans have fewer than
    ``checks.min_valid_beams``; else ``None``.
    """
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ranges) & (ranges >= range_min) & (ranges > 0) & (ranges < range_max)
    per_scan = valid.sum(axis=1)
    n = int(per_scan.shape[0])
    window = f"[range_min, range_max) = [{range_min:g}, {range_max:g}) m"
    if not per_scan.any():
        finite = ranges[np.isfinite(ranges)]
        longest = f"{float(finite.max()):.4g} m" if finite.size else "none"
        with np.errstate(invalid="ignore"):
            beyond = int(np.count_nonzero(finite >= no_return))
            between = int(np.count_nonzero((finite >= range_max) & (finite < no_return)))
        raise DataError(
            f"{scan_source(log)}: no scan has a valid beam (a finite reading in {window}; "
            f"lidar.range_min, lidar.range_max): of the {n} processed scans' {ranges.size} "
            f"readings, {ranges.size - finite.size} are invalid (NaN, inf, negative, below "
            f"range_min or beyond 1000 m), {between} between range_max "
            f"and no_return = {no_return:g} m and {beyond} at or beyond no_return (no echo); "
            f"longest reading {longest}"
        )
    sparse = int(np.count_nonzero(per_scan < checks.min_valid_beams))
    share = sparse / n
    if share > checks.max_sparse_scan_share:
        return (
            f"{scan_source(log)}: {sparse} of {n} processed scans ({share:.0%}, more than "
            f"checks.max_sparse_scan_share = {checks.max_sparse_scan_share:g}) have fewer than "
            f"checks.min_valid_beams = {checks.min_valid_beams} valid beams (finite readings in "
            f"{window}); the filter has little to match them against, expect drift "
            f"(median {float(np.median(per_scan)):g} valid beams per scan)"
        )
    return None
