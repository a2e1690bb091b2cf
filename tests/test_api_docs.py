"""The examples of docs/api.md run as written, on a simulated log and on intel's first 500 scans."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import slam
from slam.eval.trajectory import evaluate_against_reference
from slam.io.tum import read_tum

API_DOC = Path(__file__).resolve().parent.parent / "docs" / "api.md"


def python_blocks(section: str) -> list[str]:
    """The ```python blocks of the section of docs/api.md whose heading starts with ``section``."""
    text = API_DOC.read_text()
    parts = re.split(r"^## ", text, flags=re.M)
    (body,) = [p for p in parts if p.startswith(section)]
    return re.findall(r"```python\n(.*?)```", body, flags=re.S)


def run_example(name: str, max_scans: int, ece276a: bool = False) -> dict:
    """Run the first-run example (and the ECE276A one) with ``NAME``, ``MAX_SCANS`` replaced."""
    settings, example = python_blocks("A first run")
    assert 'NAME = "intel"' in settings and "MAX_SCANS = 500" in settings
    namespace: dict = {}
    exec(settings, namespace)
    namespace.update(NAME=name, MAX_SCANS=max_scans)
    exec(example, namespace)
    if ece276a:
        namespace["first_result"] = namespace["result"]
        (online,) = python_blocks("ECE276A robots")
        exec(online, namespace)
    return namespace


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    from slam.sim.dataset import SimOptions, generate_dataset

    folder = tmp_path_factory.mktemp("apidoc") / "small"
    generate_dataset(folder, SimOptions(scenario="small", seed=7, duration=30.0, rgbd=False))
    return folder


def test_the_examples_run_on_a_simulated_log(small, capsys):
    ns = run_example(str(small), 600, ece276a=True)
    truth = read_tum(small / "groundtruth.tum")
    first, online = ns["first_result"], ns["result"]
    out = capsys.readouterr().out
    assert "scan 500: pose" in out and "600 poses" in out
    for result in (first, online):  # ATE 0.006 m (batch odometry), 0.012 m (encoders + IMU)
        assert len(result.trajectory) == 600
        assert evaluate_against_reference(result.trajectory, truth)["ate_rmse"] < 0.02
        assert np.count_nonzero(result.grid.log_odds > 0) > 1000
    # The first example feeds the batch odometry: it is the batch run but for the scan period
    # (the median so far instead of the whole log's), which on these scans makes the same update
    # decisions: the poses are identical today; the tolerance is the regression tests'.
    batch = slam.run(str(small), seed=0, max_scans=600)
    assert np.abs(first.poses - batch.poses)[:, :2].max() < 0.05


def test_the_first_example_runs_on_intel(carmen_dir, monkeypatch, capsys):
    monkeypatch.setenv("SLAM_DATA_DIR", str(carmen_dir.parent))
    result = run_example("intel", 500)["result"]
    assert "500 poses" in capsys.readouterr().out
    reference = read_tum(API_DOC.parent.parent / "data" / "reference" / "slam" / "intel-rbpf.tum")
    # online, without the batch run's scan period, the update decisions on these 500 scans are
    # the batch run's: the committed reference to its 1e-6 m precision today (tolerance: the
    # regression tests')
    in_time_order = result.trajectory.sorted_by_time()  # trajectory.tum is in time order
    deviation = np.hypot(*(in_time_order.poses[:, :2] - reference.poses[:, :2]).T)
    assert deviation.max() < 0.05
    assert result.stats["updates"] == 172
