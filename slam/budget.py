"""Memory budget: refuse, before allocating, work that would need more memory than the machine has.

A run, a simulation, a grid world or a file header can ask for more memory than exists (a
``--particles`` typo, a header claiming 10¹¹ values, a 100000² grid). Allocating first fails late
(numpy's ``MemoryError`` traceback, the OOM killer, a machine swapping for minutes). Instead, each
of those computes an estimate of its largest allocations from what it was asked, and
:func:`check_memory` refuses with one line when the estimate exceeds ``share`` of the physical
memory (``os.sysconf``), or of the cgroup's limit when that is lower. The share is
``checks.max_memory_share`` of the run configuration (default :data:`DEFAULT_MEMORY_SHARE`).

Estimates count the arrays that grow with the input (per-scan, per-particle, per-cell); the fixed
overhead of the interpreter and libraries is not part of them.
"""

from __future__ import annotations

import contextlib
import contextvars
import ctypes
import ctypes.util
import functools
import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from slam.errors import UsageError

if TYPE_CHECKING:
    from slam.config import Config

DEFAULT_MEMORY_SHARE = 0.5
"""Share of the physical memory one command may plan to use (``checks.max_memory_share``)."""

_GROWTH_SHARE: contextvars.ContextVar[float] = contextvars.ContextVar(
    "growth_share", default=DEFAULT_MEMORY_SHARE
)


@contextlib.contextmanager
def growth_share(share: float) -> Iterator[None]:
    """Within the block, a map's growth is checked against ``share`` of the machine's memory
    (the run's ``checks.max_memory_share``; :func:`growth_limit_share` outside any block)."""
    token = _GROWTH_SHARE.set(float(share))
    try:
        yield
    finally:
        _GROWTH_SHARE.reset(token)


def growth_limit_share() -> float:
    """The share a map's growth is checked against here (:func:`growth_share`)."""
    return _GROWTH_SHARE.get()


_CGROUP_LIMITS = (
    Path("/sys/fs/cgroup/memory.max"),
    Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"),
)


@functools.cache
def physical_memory_bytes() -> int:
    """The machine's physical memory, or the cgroup's memory limit when that is lower (bytes).

    Read once per process: a run checks its budget at every map growth, and the files behind it
    do not change while it runs.
    """
    try:
        total = int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not POSIX: assume a small machine
        total = 4 << 30
    for path in _CGROUP_LIMITS:
        try:
            text = path.read_text().strip()
        except OSError:
            continue
        if text.isdigit() and 0 < int(text) < total:
            total = int(text)
    return total


def memory_limit(share: float = DEFAULT_MEMORY_SHARE) -> int:
    """Bytes one command may plan to use: ``share`` of :func:`physical_memory_bytes`."""
    return int(share * physical_memory_bytes())


