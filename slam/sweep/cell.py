"""One cell of a sweep: an ordinary ``slam run`` into the cell's folder, then its evaluation.

:func:`run_cell` parses the cell's ``slam run`` arguments with slam's own parser and runs
:func:`slam.commands.run.run_command` on them, so a cell is exactly ``slam run ARGS --out DIR``
(same configuration layers, same run-folder safety). It then evaluates the run
(:func:`evaluate_run_folder`): the relation metric when the log has a relations file, the ATE
against the ground truth for simulated logs, else the no-reference map quality score. Nothing it
raises escapes except an interrupt: a failing cell is a result with ``status = "error"``.

``python -m slam.sweep.cell`` is the worker process of the local executor: it reads one task
(JSON) on standard input, prints the result (JSON) as the last line of standard output, and sends
everything else (the run's own output) to standard error.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import sys
import traceback
from pathlib import Path
from typing import Any

from slam.errors import DataError, SlamError

RELATION_OUTLIER_M = 0.2
"""Relations with a translation error above this (m) are counted as outliers."""

METRIC_FIGURES = (
    "wall_s",
    "estimate_wall_s",
    "peak_rss_mb",
    "scans",
    "poses",
    "particles",
    "path_length_m",
    "scans_per_s",
    "real_time_factor",
)
"""The run's metrics.json figures a cell result carries."""


