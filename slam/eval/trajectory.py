"""Trajectory-to-reference metrics: SE(2) alignment, ATE and RPE (pure maths, no I/O).

Association
    Both trajectories are sorted by time. The pairs are the estimate's poses, each with the
    reference interpolated at its time (:func:`slam.geometry.interpolate_poses`). Where the
    reference has fewer poses than the estimate in their overlap (a pose a second, another
    tool's keyframes), only the estimate pose nearest to each of its stamps is paired, as evo
    pairs a sparse reference: the reference is not drawn as straight chords between its stamps,
    and the estimate is never interpolated (an interpolated estimate averages its own noise
    away). A time outside the other trajectory's range is excluded and counted, never
    extrapolated; so is a time inside a gap of the other longer than :data:`GAP_PERIODS` of its
    periods (a reference with a minute missing, or one pose at each end, is not filled in with
    a straight line).

Alignment
    :func:`align_se2` is the closed-form least-squares rigid alignment in the plane (Horn /
    Umeyama without scale): with centred positions ``aₖ`` (estimate) and ``bₖ`` (reference),
    ``θ = atan2(Σ aₖ × bₖ, Σ aₖ · bₖ)`` and ``t = b̄ − R(θ) ā``. The aligned estimate is
    ``T ⊕ xₖ`` with ``T = (t, θ)``.

ATE (absolute trajectory error)
    ``‖position(T ⊕ xₖ) − position(yₖ)‖`` over the associated poses: RMSE (the headline figure),
    mean, median, max and standard deviation, plus the RMSE of the heading error in degrees.

RPE (relative pose error)
    For pose pairs ``(i, j)`` a fixed ``delta`` apart (in frames or in seconds, see
    :class:`DeltaUnit`), ``Eᵢⱼ = (yᵢ⁻¹ ⊕ yⱼ)⁻¹ ⊕ (xᵢ⁻¹ ⊕ xⱼ)``; translation mean, RMSE, median
    and max of ``‖translation(Eᵢⱼ)‖``, rotation mean and RMSE of ``|rotation(Eᵢⱼ)|`` in degrees.
    RPE does not depend on any alignment. Pairs are formed over the associated poses sorted by
    time: in frames, ``j = i + delta``; in seconds, ``j`` is the first pose with
    ``tⱼ ≥ tᵢ + delta`` (to 1e-6 s).

Degenerate inputs
    A score needs something to score: :func:`evaluate_against_reference` requires at least
    :data:`MIN_MATCHED_POSES` associated poses at distinct times (an SE(2) alignment has three
    degrees of freedom: with one pose it cancels any error, with two it leaves one residual), and
    at least one RPE pair. Fewer is a :class:`~slam.errors.DataError` naming both trajectories,
    never a perfect score.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from slam.errors import DataError, UsageError
from slam.geometry import compose, interpolate_poses, relative, wrap_angle
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]

MIN_MATCHED_POSES = 3
"""Fewest associated poses (at distinct times) ATE and RPE are computed from."""


class DeltaUnit(Enum):
    """Unit of the RPE pair spacing."""

    FRAMES = "frames"
    """``delta`` poses apart (an integer)."""
    SECONDS = "seconds"
    """At least ``delta`` seconds apart."""


class Alignment(Enum):
    """How the estimate is brought into the reference frame before ATE."""

    SE2 = "se2"
    """Least-squares rotation and translation (no scale)."""
    NONE = "none"
    """Compare as is (both trajectories already share a frame)."""


GAP_PERIODS = 10.0
"""The denser trajectory is interpolated only across gaps of at most this many of its periods
(the larger of its median and mean step): a pose in a longer gap (a stretch the trajectory does
not hold) is not evaluated."""

SAME_TIME_S = 1e-6
"""Times this close are the same time (TUM files keep microseconds)."""


@dataclass(frozen=True)
class Association:
    """Estimate poses paired with the reference interpolated at their times (time-sorted)."""

    time: F64
    """``(M,)`` times of the pairs, non-decreasing."""
    estimate: F64
    """``(M, 3)`` estimate poses at ``time``."""
    reference: F64
    """``(M, 3)`` reference poses at ``time``."""
    excluded: int
    """Poses not evaluated (the estimate's; the reference's stamps where it is the sparser):
    outside the other's time range, or in a gap of it longer than :data:`GAP_PERIODS` of its
    periods."""
    at: str = "estimate"
    """``"reference"`` where the pairs are the estimate poses nearest to a sparser reference's
    stamps, else ``"estimate"`` (every estimate pose)."""

    def __len__(self) -> int:
        return int(self.time.shape[0])


def associate(estimate: Trajectory, reference: Trajectory) -> Association:
    """Pair the trajectories (module docstring): at the estimate's times, the reference
    interpolated there; where the reference has fewer poses in their overlap, at the estimate
    poses nearest to its stamps instead (the estimate's own poses, never interpolated)."""
    est = Trajectory(*_checked(estimate, "estimate")).sorted_by_time()
    ref = Trajectory(*_checked(reference, "reference")).sorted_by_time()
    lo, hi = max(est.times[0], ref.times[0]), min(est.times[-1], ref.times[-1])
    in_est = np.unique(est.times[(est.times >= lo) & (est.times <= hi)]).size  # distinct times
    in_ref = np.unique(ref.times[(ref.times >= lo) & (ref.times <= hi)]).size
    if in_ref < in_est:  # a sparse reference: one estimate pose per stamp the estimate holds
        stamps = ref.times[_covered(est.times, ref.times)]
        right = np.clip(np.searchsorted(est.times, stamps), 0, est.times.size - 1)
        left = np.clip(right - 1, 0, est.times.size - 1)
        nearest = np.where(
            np.abs(est.times[left] - stamps) <= np.abs(est.times[right] - stamps), left, right
        )
        rows = np.unique(nearest)
        rows = rows[_covered(ref.times, est.times[rows])]
        time = est.times[rows]
        return Association(
            time=time,
            estimate=est.poses[rows],
            reference=interpolate_poses(ref.times, ref.poses, time),
            excluded=int(ref.times.size - time.size),
            at="reference",
        )
    keep = _covered(ref.times, est.times)
    time = est.times[keep]
    return Association(
        time=time,
        estimate=est.poses[keep],
        reference=interpolate_poses(ref.times, ref.poses, time),
        excluded=int(np.count_nonzero(~keep)),
    )


def _covered(dense: F64, query: F64) -> NDArray[np.bool_]:
    """Which ``query`` times the sorted ``dense`` times hold: within their range, and at one of
    them or between two at most :data:`GAP_PERIODS` periods apart."""
    if query.size == 0:
        return np.zeros(0, dtype=bool)
    inside = (query >= dense[0] - SAME_TIME_S) & (query <= dense[-1] + SAME_TIME_S)
    steps = np.diff(dense)
    steps = steps[steps > SAME_TIME_S]
    # a period: the median step, or the mean where the poses come in bursts (intel's odometry:
    # a median step of 3 ms, a mean of 0.1 s)
    max_gap = GAP_PERIODS * max(float(np.median(steps)), float(steps.mean())) if steps.size else 0.0
    right = np.clip(np.searchsorted(dense, query, side="left"), 0, dense.size - 1)
    left = np.clip(right - 1, 0, dense.size - 1)
    at_one = (np.abs(dense[right] - query) <= SAME_TIME_S) | (
        np.abs(dense[left] - query) <= SAME_TIME_S
    )
    return inside & (at_one | (dense[right] - dense[left] <= max_gap))


def _checked(trajectory: Trajectory, what: str) -> tuple[F64, F64]:
    if len(trajectory) == 0:
        raise UsageError(f"{what} trajectory has no poses")
    return trajectory.times, trajectory.poses


def align_se2(source_xy: ArrayLike, target_xy: ArrayLike) -> F64:
    """The SE(2) transform ``T = (tx, ty, θ)`` minimising ``Σ ‖R(θ) sₖ + t − tgtₖ‖²``.

    ``compose(T, pose)`` then maps a source pose into the target frame.
    """
    source = np.asarray(source_xy, dtype=np.float64).reshape(-1, 2)
    target = np.asarray(target_xy, dtype=np.float64).reshape(-1, 2)
    if source.shape != target.shape or source.shape[0] == 0:
        raise ValueError(f"cannot align {source.shape[0]} points to {target.shape[0]} points")
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    a, b = source - mu_s, target - mu_t
    cross = float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
    dot = float(np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))
    theta = math.atan2(cross, dot)
    c, s = math.cos(theta), math.sin(theta)
    tx = mu_t[0] - (c * mu_s[0] - s * mu_s[1])
    ty = mu_t[1] - (s * mu_s[0] + c * mu_s[1])
    return np.array([tx, ty, theta])


