"""The project's own error types.

Every error a user can cause (a missing file, a malformed line, a bad config value) is raised as a
:class:`SlamError` subclass whose message names the file, key or line, what was expected and what
was found. The CLI turns these into one line on stderr and exit code 2; anything else is a bug.
"""

from __future__ import annotations


class SlamError(Exception):
    """Base class of every error meant for a person rather than a traceback."""

    exit_code: int = 2


class DataError(SlamError):
    """A data file is missing, unreadable or malformed."""


class ConfigError(SlamError):
    """A configuration file or override is invalid."""


class UsageError(SlamError):
    """A command was called with arguments that cannot work together."""


class Terminated(KeyboardInterrupt):
    """A termination signal (SIGTERM, SIGHUP) received by the CLI, raised like Ctrl-C's
    :class:`KeyboardInterrupt` so that outputs being assembled are removed the same way; the CLI
    exits with ``128 + signum`` (143 for SIGTERM)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


_PENDING: list[int] = []
"""Termination signals raised as :class:`Terminated` and not yet seen ending a command."""


def note_termination(signum: int) -> Terminated:
    """The :class:`Terminated` a signal handler raises, remembered until
    :func:`raise_pending_termination` or :func:`clear_pending_termination`: Python swallows an
    exception raised in some callbacks (a weakref's, the import system's lock release: "Exception
    ignored in ..."), and the signal must not be lost with it."""
    _PENDING.append(signum)
    return Terminated(signum)


def raise_pending_termination() -> None:
    """Raise the remembered :class:`Terminated`, if a termination signal came and was swallowed
    (called before an output is committed and when a command returns)."""
    if _PENDING:
        signum = _PENDING[0]
        _PENDING.clear()
        raise Terminated(signum)


def clear_pending_termination() -> None:
    """Forget remembered signals (a command starting, or one that ended by its Terminated)."""
    _PENDING.clear()
