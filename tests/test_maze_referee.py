"""The referee follows the Udacity tester: sensors, moves, resets, the step limit, the score."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from slam.errors import DataError
from slam.maze.formats import DX, DY, EAST, NORTH, maze_from_walls, read_maze
from slam.maze.kernels import ray_lengths
from slam.maze.referee import RESET, MazeInfo, run_trial, sense
from slam.maze.robots import WallKnowledge, make_robot


class Scripted:
    """Replays a list of actions, then repeats the last one; records what it sensed."""

    def __init__(self, actions):
        self.actions = list(actions)
        self.calls = 0
        self.sensed = []

    def next_move(self, sensors):
        self.sensed.append(sensors)
        action = self.actions[min(self.calls, len(self.actions) - 1)]
        self.calls += 1
        return action


def corridor_maze():
    """4x4 open field, goal centre 2x2; a wall north of (0,1) stops moves up the first column."""
    return maze_from_walls(4, 4, [((0, 1), NORTH)], name="corridor")


def test_sensors_read_left_front_right_open_cells():
    maze = corridor_maze()
    robot = Scripted([(0, 1), (90, 0), (90, 0)])
    run_trial(maze, robot, max_steps=3)
    # at (0,0) facing north: left = west border, front = 1 cell to the wall, right = 3 cells
    assert robot.sensed[0] == (0, 1, 3)
    # at (0,1) facing north: front blocked by the wall
    assert robot.sensed[1] == (0, 0, 3)
    # turned east at (0,1): left (north) blocked, front 3, right (south) 1
    assert robot.sensed[2] == (0, 3, 1)


def test_wall_stops_a_move_silently():
    maze = corridor_maze()
    result = run_trial(maze, Scripted([(0, 3)]), max_steps=1)
    assert (result.x[0], result.y[0]) == (0, 1)
    assert result.moved[0] == 1 and result.movement[0] == 3
    assert result.events["wall_stop"] == 1


def test_movement_clamped_backwards_moves_and_invalid_rotation():
    maze = maze_from_walls(4, 4)
    robot = Scripted([(0, 5), (0, -2), (45, 1), (90, -1)])
    result = run_trial(maze, robot, max_steps=4)
    assert [
        (int(x), int(y), int(h)) for x, y, h in zip(result.x, result.y, result.heading, strict=True)
    ] == [
        (0, 3, 0),  # 5 clamped to 3
        (0, 1, 0),  # backwards, still facing north
        (0, 2, 0),  # 45 is not a rotation: ignored, the move still happens
        (0, 2, 1),  # turn east, then one cell back: into the west border, no move
    ]
    assert result.events["movement_clamped"] == 1
    assert result.events["invalid_rotation"] == 1
    assert result.events["wall_stop"] == 1


def test_reset_is_refused_before_the_goal_and_counts_as_a_step():
    maze = maze_from_walls(4, 4)  # goal (1,1)..(2,2)
    actions = [RESET, (0, 1), (90, 1), RESET, (0, 1), (90, 1)]
    result = run_trial(maze, Scripted(actions))
    assert result.events["reset_refused"] == 1
    assert result.reset[0] and (result.x[0], result.y[0]) == (0, 0)  # stayed put
    assert result.run_steps == [4, 2]  # refused reset, two moves, the accepted reset
    assert result.score == pytest.approx(2 + 4 / 30)
    assert result.run.tolist() == [0, 0, 0, 0, 1, 1]


def test_goal_counts_only_where_a_step_ends():
    maze = maze_from_walls(4, 4)
    # to (0,1); turn east and move 3: through goal cells (1,1) and (2,1), ending at (3,1)
    actions = [(0, 1), (90, 3), RESET, (-90, 1), (-90, 1), RESET, (0, 1), (90, 1)]
    result = run_trial(maze, Scripted(actions))
    assert (result.x[1], result.y[1]) == (3, 1)
    assert (result.x[3], result.y[3]) == (3, 2)  # turned north, moved: still outside the goal
    assert (result.x[4], result.y[4]) == (2, 2)  # turned west, moved: inside the goal
    assert result.events["reset_refused"] == 1  # only the first reset: the goal was just passed
    assert result.run_steps == [6, 2]


def test_run_one_ends_on_entering_the_goal_and_refuses_resets():
    maze = maze_from_walls(4, 4)
    actions = [(0, 1), (90, 1), RESET, RESET, (0, 1), (90, 1), (0, 1)]
    result = run_trial(maze, Scripted(actions))
    assert result.success
    assert result.run_steps == [3, 3]  # the refused reset in run 1 is a lost step
    assert result.events["reset_refused"] == 1
    assert result.total_steps == 6  # the last scripted action is never asked for
    assert result.score == pytest.approx(3 + 3 / 30)


def test_step_limit_is_global_and_fails_the_trial():
    maze = maze_from_walls(4, 4)
    spinner = Scripted([(90, 0)])
    result = run_trial(maze, spinner)
    assert spinner.calls == 1000  # the 1001st step is over the limit before the robot is asked
    assert not result.success and result.score is None
    assert result.failure == "step limit of 1000 exceeded in run 0"
    # a robot that resets at step 10 has 990 steps left for run 1
    late = Scripted([(0, 1), (90, 1)] + [(90, 0)] * 7 + [RESET] + [(90, 0)])
    result = run_trial(maze, late)
    assert result.run_steps == [10]
    assert late.calls == 1000
    assert result.failure == "step limit of 1000 exceeded in run 1"


def test_trial_needs_a_goal():
    maze = maze_from_walls(4, 4, goal=[])
    with pytest.raises(DataError, match="no goal cells"):
        run_trial(maze, Scripted([(0, 1)]))


def _tester_dist_to_wall(maze, x, y, d):
    """The tester's ``dist_to_wall``, written out independently."""
    distance = 0
    while maze.open_mask[x, y] >> d & 1:
        distance += 1
        x, y = x + DX[d], y + DY[d]
    return distance


