#!/usr/bin/env python3
"""The short relations of a benchmark log: where a SLAM run is locally worse than dead reckoning.

For a run folder and a dead-reckoning run folder of the same log (``slam run LOG --method
odometry``), over the relations that span less than ``--span`` seconds: the share of each run's
errors over ``--over`` metres, how many are over it for the SLAM run but under half of it for
dead reckoning (and the reverse), how far the SLAM run's relative motion is from dead reckoning's
on its bad relations, and the relations' rotation on the bad and the good ones (docs/slam.md,
"fr-clinic's short relations").

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


def compare(
    relations: Relations, runs: dict[str, Trajectory], span: float = 10.0, over: float = 0.2
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
    return {
        "short_relations": int(short.sum()),
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
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
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
    report = {"log": args.log, **compare(relations, runs, args.span, args.over)}
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for key, value in report.items():
            print(f"{key:36s} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