@dataclass(frozen=True)
class AteResult:
    """Absolute trajectory error after alignment."""

    errors: F64
    """``(M,)`` position error of each associated pose (m)."""
    yaw_errors: F64
    """``(M,)`` heading error of each associated pose (rad, signed)."""
    transform: F64
    """``(3,)`` alignment applied to the estimate (identity with :attr:`Alignment.NONE`)."""

    def summary(self) -> dict[str, float]:
        """RMSE, mean, median, max and std of the position error; heading RMSE in degrees."""
        e = self.errors
        return {
            "ate_rmse": float(np.sqrt(np.mean(e**2))),
            "ate_mean": float(e.mean()),
            "ate_median": float(np.median(e)),
            "ate_max": float(e.max()),
            "ate_std": float(e.std()),
            "ate_rot_rmse_deg": float(np.rad2deg(np.sqrt(np.mean(self.yaw_errors**2)))),
        }


def ate(association: Association, alignment: Alignment = Alignment.SE2) -> AteResult:
    """Absolute trajectory error of an association (see the module docstring)."""
    if len(association) == 0:
        raise UsageError(
            "no estimate pose lies within the reference's time range: nothing to compare"
        )
    if alignment is Alignment.SE2:
        transform = align_se2(association.estimate[:, :2], association.reference[:, :2])
    else:
        transform = np.zeros(3)
    aligned = compose(transform, association.estimate)
    diff = aligned[:, :2] - association.reference[:, :2]
    return AteResult(
        errors=np.hypot(diff[:, 0], diff[:, 1]),
        yaw_errors=wrap_angle(aligned[:, 2] - association.reference[:, 2]),
        transform=transform,
    )


