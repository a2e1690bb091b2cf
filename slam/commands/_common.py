"""Arguments and helpers shared by several sub-commands.

Every command's parser is made by :func:`add_command` (:func:`slam.cli.build_parser` calls it
with the command's line of :data:`slam.cli.COMMANDS`), which takes the command's description from
the module docstring: every paragraph after the first (the one line saying what the module owns).
A command with sub-commands adds them to the group :func:`add_actions` returns.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slam.io.datadir import resolve_data_dir

if TYPE_CHECKING:
    from slam.io.rosbag import BagOptions


def doc_description(doc: str | None) -> str | None:
    """The paragraphs of the docstring ``doc`` after its first, as plain text: RST double
    backquotes become plain quotes and a cross-reference role (``:func:`x```) its quoted target
    (``None`` when there is nothing after the first, or no docstring, as under ``python -OO``)."""
    if doc is None or "\n\n" not in doc:
        return None
    text = doc.split("\n\n", 1)[1]
    text = re.sub(r":(?:func|class|meth|mod|data|attr):`~?([^`]+)`", r"'\1'", text)
    return text.replace("``", "'")


def add_command(
    subparsers: argparse._SubParsersAction,
    name: str,
    doc: str | None,
    help: str,
    layout: bool = False,
) -> argparse.ArgumentParser:
    """Add the parser of command ``name`` to ``subparsers``: ``help`` is its line in the
    commands' list, its description :func:`doc_description` of ``doc`` (the command module's
    ``__doc__``), rewrapped to the terminal, or with ``layout`` printed with the docstring's own
    line breaks (lists, examples)."""
    formatter = argparse.RawDescriptionHelpFormatter if layout else argparse.HelpFormatter
    return subparsers.add_parser(
        name, help=help, description=doc_description(doc), formatter_class=formatter
    )


def add_actions(
    parser: argparse.ArgumentParser, dest: str, metavar: str = "SUBCOMMAND"
) -> argparse._SubParsersAction:
    """Add to ``parser`` a group of sub-commands one of which must be given (its name goes to
    ``args.<dest>``; ``metavar`` names it in the usage line); add each with
    :func:`add_command` or ``add_parser``."""
    actions = parser.add_subparsers(dest=dest, metavar=metavar)
    actions.required = True
    return actions


def add_log_argument(parser: argparse.ArgumentParser, metavar: str) -> None:
    """Add the positional log (``args.name``, shown as ``metavar``) of a command that reads one:
    a dataset name of the registry, ``demo``, or a path (see :func:`slam.io.sources.resolve`)."""
    parser.add_argument("name", metavar=metavar, help="dataset name, 'demo', or a path")


def add_quiet_argument(parser: argparse.ArgumentParser, help: str = "no progress bar") -> None:
    """Add ``--quiet`` (help text ``help``); :func:`show_progress` reads it."""
    parser.add_argument("--quiet", action="store_true", help=help)


def add_record_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """Add ``--record FILE``: also write a rerun recording (``.rrd``) holding ``what``."""
    parser.add_argument(
        "--record",
        type=Path,
        metavar="FILE",
        help=f"also write a rerun recording (.rrd): {what}",
    )


def add_file_force_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--force``: replace an output file that exists (:func:`check_new_file`)."""
    parser.add_argument(
        "--force", action="store_true", help="replace an output file that exists already"
    )


def add_data_dir_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--data-dir`` (default: ``$SLAM_DATA_DIR``, else ``./data``)."""
    parser.add_argument(
        "--data-dir",
        type=Path,
        default=None,
        help="data directory (default: $SLAM_DATA_DIR, else ./data)",
    )


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--config`` (a TOML file) and ``--set SECTION.KEY=VALUE`` (repeatable); read them
    with :func:`slam.commands.run.overrides_from`."""
    parser.add_argument("--config", type=Path, help="configuration file (TOML)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override one configuration value (repeatable)",
    )


def add_scan_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--seed``, ``--every`` and ``--max-scans`` (shortcuts for ``filter.seed``,
    ``filter.every`` and ``filter.max_scans``)."""
    parser.add_argument("--seed", type=int, help="random seed")
    parser.add_argument("--every", type=int, help="process every k-th scan")
    parser.add_argument("--max-scans", type=int, help="stop after this many scans (0: all)")


def add_output_arguments(
    parser: argparse.ArgumentParser,
    folder: str,
    record: bool = True,
    quiet: str = "no progress bar",
) -> None:
    """Add ``--no-record`` (when ``record``), ``--force`` (replace an existing ``folder``, never
    any other folder) and ``--quiet`` (help text ``quiet``)."""
    if record:
        parser.add_argument(
            "--no-record", action="store_true", help="do not write recording.rrd (viz.record=false)"
        )
    parser.add_argument(
        "--force",
        action="store_true",
        help=f"replace an existing {folder} (never any other folder)",
    )
    add_quiet_argument(parser, quiet)


def output_request_fields(args: argparse.Namespace) -> dict[str, Any]:
    """The fields of a folder-writing command's request (:class:`slam.pipeline.RunRequest`,
    :class:`slam.localize.run.LocalizeRequest`) that its ``--out``, ``--force``, ``--config``
    and ``--quiet`` set: ``out``, ``force``, ``inputs`` (the ``--config`` file, which the folder
    may not hold) and ``progress``."""
    return {
        "out": args.out,
        "force": args.force,
        "inputs": (args.config,) if args.config is not None else (),
        "progress": show_progress(args),
    }


def data_dir_from(args: argparse.Namespace) -> Path:
    """The data directory chosen by ``args`` (see :func:`slam.io.datadir.resolve_data_dir`)."""
    return resolve_data_dir(getattr(args, "data_dir", None))


def show_progress(args: argparse.Namespace) -> bool:
    """Progress bars only on a terminal and without ``--quiet``."""
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


def add_bag_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--scan-topic``, ``--odom-topic`` and ``--base-frame`` (ROS bags and MCAP files)."""
    group = parser.add_argument_group("ROS bags and MCAP files")
    group.add_argument(
        "--scan-topic",
        metavar="TOPIC",
        help="LaserScan or MultiEchoLaserScan topic (default: the only one)",
    )
    group.add_argument(
        "--odom-topic",
        metavar="TOPIC",
        help="Odometry topic, or 'tf' for the odom → base transforms (default: the only "
        "Odometry topic, else tf, else none: the run then matches the scans for its odometry)",
    )
    group.add_argument(
        "--odom-sync",
        choices=("interpolate", "latest"),
        default="interpolate",
        help="odometry pose at a scan: interpolated at its stamp (default, as tf does) or the "
        "latest one at or before it (as CARMEN logs record it)",
    )
    group.add_argument(
        "--base-frame",
        metavar="FRAME",
        help="robot frame (default: the Odometry child_frame_id, the laser's moving ancestor in "
        "tf, or, without odometry, the top of the laser's tf_static chain)",
    )


def bag_options_from(args: argparse.Namespace) -> BagOptions:
    """The :class:`~slam.io.rosbag.BagOptions` chosen by ``args``."""
    from slam.io.rosbag import BagOptions

    return BagOptions(
        scan_topic=getattr(args, "scan_topic", None),
        odom_topic=getattr(args, "odom_topic", None),
        base_frame=getattr(args, "base_frame", None),
        odom_sync=getattr(args, "odom_sync", None) or "interpolate",
    )
