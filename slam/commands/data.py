"""``slam data``: which datasets are under the data directory, and are they sound.

List and verify the datasets of the registry (data/datasets.toml) under the data directory:
--data-dir, else $SLAM_DATA_DIR, else ./data.

* ``slam data list [--data-dir D] [--json]``: every registry dataset as present, partial (with
  the missing files) or absent.
* ``slam data verify NAME [--data-dir D] [--json]``: sizes and hashes of the files present, then
  the loader's checks (keys, shapes, dtypes, timestamps, rates) and a summary per stream (counts,
  duration, rates, gaps, invalid beams, non-monotonic scans). Exit code 2 when a present file is
  wrong or nothing of the dataset is there; a partial dataset whose present files are sound
  exits 0 and lists what is missing.
* ``slam data inspect FILE [--json]``: what a ROS bag / MCAP file / ROS 2 bag folder, CARMEN log
  or ECE276A folder holds (topics, message types, counts, rates, time span, tf frames, or the
  loader's stream summary) and the ``slam run`` command that would use it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from slam.commands._common import (
    add_actions,
    add_bag_arguments,
    add_command,
    add_data_dir_argument,
    bag_options_from,
    data_dir_from,
)
from slam.io.datadir import DATA_DIR_ENV


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the sub-commands of ``slam data`` and their arguments."""
    actions = add_actions(parser, "data_command", "ACTION")

    listing = add_command(
        actions, "list", __doc__, "show each dataset as present, partial or absent", layout=True
    )
    add_data_dir_argument(listing)
    listing.add_argument("--json", action="store_true", help="print JSON instead of a table")
    listing.set_defaults(func=run_list)

    verify = actions.add_parser(
        "verify",
        help="check a dataset's files and print its summary",
        description="Check sizes and hashes, keys, shapes, dtypes, timestamps and rates of a "
        "dataset's files and print counts, durations, rates and gaps per stream.",
    )
    verify.add_argument("name", help="dataset name (see `slam data list`)")
    add_data_dir_argument(verify)
    verify.add_argument("--json", action="store_true", help="print the report as JSON")
    verify.set_defaults(func=run_verify)

    inspect = actions.add_parser(
        "inspect",
        help="show what a bag, MCAP file, CARMEN log or ECE276A folder holds",
        description="Show what a log file or folder holds (format detected by content): topics, "
        "message types, counts, rates, time span and tf frames of a bag; streams of other logs; "
        "and the `slam run` command that would use it.",
    )
    inspect.add_argument("path", type=Path, metavar="FILE", help="log file or folder")
    inspect.add_argument("--json", action="store_true", help="print the report as JSON")
    add_bag_arguments(inspect)
    inspect.set_defaults(func=run_inspect)


def _data_dir_origin(args: argparse.Namespace) -> str:
    if getattr(args, "data_dir", None):
        return "--data-dir"
    if os.environ.get(DATA_DIR_ENV):
        return f"${DATA_DIR_ENV}"
    return "default"


def _short(path: str, folder: str) -> str:
    prefix = folder.rstrip("/") + "/"
    return path[len(prefix) :] if path.startswith(prefix) else path


def run_list(args: argparse.Namespace) -> int:
    """``slam data list``."""
    from slam.io.registry import check_readable_dir, dataset_status, load_registry

    data_dir = data_dir_from(args)
    exists = check_readable_dir(data_dir, "data directory")
    statuses = [dataset_status(d, data_dir) for d in load_registry().values()]
    if args.json:
        report = {
            "data_dir": str(data_dir),
            "data_dir_exists": exists,
            "datasets": [s.as_dict() for s in statuses],
        }
        print(json.dumps(report, indent=2))
        return 0

    out = sys.stdout
    print(f"data directory: {data_dir} ({_data_dir_origin(args)})", file=out)
    if not exists:
        print(
            f"  (does not exist: every dataset is absent; pass --data-dir or set "
            f"{DATA_DIR_ENV}, see docs/data.md)",
            file=out,
        )
    rows = [("NAME", "LOADER", "STATUS", "MISSING")]
    for s in statuses:
        if s.state == "absent":
            missing = "everything"
        else:
            missing = ", ".join(_short(p, s.dataset.folder) for p in s.missing) or "-"
        rows.append((s.dataset.name, s.dataset.loader, s.state, missing))
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    for row in rows:
        head = "  ".join(cell.ljust(widths[i]) for i, cell in enumerate(row[:3]))
        print(f"{head}  {row[3]}", file=out)
    counts = {state: sum(s.state == state for s in statuses) for state in ("present", "partial")}
    absent = len(statuses) - counts["present"] - counts["partial"]
    print(
        f"\n{counts['present']} present, {counts['partial']} partial, {absent} absent. "
        f"Missing paths are relative to each dataset's folder; `slam data verify NAME` checks "
        f"a dataset, docs/data.md says where files go.",
        file=out,
    )
    return 0


