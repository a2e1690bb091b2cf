"""``slam`` as a subprocess, for the tests that signal, kill or time a real CLI process, and
:func:`finished_run`, the run folder of an in-process ``slam run`` that other tests read.

Not a test module (no ``test_`` prefix); the tests import it (pytest puts ``tests/`` on the path).
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def sigint_as_a_terminal_gives_it() -> None:
    """``preexec_fn`` of a CLI subprocess a test interrupts with SIGINT: the default disposition,
    so that Python turns the signal into ``KeyboardInterrupt`` as in a terminal. A shell without
    job control starts its background jobs with SIGINT and SIGQUIT ignored (POSIX), and a process
    that inherits an ignored SIGINT keeps ignoring it (Python too): a suite started that way (a
    CI runner's ``cmd &``, ``nohup``) would otherwise send Ctrl-C into the void."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def cli_env(**extra: str) -> dict[str, str]:
    """Environment of CLI subprocesses: the worktree's package first on the path, rerun's
    analytics off, plus ``extra``."""
    return dict(
        os.environ,
        RERUN_ANALYTICS="0",
        RERUN_TELEMETRY="0",
        PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
        **extra,
    )


def slam_cmd(*args: str) -> list[str]:
    """The command line of ``slam ARGS`` run by this interpreter."""
    return [sys.executable, "-m", "slam", *args]


def finished_run(log: Path | str, out: Path, *args: str) -> Path:
    """``out``, the run folder of ``slam run LOG --out OUT ARGS`` run in this process (the run
    must succeed)."""
    from slam.cli import main

    assert main(["run", str(log), "--out", str(out), *args]) == 0
    return out
