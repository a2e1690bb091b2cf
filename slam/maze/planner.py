"""Step-optimal planning on a known maze: the fewest Udacity steps from a pose to the goal.

A step turns by -90, 0 or +90 degrees and then moves up to three cells forwards or backwards
(:mod:`slam.maze.kernels` holds the breadth-first searches). The planner searches over
(cell, heading), so the plan it returns is a list of ``(rotation, movement)`` actions the robot
can send as they are. In this action set the heading never costs a step (a perpendicular move
turns in the same step, a move straight back needs no turn), so the step count equals a
breadth-first search over cells alone; the tests check that equality.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError
from slam.maze.formats import DX, DY, Maze
from slam.maze.kernels import bfs_cells, bfs_poses

MAX_MOVE = 3
"""Cells a single step may move (the Udacity tester clamps movement to -3..3)."""

ROTATIONS = (-90, 0, 90)

Pose = tuple[int, int, int]


@dataclass(frozen=True)
class Plan:
    """Actions from a start pose, and the pose after each of them."""

    actions: tuple[tuple[int, int], ...]
    poses: tuple[Pose, ...]

    @property
    def steps(self) -> int:
        """Number of steps (actions) of the plan."""
        return len(self.actions)


def decode_action(code: int, max_move: int = MAX_MOVE) -> tuple[int, int]:
    """``(rotation in degrees, movement in cells)`` of a kernel action code."""
    span = 2 * max_move + 1
    return ROTATIONS[code // span], code % span - max_move


def apply_action(pose: Pose, rotation: int, movement: int) -> Pose:
    """The pose after ``(rotation, movement)``, assuming no wall stops the move."""
    x, y, h = pose
    h = (h + rotation // 90) % 4
    d = h if movement >= 0 else (h + 2) % 4
    k = abs(movement)
    return x + DX[d] * k, y + DY[d] * k, h


def _state_index(pose: Pose, height: int) -> int:
    x, y, h = pose
    return (x * height + y) * 4 + h


def _state_pose(state: int, height: int) -> Pose:
    cell, h = divmod(int(state), 4)
    x, y = divmod(cell, height)
    return x, y, h


def pose_search(
    open_mask: NDArray[np.uint8],
    pose: Pose,
    stop_mask: NDArray[np.bool_] | None = None,
    max_move: int = MAX_MOVE,
    early_stop: bool = False,
) -> tuple[NDArray[np.int32], NDArray[np.int64], NDArray[np.int32], int]:
    """Breadth-first search over poses from ``pose``: ``(dist, parent, action, found)``.

    ``dist`` has shape ``(width, height, 4)``; ``parent`` and ``action`` are flat per pose index
    (see :func:`path_to`); ``found`` is the first pose index in ``stop_mask`` or -1.
    """
    mask = np.ascontiguousarray(open_mask, dtype=np.uint8)
    if stop_mask is None:
        stop_mask = np.zeros(mask.shape, dtype=np.bool_)
    dist, parent, action, found = bfs_poses(
        mask, int(pose[0]), int(pose[1]), int(pose[2]), max_move, stop_mask, early_stop
    )
    width, height = mask.shape
    return dist.reshape(width, height, 4), parent, action, int(found)


def path_to(
    parent: NDArray[np.int64],
    action: NDArray[np.int32],
    target: Pose,
    height: int,
    max_move: int = MAX_MOVE,
) -> Plan:
    """Actions leading to ``target`` in a :func:`pose_search` tree."""
    state = _state_index(target, height)
    actions: list[tuple[int, int]] = []
    poses: list[Pose] = []
    while parent[state] >= 0:
        actions.append(decode_action(int(action[state]), max_move))
        poses.append(_state_pose(state, height))
        state = int(parent[state])
    actions.reverse()
    poses.reverse()
    return Plan(tuple(actions), tuple(poses))


def plan_run(
    open_mask: NDArray[np.uint8],
    start: Pose,
    goal_mask: NDArray[np.bool_],
    max_move: int = MAX_MOVE,
) -> Plan | None:
    """Fewest-step plan from ``start`` until the robot stands in a goal cell (``None``: no way).

    Moves only over sides that are open in ``open_mask``; the goal counts only where a step
    *ends*, as in the tester (passing through a goal cell mid-move does not finish a run).
    """
    _, parent, action, found = pose_search(open_mask, start, goal_mask, max_move, early_stop=True)
    if found < 0:
        return None
    height = open_mask.shape[1]
    return path_to(parent, action, _state_pose(found, height), height, max_move)


def step_distances(
    open_mask: NDArray[np.uint8], sources: NDArray[np.bool_], max_move: int = MAX_MOVE
) -> NDArray[np.int32]:
    """Fewest steps between every cell and the nearest source cell (-1: unreachable)."""
    return bfs_cells(
        np.ascontiguousarray(open_mask, dtype=np.uint8),
        np.ascontiguousarray(sources, dtype=np.bool_),
        max_move,
    )


def optimal_plan(maze: Maze, max_move: int = MAX_MOVE) -> Plan:
    """The step-optimal run-1 plan on the true maze, from the start facing north."""
    if not maze.goal:
        raise DataError(f"{maze.name or 'maze'}: no goal cells (none marked 'G')")
    if maze.start in maze.goal:
        raise DataError(
            f"{maze.name or 'maze'}: the start cell {maze.start} is a goal cell (goal "
            f"{sorted(maze.goal)}): expected a start outside the goal (a Udacity maze of side 4 "
            "or more)"
        )
    plan = plan_run(maze.open_mask, (*maze.start, 0), maze.goal_mask(), max_move)
    if plan is None:
        raise DataError(
            f"{maze.name or 'maze'}: no goal cell can be reached from the start {maze.start}"
        )
    return plan


def lower_bound(optimal_steps: int, exploration_weight: float = 1 / 30) -> float:
    """Score no robot can beat: the optimal run 1 plus the same steps, weighted, for run 0."""
    return optimal_steps * (1.0 + exploration_weight)
