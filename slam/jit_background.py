"""Compile the later stages' kernels in a background process while the log loads and the filter runs.

On a fresh numba cache the first ``slam run`` compiles its kernels one after another, on one core.
:func:`start` (called at the beginning of :func:`slam.pipeline.execute`) starts a second Python
process that compiles, into numba's cache, the kernels the stages after the filter call (loop
closing and re-registration, texture, map quality, the outputs and recording), while this process
loads the log and compiles and runs the filter: the two cores compile at once. Which kernels, with
which argument types, and in which stage they are first called comes from ``slam/jit_manifest.json``
(written by ``tools/make_jit_manifest.py`` from a cold ``slam run demo``).

When this process reaches a stage (:func:`reach_stage`) whose kernels the background process is
still compiling, it compiles that stage's kernels itself from the last one backwards, those the
background process has not started (it tells it to skip them), until the background process,
going on from the first, reports the stage done; then it loads the background process's kernels
from the cache. At most the kernel the two meet on is compiled twice. The time counts as
compilation (:func:`slam.jit.compile_seconds`), and the progress bar says "compiling kernels
(first run only)" meanwhile. :func:`report` is what ``metrics.json`` records as
``compile_background``.

It is off with ``SLAM_BACKGROUND_COMPILE=0``, on one core, without the manifest, and when every
kernel of the manifest is already in numba's cache (a warm cache: nothing to compile). A kernel the
manifest does not list (a stale manifest, another log's types) is compiled by this process as
before; ``compiled_here`` in the report lists those compiled in the background's stages.
"""

from __future__ import annotations

import atexit
import hashlib
import importlib
import inspect
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import slam.jit as jit

MANIFEST = Path(__file__).resolve().parent / "jit_manifest.json"
"""The committed manifest: kernels, argument types and first stage of a cold ``slam run demo``."""

FOREGROUND_STAGES = ("start", "load", "filter")
"""Stages whose kernels this process compiles itself (it needs them first)."""

ENV = "SLAM_BACKGROUND_COMPILE"
"""``SLAM_BACKGROUND_COMPILE=0`` turns the background compiler off."""


# -- numba types as JSON ---------------------------------------------------------------------


def type_to_json(numba_type: Any) -> Any:
    """A numba argument type as JSON (arrays, numbers, booleans, tuples, named tuples of a
    module-level class, None, an omitted default argument of a number); ``ValueError`` for any
    other type."""
    from numba.core import types

    if isinstance(numba_type, types.Array):
        return {
            "array": str(numba_type.dtype),
            "ndim": numba_type.ndim,
            "layout": numba_type.layout,
            "readonly": not numba_type.mutable,
            "aligned": numba_type.aligned,
        }
    if isinstance(numba_type, (types.Integer, types.Float, types.Boolean, types.Complex)):
        return str(numba_type)
    if isinstance(numba_type, types.BaseNamedTuple):  # e.g. kernels.field.FieldView
        cls = numba_type.instance_class
        items = [type_to_json(t) for t in numba_type.types]
        return {"namedtuple": f"{cls.__module__}.{cls.__qualname__}", "items": items}
    if isinstance(numba_type, types.BaseTuple):
        return {"tuple": [type_to_json(t) for t in numba_type.types]}
    if isinstance(numba_type, types.NoneType):
        return "none"
    if isinstance(numba_type, types.Omitted) and isinstance(numba_type.value, (bool, int, float)):
        return {"omitted": numba_type.value}  # a default argument left out by the caller
    raise ValueError(f"slam.jit_background: cannot record the argument type {numba_type!r}")


