"""Small synthetic logs for tests: a robot driving through a box room, as CARMEN text or as the
ECE276A files. Every range is ray-cast, so SLAM on them runs like on a real (if boring) log.

Not a test module (no ``test_`` prefix); the tests import it (pytest puts ``tests/`` on the path).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOM = (-5.0, 5.0, -3.0, 3.0)
"""The walls: x from -5 to 5 m, y from -3 to 3 m."""
PILLAR = (1.0, 1.5, 1.0, 1.5)
"""A square pillar, so the room is not symmetric."""
T0 = 1298445274.5
"""Start time of the ECE276A logs (Unix time, like the course's)."""


def _box_hits(x: np.ndarray, y: np.ndarray, c: np.ndarray, s: np.ndarray, box, inside: bool):
    """Distance along (c, s) from (x, y) to the box's boundary (inf where missed)."""
    x0, x1, y0, y1 = box
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.stack([(x0 - x) / c, (x1 - x) / c])
        ty = np.stack([(y0 - y) / s, (y1 - y) / s])
    if inside:
        tx = np.where(tx > 0, tx, np.inf).min(axis=0)
        ty = np.where(ty > 0, ty, np.inf).min(axis=0)
        return np.minimum(tx, ty)
    t_near = np.maximum(np.minimum(tx[0], tx[1]), np.minimum(ty[0], ty[1]))
    t_far = np.minimum(np.maximum(tx[0], tx[1]), np.maximum(ty[0], ty[1]))
    hit = (t_near <= t_far) & (t_near > 0)
    return np.where(hit, t_near, np.inf)


def ray_cast(pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Ranges from ``pose`` (x, y, θ) along ``angles`` (sensor frame) to the room's walls."""
    a = pose[2] + angles
    c, s = np.cos(a), np.sin(a)
    x = np.full_like(a, pose[0])
    y = np.full_like(a, pose[1])
    walls = _box_hits(x, y, c, s, ROOM, inside=True)
    pillar = _box_hits(x, y, c, s, PILLAR, inside=False)
    return np.minimum(walls, pillar)


def path(n: int) -> np.ndarray:
    """``(n, 3)`` poses: from (-3, -1) along x with a gentle curve, 0.05 m per step."""
    k = np.arange(n)
    x = -3.0 + 0.05 * k
    y = -1.0 + 0.3 * np.sin(k / 40.0)
    theta = np.arctan2(np.gradient(y), np.gradient(x))
    return np.stack([x, y, theta], axis=1)


def flaser_line(ranges, pose, t: float) -> str:
    """One FLASER line (laser pose = odometry pose)."""
    nums = " ".join(f"{r:.3f}" for r in ranges)
    p = " ".join(f"{v:.6f}" for v in pose)
    return f"FLASER {len(ranges)} {nums} {p} {p} {t:.6f} host {t:.6f}"


def carmen_lines(
    n: int = 40, beams: int = 180, period: float = 0.1, interlaced: bool = False
) -> list[str]:
    """FLASER lines of ``n`` scans along :func:`path`, one every ``period`` seconds.

    ``interlaced``: a SICK LMS's interlaced sweeps instead, as fr-clinic has them: the even
    scans read the 181 whole degrees from −90° to +90°, the odd ones the 180 half degrees
    between them (``beams`` is not used)."""
    angles = np.linspace(-np.pi / 2, np.pi / 2, beams)
    halves = np.deg2rad(np.arange(180) - 89.5)
    wholes = np.deg2rad(np.arange(181) - 90.0)
    lines = []
    for k, pose in enumerate(path(n)):
        if interlaced:
            angles = halves if k % 2 else wholes
        lines.append(flaser_line(ray_cast(pose, angles), pose, 100.0 + period * k))
    return lines


def write_carmen(folder: Path, lines: list[str], name: str = "room.clf") -> Path:
    """Write ``lines`` (with a comment line first) as a CARMEN log; return its path."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / name
    out.write_text("# synthetic box room\n" + "\n".join(lines) + "\n")
    return out


HOKUYO_BEAMS = 1081
ANGLE_MIN = -2.356194490192345
ANGLE_INCREMENT = 2 * 2.356194490192345 / (HOKUYO_BEAMS - 1)
METERS_PER_TICK = np.pi * 0.254 / 360.0


def write_ece276a(
    folder: Path,
    n: int = 200,
    nn: int = 20,
    ranges: np.ndarray | None = None,
    scan_times: np.ndarray | None = None,
    encoder_times: np.ndarray | None = None,
) -> Path:
    """``EncodersNN.npz``, ``ImuNN.npz`` and ``HokuyoNN.npz`` of a robot driving straight along x
    at 0.2 m/s for ``n`` readings at 40 Hz (scans at the encoder times, IMU at 100 Hz);
    ``ranges`` ``(1081, n)`` (float64 kept as is, else float32), ``scan_times`` and
    ``encoder_times`` replace the generated ones."""
    folder.mkdir(parents=True, exist_ok=True)
    t = T0 + np.arange(n) / 40.0
    ticks = np.full(n, round(0.2 / 40.0 / METERS_PER_TICK), dtype=np.int16)
    counts = np.stack([ticks, ticks, ticks, ticks])
    np.savez(
        folder / f"Encoders{nn}.npz",
        counts=counts,
        time_stamps=t if encoder_times is None else encoder_times,
    )
    imu_t = T0 - 0.05 + np.arange(int(n * 2.5) + 10) / 100.0
    angular = np.zeros((3, imu_t.size))
    accel = np.tile([[0.0], [0.0], [1.0]], (1, imu_t.size))
    np.savez(
        folder / f"Imu{nn}.npz",
        angular_velocity=angular,
        linear_acceleration=accel,
        time_stamps=imu_t,
    )
    if ranges is None:
        angles = ANGLE_MIN + ANGLE_INCREMENT * np.arange(HOKUYO_BEAMS)
        travelled = METERS_PER_TICK * float(ticks[0]) * np.arange(n)
        poses = np.stack([-2.0 + travelled + 0.13323, np.full(n, -0.5), np.zeros(n)], axis=1)
        ranges = np.stack([np.minimum(ray_cast(p, angles), 30.0) for p in poses], axis=1)
    ranges = np.asarray(ranges)
    np.savez(
        folder / f"Hokuyo{nn}.npz",
        angle_min=np.array([[ANGLE_MIN]]),
        angle_max=np.array([[-ANGLE_MIN]]),
        angle_increment=np.array([[ANGLE_INCREMENT]]),
        range_min=np.array([[0.1]]),
        range_max=np.array([[30.0]]),
        ranges=ranges if ranges.dtype == np.float64 else ranges.astype(np.float32),
        time_stamps=t if scan_times is None else scan_times,
    )
    return folder
