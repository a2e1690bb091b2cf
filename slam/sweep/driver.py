"""The sweep folder: which cells to run, resuming, the results table, summary and plot.

A sweep folder ``SWEEP_DIR`` holds ``.slam-sweep`` (its marker, written when slam makes the
folder), ``sweep.json`` (the spec's identity, :meth:`~slam.sweep.spec.SweepSpec.identity`), one
run folder per cell (``SWEEP_DIR/<cell>/``, an ordinary ``slam run`` folder plus the cell's
``eval.json``), ``logs/<cell>.log`` (what each worker printed), ``results.json``,
``results.csv`` and ``sweep.png``.

Safety: slam makes a sweep folder only where nothing is (or an empty folder), and writes into an
existing one only when it carries the marker and the same identity; anything else is refused
before any work, and nothing in it is replaced. A cell folder is written only through ``slam
run``'s atomic run folder (never replacing anything: a cell folder that exists and is not that
cell's finished run is that cell's error, and is left alone).

Resume: a cell whose run folder is complete (``.slam-run`` marker, the configuration the cell
would use) and evaluated (``eval.json`` naming the cell) is skipped; complete but not evaluated
is only evaluated; anything else runs (a partial folder of a dead run is removed by the run-folder
machinery, one of a live run is refused). Results are rewritten (atomically) after every cell, so
an interrupted sweep leaves a true table of what is done.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from slam.errors import UsageError
from slam.sweep.spec import Cell, SweepSpec

SWEEP_MARKER = ".slam-sweep"
"""Marker file of a sweep folder made by slam."""
SWEEP_FILE = "sweep.json"
RESULTS_JSON = "results.json"
RESULTS_CSV = "results.csv"
PLOT = "sweep.png"
LOG_DIR = "logs"
EVAL_FILE = "eval.json"

RELATION_FIGURES = (
    "trans_mean",
    "trans_std",
    "trans_median",
    "rot_mean_deg",
    "rot_std_deg",
    "rot_median_deg",
    "share_over_0.2m",
)
"""The relation-metric figures of a cell (a row of results.csv; empty for other metrics)."""

CSV_COLUMNS = (
    "cell",
    "log",
    "seed",
    "setting",
    "status",
    "metric",
    "error",
    *RELATION_FIGURES,
    "relations",
    "ate_rmse",
    "quality_score",
    "wall_s",
    "estimate_wall_s",
    "peak_rss_mb",
    "scans",
    "trajectory_sha256",
    "message",
)
"""Columns of ``results.csv``, one row per cell."""


@dataclass
class SweepOutcome:
    """What a sweep did: every cell's row, and how many ran, were skipped and failed."""

    folder: Path
    rows: list[dict[str, Any]]
    ran: int = 0
    skipped: int = 0
    failed: int = 0
    wall_s: float = 0.0
    summary: list[dict[str, Any]] = field(default_factory=list)


def _marker_text() -> str:
    return (
        "This folder is a sweep written by `slam sweep` (or `slam tune`).\n"
        "Rerunning the same sweep here finishes its missing cells; slam replaces nothing in it.\n"
    )


def open_sweep_folder(folder: Path, spec: SweepSpec, option: str = "--out") -> None:
    """Make ``folder`` a sweep folder of ``spec``, or check that it is one (module docstring)."""
    from slam.io.atomic import write_text

    folder = Path(folder)
    identity = spec.identity()
    if os.path.islink(folder):
        raise UsageError(f"{folder}: {option} is a symbolic link; slam never writes through a link")
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"{folder}: {option} expected a sweep folder, found a file")
    if folder.is_dir() and any(folder.iterdir()):
        marker, record = folder / SWEEP_MARKER, folder / SWEEP_FILE
        if not marker.is_file() or os.path.islink(marker):
            raise UsageError(
                f"{folder}: {option} exists, is not empty and is not a sweep folder of slam (no "
                f"{SWEEP_MARKER}); it was left alone (choose another {option})"
            )
        try:
            recorded = json.loads(record.read_text())["identity"]
        except (OSError, ValueError, KeyError, TypeError):
            raise UsageError(f"{record}: unreadable; the sweep folder was left alone") from None
        if recorded != identity:
            keys = sorted(k for k in identity if identity.get(k) != recorded.get(k))
            raise UsageError(
                f"{folder}: holds a sweep of another spec (differs in {', '.join(keys)}); it was "
                f"left alone (choose another {option})"
            )
        return
    folder.mkdir(parents=True, exist_ok=True)
    write_text(folder / SWEEP_MARKER, _marker_text())
    write_text(folder / SWEEP_FILE, json.dumps({"identity": identity}, indent=2) + "\n")


