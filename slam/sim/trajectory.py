"""Robot trajectories of the simulator: a route, a smooth reference path, a driven trajectory.

A route is a polyline of waypoints (corridor corners, door approaches, loops inside rooms). Its
corners are rounded with circular fillets (:func:`fillet_path`), the result is sampled every 2 cm
with its curvature, a speed profile caps the speed by lateral acceleration and braking distance,
and a pure-pursuit differential-drive follower (:func:`slam.sim.kernels.follow_path`) drives it at
1 kHz with limited linear and angular acceleration. Each 1 ms step holds ``(v, ω)`` constant and
moves along the exact arc, so the trajectory is known in closed form at any time
(:meth:`Trajectory.pose_at`): that is the ground truth every sensor samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class DriveLimits:
    """Speeds and accelerations of the simulated robot (differential drive, ≈0.5–1 m/s)."""

    cruise_min: float = 0.5
    """Lowest cruise speed the planner may choose (m/s)."""
    cruise_max: float = 1.0
    """Highest cruise speed (m/s)."""
    lateral_accel: float = 0.45
    """Largest centripetal acceleration in turns (m/s²)."""
    accel: float = 0.5
    """Largest forward acceleration (m/s²)."""
    decel: float = 0.6
    """Largest braking deceleration (m/s²)."""
    max_omega: float = 1.2
    """Largest turn rate (rad/s)."""
    max_alpha: float = 2.5
    """Largest angular acceleration (rad/s²)."""
    lookahead: float = 0.35
    """Pure-pursuit look-ahead at standstill (m)."""
    lookahead_gain: float = 0.3
    """Extra look-ahead per m/s of speed (s)."""
    drive_tau: float = 0.08
    """Time constant of the drive's response to speed and turn-rate commands (s)."""
    dt: float = 0.001
    """Integration step (s)."""
    start_pause: float = 1.0
    """Time the robot stands still at the start (s), like a real log's IMU warm-up."""


