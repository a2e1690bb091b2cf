"""Observers of a running filter: what they receive, the progress bar, and a composite.

An :class:`Observer` attached to a :class:`slam.online.Slam` receives a :class:`StepRecord` after
every processed scan, detailed ones (particles, scan endpoints) every ``detail_every`` steps, and
the current map every ``map_every`` steps. The progress bar is one; the rerun recorder
(:class:`slam.viz.recorder.RunRecorder`) is another; a test can be a third.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from slam.mapping import OccupancyGrid

F64 = NDArray[np.float64]


@dataclass
class StepRecord:
    """What an observer sees after each processed scan."""

    step: int
    """Number of the processed scan (0-based)."""
    scan_index: int
    """Index of the scan in the log."""
    time: float
    """Scan time (s)."""
    pose: F64
    """Current estimate: the pose of the highest-weight particle."""
    n_eff: float
    """Effective sample size after weighting."""
    max_weight: float
    """Largest normalised weight."""
    updated: bool
    """Whether the filter ran an update on this scan (``rbpf`` skips scans between updates)."""
    resampled: bool
    """Whether the particles were resampled on this scan."""
    particles: F64 | None = None
    """``(P, 3)`` particle poses (only on detail steps)."""
    weights: F64 | None = None
    """``(P,)`` normalised weights (only on detail steps)."""
    endpoints: F64 | None = None
    """``(K, 2)`` world positions of the scan's returns from ``pose`` (only on detail steps)."""


class Observer(Protocol):
    """Receives the filter's progress: progress bars, the rerun recorder, tests.

    An observer may also define ``on_filter_end()``, called once when the filter has seen its
    last scan, before the stages after it run (:meth:`slam.online.Slam.finish`): the place to
    let go of what only the filter's steps needed (the recorder's preview map).
    """

    detail_every: int
    """Steps between records carrying particles and endpoints (0: never)."""
    map_every: int
    """Steps between map snapshots (0: never)."""

    def on_step(self, record: StepRecord) -> None:
        """Called after every processed scan."""

    def on_map(self, step: int, time: float, grid: OccupancyGrid) -> None:
        """Called every ``map_every`` steps (on filter updates) with the current map."""


COMPILING = "compiling kernels (first run only)"
"""The progress bar's label while numba compiles kernels (``slam warmup`` does it ahead)."""


class ProgressObserver:
    """A tqdm bar with scans per second and the time left (a no-op when disabled)."""

    detail_every = 0
    map_every = 0

    def __init__(self, total: int | None, enabled: bool, label: str = "") -> None:
        self._bar = None
        self._label = label
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(
                total=total, desc=label, unit="scan", dynamic_ncols=True, mininterval=0.25
            )

    def on_step(self, record: StepRecord) -> None:
        """Advance the bar by one scan."""
        if self._bar is not None:
            self._bar.update(1)

    def on_map(self, step: int, time: float, grid: OccupancyGrid) -> None:
        """Maps are not shown in a progress bar."""

    def compiling(self, active: bool) -> None:
        """Say "compiling kernels (first run only)" while numba compiles (:func:`slam.jit.on_compile`),
        and the run's label again afterwards."""
        if self._bar is not None:
            self._bar.set_description_str(COMPILING if active else self._label, refresh=True)

    def close(self) -> None:
        """Finish the bar."""
        if self._bar is not None:
            self._bar.close()


def _gcd_cadence(values: Sequence[int]) -> int:
    active = [v for v in values if v > 0]
    if not active:
        return 0
    out = active[0]
    for v in active[1:]:
        out = math.gcd(out, v)
    return out


class CompositeObserver:
    """Feeds every step to several observers, each at its own cadence."""

    def __init__(self, observers: Sequence[Observer]) -> None:
        self.observers = list(observers)
        self.detail_every = _gcd_cadence([o.detail_every for o in self.observers])
        self.map_every = _gcd_cadence([o.map_every for o in self.observers])

    def on_step(self, record: StepRecord) -> None:
        """Pass the record on; detail fields only to observers whose cadence asks for them."""
        for observer in self.observers:
            if record.particles is not None and not (
                observer.detail_every and record.step % observer.detail_every == 0
            ):
                light = StepRecord(**{**record.__dict__, "particles": None, "weights": None})
                light.endpoints = None
                observer.on_step(light)
            else:
                observer.on_step(record)

    def on_map(self, step: int, time: float, grid: OccupancyGrid) -> None:
        """Pass the map to observers whose map cadence divides ``step``."""
        for observer in self.observers:
            if observer.map_every and step % observer.map_every == 0:
                observer.on_map(step, time, grid)

    def on_filter_end(self) -> None:
        """Tell the observers that define ``on_filter_end`` that the filter has ended."""
        for observer in self.observers:
            end = getattr(observer, "on_filter_end", None)
            if end is not None:
                end()