def type_from_json(value: Any) -> Any:
    """The numba type :func:`type_to_json` wrote."""
    import numpy as np
    from numba import from_dtype
    from numba.core import types

    if value == "none":
        return types.none
    if isinstance(value, str):
        return from_dtype(np.dtype(value))
    if "omitted" in value:
        return types.Omitted(value["omitted"])
    if "namedtuple" in value:
        items = [type_from_json(v) for v in value["items"]]
        return types.BaseTuple.from_types(items, kernel(value["namedtuple"]))
    if "tuple" in value:
        return types.BaseTuple.from_types([type_from_json(v) for v in value["tuple"]])
    return types.Array(
        from_dtype(np.dtype(value["array"])),
        int(value["ndim"]),
        value["layout"],
        readonly=bool(value["readonly"]),
        aligned=bool(value["aligned"]),
    )


def kernel(name: str) -> Any:
    """The object ``module.name`` (a numba dispatcher, a named tuple class; imports its module)."""
    module, _, attr = name.rpartition(".")
    return getattr(importlib.import_module(module), attr)


def kernel_fingerprints(package: Path | None = None) -> dict[str, str]:
    """Every cached numba kernel (``@njit(cache=True)`` at module level) of the ``slam``
    package, ``module.name`` -> SHA-256 of its source text (what the manifest test compares)."""
    from numba.core.caching import NullCache
    from numba.core.registry import CPUDispatcher

    root = package or Path(__file__).resolve().parent
    found: dict[str, str] = {}
    for path in sorted(root.rglob("*.py")):
        if "njit" not in path.read_text(encoding="utf-8"):
            continue
        rel = path.relative_to(root.parent).with_suffix("")
        module = importlib.import_module(".".join(rel.parts))
        for attr, value in vars(module).items():
            if not isinstance(value, CPUDispatcher) or value.py_func.__module__ != module.__name__:
                continue
            if isinstance(value._cache, NullCache):  # not cache=True
                continue
            source = inspect.getsource(value.py_func)
            found[f"{module.__name__}.{attr}"] = hashlib.sha256(source.encode()).hexdigest()
    return dict(sorted(found.items()))


def load_manifest(path: Path = MANIFEST) -> dict[str, Any]:
    """The manifest as written by ``tools/make_jit_manifest.py``."""
    return json.loads(path.read_text())


def _signature(entry: dict[str, Any]) -> tuple:
    return tuple(type_from_json(t) for t in entry["signature"])


def _is_cached(dispatcher: Any, signature: tuple) -> bool:
    """Whether numba's cache holds machine code for ``dispatcher`` at ``signature``."""
    if tuple(signature) in dispatcher.overloads:
        return True
    try:
        cache = dispatcher._cache  # numba's FunctionCache (cache=True)
        index = cache._cache_file._load_index()
        return cache._index_key(signature, dispatcher.targetctx.codegen()) in index
    except Exception:  # noqa: BLE001 - no cache, unreadable index: not cached
        return False


# -- the background process ------------------------------------------------------------------


def _child(manifest_path: str, stages: list[str]) -> None:
    """The background process: compile the manifest's kernels of ``stages``, in that order,
    printing one JSON line when it starts a kernel (``{"start": i}``, ``i`` its position in the
    manifest), one when each stage is done and one at the end. A position read from stdin is a
    kernel the main process compiles itself (:meth:`BackgroundCompiler.wait_for`): skipped."""
    manifest = load_manifest(Path(manifest_path))
    jit.install()
    claims = _Claims(sys.stdin.fileno())
    total_start = time.perf_counter()
    for stage in stages:
        start, cpu, count = time.perf_counter(), jit.compile_cpu_seconds(), 0
        for i, entry in enumerate(manifest["kernels"]):
            if entry["stage"] != stage or i in claims.read():
                continue
            print(json.dumps({"start": i}), flush=True)
            try:
                kernel(entry["kernel"]).compile(_signature(entry))
                count += 1
            except Exception as exc:  # noqa: BLE001 - the main process compiles it itself
                print(json.dumps({"error": f"{entry['kernel']}: {exc}"[:300]}), flush=True)
        line = {
            "stage": stage,
            "kernels": count,
            "wall_s": round(time.perf_counter() - start, 3),
            "cpu_s": round(jit.compile_cpu_seconds() - cpu, 3),
        }
        print(json.dumps(line), flush=True)
    end = {"end": True, "wall_s": round(time.perf_counter() - total_start, 3)}
    end["compile_cpu_s"] = round(jit.compile_cpu_seconds(), 3)
    print(json.dumps(end), flush=True)