@dataclass(frozen=True)
class RpeResult:
    """Relative pose error over pose pairs a fixed delta apart."""

    trans: F64
    """``(P,)`` translational error of each pair (m)."""
    rot: F64
    """``(P,)`` rotational error of each pair (rad, absolute)."""
    delta: float
    unit: DeltaUnit

    def summary(self) -> dict[str, Any]:
        """Translation mean/RMSE/median/max (m), rotation mean/RMSE (deg), pair count."""
        t, r = self.trans, np.rad2deg(self.rot)
        empty = t.size == 0
        return {
            "rpe_trans_mean": math.nan if empty else float(t.mean()),
            "rpe_trans_rmse": math.nan if empty else float(np.sqrt(np.mean(t**2))),
            "rpe_trans_median": math.nan if empty else float(np.median(t)),
            "rpe_trans_max": math.nan if empty else float(t.max()),
            "rpe_rot_mean_deg": math.nan if empty else float(r.mean()),
            "rpe_rot_rmse_deg": math.nan if empty else float(np.sqrt(np.mean(r**2))),
            "rpe_pairs": int(t.size),
            "rpe_delta": self.delta,
            "rpe_delta_unit": self.unit.value,
        }


def rpe_pairs(
    time: ArrayLike, delta: float, unit: DeltaUnit
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Index pairs ``(i, j)`` of time-sorted poses ``delta`` apart (see the module docstring)."""
    time = np.asarray(time, dtype=np.float64)
    if not delta > 0:
        raise UsageError(f"RPE delta: expected a positive value, found {delta}")
    n = time.shape[0]
    if unit is DeltaUnit.FRAMES:
        if delta != int(delta):
            raise UsageError(f"RPE delta in frames: expected a whole number, found {delta}")
        i = np.arange(max(n - int(delta), 0), dtype=np.int64)
        return i, i + int(delta)
    # A microsecond of slack (the precision of TUM files) so that poses exactly delta apart
    # pair despite rounding.
    j = np.searchsorted(time, time + delta - 1e-6, side="left").astype(np.int64)
    i = np.flatnonzero(j < n).astype(np.int64)
    return i, j[i]


def rpe(
    association: Association, delta: float = 1, unit: DeltaUnit = DeltaUnit.FRAMES
) -> RpeResult:
    """Relative pose error of an association (see the module docstring)."""
    i, j = rpe_pairs(association.time, delta, unit)
    est = relative(association.estimate[i], association.estimate[j])
    ref = relative(association.reference[i], association.reference[j])
    error = relative(ref, est)
    return RpeResult(
        trans=np.hypot(error[:, 0], error[:, 1]),
        rot=np.abs(error[:, 2]),
        delta=float(delta),
        unit=unit,
    )


def evaluate_against_reference(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    alignment: Alignment = Alignment.SE2,
    delta: float = 1,
    unit: DeltaUnit = DeltaUnit.FRAMES,
    estimate_name: str = "estimate",
    reference_name: str = "reference",
) -> dict[str, Any]:
    """ATE and RPE of an estimate against a reference, as one flat dictionary.

    ``estimate_name`` and ``reference_name`` (files, usually) name the trajectories in errors:
    :class:`DataError` when fewer than :data:`MIN_MATCHED_POSES` estimate poses at distinct
    times lie within the reference's time span, or when no RPE pair is ``delta`` apart.
    """
    association = associate(estimate, reference)
    _require_matches(association, estimate.times, reference.times, estimate_name, reference_name)
    ate_result = ate(association, alignment)
    out: dict[str, Any] = {
        "matched": len(association),
        "excluded": association.excluded,
        "matched_at": association.at,
    }
    out.update(ate_result.summary())
    rpe_result = rpe(association, delta, unit)
    if rpe_result.trans.size == 0:
        raise DataError(
            f"{estimate_name}: no pair of its {len(association)} poses matched to "
            f"{reference_name} lies {delta:g} {unit.value} apart (they span "
            f"{association.time[-1] - association.time[0]:.6f} s); choose a smaller --delta"
        )
    out.update(rpe_result.summary())
    out["alignment"] = alignment.value
    out["alignment_x"] = float(ate_result.transform[0])
    out["alignment_y"] = float(ate_result.transform[1])
    out["alignment_yaw_deg"] = float(np.rad2deg(ate_result.transform[2]))
    return out


def _unit_hint(est: F64, ref: F64, estimate_name: str, reference_name: str) -> str:
    """'X's times look like nanoseconds …' when one trajectory's times are about 1e3, 1e6 or 1e9
    times the other's, else ''."""
    a, b = float(np.median(np.abs(est))), float(np.median(np.abs(ref)))
    span_a, span_b = float(np.ptp(est)), float(np.ptp(ref))
    if min(a, b, span_a, span_b) <= 0:
        return ""
    if abs(math.log10((span_a / span_b) / (a / b))) > 0.3:
        return ""  # another unit stretches the spans too; another epoch (t and t + 1.7e9) not
    big, small = (estimate_name, reference_name) if a > b else (reference_name, estimate_name)
    power = math.log10(max(a, b) / min(a, b)) / 3
    unit = {1: "milliseconds", 2: "microseconds", 3: "nanoseconds"}.get(round(power))
    if unit is None or abs(power - round(power)) > 0.1:
        return ""
    return f"{big}'s times look like {unit} where {small}'s are seconds"


def _require_matches(
    association: Association,
    est_times: ArrayLike,
    ref_times: ArrayLike,
    estimate_name: str,
    reference_name: str,
) -> None:
    """:class:`DataError` unless the association has :data:`MIN_MATCHED_POSES` distinct times."""
    distinct = int(np.unique(association.time).size)
    if distinct >= MIN_MATCHED_POSES:
        return
    est = np.asarray(est_times, dtype=np.float64).reshape(-1)
    ref = np.asarray(ref_times, dtype=np.float64).reshape(-1)
    spans = (
        f"{reference_name} spans {ref.min():.6f}..{ref.max():.6f} s with {ref.size} pose(s), "
        f"{estimate_name} {est.min():.6f}..{est.max():.6f} s with {est.size}"
    )
    if len(association) == 0:
        sparse, dense = (
            (reference_name, estimate_name)
            if association.at == "reference"
            else (estimate_name, reference_name)
        )
        raise DataError(
            f"{sparse}: none of its poses lies within the time span of {dense} or between two of "
            f"its poses at most {GAP_PERIODS:g} of its periods apart ({spans}): "
            f"{_unit_hint(est, ref, estimate_name, reference_name) or 'is it the same log?'}"
        )
    if association.at == "reference":  # paired at the sparse reference's stamps
        raise DataError(
            f"{reference_name}: only {distinct} of its stamps lie within {estimate_name}'s poses "
            f"({spans}); ATE and RPE need at least {MIN_MATCHED_POSES} matched poses at "
            "distinct times"
        )
    raise DataError(
        f"{estimate_name}: only {distinct} pose time(s) match {reference_name} ({spans}); ATE "
        f"and RPE need at least {MIN_MATCHED_POSES} matched poses at distinct times"
    )
