"""``slam runs``: manage the folders slam writes; ``slam runs clean [DIR ...]`` removes the
partial folders that killed runs left behind.

A command writing an output folder assembles it in a partial sibling folder
``.<name>.<random>.partial`` holding an owner record (pid, host, start time). Ctrl-C, SIGTERM and
errors remove it; SIGKILL, a crash or a power cut cannot. The next command writing into the same
folder removes such stale partial folders, and so does this command: it removes those whose
process is gone, and never a live one, one of another user or host, or anything without a
readable owner record (:mod:`slam.io.runfolder`).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from slam.commands._common import add_actions, add_command
from slam.errors import UsageError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the sub-command ``clean`` of ``slam runs``."""
    sub = add_actions(parser, "runs_command")
    clean = add_command(
        sub,
        "clean",
        __doc__,
        "remove stale partial folders (.NAME.XXXX.partial) whose process is gone",
    )
    clean.add_argument(
        "dirs",
        nargs="*",
        type=Path,
        metavar="DIR",
        help="folders holding run folders (default: runs); only their direct children are looked at",
    )
    clean.add_argument("--dry-run", action="store_true", help="only list what would be removed")
    clean.set_defaults(func=clean_command)


def _mb(size: int) -> str:
    return f"{size / 2**20:.1f} MB"


def clean_command(args: argparse.Namespace) -> int:
    """Remove (or list) stale partial folders; print one line per folder and a summary."""
    from slam.io.runfolder import find_partials, folder_size, remove_owned_tree

    if not args.dirs and not Path("runs").exists():
        print("no runs folder here: nothing to clean")
        return 0
    dirs = list(dict.fromkeys(Path(os.path.abspath(d)) for d in args.dirs or [Path("runs")]))
    for folder in dirs:
        if not folder.is_dir():
            found = "a file" if folder.exists() else "nothing"
            raise UsageError(f"{folder}: expected a folder holding run folders, found {found}")
    removed = kept = 0
    freed = 0
    for folder in dirs:
        for partial in find_partials(folder):
            record = partial.record or {}
            who = f"pid {record['pid']}" if record.get("pid") is not None else "no pid"
            who += f" on {record['host']}" if record.get("host") else ""
            who += f", started {record['started']}" if record.get("started") else ""
            if partial.stale:
                size = folder_size(partial.path)
                if args.dry_run:
                    print(f"would remove {partial.path} ({who}: gone; {_mb(size)})")
                elif remove_owned_tree(partial.path):
                    print(f"removed {partial.path} ({who}: gone; {_mb(size)})")
                else:
                    print(f"could not remove all of {partial.path} ({who}: gone)")
                    continue
                removed += 1
                freed += size
            elif partial.state == "live":
                print(f"kept {partial.path} ({who}: still running)")
                kept += 1
            elif partial.state == "unknown":
                print(f"kept {partial.path} ({who}: another host, cannot tell)")
                kept += 1
            else:
                print(f"left {partial.path} (no owner record of yours: not a slam partial folder)")
                kept += 1
    verb = "would remove" if args.dry_run else "removed"
    print(f"{verb} {removed} stale partial folder(s) ({_mb(freed)}); kept {kept}")
    return 0
