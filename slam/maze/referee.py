"""The referee: the Udacity tester's rules, step for step, and the record of a trial.

:func:`run_trial` replays ``tester.py`` of "Plot and Navigate a Virtual Maze" exactly:

* one global step counter; each step first adds one, and a count above ``max_steps`` (1000)
  ends the trial as a failure before the robot is asked anything;
* the robot receives three sensor readings (left, front, right of its heading): the number of
  open cells it could move through in that direction;
* ``("Reset", "Reset")`` ends run 0 only once the robot has entered the goal (that step counts
  in run 0); refused otherwise, and always refused in run 1, where the step is simply lost;
* a rotation other than -90, 0, +90 is ignored (no rotation) but the movement still happens;
* the movement is ``int(movement)`` clamped to -3..3, done one cell at a time, stopping
  silently at a wall; negative movement goes backwards without turning;
* after the move the goal is checked where the robot stands (not cells passed mid-move): in run 0
  this allows a later reset, in run 1 it ends the run;
* score = run-1 steps + run-0 steps / 30.

The trial's :class:`TrialResult` carries the per-step history (position, heading, sensor readings,
action) and, for robots that keep a :class:`~slam.maze.robots.WallKnowledge`, the step at which
each wall became known, so a recorder can replay what the robot knew after every step.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError
from slam.maze.formats import DX, DY, HEADING_NAMES, Cell, Maze
from slam.maze.kernels import ray_lengths

RESET = ("Reset", "Reset")
MAX_STEPS = 1000
EXPLORATION_WEIGHT = 1 / 30
MAX_MOVE = 3

Action = tuple[Any, Any]


@dataclass(frozen=True)
class MazeInfo:
    """What a robot is told before its first step (the tester gives only the size)."""

    width: int
    height: int
    goal: tuple[Cell, ...]
    start: Cell = (0, 0)
    max_steps: int = MAX_STEPS


class MazeRobot(Protocol):
    """The tester's robot interface: one call per step, sensors in, action out."""

    def next_move(self, sensors: tuple[int, int, int]) -> Action:
        """``(rotation, movement)`` or :data:`RESET`."""
        ...


RobotFactory = Callable[[MazeInfo], MazeRobot]


