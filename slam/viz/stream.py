"""Recording streams, the viewer process, and reading recordings back.

* :func:`open_stream` makes a dedicated :class:`rerun.RecordingStream` (never the global one, so
  runs and tests are isolated) writing to a file and/or streaming to a viewer, with the
  wall-clock ``log_time`` timeline disabled (recordings of the same inputs are then identical,
  which the golden-recording test relies on);
* :func:`set_time` sets the two timelines of every recording: ``scan`` (a sequence) and ``time``
  (the log's timestamps: absolute when they look like Unix seconds, else a duration);
* :func:`spawn_viewer` starts a native viewer listening on 127.0.0.1 only and returns the URL to
  stream to; :func:`viewer_command` is the command line of ``slam view`` (whose web viewer
  fetches the recording from :mod:`slam.viz.webserve`);
* :func:`summarize` reads a recording back with :class:`rerun.chunk.RrdReader`: entities, their
  timelines, row counts and archetype fields (what the tests check).

Rerun's servers bind every interface unless told otherwise: every command built here passes
``--bind 127.0.0.1``. Usage analytics are turned off for every viewer process started here.
"""

from __future__ import annotations

import ctypes
import os
import signal
import socket
import subprocess
import sys
import time
import uuid
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from slam.errors import DataError, UsageError

APPLICATION_ID = "slam"
"""Application id of every recording (the viewer groups recordings by it)."""

LOOPBACK = "127.0.0.1"
"""The only address a viewer or web server started by slam listens on."""

UNIX_SECONDS = 1e8
"""Log times above this (1973) are Unix timestamps; smaller ones are durations from a start."""


def open_stream(
    path: Path | None,
    *,
    name: str,
    viewer_url: str | None = None,
    recording_id: str | None = None,
    blueprint: rr.blueprint.BlueprintLike | None = None,
    batcher_config: rr.ChunkBatcherConfig | None = None,
) -> rr.RecordingStream:
    """A new recording stream writing to ``path`` and/or streaming to ``viewer_url``.

    ``recording_id`` defaults to a fresh UUID; pass a fixed one for reproducible files.
    ``blueprint`` is sent as the default layout. ``batcher_config`` sets how rerun groups logged
    rows into chunks (default: by time and size; ``NEVER`` makes the chunks, and so the file,
    independent of timing).
    """
    rec = rr.RecordingStream(
        APPLICATION_ID,
        recording_id=recording_id or str(uuid.uuid4()),
        send_properties=False,
        batcher_config=batcher_config,
    )
    rec.set_log_time_enabled(False)
    sinks: list = []
    if path is not None:
        sinks.append(rr.FileSink(str(path)))
    if viewer_url is not None:
        sinks.append(rr.GrpcSink(url=viewer_url))
    if not sinks:
        raise ValueError("open_stream: give a file path, a viewer URL or both")
    rec.set_sinks(*sinks, default_blueprint=blueprint)
    rec.send_recording_name(name)
    return rec


def check_recording_path(path: Path) -> Path:
    """``path`` if a recording can be written there (a ``.rrd`` name, not a folder, in an
    existing folder)."""
    path = Path(path)
    if path.suffix != ".rrd":
        raise UsageError(f"--record {path}: expected a file name ending in .rrd")
    if path.is_dir():
        raise UsageError(f"--record {path}: expected a file name, found a folder")
    if not path.parent.exists():
        raise UsageError(f"--record {path}: folder {path.parent} does not exist")
    if not path.parent.is_dir():
        raise UsageError(f"--record {path}: {path.parent} is a file, not a folder")
    return path


def close_stream(rec: rr.RecordingStream, path: Path | None = None) -> None:
    """Flush everything logged and close the stream's file and connections.

    Rerun writes files on a thread of its own and reports a failed write (a full disk) only
    here, as a ``RuntimeError``: it becomes an :class:`OSError` naming ``path`` (``ENOSPC`` when
    its file system is full, else ``EIO``), which the CLI prints as one line. The stream is
    then disconnected as :func:`disconnect` does (never waiting for ever).
    """
    try:
        rec.flush()
    except RuntimeError as exc:
        disconnect(rec, raising=False)  # the write's failure is the news, not the disconnect's
        if path is None:
            raise
        raise _write_error(Path(path), exc) from None
    try:
        disconnect(rec)
    except RuntimeError as exc:
        if path is None:
            raise
        raise _write_error(Path(path), exc) from None


DISCONNECT_WAIT_S = 5.0
"""Longest wait for rerun to close a stream (:func:`disconnect`)."""

