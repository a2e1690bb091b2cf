"""``slam run NAME``: estimate a trajectory and a map from a log and write a run folder.

Run SLAM on NAME: a dataset of the registry (slam data list), 'demo' (a simulated dataset20-scale
log generated on first use, with ground truth), or a path to a CARMEN log, an ECE276A dataset
folder, a ROS 1 bag, a ROS 2 bag folder or an MCAP file (format detected by content). Writes to
the run folder: config.toml, metrics.json and trajectory.tum (sorted by time, plus
trajectory_file_order.tum when the log's clock runs backwards, as intel's does); from a log with
laser scans, map.npz, map.png, map_clean.png, map.pgm/map.yaml and quality.png (the map-quality
picture, unless quality.enabled = false); recording.rrd (the rerun recording, unless --no-record);
and, with RGB-D frames, texture.npz, texture.png and texture_overlay.png (unless --no-texture).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from slam.commands._common import (
    add_bag_arguments,
    add_config_arguments,
    add_data_dir_argument,
    add_log_argument,
    add_output_arguments,
    add_scan_arguments,
    bag_options_from,
    data_dir_from,
    output_request_fields,
)
from slam.config import METHODS, Override


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam run``."""
    add_log_argument(parser, "NAME")
    parser.add_argument("--method", choices=METHODS, help="estimation method (default: rbpf)")
    parser.add_argument("--out", type=Path, help="run folder (default runs/NAME-<time>)")
    add_config_arguments(parser)
    parser.add_argument("--particles", type=int, help="number of particles")
    add_scan_arguments(parser)
    parser.add_argument(
        "--no-texture", action="store_true", help="skip the floor texture (RGB-D) stage"
    )
    parser.add_argument(
        "--viewer", action="store_true", help="stream the run live to a rerun viewer (127.0.0.1)"
    )
    add_output_arguments(parser, "run folder of slam run")
    add_bag_arguments(parser)
    add_data_dir_argument(parser)
    parser.set_defaults(func=run_command)


def overrides_from(args: argparse.Namespace) -> list[str]:
    """``--set`` values (untouched: a TOML literal string ``'a "b"'`` stays one) plus the
    shortcut flags, as ``section.key=value`` strings (string values as TOML basic strings); a
    flag's is an :class:`~slam.config.Override` naming the flag, so that a message about its value
    names what the user typed (``--every 0``), not a ``--set`` they did not."""
    out: list[str] = list(args.set)
    for flag, key in (
        ("method", "filter.method"),
        ("particles", "filter.particles"),
        ("seed", "filter.seed"),
        ("every", "filter.every"),
        ("max_scans", "filter.max_scans"),
    ):
        value = getattr(args, flag, None)
        if value is not None:
            text = f"{key}={json.dumps(value)}" if isinstance(value, str) else f"{key}={value}"
            out.append(Override(text, f"--{flag.replace('_', '-')} {value}"))
    if getattr(args, "no_texture", False):
        out.append(Override("texture.enabled=false", "--no-texture"))
    if getattr(args, "no_record", False):
        out.append(Override("viz.record=false", "--no-record"))
    return out


def run_command(args: argparse.Namespace) -> int:
    """Resolve the configuration, run, and print where the results are."""
    import dataclasses

    from slam.config import load_config
    from slam.io.sources import resolve
    from slam.pipeline import RunRequest, run

    data_dir = data_dir_from(args)
    ref = resolve(args.name, data_dir, where="slam run NAME")
    config = load_config(
        ref.config_name if ref.shipped_config else "", args.config, overrides_from(args)
    )
    if not ref.shipped_config:  # a bag: geometry from its messages, never configs/<name>.toml
        config = dataclasses.replace(config, dataset=ref.config_name)
    out = run(
        RunRequest(
            name=args.name,
            config=config,
            data_dir=data_dir,
            viewer=getattr(args, "viewer", False),
            bag=bag_options_from(args),
            **output_request_fields(args),
        )
    )
    metrics = json.loads((out / "metrics.json").read_text())
    summary = [f"{metrics['poses']} poses", f"{metrics['path_length_m']:.1f} m"]
    if "scans_per_s" in metrics:
        summary.append(f"{metrics['scans_per_s']:.0f} scans/s")
        summary.append(f"{metrics['real_time_factor']:.1f}x real time")
    score = metrics.get("quality", {}).get("score")
    if score is not None:
        summary.append(f"map quality {score:.3f}")
    if "ate_rmse" in metrics:
        summary.append(f"ATE RMSE {metrics['ate_rmse']:.3f} m")
    if "frames_used" in metrics.get("texture", {}):
        summary.append(f"texture from {metrics['texture']['frames_used']} frames")
    print(f"{out}: {', '.join(summary)}")
    return 0
