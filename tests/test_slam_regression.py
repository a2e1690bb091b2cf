"""Regression against the committed reference runs in ``data/reference/slam/``.

A change that moves SLAM results must be deliberate: rerun
``SLAM_DATA_DIR=../shared/data uv run python tools/make_slam_reference.py``, check the new
figures and commit them with the change. The tolerances absorb floating-point differences between
machines and numba versions (the filter is seeded, so on one machine the runs repeat exactly).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tool_modules import load_tool

from slam.io.tum import read_tum

ROOT = Path(__file__).resolve().parent.parent
REFERENCE_DIR = ROOT / "data" / "reference" / "slam"

MAX_POSITION_DEV_M = 0.05
MAX_HEADING_DEV_RAD = 0.02
CELL_TOLERANCE = 0.05


def _reference(name: str) -> tuple[np.ndarray, np.ndarray, dict]:
    tum, meta = REFERENCE_DIR / f"{name}.tum", REFERENCE_DIR / f"{name}.json"
    assert tum.is_file() and meta.is_file(), (
        f"missing reference {name}: run tools/make_slam_reference.py"
    )
    times, poses = read_tum(tum).sorted_by_time()  # runs write trajectory.tum in time order
    return times, poses, json.loads(meta.read_text())


def _compare(name: str, case: dict, tmp_path: Path) -> None:
    ref_times, ref_poses, ref = _reference(name)
    out = tmp_path / f"{name}.tum"
    out.write_text(case["tum"])
    times, poses = read_tum(out)
    stats = case["stats"]
    assert stats["poses"] == ref["poses"] == len(ref_times)
    np.testing.assert_allclose(times, ref_times, rtol=0, atol=1e-6)
    dev = np.hypot(*(poses[:, :2] - ref_poses[:, :2]).T)
    heading = np.abs(np.angle(np.exp(1j * (poses[:, 2] - ref_poses[:, 2]))))
    assert dev.max() <= MAX_POSITION_DEV_M, (
        f"{name}: position drifted {dev.max():.3f} m from the reference"
    )
    assert heading.max() <= MAX_HEADING_DEV_RAD, f"{name}: heading drifted {heading.max():.4f} rad"
    for key in ("occupied_cells", "free_cells"):
        assert abs(stats[key] - ref[key]) <= CELL_TOLERANCE * ref[key], (
            f"{name}: {key} {stats[key]} vs reference {ref[key]}"
        )


@pytest.fixture(scope="module")
def small_folder(tmp_path_factory) -> Path:
    return load_tool("make_slam_reference").small_dataset(
        tmp_path_factory.mktemp("regression") / "small"
    )


@pytest.mark.parametrize("method", ["rbpf", "classic"])
def test_small_run_matches_its_reference(method, small_folder, tmp_path):
    tool = load_tool("make_slam_reference")
    small = tool.SMALL
    case = tool.run_case(
        str(small_folder), method, small_folder.parent, small["scans"], small["particles"]
    )
    _compare(f"small-{method}", case, tmp_path)


def test_intel_run_matches_its_reference(carmen_dir, tmp_path):
    tool = load_tool("make_slam_reference")
    intel = tool.INTEL
    case = tool.run_case("intel", "rbpf", carmen_dir.parent, intel["scans"], intel["particles"])
    _compare("intel-rbpf", case, tmp_path)
