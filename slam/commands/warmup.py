"""``slam warmup``: compile the kernels of ``slam run demo`` into numba's cache, once.

First byte-compiles slam's sources and its environment's packages (where Python may not write
``.pyc`` files itself, e.g. with ``PYTHONDONTWRITEBYTECODE=1`` as in many containers, each run
would compile the modules it imports again).

Runs the demo pipeline into a temporary folder (generating the demo dataset first when it is not
cached yet) so that numba compiles every kernel a run calls and stores it in its cache
(``__pycache__`` beside the sources, or ``$NUMBA_CACHE_DIR``); later runs start at full speed.
Prints the seconds spent compiling and how many kernels were compiled (0 when the cache was
already warm). ``.ci/run`` calls it before the tests.
"""

from __future__ import annotations

import argparse

from slam.commands._common import (
    add_data_dir_argument,
    add_quiet_argument,
    data_dir_from,
    show_progress,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam warmup``."""
    add_quiet_argument(parser)
    add_data_dir_argument(parser)
    parser.set_defaults(func=run_warmup)


def run_warmup(args: argparse.Namespace) -> int:
    """Warm the cache up and print one summary line."""
    import warnings

    from slam.jit import warmup

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the demo's warnings are the run's business, not ours
        done = warmup(data_dir_from(args), progress=show_progress(args))
    names = sorted(set(done.kernels))
    more = f", {done.background} more in a background process" if done.background else ""
    sources = f"; {done.bytecode} Python files byte-compiled" if done.bytecode else ""
    print(
        f"slam warmup: {len(names)} kernels compiled in {done.compile_s:.1f} s{more} "
        f"({done.wall_s:.1f} s in all{sources}); later runs load them from numba's cache"
    )
    return 0
