"""The relation metric of Kümmerle et al. 2009, "On measuring the accuracy of SLAM algorithms".

A relation ``k`` is the true motion ``δ*ₖ`` from the robot pose at ``t1[k]`` to the pose at
``t2[k]``, in the frame of the first pose. For an estimated trajectory the same motion is
``δₖ = xᵢ⁻¹ ⊕ xⱼ`` with ``xᵢ``, ``xⱼ`` the poses whose timestamps equal ``t1[k]`` and ``t2[k]``
(within a tolerance, 1e-4 s by default), and the error of the relation is
``eₖ = δₖ ⊖ δ*ₖ = δ*ₖ⁻¹ ⊕ δₖ``. The metric reports, over all matched relations, the mean and
standard deviation of ``|translation(eₖ)|`` (m) and ``|rotation(eₖ)|`` (degrees), and the same
for their squares. Standard deviations are population standard deviations (``ddof = 0``).

A relation whose ``t1`` or ``t2`` matches no pose is never dropped silently: it is counted in
:attr:`RelationErrors.unmatched` and listed in :attr:`RelationErrors.unmatched_index`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.geometry import relative
from slam.io.relations import Relations
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]

DEFAULT_TOLERANCE_S = 1e-4
"""Largest difference between a relation timestamp and a pose timestamp that still matches."""


def match_times(
    times: ArrayLike, query: ArrayLike, tolerance: float = DEFAULT_TOLERANCE_S
) -> NDArray[np.int64]:
    """Index of the pose whose time is nearest each query time, or −1 if none is within
    ``tolerance``. ``times`` may be in any order (CARMEN scans are in file order); ties go to the
    pose that comes first in ``times``."""
    times = np.asarray(times, dtype=np.float64)
    query = np.asarray(query, dtype=np.float64)
    if times.size == 0:
        return np.full(query.shape, -1, dtype=np.int64)
    order = np.argsort(times, kind="stable")
    sorted_times = times[order]
    right = np.clip(np.searchsorted(sorted_times, query, side="left"), 0, times.size - 1)
    left = np.clip(right - 1, 0, times.size - 1)
    d_left = np.abs(sorted_times[left] - query)
    d_right = np.abs(sorted_times[right] - query)
    nearest = np.where(d_left < d_right, left, right)
    # Several poses may share the nearest time: the stable sort keeps them in file order, so
    # the first of the run is the first in the file.
    nearest = np.searchsorted(sorted_times, sorted_times[nearest], side="left")
    distance = np.minimum(d_left, d_right)
    return np.where(distance <= tolerance, order[nearest], -1).astype(np.int64)


@dataclass(frozen=True)
class RelationErrors:
    """Per-relation errors of a trajectory, for the matched relations."""

    trans: F64
    """``(M,)`` translational error ``|translation(eₖ)|`` (m) of each matched relation."""
    rot: F64
    """``(M,)`` rotational error ``|rotation(eₖ)|`` (rad) of each matched relation."""
    matched_index: NDArray[np.int64]
    """``(M,)`` indices (into the relations) of the matched relations."""
    unmatched_index: NDArray[np.int64]
    """Indices of the relations whose ``t1`` or ``t2`` matched no pose."""
    total: int
    """Number of relations evaluated (matched + unmatched)."""
    tolerance: float
    """Time tolerance used for matching (s)."""

    @property
    def count(self) -> int:
        """Number of matched relations (the ones the statistics are over)."""
        return int(self.trans.shape[0])

    @property
    def unmatched(self) -> int:
        """Number of relations that matched no pose."""
        return int(self.unmatched_index.shape[0])

    def summary(self) -> dict[str, Any]:
        """The statistics of the metric (NaN when no relation matched)."""
        trans, rot_deg = self.trans, np.rad2deg(self.rot)
        return {
            "count": self.count,
            "total": self.total,
            "unmatched": self.unmatched,
            "tolerance_s": self.tolerance,
            "trans_mean": _mean(trans),
            "trans_std": _std(trans),
            "trans_max": _max(trans),
            "rot_mean_deg": _mean(rot_deg),
            "rot_std_deg": _std(rot_deg),
            "rot_max_deg": _max(rot_deg),
            "trans_sq_mean": _mean(trans**2),
            "trans_sq_std": _std(trans**2),
            "rot_sq_mean_deg2": _mean(rot_deg**2),
            "rot_sq_std_deg2": _std(rot_deg**2),
        }


def relation_errors(
    trajectory: Trajectory,
    relations: Relations,
    tolerance: float = DEFAULT_TOLERANCE_S,
) -> RelationErrors:
    """Errors of ``trajectory`` against ``relations``."""
    times, poses = trajectory.times, trajectory.poses
    i = match_times(times, relations.t1, tolerance)
    j = match_times(times, relations.t2, tolerance)
    ok = (i >= 0) & (j >= 0)
    estimated = relative(poses[i[ok]], poses[j[ok]])
    error = relative(relations.motions[ok], estimated)
    return RelationErrors(
        trans=np.hypot(error[:, 0], error[:, 1]),
        rot=np.abs(error[:, 2]),
        matched_index=np.flatnonzero(ok).astype(np.int64),
        unmatched_index=np.flatnonzero(~ok).astype(np.int64),
        total=len(relations),
        tolerance=float(tolerance),
    )


def _mean(values: F64) -> float:
    return float(values.mean()) if values.size else math.nan


def _std(values: F64) -> float:
    return float(values.std()) if values.size else math.nan


def _max(values: F64) -> float:
    return float(values.max()) if values.size else math.nan
