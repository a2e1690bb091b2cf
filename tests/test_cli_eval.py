"""``slam eval``: both modes, the JSON report, eval.json, and one-line errors with exit code 2."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from slam.cli import main
from slam.geometry import compose, relative
from slam.io.tum import write_tum
from slam.trajectory import Trajectory

TRUTH = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, np.pi / 2]])
# Times like a CARMEN log's (1e9 s): the TUM file keeps microseconds, enough for 1e-4 s matching.
TIMES = np.array([976052857.337530, 976052858.337531, 976052859.337532])
ESTIMATE = TRUTH + np.array([[0, 0, 0], [0.1, 0, 0], [0, 0, 0.1]])


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    folder = tmp_path / "run"
    folder.mkdir()
    write_tum(folder / "trajectory.tum", Trajectory(TIMES, ESTIMATE))
    return folder


def write_relations(path: Path, pairs, times=TIMES, extra: str = "") -> Path:
    lines = ["# timestamp1 timestamp2 x y z roll pitch yaw"]
    for i, j in pairs:
        x, y, yaw = relative(TRUTH[i], TRUTH[j])
        lines.append(f"{times[i]:.6f} {times[j]:.6f} {x:.9f} {y:.9f} 0 0 0 {yaw:.9f}")
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


def test_relations_json_and_eval_file(run_dir, tmp_path, capsys):
    rel = write_relations(tmp_path / "r.relations", [(0, 1), (1, 2), (0, 2)])
    assert main(["eval", str(run_dir), "--relations", str(rel), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    stats = printed["relations"]
    for key in ("count", "trans_mean", "trans_std", "rot_mean_deg", "rot_std_deg"):
        assert key in stats
    # Hand-computed in tests/test_relations.py: errors (0.1, 0.1, 0) m and (0, 0.1, 0.1) rad.
    assert stats["count"] == 3 and stats["unmatched"] == 0
    assert stats["trans_mean"] == pytest.approx(0.2 / 3, abs=1e-6)
    assert stats["rot_mean_deg"] == pytest.approx(math.degrees(0.2 / 3), abs=1e-5)
    assert json.loads((run_dir / "eval.json").read_text()) == printed
    assert not list(run_dir.glob(".eval*"))  # no temporary file left behind


def test_relations_table(run_dir, tmp_path, capsys):
    rel = write_relations(tmp_path / "r.relations", [(0, 1), (1, 2)])
    assert main(["eval", str(run_dir), "--relations", str(rel)]) == 0
    out = capsys.readouterr().out
    assert "2 of 2 (0 unmatched" in out
    assert "translation  mean 0.1000 m  std 0.0000 m" in out
    assert (run_dir / "eval.json").is_file()


def test_unmatched_relations_warn_and_are_counted(run_dir, tmp_path, capsys):
    rel = write_relations(
        tmp_path / "r.relations", [(0, 1)], extra="5.0 6.0 1 0 0 0 0 0\n7.0 8.0 1 0 0 0 0 0\n"
    )
    assert main(["eval", str(run_dir), "--relations", str(rel), "--json"]) == 0
    captured = capsys.readouterr()
    stats = json.loads(captured.out)["relations"]
    assert stats["count"] == 1 and stats["unmatched"] == 2 and stats["total"] == 3
    assert stats["unmatched_first"] == [[5.0, 6.0], [7.0, 8.0]]
    assert "2 of 3 relations" in captured.err and "match no pose" in captured.err


def test_reference_json(run_dir, tmp_path, capsys):
    reference = tmp_path / "truth.tum"
    moved = compose(np.array([1.0, -2.0, 0.5]), TRUTH)  # the truth in another frame
    write_tum(reference, Trajectory(TIMES, moved))
    code = main(["eval", str(run_dir), "--reference", str(reference), "--json", "--delta", "1"])
    assert code == 0
    printed = json.loads(capsys.readouterr().out)
    for key in ("ate_rmse", "ate_mean", "ate_max", "rpe_trans_mean", "rpe_rot_mean_deg"):
        assert isinstance(printed[key], float)
    assert printed["matched"] == 3 and printed["excluded"] == 0
    assert printed["rpe_pairs"] == 2
    # RPE needs no alignment: pair errors are 0.1 m (0->1) and 0.1 m (1->2), as in the relations.
    assert printed["rpe_trans_mean"] == pytest.approx(0.1, abs=1e-6)
    assert json.loads((run_dir / "eval.json").read_text()) == printed


def test_reference_table(run_dir, tmp_path, capsys):
    reference = tmp_path / "truth.tum"
    write_tum(reference, Trajectory(TIMES, ESTIMATE))
    assert main(["eval", str(run_dir), "--reference", str(reference)]) == 0
    out = capsys.readouterr().out
    assert "ATE        rmse 0.0000 m" in out
    assert "2 pairs 1 frames apart" in out


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


def test_missing_trajectory(tmp_path, capsys):
    rel = write_relations(tmp_path / "r.relations", [(0, 1)])
    (tmp_path / "empty").mkdir()
    assert main(["eval", str(tmp_path / "empty"), "--relations", str(rel)]) == 2
    assert "empty/trajectory.tum: trajectory file not found" in one_line_error(capsys)
    assert main(["eval", str(tmp_path / "nope"), "--relations", str(rel)]) == 2
    assert "nope: run folder not found" in one_line_error(capsys)


def test_bad_relations_line(run_dir, tmp_path, capsys):
    rel = write_relations(tmp_path / "r.relations", [(0, 1)], extra="1 2 3 four 5 6 7 8\n")
    assert main(["eval", str(run_dir), "--relations", str(rel)]) == 2
    assert "r.relations:3: y: expected a number, found 'four'" in one_line_error(capsys)
    assert not (run_dir / "eval.json").exists()


def test_no_relation_matches(run_dir, tmp_path, capsys):
    rel = write_relations(tmp_path / "r.relations", [(0, 1)], times=TIMES + 1000)
    assert main(["eval", str(run_dir), "--relations", str(rel)]) == 2
    assert "none of its 1 relations matches" in one_line_error(capsys)


def test_usage_errors(run_dir, capsys):
    # Without ground truth `slam eval` scores the map, which needs the run's config.toml.
    assert main(["eval", str(run_dir)]) == 2
    assert "run/config.toml: not found" in one_line_error(capsys)
    assert main(["eval", str(run_dir), "--reference", str(run_dir / "trajectory.tum"),
                 "--delta", "0.5"]) == 2  # fmt: skip
    assert "expected a whole number" in one_line_error(capsys)


def test_console_entry_point_exit_code(run_dir, tmp_path):
    rel = write_relations(tmp_path / "r.relations", [(0, 1)], extra="1 2 3\n")
    proc = subprocess.run(
        [sys.executable, "-m", "slam", "eval", str(run_dir), "--relations", str(rel)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        f"slam: error: {rel}:3: expected 8 columns 't1 t2 x y z roll pitch yaw', found 3"
    )


def test_intel_odometry_through_the_cli(carmen_dir, tmp_path, capsys):
    """The raw FLASER odometry of intel, written as a run folder, evaluated by the CLI."""
    from slam.io.carmen import load_carmen

    log = load_carmen(carmen_dir / "intel.clf.gz")
    folder = tmp_path / "intel-odometry"
    write_tum(folder / "trajectory.tum", Trajectory(log.scans.time, log.scans.odometry))
    rel = carmen_dir / "relations" / "intel.relations"
    assert main(["eval", str(folder), "--relations", str(rel), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)["relations"]
    assert stats["count"] == 2984 and stats["unmatched"] == 0
    assert stats["trans_mean"] > 1.0  # dead reckoning; the figure itself is reported, not pinned


def test_eval_replaces_no_file_in_a_folder_slam_did_not_make(run_dir, tmp_path, capsys):
    """The bug: `slam eval` on a folder of another tool's trajectory replaced the user's own
    eval.json. It writes one where there is none, and otherwise says why it did not."""
    rel = write_relations(tmp_path / "r.relations", [(0, 1), (1, 2)])
    assert main(["eval", str(run_dir), "--relations", str(rel), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert json.loads((run_dir / "eval.json").read_text()) == first  # none was there
    (run_dir / "eval.json").write_text("mine\n")
    assert main(["eval", str(run_dir), "--relations", str(rel), "--json"]) == 0
    captured = capsys.readouterr()
    message = (
        f"{run_dir / 'eval.json'} not written: it exists, and {run_dir} is not a folder slam made"
    )
    assert f"slam: warning: {message}\n" in captured.err
    assert json.loads(captured.out)["warnings"] == [message]
    assert (run_dir / "eval.json").read_text() == "mine\n"


def test_a_non_numeric_tum_field_names_its_column(tmp_path):
    """The message names the column and what it holds (it quoted the whole line before)."""
    from slam.errors import DataError
    from slam.io.tum import read_tum

    path = tmp_path / "t.tum"
    path.write_text("# t x y z qx qy qz qw\n0 0 0 0 0 0 0 1\n1 0 0.5x 0 0 0 0 1\n")
    with pytest.raises(DataError) as caught:
        read_tum(path)
    assert str(caught.value) == f"{path}:3: column 3 (ty): expected a number, found '0.5x'"
