"""Recording overhead: the same ``slam run`` with and without ``recording.rrd``.

* ``demo_overhead`` — ``slam run demo`` (4960 scans, rbpf, 30 particles);
* ``intel_overhead`` — ``slam run intel --max-scans 2000`` (needs the CARMEN logs in the data
  directory; skipped otherwise).

After a warm-up run (kernels compiled, dataset cached), the pipeline runs ``PAIRS`` times without
(``viz.record=false``) and with the recording, alternately. The texture stage is off in both (the
overhead is then relative to a shorter run: the conservative figure). Reported:

* ``recorder_pct`` — the recorder's own time (every call into it, file closing included,
  ``metrics.json`` → ``recording.log_s``) relative to the median run without recording: the
  direct measure of what recording costs;
* ``wall_difference_pct`` — the median of the paired wall-time differences (with − without),
  relative to the same median; on a shared 2-core machine single runs vary by ±15 %, so this
  figure is only as good as that noise (it also includes rerun's own background threads);
* the recording's size, whether ``rerun rrd verify`` accepts it, and its rows per entity.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from benches._util import data_dir, skip

PAIRS = 6


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
    from slam.viz.stream import rerun_executable, summarize, viewer_env

    with tempfile.TemporaryDirectory(prefix="slam-viz-bench-") as tmp:
        base = Path(tmp)
        _run(name, base / "warmup", overrides)
        plain, recorded = [], []
        for _ in range(PAIRS):
            plain.append(_run(name, base / "plain", [*overrides, "viz.record=false"]))
            recorded.append(_run(name, base / "rec", overrides))
        rrd = base / "rec" / "recording.rrd"
        rows = {path: s.rows for path, s in summarize(rrd).items() if s.rows}
        verify = subprocess.run(
            [*rerun_executable(), "rrd", "verify", str(rrd)], env=viewer_env(), capture_output=True
        )
        size_mb = rrd.stat().st_size / 2**20
    walls_plain = [m["bench_wall_s"] for m in plain]
    walls_rec = [m["bench_wall_s"] for m in recorded]
    median_plain = statistics.median(walls_plain)
    log_s = statistics.median(m["recording"]["log_s"] for m in recorded)
    difference = statistics.median(r - p for r, p in zip(walls_rec, walls_plain, strict=True))
    return {
        "scans": recorded[-1].get("scans"),
        "median_wall_without_recording_s": round(median_plain, 2),
        "median_wall_with_recording_s": round(statistics.median(walls_rec), 2),
        "recorder_s": round(log_s, 3),
        "recorder_pct": round(100.0 * log_s / median_plain, 1),
        "wall_difference_pct": round(100.0 * difference / median_plain, 1),
        "recording_mb": round(size_mb, 2),
        "rrd_verify_ok": verify.returncode == 0,
        "map_snapshots": recorded[-1]["recording"]["maps"],
        "rows": rows,
        "walls_without_s": [round(w, 2) for w in walls_plain],
        "walls_with_s": [round(w, 2) for w in walls_rec],
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