class _Claims:
    """The kernels the main process has claimed, as positions it writes one per line to the
    child's stdin; :meth:`read` takes in, without blocking, every line written so far."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.claimed: set[int] = set()
        self.rest = b""
        self.open = True
        try:
            os.set_blocking(fd, False)
        except OSError:  # not a pipe (a terminal, /dev/null): nothing will be claimed
            self.open = False

    def read(self) -> set[int]:
        """Every position claimed so far."""
        while self.open:
            try:
                chunk = os.read(self.fd, 4096)
            except BlockingIOError:
                break
            except OSError:
                self.open = False
                break
            if not chunk:  # the main process closed the pipe
                self.open = False
                break
            *lines, self.rest = (self.rest + chunk).split(b"\n")
            self.claimed.update(int(line) for line in lines if line.strip().isdigit())
        return self.claimed


class BackgroundCompiler:
    """The background process and what it has reported so far.

    Both processes compile a stage's kernels when this one waits for it: the child from the
    first, this process from the last (:meth:`wait_for`), so a wait lasts about half of what is
    left to compile instead of all of it.
    """

    def __init__(self, manifest_path: Path, stages: list[str], kernels: int) -> None:
        self.stages = stages
        self.kernels = kernels
        self.entries = load_manifest(manifest_path)["kernels"]
        self.started = time.perf_counter()
        self.done: dict[str, dict[str, Any]] = {}
        self.errors: list[str] = []
        self.end: dict[str, Any] | None = None
        self.waited: dict[str, float] = {}
        self.begun: set[int] = set()
        """Manifest positions the child has started compiling."""
        self.taken: list[str] = []
        """Kernels this process compiled itself while it waited (:meth:`wait_for`)."""
        self._claimed: set[int] = set()
        self._cond = threading.Condition()
        code = (
            "import sys; from slam.jit_background import _child; _child(sys.argv[1], sys.argv[2:])"
        )
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code, str(manifest_path), *stages],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            stdin=subprocess.PIPE,
            text=True,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        atexit.register(self.stop)

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for raw in self.proc.stdout:
            try:
                line = json.loads(raw)
            except ValueError:
                continue
            with self._cond:
                if "start" in line:
                    self.begun.add(int(line["start"]))
                elif "stage" in line:
                    self.done[line["stage"]] = line
                elif "error" in line:
                    self.errors.append(line["error"])
                elif line.get("end"):
                    self.end = line
                self._cond.notify_all()
        self.proc.wait()
        with self._cond:
            if self.end is None:
                self.end = {"end": True, "exit_code": self.proc.returncode}
            self._cond.notify_all()

    def _claim(self, stage: str) -> int | None:
        """The last kernel of ``stage`` that neither process has started, now this process's
        (the child is told to skip it); None when there is none. Called holding the lock."""
        for i in range(len(self.entries) - 1, -1, -1):
            if self.entries[i]["stage"] != stage or i in self.begun or i in self._claimed:
                continue
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.write(f"{i}\n")
                self.proc.stdin.flush()
            except (OSError, ValueError):  # the child has ended: nothing left to share
                return None
            self._claimed.add(i)
            return i
        return None

    def wait_for(self, stage: str) -> float:
        """Block until ``stage``'s kernels are compiled (or the child ended); return the seconds
        spent idle (this process's own compiling counts by itself, :mod:`slam.jit`).

        Meanwhile this process compiles the stage's kernels from the last backwards, each one
        the child has not started (and is told to skip). The two meet in the middle; at worst
        one kernel is compiled by both, the same machine code written twice to numba's cache.
        """
        if stage not in self.stages:
            return 0.0
        start, compiling = time.perf_counter(), 0.0
        while True:
            with self._cond:
                if stage in self.done or self.end is not None:
                    break
                claimed = self._claim(stage)
                if claimed is None:
                    self._cond.wait()
                    continue
            entry, began = self.entries[claimed], time.perf_counter()
            try:
                kernel(entry["kernel"]).compile(_signature(entry))
                self.taken.append(entry["kernel"])
            except Exception:  # noqa: BLE001 - compiled at its first call instead
                pass
            compiling += time.perf_counter() - began
        waited = time.perf_counter() - start - compiling
        self.waited[stage] = round(waited, 3)
        return waited

    def stop(self) -> None:
        """End the background process if it still runs (the run failed or ended early)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait()

    def report(self) -> dict[str, Any]:
        """What happened, for ``metrics.json``."""
        with self._cond:
            return {
                "enabled": True,
                "stages": list(self.stages),
                "kernels": self.kernels,
                "compiled": {name: line["kernels"] for name, line in self.done.items()},
                "compiled_while_waiting": list(self.taken),
                "compile_cpu_s": (self.end or {}).get("compile_cpu_s"),
                "wall_s": (self.end or {}).get("wall_s"),
                "waited_s": dict(self.waited),
                "errors": list(self.errors),
            }


_active: dict[str, Any] = {"compiler": None, "reason": "not started", "mark": 0}


def _off(reason: str) -> dict[str, Any]:
    _active.update(compiler=None, reason=reason)
    return report()


def start(manifest_path: Path = MANIFEST) -> dict[str, Any]:
    """Start the background compiler unless it is off (see the module's docstring); return
    :func:`report`."""
    stop()
    _active["mark"] = len(jit.compiled_signatures())
    if os.environ.get(ENV, "1").strip() == "0":
        return _off(f"{ENV}=0")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if (cores or 1) < 2:
        return _off("one core")
    if not manifest_path.is_file():
        return _off(f"no manifest {manifest_path.name}")
    manifest = load_manifest(manifest_path)
    todo: list[str] = []
    kernels = 0
    for entry in manifest["kernels"]:
        if entry["stage"] in FOREGROUND_STAGES:
            continue
        try:
            cached = _is_cached(kernel(entry["kernel"]), _signature(entry))
        except Exception:  # noqa: BLE001 - a kernel gone or renamed: the child reports it
            cached = False
        if not cached:
            kernels += 1
            if entry["stage"] not in todo:
                todo.append(entry["stage"])
    if not todo:
        return _off("warm cache")
    _active.update(compiler=BackgroundCompiler(manifest_path, todo, kernels), reason="")
    return report()


def reach_stage(stage: str) -> None:
    """This process enters ``stage``: name it for the compile records (:func:`slam.jit.set_phase`)
    and wait for the background compiler to finish that stage's kernels (the wait counts as
    compilation, and the progress bar says so)."""
    jit.set_phase(stage)
    compiler = _active["compiler"]
    if compiler is None or stage not in compiler.stages or stage in compiler.waited:
        return
    jit.notify(True)
    try:
        jit.add_wait(compiler.wait_for(stage))
    finally:
        jit.notify(False)


def stop() -> None:
    """End a background compiler that still runs."""
    compiler = _active["compiler"]
    if compiler is not None:
        compiler.stop()


def report() -> dict[str, Any]:
    """``compile_background`` of ``metrics.json``: ``enabled``; when off, ``reason``; when on,
    the stages and kernels given to the background process, what it compiled per stage, the
    kernels this process took while it waited (``compiled_while_waiting``), its CPU and wall
    seconds, the seconds this process waited idle per stage, and ``compiled_here``: kernels this
    process still compiled itself in those stages at their first call (the manifest did not
    list them)."""
    compiler = _active["compiler"]
    if compiler is None:
        return {"enabled": False, "reason": _active["reason"]}
    since = jit.compiled_signatures()[_active["mark"] :]
    taken = set(compiler.taken)
    here = sorted(
        {name for name, phase, _ in since if phase in compiler.stages and name not in taken}
    )
    return {**compiler.report(), "compiled_here": here}
