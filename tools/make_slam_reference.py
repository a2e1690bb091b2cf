#!/usr/bin/env python3
"""Regenerate the SLAM regression references in ``data/reference/slam/``.

The references are short runs whose outputs ``tests/test_slam_regression.py`` compares against:

* ``small-<method>``: the simulator's ``small`` scenario (seed 7, 30 s, no RGB-D), first 600 scans,
  for ``rbpf`` and ``classic`` — generated from the project's own simulator, so it needs no data;
* ``intel-rbpf``: the first 500 scans of the intel log (needs ``$SLAM_DATA_DIR``);
* ``mit-csail-rbpf``: the first 400 scans of the mit-csail log, through the odometry glitch at
  scans 266→268 (56.8 s) that the filter's basin probe repairs (needs ``$SLAM_DATA_DIR``).

Each reference is a ``.tum`` trajectory plus a ``.json`` with map statistics. Run after a change
that is meant to alter SLAM results, check the new figures, and commit them::

    SLAM_DATA_DIR=../shared/data uv run python tools/make_slam_reference.py
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

REFERENCE_DIR = Path(__file__).resolve().parent.parent / "data" / "reference" / "slam"

SMALL = {"scenario": "small", "seed": 7, "duration": 30.0, "scans": 600, "particles": 20}
INTEL = {"scans": 500, "particles": 30}
CSAIL = {"scans": 400, "particles": 30}


def small_dataset(folder: Path) -> Path:
    """Generate the small simulated dataset the references are made from."""
    from slam.sim.dataset import SimOptions, generate_dataset

    options = SimOptions(
        scenario=SMALL["scenario"], seed=SMALL["seed"], duration=SMALL["duration"], rgbd=False
    )
    generate_dataset(folder, options)
    return folder


def run_case(
    name: str,
    method: str,
    data_dir: Path,
    scans: int,
    particles: int,
    settings: tuple[str, ...] = (),
) -> dict:
    """Run ``slam run`` on ``name`` (with the extra ``section.key=value`` ``settings``) and
    return its trajectory and map statistics."""
    from slam.config import load_config
    from slam.io.tum import read_tum
    from slam.pipeline import RunRequest, run

    dataset = Path(name).name if Path(name).exists() else name
    config = load_config(
        dataset,
        None,
        [
            f'filter.method="{method}"',
            f"filter.max_scans={scans}",
            f"filter.particles={particles}",
            "filter.seed=0",
            "viz.record=false",
            "texture.enabled=false",
            *settings,
        ],
    )
    with tempfile.TemporaryDirectory() as tmp:
        out = run(RunRequest(name=name, config=config, data_dir=data_dir, out=Path(tmp) / "run"))
        times, poses = read_tum(out / "trajectory.tum")
        with np.load(out / "map.npz") as m:
            log_odds = m["log_odds"]
        tum = (out / "trajectory.tum").read_text()
    return {
        "tum": tum,
        "stats": {
            "poses": int(len(times)),
            "occupied_cells": int(np.count_nonzero(log_odds > 0)),
            "free_cells": int(np.count_nonzero(log_odds < 0)),
            "final_pose": [float(v) for v in poses[-1]],
        },
    }


def main() -> int:
    """Write every reference whose input is available."""
    from slam.io.datadir import resolve_data_dir

    REFERENCE_DIR.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = small_dataset(Path(tmp) / "small")
        for method in ("rbpf", "classic"):
            case = run_case(str(folder), method, Path(tmp), SMALL["scans"], SMALL["particles"])
            (REFERENCE_DIR / f"small-{method}.tum").write_text(case["tum"])
            (REFERENCE_DIR / f"small-{method}.json").write_text(
                json.dumps({**SMALL, **case["stats"]}, indent=2) + "\n"
            )
            print(f"small-{method}: {case['stats']}")
    data_dir = resolve_data_dir(None)
    for log, piece in (("intel", INTEL), ("mit-csail", CSAIL)):
        if not (data_dir / "carmen" / f"{log}.clf.gz").is_file():
            print(f"{log}-rbpf: skipped, {data_dir}/carmen/{log}.clf.gz is absent", file=sys.stderr)
            continue
        case = run_case(log, "rbpf", data_dir, piece["scans"], piece["particles"])
        (REFERENCE_DIR / f"{log}-rbpf.tum").write_text(case["tum"])
        (REFERENCE_DIR / f"{log}-rbpf.json").write_text(
            json.dumps({**piece, **case["stats"]}, indent=2) + "\n"
        )
        print(f"{log}-rbpf: {case['stats']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
