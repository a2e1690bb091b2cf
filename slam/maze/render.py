"""PNG pictures of a maze trial: walls, what the robot explored, and both runs.

Drawn with OpenCV, north up. Cells the robot stood in during run 0 are shaded; walls the robot
learnt are black, walls it never saw are light grey; the goal is green, the start blue. The run-0
track is orange (thin), the run-1 track red (thick), both drawn through the cell centres of the
steps' end points (written by :func:`slam.io.atomic.write_png`).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from slam.maze.formats import EAST, NORTH, Maze
from slam.maze.referee import TrialResult

BACKGROUND = (255, 255, 255)
EXPLORED = (235, 222, 200)
GOAL = (170, 225, 170)
START = (240, 200, 150)
KNOWN_WALL = (20, 20, 20)
UNSEEN_WALL = (200, 200, 200)
RUN0 = (0, 140, 255)
RUN1 = (30, 30, 220)
TEXT = (40, 40, 40)


def render_trial(
    maze: Maze, result: TrialResult | None = None, cell: int = 32
) -> NDArray[np.uint8]:
    """BGR image of ``maze`` and, when given, the trial ``result`` on it."""
    width, height = maze.width, maze.height
    margin = cell // 2
    legend = max(60, 2 * cell) if result is not None else 0
    img = np.full(
        (height * cell + 2 * margin + legend, width * cell + 2 * margin, 3), BACKGROUND, np.uint8
    )

    def corner(x: int, y: int) -> tuple[int, int]:
        return margin + x * cell, margin + (height - y) * cell

    def centre(x: int, y: int) -> tuple[int, int]:
        return margin + x * cell + cell // 2, margin + (height - 1 - y) * cell + cell // 2

    def fill(x: int, y: int, colour: tuple[int, int, int]) -> None:
        x0, y1 = corner(x, y)
        x1, y0 = corner(x + 1, y + 1)
        cv2.rectangle(img, (x0, y0), (x1, y1), colour, thickness=-1)

    if result is not None:
        for x, y in np.argwhere(result.visited_mask(0)):
            fill(int(x), int(y), EXPLORED)
    for x, y in maze.goal:
        fill(x, y, GOAL)
    fill(*maze.start, START)

    known_v = known_h = None
    if result is not None and result.walls_known_at is not None:
        known_v = result.walls_known_at["vertical"] >= 0
        known_h = result.walls_known_at["horizontal"] >= 0
    thick = max(2, cell // 10)
    for x in range(width):
        for y in range(height):
            if not maze.is_open(x, y, NORTH) or y == height - 1:
                seen = known_h is None or bool(known_h[x, y + 1])
                cv2.line(
                    img,
                    corner(x, y + 1),
                    corner(x + 1, y + 1),
                    KNOWN_WALL if seen else UNSEEN_WALL,
                    thick,
                )
            if not maze.is_open(x, y, EAST) or x == width - 1:
                seen = known_v is None or bool(known_v[x + 1, y])
                cv2.line(
                    img,
                    corner(x + 1, y),
                    corner(x + 1, y + 1),
                    KNOWN_WALL if seen else UNSEEN_WALL,
                    thick,
                )
    for x in range(width):
        seen = known_h is None or bool(known_h[x, 0])
        cv2.line(img, corner(x, 0), corner(x + 1, 0), KNOWN_WALL if seen else UNSEEN_WALL, thick)
    for y in range(height):
        seen = known_v is None or bool(known_v[0, y])
        cv2.line(img, corner(0, y), corner(0, y + 1), KNOWN_WALL if seen else UNSEEN_WALL, thick)

    if result is not None:
        for run, colour, width_px in ((0, RUN0, max(1, cell // 16)), (1, RUN1, max(2, cell // 8))):
            points = np.array([centre(x, y) for x, y in result.path(run)], dtype=np.int32)
            if len(points) > 1:
                cv2.polylines(img, [points], False, colour, width_px, lineType=cv2.LINE_AA)
        score = "failed" if result.score is None else f"score {result.score:.3f}"
        runs = ", ".join(f"run {i}: {n} steps" for i, n in enumerate(result.run_steps))
        lines = [
            f"{maze.name} | {result.robot} | {score}",
            runs or (result.failure or ""),
            "orange: run 0, red: run 1, grey: walls never seen",
        ]
        _caption(img, lines, margin, height * cell + 2 * margin, legend)
    return img


def _caption(img: NDArray[np.uint8], lines: list[str], x: int, top: int, height: int) -> None:
    """Write ``lines`` in the band ``top .. top + height``, scaled to fit the image width."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    room = img.shape[1] - 2 * x
    line_h = height / (len(lines) + 0.5)
    widest = max(cv2.getTextSize(t, font, 1.0, 1)[0][0] for t in lines) or 1
    scale = min(room / widest, line_h / 30.0)
    for i, text in enumerate(lines):
        y = int(top + (i + 1) * line_h)
        cv2.putText(img, text, (x, y), font, scale, TEXT, 1, cv2.LINE_AA)
