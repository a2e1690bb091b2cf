#!/usr/bin/env python3
"""What smoothing a run's trajectory with the odometry does to its relation error, per factor.

Run it on a folder of ``slam run LOG --set rbpf.smooth_odometry=false``, whose every scan's pose
is registered on the node map on its own (``trajectory.tum``): between neighbouring scans the
odometry is often the better relative measurement (aces: dead reckoning with the synchronised
odometry beats the filter on relations under 5 s). For every scan pose ``x_k`` it solves
``Σ ‖x_k − p_k‖²_reg + Σ ‖(x_k⁻¹ ⊕ x_{k+1}) ⊖ (o_k⁻¹ ⊕ o_{k+1})‖²_odo`` (``p``: the run's poses,
``o``: the odometry ``slam run`` used, ``robot.odometry_sync``) with what ``rbpf.smooth_odometry``
runs (:func:`slam.graph.smooth_with_odometry`) and prints the relation error before and after.
The registration's sigmas are fixed (``--reg-xy``, ``--reg-th``); the odometry's are its
disagreement with the filter's matcher over 1000 pairs of consecutive scans, along and across the
robot's heading and in heading
(:func:`slam.calibration.odometry_disagreement`) times each ``--factor`` (``rbpf.smooth_factor``):
the odometry is trusted as far as the log shows it deserves. docs/accuracy.md, "Smoothing with the
odometry (default, measured)".

Usage::

    uv run python tools/smoothing_check.py aces RUN_DIR [--factor 1 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from slam.calibration import odometry_disagreement
from slam.config import load_config
from slam.eval.relations import relation_errors
from slam.graph import smooth_with_odometry
from slam.io.datadir import resolve_data_dir
from slam.io.relations import read_relations
from slam.io.tum import read_tum
from slam.pipeline import load_source
from slam.scans import LogScans
from slam.trajectory import Trajectory


def main() -> int:
    """Print (or emit as JSON) the relation error of the run and of its smoothed trajectories."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", help="registry name of a CARMEN log with relations")
    parser.add_argument("run", type=Path, help="a `slam run LOG` folder of the same log")
    parser.add_argument("--factor", type=float, nargs="+", default=[1.0, 1.5, 2.0])
    parser.add_argument("--reg-xy", type=float, default=0.02, help="registration sigma (m)")
    parser.add_argument("--reg-th", type=float, default=0.005, help="registration sigma (rad)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    config = load_config(args.log)
    data_dir = resolve_data_dir(None)
    scans = LogScans.from_log(load_source(args.log, data_dir, config).log, config)
    in_order = args.run / "trajectory_file_order.tum"
    run = read_tum(in_order if in_order.exists() else args.run / "trajectory.tum")
    if len(run.poses) != len(scans):
        print(f"{args.run}: {len(run.poses)} poses for {len(scans)} scans", file=sys.stderr)
        return 2
    relations = read_relations(data_dir / "carmen" / "relations" / f"{args.log}.relations")

    def error(poses: np.ndarray) -> float:
        return round(
            float(relation_errors(Trajectory(scans.times, poses), relations).trans.mean()), 4
        )

    measured = odometry_disagreement(lambda k: scans.scan(k).hits(), scans.odometry, config)
    along, across, heading = measured.along, measured.across, measured.heading
    reg = (args.reg_xy, args.reg_th)
    report = {
        "log": args.log,
        "run": error(run.poses),
        "odometry_disagreement": {
            "along_m": round(along, 4),
            "across_m": round(across, 4),
            "th_deg": round(float(np.degrees(heading)), 3),
        },
        "smoothed": {
            f"{f:g}": error(
                smooth_with_odometry(
                    run.poses,
                    scans.odometry,
                    reg,
                    (f * along, f * across, f * heading),
                    config.loops,
                )  # fmt: skip
            )
            for f in args.factor
        },
    }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(
            f"{args.log}: run {report['run']} m; odometry vs matcher {along:.4f} m along, "
            f"{across:.4f} m across, {np.degrees(heading):.3f}°; smoothed (factor: m) "
            + ", ".join(f"{k}: {v}" for k, v in report["smoothed"].items())
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
