"""slam.jit_background: the committed manifest is current, the main process waits for the
background compiler instead of compiling the same kernel, and the compiler is off when asked."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from numba.core import types

import slam.jit as jit
import slam.jit_background as jit_background

ROOT = Path(__file__).resolve().parent.parent
TOOL = "uv run python tools/make_jit_manifest.py"


def test_the_manifest_is_current() -> None:
    """Fails when a cached kernel was added, removed, renamed or edited (its parameters
    included) since tools/make_jit_manifest.py last wrote slam/jit_manifest.json."""
    manifest = jit_background.load_manifest()
    recorded, live = manifest["fingerprints"], jit_background.kernel_fingerprints()
    added = sorted(set(live) - set(recorded))
    removed = sorted(set(recorded) - set(live))
    changed = sorted(k for k in set(live) & set(recorded) if live[k] != recorded[k])
    stale = [f"{what}: {', '.join(names)}" for what, names in
             (("added", added), ("removed", removed), ("changed", changed)) if names]  # fmt: skip
    assert not stale, f"slam/jit_manifest.json is stale ({'; '.join(stale)}): run `{TOOL}`"
    for entry in manifest["kernels"]:
        assert entry["kernel"] in live, f"{entry['kernel']} is not a kernel: run `{TOOL}`"
        assert len(jit_background._signature(entry)) == len(entry["signature"])
    stages = {entry["stage"] for entry in manifest["kernels"]}
    assert {"filter", "finish", "texture"} <= stages
    # the smoothing's choice (rbpf.smooth_scales) scores trajectories in the stages after the
    # filter: the map-quality kernels are first needed there, not after the texture
    first = {entry["kernel"]: entry["stage"] for entry in manifest["kernels"]}
    assert first["slam.kernels.quality._classify"] == "finish"


class Point(NamedTuple):
    """A homogeneous named tuple (numba: NamedUniTuple)."""

    x: float
    y: float


def test_numba_types_round_trip_through_json() -> None:
    from slam.kernels.field import FieldView

    field_view = [types.Array(types.float32, 3, "C"), types.Array(types.int32, 2, "C")]
    field_view += [types.int64, types.float64, types.float64, types.float64]

    cases = [
        types.float64,
        types.int64,
        types.boolean,
        types.uint8,
        types.Array(types.float64, 2, "C"),
        types.Array(types.int32, 1, "A", readonly=True),
        types.UniTuple(types.int64, 3),
        types.Tuple([types.float64, types.Array(types.uint8, 3, "C")]),
        types.none,
        types.Omitted(1),
        types.BaseTuple.from_types(field_view, FieldView),
        types.BaseTuple.from_types([types.float64, types.float64], Point),
    ]
    for case in cases:
        text = json.dumps(jit_background.type_to_json(case))
        assert jit_background.type_from_json(json.loads(text)) == case
    with pytest.raises(ValueError, match="cannot record the argument type"):
        jit_background.type_to_json(types.unicode_type)


KERNELS = """
from numba import njit


@njit(cache=True)
def blend(a, b, w):
    out = a.copy()
    for i in range(a.size):
        out[i] = (1.0 - w) * a[i] + w * b[i]
    return out


@njit(cache=True)
def scale(a, w):
    return a * w
"""


def _manifest(tmp_path: Path, module: str = "bg_kernels_for_test", both: bool = False) -> Path:
    """A manifest of one kernel of ``module``, written in ``tmp_path`` (``blend``), or with
    ``both`` two (``blend``, ``scale``), in the texture stage (a module name per test: one
    imported by an earlier test would hold its kernels compiled already)."""
    (tmp_path / f"{module}.py").write_text(textwrap.dedent(KERNELS))
    array = {"array": "float64", "ndim": 1, "layout": "C", "readonly": False, "aligned": True}
    entries = [{"kernel": f"{module}.blend", "stage": "texture",
                "signature": [array, array, "float64"], "cpu_s": None}]  # fmt: skip
    if both:
        entries.append({"kernel": f"{module}.scale", "stage": "texture",
                        "signature": [array, "float64"], "cpu_s": None})  # fmt: skip
    path = tmp_path / "manifest.json"
    path.write_text(json.dumps({"kernels": entries, "fingerprints": {}}))
    return path


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """A fresh numba cache and the test module importable, here and in the child process."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), str(ROOT)]))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv(jit_background.ENV, raising=False)
    from numba.core.config import reload_config

    reload_config()
    yield tmp_path
    monkeypatch.undo()
    reload_config()
    jit_background.stop()


