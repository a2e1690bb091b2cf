"""``slam tune SPEC.toml``: search the spec's ``[tune.ranges]`` for the least mean error.

Random (default) or grid search; trial 0 is the default configuration. The trials run as one
sweep (resumable, local pool or Ray); the best becomes ``TUNE_DIR/config.toml`` (ready for
``slam run LOG --config``), the error-vs-wall trade-off ``tune.json``, the table and ``tune.png``.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from slam.commands._common import data_dir_from
from slam.commands.sweep import add_sweep_arguments
from slam.sweep.tune import SEARCHES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam tune``."""
    add_sweep_arguments(parser)
    parser.add_argument("--trials", type=int, help="trials, the default included (budget)")
    parser.add_argument("--search", choices=SEARCHES, help="random (default) or grid")
    parser.set_defaults(func=run_tune_command, set=[])


def run_tune_command(args: argparse.Namespace) -> int:
    """Run the trials, rank them, write the best configuration."""
    from slam.errors import UsageError
    from slam.sweep.driver import run_sweep, write_plot
    from slam.sweep.spec import build_spec, read_spec_file
    from slam.sweep.tune import format_trials, parse_tune, report, tune_spec_for, write_tune_plot

    if args.spec is None:
        raise UsageError("slam tune: give SPEC.toml (its [tune.ranges] declare the search)")
    spec = build_spec(args.spec, args)
    if args.out is None and spec.out is None:
        spec = replace(spec, out=Path("runs") / f"tune-{Path(args.spec).stem}")
    spec = tune_spec_for(spec, parse_tune(read_spec_file(args.spec), str(args.spec), args))
    outcome = run_sweep(spec, data_dir_from(args))
    result = report(spec, outcome)
    notes = [
        write_plot(outcome.folder, outcome.rows),
        write_tune_plot(outcome.folder, result["trials"]),
    ]
    print(format_trials(result["trials"], result["best"]), end="")
    for note in notes:
        if note:
            print(f"slam: note: {note}", file=sys.stderr)
    best, default = result["best"], result["default"]
    if best is None:
        print(f"slam: error: no trial finished in {outcome.folder}", file=sys.stderr)
        return 1
    gain = ""
    if "error_mean" in default:
        gain = f" (default {default['error_mean']:.4f})"
    print(
        f"{outcome.folder}: best {best['trial']} mean error {best['error_mean']:.4f}{gain}; "
        f"config {result['config']}; tune.json"
    )
    return 1 if outcome.failed else 0
