"""``slam maze run|bench|show|convert`` end to end."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest

from slam.cli import main
from slam.maze.formats import EAST, NORTH, maze_from_walls, read_maze, write_maze


@pytest.fixture
def maze_dir(tmp_path: Path) -> Path:
    folder = tmp_path / "mazes"
    write_maze(maze_from_walls(6, 6, [((0, 0), EAST), ((2, 2), NORTH)]), folder / "a.txt", "ascii")
    write_maze(maze_from_walls(4, 4, [((1, 0), NORTH)]), folder / "b.txt", "udacity")
    return folder


def test_run_prints_score_steps_and_path(maze_dir, capsys):
    assert main(["maze", "run", str(maze_dir / "b.txt"), "--robot", "explore-all"]) == 0
    out = capsys.readouterr().out
    assert "maze b (4x4), robot explore-all" in out
    assert "optimal run 1: 2 steps" in out
    assert "run 1 path: (0,0)" in out


def test_run_json_carries_history_for_a_recorder(maze_dir, capsys):
    assert main(["maze", "run", str(maze_dir / "a.txt"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["success"] and out["robot"] == "bounded"
    assert out["score"] == pytest.approx(out["run1_steps"] + out["run0_steps"] / 30, abs=1e-6)
    assert out["run1_steps"] == out["optimal_run1_steps"]
    history = out["history"]
    n = out["total_steps"]
    assert {len(history[k]) for k in ("step", "run", "sensors", "x", "y", "heading")} == {n}
    assert history["step"] == list(range(1, n + 1))
    known = out["walls_known_at"]
    assert len(known["vertical"]) == 7 and len(known["vertical"][0]) == 6
    assert len(known["horizontal"]) == 6 and len(known["horizontal"][0]) == 7


def test_bench_table_and_json(maze_dir, tmp_path, capsys):
    closed = maze_from_walls(4, 4, [((0, 0), NORTH), ((0, 0), EAST)])  # start boxed in
    write_maze(closed, maze_dir / "c.txt", "ascii")
    assert main(["maze", "bench", str(maze_dir), "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert "unsolvable: c: no goal cell can be reached" in out
    assert "3 mazes, 2 finished, 0 failures" in out
    assert "mean score/bound" in out
    assert main(["maze", "bench", str(maze_dir / "a.txt"), "--json", "--robot", "block-out"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["robot"] == "block-out"
    assert report["summary"]["finished"] == 1
    row = report["rows"][0]
    assert row["ratio"] == pytest.approx(row["score"] / row["bound"])
    # an unreadable file is bad input: the table, then one error line and exit 2 (it was exit 0)
    (maze_dir / "empty.txt").write_text("")
    assert main(["maze", "bench", str(maze_dir), "--jobs", "1"]) == 2
    captured = capsys.readouterr()
    assert "4 mazes" in captured.out
    assert captured.err.startswith(
        "slam: error: 1 of the 4 maze files could not be read; the first: "
    )
    assert "empty.txt" in captured.err and captured.err.count("\n") == 1


def test_show_writes_a_png(maze_dir, tmp_path, capsys):
    out = tmp_path / "pictures" / "a.png"
    assert main(["maze", "show", str(maze_dir / "a.txt"), "--out", str(out), "--cell", "20"]) == 0
    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] == 6 * 20 + 20
    walls = ["maze", "show", str(maze_dir / "a.txt"), "--out", str(out), "--walls-only"]
    assert main([*walls, "--cell", "20"]) == 2  # the file exists: left alone without --force
    assert "exists; it was left alone" in capsys.readouterr().err
    assert main([*walls, "--cell", "20", "--force"]) == 0
    assert cv2.imread(str(out)).shape[0] == 6 * 20 + 20


def test_outputs_replace_no_file_without_force(maze_dir, tmp_path, capsys):
    """The bug: `slam maze convert`, `maze show --out`, `maze run --record` (and `slam grid`'s
    outputs) replaced a user's file of that name without a word."""
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    record = tmp_path / "keep.rrd"
    record.write_text("mine")
    picture = tmp_path / "mine.jpg"
    for argv, message in (
        (["maze", "convert", str(maze_dir / "a.txt"), str(notes)], f"OUT {notes}: exists"),
        (["maze", "run", str(maze_dir / "a.txt"), "--record", str(record)], f"--record {record}: exists"),
        (["maze", "show", str(maze_dir / "a.txt"), "--out", str(picture)], f"--out {picture}: expected a .png file name"),
        (["grid", "run", "tutorial-1d", "--record", str(record)], f"--record {record}: exists"),
    ):  # fmt: skip
        assert main(argv) == 2, argv
        assert message in capsys.readouterr().err
    assert notes.read_text() == "mine" and record.read_text() == "mine"
    assert not picture.exists()


def test_convert_round_trip(maze_dir, tmp_path):
    ascii_out = tmp_path / "b_ascii.txt"
    udacity_out = tmp_path / "b_udacity.txt"
    assert main(["maze", "convert", str(maze_dir / "b.txt"), str(ascii_out)]) == 0
    assert ascii_out.read_text().startswith("o---o")
    assert main(["maze", "convert", str(ascii_out), str(udacity_out)]) == 0
    assert udacity_out.read_text() == (maze_dir / "b.txt").read_text()


def test_errors_are_one_line_and_exit_2(maze_dir, capsys):
    assert main(["maze", "run", str(maze_dir / "missing.txt")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "maze" in err[0] and "not found" in err[0]
    assert main(["maze", "run", str(maze_dir / "a.txt"), "--set", "payoff"]) == 2
    assert "--set expects KEY=VALUE" in capsys.readouterr().err
    assert main(["maze", "run", str(maze_dir / "a.txt"), "--set", "payoff=1\nx=2"]) == 2
    assert capsys.readouterr().err == (
        "slam: error: --set payoff: expected one value on one line, found a line break in "
        "'1\\nx=2'\n"
    )
    bad = maze_dir / "bad.txt"
    bad.write_text("2\n1,6\n1,4\n")
    assert main(["maze", "run", str(bad)]) == 2
    assert "inconsistent walls" in capsys.readouterr().err


def test_data_relative_names(data_dir, capsys):
    assert main(["maze", "run", "udacity/test_maze_01", "--data-dir", str(data_dir)]) == 0
    out = capsys.readouterr().out
    assert "score 19.633" in out and "optimal run 1: 17 steps" in out
    assert read_maze(data_dir / "maze" / "udacity" / "test_maze_01.txt").width == 12


def test_a_start_inside_the_goal_is_one_error(tmp_path, capsys):
    """The bug: a 2×2 Udacity maze (the centre goal covers the start) ended in an IndexError
    traceback in every robot."""
    maze = tmp_path / "u2.txt"
    maze.write_text("2\n0,0\n0,0\n")
    assert main(["maze", "run", str(maze)]) == 2
    assert capsys.readouterr().err == (
        "slam: error: u2: the start cell (0, 0) is a goal cell (goal [(0, 0), (0, 1), (1, 0), "
        "(1, 1)]): expected a start outside the goal (a Udacity maze of side 4 or more)\n"
    )
