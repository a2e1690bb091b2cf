"""numba compilation: how long a process spends compiling kernels, and ``slam warmup``.

This module owns the accounting of compilation. numba compiles a kernel the first time it is
called with a new type signature, unless its machine code is in numba's cache (``cache=True``,
``__pycache__`` beside the sources or ``$NUMBA_CACHE_DIR``). On a fresh cache the first
``slam run demo`` therefore spends tens of seconds compiling inside the filter. A listener on
numba's ``numba:compile`` event (fired only for real compilations, never for cache loads) adds up
the seconds spent in outermost compilations (:func:`compile_seconds`; CPU seconds of the
compiling thread: :func:`compile_cpu_seconds`), counts the kernels (:func:`compiled_kernels`),
keeps what each outermost compilation cost (:func:`compile_table`), and tells the progress bar
when one starts and ends (:func:`on_compile`), so that ``metrics.json`` reports ``compile_s``
apart from ``estimate_wall_s`` and the bar says "compiling kernels (first run only)". With
``$SLAM_COMPILE_REPORT`` set to a file name, the process writes that table there as JSON when it
exits (the cold-start bench reads it).

:func:`warmup` (``slam warmup``) fills the cache with the kernels ``slam run demo`` uses by
running that pipeline once into a temporary folder: the very calls, so the very signatures,
whatever the kernels look like.
"""

from __future__ import annotations

import atexit
import json
import os
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

_lock = threading.Lock()
_state: dict[str, Any] = {
    "seconds": 0.0,
    "cpu_seconds": 0.0,
    "kernels": [],
    "depth": {},
    "table": [],
    "signatures": [],
    "installed": False,
    "phase": "start",
    "wait_s": 0.0,
}
_callbacks: list[Callable[[bool], None]] = []


def _kernel_name(data: dict) -> str:
    dispatcher = data.get("dispatcher")
    func = getattr(dispatcher, "py_func", None)
    if func is None:
        return str(dispatcher)
    return f"{func.__module__}.{func.__qualname__}"


