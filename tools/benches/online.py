"""What the online filter costs per scan: ``slam.Slam.update`` timed call by call.

A robot that runs the filter live needs each scan processed before the next one arrives. Each
bench feeds a log into a :class:`slam.Slam` (default configuration, seed 0, the log's nominal scan
period) as ``slam run`` does — every selected scan with its synchronised odometry pose
(:class:`slam.scans.LogScans`), read before the clock starts — and times every ``update()``
call, ``map()`` after the last scan (the map so far) and the final ``finish()`` (the post-filter
stages). A first pass over the log's first :data:`WARMUP_SCANS` scans, finished too, compiles
the kernels first (a warm numba cache is what a robot runs on: ``slam warmup``), so no
compilation is in the figures.

Reported per log (milliseconds unless named): the scans and the updates among them (``rbpf``
weighs a scan only after enough motion or time: :attr:`slam.Estimate.updated`), the log's median
time between scans (``scan_period_ms``), the updates' median, 99th percentile and maximum, the
other scans' median and maximum, the mean over every scan, the filter's total (``filter_s``),
``map_s`` (``Slam.map()``, the map so far, after the last scan), ``finish_s``, and the step of the
slowest update. ``demo`` is the simulated dataset20-scale robot
(1081 beams at 40 Hz, ``slam run demo``'s log), the others the benchmark logs.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from benches._util import data_dir, skip

WARMUP_SCANS = 300
"""Scans of the warm-up pass that compiles the kernels before the timed one."""

LOGS = ("demo", "intel", "fr-clinic", "mit-killian")
"""The logs timed: the simulated robot, a small office, wide halls, a long loopy building."""


def _scans(name: str) -> tuple[list, float] | str:
    """Every selected scan of the log with its odometry pose, as ``slam run`` feeds them
    (:class:`slam.scans.LogScans`), and the log's nominal scan period; or why not."""
    import slam
    from slam.errors import DataError
    from slam.pipeline import load_source
    from slam.scans import LogScans

    config = slam.load_config(name)
    try:
        selected = LogScans.from_log(load_source(name, data_dir(), config).log, config)
    except DataError as exc:
        return str(exc)
    return list(selected), selected.scan_period()


def _replay(name: str, fed: list, period: float) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Per ``update()`` call its seconds and whether it updated, and the seconds of ``map()`` after
    the last scan and of ``finish()``."""
    import slam

    s = slam.Slam(slam.load_config(name), seed=0, scan_period=period)
    seconds = np.empty(len(fed))
    updated = np.zeros(len(fed), dtype=bool)
    for k, (scan, odometry) in enumerate(fed):
        start = time.perf_counter()
        estimate = s.update(scan, odometry=odometry)
        seconds[k] = time.perf_counter() - start
        updated[k] = estimate.updated
    start = time.perf_counter()
    s.map()
    map_s = time.perf_counter() - start
    start = time.perf_counter()
    s.finish()
    return seconds, updated, map_s, time.perf_counter() - start


def _ms(values: np.ndarray, q: float | None = None) -> float | None:
    """The median (``q`` None), a percentile or — ``q`` 100 — the maximum, in ms (None: none)."""
    if values.size == 0:
        return None
    return round(float(np.percentile(values, 50.0 if q is None else q)) * 1e3, 2)


def _bench(name: str) -> Callable[[], dict]:
    def bench() -> dict:
        loaded = _scans(name)
        if isinstance(loaded, str):
            return skip(loaded)
        fed, period = loaded
        _replay(name, fed[:WARMUP_SCANS], period)
        seconds, updated, map_s, finish_s = _replay(name, fed, period)
        times = np.array([scan.time for scan, _ in fed])
        ups, others = seconds[updated], seconds[~updated]
        return {
            "scans": len(fed),
            "updates": int(updated.sum()),
            "scan_period_ms": round(float(np.median(np.diff(times))) * 1e3, 1),
            "update_median_ms": _ms(ups),
            "update_p99_ms": _ms(ups, 99.0),
            "update_max_ms": _ms(ups, 100.0),
            "other_median_ms": _ms(others),
            "other_max_ms": _ms(others, 100.0),
            "mean_ms_per_scan": round(float(seconds.mean()) * 1e3, 3),
            "filter_s": round(float(seconds.sum()), 2),
            "map_s": round(map_s, 3),
            "finish_s": round(finish_s, 2),
            "slowest_update_step": int(np.flatnonzero(updated)[np.argmax(ups)]),
            "duration_s": round(float(times[-1] - times[0]), 1),
        }

    return bench


def benches() -> dict[str, Callable[[], dict]]:
    """One bench per log of :data:`LOGS`."""
    return {name: _bench(name) for name in LOGS}