_WEDGED: list[rr.RecordingStream] = []
"""Streams whose ``disconnect`` never returned (kept: dropping one blocks the same way)."""


def disconnect(rec: rr.RecordingStream, wait: float | None = None, raising: bool = True) -> bool:
    """``rec.disconnect()``, waiting at most ``wait`` seconds (default
    :data:`DISCONNECT_WAIT_S`); ``False`` when it did not return.

    rerun 0.41 can block for ever in ``disconnect`` once its file writer has stopped on a failed
    write: on a full 64 KiB file system 2 of 15 trials of a bare stream blocked, and so did a
    ``slam run`` in two of three CI runs (at the interpreter's exit, then in the disconnect after
    the failure). The call runs on a daemon thread; a stream that does not come back is kept
    in a list (its drop would block the same way) and :func:`wedged` says so, for
    :func:`slam.cli.entry` to end the process without the interpreter's clean-up. ``raising``:
    re-raise the ``RuntimeError`` the disconnect reported (else ignore it, for a stream whose
    failure is already known).
    """
    import threading

    errors: list[RuntimeError] = []
    done = threading.Event()

    def run() -> None:
        try:
            rec.disconnect()
        except RuntimeError as exc:
            errors.append(exc)
        finally:
            done.set()

    threading.Thread(target=run, name="rerun-disconnect", daemon=True).start()
    if not done.wait(DISCONNECT_WAIT_S if wait is None else wait):
        _WEDGED.append(rec)
        return False
    if errors and raising:
        raise errors[0]
    return True


def wedged() -> bool:
    """Whether a stream of this process could not be closed (:func:`disconnect`)."""
    return bool(_WEDGED)


def _write_error(path: Path, exc: RuntimeError) -> OSError:
    import errno

    try:
        full = os.statvfs(path.parent).f_bavail == 0
    except OSError:
        full = False
    if full:
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    return OSError(errno.EIO, f"rerun could not write the recording ({exc})", str(path))


def set_time(rec: rr.RecordingStream, scan: int, stamp: float | None = None) -> None:
    """Set the ``scan`` sequence and, when known, the ``time`` timeline (log seconds)."""
    rec.set_time("scan", sequence=int(scan))
    if stamp is not None:
        if stamp > UNIX_SECONDS:
            rec.set_time("time", timestamp=float(stamp))
        else:
            rec.set_time("time", duration=float(stamp))


def time_columns(scans: NDArray[np.int64], stamps: NDArray[np.float64]) -> list[rr.TimeColumn]:
    """The ``scan`` and ``time`` index columns of rows sent with ``send_columns``."""
    columns = [rr.TimeColumn("scan", sequence=np.asarray(scans, dtype=np.int64))]
    stamps = np.asarray(stamps, dtype=np.float64)
    if stamps.size and stamps[0] > UNIX_SECONDS:
        columns.append(rr.TimeColumn("time", timestamp=stamps))
    elif stamps.size:
        columns.append(rr.TimeColumn("time", duration=stamps))
    return columns


def rerun_executable() -> list[str]:
    """The ``rerun`` binary shipped with rerun-sdk (``$RERUN_CLI_PATH`` overrides it).

    The binary itself, not ``python -m rerun_cli``: that wrapper drops the exit code and leaves
    the binary running when it is terminated.
    """
    override = os.environ.get("RERUN_CLI_PATH")
    if override:
        return [override]
    import rerun_cli

    binary = Path(rerun_cli.__file__).parent / "rerun"
    if not binary.is_file():
        raise UsageError(f"{binary}: the rerun binary of rerun-sdk is missing (reinstall it)")
    return [str(binary)]


def viewer_env() -> dict[str, str]:
    """The environment of viewer processes: ours, with usage analytics off (and without the
    ``RUST_LOG=off`` the CLI sets for the SDK: the viewer keeps its own log)."""
    env = dict(os.environ)
    env.setdefault("RERUN_ANALYTICS", "0")
    env.setdefault("RERUN_TELEMETRY", "0")
    if env.get("RUST_LOG") == "off":
        del env["RUST_LOG"]
    return env


PR_SET_PDEATHSIG = 1
"""``prctl`` option: the signal a process gets when its parent dies (Linux)."""


def die_with_parent(signum: int = signal.SIGTERM) -> Callable[[], None] | None:
    """A ``preexec_fn`` that makes a child process receive ``signum`` when we die (Linux
    ``prctl(PR_SET_PDEATHSIG)``, even when we are SIGKILLed); ``None`` elsewhere."""
    if not sys.platform.startswith("linux"):
        return None
    parent = os.getpid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        prctl = libc.prctl
    except (OSError, AttributeError):
        return None

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, signum, 0, 0, 0)
        if os.getppid() != parent:  # the parent died before prctl: follow it now
            os.kill(os.getpid(), signum)

    return preexec


