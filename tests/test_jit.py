"""slam.jit: compilation is counted apart (compile_s), the bar is told, cache loads are not counted."""

from __future__ import annotations

import numpy as np
from numba import njit

from slam import jit
from slam.observers import COMPILING, ProgressObserver


def test_compilations_are_counted_and_reported_to_the_callback() -> None:
    @njit  # no cache: compiled here, in the test, for each new signature
    def twice(x):
        return 2 * x

    events: list[bool] = []
    before, kernels = jit.compile_seconds(), len(jit.compiled_kernels())
    with jit.on_compile(events.append):
        assert twice(3) == 6
        assert twice(4) == 8  # same signature: no compilation
        assert twice(np.float64(1.5)) == 3.0  # a new one
    spent = jit.compile_seconds() - before
    assert events == [True, False, True, False]
    assert spent > 0.0
    names = jit.compiled_kernels()[kernels:]
    assert len(names) == 2 and all(n.endswith("twice") for n in names)
    twice(np.float32(1.0))  # after the context: counted, but the callback is gone
    assert events == [True, False, True, False]
    assert jit.compile_seconds() > before + spent


def test_the_progress_bar_says_compiling_while_numba_compiles(capsys) -> None:
    bar = ProgressObserver(10, enabled=True, label="demo rbpf")
    bar.compiling(True)
    assert bar._bar.desc == COMPILING
    bar.compiling(False)
    assert bar._bar.desc == "demo rbpf"
    bar.close()
    ProgressObserver(10, enabled=False).compiling(True)  # disabled: a no-op