def _fmt_stream(name: str, info: dict[str, Any]) -> str:
    count = info.get("count", 0)
    if not count:
        return f"  {name:<10} 0 readings"
    text = (
        f"  {name:<10} {count:>6} readings  {info['duration_s']:8.2f} s  "
        f"{info['rate_hz']:7.2f} Hz  median dt {info['median_dt_s'] * 1000:6.2f} ms  "
        f"max gap {info['max_gap_s']:.3f} s"
    )
    extras = []
    if "beams" in info:
        extras.append(f"{info['beams']} beams")
        extras.append(f"invalid beams {info['invalid_beams']}")
        extras.append(f"no-return beams {info['no_return_beams']}")
        extras.append(f"non-monotonic {info['non_monotonic']}")
    return text + (f"\n  {'':<10} " + ", ".join(extras) if extras else "")


def run_verify(args: argparse.Namespace) -> int:
    """``slam data verify NAME``."""
    from slam.errors import DataError
    from slam.io.registry import verify_dataset

    data_dir = data_dir_from(args)
    report = verify_dataset(args.name, data_dir)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print_verify(report, data_dir)
    if report["problems"]:
        raise DataError(
            f"{args.name}: {len(report['problems'])} problem(s) found: "
            + "; ".join(report["problems"])
        )
    return 0


def _print_verify(report: dict[str, Any], data_dir: Path) -> None:
    out = sys.stdout
    print(f"{report['name']} ({report['loader']}) in {data_dir}: {report['status']}", file=out)
    print("files:", file=out)
    for f in report["files"]:
        if "entries" in f:
            detail = f"{f['entries']} files"
        else:
            detail = f"{f['size']} bytes"
            if f.get("sha256") == "ok":
                detail += ", sha256 ok"
        state = "ok" if f["status"] == "ok" else "BAD"
        print(f"  {state:<8} {f['path']}  ({detail})", file=out)
        for problem in f["problems"]:
            print(f"  {'':<8} {problem}", file=out)
    for path in report["missing"]:
        print(f"  {'missing':<8} {path}", file=out)
    summary = report["summary"]
    streams = [k for k, v in summary.items() if isinstance(v, dict)]
    if streams:
        print("streams:", file=out)
        for name in streams:
            print(_fmt_stream(name, summary[name]), file=out)
        notes = {
            k: v
            for k, v in summary.items()
            if not isinstance(v, dict) and k not in ("name", "kind")
        }
        if notes:
            print("notes:", file=out)
            for key, value in notes.items():
                print(f"  {key}: {value}", file=out)
    for warning in report.get("warnings", []):
        print(f"warning: {warning}", file=out)
    if report["problems"]:
        print(f"result: {len(report['problems'])} problem(s)", file=out)
    elif report["missing"]:
        print(
            f"result: the files present check out; {len(report['missing'])} missing "
            f"(see docs/data.md for where to put them)",
            file=out,
        )
    else:
        print("result: all files present and sound", file=out)


def run_inspect(args: argparse.Namespace) -> int:
    """``slam data inspect FILE``."""
    from slam.io.inspect import format_inspection, inspect_path

    report = inspect_path(args.path, bag_options_from(args))
    print(json.dumps(report, indent=2) if args.json else format_inspection(report), end="")
    return 0
