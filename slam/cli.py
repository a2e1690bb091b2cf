"""The ``slam`` command line: one sub-command per module in :mod:`slam.commands`.

:data:`COMMANDS` lists the sub-commands in help order, each with its line in ``slam --help``;
each is the module of its name, which exposes ``add_arguments(parser)``: it adds the command's
arguments (sub-commands go in :func:`~slam.commands._common.add_actions`) and sets ``func``.
:func:`build_parser` makes every command's parser with
:func:`~slam.commands._common.add_command`, the description being the module docstring after its
first paragraph.
Heavy imports (numba kernels, rerun) happen inside the handlers so ``slam --help`` stays instant.
Errors meant for people (:class:`~slam.errors.SlamError`) print one line and exit with code 2.

What the user's environment does to a command is also one line, not a traceback:

* an :class:`OSError` of the environment (:data:`ENVIRONMENT_ERRNOS`: disk full, read-only file
  system, permission denied, a path under a file, ...) prints the path and the reason, exit 2;
  any other exception is a bug and keeps its traceback;
* Ctrl-C (SIGINT) exits 130; SIGTERM and SIGHUP are raised like Ctrl-C (as
  :class:`~slam.errors.Terminated`) so outputs being assembled are removed the same way, exit
  ``128 + signum`` (143 for SIGTERM). An interrupt that numba's dispatcher wraps into a
  ``SystemError`` counts as the interrupt; a termination whose exception Python swallowed (it
  arrived in a weakref's or the import system's callback) is raised again before an output is
  committed and when the command returns (:func:`slam.errors.raise_pending_termination`);
* a closed standard output (``slam grid run X --json | head``) ends the command quietly, exit 141
  (``128 + SIGPIPE``, what a shell reports for a program killed by SIGPIPE).

Rerun's own log lines are off unless ``RUST_LOG`` says otherwise: a recording that cannot be
written is reported by slam itself (one line), not by rerun's logger.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import os
import pkgutil
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from typing import NamedTuple, NoReturn

from slam import __version__
from slam.commands._common import add_actions, add_command
from slam.errors import (
    SlamError,
    clear_pending_termination,
    note_termination,
    raise_pending_termination,
)


class Command(NamedTuple):
    """How a sub-command presents itself in ``slam --help`` and in its own help."""

    help: str
    """Its line in the list of commands of ``slam --help``."""
    layout: bool = False
    """Print its description with the docstring's own line breaks (lists, examples) instead of
    rewrapping it to the terminal."""


COMMANDS: dict[str, Command] = {
    "run": Command("run SLAM (or dead reckoning) on a dataset and write a run folder"),
    "warmup": Command(
        "compile the kernels of `slam run` into numba's cache (first run at full speed)"
    ),
    "localize": Command(
        "localize a log on a saved map (Monte Carlo localization, global localization)"
    ),
    "data": Command(
        "list and verify the datasets under the data directory, inspect a log, calibrate its "
        "odometry and laser mount",
        layout=True,
    ),
    "sim": Command("simulate a robot log with ground truth (ECE276A format)", layout=True),
    "eval": Command("evaluate a run: map quality without ground truth, relations metric, ATE, RPE"),
    "export": Command(
        "write a finished run's map or trajectory for other tools (map_server, evo, KITTI)",
        layout=True,
    ),
    "texture": Command("recompute the floor texture (RGB-D) of a finished run"),
    "view": Command("open a run's recording.rrd in the rerun viewer (native, or web with --web)"),
    "grid": Command("grid-world localization (exact histogram filter)", layout=True),
    "maze": Command(
        "micromouse mazes: run, bench, show and convert (Udacity tester rules)", layout=True
    ),
    "runs": Command("manage run folders: remove partial folders left by killed runs (runs clean)"),
    "sweep": Command("run many cells (logs × seeds × settings), evaluate, tabulate; resumable"),
    "tune": Command("random/grid search over declared ranges for the least mean error"),
}
"""The sub-commands in the order of ``slam --help``: each is the module of its name in
:mod:`slam.commands`."""


def command_modules() -> list[str]:
    """Names of the modules in :mod:`slam.commands`, in help order (those :data:`COMMANDS` does
    not list, which it should, last)."""
    import slam.commands

    found = [
        m.name
        for m in pkgutil.iter_modules(slam.commands.__path__)
        if not m.ispkg and not m.name.startswith("_")
    ]
    rank = {name: i for i, name in enumerate(COMMANDS)}
    return sorted(found, key=lambda n: (rank.get(n, len(rank)), n))


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="slam",
        description="Particle-filter SLAM, texture mapping, grid localization and maze robots.",
    )
    parser.add_argument("--version", action="version", version=f"slam {__version__}")
    subparsers = add_actions(parser, "command", "COMMAND")
    for name, command in COMMANDS.items():
        module = importlib.import_module(f"slam.commands.{name}")
        module.add_arguments(
            add_command(subparsers, name, module.__doc__, command.help, command.layout)
        )
    return parser


ENVIRONMENT_ERRNOS: frozenset[int] = frozenset(
    {
        errno.ENOSPC,
        errno.EDQUOT,
        errno.EFBIG,
        errno.EROFS,
        errno.EACCES,
        errno.EPERM,
        errno.ENOTDIR,
        errno.EISDIR,
        errno.EEXIST,
        errno.ENOTEMPTY,
        errno.ENOENT,
        errno.ENAMETOOLONG,
        errno.ELOOP,
        errno.EXDEV,
        errno.EBUSY,
        errno.EMFILE,
        errno.ENFILE,
        errno.EIO,
        errno.ETXTBSY,
    }
)
"""Errors of the user's environment (not of slam): one line naming the path, exit 2."""

