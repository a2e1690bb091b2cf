"""Progress bars for long runs: scans per second and time left, on a terminal only."""

from __future__ import annotations

from slam.particle_filter import StepRecord


class ProgressObserver:
    """A filter observer that drives a tqdm bar (a no-op when disabled)."""

    detail_every = 0
    map_every = 0

    def __init__(self, total: int, enabled: bool, label: str = "") -> None:
        self._bar = None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(
                total=total, desc=label, unit="scan", dynamic_ncols=True, mininterval=0.25
            )

    def on_step(self, record: StepRecord) -> None:
        """Advance the bar by one scan."""
        if self._bar is not None:
            self._bar.update(1)

    def on_map(self, step: int, time: float, grid: object) -> None:
        """Maps are not shown in a progress bar."""

    def close(self) -> None:
        """Finish the bar."""
        if self._bar is not None:
            self._bar.close()
