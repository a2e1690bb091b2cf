"""Robots: they always know where they are, finish, and score what the docs say."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slam.errors import UsageError
from slam.maze.bench import bench_one, summarize, trial
from slam.maze.formats import DX, DY, EAST, NORTH, SOUTH, WEST, maze_from_walls, read_maze
from slam.maze.planner import optimal_plan
from slam.maze.referee import RESET, MazeInfo, run_trial
from slam.maze.robots import ROBOTS, BoundedConfig, contest_walls, make_robot

# A 6x6 hand-made maze with a dead end and two routes to the centre of different lengths.
HAND_WALLS = [
    ((0, 0), EAST),
    ((0, 2), EAST),
    ((1, 1), NORTH),
    ((1, 3), EAST),
    ((2, 1), EAST),
    ((2, 2), SOUTH),
    ((3, 3), EAST),
    ((3, 4), WEST),
    ((4, 2), NORTH),
    ((4, 0), NORTH),
    ((5, 4), SOUTH),
]


def hand_maze():
    return maze_from_walls(6, 6, HAND_WALLS, name="hand")


class PoseCheck:
    """Wraps a robot and checks after each step that its pose belief is the referee's pose."""

    def __init__(self, robot, maze):
        self.robot = robot
        self.maze = maze
        self.knowledge = robot.knowledge
        self.trace = []

    def next_move(self, sensors):
        action = self.robot.next_move(sensors)
        self.trace.append((action, self.robot.pose))
        return action


@pytest.mark.parametrize("name", list(ROBOTS))
def test_robots_finish_hand_made_maze_knowing_their_pose(name):
    maze = hand_maze()
    info = MazeInfo(maze.width, maze.height, maze.goal, maze.start)
    wrapper = PoseCheck(make_robot(name, info), maze)
    result = run_trial(maze, wrapper, name)
    assert result.success
    assert result.events == {
        "reset_refused": 0,
        "invalid_rotation": 0,
        "movement_clamped": 0,
        "wall_stop": 0,
    }
    for i, (action, believed) in enumerate(wrapper.trace):
        if action == RESET:
            assert believed == (0, 0, 0)
        else:
            assert believed == (int(result.x[i]), int(result.y[i]), int(result.heading[i]))
    optimal = optimal_plan(maze).steps
    assert result.run_steps[1] >= optimal
    if name in ("explore-all", "bounded"):
        assert result.run_steps[1] == optimal


def test_block_out_plans_through_visited_cells_only():
    maze = hand_maze()
    info = MazeInfo(maze.width, maze.height, maze.goal, maze.start)
    robot = make_robot("block-out", info)
    result = run_trial(maze, robot, "block-out")
    visited_run0 = result.visited_mask(0)
    for x, y in result.path(1):
        assert visited_run0[x, y]


def test_make_robot_options_and_errors():
    info = MazeInfo(4, 4, ((1, 1),))
    robot = make_robot("bounded", info, payoff=0.5, stride=2)
    assert robot.config == BoundedConfig(payoff=0.5, stride=2)
    with pytest.raises(UsageError, match="unknown maze robot 'wall-follower'"):
        make_robot("wall-follower", info)
    with pytest.raises(UsageError, match="unknown option"):
        make_robot("bounded", info, speed=2)
    with pytest.raises(UsageError, match="takes no options"):
        make_robot("block-out", info, payoff=1.0)
    with pytest.raises(UsageError, match="stride must be"):
        make_robot("bounded", info, stride=4)


def _set_side(mask, x, y, d):
    """Set side ``d`` of ``(x, y)`` and the neighbour's facing side in a bit-mask array."""
    mask[x, y] |= 1 << d
    mask[x + DX[d], y + DY[d]] |= 1 << ((d + 2) % 4)


def test_contest_walls_posts_and_goal_entrance():
    """A post with three open lines closes its fourth; a known entrance closes the goal rim."""
    goal = np.zeros((6, 6), dtype=np.bool_)
    goal[2:4, 2:4] = True
    rim = np.zeros((6, 6), dtype=np.uint8)
    for x, y in np.argwhere(goal):
        for d in range(4):
            if not goal[x + DX[d], y + DY[d]]:
                _set_side(rim, x, y, d)
    known_open = np.zeros((6, 6), dtype=np.uint8)  # every side a known wall, except:
    unknown = np.zeros((6, 6), dtype=np.uint8)
    # post (1, 1), the corner of cells (0, 0), (1, 0), (0, 1), (1, 1): three lines open ...
    _set_side(known_open, 0, 0, EAST)
    _set_side(known_open, 0, 1, EAST)
    _set_side(known_open, 0, 0, NORTH)
    _set_side(unknown, 1, 0, NORTH)  # ... and the fourth unknown: it must be a wall
    _set_side(unknown, 2, 1, NORTH)  # goal rim sides, unknown
    _set_side(unknown, 3, 1, NORTH)
    possible, posts_ok = contest_walls(known_open, unknown, goal, rim)
    assert posts_ok
    assert not possible[1, 0] >> NORTH & 1 and not possible[1, 1] >> SOUTH & 1
    assert possible[2, 1] >> NORTH & 1  # no entrance known yet: the rim stays possible
    possible, _ = contest_walls(known_open, unknown, goal, rim, posts=False)
    assert possible[1, 0] >> NORTH & 1  # no post inference when asked not to
    # an entrance is known: the other rim sides are walls
    entrance = known_open.copy()
    _set_side(entrance, 2, 3, NORTH)
    possible, _ = contest_walls(entrance, unknown, goal, rim)
    assert not (possible & rim).any() and not possible[2, 1] >> NORTH & 1
    # a post without walls in sight: the maze breaks the rule
    no_wall = known_open.copy()
    _set_side(no_wall, 1, 0, NORTH)
    _, posts_ok = contest_walls(no_wall, unknown & ~no_wall, goal, rim)
    assert not posts_ok


# ------------------------------------------------------------------ real data

UDACITY = {
    # robot: (scores, [run 0, run 1] per maze); see docs/maze.md for the report's figures
    "explore-all": ([24.467, 32.233, 38.2], [[224, 17], [307, 22], [396, 25]]),
    "block-out": ([23.5, 34.467, 40.467], [[45, 22], [74, 32], [74, 38]]),
    "bounded": ([19.633, 26.767, 30.2], [[79, 17], [143, 22], [156, 25]]),
}
BEST_PUBLIC = [20.667, 27.7, 30.667]


@pytest.mark.parametrize("name", list(UDACITY))
def test_udacity_scores(data_dir: Path, name):
    scores, steps = UDACITY[name]
    for i in range(3):
        maze = read_maze(data_dir / "maze" / "udacity" / f"test_maze_0{i + 1}.txt")
        result = trial(maze, name)
        assert result.run_steps == steps[i]
        assert result.score == pytest.approx(scores[i], abs=5e-4)
        if name == "bounded":
            assert result.score < BEST_PUBLIC[i]
        if name == "explore-all":
            assert result.run_steps[1] == [17, 22, 25][i]  # it mapped enough for the optimum


def test_classic_sample_no_failure(data_dir: Path):
    """20 of the 521 classic mazes (every 26th); the full set is `slam maze bench`."""
    paths = sorted((data_dir / "maze" / "micromouseonline" / "classic").glob("*.txt"))[2::26]
    rows = [bench_one(p) for p in paths]
    summary = summarize(rows)
    assert summary["finished"] == 20 and summary["failures"] == 0
    assert all(r.run0 + r.run1 <= 1000 for r in rows)
    assert summary["mean_ratio"] == pytest.approx(1.1592, abs=1e-3)
    assert summary["run1_optimal"] == 20
