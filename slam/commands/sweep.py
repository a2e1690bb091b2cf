"""``slam sweep [SPEC.toml]``: many ``slam run`` cells (logs × seeds × settings), evaluated.

Each cell is an ordinary ``slam run`` into ``SWEEP_DIR/<cell>/`` plus its evaluation (relations,
ATE or the map quality score); the results go to ``results.csv`` / ``results.json`` and the
printed table (mean ± std per setting over seeds and logs), the plot to ``sweep.png``. Rerunning
the same sweep finishes only its missing cells. Exit 0 when every cell succeeded, 1 when some
failed (each recorded with its error), 2 on bad input, 130 when interrupted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from slam.commands._common import add_data_dir_argument, data_dir_from
from slam.config import METHODS
from slam.sweep.spec import EXECUTORS


def add_sweep_arguments(parser: argparse.ArgumentParser) -> None:
    """The options ``slam sweep`` and ``slam tune`` share: what to run, and where."""
    parser.add_argument("spec", nargs="?", type=Path, metavar="SPEC.toml", help="sweep spec file")
    parser.add_argument("--logs", metavar="A,B", help="logs (dataset names, 'demo' or paths)")
    parser.add_argument("--seeds", metavar="0-3", help="seeds: 0-3, 0,2,5")
    parser.add_argument("--out", type=Path, help="sweep folder (default runs/sweep-<spec name>)")
    parser.add_argument("--executor", choices=EXECUTORS, help="where cells run (default local)")
    parser.add_argument("--address", metavar="HOST:PORT", help="Ray cluster (with --executor ray)")
    parser.add_argument("--workers", type=int, help="cells at once (default: the cores)")
    run = parser.add_argument_group("slam run options, applied to every cell")
    run.add_argument("--method", choices=METHODS)
    run.add_argument("--particles", type=int)
    run.add_argument("--every", type=int)
    run.add_argument("--max-scans", type=int)
    run.add_argument("--config", type=Path, help="configuration file (TOML)")
    run.add_argument("--no-texture", action="store_true")
    run.add_argument("--no-record", action="store_true")
    add_data_dir_argument(parser)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam sweep``."""
    add_sweep_arguments(parser)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=V1[,V2,...]",
        help="one value: for every cell; several: a sweep axis (repeatable)",
    )
    parser.set_defaults(func=run_sweep_command)


def run_sweep_command(args: argparse.Namespace) -> int:
    """Build the spec, run the sweep, print the table, draw the plot."""
    from slam.sweep.driver import format_summary, run_sweep, write_plot
    from slam.sweep.spec import build_spec

    spec = build_spec(args.spec, args)
    outcome = run_sweep(spec, data_dir_from(args))
    note = write_plot(outcome.folder, outcome.rows)
    print(format_summary(outcome.summary), end="")
    if note:
        print(f"slam: note: {note}", file=sys.stderr)
    print(
        f"{outcome.folder}: {len(outcome.rows)} cells ({outcome.ran} run, {outcome.skipped} "
        f"already done, {outcome.failed} failed) in {outcome.wall_s:.1f} s; results.csv, "
        "results.json" + ("" if note else ", sweep.png")
    )
    if outcome.failed:
        for row in outcome.rows:
            if row["status"] != "ok":
                print(f"slam: cell {row['cell']} failed: {row.get('message')}", file=sys.stderr)
        return 1
    return 0
