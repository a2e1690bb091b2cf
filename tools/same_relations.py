#!/usr/bin/env python3
"""Runs of one log compared on the same relations: a run at a lower rate against the full rate.

A run that reads every k-th scan (``--every k``, ``filter.every``) can only be scored on the
relations whose two scans it kept, and those subsets differ in difficulty from the whole set (on
fr079 the 95 relations of every 3rd scan average 0.060 m at the full rate, against 0.040 m for
all of them). For a base run folder (the full rate) and other run folders of the same log, this
scores each other run on the relations it matched and the base run on exactly those, so that
the difference is the run's, not the subset's (docs/accuracy.md, "A robot that scans less
often"). The relations are the log's as ``slam eval`` reads them (mit-killian's re-timed copy),
or ``--relations FILE`` (a copy of a log under another path, such as ``tools/perturb_ranges.py``
writes).

Usage::

    uv run python tools/same_relations.py fr079 BASE_RUN RUN [RUN ...] [--relations FILE] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from slam.errors import SlamError
from slam.eval.relations import relation_errors
from slam.eval.retime import relations_file
from slam.io import sources
from slam.io.datadir import resolve_data_dir
from slam.io.relations import Relations, read_relations
from slam.io.tum import read_tum
from slam.trajectory import Trajectory


def on_same_relations(
    relations: Relations, base: Trajectory, runs: dict[str, Trajectory]
) -> list[dict]:
    """For each of ``runs``: the relations it matched, its mean translation error on them
    (m) and ``base``'s on the same relations (the relations ``base`` did not match left out of
    both; a run that matches none gets ``None``)."""
    whole = relation_errors(base, relations)
    base_error = dict(zip(whole.matched_index.tolist(), whole.trans.tolist(), strict=True))
    rows = []
    for name, trajectory in runs.items():
        errors = relation_errors(trajectory, relations)
        own = dict(zip(errors.matched_index.tolist(), errors.trans.tolist(), strict=True))
        common = sorted(set(own) & set(base_error))
        rows.append(
            {
                "run": name,
                "relations": len(common),
                "run_mean_m": round(float(np.mean([own[i] for i in common])), 4)
                if common
                else None,
                "base_mean_m": round(float(np.mean([base_error[i] for i in common])), 4)
                if common
                else None,
            }
        )
    return rows


def _trajectory(folder: Path) -> Trajectory:
    """The run folder's trajectory in the log's own order where the clock ran backwards."""
    for name in ("trajectory_file_order.tum", "trajectory.tum"):
        if (folder / name).is_file():
            return read_tum(folder / name)
    raise SlamError(f"{folder}: expected a run folder with trajectory.tum")


def main() -> int:
    """Print (or emit as JSON) each run's error and the base run's on the same relations."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", help="registry name or path of the log (its relations file)")
    parser.add_argument("base", type=Path, help="run folder scored on every run's relations")
    parser.add_argument("runs", type=Path, nargs="+", help="run folders to compare with it")
    parser.add_argument("--relations", type=Path, help="relations file (default: the log's)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    try:
        path = args.relations
        if path is None:
            data_dir = resolve_data_dir(None)
            path = relations_file(sources.resolve(args.log, data_dir, where="log"))
        if path is None:
            raise SlamError(
                f"{args.log}: expected a log with a relations file in {data_dir}, found none "
                "(give one with --relations)"
            )
        relations = read_relations(path)
        base = _trajectory(args.base)
        runs = {str(folder): _trajectory(folder) for folder in args.runs}
    except SlamError as exc:
        print(f"same_relations: {exc}", file=sys.stderr)
        return 2
    rows = on_same_relations(relations, base, runs)
    if args.json:
        print(json.dumps({"log": args.log, "base": str(args.base), "runs": rows}, indent=2))
    else:
        for row in rows:
            print(
                f"{row['run']}: {row['relations']} relations, {row['run_mean_m']} m; "
                f"the base run on the same: {row['base_mean_m']} m"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
