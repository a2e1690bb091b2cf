"""Simulated sensors of the ECE276A robot, sampled from a ground-truth trajectory and world.

Specifications (``docs/sim.md`` and the shared data-format notes):

* **Encoders**, 40 Hz: ticks per interval of the four wheels (FR, FL, RR, RL), int16. A side's
  wheels travel ``d(t) ± (track/2)·θ(t)``; each wheel's cumulative travel is quantised to whole
  ticks (``floor``), so counts never lose fractional ticks. Noise: per-interval slip of each wheel
  and front/rear scrub in turns (skid steer), which cancel on average over a side pair.
* **IMU**, 100 Hz: gyro (rad/s) with constant bias, bias random walk and white noise; the
  accelerometer (g) measures forward acceleration, centripetal acceleration ``v·ω`` and gravity
  (+1 g on z).
* **Hokuyo UTM-30LX**, 40 Hz: 1081 beams over ±135°, 0.1–30 m, mounted 0.13323 m ahead of the
  centre; ray cast against the obstacle grid. A beam reports the distance to the face it enters
  plus a 2 mm penetration (so a float32 range never rounds back into the free cell in front of the
  wall); no obstacle within 30 m reads exactly 30 m (the range maximum). Noise: Gaussian range
  noise (1 cm below 10 m, 3 cm beyond, per the datasheet), dropouts that read a few millimetres
  (below ``range_min``, like the real sensor's error codes), more likely at grazing incidence.
* **Kinect**, ≈20 Hz or lower: see :mod:`slam.sim.render`.

Time stamps are Unix-like seconds. Noise-free mode (:meth:`NoiseConfig.off`) sets every noise,
jitter and drop to zero, which makes dead reckoning from the encoders and IMU reproduce the
ground truth (up to tick quantisation).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from slam.geometry import compose
from slam.sim.kernels import cast_scans
from slam.sim.trajectory import Trajectory
from slam.sim.world import World

F64 = NDArray[np.float64]
GRAVITY = 9.80665


@dataclass(frozen=True)
class NoiseConfig:
    """Every noise of the simulated sensors; :meth:`off` gives the noise-free simulator."""

    time_jitter: float = 0.0008
    """Std of time-stamp jitter of encoders, IMU and lidar (s)."""
    encoder_slip: float = 0.015
    """Std of the relative per-interval travel error of each wheel."""
    encoder_scrub: float = 0.08
    """Front/rear travel difference per radian turned (m/rad), opposite for front and rear."""
    gyro_noise: float = 0.004
    """Std of gyro white noise per sample (rad/s)."""
    gyro_bias: float = 0.0015
    """Std of the constant gyro bias drawn per axis (rad/s)."""
    gyro_bias_walk: float = 0.0001
    """Gyro bias random walk (rad/s per √s)."""
    accel_noise: float = 0.003
    """Std of accelerometer white noise (g)."""
    accel_bias: float = 0.01
    """Std of the constant accelerometer bias per axis (g)."""
    lidar_noise_near: float = 0.01
    """Range noise std below 10 m (m)."""
    lidar_noise_far: float = 0.03
    """Range noise std beyond 10 m (m)."""
    lidar_dropout: float = 0.002
    """Probability that a beam returns an error reading."""
    lidar_grazing_dropout: float = 0.3
    """Extra dropout probability at grazing incidence (scaled by (1 − |cos|)⁴)."""
    disparity_noise: float = 0.35
    """Std of disparity noise before rounding (disparity units)."""
    disparity_holes: float = 0.004
    """Probability that a disparity pixel has no measurement."""
    rgb_noise: float = 0.0
    """Std of RGB pixel noise (levels of 255); off by default: it makes the PNGs ~40× larger and
    slower to write, while exposure changes (:attr:`rgb_gain`) already vary the colours."""
    rgb_gain: float = 0.03
    """Std of the per-frame exposure gain around 1."""
    rgb_delay: float = 0.012
    """Mean delay of an RGB frame after its disparity frame (s)."""
    rgb_delay_jitter: float = 0.004
    """Std of that delay (s)."""
    rgb_drop: float = 0.05
    """Probability that an RGB frame is missing from the log."""
    disparity_drop: float = 0.01
    """Probability that a disparity frame is missing from the log."""

    @classmethod
    def off(cls) -> NoiseConfig:
        """The noise-free simulator: exact sensors (quantisation only), no jitter, no drops."""
        return replace(cls(), **{name: 0.0 for name in cls.__dataclass_fields__})

    @property
    def enabled(self) -> bool:
        """Whether any noise is on."""
        return any(getattr(self, name) != 0.0 for name in self.__dataclass_fields__)


@dataclass(frozen=True)
class LidarSpec:
    """Hokuyo UTM-30LX as mounted on the ECE276A robot."""

    beams: int = 1081
    angle_min: float = -2.356194490192345
    angle_max: float = 2.356194490192345
    range_min: float = 0.1
    range_max: float = 30.0
    x: float = 0.13323
    """Mounting position ahead of the robot centre (m)."""
    rate_hz: float = 40.0
    penetration: float = 0.002
    """Distance a beam's endpoint lies inside the surface it hits (m)."""

    @property
    def angle_increment(self) -> float:
        """Angle between consecutive beams (rad)."""
        return (self.angle_max - self.angle_min) / (self.beams - 1)

    def angles(self) -> F64:
        """Beam angles (rad), counter-clockwise, 0 = forward."""
        return self.angle_min + self.angle_increment * np.arange(self.beams)


