"""Where the cells of a sweep run: a local process pool, or a Ray cluster.

Both take the tasks of :func:`slam.sweep.cell.run_cell` and hand each result to the driver's
callback, in the driver's main thread, as it arrives (so the driver alone writes results).

* :class:`LocalExecutor` — one worker process per cell (``python -m slam.sweep.cell``: a fresh
  process, so a crash, a leak or the peak memory of one cell is its own), at most ``workers`` at
  once (default: the usable cores), each with ``NUMBA_NUM_THREADS`` = cores // workers (and the
  BLAS pools at 1) so the pool does not oversubscribe the machine. The worker writes the run
  folder itself, through ``slam run``'s atomic run folder. A worker killed by a signal or exiting
  without a result is that cell's error, not the sweep's. Ctrl-C (or SIGTERM) is forwarded to the
  running workers, which remove their partial folders; the interrupt is then re-raised.
* :class:`RayExecutor` — each cell a Ray task (1 CPU, ``NUMBA_NUM_THREADS=1``; Ray reuses its
  worker processes, so a cell's ``peak_rss_mb`` is its worker's peak so far; a cell is retried
  up to :data:`RAY_RETRIES` times when its worker dies). The
  task runs the cell into a temporary folder on its node and returns the folder's files; the
  driver writes them into the sweep folder (the data directory must be the same path on every
  node: shared storage). ``ray.init(include_dashboard=False)`` locally (on 127.0.0.1), or
  ``address=HOST:PORT`` for an existing cluster.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from slam.errors import UsageError

Task = dict[str, Any]
Result = dict[str, Any]
OnResult = Callable[[Task, Result], None]

RAY_RETRIES = 3
"""How often Ray re-runs a cell whose worker process died."""

LOOPBACK_ONLY = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
"""Set to ``0``, Ray takes 127.0.0.1 as the node's address (else the first interface's)."""

NO_UV_RUN_HOOK = "RAY_ENABLE_UV_RUN_RUNTIME_ENV"
"""Set to ``0``, Ray's workers use the cluster's Python, not ``uv run`` in a copy of the cwd."""

THREAD_POOLS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""BLAS/OpenMP pools set to one thread in the workers (numba's is set by the executor)."""


def usable_cores() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def worker_environment(numba_threads: int, data_dir: Path) -> dict[str, str]:
    """The environment variables a worker gets on top of the driver's."""
    env = {"NUMBA_NUM_THREADS": str(numba_threads), "SLAM_DATA_DIR": str(data_dir)}
    env.update({name: "1" for name in THREAD_POOLS})
    env.update(RERUN_ANALYTICS="0", RUST_LOG=os.environ.get("RUST_LOG", "off"))
    return env


def _exit_reason(code: int) -> str:
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exited with code {code}"


def _last_line(path: Path) -> str:
    try:
        lines = [x for x in path.read_text(errors="replace").splitlines() if x.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""


class LocalExecutor:
    """Cells as local worker processes (see the module docstring)."""

    def __init__(self, workers: int | None, data_dir: Path, log_dir: Path) -> None:
        cores = usable_cores()
        self.workers = workers or cores
        self.numba_threads = max(1, cores // self.workers)
        self.data_dir = Path(data_dir)
        self.log_dir = Path(log_dir)
        self._running: dict[int, subprocess.Popen] = {}
        self._lock = threading.Lock()
        self._stopping = False

    def describe(self) -> str:
        """One line for the sweep's header."""
        return f"local pool: {self.workers} worker(s), NUMBA_NUM_THREADS={self.numba_threads}"

    def _one(self, task: Task) -> Result | None:
        if self._stopping:
            return None
        env = dict(os.environ, **worker_environment(self.numba_threads, self.data_dir))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log = self.log_dir / f"{task['cell']}.log"
        with open(log, "ab") as err:
            with self._lock:
                if self._stopping:
                    return None
                proc = subprocess.Popen(
                    [sys.executable, "-m", "slam.sweep.cell"],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=err,
                    env=env,
                    start_new_session=True,  # Ctrl-C reaches it once, forwarded by the driver
                )
                self._running[proc.pid] = proc
            try:
                out, _ = proc.communicate(json.dumps(task).encode())
            finally:
                with self._lock:
                    self._running.pop(proc.pid, None)
        if self._stopping:
            return None
        lines = out.decode(errors="replace").strip().splitlines()
        if proc.returncode == 0 and lines:
            try:
                return json.loads(lines[-1])
            except ValueError:
                pass
        last = _last_line(log)
        return {
            "cell": task["cell"],
            "status": "error",
            "stage": "worker",
            "error": f"worker process {_exit_reason(proc.returncode)} (log {log}"
            + (f"; last line: {last}" if last else "")
            + ")",
        }

    def _stop(self, signum: int) -> None:
        with self._lock:
            self._stopping = True
            running = list(self._running.values())
        for proc in running:
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signum)
        for proc in running:
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()

    def run(self, tasks: list[Task], on_result: OnResult) -> None:
        """Run ``tasks``, ``on_result`` for each in the calling thread as it finishes."""
        if not tasks:
            return
        pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="slam-sweep")
        futures = {pool.submit(self._one, task): task for task in tasks}
        try:
            for future in as_completed(futures):
                result = future.result()
                if result is not None:
                    on_result(futures[future], result)
        except KeyboardInterrupt as exc:
            self._stop(int(getattr(exc, "signum", signal.SIGINT)))
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        pool.shutdown(wait=True)


