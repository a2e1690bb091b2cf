"""SLAM speed and accuracy: the figures of the README's "Performance" and "Accuracy" tables.

Speed (``demo_*``): ``slam run demo`` (simulated dataset20 scale, 4960 scans × 1081 beams) with the
default method, after a warm-up run so numba kernels are compiled and the demo is cached, three
times (:data:`SPEED_RUNS`; the figures of the median run, ``estimate_wall_s_runs`` every run's;
``run_peak_rss_mb`` the first run's peak memory, since the process's peak only grows). The
texture stage and the recording are off so the figure is the SLAM pipeline's own. Reported: the
filter's wall time (``estimate_wall_s``; by part, the filter and each post-filter stage,
``estimate_parts_s``), the whole pipeline's (``wall_s``), scans/s, real-time factor, peak
resident memory, ATE RMSE against the simulator's ground truth.

Accuracy (``intel``, ``aces``, ``fr079``, ``mit-csail``, ``fr-clinic``, ``mit-killian``): the
sweep spec ``tools/sweeps/slam_bench.toml`` run by ``slam sweep`` one log at a time into
``$SLAM_CACHE_DIR/bench-sweep/<code>/<log>``, where ``<code>`` is :func:`code_key` of the
package, configurations, lock file, spec and host CPU (resumable: a rerun of the same code on
the same host finishes only the missing cells; after a change to any of them it starts afresh,
never reading the cells of other code; the folders of other codes are left for you to remove), then
summarised by :func:`summarise_log`. Per log: ``odometry`` and ``rbpf`` keep their earlier keys
(seed 0: relation metric of Kümmerle et al. mean ± std, relations, wall, speed, peak memory,
scans), ``rbpf`` adds the median errors and the share of relations over 0.2 m, ``per_seed`` (every
seed's figures) and ``over_seeds`` (mean, std, min and max over the seeds; the largest peak
memory). mit-killian's shared copy has synthetic times: its relations are re-timed onto its
scans (:mod:`slam.eval.retime`), and its blocks carry the runs' map quality score too
(``quality_score``, per seed and over the seeds). ``intel_classic``: the course's
method on the same inputs.
"""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benches._util import cpu_model, data_dir, skip

from slam.sweep.driver import RELATION_FIGURES

REFERENCES = {
    "intel": {"gmapping_published": 0.070, "gmapping_measured": "0.029 ± 0.022 m in 70 s"},
    "aces": {"gmapping_published": 0.060, "gmapping_measured": "0.046 ± 0.040 m in 36 s"},
    "fr079": {"gmapping_published": 0.061, "gmapping_measured": "diverges"},
}


def _run(name: str, overrides: list[str], out: Path) -> dict:
    from slam.config import load_config
    from slam.pipeline import RunRequest, run

    config = load_config(name, None, ["texture.enabled=false", "viz.record=false", *overrides])
    start = time.perf_counter()
    folder = run(RunRequest(name=name, config=config, data_dir=data_dir(), out=out, force=True))
    metrics = json.loads((folder / "metrics.json").read_text())
    metrics["bench_wall_s"] = round(time.perf_counter() - start, 3)
    return metrics


SPEED_RUNS = 3
"""Runs of each ``demo_*`` bench: the figures are those of the run with the median estimate
(the runs give the same trajectory; their times vary by a few per cent on a shared machine)."""


