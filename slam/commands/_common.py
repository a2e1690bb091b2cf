"""Arguments and helpers shared by several sub-commands."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from slam.io.datadir import resolve_data_dir


def add_data_dir_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--data-dir`` (default: ``$SLAM_DATA_DIR``, else ``./data``)."""
    parser.add_argument(
        "--data-dir",
        type=Path,
        default=None,
        help="data directory (default: $SLAM_DATA_DIR, else ./data)",
    )


def data_dir_from(args: argparse.Namespace) -> Path:
    """The data directory chosen by ``args`` (see :func:`slam.io.datadir.resolve_data_dir`)."""
    return resolve_data_dir(getattr(args, "data_dir", None))


def show_progress(args: argparse.Namespace) -> bool:
    """Progress bars only on a terminal and without ``--quiet``."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()
