"""slam: robot logs in, trajectory, occupancy map and floor texture out.

The package owns the whole pipeline of the toolkit: loaders (:mod:`slam.io`), odometry,
numba kernels, the particle filter, texture mapping, the discrete (grid-world) filter, the
micromouse maze robot, the simulator, evaluation and visualisation.

Its public face is the online :class:`Slam` object and the one-call :func:`run` (docs/api.md)::

    import slam
    s = slam.Slam(slam.load_config("intel"), seed=0)
    est = s.update(slam.Scan(t, ranges, angles), odometry=pose)   # one scan at a time
    result = s.finish()                                           # trajectory, map, diagnostics

    result = slam.run("intel", seed=0, max_scans=500)             # a recorded log in one call

The names below are imported on first use (``import slam`` and ``slam --help`` stay fast: numba
and rerun load only when a filter or a recorder is made).
"""

import os as _os
from importlib import import_module as _import_module
from typing import Any as _Any

# numba's OpenMP threads spin while idle by default (libgomp: 300,000 spins, then again and
# again while the program keeps them busy); when the other cores are busy (a laptop running
# anything else, CI), every parallel region then waits milliseconds for a descheduled spinner.
# Sleeping idle threads wake in ~50 µs instead, which the filter pays at each of its ~5 parallel
# regions per update. The middle way: sleep, but after a short spin (GOMP_SPINCOUNT, about a
# millisecond here), which catches the next region of the same update (docs/performance.md, "Parallel
# regions that start at once, …": the demo's estimate at 100 particles ~0.05 s faster, intel's
# filter 4.9 → 4.2 s). Set before numba loads OpenMP; an explicit user setting of either wins.
if "OMP_WAIT_POLICY" not in _os.environ:
    _os.environ["OMP_WAIT_POLICY"] = "PASSIVE"
    _os.environ.setdefault("GOMP_SPINCOUNT", "10000")

__version__ = "0.1.0"

_EXPORTS = {
    "Slam": ("slam.online", "Slam"),
    "Estimate": ("slam.online", "Estimate"),
    "Result": ("slam.online", "Result"),
    "Scan": ("slam.scans", "Scan"),
    "Trajectory": ("slam.trajectory", "Trajectory"),
    "Config": ("slam.config", "Config"),
    "load_config": ("slam.config", "load_config"),
    "run": ("slam.pipeline", "run_dataset"),
    "Observer": ("slam.observers", "Observer"),
    "StepRecord": ("slam.observers", "StepRecord"),
    "SlamError": ("slam.errors", "SlamError"),
    "Localizer": ("slam.localize.localizer", "Localizer"),
    "LocalizationEstimate": ("slam.localize.localizer", "LocalizationEstimate"),
    "load_map": ("slam.localize.maps", "load_map"),
}

__all__ = [*_EXPORTS, "__version__"]


def __getattr__(name: str) -> _Any:
    """Import the public names of :data:`_EXPORTS` on first use."""
    try:
        module, attribute = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'slam' has no attribute {name!r}") from None
    value = getattr(_import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
