"""Robots: they always know where they are, finish, and score what the docs say."""

from __future__ import annotations

from pathlib import Path

import pytest

from slam.errors import UsageError
from slam.maze.bench import bench_one, summarize, trial
from slam.maze.formats import EAST, NORTH, SOUTH, WEST, maze_from_walls, read_maze
from slam.maze.planner import optimal_plan
from slam.maze.referee import RESET, MazeInfo, run_trial
from slam.maze.robots import ROBOTS, BoundedConfig, make_robot

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


# ------------------------------------------------------------------ real data

UDACITY = {
    # robot: (scores, [run 0, run 1] per maze); see docs/maze.md for the report's figures
    "explore-all": ([24.467, 32.233, 38.2], [[224, 17], [307, 22], [396, 25]]),
    "block-out": ([23.5, 34.467, 40.467], [[45, 22], [74, 32], [74, 38]]),
    "bounded": ([19.667, 26.933, 30.6], [[80, 17], [148, 22], [168, 25]]),
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
    assert summary["mean_ratio"] == pytest.approx(1.1667, abs=1e-3)
    assert summary["run1_optimal"] == 19
