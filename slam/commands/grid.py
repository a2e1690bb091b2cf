"""``slam grid``: grid-world localization with the exact histogram filter.

Grid-world localization: the Bayes filter on cells, computed exactly.

* ``slam grid list`` — the shipped scenarios (and the Udacity cases when the data is present);
* ``slam grid run SCENARIO [--json]`` — the posterior after every sense and every move;
* ``slam grid study [...]`` — random colour maps: observations until one cell holds ≥ 0.999 and
  how often that cell is the true one; a table and a PNG plot.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from slam.commands._common import (
    add_actions,
    add_data_dir_argument,
    add_file_force_argument,
    add_quiet_argument,
    add_record_argument,
    data_dir_from,
    show_progress,
)
from slam.errors import UsageError
from slam.io.atomic import check_new_file


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the sub-commands of ``slam grid`` and their arguments."""
    sub = add_actions(parser, "grid_command")

    p_list = sub.add_parser("list", help="list the shipped scenarios")
    add_data_dir_argument(p_list)
    p_list.set_defaults(func=cmd_list)

    p_run = sub.add_parser(
        "run",
        help="run a scenario and print the posterior after every step",
        description="Run a scenario: the posterior after every sense and move, in percent.",
    )
    p_run.add_argument(
        "scenario", help="shipped name (see 'slam grid list'), udacity:<case>, or a TOML file"
    )
    p_run.add_argument("--json", action="store_true", help="print the steps as JSON")
    add_record_argument(p_run, "the posterior heat map after every step")
    add_file_force_argument(p_run)
    p_run.add_argument(
        "--no-stop",
        action="store_true",
        help="run every step even after the stopping threshold is reached",
    )
    add_data_dir_argument(p_run)
    p_run.set_defaults(func=cmd_run)

    p_study = sub.add_parser(
        "study",
        help="localization statistics on random colour maps (table + PNG)",
        description="Random n×n colour maps: observations until one cell holds the threshold, "
        "and how often it is the true cell.",
    )
    p_study.add_argument(
        "--sizes", default="3,5,10,20,50", help="grid sides, comma-separated (default: %(default)s)"
    )
    p_study.add_argument(
        "--errors",
        default="0.001,0.002,0.005,0.05",
        help="sensor error probabilities, comma-separated (default: %(default)s)",
    )
    p_study.add_argument("--colours", type=int, default=4, help="colours (default: 4)")
    p_study.add_argument("--trials", type=int, default=20, help="maps per setting (default: 20)")
    p_study.add_argument(
        "--max-steps", type=int, default=100, help="observations per trial (default: 100)"
    )
    p_study.add_argument(
        "--threshold", type=float, default=0.999, help="declare at max ≥ this (default: 0.999)"
    )
    p_study.add_argument("--seed", type=int, default=0, help="base seed (default: 0)")
    p_study.add_argument(
        "--out", type=Path, default=Path("grid-study.png"), help="PNG plot (default: %(default)s)"
    )
    p_study.add_argument("--json", action="store_true", help="print the rows as JSON")
    add_file_force_argument(p_study)
    add_quiet_argument(p_study)
    p_study.set_defaults(func=cmd_study)


