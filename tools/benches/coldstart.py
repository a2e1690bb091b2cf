"""Cold start: ``slam run demo`` on a fresh numba cache, then again on the cache it filled.

Each bench makes a fresh ``NUMBA_CACHE_DIR`` in a temporary folder (nothing compiled), makes sure
the demo dataset is generated (``$SLAM_CACHE_DIR``: the figures are "dataset already cached"),
and runs the commands as a user would, each in its own process (``uv``'s environment, i.e. the
interpreter running this bench):

* ``demo_cold_then_warm`` — ``slam run demo`` (default: 30 particles, texture, recording) on the
  fresh cache (the background compiler on: :mod:`slam.jit_background`, its report as
  ``compile_background``), then the same command again: wall and CPU seconds (user + system of the child, all
  its threads) of each, and ``compile_s`` / ``estimate_wall_s`` from their ``metrics.json``;
  the cold run also reports the CPU seconds of compilation (``compile_cpu_s``, the compiling
  thread's, from ``$SLAM_COMPILE_REPORT``: :mod:`slam.jit`) and the kernels that cost most
  (``compile_top``: outermost compilations, each with the functions compiled on the way);
* ``demo_cold_without_background`` — the cold run with ``SLAM_BACKGROUND_COMPILE=0``: every
  kernel compiled by the run's process itself (the figure without :mod:`slam.jit_background`);
* ``warmup_then_run`` — ``slam warmup`` on a fresh cache, then ``slam run demo``: what the warm-up
  costs and that the run after it compiles nothing (``compile_s`` 0).

The machine's load average is reported with each figure: the 2-core machine is shared, so the
wall times there are upper bounds and the CPU seconds are the steadier figure.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _ensure_demo() -> None:
    from slam.io.datadir import resolve_cache_dir
    from slam.sim.demo import ensure_demo

    ensure_demo(resolve_cache_dir())


TOP_KERNELS = 15
"""How many of the costliest compilations a cold run lists."""


def _slam(args: list[str], cache: Path, background: bool = True) -> dict:
    """Run ``slam ARGS`` in a child process with ``NUMBA_CACHE_DIR=cache`` (and
    ``SLAM_BACKGROUND_COMPILE=0`` unless ``background``); wall, CPU, output, and what the main
    process compiled (:mod:`slam.jit`'s report)."""
    report = cache.parent / f"compile-{time.monotonic_ns()}.json"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), SLAM_COMPILE_REPORT=str(report))
    env["SLAM_BACKGROUND_COMPILE"] = "1" if background else "0"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load = os.getloadavg()[0]
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "slam", *args], env=env, capture_output=True, text=True
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"slam {' '.join(args)}: exit {proc.returncode}: {proc.stderr[-400:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    compiled = json.loads(report.read_text())
    top = sorted(compiled["outermost"], key=lambda row: -row["cpu_s"])[:TOP_KERNELS]
    return {
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 2),
        "load_average_at_start": round(load, 2),
        "load_average_at_end": round(os.getloadavg()[0], 2),
        "stdout": proc.stdout.strip().splitlines()[-1:],
        "compile_cpu_s": compiled["compile_cpu_s"],
        "kernels_compiled": compiled["kernels_compiled"],
        "compile_top": top,
    }


def _run_demo(cache: Path, out: Path, background: bool = True) -> dict:
    figures = _slam(["run", "demo", "--quiet", "--force", "--out", str(out)], cache, background)
    metrics = json.loads((out / "metrics.json").read_text())
    texture = metrics.get("texture", {})
    figures.update(
        compile_s=metrics.get("compile_s"),
        estimate_wall_s=metrics.get("estimate_wall_s"),
        estimate_compile_s=metrics.get("estimate_compile_s"),
        texture_wall_s=texture.get("wall_s"),
        texture_frames_per_s=texture.get("frames_per_s"),
        quality_wall_s=metrics.get("quality", {}).get("wall_s"),
        run_wall_s=metrics.get("wall_s"),
        ate_rmse=metrics.get("ate_rmse"),
        compile_background=metrics.get("compile_background"),
    )
    return figures


def demo_cold_then_warm() -> dict:
    """``slam run demo`` on a fresh numba cache, then again (warm)."""
    _ensure_demo()
    with tempfile.TemporaryDirectory(prefix="slam-cold-") as tmp:
        cache = Path(tmp) / "numba"
        cold = _run_demo(cache, Path(tmp) / "cold")
        warm = _run_demo(cache, Path(tmp) / "warm")
    return {"cold": cold, "warm": warm}


def demo_cold_without_background() -> dict:
    """``slam run demo`` on a fresh numba cache with ``SLAM_BACKGROUND_COMPILE=0`` (everything
    compiled by the run's own process, one kernel after another: the figure before
    :mod:`slam.jit_background`)."""
    _ensure_demo()
    with tempfile.TemporaryDirectory(prefix="slam-cold-") as tmp:
        return {"cold": _run_demo(Path(tmp) / "numba", Path(tmp) / "cold", background=False)}


def warmup_then_run() -> dict:
    """``slam warmup`` on a fresh numba cache, then ``slam run demo`` on it."""
    _ensure_demo()
    with tempfile.TemporaryDirectory(prefix="slam-cold-") as tmp:
        cache = Path(tmp) / "numba"
        warmup = _slam(["warmup", "--quiet"], cache)
        run = _run_demo(cache, Path(tmp) / "run")
    return {"warmup": warmup, "run": run}


def benches() -> dict:
    """The cold-start benches."""
    return {
        "demo_cold_then_warm": demo_cold_then_warm,
        "demo_cold_without_background": demo_cold_without_background,
        "warmup_then_run": warmup_then_run,
    }
