"""Helpers shared by the bench modules (not a bench itself)."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


def data_dir() -> Path:
    """The data directory benches read real logs from (``$SLAM_DATA_DIR`` or ``./data``)."""
    from slam.io.datadir import resolve_data_dir

    return resolve_data_dir(None)


def best_of(fn: Callable[[], Any], repeat: int = 3) -> tuple[float, Any]:
    """Smallest wall time of ``repeat`` calls of ``fn`` and the last result."""
    best = float("inf")
    result = None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - start)
    return best, result


def skip(reason: str) -> dict:
    """Result of a bench that cannot run here (e.g. its data is absent)."""
    return {"skipped": reason, "pid": os.getpid()}


def cpu_model() -> str:
    """The CPU's model name and whether it has AVX-512 (``/proc/cpuinfo``; ``platform`` elsewhere):
    the figures depend on the host, its speed and, in the last bits, its instruction set
    (docs/accuracy.md, "Reproducible on one machine, not bit for bit across CPUs")."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor() or "unknown"
    model = next((line.split(":", 1)[1].strip() for line in text.splitlines()
                  if line.startswith("model name")), "unknown")  # fmt: skip
    flags = next((line.split(":", 1)[1].split() for line in text.splitlines()
                  if line.startswith("flags")), [])  # fmt: skip
    return f"{model}, {'AVX-512' if 'avx512f' in flags else 'no AVX-512'}"