def sha256_of(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _relations(trajectory: Any, relations_file: Path) -> dict[str, Any]:
    import numpy as np

    from slam.eval.relations import relation_errors
    from slam.io.relations import read_relations

    errors = relation_errors(trajectory, read_relations(relations_file))
    if errors.count == 0:
        raise DataError(
            f"{relations_file}: none of its relations matches two poses of the run (is the run "
            "too short, or the log's times synthetic? evaluate it by quality instead)"
        )
    summary: dict[str, Any] = {"file": str(relations_file), **errors.summary()}
    summary["trans_median"] = float(np.median(errors.trans))
    summary["rot_median_deg"] = float(np.median(np.rad2deg(errors.rot)))
    summary["share_over_0.2m"] = float(np.mean(errors.trans > RELATION_OUTLIER_M))
    return summary


METRIC_NEEDS = {"relations": "a relations file", "ate": "a ground-truth trajectory"}
"""What a log needs for each metric that not every log has (``quality`` needs the map only)."""


def metrics_of(ref: Any) -> tuple[str, ...]:
    """The metrics the cells of the dataset ``ref`` (a :class:`slam.io.sources.DatasetRef`) can be
    evaluated by, as :func:`evaluate_run_folder` decides: ``relations`` when it has a relations
    file (re-timed where its times were lost), ``ate`` when it has a ground-truth trajectory (the
    demo's is made with it), and ``auto`` and ``quality`` always."""
    from slam.io.sources import Kind

    out = ["auto"]
    if ref.relations is not None and ref.relations.is_file():
        out.append("relations")
    reference = ref.reference
    if ref.kind == Kind.DEMO or (reference is not None and reference.is_file()):
        out.append("ate")
    return (*out, "quality")


def evaluate_run_folder(
    run_dir: Path, log: str, data_dir: Path, metric: str = "auto"
) -> dict[str, Any]:
    """Evaluate the finished run folder ``run_dir`` of ``log``: ``{"metric", "error", ...}``
    where ``error`` is the figure to minimise (relations: mean translation error, m; ATE: RMSE,
    m; quality: ``1 - score``) and the metric's own summary is under its name."""
    from slam.io import sources
    from slam.io.tum import read_tum

    run_dir = Path(run_dir)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    ref = sources.resolve(log, data_dir, where="sweep log")
    trajectory = read_tum(run_dir / "trajectory.tum")
    from slam.eval.retime import relations_file

    # re-timed where the log lost its times (cached); not read for another metric
    relations = relations_file(ref) if metric in ("auto", "relations") else None
    has_relations = relations is not None
    if metric == "auto":
        if has_relations:
            metric = "relations"
        elif "ate_rmse" in metrics or ref.reference is not None:
            metric = "ate"
        else:
            metric = "quality"
    out: dict[str, Any] = {"metric": metric}
    if metric == "relations":
        if not has_relations:
            raise DataError(
                f"{log}: evaluation 'relations' asked for, but the log has no relations file"
            )
        out["relations"] = _relations(trajectory, relations)
        out["error"] = out["relations"]["trans_mean"]
        quality = metrics.get("quality")  # the run's own map score comes along
        if isinstance(quality, dict) and quality.get("score") is not None:
            out["quality"] = {k: v for k, v in quality.items() if k != "worst"}
    elif metric == "ate":
        if "ate_rmse" in metrics:
            out["ate"] = metrics["ground_truth"]
        elif ref.reference is not None and ref.reference.is_file():
            from slam.eval.trajectory import evaluate_against_reference

            out["ate"] = evaluate_against_reference(
                trajectory, read_tum(ref.reference, distinct_times=True)
            )
        else:
            raise DataError(f"{log}: evaluation 'ate' asked for, but the log has no ground truth")
        out["error"] = float(out["ate"]["ate_rmse"])
    else:
        quality = metrics.get("quality")
        if not isinstance(quality, dict) or quality.get("score") is None:
            from slam.eval.quality_run import evaluate_run

            quality, _scored = evaluate_run(run_dir, ref, trajectory)
        out["quality"] = {k: v for k, v in quality.items() if k != "worst"}
        if quality.get("score") is None:
            raise DataError(
                f"{run_dir}: the map quality score could not be computed (no stretch judged)"
            )
        out["error"] = 1.0 - float(quality["score"])
    return out


def _run(task: dict[str, Any]) -> None:
    from slam.cli import build_parser
    from slam.commands.run import run_command

    argv = ["run", *task["argv"], "--out", task["out"], "--quiet", "--data-dir", task["data_dir"]]
    args = build_parser().parse_args(argv)
    with contextlib.redirect_stdout(sys.stderr):
        run_command(args)


def _failure(exc: BaseException) -> str:
    if isinstance(exc, SlamError):
        return str(exc)
    if isinstance(exc, OSError):
        from slam.cli import environment_message

        return environment_message(exc)
    traceback.print_exc(file=sys.stderr)  # a bug: keep its traceback in the cell's log
    return f"{type(exc).__name__}: {exc}"


def run_cell(task: dict[str, Any]) -> dict[str, Any]:
    """Run (unless ``task["evaluate_only"]``) and evaluate one cell; never raises but for an
    interrupt. ``task``: ``cell``, ``log``, ``argv`` (``slam run`` arguments), ``out`` (the
    run folder), ``data_dir``, ``metric``."""
    out = Path(task["out"])
    result: dict[str, Any] = {
        "cell": task["cell"],
        "status": "ok",
        "worker": {
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "numba_threads": os.environ.get("NUMBA_NUM_THREADS", "default"),
        },
    }
    stage = "run"
    try:
        if not task.get("evaluate_only"):
            _run(task)
        stage = "evaluation"
        metrics = json.loads((out / "metrics.json").read_text())
        result["metrics"] = {k: metrics[k] for k in METRIC_FIGURES if k in metrics}
        result["trajectory_sha256"] = sha256_of(out / "trajectory.tum")
        result["evaluation"] = evaluate_run_folder(
            out, task["log"], Path(task["data_dir"]), task["metric"]
        )
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - a cell's failure is its result
        from slam.cli import _interrupt_in

        interrupt = _interrupt_in(exc) if isinstance(exc, SystemError) else None
        if interrupt is not None:  # numba wrapped a Ctrl-C: still an interrupt
            raise interrupt from None
        result.update(status="error", stage=stage, error=_failure(exc))
    return result


def main() -> int:
    """The local executor's worker: one task on stdin, its result as stdout's last line."""
    from slam.cli import _termination_as_interrupt

    task = json.loads(sys.stdin.read())
    try:
        with _termination_as_interrupt():
            result = run_cell(task)
    except KeyboardInterrupt as exc:
        return 128 + int(getattr(exc, "signum", 2))
    print(json.dumps(result, allow_nan=True), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
