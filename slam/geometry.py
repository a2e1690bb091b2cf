"""SE(2) geometry: poses as ``(x, y, theta)`` arrays, composition, inversion, relative motion.

Every pose function broadcasts over leading dimensions, so a whole trajectory ``(N, 3)`` or a
particle set is handled in one call (:func:`path_along` takes one ``(N, 3)`` chain). Angles are
radians, wrapped to ``[-pi, pi)``. Also the beams' trigonometry (:func:`row_trig`) and which of
``n`` beams (or scans, or pairs) a thinning to fewer keeps (:func:`spread_picks`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def spread_picks(n: int, count: int) -> NDArray[np.int64]:
    """Positions of ``count`` of ``n`` items evenly spread, the first and the last included:
    ``np.linspace(0, n − 1, count)`` rounded half to even. The one thinning rule of the package
    (the returns :meth:`slam.scans.Scan.hits` keeps, and every sampling that must keep the same
    ones); callers ask for it only when ``n > count``."""
    return np.linspace(0, n - 1, count).round().astype(np.int64)


def wrap_angle(theta: ArrayLike) -> Array:
    """Wrap angles to ``[-pi, pi)``."""
    theta = np.asarray(theta, dtype=np.float64)
    return (theta + np.pi) % (2.0 * np.pi) - np.pi


def _wrap(theta: np.float64) -> np.float64:
    """:func:`wrap_angle` of one angle (the same operations on a scalar)."""
    return (theta + np.pi) % (2.0 * np.pi) - np.pi


def row_trig(angles: Array) -> tuple[Array, Array]:
    """Cosines and sines of ``angles`` ``(S, B)`` (the beam directions of ``S`` scans), each
    the value ``np.cos`` / ``np.sin`` gives that angle, computed once for the rows whose angles
    have the very bits of the first row's (the beams of one laser) and row by row for the
    others: ``(1, B)`` arrays, which broadcast over the rows, when every row shares them, else
    ``(S, B)``."""
    bits = angles.view(np.int64)
    shared = np.all(bits == bits[:1], axis=1)
    if shared.all():
        return np.cos(angles[:1]), np.sin(angles[:1])
    cos, sin = np.empty_like(angles), np.empty_like(angles)
    if shared.any():
        cos[shared], sin[shared] = np.cos(angles[0]), np.sin(angles[0])
    cos[~shared], sin[~shared] = np.cos(angles[~shared]), np.sin(angles[~shared])
    return cos, sin


def compose(a: ArrayLike, b: ArrayLike) -> Array:
    """Return ``a ⊕ b``: pose ``b`` (expressed in the frame of ``a``) mapped to the world frame."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim == 1 and b.ndim == 1:  # one pose (the filter's every scan): no stacking
        c, s = np.cos(a[2]), np.sin(a[2])
        return np.array(
            [a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2])]
        )
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def inverse(a: ArrayLike) -> Array:
    """Return ``a⁻¹`` so that ``compose(a, inverse(a))`` is the identity."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def relative(a: ArrayLike, b: ArrayLike) -> Array:
    """Return ``a⁻¹ ⊕ b``: the motion from pose ``a`` to pose ``b`` in the frame of ``a``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim == 1 and b.ndim == 1:  # one pose: the same arithmetic without stacking
        c, s = np.cos(a[2]), np.sin(a[2])
        dx, dy = b[0] - a[0], b[1] - a[1]
        return np.array([c * dx + s * dy, -s * dx + c * dy, _wrap(b[2] - a[2])])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx = b[..., 0] - a[..., 0]
    dy = b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], axis=-1)


