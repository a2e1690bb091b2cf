"""Maze benches: one 16×16 trial, and the bench over the 521 classic mazes.

* ``run_16x16`` — wall time of one ``bounded`` trial on the Udacity 16×16 maze (test_maze_03):
  reading the file, the optimal plan, both runs through the referee (best of 5, kernels warmed
  up first; the first call's compile or cache-load time is reported separately).
* ``bench_classic`` — wall time of ``slam maze bench micromouseonline/classic`` as the CLI runs
  it (2 worker processes), with its summary figures (mean score / lower bound, failures).
"""

from __future__ import annotations

import time

from benches._util import best_of, data_dir, skip


def run_16x16() -> dict:
    """Seconds for one ``bounded`` trial on a 16×16 maze."""
    from slam.maze.bench import trial
    from slam.maze.formats import read_maze
    from slam.maze.planner import optimal_plan

    path = data_dir() / "maze" / "udacity" / "test_maze_03.txt"
    if not path.is_file():
        return skip(f"{path} is absent")

    def once():
        maze = read_maze(path)
        optimal_plan(maze)
        return trial(maze, "bounded")

    start = time.perf_counter()
    once()
    first = time.perf_counter() - start
    seconds, result = best_of(once, 5)
    return {
        "seconds": round(seconds, 4),
        "first_call_s": round(first, 3),
        "score": round(result.score, 3),
        "run0_steps": result.run_steps[0],
        "run1_steps": result.run_steps[1],
        "target_s": 0.5,
    }


def bench_classic() -> dict:
    """Seconds for the 521-maze classic bench with 2 processes, and its figures."""
    from slam.maze.bench import run_bench, summarize
    from slam.maze.formats import locate_mazes

    folder = data_dir() / "maze" / "micromouseonline" / "classic"
    if not folder.is_dir():
        return skip(f"{folder} is absent")
    paths = locate_mazes([folder])
    start = time.perf_counter()
    rows = run_bench(paths, "bounded", jobs=2)
    seconds = time.perf_counter() - start
    summary = summarize(rows)
    return {
        "seconds": round(seconds, 2),
        "mazes": summary["mazes"],
        "finished": summary["finished"],
        "failures": summary["failures"],
        "unsolvable": summary["unsolvable"],
        "mean_ratio": round(summary["mean_ratio"], 4),
        "worst_ratio": round(summary["worst_ratio"], 4),
        "mean_run0": round(summary["mean_run0"], 1),
        "run1_optimal": summary["run1_optimal"],
        "target_s": 120,
    }


def benches() -> dict:
    """The maze benches by name."""
    return {"run_16x16": run_16x16, "bench_classic": bench_classic}