def cmd_list(args: argparse.Namespace) -> int:
    """Print the shipped scenarios with their descriptions."""
    from slam.discrete.scenario import (
        UDACITY_FILE,
        load_scenario,
        load_udacity_cases,
        shipped_scenarios,
    )

    for name, path in shipped_scenarios().items():
        print(f"{name:<16} {load_scenario(path).description}")
    cases = data_dir_from(args) / UDACITY_FILE
    if cases.is_file():
        names = ", ".join(s.name for s in load_udacity_cases(cases))
        print(f"{'udacity:<case>':<16} Udacity test vectors from {cases}: {names}")
    else:
        print(f"{'udacity:<case>':<16} Udacity test vectors (needs {UDACITY_FILE} in --data-dir)")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    """Run one scenario and print its posteriors."""
    from slam.discrete.scenario import (
        format_table,
        posterior_json,
        resolve_scenario,
        run_scenario,
        step_title,
    )
    from slam.discrete.world import DIRECTIONS

    if args.record is not None:  # before any work
        from slam.viz.stream import check_recording_path

        check_recording_path(check_new_file(args.record, "--record", args.force))
    data_dir = data_dir_from(args) if args.scenario.startswith("udacity:") else None
    scenario = resolve_scenario(args.scenario, data_dir)
    if not scenario.steps:
        raise UsageError(f"{scenario.source}: the scenario has no steps ([run] steps = [...])")
    result = run_scenario(scenario, stop_when_localized=not args.no_stop)
    if args.record is not None:
        from slam.viz.grid import record_grid_run

        record_grid_run(result, args.record)
    world = scenario.world
    if args.json:
        out = {
            "scenario": scenario.name,
            "shape": list(world.shape),
            "headings": world.headings,
            "steps": [
                {
                    "after": rec.after,
                    "action": rec.action,
                    "posterior": posterior_json(rec.posterior, world),
                }
                for rec in result.steps
            ],
            "localized": list(result.localized_cell) if result.localized_cell else None,
            "expected_max_error": result.expected_error,
        }
        json.dump(out, sys.stdout)
        print()
        return 0
    print(f"Scenario {scenario.name}: {scenario.description}")
    print(f"World:  {world.describe()}")
    if scenario.sensor is not None:
        print(f"Sensor: {scenario.sensor.describe()}")
    if scenario.motion is not None:
        print(f"Motion: {scenario.motion.describe()}")
    for rec in result.steps:
        print()
        print(step_title(rec))
        print(format_table(rec.posterior, world))
        if world.headings > 1:
            headings = rec.belief.sum(axis=(1, 2))
            shares = "  ".join(
                f"{d} {100 * p:6.2f}" for d, p in zip(DIRECTIONS, headings, strict=True)
            )
            print(f"Heading: {shares}")
    if scenario.threshold is not None:
        print()
        if result.localized_cell is not None and result.localized_step is not None:
            r, c = result.localized_cell
            share = 100 * result.steps[result.localized_step].posterior[r, c]
            senses = sum(
                1 for rec in result.steps[: result.localized_step + 1] if rec.after == "sense"
            )
            print(
                f"Localized: cell ({r}, {c}) holds {share:.2f}% (≥ {100 * scenario.threshold:g}%) "
                f"after {senses} observations"
            )
        else:
            print(f"Not localized: no cell reached {100 * scenario.threshold:g}%")
    if result.expected_error is not None:
        verdict = "ok" if result.expected_error <= 1e-3 else "MISMATCH"
        print()
        print(f"Expected posterior: max |difference| = {result.expected_error:.2e} ({verdict})")
    return 0


def _numbers(text: str, kind: type, name: str) -> tuple:
    """Comma-separated numbers of ``kind``; an empty item (``3,,5``) is refused, as ``--seeds``
    refuses it."""
    parts = text.split(",")
    if not text.strip() or any(not p.strip() for p in parts):
        raise UsageError(
            f"--{name} {text!r}: expected comma-separated numbers, found an empty item"
        )
    try:
        return tuple(kind(p) for p in parts)
    except ValueError:
        raise UsageError(f"--{name} {text!r}: expected comma-separated numbers") from None


def cmd_study(args: argparse.Namespace) -> int:
    """Run the study, print the table, write the plot."""
    from slam.discrete.study import StudyConfig, format_rows, rows_json, run_study, study_figure
    from slam.io.atomic import write_png

    config = StudyConfig(
        sizes=_numbers(args.sizes, int, "sizes"),
        errors=_numbers(args.errors, float, "errors"),
        colours=args.colours,
        trials=args.trials,
        max_steps=args.max_steps,
        threshold=args.threshold,
        seed=args.seed,
    )
    from slam.discrete.scenario import check_world_memory

    side = max(config.sizes)
    check_world_memory(side, side, 1, f"--sizes {args.sizes}")
    if args.out.suffix.lower() != ".png":
        raise UsageError(f"--out {args.out}: expected a .png file name")
    check_new_file(args.out, "--out", args.force)
    total = len(config.sizes) * len(config.errors) * config.trials
    bar = None
    if show_progress(args):
        from tqdm import tqdm

        bar = tqdm(total=total, unit="trial", desc="grid study")
    try:
        rows = run_study(config, bar.update if bar is not None else None)
    finally:
        if bar is not None:
            bar.close()
    image = study_figure(rows, config)
    write_png(args.out, image)
    if args.json:
        json.dump({"rows": rows_json(rows), "plot": str(args.out)}, sys.stdout)
        print()
    else:
        print(format_rows(rows, config))
        seconds = sum(r.seconds for r in rows)
        print()
        print(f"{total} trials in {seconds:.1f} s; plot written to {args.out}")
    return 0
