"""The ``slam`` command line: one sub-command per module in :mod:`slam.commands`.

Each command module exposes ``register(subparsers)``, which adds its parser and sets ``func``.
Heavy imports (numba kernels, rerun) happen inside the handlers so ``slam --help`` stays instant.
Errors meant for people (:class:`~slam.errors.SlamError`) print one line and exit with code 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
from collections.abc import Sequence

from slam import __version__
from slam.errors import SlamError

COMMAND_ORDER: tuple[str, ...] = (
    "run",
    "data",
    "sim",
    "eval",
    "texture",
    "view",
    "grid",
    "maze",
)
"""Order of the sub-commands in ``slam --help``; any other module of the package comes after."""


def command_modules() -> list[str]:
    """Names of the modules in :mod:`slam.commands`, in help order."""
    import slam.commands

    found = [
        m.name
        for m in pkgutil.iter_modules(slam.commands.__path__)
        if not m.ispkg and not m.name.startswith("_")
    ]
    rank = {name: i for i, name in enumerate(COMMAND_ORDER)}
    return sorted(found, key=lambda n: (rank.get(n, len(rank)), n))


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="slam",
        description="Particle-filter SLAM, texture mapping, grid localization and maze robots.",
    )
    parser.add_argument("--version", action="version", version=f"slam {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers.required = True
    for name in command_modules():
        importlib.import_module(f"slam.commands.{name}").register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the process exit code."""
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except SlamError as exc:
        print(f"slam: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except FileExistsError as exc:
        print(f"slam: error: {exc} (use --force to replace it)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("slam: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