def format_bytes(n: float) -> str:
    """``n`` bytes for people (``"1.5 GiB"``)."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} EiB"  # pragma: no cover - the loop always returns


def check_memory(
    needed: float,
    what: str,
    hint: str,
    share: float = DEFAULT_MEMORY_SHARE,
    setting: str | None = None,
    limit: int | None = None,
) -> None:
    """Refuse (:class:`~slam.errors.UsageError`) when ``needed`` bytes exceed the budget.

    ``what`` says what would need the memory (``"intel: 100000 particle maps of ..."``), ``hint``
    what to change, ``setting`` the configuration key that sets ``share`` (if any). ``limit``
    replaces :func:`memory_limit` (tests).
    """
    budget = memory_limit(share) if limit is None else limit
    if needed > budget:
        key = f", {setting}" if setting else ""
        raise UsageError(
            f"{what} would need about {format_bytes(needed)} of memory; the limit is "
            f"{format_bytes(budget)} ({share:g} of this machine's "
            f"{format_bytes(physical_memory_bytes())}{key}); {hint}"
        )


GRID_BYTES_PER_CELL = 16
"""Occupancy-grid memory per cell: the float32 log-odds, the copy ``np.pad`` makes when the grid
grows, the cropped copy and the rendered picture."""
SCAN_BYTES_PER_READING = 20
"""Per processed scan and beam: the float32 ranges (4 bytes) and, at the run's peak, the
map-quality score's rays and verdicts (about 16; more than the 8 of the float32 endpoints the
stages before it keep): a 20-minute 1081-beam log, 52 million readings, peaked at 1,262 MB."""


def run_memory(
    config: Config, scans: int, beams: int, extent_x_m: float, extent_y_m: float, reach_m: float
) -> dict[str, float]:
    """Estimated bytes of the largest allocations of a run, by component.

    ``scans`` × ``beams`` is the processed scan sequence, ``extent_*_m`` the odometry's bounding
    box and ``reach_m`` the longest obstacle range; maps cover the box plus the reach and the
    growth margin on every side (at least ``map.initial_size_m``). Components: ``scans``,
    ``occupancy grid`` and, for ``rbpf``, ``particle-map tables`` (one tile index per particle
    and tile, twice while resampling) and ``particle-map tiles`` (the shared map plus, per
    particle, the tiles one update copies) and ``vacancy grid`` (four bytes a cell of twice
    the particle maps' size, twice while it grows, when ``rbpf.vacate_after`` is set).
    """
    m = config.map
    margin = 2.0 * (reach_m + m.grow_margin_m + 1.0)
    side_x = max(extent_x_m + margin, m.initial_size_m)
    side_y = max(extent_y_m + margin, m.initial_size_m)
    cells = (side_x / m.resolution) * (side_y / m.resolution)
    out = {
        "scans": float(scans) * beams * SCAN_BYTES_PER_READING,
        "occupancy grid": cells * GRID_BYTES_PER_CELL,
    }
    if config.filter.method == "rbpf":
        rc = config.rbpf
        tile_m = rc.tile * (rc.resolution or m.resolution)
        tiles = (side_x / tile_m + 1) * (side_y / tile_m + 1)
        per_update = min(tiles, min(rc.insert_beams, beams))
        tile_bytes = 2 * 4 * rc.tile * rc.tile  # distance and surface layers, float32
        particles = config.filter.particles
        out["particle-map tables"] = 2.0 * particles * tiles * 4
        out["particle-map tiles"] = (tiles + particles * per_update) * tile_bytes
        if rc.vacate_after:
            coarse = 2.0 * (rc.resolution or m.resolution)
            out["vacancy grid"] = 8.0 * (side_x / coarse) * (side_y / coarse)  # pad copies
    return out


_HINTS = {
    "scans": "process fewer scans (filter.every, --max-scans)",
    "occupancy grid": "use a coarser map.resolution or a smaller map.initial_size_m",
    "particle-map tables": "use fewer particles (--particles) or a larger rbpf.tile",
    "particle-map tiles": "use fewer particles (--particles) or a smaller rbpf.tile",
    "vacancy grid": "use a coarser rbpf.resolution, or rbpf.vacate_after = 0",
}


def check_run_memory(name: str, components: dict[str, float], config: Config) -> None:
    """Refuse a run whose :func:`run_memory` estimate exceeds ``checks.max_memory_share``."""
    total = sum(components.values())
    largest = max(components, key=lambda k: components[k])
    parts = ", ".join(f"{k} {format_bytes(v)}" for k, v in components.items())
    check_memory(
        total,
        f"{name}: {config.filter.method} with {config.filter.particles} particles ({parts})",
        _HINTS[largest],
        share=config.checks.max_memory_share,
        setting="checks.max_memory_share",
    )


@functools.cache
def _malloc_trim() -> ctypes._CFuncPtr | None:  # type: ignore[name-defined]
    """glibc's ``malloc_trim``, or None where the C library has none (macOS, musl)."""
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None


def release_free_memory() -> bool:
    """Hand the free pages of the C heap back to the operating system (glibc's ``malloc_trim``);
    ``False`` where the C library cannot (nothing happens then).

    Memory a stage freed stays in the process's heap, counted in its resident size, until
    something trims it: after mit-killian's estimate 80 MB of the filter's and the stages' freed
    blocks, which the outputs' pictures then came on top of (docs/performance.md, "Peak memory after
    the estimate"). ``slam run`` calls it between its stages, and the final-map stage
    (:class:`slam.stages.FinalMap`) before it allocates the grid; it changes no result, and
    costs about 10 ms."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
