"""Maze files: the Udacity and ASCII readers, writers, validation, round trips, lookup."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slam.errors import DataError, UsageError
from slam.maze.formats import (
    EAST,
    NORTH,
    SOUTH,
    WEST,
    detect_format,
    format_ascii,
    format_udacity,
    locate_maze,
    locate_mazes,
    maze_from_walls,
    parse_ascii,
    parse_maze,
    parse_udacity,
    read_maze,
    write_maze,
)

# The example of micromouseonline's FORMAT-README (4x4, goal top-left, start bottom-left).
README_EXAMPLE = """\
o---o---o---o---o
| G |           |
o   o   o   o---o
|       |       |
o---o---o---o   o
|               |
o   o---o---o   o
| S |           |
o---o---o---o---o
"""

# A 2x2 Udacity maze: column x=0 then x=1, values y=0..1; an open square with the wall
# between (0,0) and (1,0) closed.
UDACITY_2X2 = "2\n1,6\n1,12\n"


def test_udacity_reader_masks_goal_and_start():
    maze = parse_udacity(UDACITY_2X2)
    assert maze.width == maze.height == 2
    assert maze.open_mask.tolist() == [[1, 6], [1, 12]]
    assert maze.is_open(0, 0, NORTH) and not maze.is_open(0, 0, EAST)
    assert maze.is_open(0, 1, EAST) and maze.is_open(1, 1, WEST)
    assert sorted(maze.goal) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert maze.start == (0, 0)


def test_ascii_reader_on_the_readme_example():
    maze = parse_ascii(README_EXAMPLE)
    assert (maze.width, maze.height) == (4, 4)
    assert maze.goal == ((0, 3),)
    assert maze.start == (0, 0)
    # start cell: walls west, east, south; open north
    assert maze.open_mask[0, 0] == 1 << NORTH
    # goal cell (0,3): walls north, east, west; open south
    assert maze.open_mask[0, 3] == 1 << SOUTH
    # the wall under row 2 spans x = 0..2, x = 3 is open
    assert [maze.is_open(x, 2, SOUTH) for x in range(4)] == [False, False, False, True]
    assert format_ascii(maze) == README_EXAMPLE


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("3\n1,1,1\n1,1,1\n1,1,1\n", "even number"),
        ("x\n", "side length"),
        ("2\n1,6\n", "m.txt:2: expected 2 lines of masks after the size, found 1"),
        ("2\n1,6\n1,12\n3,4\n", "m.txt:4: expected 2 lines of masks after the size, found 3"),
        ("2\n1,6,0\n1,12\n", "expected 2 comma-separated"),
        ("2\n1,16\n1,12\n", "0..15, found 16"),
        ("2\n1,a\n1,12\n", "found 'a'"),
        # east side of (0,1) open, west side of (1,1) not: both sides named where they are written
        (
            "2\n1,6\n\n1,4\n",
            "(0,1) and (1,1) is open from the west cell (line 2, mask 2) but closed from the east "
            "cell (line 4, mask 2)",
        ),
        ("2\n9,6\n1,12\n", "outer west wall of (0,0) is open (line 2, mask 1)"),
    ],
)
def test_udacity_reader_errors_name_the_problem(text, message):
    with pytest.raises(DataError, match=None) as info:
        parse_udacity(text, source="m.txt")
    assert message in str(info.value)
    assert str(info.value).startswith("m.txt")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            README_EXAMPLE.replace("o---o---o---o---o\n| G", "o---+---o---o---o\n| G", 1),
            ":1:5: expected a post",
        ),
        (
            README_EXAMPLE.replace("o   o   o   o---o", "o   o - o   o---o", 1),
            "expected a wall '---'",
        ),
        (README_EXAMPLE.replace("|       |       |", "|     X |       |", 1), "inside cell (1,2)"),
        (README_EXAMPLE.replace("| G |", "| S |", 1), "a second start cell"),
        (
            README_EXAMPLE.replace("| S |           |", "  S |           |", 1),
            "outer west wall of (0,0) is open (line 8, column 1)",
        ),
        (  # blank lines before the maze count in the line numbers
            "\n\n" + README_EXAMPLE.replace("| S |           |", "  S |           |", 1),
            "outer west wall of (0,0) is open (line 10, column 1)",
        ),
        (
            "\n" + README_EXAMPLE.replace("o---o---o---o---o\n| G", "o---+---o---o---o\n| G", 1),
            ":2:5: expected a post",
        ),
        (README_EXAMPLE.replace("| S |", "| S\t|", 1), "a.txt:8:4: a tab"),
        ("\n".join(README_EXAMPLE.splitlines()[:-1]) + "\n", "odd number of lines"),
        ("o--o\n|  |\no--o\n", "north border"),
    ],
)
def test_ascii_reader_errors_name_the_problem(text, message):
    with pytest.raises(DataError) as info:
        parse_ascii(text, source="a.txt")
    assert message in str(info.value)


def test_format_detection_and_unknown_format():
    assert detect_format(UDACITY_2X2) == "udacity"
    assert detect_format("\n" + README_EXAMPLE) == "ascii"
    with pytest.raises(DataError, match="unknown maze format"):
        parse_maze("hello\n", source="h.txt")
    with pytest.raises(DataError, match=r"^h\.txt:2: unknown maze format: .* found 'hello'$"):
        parse_maze("\nhello\n", source="h.txt")
    with pytest.raises(DataError, match=r"^h\.txt: unknown maze format: the file is empty"):
        parse_maze("\n \n", source="h.txt")


def test_read_maze_names_the_line_of_a_non_ascii_byte(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_bytes(b"o---o\n| \xc3 |\no---o\n")
    with pytest.raises(DataError, match=r"bad\.txt:2:3: expected ASCII text, found byte 0xc3$"):
        read_maze(path)


def test_read_maze_accepts_crlf_line_ends(tmp_path):
    path = tmp_path / "crlf.txt"
    path.write_bytes(UDACITY_2X2.replace("\n", "\r\n").encode("ascii"))
    assert read_maze(path).same_walls(parse_udacity(UDACITY_2X2))


def test_round_trip_between_formats_on_hand_made_maze():
    maze = maze_from_walls(6, 6, [((0, 0), EAST), ((2, 2), NORTH), ((4, 1), WEST), ((5, 3), SOUTH)])
    ascii_text = format_ascii(maze)
    back = parse_ascii(ascii_text)
    assert back.same_walls(maze)
    assert sorted(back.goal) == sorted(maze.goal) and back.start == maze.start
    again = parse_udacity(format_udacity(back))
    assert again.same_walls(maze)
    assert format_ascii(again) == ascii_text


def test_udacity_writer_refuses_what_it_cannot_hold():
    odd = maze_from_walls(5, 5, goal=[(2, 2)])
    with pytest.raises(UsageError, match="even square"):
        format_udacity(odd)
    corner_goal = maze_from_walls(4, 4, goal=[(3, 3)])
    with pytest.raises(UsageError, match="centre 2x2"):
        format_udacity(corner_goal)


def test_write_maze_and_read_back(tmp_path):
    maze = maze_from_walls(4, 4, [((1, 1), EAST)], name="hand")
    write_maze(maze, tmp_path / "hand_ascii.txt", "ascii")
    write_maze(maze, tmp_path / "hand_udacity.txt", "udacity")
    assert read_maze(tmp_path / "hand_ascii.txt").same_walls(maze)
    assert read_maze(tmp_path / "hand_udacity.txt").same_walls(maze)
    assert read_maze(tmp_path / "hand_ascii.txt").name == "hand_ascii"
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind
    with pytest.raises(DataError, match="not found"):
        read_maze(tmp_path / "missing.txt")


def test_locate_plain_paths_and_data_names(tmp_path):
    folder = tmp_path / "maze" / "mine"
    folder.mkdir(parents=True)
    maze = maze_from_walls(4, 4)
    write_maze(maze, folder / "a.txt", "ascii")
    write_maze(maze, folder / "b.txt", "udacity")
    assert locate_maze(folder / "a.txt") == folder / "a.txt"
    assert locate_maze("mine/a", tmp_path) == folder / "a.txt"
    assert locate_maze("maze/mine/b.txt", tmp_path) == folder / "b.txt"
    assert locate_mazes(["mine"], tmp_path) == [folder / "a.txt", folder / "b.txt"]
    with pytest.raises(DataError, match="'mine/c' not found"):
        locate_maze("mine/c", tmp_path)


# ------------------------------------------------------------------ real data


def test_udacity_mazes_round_trip_through_ascii(data_dir: Path):
    for number in (1, 2, 3):
        path = data_dir / "maze" / "udacity" / f"test_maze_0{number}.txt"
        maze = read_maze(path)
        assert maze.width == {1: 12, 2: 14, 3: 16}[number]
        ascii_maze = parse_ascii(format_ascii(maze))
        assert ascii_maze.same_walls(maze)
        assert sorted(ascii_maze.goal) == sorted(maze.centre_goal())
        text = format_udacity(ascii_maze)
        assert text.split() == path.read_text().split()


def test_every_micromouseonline_maze_reads_and_rewrites_identically(data_dir: Path):
    root = data_dir / "maze" / "micromouseonline"
    files = sorted(root.glob("*/*.txt"))
    assert len(files) == 579
    classic = [f for f in files if f.parent.name == "classic"]
    assert len(classic) == 521
    for path in files:
        maze = read_maze(path)
        text = "\n".join(line.rstrip() for line in path.read_text().strip("\n").splitlines())
        if "S" in text:  # the training mazes mark no start; the writer always does
            assert format_ascii(maze) == text + "\n", path.name
        if path.parent.name == "classic":
            assert (maze.width, maze.height, maze.start) == (16, 16, (0, 0))
            assert sorted(maze.goal) == [(7, 7), (7, 8), (8, 7), (8, 8)]
    assert np.all(read_maze(classic[0]).open_mask <= 15)
