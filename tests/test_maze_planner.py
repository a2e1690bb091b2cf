"""Step-optimal planning: hand-made optima, the heading-free equality, the Udacity optima."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slam.errors import DataError
from slam.maze.formats import EAST, NORTH, maze_from_walls, read_maze
from slam.maze.planner import (
    apply_action,
    lower_bound,
    optimal_plan,
    plan_run,
    step_distances,
)
from slam.maze.referee import RESET, run_trial


def test_open_field_needs_one_step_per_axis():
    maze = maze_from_walls(4, 4)  # goal (1,1)..(2,2)
    plan = optimal_plan(maze)
    assert plan.steps == 2
    assert maze.goal_mask()[plan.poses[-1][:2]]


def test_long_corridor_takes_three_cells_per_step():
    # a 1-wide corridor up column 0 to (0,7), then the goal is the far corner (row 7 is open)
    walls = [((0, y), EAST) for y in range(7)]
    maze = maze_from_walls(8, 8, walls, goal=[(7, 7)])
    plan = optimal_plan(maze)
    # 7 cells north: 3 + 3 + 1, then 7 cells east: 3 + 3 + 1
    assert plan.steps == 6
    assert sorted(abs(m) for _, m in plan.actions) == [1, 1, 3, 3, 3, 3]
    assert plan.poses[-1][:2] == (7, 7)


def test_plan_actions_replay_to_the_goal_under_the_tester():
    maze = maze_from_walls(6, 6, [((0, 0), NORTH), ((1, 1), EAST), ((2, 3), NORTH)])
    plan = optimal_plan(maze)
    pose = (0, 0, 0)
    for action, expected in zip(plan.actions, plan.poses, strict=True):
        pose = apply_action(pose, *action)
        assert pose == expected

    class Replay:
        def __init__(self):
            self.queue = [*plan.actions, RESET, *plan.actions]

        def next_move(self, sensors):
            return self.queue.pop(0)

    result = run_trial(maze, Replay())
    assert result.run_steps == [plan.steps + 1, plan.steps]
    assert result.events["wall_stop"] == 0


def test_unreachable_goal():
    walls = [((1, y), EAST) for y in range(4)]  # a full wall between columns 1 and 2
    maze = maze_from_walls(4, 4, walls, goal=[(3, 3)])
    assert plan_run(maze.open_mask, (0, 0, 0), maze.goal_mask()) is None
    with pytest.raises(DataError, match="no goal cell can be reached"):
        optimal_plan(maze)


def test_lower_bound_adds_the_same_steps_at_one_thirtieth():
    assert lower_bound(30) == pytest.approx(31.0)
    assert lower_bound(17) == pytest.approx(17 + 17 / 30)


walls_strategy = st.lists(
    st.tuples(st.integers(0, 5), st.integers(0, 5), st.integers(0, 3)), max_size=30
)


@settings(max_examples=60, deadline=None)
@given(walls_strategy, st.integers(0, 3))
def test_heading_never_costs_a_step(walls, start_heading):
    """BFS over (cell, heading) equals BFS over cells: a turn always fits inside a move."""
    maze = maze_from_walls(6, 6, [((x, y), d) for x, y, d in walls])
    dist = step_distances(maze.open_mask, maze.goal_mask())
    plan = plan_run(maze.open_mask, (0, 0, start_heading), maze.goal_mask())
    if dist[0, 0] < 0:
        assert plan is None
    else:
        assert plan is not None and plan.steps == dist[0, 0]


def test_udacity_optima_are_17_22_25(data_dir: Path):
    steps = []
    for number in (1, 2, 3):
        maze = read_maze(data_dir / "maze" / "udacity" / f"test_maze_0{number}.txt")
        plan = optimal_plan(maze)
        steps.append(plan.steps)
        dist = step_distances(maze.open_mask, maze.goal_mask())
        assert dist[0, 0] == plan.steps
        assert np.count_nonzero(dist < 0) == 0  # every cell can reach the goal
    assert steps == [17, 22, 25]
