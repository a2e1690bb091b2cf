"""Recording of ``slam maze run``: the walls as known to the robot after every step, and its path.

Timeline ``step`` (the tester's global step count, 1-based; step 0 is the start). Maze units:
one cell per unit, cell ``(x, y)`` spans ``[x, x+1] × [y, y+1]``, +y north (flipped once at the
``maze`` entity so north is up). Entities:

* ``maze/walls/true`` — ``LineStrips2D`` (static, faint): every wall of the maze;
* ``maze/walls/known`` — ``LineStrips2D``: the walls the robot knows, logged at the steps where
  its knowledge grows (robots that keep a wall map; the tester's baselines all do);
* ``maze/goal`` — ``Boxes2D`` (static): the goal cells;
* ``maze/path/run0``, ``maze/path/run1`` — ``LineStrips2D``: one segment per step (previous cell →
  cell) of the exploration run (orange) and of the race (red);
* ``maze/robot`` — ``Arrows2D``: position and heading after each step;
* ``metrics/known_sides`` — ``Scalars``: how many cell sides (wall or open) the robot knows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
from numpy.typing import NDArray

from slam.io.atomic import atomic_path
from slam.maze.formats import EAST, NORTH, SOUTH, WEST, Maze
from slam.maze.referee import TrialResult
from slam.viz.blueprint import maze_blueprint, world_flip
from slam.viz.stream import close_stream, open_stream

ROOT = "maze"
TRUE_WALLS = "maze/walls/true"
KNOWN_WALLS = "maze/walls/known"
GOAL = "maze/goal"
PATH = "maze/path"
ROBOT = "maze/robot"
KNOWN_COUNT = "metrics/known_sides"

_RUN_COLOURS = ((240, 150, 20), (220, 40, 40))
_HEADING = np.array([[0.0, 1.0], [1.0, 0.0], [0.0, -1.0], [-1.0, 0.0]])  # N, E, S, W


def wall_sides(maze: Maze) -> dict[str, NDArray[np.bool_]]:
    """Closed sides as ``vertical (W+1, H)`` (west side of column x) and ``horizontal (W, H+1)``
    (south side of row y), the layout of :attr:`TrialResult.walls_known_at`."""
    mask = maze.open_mask
    w, h = maze.width, maze.height
    vertical = np.zeros((w + 1, h), dtype=np.bool_)
    horizontal = np.zeros((w, h + 1), dtype=np.bool_)
    vertical[:w] = (mask >> WEST & 1) == 0
    vertical[w] = (mask[w - 1] >> EAST & 1) == 0
    horizontal[:, :h] = (mask >> SOUTH & 1) == 0
    horizontal[:, h] = (mask[:, h - 1] >> NORTH & 1) == 0
    return {"vertical": vertical, "horizontal": horizontal}


def wall_segments(
    vertical: NDArray[np.bool_], horizontal: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """``(K, 2, 2)`` segments of the marked sides (maze units)."""
    vx, vy = np.nonzero(vertical)
    hx, hy = np.nonzero(horizontal)
    v = np.stack([np.stack([vx, vy], 1), np.stack([vx, vy + 1], 1)], axis=1)
    hz = np.stack([np.stack([hx, hy], 1), np.stack([hx + 1, hy], 1)], axis=1)
    return np.concatenate([v, hz]).astype(np.float64).reshape(-1, 2, 2)


def _write_maze(result: TrialResult, path: Path, recording_id: str | None = None) -> int:
    """Log the recording of a maze trial to ``path``; return the number of steps logged."""
    maze = result.maze
    rec = open_stream(
        Path(path),
        name=f"slam maze run {maze.name} ({result.robot})",
        recording_id=recording_id,
        blueprint=maze_blueprint(),
    )
    ui = rr.Radius.ui_points
    truth = wall_sides(maze)
    rec.log(ROOT, world_flip(), static=True)
    rec.log(
        TRUE_WALLS,
        rr.LineStrips2D(
            wall_segments(truth["vertical"], truth["horizontal"]),
            colors=[(90, 90, 90)],
            radii=ui(1.0),
            draw_order=0.0,
        ),
        static=True,
    )
    goal = np.asarray(maze.goal, dtype=np.float64)
    rec.log(
        GOAL,
        rr.Boxes2D(mins=goal, sizes=np.ones_like(goal), colors=[(60, 170, 60)], draw_order=-1.0),
        static=True,
    )
    rec.log(
        KNOWN_WALLS,
        rr.LineStrips2D.from_fields(colors=[(235, 235, 235)], radii=ui(2.5), draw_order=1.0),
        static=True,
    )
    rec.log(ROBOT, rr.Arrows2D.from_fields(colors=[(220, 40, 40)], radii=ui(3.0)), static=True)
    for run, colour in enumerate(_RUN_COLOURS):
        rec.log(
            f"{PATH}/run{run}",
            rr.LineStrips2D.from_fields(colors=[colour], radii=ui(2.0), draw_order=2.0),
            static=True,
        )
    known_at = result.walls_known_at
    start = np.array(maze.start, dtype=np.float64) + 0.5
    previous = start
    last_known = -1
    for i in range(-1, len(result.step)):
        if i < 0:
            step, xy, heading = 0, start, 0
        else:
            step = int(result.step[i])
            xy = np.array([result.x[i], result.y[i]], dtype=np.float64) + 0.5
            heading = int(result.heading[i])
        rec.set_time("step", sequence=step)
        if i > 0 and result.run[i] != result.run[i - 1]:
            previous = start  # run 1 starts again from the start cell
        run = 0 if i < 0 else int(result.run[i])
        rec.log(f"{PATH}/run{run}", rr.LineStrips2D([np.stack([previous, xy])]))
        rec.log(
            ROBOT,
            rr.Arrows2D(origins=[xy - 0.3 * _HEADING[heading]], vectors=[0.6 * _HEADING[heading]]),
        )
        previous = xy
        if known_at is not None:
            kv = (known_at["vertical"] >= 0) & (known_at["vertical"] <= step)
            kh = (known_at["horizontal"] >= 0) & (known_at["horizontal"] <= step)
            count = int(np.count_nonzero(kv) + np.count_nonzero(kh))
            if count != last_known:
                segments = wall_segments(kv & truth["vertical"], kh & truth["horizontal"])
                rec.log(KNOWN_WALLS, rr.LineStrips2D(segments))
                rec.log(KNOWN_COUNT, rr.Scalars(count))
                last_known = count
    close_stream(rec, Path(path))
    return len(result.step) + 1


def record_maze_trial(result: TrialResult, path: Path, recording_id: str | None = None) -> int:
    """Write the recording of a maze trial to ``path`` atomically (it appears whole or not at
    all); return the number of steps logged. ``recording_id`` fixes the id (reproducible files)."""
    with atomic_path(Path(path)) as tmp:
        return _write_maze(result, tmp, recording_id)
