"""Recording overhead: the same ``slam run`` with and without ``recording.rrd``.

* ``demo_overhead`` — ``slam run demo`` (4960 scans, rbpf, 30 particles);
* ``intel_overhead`` — ``slam run intel --max-scans 2000`` (needs the CARMEN logs in the data
  directory; skipped otherwise).

Each runs the pipeline alternately without (``viz.record=false``) and with the recording,
``REPEATS`` times each after a warm-up run, and keeps the fastest wall time of each (the machine
is shared: the minimum is the least disturbed run). The texture stage is off in both (the overhead is then
relative to a shorter run, the conservative figure). Reported: both wall times, the overhead in
percent, the recorder's own logging time, the recording's size and its rows. The demo dataset is
generated on first use (cached).
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

from benches._util import data_dir, skip

REPEATS = 3


def _run(name: str, out: Path, overrides: list[str]) -> dict:
    from slam.config import load_config
    from slam.pipeline import RunRequest, run

    config = load_config(name, None, ["texture.enabled=false", *overrides])
    start = time.perf_counter()
    folder = run(RunRequest(name=name, config=config, data_dir=data_dir(), out=out, force=True))
    wall = time.perf_counter() - start
    metrics = json.loads((folder / "metrics.json").read_text())
    metrics["bench_wall_s"] = wall
    return metrics


def _overhead(name: str, overrides: list[str]) -> dict:
    with tempfile.TemporaryDirectory(prefix="slam-viz-bench-") as tmp:
        base = Path(tmp)
        _run(name, base / "warmup", overrides)  # compiles every kernel, caches the dataset
        plain, recorded = [], []
        metrics: dict = {}
        for k in range(REPEATS):
            plain.append(_run(name, base / f"plain{k}", [*overrides, "viz.record=false"]))
            metrics = _run(name, base / f"rec{k}", overrides)
            recorded.append(metrics)
            rrd = base / f"rec{k}" / "recording.rrd"
        from slam.viz.stream import summarize

        rows = {path: s.rows for path, s in summarize(rrd).items() if s.rows}
        size_mb = rrd.stat().st_size / 2**20
    wall_plain = min(m["bench_wall_s"] for m in plain)
    wall_rec = min(m["bench_wall_s"] for m in recorded)
    return {
        "scans": metrics.get("scans"),
        "wall_without_recording_s": round(wall_plain, 2),
        "wall_with_recording_s": round(wall_rec, 2),
        "overhead_pct": round(100.0 * (wall_rec - wall_plain) / wall_plain, 1),
        "recorder_log_s": min(m["recording"]["log_s"] for m in recorded),
        "recorder_log_pct": round(
            100.0 * min(m["recording"]["log_s"] for m in recorded) / wall_plain, 1
        ),
        "recording_mb": round(size_mb, 2),
        "map_snapshots": metrics["recording"]["maps"],
        "rows": rows,
        "walls_without_s": [round(m["bench_wall_s"], 2) for m in plain],
        "walls_with_s": [round(m["bench_wall_s"], 2) for m in recorded],
    }


def demo_overhead() -> dict:
    """Wall time of ``slam run demo`` with and without the recording."""
    return _overhead("demo", [])


def intel_overhead() -> dict:
    """Wall time of ``slam run intel --max-scans 2000`` with and without the recording."""
    if not (data_dir() / "carmen" / "intel.clf.gz").is_file():
        return skip(f"{data_dir()}/carmen/intel.clf.gz is absent")
    return _overhead("intel", ["filter.max_scans=2000"])


def benches() -> dict:
    """The benches of this module."""
    return {"demo_overhead": demo_overhead, "intel_overhead": intel_overhead}
