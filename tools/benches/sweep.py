"""``slam sweep``'s local pool: a 12-cell sweep on all cores vs the same cells one after another.

The cells: a 12 s simulated log (``slam sim small``, generated in a temporary folder) × seeds 0-5
× ``rbpf.temperature`` 10 and 40, texture and recording off. ``pool`` runs them with one worker
per core (``NUMBA_NUM_THREADS`` = 1 each), ``serial`` with one worker (``NUMBA_NUM_THREADS`` = the
cores), each into a fresh sweep folder. Reported: both walls, their ratio, and whether both gave
the same trajectories (they must: a run is deterministic given its seed whatever the thread count),
with the load average before and after (other work on the machine lowers the ratio).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CELLS = ["--seeds", "0-5", "--set", "rbpf.temperature=10,40", "--no-texture", "--no-record"]


def _sweep(log: Path, out: Path, workers: int) -> tuple[float, dict]:
    cmd = [sys.executable, "-m", "slam", "sweep", "--logs", str(log), "--out", str(out),
           "--workers", str(workers), *CELLS]  # fmt: skip
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    wall = time.perf_counter() - start
    rows = json.loads((out / "results.json").read_text())["cells"]
    return wall, {r["cell"]: r["trajectory_sha256"] for r in rows}


def _pool() -> dict:
    cores = len(os.sched_getaffinity(0))
    with tempfile.TemporaryDirectory(prefix="slam-bench-sweep-") as tmp:
        log = Path(tmp) / "small"
        subprocess.run([sys.executable, "-m", "slam", "sim", "small", "--out", str(log),
                        "--duration", "12", "--no-rgbd", "--quiet"], check=True)  # fmt: skip
        load_before = os.getloadavg()[0]
        serial, serial_hashes = _sweep(log, Path(tmp) / "serial", 1)
        pool, pool_hashes = _sweep(log, Path(tmp) / "pool", cores)
        load_after = os.getloadavg()[0]
    return {
        "cells": len(pool_hashes),
        "cores": cores,
        "serial_wall_s": round(serial, 2),
        "pool_wall_s": round(pool, 2),
        "serial_over_pool": round(serial / pool, 2),
        "same_trajectories": serial_hashes == pool_hashes,
        "load_average_before_after": [round(load_before, 2), round(load_after, 2)],
    }


def benches() -> dict:
    """The sweep benches."""
    return {"pool_12": _pool}
