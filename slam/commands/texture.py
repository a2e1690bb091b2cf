"""``slam texture RUN_DIR``: recompute the floor texture of a finished run.

Reads the run's ``trajectory.tum``, ``map.npz`` and ``config.toml`` (whose ``dataset`` names the
log: ``demo``, a registry dataset, or give the folder with ``--dataset``), projects the dataset's
RGB-D frames along the trajectory, and rewrites ``texture.npz``, ``texture.png``,
``texture_overlay.png`` and the texture figures of ``metrics.json`` (each atomically).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from slam.commands._common import (
    add_data_dir_argument,
    add_quiet_argument,
    data_dir_from,
    show_progress,
)
from slam.config import TEXTURE_MODES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam texture``."""
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="run folder of `slam run`")
    parser.add_argument(
        "--mode",
        choices=TEXTURE_MODES,
        help="colour per cell: running mean of every sample, or the latest frame's "
        "(default: the run's texture.mode)",
    )
    parser.add_argument(
        "--dataset",
        metavar="NAME_OR_PATH",
        help="dataset to read the frames from (default: the 'dataset' of the run's config.toml)",
    )
    add_quiet_argument(parser)
    add_data_dir_argument(parser)
    parser.set_defaults(func=run_texture)


def run_texture(args: argparse.Namespace) -> int:
    """Recompute, print warnings and a one-line summary."""
    from slam.texture import recompute_run

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        figures = recompute_run(
            args.run_dir,
            data_dir_from(args),
            mode=args.mode,
            dataset=args.dataset,
            progress=show_progress(args),
        )
    for message in sorted({str(w.message) for w in caught}):
        print(f"slam: warning: {message}", file=sys.stderr, flush=True)
    parts = [
        f"{figures['frames_used']} frames used",
        f"{figures['frames_skipped']} skipped",
        f"{figures['coloured_cells']} cells coloured ({figures['mode']})",
    ]
    if figures.get("frames_per_s") is not None:
        parts.append(f"{figures['frames_per_s']:.0f} frames/s")
    gt = figures.get("ground_truth")
    if gt and gt.get("colour_mae") is not None:
        parts.append(f"colour error {gt['colour_mae']:.1f}/255")
    if gt and gt.get("coverage") is not None:
        parts.append(f"coverage {100 * gt['coverage']:.1f}%")
    print(f"{args.run_dir}: texture {', '.join(parts)}")
    return 0