def _read_files(folder: Path) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    for root, _dirs, names in os.walk(folder):
        for name in names:
            path = Path(root) / name
            if not path.is_symlink():
                files[str(path.relative_to(folder))] = path.read_bytes()
    return files


def ray_cell(task: Task) -> dict[str, Any]:
    """The Ray task: run the cell into a temporary folder on this node, return the result and
    the folder's files (``{"result": ..., "files": {relative path: bytes}}``)."""
    from slam.sweep.cell import run_cell

    tmp = Path(tempfile.mkdtemp(prefix="slam-sweep-"))
    try:
        folder = tmp / task["cell"]
        result = run_cell(dict(task, out=str(folder)))
        files = _read_files(folder) if folder.is_dir() else {}
        return {"result": result, "files": files}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def import_ray() -> Any:
    """The ``ray`` module, or a one-line error saying how to install it."""
    try:
        import ray
    except ImportError:
        raise UsageError(
            "--executor ray: Ray is not installed (uv sync --extra ray, or pip install 'slam[ray]')"
        ) from None
    return ray


def ray_endpoint(address: str, where: str) -> tuple[str, int] | None:
    """``(host, port)`` of a Ray cluster's ``address`` (``HOST:PORT``, ``ray://HOST:PORT``, an
    IPv6 host in brackets), ``None`` for ``auto`` and ``local`` (Ray finds, or starts, the
    cluster itself); anything else is one :class:`UsageError` naming ``where``."""
    if not isinstance(address, str):
        raise UsageError(f"{where}: expected HOST:PORT of a Ray cluster, found {address!r}")
    if address in ("auto", "local"):
        return None
    text = address.removeprefix("ray://")
    match = re.fullmatch(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})", text)
    if match is None or not 1 <= int(match[2]) <= 65535:
        raise UsageError(
            f"{where}: expected HOST:PORT of a Ray cluster (e.g. 127.0.0.1:6379, auto or local), "
            f"found {address!r}"
        )
    return match[1].strip("[]"), int(match[2])


def probe_ray_address(address: str, where: str, timeout: float = 5.0) -> None:
    """Refuse, with one :class:`UsageError`, a Ray ``address`` that no server answers at within
    ``timeout`` seconds: checked before the sweep folder is made (``ray.init`` itself would
    retry for minutes)."""
    endpoint = ray_endpoint(address, where)
    if endpoint is None:
        return
    try:
        with socket.create_connection(endpoint, timeout=timeout):
            pass
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise UsageError(f"{where} {address}: no Ray cluster answers there ({reason})") from None


class RayExecutor:
    """Cells as Ray tasks (see the module docstring)."""

    def __init__(self, workers: int | None, data_dir: Path, address: str | None) -> None:
        if address is None:  # a local instance: every Ray address on loopback (read at import)
            os.environ.setdefault(LOOPBACK_ONLY, "0")
        # Under `uv run`, Ray would start its workers with `uv run` in an uploaded copy of the
        # current folder (a new environment per job); the cells use the installed slam.
        os.environ.setdefault(NO_UV_RUN_HOOK, "0")
        self.ray = import_ray()
        self.workers = workers
        self.data_dir = Path(data_dir)
        self.address = address

    def describe(self) -> str:
        """One line for the sweep's header."""
        where = self.address or "a local Ray instance on 127.0.0.1"
        return f"ray: {where}, 1 CPU and NUMBA_NUM_THREADS=1 per cell"

    def _init(self) -> None:
        ray = self.ray
        options: dict[str, Any] = {
            "include_dashboard": False,
            "log_to_driver": False,
            "configure_logging": False,
            "runtime_env": {"env_vars": worker_environment(1, self.data_dir)},
        }
        if self.address is not None:
            options["address"] = self.address
        else:
            options["_node_ip_address"] = "127.0.0.1"
            if self.workers is not None:
                options["num_cpus"] = self.workers
        try:
            ray.init(**options)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            if self.address is None:  # no address given: Ray's own start failed
                raise UsageError(
                    f"--executor ray: cannot start a local Ray instance ({first})"
                ) from None
            raise UsageError(
                f"--address {self.address}: cannot reach a Ray cluster ({first})"
            ) from None

    def run(self, tasks: list[Task], on_result: OnResult) -> None:
        """Run ``tasks`` on the cluster, ``on_result`` for each as it finishes (with ``files``)."""
        if not tasks:
            return
        ray = self.ray
        self._init()
        try:
            remote = ray.remote(num_cpus=1, max_retries=RAY_RETRIES)(ray_cell)
            pending = {remote.remote(task): task for task in tasks}
            try:
                while pending:
                    done, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
                    for ref in done:
                        task = pending.pop(ref)
                        try:
                            payload = ray.get(ref)
                        except ray.exceptions.RayError as exc:
                            first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
                            payload = {
                                "result": {
                                    "cell": task["cell"],
                                    "status": "error",
                                    "stage": "worker",
                                    "error": f"Ray task failed after {RAY_RETRIES} retries: "
                                    f"{type(exc).__name__}: {first}",
                                },
                                "files": {},
                            }
                        on_result(task, dict(payload["result"], files=payload["files"]))
            except KeyboardInterrupt:
                for ref in pending:
                    ray.cancel(ref, force=True)
                raise
        finally:
            ray.shutdown()
