"""Maze files: the Udacity mask format and the micromouseonline ASCII format, and conversion.

The module owns :class:`Maze` (walls as per-cell open masks, start and goal cells), the two
readers, the two writers and the wall-consistency validation. Every problem a user can cause (a
malformed line, walls that disagree from the two sides, an open outer border) is a
:class:`~slam.errors.DataError` naming the file, the line and what was expected.

Conventions (those of the Udacity tester): cells are ``(x, y)`` with ``x`` to the right and
``y = 0`` at the bottom; a cell's mask has a bit set when that side is **open**:
1 north (up), 2 east (right), 4 south (down), 8 west (left). Headings use the same order as
indices 0..3 (north, east, south, west), so a +90° (clockwise) rotation adds one.

* Udacity format: first line ``n``; then ``n`` lines of ``n`` comma-separated masks; line ``k`` is
  column ``x = k`` and its values run ``y = 0 .. n-1``. The maze must be square with an even side;
  the goal is the centre 2×2 by rule and the start is ``(0, 0)``.
* micromouseonline ASCII: posts ``o``, horizontal walls ``---``, vertical walls ``|``, ``S`` and
  ``G`` in the middle of the start and goal cells; the first line is the north border.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError, UsageError
from slam.io.atomic import write_text
from slam.io.text import read_input

NORTH, EAST, SOUTH, WEST = 0, 1, 2, 3
HEADING_NAMES = ("north", "east", "south", "west")
DX = (0, 1, 0, -1)
DY = (1, 0, -1, 0)
FORMATS = ("udacity", "ascii")

Cell = tuple[int, int]


@dataclass(frozen=True, eq=False)
class Maze:
    """A rectangular maze: open-side masks ``(width, height)`` indexed ``[x, y]``, start, goal."""

    open_mask: NDArray[np.uint8]
    goal: tuple[Cell, ...]
    start: Cell = (0, 0)
    name: str = ""

    @property
    def width(self) -> int:
        """Number of columns (cells along x)."""
        return int(self.open_mask.shape[0])

    @property
    def height(self) -> int:
        """Number of rows (cells along y)."""
        return int(self.open_mask.shape[1])

    def is_open(self, x: int, y: int, direction: int) -> bool:
        """Whether cell ``(x, y)`` is open on side ``direction`` (0 north .. 3 west)."""
        return bool(self.open_mask[x, y] >> direction & 1)

    def goal_mask(self) -> NDArray[np.bool_]:
        """Boolean ``(width, height)`` array of the goal cells."""
        mask = np.zeros(self.open_mask.shape, dtype=np.bool_)
        for x, y in self.goal:
            mask[x, y] = True
        return mask

    def centre_goal(self) -> tuple[Cell, ...]:
        """The centre 2×2 cells (the Udacity goal rule), for an even square maze."""
        a, b = self.width // 2 - 1, self.width // 2
        return ((a, a), (a, b), (b, a), (b, b))

    def same_walls(self, other: Maze) -> bool:
        """Whether ``other`` has exactly the same walls (start and goal not compared)."""
        return self.open_mask.shape == other.open_mask.shape and bool(
            np.array_equal(self.open_mask, other.open_mask)
        )


Locate = Callable[[int, int, int], str]
"""Where side ``(x, y, heading)`` of a cell is written in the file: ``"line L, ..."``."""


def wall_errors(open_mask: NDArray[np.uint8], locate: Locate | None = None) -> list[str]:
    """Human-readable wall problems: sides that disagree between neighbours, open outer border;
    each side named where the file writes it when ``locate`` is given."""
    mask = np.asarray(open_mask, dtype=np.uint8)
    width, height = mask.shape

    def at(x: int, y: int, side: int) -> str:
        return f" ({locate(x, y, side)})" if locate is not None else ""

    def state(bit: int) -> str:
        return "open" if bit else "closed"

    problems: list[str] = []
    east = (mask[:-1, :] >> EAST) & 1
    west = (mask[1:, :] >> WEST) & 1
    for x, y in np.argwhere(east != west):
        problems.append(
            f"wall between ({x},{y}) and ({x + 1},{y}) is {state(east[x, y])} from the west "
            f"cell{at(x, y, EAST)} but {state(west[x, y])} from the east cell"
            f"{at(x + 1, y, WEST)}"
        )
    north = (mask[:, :-1] >> NORTH) & 1
    south = (mask[:, 1:] >> SOUTH) & 1
    for x, y in np.argwhere(north != south):
        problems.append(
            f"wall between ({x},{y}) and ({x},{y + 1}) is {state(north[x, y])} from the south "
            f"cell{at(x, y, NORTH)} but {state(south[x, y])} from the north cell"
            f"{at(x, y + 1, SOUTH)}"
        )
    for side, cells in (
        (WEST, [(0, y) for y in range(height)]),
        (EAST, [(width - 1, y) for y in range(height)]),
        (SOUTH, [(x, 0) for x in range(width)]),
        (NORTH, [(x, height - 1) for x in range(width)]),
    ):
        for x, y in cells:
            if mask[x, y] >> side & 1:
                problems.append(
                    f"outer {HEADING_NAMES[side]} wall of ({x},{y}) is open{at(x, y, side)}"
                )
    return problems


def validate_maze(maze: Maze, source: str = "maze", locate: Locate | None = None) -> Maze:
    """Check wall consistency, the closed border, and that start and goal cells lie inside
    (``locate``: where the file writes each cell's sides, for the messages)."""
    problems = wall_errors(maze.open_mask, locate)
    if problems:
        more = f" (and {len(problems) - 3} more)" if len(problems) > 3 else ""
        raise DataError(f"{source}: inconsistent walls: {'; '.join(problems[:3])}{more}")
    for what, cells in (("start", [maze.start]), ("goal", list(maze.goal))):
        for x, y in cells:
            if not (0 <= x < maze.width and 0 <= y < maze.height):
                raise DataError(
                    f"{source}: {what} cell ({x},{y}) lies outside the "
                    f"{maze.width}x{maze.height} maze"
                )
    return maze


# --------------------------------------------------------------------------- Udacity format


def parse_udacity(text: str, source: str = "<text>", name: str = "") -> Maze:
    """Parse the Udacity mask format (see the module docstring); goal = centre 2×2."""
    lines = [(i, line.strip()) for i, line in enumerate(text.splitlines(), start=1)]
    lines = [(i, line) for i, line in lines if line]
    if not lines:
        raise DataError(f"{source}: empty maze file (expected the side length n on line 1)")
    first_no, first = lines[0]
    try:
        n = int(first)
    except ValueError:
        raise DataError(
            f"{source}:{first_no}: expected the maze side length (an integer), found {first!r}"
        ) from None
    if n < 2 or n % 2:
        raise DataError(
            f"{source}:{first_no}: the maze side must be an even number >= 2, found {n}"
        )
    rows = lines[1:]
    if len(rows) < n:
        last = rows[-1][0] if rows else first_no
        raise DataError(
            f"{source}:{last}: expected {n} lines of masks after the size, found {len(rows)} "
            f"(the file ends here)"
        )
    if len(rows) > n:
        extra_no, extra = rows[n]
        raise DataError(
            f"{source}:{extra_no}: expected {n} lines of masks after the size, found "
            f"{len(rows)} (extra line {extra[:40]!r})"
        )
    mask = np.zeros((n, n), dtype=np.uint8)
    for x, (lineno, line) in enumerate(rows):
        fields = [f.strip() for f in line.split(",")]
        if len(fields) != n:
            raise DataError(
                f"{source}:{lineno}: expected {n} comma-separated masks, found {len(fields)}"
            )
        for y, field in enumerate(fields):
            try:
                value = int(field)
            except ValueError:
                raise DataError(
                    f"{source}:{lineno}: mask {y + 1} must be an integer 0..15, found {field!r}"
                ) from None
            if not 0 <= value <= 15:
                raise DataError(
                    f"{source}:{lineno}: mask {y + 1} must be an integer 0..15, found {value}"
                )
            mask[x, y] = value
    a, b = n // 2 - 1, n // 2
    maze = Maze(mask, goal=((a, a), (a, b), (b, a), (b, b)), start=(0, 0), name=name)
    return validate_maze(maze, source, lambda x, y, side: f"line {rows[x][0]}, mask {y + 1}")


def format_udacity(maze: Maze) -> str:
    """Udacity text of ``maze``; only an even square maze with the centre 2×2 goal fits."""
    if maze.width != maze.height or maze.width % 2:
        raise UsageError(
            f"{maze.name or 'maze'}: the Udacity format holds only even square mazes, "
            f"this one is {maze.width}x{maze.height}"
        )
    if sorted(maze.goal) != sorted(maze.centre_goal()) or maze.start != (0, 0):
        raise UsageError(
            f"{maze.name or 'maze'}: the Udacity format fixes start (0,0) and the centre 2x2 "
            f"goal; this maze has start {maze.start} and goal {sorted(maze.goal)}"
        )
    lines = [str(maze.width)]
    for x in range(maze.width):
        lines.append(",".join(str(int(v)) for v in maze.open_mask[x, :]))
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- ASCII format


def _read_wall_line(where: str, line: str, width: int, h_open: NDArray[np.bool_]) -> None:
    """Posts and horizontal walls of one line ``o---o   o``: ``h_open[x]`` true where open."""
    for col in range(0, len(line), 4):
        if line[col] != "o":
            raise DataError(f"{where}:{col + 1}: expected a post 'o', found {line[col]!r}")
    for x in range(width):
        seg = line[4 * x + 1 : 4 * x + 4]
        if seg == "---":
            h_open[x] = False
        elif seg == "   ":
            h_open[x] = True
        else:
            raise DataError(
                f"{where}:{4 * x + 2}: expected a wall '---' or an opening '   ', found {seg!r}"
            )


def _read_cell_line(
    where: str,
    line: str,
    width: int,
    y: int,
    v_open: NDArray[np.bool_],
    goal: list[Cell],
    start: Cell | None,
) -> Cell | None:
    """Vertical walls and cell marks of row ``y``'s line ``|   | S |``: fills ``v_open[:, y]``,
    appends ``G`` cells to ``goal``; returns the start cell (``start`` unless this row has the
    ``S``)."""
    for xl in range(width + 1):
        ch = line[4 * xl]
        if ch == "|":
            v_open[xl, y] = False
        elif ch == " ":
            v_open[xl, y] = True
        else:
            raise DataError(f"{where}:{4 * xl + 1}: expected a wall '|' or ' ', found {ch!r}")
    for x in range(width):
        inner = line[4 * x + 1 : 4 * x + 4]
        mark = inner.strip()
        if mark == "":
            continue
        if mark not in ("S", "G") or inner[1] != mark:
            raise DataError(
                f"{where}:{4 * x + 2}: expected ' ', ' S ' or ' G ' inside cell ({x},{y}), "
                f"found {inner!r}"
            )
        if mark == "G":
            goal.append((x, y))
        elif start is not None:
            raise DataError(
                f"{where}: a second start cell 'S' at ({x},{y}); the first is at {start}"
            )
        else:
            start = (x, y)
    return start


def parse_ascii(text: str, source: str = "<text>", name: str = "") -> Maze:
    """Parse the micromouseonline ASCII format; goal = cells marked ``G``, start = ``S``.

    Without an ``S`` the start is ``(0, 0)``; a maze without ``G`` reads fine (it can be shown
    or converted) but has an empty goal, which the referee refuses.
    """
    raw = [line.rstrip("\r\n").rstrip() for line in text.splitlines()]
    while raw and not raw[-1]:
        raw.pop()
    skipped = 0  # blank lines before the maze: line numbers count them
    while raw and not raw[0]:
        raw.pop(0)
        skipped += 1
    if not raw:
        raise DataError(f"{source}: empty maze file")
    top = raw[0]
    if len(top) < 5 or (len(top) - 1) % 4 or not top.startswith("o"):
        raise DataError(
            f"{source}:{skipped + 1}: expected the north border 'o---o---...o' (4*width+1 "
            "characters), "
            f"found {top[:40]!r}"
        )
    width = (len(top) - 1) // 4
    if len(raw) % 2 == 0 or len(raw) < 3:
        raise DataError(f"{source}: expected an odd number of lines (2*height+1), found {len(raw)}")
    height = (len(raw) - 1) // 2
    lines = []
    for lineno, line in enumerate(raw, start=skipped + 1):
        if "\t" in line:
            raise DataError(
                f"{source}:{lineno}:{line.index(chr(9)) + 1}: a tab; the ASCII format places "
                "walls by column: write spaces"
            )
        if len(line) > 4 * width + 1:
            raise DataError(
                f"{source}:{lineno}: line is {len(line)} characters long, expected at most "
                f"{4 * width + 1} for a maze {width} cells wide"
            )
        lines.append(line.ljust(4 * width + 1))

    v_open = np.zeros(
        (width + 1, height), dtype=bool
    )  # vertical wall line x: west side of column x
    h_open = np.zeros(
        (width, height + 1), dtype=bool
    )  # horizontal wall line y: south side of row y
    start: Cell | None = None
    goal: list[Cell] = []
    for k, line in enumerate(lines):
        if k % 2 == 0:  # horizontal line k is the south side of row height - k // 2
            where = f"{source}:{skipped + k + 1}"
            _read_wall_line(where, line, width, h_open[:, height - k // 2])
        else:
            y = height - 1 - k // 2
            where = f"{source}:{skipped + k + 1}"
            start = _read_cell_line(where, line, width, y, v_open, goal, start)

    mask = np.zeros((width, height), dtype=np.uint8)
    mask |= h_open[:, 1:].astype(np.uint8) << NORTH
    mask |= v_open[1:, :].astype(np.uint8) << EAST
    mask |= h_open[:, :-1].astype(np.uint8) << SOUTH
    mask |= v_open[:-1, :].astype(np.uint8) << WEST
    maze = Maze(mask, goal=tuple(sorted(goal)), start=start or (0, 0), name=name)

    def locate(x: int, y: int, side: int) -> str:
        row = skipped + 2 * (height - 1 - y) + 2  # the cell's own line (1-based)
        line = row + (-1 if side == NORTH else 1 if side == SOUTH else 0)
        column = 4 * x + (5 if side == EAST else 1 if side == WEST else 2)
        return f"line {line}, column {column}"

    return validate_maze(maze, source, locate)


def format_ascii(maze: Maze) -> str:
    """micromouseonline ASCII text of ``maze`` (``S`` and ``G`` marked, north border first)."""
    marks = {cell: "G" for cell in maze.goal}
    marks[maze.start] = "S"
    out: list[str] = []
    for row in range(maze.height, -1, -1):
        # horizontal line: the north side of row `row - 1` (south side of row `row`)
        parts = ["o"]
        for x in range(maze.width):
            # row == height is the north border; below it, the south side of row `row`
            closed = row == maze.height or not maze.is_open(x, row, SOUTH)
            parts.append("---o" if closed else "   o")
        out.append("".join(parts))
        if row == 0:
            break
        y = row - 1
        parts = ["|" if not maze.is_open(0, y, WEST) else " "]
        for x in range(maze.width):
            parts.append(f" {marks.get((x, y), ' ')} ")
            parts.append("|" if not maze.is_open(x, y, EAST) else " ")
        out.append("".join(parts))
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------- files


def detect_format(text: str, source: str = "<text>") -> str:
    """``"udacity"`` when the first non-blank line is an integer, ``"ascii"`` when it is a border."""
    for lineno, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        if line.isdigit():
            return "udacity"
        if line.startswith("o"):
            return "ascii"
        raise DataError(
            f"{source}:{lineno}: unknown maze format: expected a side length (Udacity) or a "
            f"border of posts 'o---o' (micromouseonline ASCII) on the first line, found "
            f"{line[:40]!r}"
        )
    raise DataError(
        f"{source}: unknown maze format: the file is empty (expected a side length (Udacity) "
        f"or a border of posts 'o---o' (micromouseonline ASCII) on the first line)"
    )


def parse_maze(text: str, source: str = "<text>", name: str = "", fmt: str | None = None) -> Maze:
    """Parse maze text in ``fmt`` (``None``: detected from the first line)."""
    fmt = fmt or detect_format(text, source)
    if fmt == "udacity":
        return parse_udacity(text, source, name)
    if fmt == "ascii":
        return parse_ascii(text, source, name)
    raise UsageError(f"unknown maze format {fmt!r}; expected one of {', '.join(FORMATS)}")


def read_maze(path: Path, fmt: str | None = None) -> Maze:
    """Read a maze file in either format (detected unless ``fmt`` is given)."""
    path = Path(path)
    text = read_maze_text(path)
    return parse_maze(text, str(path), name=path.stem, fmt=fmt)


def read_maze_text(path: Path) -> str:
    """The text of a maze file (ASCII); a :class:`DataError` names the file, line and byte."""
    path = Path(path)
    data = read_input(
        path, "maze file not found", "is a folder, expected a maze file", "cannot read maze file"
    )
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        lineno = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise DataError(
            f"{path}:{lineno}:{column}: expected ASCII text, found byte 0x{data[exc.start]:02x}"
        ) from None
    return text.replace("\r\n", "\n").replace("\r", "\n")  # universal newlines, as read_text


def format_maze(maze: Maze, fmt: str) -> str:
    """Text of ``maze`` in ``fmt`` (``"udacity"`` or ``"ascii"``)."""
    if fmt == "udacity":
        return format_udacity(maze)
    if fmt == "ascii":
        return format_ascii(maze)
    raise UsageError(f"unknown maze format {fmt!r}; expected one of {', '.join(FORMATS)}")


def write_maze(maze: Maze, path: Path, fmt: str) -> None:
    """Write ``maze`` to ``path`` in ``fmt``, atomically."""
    write_text(Path(path), format_maze(maze, fmt))


def maze_from_walls(
    width: int,
    height: int,
    walls: Iterable[tuple[Cell, int]] = (),
    goal: Iterable[Cell] | None = None,
    start: Cell = (0, 0),
    name: str = "",
) -> Maze:
    """An open field with a closed border and the given interior walls (``(cell, side)`` pairs).

    For hand-made mazes in tests and examples; ``goal`` defaults to the centre 2×2.
    """
    mask = np.full((width, height), 15, dtype=np.uint8)
    mask[0, :] &= ~np.uint8(1 << WEST)
    mask[-1, :] &= ~np.uint8(1 << EAST)
    mask[:, 0] &= ~np.uint8(1 << SOUTH)
    mask[:, -1] &= ~np.uint8(1 << NORTH)
    for (x, y), side in walls:
        mask[x, y] &= ~np.uint8(1 << side)
        nx, ny = x + DX[side], y + DY[side]
        if 0 <= nx < width and 0 <= ny < height:
            mask[nx, ny] &= ~np.uint8(1 << ((side + 2) % 4))
    if goal is None:
        a, b = width // 2 - 1, width // 2
        c, d = height // 2 - 1, height // 2
        goal = ((a, c), (a, d), (b, c), (b, d))
    maze = Maze(mask, goal=tuple(sorted(goal)), start=start, name=name)
    return validate_maze(maze, name or "maze")


# --------------------------------------------------------------------------- finding mazes


def locate_maze(name: str | Path, data_dir: Path | None = None, folder: bool = False) -> Path:
    """The maze file (or, with ``folder``, maze file or folder) that ``name`` designates.

    A path that exists is taken as it is; otherwise ``name`` is looked up in the data directory,
    under ``<data dir>/maze/`` first, then ``<data dir>/``, also with ``.txt`` appended
    (``udacity/test_maze_01`` finds ``<data dir>/maze/udacity/test_maze_01.txt``).
    """
    path = Path(name)
    tried = [path]
    candidates = [path]
    if data_dir is not None and not path.is_absolute():
        for base in (Path(data_dir) / "maze", Path(data_dir)):
            candidates.append(base / path)
            candidates.append(base / f"{path}.txt")
    for candidate in candidates:
        if candidate.is_file() or (folder and candidate.is_dir()):
            return candidate
        tried.append(candidate)
    where = f" or under the data directory {data_dir}" if data_dir is not None else ""
    raise DataError(
        f"maze {str(name)!r} not found: no such {'file or folder' if folder else 'file'} here"
        f"{where} (tried {', '.join(str(t) for t in dict.fromkeys(tried))})"
    )


def locate_mazes(names: Iterable[str | Path], data_dir: Path | None = None) -> list[Path]:
    """Maze files for ``names``: files as they are, folders expanded to their ``*.txt`` files."""
    paths: list[Path] = []
    for name in names:
        found = locate_maze(name, data_dir, folder=True)
        if found.is_dir():
            files = sorted(p for p in found.glob("*.txt") if p.is_file())
            if not files:
                raise DataError(f"{found}: folder holds no maze files (*.txt)")
            paths.extend(files)
        else:
            paths.append(found)
    return paths
