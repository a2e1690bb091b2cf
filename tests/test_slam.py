"""``slam run`` end to end on a simulated log: outputs, accuracy, determinism, errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_process import finished_run

from slam.cli import main
from slam.config import load_config
from slam.io.tum import read_tum

SCANS = 600


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """The simulator's small scenario (30 s, no RGB-D): ~1200 scans with ground truth."""
    from slam.sim.dataset import SimOptions, generate_dataset

    folder = tmp_path_factory.mktemp("slam") / "small"
    generate_dataset(folder, SimOptions(scenario="small", seed=7, duration=30.0, rgbd=False))
    return folder


@pytest.fixture(scope="module")
def rbpf_run(small, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "rbpf"
    return finished_run(small, out, "--max-scans", str(SCANS), "--particles", "20", "--quiet")


def test_run_folder_has_every_output(rbpf_run):
    names = {p.name for p in rbpf_run.iterdir()}
    assert {"config.toml", "trajectory.tum", "map.npz", "map.png", "metrics.json"} <= names
    assert "recording.rrd" in names
    times, poses = read_tum(rbpf_run / "trajectory.tum")
    assert len(times) == SCANS and poses.shape == (SCANS, 3)
    with np.load(rbpf_run / "map.npz") as m:
        assert set(m.files) == {"log_odds", "resolution", "origin"}
        assert float(m["resolution"]) == 0.05 and m["origin"].shape == (2,)
        assert np.count_nonzero(m["log_odds"] > 0) > 500


def test_metrics_json_reports_speed_diagnostics_and_ate(rbpf_run):
    m = json.loads((rbpf_run / "metrics.json").read_text())
    for key in ("scans", "particles", "wall_s", "scans_per_s", "real_time_factor",
                "peak_rss_mb", "n_eff_mean", "n_eff_min", "resampling_count", "ate_rmse"):  # fmt: skip
        assert key in m, key
    assert m["scans"] == SCANS and m["particles"] == 20 and m["method"] == "rbpf"
    assert 1 <= m["n_eff_min"] <= m["n_eff_mean"] <= 20
    assert m["scans_per_s"] > 0 and m["real_time_factor"] > 1
    assert m["ate_rmse"] < 0.05  # the small loop, 15 s of driving


def test_config_toml_reproduces_the_run(rbpf_run, small, tmp_path):
    config = load_config(config_file=rbpf_run / "config.toml")
    assert config.filter.particles == 20 and config.filter.max_scans == SCANS
    out = tmp_path / "again"
    assert main(["run", str(small), "--config", str(rbpf_run / "config.toml"),
                 "--out", str(out), "--quiet", "--no-record"]) == 0  # fmt: skip
    assert (out / "trajectory.tum").read_bytes() == (rbpf_run / "trajectory.tum").read_bytes()


def test_rbpf_beats_dead_reckoning_and_classic_on_the_small_loop(small, tmp_path):
    ate = {}
    for method in ("odometry", "classic", "rbpf"):
        out = tmp_path / method
        args = ["run", str(small), "--out", str(out), "--method", method, "--quiet", "--no-record"]
        assert main(args) == 0
        ate[method] = json.loads((out / "metrics.json").read_text())["ate_rmse"]
    assert ate["rbpf"] < 0.05
    assert ate["rbpf"] < ate["odometry"]
    assert ate["classic"] < 0.5  # the course's method works, less precisely


def test_same_seed_same_trajectory_for_one_and_two_threads(small, tmp_path):
    outputs = []
    for threads in ("1", "2"):
        out = tmp_path / f"t{threads}"
        env = {**os.environ, "NUMBA_NUM_THREADS": threads}
        subprocess.run(
            [sys.executable, "-m", "slam", "run", str(small), "--out", str(out),
             "--max-scans", "400", "--particles", "16", "--seed", "5", "--quiet", "--no-record"],
            check=True, env=env,
        )  # fmt: skip
        outputs.append((out / "trajectory.tum").read_bytes())
    assert outputs[0] == outputs[1]


def test_other_seed_other_trajectory(small, tmp_path, rbpf_run):
    out = tmp_path / "seed9"
    assert main(["run", str(small), "--out", str(out), "--max-scans", str(SCANS),
                 "--particles", "20", "--seed", "9", "--quiet", "--no-record"]) == 0  # fmt: skip
    assert (out / "trajectory.tum").read_bytes() != (rbpf_run / "trajectory.tum").read_bytes()


def test_every_and_max_scans(small, tmp_path):
    out = tmp_path / "every"
    assert main(["run", str(small), "--out", str(out), "--every", "3", "--max-scans", "100",
                 "--particles", "8", "--quiet", "--no-record"]) == 0  # fmt: skip
    times, _ = read_tum(out / "trajectory.tum")
    assert len(times) == 100
    all_times, _ = read_tum(small / "groundtruth.tum")
    assert np.all(np.diff(times) > 0.07)  # every 3rd scan of a 40 Hz log


def test_existing_run_folder_is_refused_and_kept(small, rbpf_run, capsys):
    before = (rbpf_run / "trajectory.tum").read_bytes()
    assert main(["run", str(small), "--out", str(rbpf_run), "--quiet"]) == 2
    assert "exists" in capsys.readouterr().err
    assert (rbpf_run / "trajectory.tum").read_bytes() == before


def test_failed_run_leaves_no_folder(small, tmp_path, monkeypatch, capsys):
    from slam.errors import DataError
    from slam.online import Slam

    def broken(*args, **kwargs):
        raise DataError("injected failure in the middle of the run")

    monkeypatch.setattr(Slam, "finish", broken)
    out = tmp_path / "broken"
    assert main(["run", str(small), "--out", str(out), "--quiet"]) == 2
    assert "injected failure" in capsys.readouterr().err
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".broken")]