def _speed(particles: int, method: str = "rbpf") -> dict:
    overrides = [f"filter.particles={particles}", f'filter.method="{method}"']
    with tempfile.TemporaryDirectory(prefix="slam-bench-") as tmp:
        _run("demo", overrides + ["filter.max_scans=50"], Path(tmp) / "warm")
        runs = [_run("demo", overrides, Path(tmp) / f"run{i}") for i in range(SPEED_RUNS)]
    times = [r["estimate_wall_s"] for r in runs]
    m = runs[sorted(range(len(runs)), key=times.__getitem__)[len(runs) // 2]]
    return {
        "method": method,
        "particles": particles,
        "scans": m["scans"],
        "estimate_wall_s": m["estimate_wall_s"],
        "estimate_wall_s_runs": times,
        "estimate_parts_s": m["estimate_parts_s"],
        "wall_s": m["wall_s"],
        "scans_per_s": m["scans_per_s"],
        "real_time_factor": m["real_time_factor"],
        # the first run's peak; the bench's own peak_rss_mb (tools/bench.py) is the process's
        # after all the runs, which later runs only raise (the earlier runs' freed heap)
        "run_peak_rss_mb": runs[0]["peak_rss_mb"],
        "ate_rmse": round(m["ate_rmse"], 4),
        "path_length_m": m["path_length_m"],
        "true_path_length_m": _true_length(),
    }


def _true_length() -> float:

    from slam.io.datadir import resolve_cache_dir
    from slam.io.tum import read_tum
    from slam.sim.demo import ensure_demo

    return round(read_tum(ensure_demo(resolve_cache_dir()) / "groundtruth.tum").path_length(), 2)


def _accuracy(name: str, method: str = "rbpf", extra: list[str] | None = None) -> dict:
    from slam.eval.relations import relation_errors
    from slam.io.registry import get_dataset
    from slam.io.relations import read_relations
    from slam.io.tum import read_tum

    dataset = get_dataset(name)
    log_path = data_dir() / dataset.log_file().path
    if not log_path.is_file():
        return skip(f"{log_path} is absent")
    relations = read_relations(data_dir() / dataset.relations)
    out: dict = {"method": method, **REFERENCES.get(name, {})}
    with tempfile.TemporaryDirectory(prefix="slam-bench-") as tmp:
        for label, meth in (("odometry", "odometry"), (method, method)):
            m = _run(name, [f'filter.method="{meth}"', *(extra or [])], Path(tmp) / label)
            err = relation_errors(read_tum(Path(tmp) / label / "trajectory.tum"), relations)
            err = err.summary()
            out[label] = {
                "trans_mean": round(err["trans_mean"], 4),
                "trans_std": round(err["trans_std"], 4),
                "rot_mean_deg": round(err["rot_mean_deg"], 3),
                "rot_std_deg": round(err["rot_std_deg"], 3),
                "relations": err["count"],
                "wall_s": m["wall_s"],
            }
            if meth != "odometry":
                out[label].update(
                    estimate_wall_s=m["estimate_wall_s"],
                    scans_per_s=m["scans_per_s"],
                    real_time_factor=m["real_time_factor"],
                    peak_rss_mb=m["peak_rss_mb"],
                    particles=m["particles"],
                    scans=m["scans"],
                )
    return out


SPEC = Path(__file__).resolve().parent.parent / "sweeps" / "slam_bench.toml"
"""The sweep spec of the accuracy benches."""

SEED_FIGURES = RELATION_FIGURES
"""Relation-metric figures kept per seed (rounded)."""


def _round(value, digits: int = 4):
    return None if value is None else round(float(value), digits)


def _spread(values: list[float]) -> dict:
    n = len(values)
    mean = sum(values) / n
    std = math.sqrt(sum((v - mean) ** 2 for v in values) / n)
    return {"mean": round(mean, 4), "std": round(std, 4), "min": round(min(values), 4),
            "max": round(max(values), 4)}  # fmt: skip


def _cell_figures(folder: Path, row: dict) -> dict:
    """One finished cell: its evaluation and its run's speed and memory."""
    metrics = json.loads((folder / row["cell"] / "metrics.json").read_text())
    out: dict = {"seed": row["seed"]}
    if row["metric"] == "relations":
        for key in SEED_FIGURES:
            out[key] = _round(row.get(key), 3 if "deg" in key else 4)
        out["relations"] = row.get("relations")
        if row.get("quality_score") is not None:  # the run's own map score (mit-killian's)
            out["quality_score"] = _round(row.get("quality_score"))
    else:
        out["quality_score"] = _round(row.get("quality_score"))
    out["wall_s"] = metrics.get("wall_s")
    for key in ("estimate_wall_s", "estimate_parts_s", "scans_per_s", "real_time_factor",
                "peak_rss_mb", "particles"):  # fmt: skip
        if key in metrics and metrics.get("method", row["setting"]) != "odometry":
            out[key] = metrics[key]
    return out


def summarise_log(folder: Path, name: str) -> dict:
    """The bench entry of log ``name`` from the sweep folder ``folder`` (module docstring)."""
    rows = [
        r for r in json.loads((folder / "results.json").read_text())["cells"] if r["log"] == name
    ]
    out: dict = {"method": "rbpf", **REFERENCES.get(name, {}), "sweep_dir": str(folder)}
    failed = [{"cell": r["cell"], "error": r.get("message")} for r in rows if r["status"] != "ok"]
    if failed:
        out["failed"] = failed
    blocks: dict = {}
    for setting in ("odometry", "rbpf"):
        cells = sorted((r for r in rows if r["setting"] == setting and r["status"] == "ok"),
                       key=lambda r: r["seed"])  # fmt: skip
        if not cells:
            continue
        seeds = [_cell_figures(folder, r) for r in cells]
        block = {k: v for k, v in seeds[0].items() if k != "seed"}
        if setting == "odometry":
            drop = ("trans_median", "rot_median_deg", "share_over_0.2m")
            block = {k: v for k, v in block.items() if k not in drop}
        else:
            figures = ["trans_mean", "rot_mean_deg", "trans_median", "share_over_0.2m"]
            if cells[0]["metric"] != "relations":
                figures = ["quality_score"]
            elif name == "mit-killian":  # its map score stays beside the re-timed relations
                figures.append("quality_score")
            block["scans"] = json.loads(
                (folder / cells[0]["cell"] / "metrics.json").read_text()
            ).get("scans")
            block["per_seed"] = seeds
            over: dict = {"seeds": [s["seed"] for s in seeds]}
            for key in [*figures, "wall_s"]:
                values = [s[key] for s in seeds if s.get(key) is not None]
                if values:
                    over[key] = _spread(values)
            peaks = [s["peak_rss_mb"] for s in seeds if s.get("peak_rss_mb") is not None]
            if peaks:
                over["peak_rss_mb_max"] = max(peaks)
            block["over_seeds"] = over
        blocks[setting] = block
    if rows and rows[0].get("metric") == "quality":
        # not a relation-metric bench: kept apart so the accuracy table does not read it
        out.update(metric="quality", quality=blocks)
    else:
        out.update(blocks)
    return out


ROOT = Path(__file__).resolve().parents[2]
CODE_FILES = ("slam/**/*.py", "slam/**/*.json", "configs/**/*.toml", "uv.lock", "pyproject.toml")


def code_key(root: Path = ROOT, extra: tuple[str, ...] = (), host: str | None = None) -> str:
    """12 hex digits of a SHA-256 over what a bench cell's result depends on: every file of
    :data:`CODE_FILES` under ``root`` (path and bytes, in sorted order), the sweep spec, the
    options ``extra`` added to it and the ``host`` CPU (:func:`benches._util.cpu_model`; its
    instruction set moves the last bits, docs/accuracy.md). A sweep folder resumed with other
    code, or on another host, would report that code's or host's figures as these."""
    digest = hashlib.sha256()
    files = sorted({p for pattern in CODE_FILES for p in root.glob(pattern) if p.is_file()})
    for path in [*files, SPEC]:
        name = path.relative_to(root) if path.is_relative_to(root) else path.name
        digest.update(str(name).encode() + b"\0" + path.read_bytes() + b"\0")
    for word in [*extra, cpu_model() if host is None else host]:
        digest.update(word.encode() + b"\0")
    return digest.hexdigest()[:12]


def sweep_accuracy(name: str, extra: tuple[str, ...] = ()) -> dict:
    """Run (or finish) the bench sweep of log ``name`` and summarise it."""
    from slam.io.datadir import resolve_cache_dir
    from slam.io.registry import get_dataset

    log_path = data_dir() / get_dataset(name).log_file().path
    if not log_path.is_file():
        return skip(f"{log_path} is absent")
    folder = resolve_cache_dir() / "bench-sweep" / code_key(extra=extra) / name
    cmd = [
        sys.executable,
        "-m",
        "slam",
        "sweep",
        str(SPEC),
        "--logs",
        name,
        "--out",
        str(folder),
        *extra,
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode not in (0, 1):  # 1: some cells failed, recorded in the summary
        raise RuntimeError(f"slam sweep {name}: {proc.stderr.strip().splitlines()[-1:]}")
    return summarise_log(folder, name)


def benches() -> dict:
    """The SLAM benches."""
    return {
        "demo_100": lambda: _speed(100),
        "demo_1000": lambda: _speed(1000),
        "demo_classic_100": lambda: _speed(100, "classic"),
        "intel": lambda: sweep_accuracy("intel"),
        "aces": lambda: sweep_accuracy("aces"),
        "fr079": lambda: sweep_accuracy("fr079"),
        "mit-csail": lambda: sweep_accuracy("mit-csail"),
        "fr-clinic": lambda: sweep_accuracy("fr-clinic"),
        "mit-killian": lambda: sweep_accuracy("mit-killian"),
        "intel_classic": lambda: _accuracy("intel", "classic", ["filter.particles=100"]),
    }
