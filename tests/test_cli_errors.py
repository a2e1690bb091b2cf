"""Bad input on ``slam eval``, ``slam sim`` and ``slam texture``: one line naming the file, what
was expected and what was found, exit code 2, no traceback."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slam.cli import main
from slam.io.tum import write_tum
from slam.trajectory import Trajectory


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


def make_run(folder: Path) -> Path:
    folder.mkdir()
    write_tum(folder / "trajectory.tum", Trajectory(np.array([1.0, 2.0]), np.zeros((2, 3))))
    return folder


def test_eval_reference_or_relations_that_is_a_folder(tmp_path, capsys):
    run = make_run(tmp_path / "run")
    (tmp_path / "dir").mkdir()
    for option in ("--reference", "--relations"):
        assert main(["eval", str(run), option, str(tmp_path / "dir")]) == 2
        err = one_line_error(capsys)
        assert f"dir: {option} expected a file, found a folder" in err
    assert not (run / "eval.json").exists()


def test_eval_missing_trajectory_says_what_was_expected(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    (tmp_path / "r.relations").write_text("1 2 0 0 0 0 0 0\n")
    assert (
        main(["eval", str(tmp_path / "empty"), "--relations", str(tmp_path / "r.relations")]) == 2
    )
    err = one_line_error(capsys)
    assert "empty/trajectory.tum: trajectory file not found (expected the trajectory.tum" in err


def test_sim_out_that_is_a_file(tmp_path, capsys):
    out = tmp_path / "taken"
    out.write_text("x")
    assert main(["sim", "small", "--out", str(out), "--quiet"]) == 2
    assert "taken: --out expected a folder to create, found a file" in one_line_error(capsys)
    assert out.read_text() == "x"


def test_texture_map_with_bad_resolution_or_origin(tmp_path, capsys):
    run = make_run(tmp_path / "run")
    (run / "config.toml").write_text('dataset = "demo"\n')
    np.savez(
        run / "map.npz", log_odds=np.zeros((4, 4)), resolution=np.array([0.05, 0.05]), origin=[0, 0]
    )
    assert main(["texture", str(run), "--quiet"]) == 2
    err = one_line_error(capsys)
    assert (
        "map.npz: key 'resolution': expected one finite number > 0 (m), found array([0.05, 0.05])"
        in err
    )
    np.savez(run / "map.npz", log_odds=np.zeros((4, 4)), resolution=0.05, origin=np.zeros(3))
    assert main(["texture", str(run), "--quiet"]) == 2
    assert (
        "map.npz: key 'origin': expected 2 finite numbers (x, y), found array([0., 0., 0.])"
        in one_line_error(capsys)
    )