def install() -> None:
    """Start counting compilations in this process (idempotent; done on import)."""
    from numba.core import event

    with _lock:
        if _state["installed"]:
            return
        _state["installed"] = True

    class _Listener(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            ident = threading.get_ident()
            with _lock:
                depth = _state["depth"].get(ident, (0, 0.0, 0.0))
                if depth[0] == 0:
                    start, cpu = time.perf_counter(), time.thread_time()
                    args = tuple(ev.data.get("args") or ())
                    _state["signatures"].append((_kernel_name(ev.data), _state["phase"], args))
                else:
                    start, cpu = depth[1], depth[2]
                _state["depth"][ident] = (depth[0] + 1, start, cpu)
                outermost = depth[0] == 0
            if outermost:
                for callback in list(_callbacks):
                    callback(True)

        def on_end(self, ev: event.Event) -> None:
            ident = threading.get_ident()
            with _lock:
                now, cpu_now = time.perf_counter(), time.thread_time()
                level, start, cpu = _state["depth"].get(ident, (1, now, cpu_now))
                _state["depth"][ident] = (level - 1, start, cpu)
                name = _kernel_name(ev.data)
                _state["kernels"].append(name)
                outermost = level == 1
                if outermost:
                    _state["seconds"] += now - start
                    _state["cpu_seconds"] += cpu_now - cpu
                    _state["table"].append((name, now - start, cpu_now - cpu))
            if outermost:
                for callback in list(_callbacks):
                    callback(False)

    event.register("numba:compile", _Listener())
    report = os.environ.get("SLAM_COMPILE_REPORT")
    if report:
        atexit.register(_write_report, Path(report))


def compile_seconds() -> float:
    """Seconds this process has spent compiling kernels (outermost compilations only), and
    waiting for the background compiler to compile kernels it needs (:func:`reach_stage`)."""
    with _lock:
        return float(_state["seconds"] + _state["wait_s"])


def add_wait(seconds: float) -> None:
    """Count ``seconds`` spent waiting for the background compiler as compilation time
    (:mod:`slam.jit_background`)."""
    with _lock:
        _state["wait_s"] += float(seconds)


def set_phase(name: str) -> None:
    """Name the pipeline stage this process is in (each outermost compilation is recorded with
    it: :func:`compiled_signatures`, what ``tools/make_jit_manifest.py`` reads)."""
    with _lock:
        _state["phase"] = name


def compiled_signatures() -> list[tuple[str, str, tuple]]:
    """Every outermost compilation so far: kernel (``module.name``), the stage it happened in
    (:func:`set_phase`) and its argument types (numba types)."""
    with _lock:
        return list(_state["signatures"])


def compile_cpu_seconds() -> float:
    """CPU seconds of the compiling threads in outermost compilations (steadier than the wall
    seconds of :func:`compile_seconds` on a loaded machine)."""
    with _lock:
        return float(_state["cpu_seconds"])


def compile_table() -> list[dict[str, Any]]:
    """Every outermost compilation so far, in order: ``kernel`` (``module.name``), ``wall_s`` and
    ``cpu_s`` (the kernel with the functions it compiled on the way)."""
    with _lock:
        return [
            {"kernel": name, "wall_s": round(wall, 3), "cpu_s": round(cpu, 3)}
            for name, wall, cpu in _state["table"]
        ]


def _write_report(path: Path) -> None:
    report = {
        "compile_s": round(compile_seconds(), 3),
        "compile_cpu_s": round(compile_cpu_seconds(), 3),
        "kernels_compiled": len(compiled_kernels()),
        "outermost": compile_table(),
    }
    path.write_text(json.dumps(report, indent=1) + "\n")


def compiled_kernels() -> list[str]:
    """Every kernel (``module.name``) compiled so far in this process, in order, callees included."""
    with _lock:
        return list(_state["kernels"])


def notify(active: bool) -> None:
    """Tell the :func:`on_compile` callbacks that compiling (or waiting for the background
    compiler) starts (``True``) or ends."""
    for callback in list(_callbacks):
        callback(active)


@contextmanager
def on_compile(callback: Callable[[bool], None]) -> Iterator[None]:
    """Call ``callback(True)`` when an outermost compilation starts and ``callback(False)`` when
    it ends, while the context is open (the progress bar's "compiling kernels")."""
    install()
    _callbacks.append(callback)
    try:
        yield
    finally:
        _callbacks.remove(callback)


@dataclass
class Warmup:
    """What :func:`warmup` compiled."""

    compile_s: float
    """Seconds spent compiling (0 when everything came from the cache)."""
    wall_s: float
    """Seconds of the whole warm-up (compilation plus the run that triggers it)."""
    kernels: list[str] = field(default_factory=list)
    """Kernels compiled (outermost and callees), in order."""
    background: int = 0
    """Kernel signatures the background compiler compiled meanwhile (:mod:`slam.jit_background`)."""
    bytecode: int = 0
    """Source files byte-compiled (:func:`compile_sources`; 0 when all were current)."""


def environment_sources() -> list[Path]:
    """The folders :func:`compile_sources` byte-compiles by default: slam's own package and, in a
    virtual environment, its ``site-packages`` (nothing outside one)."""
    import sys
    import sysconfig

    folders = [Path(__file__).resolve().parent]
    if sys.prefix != sys.base_prefix:
        folders += sorted({Path(sysconfig.get_paths()[k]) for k in ("purelib", "platlib")})
    return folders


def compile_sources(folders: list[Path] | None = None) -> int:
    """Byte-compile the ``.py`` files under ``folders`` (default :func:`environment_sources`)
    into their ``__pycache__`` folders; return how many needed it. Python writes ``.pyc`` files
    at import time only where it may (``PYTHONDONTWRITEBYTECODE`` unset, a writable folder):
    else every run compiles the ~1,500 modules it imports (numba, rerun, ...) again, ~3 s of
    each ``slam run`` on the benchmark machine. Files whose ``.pyc`` is current are left as they
    are; a folder this process may not write is skipped."""
    import compileall
    import importlib.util

    writable = [
        f for f in (environment_sources() if folders is None else folders)
        if f.is_dir() and os.access(f, os.W_OK)
    ]  # fmt: skip
    stale = 0
    for folder in writable:
        for source in folder.rglob("*.py"):
            cached = Path(importlib.util.cache_from_source(str(source)))
            if not cached.is_file() or cached.stat().st_mtime < source.stat().st_mtime:
                stale += 1
    if stale:
        for folder in writable:  # compileall's own check skips the current files
            compileall.compile_dir(folder, quiet=2, workers=0)
    return stale


def warmup(data_dir: Path, progress: bool = False) -> Warmup:
    """Byte-compile the Python sources (:func:`compile_sources`), then compile into numba's cache
    every kernel ``slam run demo`` calls, by running that pipeline
    (default configuration; texture on every 10th RGB frame; no recording) into a temporary
    folder that is removed afterwards. The demo dataset is generated first when it is not in the
    cache yet (as the first ``slam run demo`` would). Returns what was compiled and how long it
    took; later runs load the machine code from the cache.
    """
    from slam.config import load_config
    from slam.io.sources import resolve
    from slam.pipeline import RunRequest, execute

    install()
    start, compiled, before = time.perf_counter(), compile_seconds(), len(compiled_kernels())
    bytecode = compile_sources()
    ref = resolve("demo", data_dir, where="slam warmup")
    config = load_config(
        ref.config_name if ref.shipped_config else "",
        None,
        ["texture.frame_stride=10", "viz.record=false"],
    )
    with tempfile.TemporaryDirectory(prefix="slam-warmup-") as tmp:
        request = RunRequest(
            name="demo", config=config, data_dir=data_dir, out=Path(tmp) / "run", progress=progress
        )
        result = execute(request)
    background = result.metrics.get("compile_background", {})
    return Warmup(
        compile_s=compile_seconds() - compiled,
        wall_s=time.perf_counter() - start,
        kernels=compiled_kernels()[before:],
        background=sum(background.get("compiled", {}).values()),
        bytecode=bytecode,
    )


install()
