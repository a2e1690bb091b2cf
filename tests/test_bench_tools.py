"""The benches' own bookkeeping: the sweep folder of ``tools/bench.py slam`` keyed by the code."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parent.parent / "tools"


@pytest.fixture(scope="module")
def bench_slam():
    sys.path.insert(0, str(TOOLS))
    try:
        import benches.slam as module

        yield module
    finally:
        sys.path.remove(str(TOOLS))
        for name in [m for m in sys.modules if m == "benches" or m.startswith("benches.")]:
            del sys.modules[name]


HOST = "AMD EPYC, no AVX-512"


def make_tree(root: Path) -> None:
    (root / "slam" / "kernels" / "__pycache__").mkdir(parents=True)
    (root / "configs").mkdir()
    (root / "slam" / "graph.py").write_text("CAP = 300\n")
    (root / "slam" / "kernels" / "field.py").write_text("def f(): ...\n")
    (root / "configs" / "intel.toml").write_text("[lidar]\n")
    (root / "uv.lock").write_text("numpy 2.3\n")
    (root / "pyproject.toml").write_text("[project]\n")


def test_the_sweep_folder_changes_with_the_code_and_only_with_it(bench_slam, tmp_path):
    make_tree(tmp_path)
    key = bench_slam.code_key(tmp_path, host=HOST)
    assert len(key) == 12 and int(key, 16) >= 0
    assert bench_slam.code_key(tmp_path, host=HOST) == key  # the same files, the same folder
    # compiled kernels, run folders and notes are not the code
    (tmp_path / "slam" / "kernels" / "__pycache__" / "field.f-1.py311.nbi").write_bytes(b"\0")
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "metrics.json").write_text("{}")
    (tmp_path / "NOTES.md").write_text("a note")
    assert bench_slam.code_key(tmp_path, host=HOST) == key
    changed = []
    for path, text in [
        ("slam/graph.py", "CAP = 10000\n"),
        ("configs/intel.toml", "[lidar]\nx = 0.1\n"),
        ("uv.lock", "numpy 2.4\n"),
    ]:
        before = (tmp_path / path).read_text()
        (tmp_path / path).write_text(text)
        changed.append(bench_slam.code_key(tmp_path, host=HOST))
        (tmp_path / path).write_text(before)
    changed.append(bench_slam.code_key(tmp_path, host="another CPU, AVX-512"))
    changed.append(bench_slam.code_key(tmp_path, ("--set", "rbpf.particles=60"), host=HOST))
    assert len({key, *changed}) == 6
    assert bench_slam.code_key(tmp_path, host=HOST) == key
    # a file moved is other code, even with the same bytes
    (tmp_path / "slam" / "graph.py").rename(tmp_path / "slam" / "graph2.py")
    assert bench_slam.code_key(tmp_path, host=HOST) != key


def test_the_repository_has_a_key_of_this_host(bench_slam):
    from benches._util import cpu_model

    assert bench_slam.code_key() == bench_slam.code_key(host=cpu_model())
    assert bench_slam.code_key() != bench_slam.code_key(TOOLS)  # tools/ alone holds no package
