"""``slam localize LOG --map RUN_DIR|map.yaml``: localize a log on a saved map and write a run folder.

Localize LOG (a dataset name, 'demo', or a path) on the map of a slam run folder (or a map.npz, or
a ROS map_server map.yaml). With --initial the particles start around that pose; without it (or
with --global) an exact histogram filter over the map's free cells and headings finds the pose
first. Writes trajectory.tum (sorted by time, and trajectory_file_order.tum when the log's clock
runs backwards, as slam run), localization.npz, metrics.json, map.png, config.toml and
recording.rrd to the run folder. A negative coordinate needs no '=': --initial -19,-24,0 works.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

from slam.commands._common import (
    add_config_arguments,
    add_data_dir_argument,
    add_log_argument,
    add_output_arguments,
    add_scan_arguments,
    data_dir_from,
    output_request_fields,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam localize``."""
    add_log_argument(parser, "LOG")
    parser.add_argument(
        "--map",
        required=True,
        type=Path,
        metavar="MAP",
        help="slam run folder, map.npz or map.yaml",
    )
    start = parser.add_mutually_exclusive_group()
    start.add_argument(
        "--initial",
        metavar="X,Y,THETA[,SIGMA]",
        help="initial pose in the map frame (m, m, rad) and its position sigma (m)",
    )
    start.add_argument(
        "--global",
        dest="global_",
        action="store_true",
        help="global localization (the default without --initial)",
    )
    parser.add_argument("--out", type=Path, help="run folder (default runs/LOG-localize-<time>)")
    add_config_arguments(parser)
    add_scan_arguments(parser)
    add_output_arguments(parser, "folder of slam localize")
    add_data_dir_argument(parser)
    accept_negative_numbers(parser)
    parser.set_defaults(func=localize_command)


NUMBER_LIST = re.compile(r"^-\.?\d[\d.eE+\-,\s]*$")
"""What ``slam localize``'s parser reads as a value, not an option, though it starts with ``-``:
a negative number or a list of numbers (``--initial -19,-24,0``)."""


def accept_negative_numbers(parser: argparse.ArgumentParser) -> None:
    """Let ``parser`` take an argument such as ``-19,-24,0`` as a value (argparse otherwise reads
    it as an unknown option and says ``--initial: expected one argument``).

    argparse decides what looks like a negative number with the parser's own
    ``_negative_number_matcher`` (``-19`` or ``-1.5``, not a list); this parser's matcher
    accepts :data:`NUMBER_LIST` too. No option of the command looks like a number, so nothing
    else changes; ``--initial=-19,-24,0`` keeps working."""
    default = getattr(parser, "_negative_number_matcher", None)  # private: absent, use "="
    if isinstance(default, re.Pattern):
        parser._negative_number_matcher = re.compile(f"{NUMBER_LIST.pattern}|{default.pattern}")


def localize_command(args: argparse.Namespace) -> int:
    """Resolve the configuration, localize, and print a summary."""
    import json

    from slam.commands.run import overrides_from
    from slam.config import load_config
    from slam.io.sources import resolve
    from slam.localize.run import LocalizeRequest, localize, parse_initial

    initial = parse_initial(args.initial) if args.initial is not None else None
    data_dir = data_dir_from(args)
    ref = resolve(args.name, data_dir, where="slam localize LOG")
    config = load_config(
        ref.config_name if ref.shipped_config else "", args.config, overrides_from(args)
    )
    if not ref.shipped_config:  # as slam run: a bag's geometry is its messages'
        config = dataclasses.replace(config, dataset=ref.config_name)
    out = localize(
        LocalizeRequest(
            name=args.name,
            map_path=args.map,
            config=config,
            data_dir=data_dir,
            initial=initial,
            **output_request_fields(args),
        )
    )
    m = json.loads((out / "metrics.json").read_text())
    summary = [f"{m['scans']} scans", f"localized on {100 * m['localized_share']:.1f} % of them"]
    if m["time_to_convergence_s"] is not None:
        summary.append(f"converged after {m['time_to_convergence_s']:.1f} s")
    if m["mean_match_quality"] is not None:
        summary.append(f"match quality {m['mean_match_quality']:.2f}")
    summary.append(f"{m['real_time_factor']:.0f}x real time")
    print(f"{out}: {', '.join(summary)}")
    return 0