def expected_config_text(cell: Cell, data_dir: Path) -> str:
    """The ``config.toml`` the cell's ``slam run`` writes (as ``slam run`` resolves it).

    A bad value is one :class:`~slam.errors.SlamError` naming where the spec gave it (``FILE:
    [grid] rbpf.temperature: ...``, ``FILE: [run] set map.resolution: ...``), not the ``--set``
    the cell passes on."""
    import dataclasses

    from slam.cli import build_parser
    from slam.commands.run import overrides_from
    from slam.config import Override, dumps, load_config
    from slam.errors import SlamError
    from slam.io.sources import resolve

    args = build_parser().parse_args(["run", *(str(a) for a in cell.argv)])
    ref = resolve(cell.log, data_dir, where=f"sweep log {cell.log!r}")
    labels = {str(a): a.option for a in cell.argv if isinstance(a, Override)}
    overrides = [
        Override(o, labels[o]) if not isinstance(o, Override) and o in labels else o
        for o in overrides_from(args)
    ]
    try:
        config = load_config(ref.config_name if ref.shipped_config else "", args.config, overrides)
    except SlamError as exc:
        raise type(exc)(_said_once(str(exc), labels.values())) from None
    if not ref.shipped_config:
        config = dataclasses.replace(config, dataset=ref.config_name)
    return dumps(config)


def _said_once(message: str, labels: Iterable[str]) -> str:
    """``LABEL: KEY...: detail`` as ``LABEL...: detail`` when ``LABEL`` ends with ``KEY`` (``FILE:
    [grid] rbpf.x: rbpf.x: unknown key`` → ``FILE: [grid] rbpf.x: unknown key``)."""
    for label in labels:
        key = label.rsplit(" ", 1)[-1]
        if message.startswith(f"{label}: {key}"):
            return label + message[len(label) + 2 + len(key) :]
    return message


def check_sweep(spec: SweepSpec, data_dir: Path) -> dict[str, str]:
    """Check, before any cell runs, what would fail a cell as bad input, and return each cell's
    expected ``config.toml`` text by cell name.

    Every log must resolve (a message names where the logs were given: ``FILE: [sweep] logs``
    or ``--logs``), every ``[sweep.evaluation]`` be a metric its log has
    (:func:`~slam.sweep.cell.metrics_of`), and every cell's configuration load
    (:func:`expected_config_text`); else one :class:`~slam.errors.SlamError` line (exit 2)."""
    from slam.io.sources import resolve
    from slam.sweep.cell import METRIC_NEEDS, metrics_of

    cells = spec.cells()
    refs = {log: resolve(log, data_dir, where=spec.logs_where) for log in spec.logs}
    for log, metric in spec.evaluation:
        if log not in refs:  # not a log of this sweep (checked by the spec when it can be)
            continue
        ref, supported = refs[log], metrics_of(refs[log])
        if metric not in supported:
            absent = metric == "relations" and ref.relations is not None
            missing = f" ({ref.relations} is missing)" if absent else ""
            raise UsageError(
                f"{spec.where('sweep.evaluation')} {log}: {metric!r} needs "
                f"{METRIC_NEEDS[metric]}, which {log} does not have{missing}; expected one of "
                f"{', '.join(supported)}"
            )
    return {c.name: expected_config_text(c, data_dir) for c in cells}


def _state(cell: Cell, folder: Path, config_text: str) -> tuple[str, dict[str, Any] | None]:
    """``("done", result)``, ``("evaluate", None)``, ``("run", None)`` or ``("foreign", None)``."""
    from slam.io.runfolder import is_own_output

    if not os.path.lexists(folder):
        return "run", None
    if not is_own_output(folder, "run"):
        if folder.is_dir() and not os.path.islink(folder) and not any(folder.iterdir()):
            return "run", None
        return "foreign", None
    try:
        if (folder / "config.toml").read_text() != config_text:
            return "foreign", None
    except OSError:
        return "foreign", None
    try:
        record = json.loads((folder / EVAL_FILE).read_text()).get("sweep")
    except (OSError, ValueError, AttributeError):
        record = None
    if (
        isinstance(record, dict)
        and record.get("cell") == cell.name
        and record.get("status") == "ok"
    ):
        return "done", record
    return "evaluate", None