@dataclass
class TrialResult:
    """Outcome and per-step history of one trial (two runs) of a robot in a maze.

    History arrays have one entry per step, in order: ``step`` (1-based global count), ``run``
    (0 or 1), ``sensors`` (left, front, right read at the start of the step), the requested
    ``rotation`` and ``movement`` (0 for a reset), ``reset`` (the robot asked for a reset),
    ``moved`` (cells actually moved, signed), and ``x``, ``y``, ``heading`` after the step.
    ``walls_known_at`` holds, when the robot reports its knowledge, the step at which each wall
    became known (-1: never; 0: known before the first step, i.e. the outer border) as
    ``vertical`` ``(width + 1, height)`` (west side of column x) and ``horizontal``
    ``(width, height + 1)`` (south side of row y).
    """

    maze: Maze
    robot: str
    success: bool
    run_steps: list[int]
    failure: str | None
    step: NDArray[np.int32]
    run: NDArray[np.int8]
    sensors: NDArray[np.int32]
    rotation: NDArray[np.int32]
    movement: NDArray[np.int32]
    reset: NDArray[np.bool_]
    moved: NDArray[np.int32]
    x: NDArray[np.int32]
    y: NDArray[np.int32]
    heading: NDArray[np.int8]
    events: dict[str, int] = field(default_factory=dict)
    walls_known_at: dict[str, NDArray[np.int32]] | None = None
    exploration_weight: float = EXPLORATION_WEIGHT

    @property
    def score(self) -> float | None:
        """run-1 steps + run-0 steps × 1/30, or ``None`` when the trial failed."""
        if not self.success:
            return None
        return self.run_steps[1] + self.exploration_weight * self.run_steps[0]

    @property
    def total_steps(self) -> int:
        """Steps used in both runs together."""
        return len(self.step)

    def path(self, run: int) -> list[Cell]:
        """Cells the robot stood in during ``run``: the start, then the cell after each step."""
        cells = [self.maze.start]
        for r, x, y in zip(self.run, self.x, self.y, strict=True):
            if r == run:
                cells.append((int(x), int(y)))
        return cells

    def visited_mask(self, run: int | None = None) -> NDArray[np.bool_]:
        """Cells the robot stood in (in ``run``, or in both runs), including the start."""
        mask = np.zeros(self.maze.open_mask.shape, dtype=np.bool_)
        mask[self.maze.start] = True
        keep = np.ones(len(self.step), dtype=np.bool_) if run is None else self.run == run
        mask[self.x[keep], self.y[keep]] = True
        return mask

    def to_dict(self, history: bool = True) -> dict[str, Any]:
        """JSON-ready summary; with ``history`` also every step and the wall knowledge."""
        out: dict[str, Any] = {
            "maze": self.maze.name,
            "size": [self.maze.width, self.maze.height],
            "robot": self.robot,
            "success": self.success,
            "failure": self.failure,
            "score": None if self.score is None else round(self.score, 6),
            "run0_steps": self.run_steps[0] if len(self.run_steps) > 0 else None,
            "run1_steps": self.run_steps[1] if len(self.run_steps) > 1 else None,
            "total_steps": self.total_steps,
            "events": dict(self.events),
            "path": {
                "run0": [list(c) for c in self.path(0)],
                "run1": [list(c) for c in self.path(1)],
            },
        }
        if history:
            out["history"] = {
                "step": self.step.tolist(),
                "run": self.run.tolist(),
                "sensors": self.sensors.tolist(),
                "rotation": self.rotation.tolist(),
                "movement": self.movement.tolist(),
                "reset": self.reset.tolist(),
                "moved": self.moved.tolist(),
                "x": self.x.tolist(),
                "y": self.y.tolist(),
                "heading": self.heading.tolist(),
                "heading_names": list(HEADING_NAMES),
            }
            if self.walls_known_at is not None:
                out["walls_known_at"] = {k: v.tolist() for k, v in self.walls_known_at.items()}
        return out


def sense(rays: NDArray[np.int32], x: int, y: int, heading: int) -> tuple[int, int, int]:
    """The three readings (left, front, right) at ``(x, y)`` facing ``heading``."""
    return (
        int(rays[x, y, (heading - 1) % 4]),
        int(rays[x, y, heading]),
        int(rays[x, y, (heading + 1) % 4]),
    )