def test_the_main_process_waits_for_the_background_compiler(fresh_cache) -> None:
    manifest = _manifest(fresh_cache)
    started = jit_background.start(manifest)
    assert started["enabled"] and started["stages"] == ["texture"] and started["kernels"] == 1
    jit_background.reach_stage("load")  # a foreground stage: no wait
    compiler = jit_background._active["compiler"]
    deadline = time.monotonic() + 120
    while not compiler.begun and time.monotonic() < deadline:  # the child has taken the kernel:
        time.sleep(0.01)  # nothing is left for this process to compile while it waits
    assert compiler.begun == {0}
    before_s, before = jit.compile_seconds(), len(jit.compiled_kernels())
    events: list[bool] = []
    with jit.on_compile(events.append):
        jit_background.reach_stage("texture")  # the child starts Python and compiles: we wait
    report = jit_background.report()
    assert report["waited_s"]["texture"] > 0.0
    assert report["compiled"] == {"texture": 1} and report["errors"] == []
    assert events == [True, False]  # the bar says "compiling kernels" while we wait
    # waited_s is rounded to the millisecond in the report
    assert jit.compile_seconds() - before_s >= report["waited_s"]["texture"] - 5e-4

    import bg_kernels_for_test

    out = bg_kernels_for_test.blend(np.zeros(3), np.ones(3), 0.25)
    assert out.tolist() == [0.25, 0.25, 0.25]
    assert len(jit.compiled_kernels()) == before  # loaded from the cache, not compiled here
    assert bg_kernels_for_test.blend.stats.cache_hits
    assert jit_background.report()["compiled_here"] == []
    jit_background.reach_stage("texture")  # a stage is waited for once
    assert jit_background.report()["waited_s"] == report["waited_s"]

    again = jit_background.start(manifest)  # now in the cache: off
    assert again == {"enabled": False, "reason": "warm cache"}


def test_the_main_process_compiles_from_the_last_kernel_while_it_waits(fresh_cache) -> None:
    manifest = _manifest(fresh_cache, "bg_two_kernels_for_test", both=True)
    assert jit_background.start(manifest)["kernels"] == 2
    jit_background.reach_stage("texture")  # at once: the child is still starting Python
    report = jit_background.report()
    # this process took the last kernel before the child could reach it, and the child was
    # told to skip it; the first is the child's, or this process's too if the child was slower
    # (both, when the child started it as this process claimed it: the one race allowed)
    taken = report["compiled_while_waiting"]
    assert taken[0] == "bg_two_kernels_for_test.scale"
    assert report["compiled"]["texture"] + len(taken) in (2, 3)
    assert report["compiled_here"] == [] and report["errors"] == []
    import bg_two_kernels_for_test as kernels

    assert kernels.scale(np.ones(2), 3.0).tolist() == [3.0, 3.0]
    assert kernels.blend(np.zeros(2), np.ones(2), 0.5).tolist() == [0.5, 0.5]
    jit_background.stop()
    assert jit_background.start(manifest) == {"enabled": False, "reason": "warm cache"}


def test_off_with_the_environment_variable_on_one_core_or_without_manifest(
    fresh_cache, monkeypatch
) -> None:
    manifest = _manifest(fresh_cache)
    monkeypatch.setenv(jit_background.ENV, "0")
    assert jit_background.start(manifest) == {
        "enabled": False,
        "reason": "SLAM_BACKGROUND_COMPILE=0",
    }
    monkeypatch.delenv(jit_background.ENV)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    assert jit_background.start(manifest)["reason"] == "one core"
    monkeypatch.undo()
    assert jit_background.start(fresh_cache / "none.json")["reason"] == "no manifest none.json"


def test_the_child_reports_each_stage_as_json_lines(fresh_cache) -> None:
    manifest = _manifest(fresh_cache, "bg_child_kernels_for_test", both=True)
    code = "import sys; from slam.jit_background import _child; _child(sys.argv[1], sys.argv[2:])"
    proc = subprocess.run(
        [sys.executable, "-c", code, str(manifest), "texture", "quality"],
        capture_output=True, text=True, check=True, env=dict(os.environ), input="1\n",
    )  # fmt: skip
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    # kernel 1 was claimed on stdin (the main process compiles it): skipped
    assert lines[0] == {"start": 0}
    assert [line.get("stage") for line in lines[1:3]] == ["texture", "quality"]
    assert lines[1]["kernels"] == 1 and lines[2]["kernels"] == 0 and lines[1]["cpu_s"] > 0.0
    assert lines[3]["end"] is True


def _njit_kind(fn: ast.FunctionDef) -> str | None:
    """``"njit"`` for a function decorated ``@njit(...)``, ``"inline"`` with
    ``inline="always"``, else None."""
    for decorator in fn.decorator_list:
        call = decorator if isinstance(decorator, ast.Call) else None
        target = call.func if call else decorator
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name == "njit":
            keywords = call.keywords if call else []
            inline = any(k.arg == "inline" and getattr(k.value, "value", None) == "always"
                         for k in keywords)  # fmt: skip
            return "inline" if inline else "njit"
    return None


def test_no_kernel_passes_an_int_literal_to_another_kernel() -> None:
    """A kernel that calls another (not inlined) with an integer literal compiles the callee
    for ``Literal[int]``: a second machine code the foreground never asks for, and a second key
    in the callee's cache index, which the background compiler and this process then write at
    once (one write lost: ``insert_scans`` calling ``insert_serial(..., 0)`` made a run after
    ``slam warmup`` compile ``insert_serial`` again). Pass ``np.int64(...)`` instead."""
    kernels: set[str] = set()
    bodies: list[tuple[Path, ast.FunctionDef]] = []
    for path in sorted((ROOT / "slam").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and (kind := _njit_kind(node)):
                bodies.append((path, node))
                if kind == "njit":
                    kernels.add(node.name)
    assert {"insert_serial", "insert_scans", "refine"} <= kernels
    found = []
    for path, fn in bodies:
        for node in ast.walk(fn):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) in kernels:
                for arg in [*node.args, *(k.value for k in node.keywords)]:
                    if isinstance(arg, ast.Constant) and type(arg.value) is int:
                        found.append(f"{path.relative_to(ROOT)}:{node.lineno} {fn.name}")
    assert not found, f"integer literals passed to kernels (use np.int64): {found}"