def transform_points(pose: ArrayLike, points: ArrayLike) -> Array:
    """Map points ``(..., 2)`` from the frame of ``pose`` to the world frame."""
    pose = np.asarray(pose, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    x = pose[..., 0, None] + c[..., None] * points[..., 0] - s[..., None] * points[..., 1]
    y = pose[..., 1, None] + s[..., None] * points[..., 0] + c[..., None] * points[..., 1]
    return np.stack([x, y], axis=-1)


def accumulate(increments: ArrayLike, start: ArrayLike | None = None) -> Array:
    """Chain relative motions ``(N, 3)`` into ``N + 1`` poses starting at ``start`` (default origin)."""
    increments = np.asarray(increments, dtype=np.float64).reshape(-1, 3)
    poses = np.empty((increments.shape[0] + 1, 3))
    poses[0] = np.zeros(3) if start is None else np.asarray(start, dtype=np.float64)
    for i, inc in enumerate(increments):
        poses[i + 1] = compose(poses[i], inc)
    return poses


def interpolate_poses(times: ArrayLike, poses: ArrayLike, query: ArrayLike) -> Array:
    """Linearly interpolate poses at ``query`` times (angles unwrapped before interpolation).

    ``times`` must be non-decreasing; queries outside ``[times[0], times[-1]]`` are clamped to the
    end poses, so callers that must not extrapolate check the range themselves.
    """
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    query = np.asarray(query, dtype=np.float64)
    theta = np.unwrap(poses[:, 2])
    out = np.stack(
        [
            np.interp(query, times, poses[:, 0]),
            np.interp(query, times, poses[:, 1]),
            wrap_angle(np.interp(query, times, theta)),
        ],
        axis=-1,
    )
    return out


def path_along(poses: ArrayLike) -> Array:
    """``(N,)`` path length from the first of the ``(N, 3)`` poses to each (m): the summed
    straight steps between consecutive positions."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.shape[0] < 2:
        return np.zeros(poses.shape[0])
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))])


def spread_corrections(
    old: ArrayLike, anchors: ArrayLike, new_anchors: ArrayLike, progress: ArrayLike
) -> Array:
    """Move a chain of poses so that its ``anchors`` land on ``new_anchors``, smoothly.

    ``old`` is the ``(N, 3)`` chain, ``anchors`` the increasing indices whose corrected poses are
    ``new_anchors`` (``anchors[0]`` must be 0). A pose between anchors ``a`` and ``b`` is placed
    from both (its motion relative to each, composed onto their corrected poses) and the two are
    blended by ``progress`` (a non-decreasing measure of motion along the chain), so the
    correction is spread over the stretch instead of appearing as a jump. Poses after the last
    anchor follow it rigidly.
    """
    old = np.asarray(old, dtype=np.float64)
    anchors = np.asarray(anchors, dtype=np.int64)
    new_anchors = np.asarray(new_anchors, dtype=np.float64)
    progress = np.asarray(progress, dtype=np.float64)
    n = old.shape[0]
    # every pose at once (the same arithmetic per pose as anchor by anchor): its anchor ``a``
    # (the last at or before it, number ``k``) and the next one ``b``
    idx = np.arange(n)
    k = np.searchsorted(anchors, idx, side="right") - 1
    last = k == anchors.size - 1  # after the last anchor: follow it rigidly
    k_next = np.minimum(k + 1, anchors.size - 1)
    a = anchors[k]
    b = np.where(last, n, anchors[k_next])
    forward = compose(new_anchors[k], relative(old[a], old))
    inner = ~last
    ii, ai, bi = idx[inner], a[inner], b[inner]
    backward = compose(new_anchors[k_next[inner]], relative(old[bi], old[ii]))
    span = progress[bi] - progress[ai]
    moved = span > 0
    f = np.where(
        moved,
        (progress[ii] - progress[ai]) / np.where(moved, span, 1.0),
        (ii - ai) / (bi - ai),
    )[:, None]
    near = forward[inner]
    blend = near + f * (backward - near)
    blend[:, 2] = near[:, 2] + f[:, 0] * wrap_angle(backward[:, 2] - near[:, 2])
    out = forward
    out[inner] = blend
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def yaw_to_quaternion(theta: ArrayLike) -> Array:
    """Quaternions ``(qx, qy, qz, qw)`` of planar rotations by ``theta`` about z."""
    theta = np.asarray(theta, dtype=np.float64)
    zeros = np.zeros_like(theta)
    return np.stack([zeros, zeros, np.sin(theta / 2.0), np.cos(theta / 2.0)], axis=-1)


def quaternion_to_yaw(q: ArrayLike) -> Array:
    """Yaw angle of quaternions ``(qx, qy, qz, qw)`` (the rotation's heading in the xy plane)."""
    q = np.asarray(q, dtype=np.float64)
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