NO_SPACE_ERRNOS: frozenset[int] = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""Environment errors reported even when the writer did not say which file it was writing."""

TERMINATING_SIGNALS: tuple[str, ...] = ("SIGTERM", "SIGHUP")
"""Signals raised as :class:`~slam.errors.Terminated` while a command runs (when not ignored)."""

EXIT_BROKEN_PIPE = 128 + 13
"""Exit code when standard output is closed under us (128 + SIGPIPE)."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise note_termination(signum)


@contextlib.contextmanager
def _termination_as_interrupt() -> Iterator[None]:
    """Turn SIGTERM and SIGHUP into :class:`~slam.errors.Terminated` (main thread only; a
    signal the parent told us to ignore, as ``nohup`` does for SIGHUP, stays ignored)."""
    previous: dict[int, object] = {}
    clear_pending_termination()
    if threading.current_thread() is threading.main_thread():
        for name in TERMINATING_SIGNALS:
            signum = getattr(signal, name, None)
            if signum is not None and signal.getsignal(signum) == signal.SIG_DFL:
                previous[signum] = signal.signal(signum, _raise_terminated)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _interrupt_in(exc: BaseException) -> KeyboardInterrupt | None:
    """The :class:`KeyboardInterrupt` that caused ``exc`` (numba's dispatcher turns one raised
    while it converts arguments or results into ``SystemError: ... returned a result with an
    exception set``)."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return None


def _interrupted(exc: KeyboardInterrupt) -> int:
    signum = getattr(exc, "signum", signal.SIGINT)
    if signum == signal.SIGINT:
        print("slam: interrupted", file=sys.stderr)
    else:
        print(f"slam: terminated by {signal.Signals(signum).name}", file=sys.stderr)
    return 128 + int(signum)


def environment_message(exc: OSError) -> str:
    """One line for an environment error: the path(s), then the reason."""
    reason = exc.strerror or str(exc)
    if exc.filename is not None and exc.filename2 is not None:
        return f"{exc.filename} -> {exc.filename2}: {reason}"
    if exc.filename is not None:
        return f"{exc.filename}: {reason}"
    return reason


def _silence_stdout() -> None:
    """Point standard output at /dev/null so the interpreter's last flush stays quiet."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the process exit code."""
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    os.environ.setdefault("RUST_LOG", "off")
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with _termination_as_interrupt():
            code = args.func(args)
            raise_pending_termination()  # a signal whose exception a callback swallowed
            sys.stdout.flush()
    except SlamError as exc:
        print(f"slam: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt as exc:
        clear_pending_termination()
        return _interrupted(exc)
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except SystemError as exc:
        interrupt = _interrupt_in(exc)
        if interrupt is None:
            raise
        clear_pending_termination()
        return _interrupted(interrupt)
    except OSError as exc:
        named = exc.filename is not None or exc.errno in NO_SPACE_ERRNOS
        if exc.errno not in ENVIRONMENT_ERRNOS or not named:
            raise
        print(f"slam: error: {environment_message(exc)}", file=sys.stderr)
        return 2
    return int(code or 0)


def entry() -> NoReturn:
    """The ``slam`` command (and ``python -m slam``): :func:`main`, then exit with its code.

    A rerun stream that could not be closed (:func:`slam.viz.stream.wedged`: rerun 0.41 blocks
    for ever in ``disconnect`` once its file writer died on a full disk) would block the
    interpreter's exit the same way; the process then ends with ``os._exit`` after flushing its
    output, with the same code. Tests call :func:`main`, which never exits."""
    code = main()
    viz_stream = sys.modules.get("slam.viz.stream")
    if viz_stream is not None and viz_stream.wedged():
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