def fillet_path(waypoints: F64, radii: F64, spacing: float = 0.02) -> tuple[F64, F64]:
    """Round the corners of a polyline with circular arcs and sample it every ``spacing`` m.

    ``radii[k]`` is the fillet radius wanted at waypoint ``k`` (ends ignored); it shrinks where the
    adjacent segments are too short. Returns ``(points (M, 2), curvature (M,))`` (signed, 1/m).
    """
    pts = np.asarray(waypoints, dtype=np.float64)
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-9
    pts = pts[keep]
    radii = np.asarray(radii, dtype=np.float64)[keep]
    n = len(pts)
    seg = np.diff(pts, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    dirs = seg / seg_len[:, None]
    pieces: list[tuple[str, tuple]] = []
    cursor = pts[0]
    for k in range(1, n - 1):
        d0, d1 = dirs[k - 1], dirs[k]
        cross = d0[0] * d1[1] - d0[1] * d1[0]
        dot = float(np.clip(d0 @ d1, -1.0, 1.0))
        turn = math.atan2(cross, dot)
        if abs(turn) < 1e-6:
            continue
        if abs(abs(turn) - math.pi) < 1e-6:
            raise ValueError(f"route reverses at waypoint {k} {tuple(pts[k])}: cannot fillet")
        half = abs(turn) / 2
        cut = radii[k] * math.tan(half)
        cut = min(cut, 0.45 * seg_len[k - 1], 0.45 * seg_len[k])
        r = cut / math.tan(half)
        a = pts[k] - d0 * cut
        b = pts[k] + d1 * cut
        pieces.append(("line", (cursor, a)))
        sign = 1.0 if turn > 0 else -1.0
        normal = np.array([-d0[1], d0[0]]) * sign
        centre = a + normal * r
        pieces.append(("arc", (centre, r, math.atan2(a[1] - centre[1], a[0] - centre[0]), turn)))
        cursor = b
    pieces.append(("line", (cursor, pts[-1])))
    out_pts = [pts[0][None, :]]
    out_k = [np.zeros(1)]
    for kind, p in pieces:
        if kind == "line":
            a, b = p
            length = float(np.hypot(*(b - a)))
            m = max(1, int(math.ceil(length / spacing)))
            s = np.arange(1, m + 1) / m
            out_pts.append(a + np.outer(s, b - a))
            out_k.append(np.zeros(m))
        else:
            centre, r, phi0, turn = p
            length = r * abs(turn)
            m = max(1, int(math.ceil(length / spacing)))
            phi = phi0 + turn * np.arange(1, m + 1) / m
            out_pts.append(centre + r * np.stack([np.cos(phi), np.sin(phi)], axis=1))
            out_k.append(np.full(m, math.copysign(1.0 / r, turn)))
    points = np.concatenate(out_pts)
    curvature = np.concatenate(out_k)
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.hypot(*np.diff(points, axis=0).T) > 1e-9
    return points[keep], curvature[keep]


def speed_profile(arc: F64, curvature: F64, cruise: float, limits: DriveLimits) -> F64:
    """Speed allowed along the path: cruise, curvature (lateral acceleration), braking, stop at end."""
    v = np.minimum(cruise, np.sqrt(limits.lateral_accel / np.maximum(np.abs(curvature), 1e-9)))
    v = np.minimum(v, limits.max_omega / np.maximum(np.abs(curvature), 1e-9) * 0.9)
    # Look ahead over the look-ahead distance: the follower starts turning before the arc begins.
    ds = np.diff(arc, prepend=arc[0])
    window = max(1, int(round(0.6 / max(float(np.median(ds[1:])) if len(ds) > 1 else 0.02, 1e-3))))
    padded = np.concatenate([v, np.full(window, v[-1])])
    ahead = np.lib.stride_tricks.sliding_window_view(padded, window + 1).min(axis=1)[: len(v)]
    v = np.minimum(v, ahead)
    v[-1] = 0.0
    for k in range(len(v) - 2, -1, -1):
        v[k] = min(v[k], math.sqrt(v[k + 1] ** 2 + 2.0 * limits.decel * (arc[k + 1] - arc[k])))
    v[:-1] = np.maximum(v[:-1], 0.06)
    return v


def travel_time(arc: F64, speed: F64, limits: DriveLimits) -> float:
    """Estimated time to drive the profile from standstill (s), including the start pause."""
    v = speed.copy()
    v[0] = 0.0
    for k in range(1, len(v)):
        v[k] = min(v[k], math.sqrt(v[k - 1] ** 2 + 2.0 * limits.accel * (arc[k] - arc[k - 1])))
    ds = np.diff(arc)
    mean_v = np.maximum(0.5 * (v[1:] + v[:-1]), 1e-3)
    return float(limits.start_pause + np.sum(ds / mean_v))


@dataclass(frozen=True)
class Trajectory:
    """A driven trajectory: ``(v, ω)`` constant over each step of ``dt`` from ``t0``.

    ``poses[k]`` is the pose at ``t0 + k·dt`` with an unwrapped heading; ``distance[k]`` the path
    length driven by then. Every query between steps integrates the exact arc.
    """

    t0: float
    dt: float
    poses: F64
    """``(K+1, 3)`` poses at the step boundaries (heading unwrapped)."""
    v: F64
    """``(K,)`` forward speed of each step (m/s)."""
    omega: F64
    """``(K,)`` turn rate of each step (rad/s)."""
    distance: F64
    """``(K+1,)`` cumulative distance at the step boundaries (m)."""

    @property
    def duration(self) -> float:
        """Length of the trajectory in time (s)."""
        return self.dt * len(self.v)

    @property
    def t_end(self) -> float:
        """Time of the last pose (s)."""
        return self.t0 + self.duration

    def _step(self, t: F64) -> tuple[NDArray[np.int64], F64]:
        t = np.asarray(t, dtype=np.float64)
        k = np.floor((t - self.t0) / self.dt).astype(np.int64)
        k = np.clip(k, 0, len(self.v) - 1)
        tau = np.clip(t - (self.t0 + k * self.dt), 0.0, None)
        # Before t0 the robot stands at poses[0]; after the end at the last pose.
        before = t < self.t0
        after = t > self.t_end
        tau = np.where(before, 0.0, tau)
        tau = np.where(after, self.dt, tau)
        return k, tau

    def pose_at(self, t: F64, unwrap: bool = False) -> F64:
        """Poses ``(N, 3)`` at times ``t`` (exact arcs; heading wrapped unless ``unwrap``)."""
        k, tau = self._step(t)
        v = self.v[k]
        w = self.omega[k]
        p = self.poses[k]
        half = 0.5 * w * tau
        chord = v * tau * np.sinc(half / np.pi)
        x = p[..., 0] + chord * np.cos(p[..., 2] + half)
        y = p[..., 1] + chord * np.sin(p[..., 2] + half)
        th = p[..., 2] + w * tau
        if not unwrap:
            th = (th + np.pi) % (2.0 * np.pi) - np.pi
        return np.stack([x, y, th], axis=-1)

    def distance_at(self, t: F64) -> F64:
        """Cumulative distance driven by times ``t`` (m)."""
        k, tau = self._step(t)
        return self.distance[k] + self.v[k] * tau

    def heading_at(self, t: F64) -> F64:
        """Unwrapped heading at times ``t`` (rad), 0 at the start."""
        k, tau = self._step(t)
        return self.poses[k, 2] + self.omega[k] * tau

    def yaw_rate_at(self, t: F64) -> F64:
        """Turn rate at times ``t`` (rad/s); 0 outside the trajectory."""
        t = np.asarray(t, dtype=np.float64)
        k, _ = self._step(t)
        inside = (t >= self.t0) & (t < self.t_end)
        return np.where(inside, self.omega[k], 0.0)

    def speed_at(self, t: F64) -> F64:
        """Forward speed at times ``t`` (m/s); 0 outside the trajectory."""
        t = np.asarray(t, dtype=np.float64)
        k, _ = self._step(t)
        inside = (t >= self.t0) & (t < self.t_end)
        return np.where(inside, self.v[k], 0.0)

    def accel_at(self, t: F64) -> F64:
        """Forward acceleration at times ``t`` (m/s²), from the speed change of that step."""
        t = np.asarray(t, dtype=np.float64)
        k, _ = self._step(t)
        prev = np.where(k > 0, self.v[np.maximum(k - 1, 0)], 0.0)
        inside = (t >= self.t0) & (t < self.t_end)
        return np.where(inside, (self.v[k] - prev) / self.dt, 0.0)

    def sample_xy(self, every: float = 0.05) -> F64:
        """Positions ``(N, 2)`` every ``every`` seconds (for rasterising the path)."""
        stride = max(1, int(round(every / self.dt)))
        return self.poses[::stride, :2].copy()


def drive(
    waypoints: F64,
    radii: F64,
    duration: float,
    t0: float,
    limits: DriveLimits = DriveLimits(),
    cruise: float | None = None,
) -> tuple[Trajectory, dict]:
    """Drive a route for ``duration`` seconds starting at ``t0`` (the start pose is waypoint 0).

    The cruise speed is chosen in ``[cruise_min, cruise_max]`` so that the route ends 2–4 s
    before ``duration`` (unless ``cruise`` is given); a route too long for that is cut off at
    ``duration``, a short one ends with the robot standing still. Returns the trajectory and a
    summary (cruise speed, planned and driven length, largest tracking error).
    """
    path, curvature = fillet_path(waypoints, radii)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    steps = int(round(duration / limits.dt))
    if cruise is None:
        cruise = _calibrate_cruise(path, arc, curvature, duration, limits)
    poses, v, w, progress = _follow(path, arc, speed_profile(arc, curvature, cruise, limits),
                                    steps, limits)  # fmt: skip
    distance = np.concatenate([[0.0], np.cumsum(v * limits.dt)])
    traj = Trajectory(t0=t0, dt=limits.dt, poses=poses, v=v, omega=w, distance=distance)
    # Tracking error: distance from driven positions to the reference path (sampled).
    sample = poses[::20, :2]
    err = _polyline_distance(sample, path)
    info = {
        "cruise_speed": float(cruise),
        "route_length_m": float(arc[-1]),
        "driven_length_m": float(distance[-1]),
        "max_tracking_error_m": float(err.max()),
        "completed": bool(progress[-1] >= arc[-1] - 0.05),
        "max_speed": float(v.max(initial=0.0)),
        "max_turn_rate": float(np.abs(w).max(initial=0.0)),
        "reference_path": path,
    }
    return traj, info


def _follow(path: F64, arc: F64, speed: F64, steps: int, limits: DriveLimits) -> tuple:
    from slam.sim.kernels import follow_path  # numba: not imported by `slam --help`

    return follow_path(
        np.ascontiguousarray(path),
        arc,
        speed,
        limits.dt,
        steps,
        int(round(limits.start_pause / limits.dt)),
        limits.lookahead,
        limits.lookahead_gain,
        limits.max_omega,
        limits.max_alpha,
        limits.accel,
        limits.decel,
        limits.drive_tau,
    )


def _finish_time(path: F64, arc: F64, curvature: F64, cruise: float, limits: DriveLimits,
                 horizon: float) -> float:  # fmt: skip
    """Time (s) the follower needs to drive the whole path at ``cruise`` (inf beyond horizon)."""
    steps = int(round(horizon / limits.dt))
    _, v, _, progress = _follow(path, arc, speed_profile(arc, curvature, cruise, limits), steps,
                                limits)  # fmt: skip
    reached = np.flatnonzero(progress >= arc[-1] - 0.05)
    return float(reached[0] * limits.dt) if reached.size else math.inf


def _calibrate_cruise(
    path: F64, arc: F64, curvature: F64, duration: float, limits: DriveLimits
) -> float:
    """Cruise speed in ``[cruise_min, cruise_max]`` that ends the route 2–4 s before ``duration``.

    Starts from the speed-profile estimate, then corrects on real drives of the follower (which
    is a little slower than the profile in turns) by the ratio of driving times.
    """
    target = max(duration - 3.0, limits.start_pause + 1.0)
    lo, hi = limits.cruise_min, limits.cruise_max

    def estimate(c: float) -> float:
        return travel_time(arc, speed_profile(arc, curvature, c, limits), limits)

    if estimate(hi) >= target:
        return hi
    if estimate(lo) <= target:
        cruise = lo
    else:
        a, b = lo, hi
        for _ in range(30):
            mid = 0.5 * (a + b)
            if estimate(mid) > target:
                a = mid
            else:
                b = mid
        cruise = b
    for _ in range(4):
        finish = _finish_time(path, arc, curvature, cruise, limits, duration + 60.0)
        if target - 1.0 <= finish <= target + 1.0 or (finish < target and cruise <= lo):
            break
        if finish > target and cruise >= hi:
            break
        moving = max(finish - limits.start_pause, 1e-3)
        wanted = max(target - limits.start_pause, 1e-3)
        cruise = float(np.clip(cruise * moving / wanted, lo, hi))
    return cruise


def _polyline_distance(points: F64, path: F64) -> F64:
    """Distance from each point to the nearest vertex of a densely sampled path (chunked): every
    other vertex, each only once. A route driven lap after lap repeats its vertices (at most two
    laps' worth are distinct: a lap of an odd count takes the other half the next time), and the
    work would otherwise grow with the square of the laps; the nearest is the same either way."""
    vertices = np.unique(path[::2], axis=0)
    out = np.empty(len(points))
    for s in range(0, len(points), 512):
        chunk = points[s : s + 512]
        d2 = ((chunk[:, None, :] - vertices[None, :, :]) ** 2).sum(axis=2)
        out[s : s + 512] = np.sqrt(d2.min(axis=1))
    return out
