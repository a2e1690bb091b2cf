"""slam.jit: compilation is counted apart (compile_s), the bar is told, cache loads are not counted."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
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


def test_slam_warmup_prints_what_it_compiled(monkeypatch, capsys, tmp_path) -> None:
    """The command's summary line (the warm-up itself runs the demo pipeline: see the coldstart
    bench, and .ci/run, which calls it before the tests)."""
    from slam.cli import main

    seen = {}

    def fake(data_dir, progress=False):
        seen["data_dir"], seen["progress"] = data_dir, progress
        return jit.Warmup(compile_s=12.34, wall_s=20.0, kernels=["a.f", "a.g", "a.f"])

    monkeypatch.setattr(jit, "warmup", fake)
    assert main(["warmup", "--quiet", "--data-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "2 kernels compiled in 12.3 s (20.0 s in all)" in out
    assert seen == {"data_dir": tmp_path, "progress": False}

    monkeypatch.setattr(
        jit, "warmup", lambda data_dir, progress=False: jit.Warmup(3.0, 9.0, ["a.f"], background=17)
    )
    assert main(["warmup", "--quiet", "--data-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "1 kernels compiled in 3.0 s, 17 more in a background process (9.0 s in all)" in out


def test_compile_cpu_seconds_and_the_table_of_outermost_compilations() -> None:
    @njit  # no cache: compiled here
    def thrice(x):
        return 3 * x

    cpu, rows = jit.compile_cpu_seconds(), len(jit.compile_table())
    assert thrice(2) == 6
    table = jit.compile_table()[rows:]
    assert [row["kernel"].endswith("thrice") for row in table] == [True]
    assert table[0]["cpu_s"] > 0.0 and table[0]["wall_s"] >= table[0]["cpu_s"] * 0.5
    assert jit.compile_cpu_seconds() >= cpu + table[0]["cpu_s"] - 1e-3


def test_the_compile_report_is_written_at_exit(tmp_path) -> None:
    import json
    import os
    import subprocess

    report = tmp_path / "compiled.json"
    code = "from numba import njit\nimport slam.jit\nf = njit(lambda x: x + 1)\nassert f(1) == 2\n"
    env = dict(os.environ, SLAM_COMPILE_REPORT=str(report))
    subprocess.run([sys.executable, "-c", code], env=env, check=True)
    data = json.loads(report.read_text())
    assert data["compile_cpu_s"] > 0.0 and data["compile_s"] >= data["compile_cpu_s"] * 0.5
    assert len(data["outermost"]) == 1 and data["kernels_compiled"] >= 1


def test_compile_sources_writes_missing_bytecode_once_and_skips_what_it_may_not_write(tmp_path):
    """``slam warmup``'s first step: a stale or missing ``.pyc`` is written, a current one is left
    alone (0 the second time), a folder this process may not write is skipped."""
    import importlib.util
    import os

    from slam.jit import compile_sources

    package = tmp_path / "pkg"
    package.mkdir()
    (package / "a.py").write_text("X = 1\n")
    (package / "b.py").write_text("Y = 2\n")
    assert compile_sources([package]) == 2
    cached = Path(importlib.util.cache_from_source(str(package / "a.py")))
    assert cached.is_file()
    stamp = cached.stat().st_mtime_ns
    assert compile_sources([package]) == 0
    assert cached.stat().st_mtime_ns == stamp  # current: not rewritten
    assert compile_sources([tmp_path / "absent"]) == 0
    if os.geteuid() != 0:  # root may write anywhere
        locked = tmp_path / "locked"
        locked.mkdir()
        (locked / "c.py").write_text("Z = 3\n")
        locked.chmod(0o555)
        try:
            assert compile_sources([locked]) == 0
        finally:
            locked.chmod(0o755)


@pytest.mark.parametrize(
    ("given", "wait_policy", "spin"),
    [
        ({}, "PASSIVE", "10000"),  # the package's defaults
        ({"OMP_WAIT_POLICY": "ACTIVE"}, "ACTIVE", None),  # the user's policy: no spin count set
        ({"GOMP_SPINCOUNT": "5"}, "PASSIVE", "5"),  # the user's spin count kept
    ],
)
def test_openmp_threads_sleep_after_a_short_spin_unless_the_user_says_otherwise(
    given, wait_policy, spin
) -> None:
    """``import slam`` sets OpenMP's wait policy to passive with a short spin
    (``GOMP_SPINCOUNT``, docs/performance.md) before numba loads OpenMP; a user's setting of either
    wins."""
    import os
    import subprocess

    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    code = "import os, slam; print(os.environ.get('OMP_WAIT_POLICY'), os.environ.get('GOMP_SPINCOUNT'))"
    out = subprocess.run([sys.executable, "-c", code], env={**env, **given}, check=True,
                         capture_output=True, text=True).stdout.split()  # fmt: skip
    assert out == [wait_policy, str(spin)]