def _eval_json(cell: Cell, folder: Path, result: dict[str, Any]) -> dict[str, Any]:
    """The cell's ``eval.json``: the metric's summary as ``slam eval`` names it, and the cell."""
    evaluation = result.get("evaluation", {})
    out: dict[str, Any] = {"trajectory": str(folder / "trajectory.tum"), "dataset": cell.log}
    if "relations" in evaluation:
        out["relations"] = evaluation["relations"]
    if "ate" in evaluation:
        out.update(evaluation["ate"])
    if "quality" in evaluation:
        out["quality"] = evaluation["quality"]
    out["sweep"] = result
    return out


def _write_files(folder: Path, files: dict[str, bytes]) -> None:
    """Write a run folder a Ray worker returned, through the atomic run folder."""
    from slam.io.atomic import atomic_dir
    from slam.io.runfolder import KINDS, OWNER_FILE

    skip = {KINDS["run"].marker, OWNER_FILE}
    with atomic_dir(folder, kind="run") as tmp:
        for name, data in sorted(files.items()):
            if Path(name).name in skip:
                continue
            path = tmp / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)


def row_of(cell: Cell, result: dict[str, Any] | None) -> dict[str, Any]:
    """The results row of ``cell`` (``status = "pending"`` without a result)."""
    row: dict[str, Any] = {
        "cell": cell.name,
        "log": cell.log,
        "seed": cell.seed,
        "setting": cell.setting.name,
        "values": dict(cell.setting.values),
        "status": "pending" if result is None else result.get("status", "error"),
    }
    if result is None:
        return row
    evaluation = result.get("evaluation", {})
    row["metric"] = evaluation.get("metric")
    row["error"] = evaluation.get("error")
    rel = evaluation.get("relations", {})
    for key in ("trans_mean", "trans_std", "trans_median", "rot_mean_deg", "rot_std_deg"):
        row[key] = rel.get(key)
    row["rot_median_deg"] = rel.get("rot_median_deg")
    row["share_over_0.2m"] = rel.get("share_over_0.2m")
    row["relations"] = rel.get("count")
    row["ate_rmse"] = evaluation.get("ate", {}).get("ate_rmse")
    row["quality_score"] = evaluation.get("quality", {}).get("score")
    for key in ("wall_s", "estimate_wall_s", "peak_rss_mb", "scans"):
        row[key] = result.get("metrics", {}).get(key)
    row["trajectory_sha256"] = result.get("trajectory_sha256")
    row["message"] = result.get("error")
    if result.get("stage"):
        row["stage"] = result["stage"]
    return row


def _mean_std(values: list[float]) -> tuple[float, float]:
    n = len(values)
    mean = sum(values) / n
    return mean, math.sqrt(sum((v - mean) ** 2 for v in values) / n)


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Mean ± std (population, over seeds and logs) of each setting's error, per metric, and of
    each (setting, log); wall time alike."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for row in rows:
        if row["status"] != "ok" or row.get("error") is None:
            continue
        for log in ("*", row["log"]):
            groups.setdefault((row["setting"], row["metric"], log), []).append(row)
    out = []
    for (setting, metric, log), members in groups.items():
        errors = [float(r["error"]) for r in members]
        walls = [float(r["wall_s"]) for r in members if r.get("wall_s") is not None]
        mean, std = _mean_std(errors)
        entry = {
            "setting": setting,
            "metric": metric,
            "log": "all" if log == "*" else log,
            "cells": len(members),
            "error_mean": mean,
            "error_std": std,
            "values": members[0].get("values", {}),
        }
        if walls:
            entry["wall_mean_s"], entry["wall_std_s"] = _mean_std(walls)
        out.append(entry)
    return out


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


def write_results(folder: Path, spec: SweepSpec, rows: list[dict[str, Any]]) -> list[dict]:
    """Write ``results.json`` and ``results.csv`` atomically; return the summary."""
    from slam.io.atomic import write_text

    summary = summarise(rows)
    report = {"sweep_dir": str(folder), "spec": spec.identity(), "cells": rows, "summary": summary}
    write_text(folder / RESULTS_JSON, json.dumps(_finite(report), indent=2, allow_nan=False) + "\n")
    buffer = io.StringIO()
    writer = csv.DictWriter(
        buffer, fieldnames=CSV_COLUMNS, extrasaction="ignore", lineterminator="\n"
    )
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in CSV_COLUMNS})
    write_text(folder / RESULTS_CSV, buffer.getvalue())
    return summary


UNITS = {
    "relations": "m (mean relation translation error)",
    "ate": "m (ATE RMSE)",
    "quality": "(1 - map score)",
}


