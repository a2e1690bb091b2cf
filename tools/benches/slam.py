"""SLAM speed and accuracy: the figures of the README's "Performance" and "Accuracy" tables.

Speed (``demo_*``): ``slam run demo`` (simulated dataset20 scale, 4960 scans × 1081 beams) with the
default method, after a warm-up run so numba kernels are compiled and the demo is cached. The
texture stage and the recording are off so the figure is the SLAM pipeline's own. Reported: the
filter's wall time (``estimate_wall_s``), the whole pipeline's (``wall_s``), scans/s, real-time
factor, peak resident memory, ATE RMSE against the simulator's ground truth.

Accuracy (``intel``, ``aces``, ``fr079``): the default configuration (only the logs' sensor
geometry differs, in ``configs/<log>.toml``), then the relation metric of Kümmerle et al. against
the log's relations file, beside the odometry-only figure and the published/measured references.
``classic_*``: the course's method on the same inputs.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

from benches._util import data_dir, skip

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


def _speed(particles: int, method: str = "rbpf") -> dict:
    overrides = [f"filter.particles={particles}", f'filter.method="{method}"']
    with tempfile.TemporaryDirectory(prefix="slam-bench-") as tmp:
        _run("demo", overrides + ["filter.max_scans=50"], Path(tmp) / "warm")
        m = _run("demo", overrides, Path(tmp) / "run")
    return {
        "method": method,
        "particles": particles,
        "scans": m["scans"],
        "estimate_wall_s": m["estimate_wall_s"],
        "wall_s": m["wall_s"],
        "scans_per_s": m["scans_per_s"],
        "real_time_factor": m["real_time_factor"],
        "peak_rss_mb": m["peak_rss_mb"],
        "ate_rmse": round(m["ate_rmse"], 4),
        "path_length_m": m["path_length_m"],
        "true_path_length_m": _true_length(),
    }


def _true_length() -> float:

    from slam.io.datadir import resolve_cache_dir
    from slam.io.tum import read_tum
    from slam.sim.demo import ensure_demo

    return round(
        read_tum(ensure_demo(resolve_cache_dir(data_dir())) / "groundtruth.tum").path_length(), 2
    )


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


def benches() -> dict:
    """The SLAM benches."""
    return {
        "demo_100": lambda: _speed(100),
        "demo_1000": lambda: _speed(1000),
        "demo_classic_100": lambda: _speed(100, "classic"),
        "intel": lambda: _accuracy("intel"),
        "aces": lambda: _accuracy("aces"),
        "fr079": lambda: _accuracy("fr079"),
        "intel_classic": lambda: _accuracy("intel", "classic", ["filter.particles=100"]),
    }
