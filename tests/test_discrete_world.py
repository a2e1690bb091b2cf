"""Grid worlds: parsing, random maps, neighbour masks, shifts and moves with bounce-back."""

import numpy as np
import pytest

from slam.discrete.world import (
    GridWorld,
    random_colour_world,
    shift,
    step,
    translate,
    world_from_rows,
)
from slam.errors import ConfigError

MAZE = [".......", ".....#.", ".#..#..", ".#..#..", ".......", "......."]


def test_rows_parse_obstacles_colours_and_legend():
    world = world_from_rows(["GR#", "R.G"], legend={"G": "green"})
    assert world.palette == ("green", "R")
    assert world.symbols == ("G", "R")
    assert world.labels.tolist() == [[0, 1, -1], [1, -1, 0]]
    assert world.blocked.tolist() == [[False, False, True], [False, False, False]]
    assert world.open_count == 5
    assert world.colour_index("green") == 0
    assert world.colour_index("g") == 0
    assert world.colour_index("R") == 1
    with pytest.raises(ConfigError, match="unknown colour 'blue'"):
        world.colour_index("blue")


@pytest.mark.parametrize(
    "rows, message",
    [
        (
            ["..", "..."],
            r"^world\.map\[1\]: expected non-empty rows of equal length, found lengths \[2, 3\]",
        ),
        ([], r"^world\.map: expected non-empty rows of equal length"),
        ([""], r"^world\.map\[0\]: expected non-empty rows"),
        (["##", "##"], "every cell is an obstacle"),
    ],
)
def test_bad_maps_are_config_errors(rows, message):
    with pytest.raises(ConfigError, match=message):
        world_from_rows(rows)


def test_random_world_with_counts_has_exactly_those_counts_and_is_seeded():
    palette = ("blue", "green", "red", "white")
    a = random_colour_world(10, 10, palette, np.random.default_rng(7), counts=[25, 25, 25, 25])
    b = random_colour_world(10, 10, palette, np.random.default_rng(7), counts=[25, 25, 25, 25])
    assert np.bincount(a.labels.ravel(), minlength=4).tolist() == [25, 25, 25, 25]
    assert np.array_equal(a.labels, b.labels)
    assert a.symbols == ("B", "G", "R", "W")
    with pytest.raises(ConfigError, match="summing to 100"):
        random_colour_world(10, 10, palette, np.random.default_rng(0), counts=[25, 25, 25, 24])


def test_can_move_respects_border_and_obstacles():
    world = world_from_rows(MAZE)
    n, e, s, w = world.can_move
    assert not n[0, 0] and not w[0, 0] and e[0, 0] and s[0, 0]
    # (1, 4) has the obstacle (1, 5) to the east and (2, 4) to the south
    assert not e[1, 4] and not s[1, 4] and n[1, 4] and w[1, 4]
    assert not world.can_move[:, world.blocked].any()
    assert world.neighbour_blocked[1, 1, 4] and world.neighbour_blocked[2, 1, 4]


def test_cyclic_world_wraps_neighbours():
    world = world_from_rows(["ab#", "abc"], cyclic=True)
    n, e, s, w = world.can_move
    assert not w[0, 0]  # wraps around to (0, 2), an obstacle
    assert not e[0, 1]
    assert w[1, 0] and e[1, 2] and n[0, 0] and s[1, 0]
    assert not world.neighbour_blocked[3, 1, 0]


def test_shift_bounded_drops_and_cyclic_wraps():
    a = np.arange(6.0).reshape(1, 2, 3)
    assert shift(a, 0, 1, cyclic=False)[0].tolist() == [[0, 0, 1], [0, 3, 4]]
    assert shift(a, 0, 1, cyclic=True)[0].tolist() == [[2, 0, 1], [5, 3, 4]]
    assert shift(a, -1, 0, cyclic=False)[0].tolist() == [[3, 4, 5], [0, 0, 0]]
    assert shift(a, 5, 0, cyclic=False).sum() == 0


def test_step_bounces_back_at_walls_and_obstacles():
    world = world_from_rows(["..#", "..."])
    belief = np.zeros((1, 2, 3))
    belief[0, 0, 1] = 0.5  # east of it is the obstacle
    belief[0, 1, 2] = 0.5  # east of it is the border
    moved = step(belief, world, 1)
    assert moved[0].tolist() == [[0, 0.5, 0], [0, 0, 0.5]]
    moved = step(belief, world, 3)  # west: both move
    assert moved[0].tolist() == [[0.5, 0, 0], [0, 0.5, 0]]


def test_translate_stops_at_the_first_obstacle():
    world = world_from_rows(["....#."])
    belief = np.zeros((1, 1, 6))
    belief[0, 0, 0] = 1.0
    assert np.argmax(translate(belief, world, 0, 5)[0, 0]) == 3
    cyclic = world_from_rows(["abcde"], cyclic=True)
    b = np.array([[[0.0, 0.5, 0.0, 0.5, 0.0]]])
    assert translate(b, cyclic, 0, 2)[0, 0].tolist() == [0.5, 0.0, 0.0, 0.5, 0.0]
    assert translate(b, cyclic, 0, 0) is not b


def test_uniform_belief_is_over_open_cells_and_headings():
    world = GridWorld(
        np.zeros((2, 2), np.int16), np.array([[1, 0], [0, 0]], bool), ("x",), headings=4
    )
    belief = world.uniform_belief()
    assert belief.shape == (4, 2, 2)
    assert belief[:, 0, 0].sum() == 0
    assert belief[0, 1, 1] == pytest.approx(1 / 12)
    with pytest.raises(ConfigError, match="world.headings"):
        GridWorld(np.zeros((1, 1), np.int16), np.zeros((1, 1), bool), ("x",), headings=2)
