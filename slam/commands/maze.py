"""``slam maze run|bench|show|convert``: micromouse mazes under the Udacity tester's rules.

A MAZE is a file path, or a name inside the data directory (``--data-dir``, else
``$SLAM_DATA_DIR``, else ``./data``), looked up under ``<data dir>/maze/``: for example
``udacity/test_maze_01`` or ``micromouseonline/classic/50``. Both the Udacity mask format and
the micromouseonline ASCII format are read (detected from the first line).

  slam maze run udacity/test_maze_03 --robot bounded      score, run-0 and run-1 steps, path
  slam maze bench micromouseonline/classic                 table against the lower bound
  slam maze show udacity/test_maze_03 --out maze03.png     walls, explored area, both runs
  slam maze convert udacity/test_maze_01 m01.txt --to ascii

Robots: ``bounded`` (ours, default), ``explore-all`` and ``block-out`` (the report's flood-fill
baselines). See docs/maze.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from slam.commands._common import (
    add_actions,
    add_data_dir_argument,
    add_file_force_argument,
    add_quiet_argument,
    add_record_argument,
    data_dir_from,
    show_progress,
)
from slam.errors import ConfigError, DataError, UsageError
from slam.io.atomic import check_new_file


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the sub-commands ``run``, ``bench``, ``show`` and ``convert`` of ``slam maze``."""
    from slam.maze import DEFAULT_ROBOT, ROBOT_NAMES

    sub = add_actions(parser, "maze_command", "ACTION")

    def robot_args(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--robot",
            default=DEFAULT_ROBOT,
            choices=list(ROBOT_NAMES),
            help=f"robot (default {DEFAULT_ROBOT})",
        )
        p.add_argument(
            "--set",
            action="append",
            default=[],
            metavar="KEY=VALUE",
            help="bounded-robot option, e.g. --set payoff=0.5 (repeatable)",
        )
        add_data_dir_argument(p)

    run = sub.add_parser("run", help="one trial: score, run-0 and run-1 steps, path")
    run.add_argument("maze", metavar="MAZE", help="maze file or data-directory name")
    robot_args(run)
    run.add_argument(
        "--json", action="store_true", help="JSON with the per-step history and wall knowledge"
    )
    add_record_argument(run, "known walls and the path after every step")
    add_file_force_argument(run)
    run.set_defaults(func=run_maze)

    bench = sub.add_parser("bench", help="many mazes: score against the lower bound")
    bench.add_argument(
        "mazes", nargs="+", metavar="DIR_OR_FILES", help="maze files or folders (or names)"
    )
    robot_args(bench)
    bench.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    bench.add_argument("--json", action="store_true", help="rows and summary as JSON")
    add_quiet_argument(bench)
    bench.set_defaults(func=bench_mazes)

    show = sub.add_parser("show", help="PNG of the walls, the explored area and both runs")
    show.add_argument("maze", metavar="MAZE", help="maze file or data-directory name")
    robot_args(show)
    show.add_argument("--out", type=Path, help="PNG to write (default: <maze>-<robot>.png here)")
    show.add_argument("--cell", type=int, default=32, help="pixels per cell (default 32)")
    show.add_argument(
        "--walls-only", action="store_true", help="draw the maze alone, without a trial"
    )
    add_file_force_argument(show)
    show.set_defaults(func=show_maze)

    convert = sub.add_parser("convert", help="convert between the Udacity and ASCII formats")
    convert.add_argument("maze", metavar="MAZE", help="maze file or data-directory name")
    convert.add_argument("out", type=Path, metavar="OUT", help="file to write")
    convert.add_argument(
        "--to",
        choices=["udacity", "ascii"],
        help="output format (default: the other one)",
    )
    add_file_force_argument(convert)
    add_data_dir_argument(convert)
    convert.set_defaults(func=convert_maze)


def _options(pairs: list[str]) -> dict[str, Any]:
    """``KEY=VALUE`` strings to the bounded robot's options, typed by its fields.

    Values are TOML literals (``0.5``, ``true``), never evaluated; a value of the wrong type or a
    non-finite number is one :class:`~slam.errors.ConfigError` naming the option (its range is
    checked by the robot's own configuration). Unknown keys are left to :func:`make_robot`.
    """
    from slam.maze.robots import BoundedConfig
    from slam.validate import Bounds, check_value, coerce, field_types, parse_literal

    types_ = field_types(BoundedConfig)
    options: dict[str, Any] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise UsageError(f"--set expects KEY=VALUE, found {pair!r}")
        try:
            value = parse_literal(text)
        except ConfigError as exc:
            raise UsageError(f"--set {key}: {exc}") from None
        if key in types_:
            value = coerce(value, types_[key], f"--set {pair}", key)
            problem = check_value(value, types_[key], Bounds())
            if problem is not None:
                raise ConfigError(f"--set {pair}: {key}: expected {problem}, found {value!r}")
        options[key] = value
    return options


