"""slam.kernels.threads: serial nogil kernels side by side on Python threads."""

from __future__ import annotations

import threading
import time

import numba
import pytest

from slam.kernels.threads import in_threads, threads


def test_results_come_in_the_order_of_the_calls_whatever_finishes_first():
    def call(i: int):
        return lambda: (time.sleep(0.02 * (5 - i)), i * i)[1]

    assert in_threads([call(i) for i in range(5)]) == [0, 1, 4, 9, 16]


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one core: no second thread")
def test_calls_run_side_by_side_on_numba_s_thread_count_and_in_this_thread_on_one():
    barrier = threading.Barrier(2, timeout=10)  # both calls must be running at once to pass it

    def meet() -> str:
        barrier.wait()
        return threading.current_thread().name

    numba.set_num_threads(2)
    names = in_threads([meet, meet])
    assert len(set(names)) == 2 and all(n.startswith("slam-kernels") for n in names)
    numba.set_num_threads(1)
    try:
        assert threads() == 1
        assert (
            in_threads([lambda: threading.current_thread().name] * 3)
            == [threading.current_thread().name] * 3
        )
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