def format_summary(summary: list[dict[str, Any]]) -> str:
    """The printed table: per setting (all logs, then each log), error mean ± std and wall."""
    lines = []
    for metric in sorted({s["metric"] for s in summary}):
        lines.append(f"error: {UNITS.get(metric, metric)}")
        lines.append(
            f"{'setting':<36} {'log':<14} {'cells':>5} {'error mean ± std':>22} {'wall (s)':>14}"
        )
        entries = [s for s in summary if s["metric"] == metric]
        entries.sort(key=lambda s: (s["setting"], s["log"] != "all", s["log"]))
        for s in entries:
            wall = (
                f"{s['wall_mean_s']:.1f} ± {s['wall_std_s']:.1f}" if "wall_mean_s" in s else "n/a"
            )
            err = f"{s['error_mean']:.4f} ± {s['error_std']:.4f}"
            lines.append(
                f"{s['setting'][:36]:<36} {s['log'][:14]:<14} {s['cells']:>5} {err:>22} {wall:>14}"
            )
    return "\n".join(lines) + ("\n" if lines else "")


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend, or None when matplotlib is not installed (the
    ``plot`` extra)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def save_figure(plt: Any, fig: Any, path: Path) -> None:
    """Lay out ``fig``, write it to ``path`` as a PNG (atomically) and close it."""
    from slam.io.atomic import write_bytes

    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    write_bytes(path, buffer.getvalue())


def write_plot(folder: Path, rows: list[dict[str, Any]], name: str = PLOT) -> str | None:
    """``sweep.png``: error per setting and log (mean, bars = std over seeds), wall time per
    setting. Returns a note when matplotlib is missing (the plot is then skipped)."""
    plt = pyplot()
    if plt is None:
        return f"matplotlib is not installed (uv sync --extra plot): {name} skipped"
    ok = [r for r in rows if r["status"] == "ok" and r.get("error") is not None]
    if not ok:
        return f"no finished cell: {name} not drawn"
    settings = list(dict.fromkeys(r["setting"] for r in rows))
    logs = list(dict.fromkeys(r["log"] for r in rows))
    fig, (ax_err, ax_wall) = plt.subplots(1, 2, figsize=(12, 4.5))
    width = 0.8 / max(1, len(logs))
    for k, log in enumerate(logs):
        means, stds, xs = [], [], []
        for i, setting in enumerate(settings):
            values = [float(r["error"]) for r in ok if r["log"] == log and r["setting"] == setting]
            if values:
                m, s = _mean_std(values)
                means.append(m)
                stds.append(s)
                xs.append(i + (k - (len(logs) - 1) / 2) * width)
        metric = next((r["metric"] for r in ok if r["log"] == log), "")
        ax_err.bar(xs, means, width, yerr=stds, capsize=3, label=f"{Path(log).name} ({metric})")
    for i, setting in enumerate(settings):
        walls = [float(r["wall_s"]) for r in ok if r["setting"] == setting and r.get("wall_s")]
        if walls:
            m, s = _mean_std(walls)
            ax_wall.bar(i, m, 0.6, yerr=s, capsize=3, color="tab:gray")
    for ax in (ax_err, ax_wall):
        ax.set_xticks(range(len(settings)))
        ax.set_xticklabels(settings, rotation=30, ha="right", fontsize=8)
    ax_err.set_ylabel("error (relations / ATE: m; quality: 1 - score)")
    ax_err.set_title("error per setting and log (bars: std over seeds)")
    ax_err.legend(fontsize=8)
    ax_wall.set_ylabel("wall time per cell (s)")
    ax_wall.set_title("wall time per setting")
    save_figure(plt, fig, folder / name)
    return None


def default_sweep_dir(spec: SweepSpec) -> Path:
    """``runs/sweep-<spec file stem>`` or ``runs/sweep-<hash of the spec>``: the same sweep
    lands in the same folder, so rerunning it resumes it."""
    if spec.source is not None:
        return Path("runs") / f"sweep-{spec.source.stem}"
    return Path("runs") / f"sweep-{spec.digest()}"


def make_executor(spec: SweepSpec, data_dir: Path, folder: Path) -> Any:
    """The executor the spec asks for."""
    from slam.sweep.executors import LocalExecutor, RayExecutor

    if spec.executor == "ray":
        return RayExecutor(spec.workers, data_dir, spec.address)
    return LocalExecutor(spec.workers, data_dir, folder / LOG_DIR)