def _load(args: argparse.Namespace):
    from slam.maze.formats import locate_maze, read_maze

    return read_maze(locate_maze(args.maze, data_dir_from(args)))


def _format_path(cells: list[tuple[int, int]]) -> str:
    return " ".join(f"({x},{y})" for x, y in cells)


def run_maze(args: argparse.Namespace) -> int:
    """One trial; prints the figures (or JSON)."""
    from slam.maze.bench import trial
    from slam.maze.planner import lower_bound, optimal_plan

    if args.record is not None:  # before any work
        from slam.viz.stream import check_recording_path

        check_recording_path(check_new_file(args.record, "--record", args.force))
    maze = _load(args)
    optimal = optimal_plan(maze)
    result = trial(maze, args.robot, **_options(args.set))
    if args.record is not None:
        from slam.viz.maze import record_maze_trial

        record_maze_trial(result, args.record)
    bound = lower_bound(optimal.steps, result.exploration_weight)
    if args.json:
        out = result.to_dict(history=True)
        out["optimal_run1_steps"] = optimal.steps
        out["lower_bound"] = round(bound, 6)
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
        return 0 if result.success else 1
    score = "FAILED" if result.score is None else f"{result.score:.3f}"
    print(f"maze {maze.name} ({maze.width}x{maze.height}), robot {result.robot}")
    print(f"score {score}  (lower bound {bound:.3f}, optimal run 1: {optimal.steps} steps)")
    runs = [f"run {i}: {n} steps" for i, n in enumerate(result.run_steps)]
    print("; ".join(runs) if runs else "no run completed")
    if result.failure:
        print(f"failure: {result.failure}")
    print(f"run 1 path: {_format_path(result.path(1))}")
    print(f"run 0 visited {int(result.visited_mask(0).sum())} of {maze.width * maze.height} cells")
    return 0 if result.success else 1


def bench_mazes(args: argparse.Namespace) -> int:
    """Bench over files and folders; prints the table (or JSON)."""
    from slam.maze.bench import format_table, rows_as_dicts, run_bench, summarize
    from slam.maze.formats import locate_mazes

    paths = locate_mazes(args.mazes, data_dir_from(args))
    if args.jobs < 1:
        raise UsageError(f"--jobs must be at least 1, got {args.jobs}")
    progress = None
    if show_progress(args) and not args.json:
        from tqdm import tqdm

        def progress(rows, total):
            return tqdm(rows, total=total, desc="mazes", unit="maze")

    rows = run_bench(paths, args.robot, args.jobs, _options(args.set) or None, progress)
    summary = summarize(rows)
    if args.json:
        json.dump(
            {"robot": args.robot, "summary": summary, "rows": rows_as_dicts(rows)}, sys.stdout
        )
        sys.stdout.write("\n")
    else:
        print(format_table(rows, summary, args.robot))
    unreadable = [r for r in rows if r.status == "unreadable"]
    if unreadable:  # bad input, not a robot's failure: the table is printed, then the error
        raise DataError(
            f"{len(unreadable)} of the {len(rows)} maze files could not be read; the first: "
            f"{unreadable[0].error}"
        )
    return 0 if summary["failures"] == 0 else 1


def show_maze(args: argparse.Namespace) -> int:
    """Render a trial (or the maze alone) to a PNG."""
    from slam.io.atomic import write_png
    from slam.maze.bench import trial
    from slam.maze.render import render_trial

    maze = _load(args)
    if args.cell < 8:
        raise UsageError(f"--cell must be at least 8 pixels, got {args.cell}")
    out = args.out or Path(f"{maze.name}-{'walls' if args.walls_only else args.robot}.png")
    if out.suffix.lower() != ".png":
        raise UsageError(f"--out {out}: expected a .png file name")
    check_new_file(out, "--out" if args.out else "the picture", args.force)
    result = None if args.walls_only else trial(maze, args.robot, **_options(args.set))
    write_png(out, render_trial(maze, result, args.cell))
    print(f"wrote {out}")
    return 0


def convert_maze(args: argparse.Namespace) -> int:
    """Read a maze in one format and write it in the other."""
    from slam.maze.formats import detect_format, locate_maze, parse_maze, read_maze_text, write_maze

    path = locate_maze(args.maze, data_dir_from(args))
    if args.out.exists() and args.out.samefile(path):
        raise UsageError(f"{args.out}: OUT is the maze being converted; write to another file")
    check_new_file(args.out, "OUT", args.force)
    text = read_maze_text(path)
    source_format = detect_format(text, str(path))
    maze = parse_maze(text, str(path), name=path.stem, fmt=source_format)
    target = args.to or ("ascii" if source_format == "udacity" else "udacity")
    write_maze(maze, args.out, target)
    print(f"wrote {args.out} ({target} format, {maze.width}x{maze.height})")
    return 0
