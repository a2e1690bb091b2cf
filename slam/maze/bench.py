"""Benchmarking robots over many mazes: score against the lower bound, failures, summary.

For each maze the row holds the robot's score, its run-0 and run-1 steps, the optimal run 1 on
the true maze and the lower bound ``optimal + optimal / 30`` (run 0 cannot reach the goal in
fewer steps than the optimal run 1). The summary reports the mean ratio score / bound over the
mazes the robot finished, and the failures (trials over the step limit, unreadable mazes).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from slam.errors import SlamError
from slam.maze import DEFAULT_ROBOT
from slam.maze.formats import Maze, read_maze
from slam.maze.planner import lower_bound, optimal_plan
from slam.maze.referee import EXPLORATION_WEIGHT, MazeInfo, TrialResult, run_trial
from slam.maze.robots import make_robot


@dataclass(frozen=True)
class BenchRow:
    """One maze of a bench: the trial's figures, or why there are none.

    ``status`` is ``"ok"``, ``"failed"`` (the robot went over the step limit), ``"unsolvable"``
    (no goal cell can be reached from the start in the true maze, so no robot can finish) or
    ``"unreadable"`` (the file is not a valid maze); ``error`` says more.
    """

    maze: str
    status: str
    score: float | None = None
    run0: int | None = None
    run1: int | None = None
    optimal: int | None = None
    bound: float | None = None
    error: str | None = None

    @property
    def ratio(self) -> float | None:
        """Score / lower bound (``None`` when the trial failed)."""
        if self.score is None or not self.bound:
            return None
        return self.score / self.bound


def trial(maze: Maze, robot: str = DEFAULT_ROBOT, **options: float) -> TrialResult:
    """Run ``robot`` (a name from :data:`slam.maze.robots.ROBOTS`) in ``maze``."""
    info = MazeInfo(maze.width, maze.height, maze.goal, maze.start)
    return run_trial(maze, make_robot(robot, info, **options), robot)


def bench_one(path: Path, robot: str = DEFAULT_ROBOT, options: dict | None = None) -> BenchRow:
    """Bench row of the maze file at ``path`` (problems become a row with a status)."""
    name = Path(path).stem
    try:
        maze = read_maze(Path(path))
    except SlamError as exc:
        return BenchRow(name, "unreadable", error=str(exc))
    try:
        optimal = optimal_plan(maze).steps
    except SlamError as exc:
        return BenchRow(name, "unsolvable", error=str(exc))
    result = trial(maze, robot, **(options or {}))
    return BenchRow(
        name,
        "ok" if result.success else "failed",
        result.score,
        result.run_steps[0] if result.run_steps else None,
        result.run_steps[1] if result.success else None,
        optimal,
        lower_bound(optimal, EXPLORATION_WEIGHT),
        error=result.failure,
    )


def _bench_star(args: tuple[Path, str, dict | None]) -> BenchRow:
    return bench_one(*args)


def run_bench(
    paths: Sequence[Path],
    robot: str = DEFAULT_ROBOT,
    jobs: int = 2,
    options: dict | None = None,
    progress: Callable[[Iterable[BenchRow], int], Iterable[BenchRow]] | None = None,
) -> list[BenchRow]:
    """Bench rows of every maze in ``paths``, in order, with up to ``jobs`` processes."""
    tasks = [(Path(p), robot, options) for p in paths]
    jobs = max(1, min(jobs, len(tasks), os.cpu_count() or 1))
    if jobs == 1:
        rows: Iterable[BenchRow] = map(_bench_star, tasks)
        if progress:
            rows = progress(rows, len(tasks))
        return list(rows)
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        rows = pool.map(_bench_star, tasks, chunksize=max(1, len(tasks) // (8 * jobs)))
        if progress:
            rows = progress(rows, len(tasks))
        return list(rows)


def summarize(rows: Sequence[BenchRow]) -> dict[str, Any]:
    """Counts per status, and over finished trials the mean score / bound ratio and more."""
    done = [r for r in rows if r.status == "ok"]
    ratios = sorted(r.ratio for r in done if r.ratio is not None)
    n = len(done)
    return {
        "mazes": len(rows),
        "finished": n,
        "failures": sum(r.status == "failed" for r in rows),
        "unsolvable": sum(r.status == "unsolvable" for r in rows),
        "unreadable": sum(r.status == "unreadable" for r in rows),
        "mean_ratio": sum(ratios) / n if n else None,
        "median_ratio": ratios[n // 2] if n else None,
        "worst_ratio": ratios[-1] if n else None,
        "mean_score": sum(r.score for r in done) / n if n else None,
        "mean_bound": sum(r.bound for r in done) / n if n else None,
        "mean_run0": sum(r.run0 for r in done) / n if n else None,
        "mean_run1_excess": sum(r.run1 - r.optimal for r in done) / n if n else None,
        "run1_optimal": sum(1 for r in done if r.run1 == r.optimal),
    }


def format_table(rows: Sequence[BenchRow], summary: dict[str, Any], robot: str) -> str:
    """Fixed-width table of the rows followed by the summary lines."""
    width = max([len("maze")] + [len(r.maze) for r in rows])
    head = f"{'maze':<{width}}  {'score':>8}  {'run0':>5}  {'run1':>5}  {'opt':>4}  {'bound':>7}  {'ratio':>6}"
    lines = [head, "-" * len(head)]
    for r in rows:
        if r.status in ("unsolvable", "unreadable"):
            lines.append(f"{r.maze:<{width}}  {r.status}: {r.error}")
            continue
        score = f"{r.score:8.3f}" if r.score is not None else f"{'FAIL':>8}"
        run0 = f"{r.run0:5d}" if r.run0 is not None else f"{'-':>5}"
        run1 = f"{r.run1:5d}" if r.run1 is not None else f"{'-':>5}"
        ratio = f"{r.ratio:6.3f}" if r.ratio is not None else f"{'-':>6}"
        lines.append(
            f"{r.maze:<{width}}  {score}  {run0}  {run1}  {r.optimal:4d}  {r.bound:7.3f}  {ratio}"
        )
    s = summary
    lines.append("-" * len(head))
    lines.append(
        f"robot {robot}: {s['mazes']} mazes, {s['finished']} finished, {s['failures']} failures "
        f"(over the step limit), {s['unsolvable']} unsolvable (no goal cell, or none reachable from the start), "
        f"{s['unreadable']} unreadable"
    )
    if s["finished"]:
        lines.append(
            f"mean score/bound {s['mean_ratio']:.4f} (median {s['median_ratio']:.4f}, worst "
            f"{s['worst_ratio']:.4f}); mean score {s['mean_score']:.3f}, mean bound "
            f"{s['mean_bound']:.3f}; mean run 0 {s['mean_run0']:.1f} steps; run 1 optimal in "
            f"{s['run1_optimal']}/{s['finished']} (mean excess {s['mean_run1_excess']:.3f} steps)"
        )
    return "\n".join(lines)


def rows_as_dicts(rows: Sequence[BenchRow]) -> list[dict[str, Any]]:
    """Rows as JSON-ready dicts (with the ratio)."""
    return [{**asdict(r), "ratio": r.ratio} for r in rows]