def run_trial(
    maze: Maze,
    robot: MazeRobot,
    robot_name: str = "",
    max_steps: int = MAX_STEPS,
    exploration_weight: float = EXPLORATION_WEIGHT,
) -> TrialResult:
    """Let ``robot`` make its two runs in ``maze`` under the tester's rules (module docstring)."""
    if not maze.goal:
        raise DataError(f"{maze.name or 'maze'}: no goal cells (none marked 'G'), cannot run")
    if maze.start in maze.goal:
        raise DataError(
            f"{maze.name or 'maze'}: the start cell {maze.start} is a goal cell (goal "
            f"{sorted(maze.goal)}), cannot run: expected a start outside the goal (a Udacity "
            "maze of side 4 or more)"
        )
    open_mask = maze.open_mask
    rays = ray_lengths(np.ascontiguousarray(open_mask, dtype=np.uint8))
    goal = maze.goal_mask()
    log: dict[str, list] = {
        k: [] for k in ("step", "run", "sensors", "rot", "mov", "reset", "moved", "x", "y", "h")
    }
    events = {"reset_refused": 0, "invalid_rotation": 0, "movement_clamped": 0, "wall_stop": 0}
    run_steps: list[int] = []
    total = 0
    failure: str | None = None
    for run in range(2):
        x, y = maze.start
        heading = 0
        hit_goal = False
        while True:
            total += 1
            if total > max_steps:
                failure = f"step limit of {max_steps} exceeded in run {run}"
                break
            sensors = sense(rays, x, y, heading)
            rotation, movement = robot.next_move(sensors)
            log["step"].append(total)
            log["run"].append(run)
            log["sensors"].append(sensors)
            if (rotation, movement) == RESET:
                _record(log, 0, 0, True, 0, x, y, heading)
                if run == 0 and hit_goal:
                    run_steps.append(total)
                    break
                events["reset_refused"] += 1
                continue
            if rotation == -90:
                heading = (heading - 1) % 4
            elif rotation == 90:
                heading = (heading + 1) % 4
            elif rotation != 0:
                events["invalid_rotation"] += 1
            if abs(movement) > MAX_MOVE:
                events["movement_clamped"] += 1
            steps = max(min(int(movement), MAX_MOVE), -MAX_MOVE)
            direction = heading if steps > 0 else (heading + 2) % 4
            x, y, moved = _walk(open_mask, x, y, direction, abs(steps), events)
            rot = int(rotation) if rotation in (-90, 0, 90) else 0
            _record(log, rot, steps, False, moved if steps >= 0 else -moved, x, y, heading)
            if goal[x, y]:
                hit_goal = True
                if run != 0:
                    run_steps.append(total - sum(run_steps))
                    break
        if failure:
            break

    knowledge = getattr(robot, "knowledge", None)
    walls_known_at = knowledge.known_at_edges() if knowledge is not None else None
    return _trial_result(
        maze, robot_name or type(robot).__name__, run_steps, failure, log, events, walls_known_at,
        exploration_weight,
    )  # fmt: skip


def _walk(
    open_mask: NDArray[np.uint8], x: int, y: int, direction: int, steps: int, events: dict
) -> tuple[int, int, int]:
    """Move up to ``steps`` cells in ``direction``, stopping at a wall (counted in ``events``);
    returns the new cell and the cells moved."""
    moved = 0
    for _ in range(steps):
        if open_mask[x, y] >> direction & 1:
            x += DX[direction]
            y += DY[direction]
            moved += 1
        else:
            events["wall_stop"] += 1
            break
    return x, y, moved


def _record(
    log: dict[str, list], rot: int, mov: int, reset: bool, moved: int, x: int, y: int, h: int
) -> None:
    """Append one step's command and outcome to the trial log (after its sensors)."""
    for key, value in zip(
        ("rot", "mov", "reset", "moved", "x", "y", "h"),
        (rot, mov, reset, moved, x, y, h),
        strict=True,
    ):
        log[key].append(value)


def _trial_result(
    maze: Maze,
    robot: str,
    run_steps: list[int],
    failure: str | None,
    log: dict[str, list],
    events: dict[str, int],
    walls_known_at: NDArray | None,
    exploration_weight: float,
) -> TrialResult:
    """The :class:`TrialResult` of a finished trial's log."""
    n = len(log["step"])
    return TrialResult(
        maze=maze,
        robot=robot,
        success=len(run_steps) == 2,
        run_steps=run_steps,
        failure=failure,
        step=np.asarray(log["step"], dtype=np.int32),
        run=np.asarray(log["run"], dtype=np.int8),
        sensors=np.asarray(log["sensors"], dtype=np.int32).reshape(n, 3),
        rotation=np.asarray(log["rot"], dtype=np.int32),
        movement=np.asarray(log["mov"], dtype=np.int32),
        reset=np.asarray(log["reset"], dtype=np.bool_),
        moved=np.asarray(log["moved"], dtype=np.int32),
        x=np.asarray(log["x"], dtype=np.int32),
        y=np.asarray(log["y"], dtype=np.int32),
        heading=np.asarray(log["h"], dtype=np.int8),
        events=events,
        walls_known_at=walls_known_at,
        exploration_weight=exploration_weight,
    )
