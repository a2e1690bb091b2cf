"""``slam eval RUN_DIR``: how good is a run's trajectory and map, with or without ground truth.

Without options it scores the map's consistency, which needs no ground truth (each stretch of
the run is compared with the map of the other stretches, re-reading the run's log; the worst
stretches are listed and drawn in RUN_DIR/quality.png), and adds the ground truth of the run's
dataset when it has one (the registry's relations file of a CARMEN benchmark log, the
groundtruth.tum of the demo or of a simulated dataset folder). ``--relations FILE`` applies the
Kümmerle relation metric, ``--reference FILE.tum`` computes ATE and RPE against a reference
trajectory; with either, ``--quality`` adds the map score. The command reads
``RUN_DIR/trajectory.tum``, prints a table (or the JSON with ``--json``) and writes the same JSON
to ``RUN_DIR/eval.json`` atomically (replacing an earlier one). With ``RUN_DIR/map.yaml`` (runs
since map_server output) the report also gives the map's size and occupied / free / unknown cell
counts under ``map`` (read with :func:`slam.io.mapserver.read_map_yaml`).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slam.commands._common import add_data_dir_argument, data_dir_from
from slam.errors import DataError, SlamError, UsageError

if TYPE_CHECKING:
    from slam.trajectory import Trajectory

TRAJECTORY_FILE = "trajectory.tum"
"""The trajectory a run folder holds."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam eval``."""
    from slam.eval.relations import DEFAULT_TOLERANCE_S
    from slam.eval.trajectory import Alignment, DeltaUnit

    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="run folder to evaluate")
    parser.add_argument(
        "--relations",
        type=Path,
        metavar="FILE",
        help="ground-truth relations file (t1 t2 x y z roll pitch yaw)",
    )
    parser.add_argument(
        "--reference", type=Path, metavar="FILE.tum", help="reference trajectory (TUM)"
    )
    parser.add_argument(
        "--json", action="store_true", help="print the JSON report instead of a table"
    )
    parser.add_argument(
        "--tolerance",
        type=float,
        default=DEFAULT_TOLERANCE_S,
        help=f"largest time difference (s) matching a relation to a pose (default {DEFAULT_TOLERANCE_S:g})",
    )
    parser.add_argument(
        "--align",
        choices=[a.value for a in Alignment],
        default=Alignment.SE2.value,
        help="alignment before ATE (default se2: least-squares rotation + translation)",
    )
    parser.add_argument("--delta", type=float, default=1.0, help="RPE pair spacing (default 1)")
    parser.add_argument(
        "--delta-unit",
        choices=[u.value for u in DeltaUnit],
        default=DeltaUnit.FRAMES.value,
        help="unit of --delta (default frames)",
    )
    parser.add_argument(
        "--quality",
        action="store_true",
        help="also score the map's consistency without ground truth (the default when neither "
        "--relations nor --reference is given); re-reads the run's log",
    )
    parser.add_argument(
        "--dataset",
        metavar="NAME_OR_PATH",
        help="the run's log, to re-read for the map score and whose ground truth to use when "
        "neither --relations nor --reference is given (default: the 'dataset' of the run's "
        "config.toml, or the log_source its metrics.json recorded)",
    )
    add_data_dir_argument(parser)
    parser.set_defaults(func=run_eval)


