"""slam.budget.release_free_memory: freed heap pages go back to the operating system."""

from __future__ import annotations

import ctypes.util
import os
import sys

import numpy as np
import pytest

from slam.budget import release_free_memory


def _resident_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or ctypes.util.find_library("c") is None,
    reason="malloc_trim is glibc's (Linux)",
)
def test_freed_heap_blocks_leave_the_resident_size():
    """64 KB blocks (below glibc's mmap threshold: they live in the heap), nine of ten freed
    with every tenth kept, so the heap cannot shrink from its top: the freed 90 % stays
    resident until the trim returns it."""
    blocks = [np.ones(8192) for _ in range(2000)]  # 2000 × 64 KB = 125 MB, pages touched
    kept = blocks[::10]
    del blocks
    before = _resident_mb()
    assert release_free_memory()
    after = _resident_mb()
    assert before - after > 60.0, (before, after)  # of the 112 MB freed
    assert all(float(b.sum()) == 8192.0 for b in kept)  # what is still used is untouched
