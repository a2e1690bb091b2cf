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