def run_eval(args: argparse.Namespace) -> int:
    """Evaluate, print and write ``eval.json``."""
    from slam.eval.report import format_table, to_json, write_eval_json
    from slam.io.tum import read_tum

    run_dir = _checked_run_dir(args)
    result: dict[str, Any] = {"trajectory": str(run_dir / TRAJECTORY_FILE)}
    relations, reference = args.relations, args.reference
    implicit = relations is None and reference is None
    no_truth = None  # why the run's dataset gives no ground truth
    if implicit:
        name, relations, reference, no_truth = _dataset_ground_truth(args, run_dir)
        if name is not None:
            result["dataset"] = name
    trajectory = read_tum(run_dir / TRAJECTORY_FILE)
    result["poses"] = len(trajectory)
    if relations is not None:
        try:
            result["relations"] = _relations(
                trajectory, relations, args.tolerance, run_dir / TRAJECTORY_FILE
            )
        except DataError as exc:
            if not implicit:
                raise
            # The dataset's own relations that match nothing (a log whose times were lost and
            # not re-timed) must not cost the map score.
            print(f"slam: warning: {exc}; left out", file=sys.stderr)
            relations = None
            no_truth = "the dataset's relations were left out (the warning above says why)"
    if reference is not None:
        result["reference"] = str(reference)
        result.update(_reference(trajectory, reference, args))
    if (run_dir / "map.yaml").is_file():  # runs before map.yaml existed have only map.npz
        from slam.io.mapserver import read_map_yaml

        result["map"] = read_map_yaml(run_dir / "map.yaml").summary()
    picture = None
    if args.quality or implicit:
        from slam.eval.quality_run import PICTURE, evaluate_run, render_quality, resolve_run_log

        try:
            log = resolve_run_log(run_dir, data_dir_from(args), args.dataset)
            result["quality"], scored = evaluate_run(run_dir, log, trajectory)
        except SlamError as exc:
            if args.quality:
                raise
            if "relations" not in result and reference is None:
                why = f": {no_truth}" if no_truth else ""
                raise type(exc)(f"{exc}; and no ground truth either{why}") from None
            print(f"slam: warning: map quality not computed: {exc}", file=sys.stderr)
        else:
            picture = render_quality(scored)
            result["quality"]["picture"] = str(run_dir / PICTURE)

    ours = _made_by_slam(run_dir)
    if picture is not None and not _may_write(run_dir / PICTURE, ours, result):
        picture = result["quality"]["picture"] = None
    if picture is not None:
        from slam.io.atomic import write_png

        try:
            write_png(run_dir / PICTURE, picture)
        except OSError as exc:
            raise DataError(f"{run_dir / PICTURE}: cannot write ({exc.strerror or exc})") from None
    if _may_write(run_dir / "eval.json", ours, result):
        try:
            write_eval_json(run_dir, result)
        except OSError as exc:
            raise DataError(
                f"{run_dir / 'eval.json'}: cannot write ({exc.strerror or exc})"
            ) from None
    print(to_json(result) if args.json else format_table(result), end="")
    return 0


def _made_by_slam(run_dir: Path) -> bool:
    """Whether ``run_dir`` is a folder of ``slam run`` or ``slam localize`` (its marker)."""
    from slam.io.runfolder import is_own_output

    return is_own_output(run_dir, "run") or is_own_output(run_dir, "localize")


def _may_write(path: Path, ours: bool, result: dict[str, Any]) -> bool:
    """Whether ``slam eval`` writes ``path``: always into a folder slam made; into another
    folder (a trajectory of another tool) only where no such file is, with a warning (and a
    note in the result) otherwise: a run never replaces what it did not make."""
    if ours or not os.path.lexists(path):
        return True
    message = f"{path} not written: it exists, and {path.parent} is not a folder slam made"
    print(f"slam: warning: {message}", file=sys.stderr)
    result.setdefault("warnings", []).append(message)
    return False


def _checked_run_dir(args: argparse.Namespace) -> Path:
    """The run folder of ``slam eval``, once the options and the folder passed their checks."""
    if not args.tolerance > 0:
        raise UsageError(
            f"--tolerance: expected a positive number of seconds, found {args.tolerance}"
        )
    run_dir: Path = args.run_dir
    if not run_dir.is_dir():
        raise DataError(
            f"{run_dir}: run folder not found (expected a folder with {TRAJECTORY_FILE})"
        )
    if not (run_dir / TRAJECTORY_FILE).is_file():
        raise DataError(
            f"{run_dir / TRAJECTORY_FILE}: trajectory file not found (expected the "
            f"{TRAJECTORY_FILE} that `slam run` writes to its run folder)"
        )
    for option, path in (("--relations", args.relations), ("--reference", args.reference)):
        if path is not None and path.is_dir():
            raise DataError(f"{path}: {option} expected a file, found a folder")
    return run_dir


