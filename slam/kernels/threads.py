"""Serial ``nogil`` kernels run side by side on Python threads: :func:`in_threads`.

numba's ``parallel=True`` compiles a loop into a parallel gufunc, which costs seconds on a fresh
cache (the parfors passes and the gufunc's own compilation). For kernels that run once per run
(the map-quality score, the texture's coverage), a serial kernel declared ``nogil`` called on a
few Python threads is as fast and compiles in a fraction of the time. The caller fixes which
call computes what, so results never depend on the number of threads.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numba

_POOL: dict[int, ThreadPoolExecutor] = {}
"""The pool of each thread count asked for so far (one, unless ``numba.set_num_threads`` changes)."""


def threads() -> int:
    """The threads to use: numba's (``NUMBA_NUM_THREADS``, or :func:`numba.set_num_threads`)."""
    return max(1, int(numba.get_num_threads()))


def in_threads(calls: list[Callable[[], Any]]) -> list[Any]:
    """The results of ``calls``, in order, computed on up to :func:`threads` threads (in this
    thread when there is one call or one thread)."""
    if len(calls) <= 1 or threads() == 1:
        return [call() for call in calls]
    n = threads()
    pool = _POOL.get(n)
    if pool is None:
        pool = _POOL[n] = ThreadPoolExecutor(max_workers=n, thread_name_prefix="slam-kernels")
    return list(pool.map(lambda call: call(), calls))
