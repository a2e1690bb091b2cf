#!/usr/bin/env python3
"""The short relations of a benchmark log: where a SLAM run is locally worse than dead reckoning.

For a run folder and a dead-reckoning run folder of the same log (``slam run LOG --method
odometry``), over the relations that span less than ``--span`` seconds: the share of each run's
errors over ``--over`` metres, how many are over it for the SLAM run but under half of it for
dead reckoning (and the reverse), how far the SLAM run's relative motion is from dead reckoning's
on its bad relations, and the relations' rotation on the bad and the good ones (docs/accuracy.md,
"fr-clinic's short relations"); the mean error of both runs on the short relations; and the
short relations at least ``--sideways-length`` long whose direction of travel, in the frame of
their first pose, differs from dead reckoning's by more than ``--sideways`` degrees, with the
share of the SLAM run's mean error (over all its relations) that they carry; and for the
relations at least ``--span`` long, the SLAM run's mean error on them, the share of its mean they
carry, and the windows of 100 s (at either end) whose relations carry the most of it (docs/accuracy.md,
"fr-clinic's return to its start"). Odometry reports
motion along the robot's heading; a relation that has the robot travel 10–20° off it for tens of
seconds, where dead reckoning goes straight, is one to check against the scans before blaming
the run (docs/accuracy.md, "fr-clinic's reference where its scans disagree").

Usage::

    uv run python tools/short_relations.py fr-clinic RUN_DIR ODOMETRY_RUN_DIR [--span 10] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from slam.eval.relations import match_times, relation_errors
from slam.geometry import relative
from slam.io.datadir import resolve_data_dir
from slam.io.registry import get_dataset
from slam.io.relations import Relations, read_relations
from slam.io.tum import read_tum
from slam.trajectory import Trajectory


def _median(values: np.ndarray, digits: int, scale: float = 1.0) -> float | None:
    """The median of ``values`` times ``scale``, rounded; ``None`` when there are none."""
    return round(float(np.median(values)) * scale, digits) if values.size else None


def _share(flags: np.ndarray) -> float | None:
    """The share of true ``flags``, rounded; ``None`` when there are none."""
    return round(float(flags.mean()), 4) if flags.size else None


def _motions(trajectory: Trajectory, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    i = match_times(trajectory.times, t1)
    j = match_times(trajectory.times, t2)
    return relative(trajectory.poses[i], trajectory.poses[j])


def _spans(a: np.ndarray, b: np.ndarray, gap: float = 30.0) -> list[list[float]]:
    """The time spans (s) covered by the relations ``[a, b]`` (sorted by start), those less
    than ``gap`` apart joined into one."""
    spans: list[list[float]] = []
    for lo, hi in sorted(zip(a.tolist(), b.tolist(), strict=True)):
        if spans and lo - spans[-1][1] < gap:
            spans[-1][1] = max(spans[-1][1], round(hi, 1))
        else:
            spans.append([round(lo, 1), round(hi, 1)])
    return spans


def _worst_pairs(
    t1: np.ndarray,
    t2: np.ndarray,
    error: np.ndarray,
    total: int,
    bin_s: float = 100.0,
    most: int = 5,
) -> list[dict]:
    """The relations ``t1 → t2`` grouped by the ``bin_s``-second windows of both ends, the
    ``most`` groups that carry the largest share of a run's mean error over its ``total``
    relations, largest first: their windows' starts (s), count, mean error and that share."""
    if error.size == 0:
        return []
    key = np.c_[np.floor(t1 / bin_s), np.floor(t2 / bin_s)]
    groups, where = np.unique(key, axis=0, return_inverse=True)
    where = where.reshape(-1)
    sums = np.bincount(where, weights=error, minlength=len(groups))
    counts = np.bincount(where, minlength=len(groups))
    order = np.argsort(-sums, kind="stable")[:most]
    return [
        {
            "t1_s": float(groups[g, 0] * bin_s),
            "t2_s": float(groups[g, 1] * bin_s),
            "relations": int(counts[g]),
            "mean_m": round(float(sums[g] / counts[g]), 3),
            "share_of_mean_m": round(float(sums[g] / total), 4),
        }
        for g in order
    ]