def _relations(
    trajectory: Trajectory, path: Path, tolerance: float, trajectory_file: Path
) -> dict[str, Any]:
    from slam.eval.relations import relation_errors
    from slam.io.relations import read_relations

    relations = read_relations(path)
    errors = relation_errors(trajectory, relations, tolerance)
    times = trajectory.times
    if errors.count == 0:
        raise DataError(
            f"{path}: none of its {len(relations)} relations matches two poses of {trajectory_file} "
            f"within {tolerance:g} s (relations span {relations.t1.min():.6f}.."
            f"{relations.t2.max():.6f} s, trajectory {times.min():.6f}..{times.max():.6f} s): "
            "is it the same log?"
        )
    summary: dict[str, Any] = {"file": str(path)}
    summary.update(errors.summary())
    first = errors.unmatched_index[:10]
    summary["unmatched_first"] = [[float(relations.t1[k]), float(relations.t2[k])] for k in first]
    if errors.unmatched:
        print(
            f"slam: warning: {errors.unmatched} of {errors.total} relations in {path} match no pose "
            f"within {tolerance:g} s (first: t1={relations.t1[first[0]]:.6f}, "
            f"t2={relations.t2[first[0]]:.6f}); the statistics cover the {errors.count} others",
            file=sys.stderr,
        )
    return summary


def _dataset_ground_truth(
    args: argparse.Namespace, run_dir: Path
) -> tuple[str | None, Path | None, Path | None, str | None]:
    """The dataset of the run (``--dataset``, else its ``config.toml``) and its ground truth:
    ``(name, relations file or None, reference trajectory or None, why there is none)``."""
    from slam.config import load_config
    from slam.io import registry, sources

    usage = "give --relations FILE and/or --reference FILE.tum"
    config_file = run_dir / "config.toml"
    name = args.dataset
    if name is None and config_file.is_file():
        name = load_config("", config_file).dataset or None
    if name is None:
        return None, None, None, f"no --dataset, and {config_file} names no dataset; {usage}"
    where = "--dataset" if args.dataset else f"{config_file}: dataset"
    if args.dataset is None and name != "demo" and name not in registry.load_registry():
        from slam.eval.quality_run import recorded_source

        recorded = recorded_source(run_dir)  # a run made from a path records only its stem
        if recorded is not None and recorded.exists():
            name, where = str(recorded), f"{run_dir / 'metrics.json'}: log_source"
    try:
        ref = sources.resolve(name, data_dir_from(args), where=where, hint=usage)
    except SlamError as exc:
        return name, None, None, str(exc)
    reference = ref.reference
    if reference is not None:
        sources.ensure(ref, progress=sys.stderr.isatty())  # the demo, generated if absent
        reference = reference if reference.is_file() else None
    from slam.eval.retime import relations_file

    try:  # mit-killian's shared copy lost its times: its relations are re-timed (cached)
        relations = relations_file(ref, progress=sys.stderr.isatty())
    except DataError as exc:
        print(f"slam: warning: {exc}; the relations are left out", file=sys.stderr)
        relations = None
    if relations is None and reference is None:
        expected = sources.GROUND_TRUTH_FILE if ref.reference is not None else "relations file"
        why = f"{where}: dataset {name!r} ({ref.kind}) has no ground truth (no {expected}); {usage}"
        return name, None, None, why
    return name, relations, reference, None


def _reference(trajectory: Trajectory, path: Path, args: argparse.Namespace) -> dict[str, Any]:
    from slam.eval.trajectory import Alignment, DeltaUnit, evaluate_against_reference
    from slam.io.tum import read_tum

    return evaluate_against_reference(
        trajectory,
        read_tum(path, distinct_times=True),
        alignment=Alignment(args.align),
        delta=args.delta,
        unit=DeltaUnit(args.delta_unit),
        estimate_name=str(args.run_dir / TRAJECTORY_FILE),
        reference_name=str(path),
    )