@dataclass(frozen=True)
class WheelSpec:
    """Wheel geometry of the ECE276A robot (matches :class:`slam.config.RobotConfig`)."""

    meters_per_tick: float = math.pi * 0.254 / 360.0
    track_width: float = 0.3937
    rate_hz: float = 40.0


def sample_times(
    rng: np.random.Generator, start: float, end: float, rate: float, jitter: float
) -> F64:
    """Time stamps at ``rate`` Hz from ``start`` up to ``end``, with Gaussian jitter (clipped)."""
    n = int(math.floor((end - start) * rate + 1e-9)) + 1
    t = start + np.arange(n) / rate
    if jitter > 0:
        t = t + np.clip(rng.normal(0.0, jitter, size=n), -0.3 / rate, 0.3 / rate)
    return t


def simulate_encoders(
    traj: Trajectory,
    times: F64,
    rng: np.random.Generator,
    noise: NoiseConfig,
    wheels: WheelSpec = WheelSpec(),
) -> NDArray[np.int16]:
    """Encoder counts ``(4, N)`` int16 (FR, FL, RR, RL) at ``times``; reading 0 counts nothing."""
    d = traj.distance_at(times)
    th = traj.heading_at(times)
    half = wheels.track_width / 2.0
    side = np.stack([d + half * th, d - half * th, d + half * th, d - half * th])  # FR FL RR RL
    inc = np.diff(side, axis=1)
    if noise.encoder_slip > 0 or noise.encoder_scrub > 0:
        dth = np.diff(th)
        slip = 1.0 + noise.encoder_slip * rng.standard_normal(inc.shape)
        scrub = noise.encoder_scrub * np.abs(dth) * rng.uniform(0.5, 1.5, size=dth.shape)
        inc = inc * slip
        inc[0:2] += scrub  # front wheels scrub forward in turns
        inc[2:4] -= scrub  # rear wheels backward; the side average is unchanged
    cum = np.concatenate([np.zeros((4, 1)), np.cumsum(inc, axis=1)], axis=1)
    ticks = np.floor(cum / wheels.meters_per_tick + 1e-9).astype(np.int64)
    counts = np.zeros_like(ticks)
    counts[:, 1:] = np.diff(ticks, axis=1)
    return counts.astype(np.int16)


def simulate_imu(
    traj: Trajectory, times: F64, rng: np.random.Generator, noise: NoiseConfig
) -> tuple[F64, F64]:
    """Gyro ``(3, N)`` rad/s and accelerometer ``(3, N)`` g at ``times``."""
    n = times.shape[0]
    w = traj.yaw_rate_at(times)
    v = traj.speed_at(times)
    a = traj.accel_at(times)
    gyro = np.zeros((3, n))
    gyro[2] = w
    accel = np.zeros((3, n))
    accel[0] = a / GRAVITY
    accel[1] = v * w / GRAVITY
    accel[2] = 1.0
    if noise.gyro_bias > 0 or noise.gyro_noise > 0 or noise.gyro_bias_walk > 0:
        bias = rng.normal(0.0, noise.gyro_bias, size=(3, 1))
        dt = np.diff(times, prepend=times[0])
        walk = np.cumsum(rng.standard_normal((3, n)) * np.sqrt(dt) * noise.gyro_bias_walk, axis=1)
        gyro = gyro + bias + walk + rng.normal(0.0, noise.gyro_noise, size=(3, n))
    if noise.accel_bias > 0 or noise.accel_noise > 0:
        accel = accel + rng.normal(0.0, noise.accel_bias, size=(3, 1))
        accel = accel + rng.normal(0.0, noise.accel_noise, size=(3, n))
    return gyro, accel


def mount_laser(robot_poses: F64, lidar: LidarSpec = LidarSpec()) -> F64:
    """World poses ``(N, 3)`` of the laser on a robot at ``robot_poses``."""
    return compose(robot_poses, np.array([lidar.x, 0.0, 0.0]))


def laser_poses(traj: Trajectory, times: F64, lidar: LidarSpec = LidarSpec()) -> F64:
    """World poses ``(N, 3)`` of the laser at ``times``."""
    return mount_laser(traj.pose_at(times), lidar)


