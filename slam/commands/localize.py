"""``slam localize LOG --map RUN_DIR|map.yaml``: localize a log on a saved map and write a run folder.

Localize LOG (a dataset name, 'demo', or a path) on the map of a slam run folder (or a map.npz, or
a ROS map_server map.yaml). With --initial the particles start around that pose; without it (or
with --global) an exact histogram filter over the map's free cells and headings finds the pose
first. Writes trajectory.tum, localization.npz, metrics.json, map.png, config.toml and
recording.rrd to the run folder.
"""

from __future__ import annotations

import argparse
import dataclasses
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
    parser.set_defaults(func=localize_command)


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
    summary = [f"{m['scans']} scans", f"localized {100 * m['localized_share']:.1f} % of the time"]
    if m["time_to_convergence_s"] is not None:
        summary.append(f"converged after {m['time_to_convergence_s']:.1f} s")
    if m["mean_match_quality"] is not None:
        summary.append(f"match quality {m['mean_match_quality']:.2f}")
    summary.append(f"{m['real_time_factor']:.0f}x real time")
    print(f"{out}: {', '.join(summary)}")
    return 0