def check_port_free(port: int, option: str = "--port") -> None:
    """:class:`~slam.errors.UsageError` unless a server can listen on 127.0.0.1:``port``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: TIME_WAIT is fine
        try:
            s.bind((LOOPBACK, port))
        except OSError as exc:
            raise UsageError(
                f"{option} {port}: {LOOPBACK}:{port} is not free ({exc.strerror}); choose "
                f"another {option}"
            ) from None


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])


def grpc_url(port: int) -> str:
    """The URL an SDK streams to for a viewer listening on ``port`` of 127.0.0.1."""
    return f"rerun+http://{LOOPBACK}:{port}/proxy"


def wait_for_port(port: int, timeout_s: float, process: subprocess.Popen | None = None) -> bool:
    """Whether something accepts connections on 127.0.0.1:``port`` within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            return False
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.settimeout(0.2)
            if s.connect_ex((LOOPBACK, port)) == 0:
                return True
        time.sleep(0.1)
    return False


def spawn_viewer(port: int | None = None, timeout_s: float = 20.0) -> tuple[subprocess.Popen, str]:
    """Start a native viewer listening on 127.0.0.1; return the process and the URL to stream to.

    Raises :class:`~slam.errors.UsageError` when the viewer does not come up (for example on a
    machine without a display). The viewer runs in its own session and outlives the run.
    """
    port = port or free_port()
    cmd = [*rerun_executable(), "--bind", LOOPBACK, "--port", str(port), "--expect-data-soon"]
    process = subprocess.Popen(  # its own session: the viewer outlives the run
        cmd,
        env=viewer_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    if not wait_for_port(port, timeout_s, process):
        if process.poll() is None:
            process.terminate()
        raise UsageError(
            f"--viewer: the rerun viewer did not start listening on {LOOPBACK}:{port} "
            f"(exit code {process.poll()}); is there a display?"
        )
    return process, grpc_url(port)


def viewer_command(
    source: Path | str, web: bool = False, port: int | None = None, web_port: int | None = None
) -> list[str]:
    """Command line of ``slam view``: the native viewer on a recording file, or the web viewer
    served on 127.0.0.1 for ``source``, the recording's ``http://`` URL
    (:class:`slam.viz.webserve.RecordingServer`: the page fetches it, and no gRPC server is
    started)."""
    cmd = [*rerun_executable(), "--bind", LOOPBACK]
    if web:
        cmd += ["--serve-web", "--web-viewer-port", str(web_port or 9090)]
    if port is not None:
        cmd += ["--port", str(port)]
    return [*cmd, str(source)]


def web_url(web_port: int, source: str) -> str:
    """Address of the web viewer served by :func:`viewer_command` with ``web=True``, opening
    ``source`` (a recording's URL)."""
    return f"http://{LOOPBACK}:{web_port}/?url={quote(source, safe='')}"


@dataclass
class EntitySummary:
    """What a recording holds for one entity."""

    rows: int = 0
    """Temporal rows (one per log call on a timeline)."""
    static_rows: int = 0
    """Static rows."""
    timelines: set[str] = field(default_factory=set)
    """Timelines its temporal rows are indexed by."""
    fields: set[str] = field(default_factory=set)
    """Logged fields as ``Archetype:field`` (e.g. ``Points2D:positions``)."""


def summarize(path: Path) -> dict[str, EntitySummary]:
    """Entities of the first recording in the ``.rrd`` file ``path`` (entity path → summary)."""
    from rerun.chunk import RrdReader

    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: recording not found")
    try:
        with warnings.catch_warnings():  # files streamed by a viewer have no footer: fine here
            warnings.filterwarnings("ignore", message="RRD file has no footer")
            chunks = RrdReader(path).stream().to_chunks()
    except Exception as exc:  # the reader raises plain exceptions on corrupt files
        raise DataError(f"{path}: not a readable rerun recording ({exc})") from None
    out: dict[str, EntitySummary] = {}
    for chunk in chunks:
        entry = out.setdefault(chunk.entity_path, EntitySummary())
        names = chunk.to_record_batch().schema.names
        entry.fields.update(n for n in names if ":" in n)
        if chunk.is_static:
            entry.static_rows += chunk.num_rows
        else:
            entry.rows += chunk.num_rows
            entry.timelines.update(chunk.timeline_names)
    return out