def _probe(spec: SweepSpec) -> None:
    """Refuse a Ray address where no cluster answers
    (:func:`~slam.sweep.executors.probe_ray_address`)."""
    from slam.sweep.executors import probe_ray_address

    probe_ray_address(str(spec.address), spec.address_where)


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def run_sweep(
    spec: SweepSpec, data_dir: Path, folder: Path | None = None, executor: Any = None
) -> SweepOutcome:
    """Run the sweep's missing cells into ``folder`` (module docstring) and write the results.

    Raises a :class:`KeyboardInterrupt` after writing the results of what is done when
    interrupted. Long because planning the cells, the result callback and the interrupt path
    share the results and the counts; split, each piece would take them all as arguments.
    """
    folder = Path(folder or spec.out or default_sweep_dir(spec))
    cells = spec.cells()
    configs = check_sweep(spec, data_dir)  # bad input: exit 2 now, before any cell
    probe = spec.executor == "ray" and spec.address is not None and executor is None
    fresh = not folder.exists()
    if probe and fresh:  # before the folder is made: a sweep that cannot run leaves nothing
        _probe(spec)
    open_sweep_folder(folder, spec)
    results: dict[str, dict[str, Any] | None] = {}
    tasks: list[dict[str, Any]] = []
    by_name = {c.name: c for c in cells}
    outcome = SweepOutcome(folder, [])
    for cell in cells:
        state, record = _state(cell, folder / cell.name, configs[cell.name])
        if state == "done":
            results[cell.name] = record
            outcome.skipped += 1
            continue
        if state == "foreign":
            results[cell.name] = {
                "cell": cell.name,
                "status": "error",
                "stage": "run",
                "error": f"{folder / cell.name}: exists and is not this cell's finished run folder "
                "(another configuration, or not a run folder of slam run); it was left alone",
            }
            continue
        results[cell.name] = None
        tasks.append(
            {
                "cell": cell.name,
                "log": cell.log,
                "argv": [str(a) for a in cell.argv],
                "out": str((folder / cell.name).resolve()),
                "data_dir": str(Path(data_dir).resolve()),
                "metric": cell.metric,
                "evaluate_only": state == "evaluate",
            }
        )

    def rows() -> list[dict[str, Any]]:
        return [row_of(c, results[c.name]) for c in cells]

    if probe and not fresh and any(not t["evaluate_only"] for t in tasks):
        _probe(spec)  # a finished sweep's results are written again without its cluster
    executor = executor or make_executor(spec, data_dir, folder)
    local_tasks = tasks
    if spec.executor == "ray":  # a finished run is evaluated where it is, by the driver
        from slam.sweep.cell import run_cell

        for task in [t for t in tasks if t["evaluate_only"]]:
            results[task["cell"]] = run_cell(task)
        local_tasks = [t for t in tasks if not t["evaluate_only"]]
    _say(
        f"slam sweep: {len(cells)} cells in {folder} ({outcome.skipped} done, "
        f"{len(local_tasks)} to run); {executor.describe()}"
    )
    start = time.perf_counter()
    done = [0]

    def on_result(task: dict[str, Any], result: dict[str, Any]) -> None:
        cell = by_name[task["cell"]]
        files = result.pop("files", None)
        cell_dir = folder / cell.name
        try:
            if files:
                _write_files(cell_dir, files)
            if result.get("status") == "ok":
                from slam.io.atomic import write_text

                write_text(
                    cell_dir / EVAL_FILE,
                    json.dumps(_finite(_eval_json(cell, cell_dir, result)), indent=2) + "\n",
                )
        except (OSError, UsageError) as exc:
            result = dict(result, status="error", stage="write", error=str(exc))
        results[cell.name] = result
        done[0] += 1
        row = row_of(cell, result)
        figure = (
            f"error {row['error']:.4f} ({row['metric']})"
            if row["status"] == "ok" and row.get("error") is not None
            else f"FAILED: {row.get('message')}"
        )
        _say(f"[{done[0]}/{len(local_tasks)}] {cell.name}: {figure}")
        write_results(folder, spec, rows())

    try:
        executor.run(local_tasks, on_result)
    except KeyboardInterrupt:
        write_results(folder, spec, rows())
        missing = sum(1 for c in cells if results[c.name] is None)
        _say(
            f"slam sweep: interrupted; {missing} cell(s) missing; rerun the same command to finish them"
        )
        raise
    outcome.wall_s = time.perf_counter() - start
    outcome.rows = rows()
    outcome.ran = len(local_tasks)
    outcome.failed = sum(1 for r in outcome.rows if r["status"] != "ok")
    outcome.summary = write_results(folder, spec, outcome.rows)
    return outcome
