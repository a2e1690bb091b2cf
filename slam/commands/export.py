"""``slam export RUN_DIR --format pgm|png|npz|tum|kitti``: a finished run in another tool's format.

* ``pgm``: ``map.pgm`` + ``map.yaml`` for ROS map_server / nav2 (trinary, thresholds 0.65/0.196);
* ``png``: ``map_clean.png``, the occupancy picture without the trajectory;
* ``npz``: ``occupancy.npz`` (int8 100/0/−1 like ``nav_msgs/OccupancyGrid``, probability,
  log-odds, resolution, origin);
* ``tum``: ``trajectory.tum`` sorted by time (older runs kept CARMEN file order);
* ``kitti``: ``trajectory.kitti`` (3×4 pose matrices) and ``trajectory_times.txt``.

Files go to ``RUN_DIR/export/`` unless ``--out PATH`` names the file; an existing file is kept
(exit 2) unless ``--force``. Every file is written atomically.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam export``."""
    from slam.io.exports import EXPORT_FORMATS

    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="run folder (slam run)")
    parser.add_argument("--format", required=True, choices=EXPORT_FORMATS, help="what to write")
    parser.add_argument("--out", type=Path, metavar="PATH", help="file to write")
    parser.add_argument("--force", action="store_true", help="replace existing files")
    parser.set_defaults(func=run_export)


def run_export(args: argparse.Namespace) -> int:
    """Export and print the files written."""
    from slam.io.exports import export_run

    for path in export_run(args.run_dir, args.format, args.out, args.force):
        print(path)
    return 0