def test_unknown_dataset_is_one_clear_error(tmp_path, capsys):
    assert (
        main(["run", "nosuchlog", "--data-dir", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    )
    err = capsys.readouterr().err
    assert "nosuchlog" in err and "intel" in err and "Traceback" not in err


def test_dataset20_without_hokuyo_names_the_missing_file(data_dir, tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "slam", "run", "dataset20", "--data-dir", str(data_dir),
         "--out", str(tmp_path / "o")],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "Hokuyo20.npz" in proc.stderr and "ranges" in proc.stderr and "(1081, N)" in proc.stderr
    assert "--data-dir" in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_dataset20_odometry_has_one_pose_per_encoder_reading(data_dir, tmp_path):
    out = tmp_path / "odo"
    assert main(["run", "dataset20", "--method", "odometry", "--data-dir", str(data_dir),
                 "--out", str(out), "--quiet"]) == 0  # fmt: skip
    times, poses = read_tum(out / "trajectory.tum")
    assert len(times) == 4956
    m = json.loads((out / "metrics.json").read_text())
    assert m["poses"] == 4956 and m["path_length_m"] == pytest.approx(96.6, abs=0.1)
    assert any("IMU" in w for w in m["warnings"])


def test_intel_odometry_one_pose_per_scan_and_its_relation_error(carmen_dir, tmp_path, capsys):
    out = tmp_path / "intel"
    assert main(["run", "intel", "--method", "odometry", "--data-dir", str(carmen_dir.parent),
                 "--out", str(out), "--quiet"]) == 0  # fmt: skip
    times, _ = read_tum(out / "trajectory.tum")
    assert len(times) == 13631
    capsys.readouterr()
    assert main(["eval", str(out), "--relations", str(carmen_dir / "relations/intel.relations"),
                 "--json"]) == 0  # fmt: skip
    rel = json.loads(capsys.readouterr().out)["relations"]
    assert rel["count"] == 2984
    assert rel["trans_mean"] == pytest.approx(7.370, abs=0.001)


def test_odometry_method_stops_at_max_scans(small, tmp_path):
    """``--method odometry --max-scans N`` ends its trajectory at the N-th scan, as the filter's
    run does (it used to keep the whole log's encoder-rate dead reckoning)."""
    ends = {}
    for method in ("odometry", "rbpf"):
        out = tmp_path / method
        assert main(["run", str(small), "--out", str(out), "--method", method, "--max-scans",
                     "100", "--particles", "5", "--quiet", "--no-record"]) == 0  # fmt: skip
        ends[method] = read_tum(out / "trajectory.tum")
    odo, rbpf = ends["odometry"], ends["rbpf"]
    assert len(rbpf.times) == 100
    assert odo.times[-1] <= rbpf.times[-1] < odo.times[-1] + 0.05  # encoders at 40 Hz
    full, _ = read_tum(small / "groundtruth.tum")
    assert odo.times[-1] < full[-1] - 20.0  # 100 scans of a 30 s log: about 2.5 s