def compare(
    relations: Relations,
    runs: dict[str, Trajectory],
    span: float = 10.0,
    over: float = 0.2,
    sideways_deg: float = 10.0,
    sideways_length: float = 0.5,
) -> dict:
    """The figures of the module docstring for ``runs`` (``{"slam": Trajectory, "odometry":
    Trajectory}``) against ``relations``, over the relations shorter than ``span`` seconds."""
    errors = {name: relation_errors(t, relations) for name, t in runs.items()}
    both = np.intersect1d(errors["slam"].matched_index, errors["odometry"].matched_index)
    trans = {name: e.trans[np.searchsorted(e.matched_index, both)] for name, e in errors.items()}
    t1, t2 = relations.t1[both], relations.t2[both]
    short = (t2 - t1) < span
    bad = short & (trans["slam"] > over)
    motion = relations.motions[both]
    apart = relative(_motions(runs["odometry"], t1, t2), _motions(runs["slam"], t1, t2))
    apart_m = np.hypot(apart[:, 0], apart[:, 1])
    half = over / 2
    dead = _motions(runs["odometry"], t1, t2)
    turn = np.angle(
        np.exp(1j * (np.arctan2(motion[:, 1], motion[:, 0]) - np.arctan2(dead[:, 1], dead[:, 0])))
    )
    sideways = (
        short
        & (np.hypot(motion[:, 0], motion[:, 1]) >= sideways_length)
        & (np.abs(turn) > np.radians(sideways_deg))
    )
    all_slam = errors["slam"].trans
    slam_long = trans["slam"][~short]
    return {
        "long_relations": int((~short).sum()),
        "slam_long_mean_m": round(float(slam_long.mean()), 4) if slam_long.size else None,
        "long_share_of_slam_mean_m": (
            round(float(slam_long.sum() / all_slam.size), 4) if all_slam.size else None
        ),
        "long_worst": _worst_pairs(
            t1[~short] - relations.t1.min(),
            t2[~short] - relations.t1.min(),
            slam_long,
            all_slam.size,
        ),
        "short_relations": int(short.sum()),
        "slam_short_mean_m": round(float(trans["slam"][short].mean()), 4) if short.any() else None,
        "odometry_short_mean_m": (
            round(float(trans["odometry"][short].mean()), 4) if short.any() else None
        ),
        "sideways_relations": int(sideways.sum()),
        "sideways_share_of_slam_mean_m": (
            round(float(trans["slam"][sideways].sum() / all_slam.size), 4)
            if all_slam.size
            else None
        ),
        "sideways_times_s": _spans(
            t1[sideways] - relations.t1.min(), t2[sideways] - relations.t1.min()
        ),
        "span_s": span,
        "over_m": over,
        "slam_share_over": _share(trans["slam"][short] > over),
        "odometry_share_over": _share(trans["odometry"][short] > over),
        "slam_over_odometry_under_half": int((bad & (trans["odometry"] < half)).sum()),
        "odometry_over_slam_under_half": int(
            (short & (trans["odometry"] > over) & (trans["slam"] < half)).sum()
        ),
        "bad_slam_to_odometry_median_m": _median(apart_m[bad], 3),
        "bad_slam_within_half_of_odometry": int((apart_m[bad] < half).sum()),
        "good_slam_to_odometry_median_m": _median(apart_m[short & ~bad], 3),
        "bad_relation_rotation_median_deg": _median(np.abs(motion[bad, 2]), 2, 180 / np.pi),
        "good_relation_rotation_median_deg": _median(
            np.abs(motion[short & ~bad, 2]), 2, 180 / np.pi
        ),
        "bad_relation_length_median_m": _median(np.hypot(motion[bad, 0], motion[bad, 1]), 2),
        "good_relation_length_median_m": _median(
            np.hypot(motion[short & ~bad, 0], motion[short & ~bad, 1]), 2
        ),
    }


def main() -> int:
    """Print (or emit as JSON) the short-relation comparison of the two runs."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", help="registry name of the benchmark log (its relations file)")
    parser.add_argument("run", type=Path, help="run folder of the SLAM run")
    parser.add_argument("odometry", type=Path, help="run folder of the dead-reckoning run")
    parser.add_argument("--span", type=float, default=10.0, help="short: t2 - t1 below this (s)")
    parser.add_argument("--over", type=float, default=0.2, help="a bad relation's error (m)")
    parser.add_argument(
        "--sideways", type=float, default=10.0, help="direction off dead reckoning's (degrees)"
    )
    parser.add_argument(
        "--sideways-length", type=float, default=0.5, help="least length of such a relation (m)"
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if not args.span > 0.0:
        print(f"--span: expected seconds > 0, found {args.span:g}", file=sys.stderr)
        return 2
    if not args.over > 0.0:
        print(f"--over: expected metres > 0, found {args.over:g}", file=sys.stderr)
        return 2
    if not 0.0 <= args.sideways <= 180.0:
        print(f"--sideways: expected degrees in [0, 180], found {args.sideways:g}", file=sys.stderr)
        return 2
    if not args.sideways_length >= 0.0:
        print(
            f"--sideways-length: expected metres >= 0, found {args.sideways_length:g}",
            file=sys.stderr,
        )
        return 2
    dataset = get_dataset(args.log)
    if dataset.relations is None:
        print(f"{args.log}: the registry gives no relations file", file=sys.stderr)
        return 2
    relations = read_relations(resolve_data_dir(None) / dataset.relations)
    runs = {}
    for name, folder in (("slam", args.run), ("odometry", args.odometry)):
        path = folder / "trajectory.tum"
        if not path.is_file():
            print(f"{path}: expected a run folder's trajectory.tum", file=sys.stderr)
            return 2
        runs[name] = read_tum(path)
    figures = compare(relations, runs, args.span, args.over, args.sideways, args.sideways_length)
    report = {"log": args.log, **figures}
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for key, value in report.items():
            print(f"{key:36s} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