def test_sensor_rays_match_the_tester_everywhere(data_dir: Path):
    for number in (1, 2, 3):
        maze = read_maze(data_dir / "maze" / "udacity" / f"test_maze_0{number}.txt")
        rays = ray_lengths(maze.open_mask)
        for x in range(maze.width):
            for y in range(maze.height):
                for h in range(4):
                    expected = tuple(
                        _tester_dist_to_wall(maze, x, y, (h + r) % 4) for r in (-1, 0, 1)
                    )
                    assert sense(rays, x, y, h) == expected


def test_history_replays_the_robot_knowledge():
    """A recorder can rebuild what the robot knew after each step from the history alone."""
    maze = maze_from_walls(6, 6, [((0, 0), EAST), ((1, 2), NORTH), ((3, 3), EAST), ((4, 1), NORTH)])
    info = MazeInfo(maze.width, maze.height, maze.goal, maze.start)
    result = run_trial(maze, make_robot("bounded", info), "bounded")
    assert result.success
    replay = WallKnowledge(maze.width, maze.height)
    pose = (0, 0, 0)
    for i in range(result.total_steps):
        replay.integrate(pose, tuple(result.sensors[i]), int(result.step[i]))
        if result.reset[i] and result.run[i] == 0:
            pose = (0, 0, 0)
        else:
            pose = (int(result.x[i]), int(result.y[i]), int(result.heading[i]))
    known = replay.known_at_edges()
    assert result.walls_known_at is not None
    for key in ("vertical", "horizontal"):
        np.testing.assert_array_equal(known[key], result.walls_known_at[key])
    assert result.walls_known_at["vertical"].shape == (7, 6)
    assert result.walls_known_at["horizontal"].shape == (6, 7)
    # the border is known before the first step, nothing is learnt after the last one
    assert result.walls_known_at["vertical"][0, :].tolist() == [0] * 6
    assert result.walls_known_at["vertical"].max() <= result.total_steps
    out = json.loads(json.dumps(result.to_dict()))
    assert len(out["history"]["step"]) == result.total_steps
    assert out["path"]["run1"][0] == [0, 0]
    assert out["run0_steps"] + out["run1_steps"] == result.total_steps