def true_ranges(world: World, poses: F64, lidar: LidarSpec = LidarSpec()) -> tuple[F64, F64]:
    """Noise-free ranges ``(N, B)`` from laser ``poses`` (inf: nothing within range) and |cos|
    of the incidence angle."""
    ranges, incidence = cast_scans(
        world.labels,
        world.origin[0],
        world.origin[1],
        world.resolution,
        np.ascontiguousarray(poses),
        lidar.angles(),
        lidar.range_max,
    )
    return ranges, incidence


def measure_ranges(
    ranges: F64,
    incidence: F64,
    rng: np.random.Generator,
    noise: NoiseConfig,
    lidar: LidarSpec = LidarSpec(),
) -> NDArray[np.float32]:
    """What the Hokuyo reports for true ``ranges`` ``(N, B)`` (inf: no obstacle within range)
    at their incidences ``incidence`` (``|cos|``, broadcast to the ranges' shape): penetration,
    range noise, dropouts, no return as ``range_max``; float32 metres."""
    incidence = np.broadcast_to(incidence, ranges.shape)
    return _measure(lambda rows: (ranges[rows], incidence[rows]), ranges.shape, rng, noise, lidar)


def simulate_lidar(
    world: World,
    traj: Trajectory,
    times: F64,
    rng: np.random.Generator,
    noise: NoiseConfig,
    lidar: LidarSpec = LidarSpec(),
) -> NDArray[np.float32]:
    """Scans ``(N, 1081)`` float32 metres at ``times`` (see the module docstring):
    :func:`measure_ranges` of :func:`true_ranges`, ray cast :data:`LIDAR_ROWS` scans at a time."""
    poses = laser_poses(traj, times, lidar)
    shape = (poses.shape[0], lidar.angles().size)
    return _measure(lambda rows: true_ranges(world, poses[rows], lidar), shape, rng, noise, lidar)


LIDAR_ROWS = 2048
"""Scans whose ranges are measured at a time."""


def _measure(
    true_rows: Callable[[slice], tuple[F64, F64]],
    shape: tuple[int, int],
    rng: np.random.Generator,
    noise: NoiseConfig,
    lidar: LidarSpec,
) -> NDArray[np.float32]:
    """The ranges of :func:`measure_ranges`, ``true_rows(rows)`` giving the true ranges and
    incidences of a block of rows.

    A block of :data:`LIDAR_ROWS` scans at a time, the draws in the order of one whole-log
    draw each: every range's noise, then every dropout's chance, then every dropout's code (a
    numpy generator gives the same numbers in blocks as at once), so the log is the same to the
    bit while only the float32 ranges, the dropout chances and their mask are held whole (13
    bytes a reading instead of about 60: ``slam sim`` of an hour, 156 million readings, peaked
    at 2.4 GB)."""
    out = np.empty(shape, dtype=np.float32)
    drops = noise.lidar_dropout > 0 or noise.lidar_grazing_dropout > 0
    chance = np.empty(shape) if drops else None
    blocks = [slice(first, first + LIDAR_ROWS) for first in range(0, shape[0], LIDAR_ROWS)]
    for rows in blocks:
        ranges, incidence = true_rows(rows)
        hit = np.isfinite(ranges)
        ranges = np.where(hit, ranges + lidar.penetration, lidar.range_max)
        if noise.lidar_noise_near > 0 or noise.lidar_noise_far > 0:
            sigma = np.where(ranges < 10.0, noise.lidar_noise_near, noise.lidar_noise_far)
            ranges = np.where(hit, ranges + sigma * rng.standard_normal(ranges.shape), ranges)
        if chance is not None:
            chance[rows] = (
                noise.lidar_dropout + noise.lidar_grazing_dropout * (1.0 - incidence) ** 4 * hit
            )
        out[rows] = np.minimum(ranges, lidar.range_max)  # a dropout may replace it below
    if chance is None:
        return out
    drop = np.empty(shape, dtype=bool)
    for rows in blocks:
        drop[rows] = rng.uniform(size=out[rows].shape) < chance[rows]
    del chance
    for rows in blocks:
        error_codes = rng.integers(1, 20, size=out[rows].shape) / 1000.0
        out[rows] = np.where(drop[rows], np.minimum(error_codes, lidar.range_max), out[rows])
    return out


def kinect_times(
    rng: np.random.Generator, start: float, end: float, rate: float, noise: NoiseConfig
) -> tuple[F64, F64]:
    """Disparity and RGB frame times: one clock at ``rate`` Hz, RGB slightly later, some dropped."""
    clock = sample_times(rng, start, end, rate, noise.time_jitter)
    delay = noise.rgb_delay + noise.rgb_delay_jitter * rng.standard_normal(clock.shape)
    delay = np.clip(delay, 0.0, 0.4 / rate)
    keep_d = rng.uniform(size=clock.shape) >= noise.disparity_drop
    keep_r = rng.uniform(size=clock.shape) >= noise.rgb_drop
    rgb = clock + delay
    return clock[keep_d], rgb[keep_r & (rgb <= end)]
