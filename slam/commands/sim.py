"""``slam sim NAME --out DIR``: write a simulated dataset in the ECE276A format, with ground truth.

NAME is a scenario (``demo``: dataset20-sized, 124 s; ``small``: a 45 s loop). The folder gets
``EncodersNN.npz``, ``ImuNN.npz``, ``HokuyoNN.npz``, ``KinectNN.npz`` and ``dataRGBD/`` exactly
like the course's logs, plus ``groundtruth.tum``, ``groundtruth_map.npz``/``.png``,
``groundtruth_texture.npz``/``.png`` and ``simulation.json``. The same options give byte-identical
files. See docs/sim.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from slam.commands._common import add_output_arguments, show_progress
from slam.io.atomic import check_output_dir


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``slam sim``."""
    from slam.sim.scenarios import SCENARIOS

    parser.add_argument(
        "name",
        metavar="NAME",
        help=f"scenario: {', '.join(f'{k} ({v.description})' for k, v in SCENARIOS.items())}",
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder (created)")
    parser.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    parser.add_argument(
        "--duration",
        type=float,
        metavar="SEC",
        help="log length in seconds (default: nominal; longer logs drive the route lap after lap)",
    )
    parser.add_argument("--number", type=int, default=20, help="file number NN (default 20)")
    parser.add_argument("--no-rgbd", action="store_true", help="skip the Kinect frames")
    parser.add_argument(
        "--rgbd-rate", type=float, metavar="HZ", help="Kinect frame rate (default 10 Hz)"
    )
    parser.add_argument(
        "--noise-free", action="store_true", help="exact sensors: no noise, jitter or drops"
    )
    add_output_arguments(
        parser,
        "dataset folder written by slam sim",
        record=False,
        quiet="no progress bar or summary",
    )
    parser.set_defaults(func=run_sim)


def run_sim(args: argparse.Namespace) -> int:
    """Simulate, write the folder atomically and print a one-line summary."""
    from slam.sim.dataset import RGBD_RATE_HZ, SimOptions, generate_dataset
    from slam.sim.scenarios import get_scenario
    from slam.sim.sensors import NoiseConfig

    get_scenario(args.name)  # UsageError for an unknown name, before any work
    check_output_dir(args.out, "sim", args.force)  # before any work
    options = SimOptions(
        scenario=args.name,
        seed=args.seed,
        duration=args.duration,
        number=args.number,
        rgbd=not args.no_rgbd,
        rgbd_rate=RGBD_RATE_HZ if args.rgbd_rate is None else args.rgbd_rate,
        noise=NoiseConfig.off() if args.noise_free else NoiseConfig(),
    )
    summary = generate_dataset(
        args.out, options, progress=show_progress(args), overwrite=args.force
    )
    if not args.quiet:
        counts = summary["counts"]
        parts = [
            f"{summary['duration_s']:.1f} s",
            f"{counts['encoders']} encoder readings",
            f"{counts['imu']} IMU samples",
            f"{counts['scans']} scans",
        ]
        if "rgb_frames" in counts:
            parts.append(
                f"{counts['disparity_frames']} disparity + {counts['rgb_frames']} RGB frames"
            )
        parts.append(f"{summary['trajectory']['driven_length_m']:.1f} m driven")
        parts.append(f"seed {summary['seed']}")
        parts.append(f"{summary['timings']['total_s']:.1f} s to generate")
        print(f"{args.out}: {', '.join(parts)}")
    return 0
