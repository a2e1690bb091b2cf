"""Grid worlds of the discrete filter: labelled cells, obstacles, borders, and moving mass on them.

A world is an ``R × C`` array of cells (a 1D world is a single row). Each open cell carries a
label (an index into the world's palette of colours, or ``-1`` when the cell has no colour);
blocked cells are obstacles. The world is either *cyclic* (leaving one side enters the opposite
side, as in the classic tutorial worlds) or *bounded*, in which case the border counts as an
obstacle.

The robot's state is a cell, or a pair (cell, heading) when ``world.headings == 4``. A belief over
the state is always held as a float array of shape ``(H, R, C)``: ``H = 1`` for cell states, ``H = 4``
for (cell, heading) states with headings ordered N, E, S, W (clockwise, so turning left is
``h - 1`` and turning right ``h + 1`` modulo 4).

This module owns the geometry every motion and sensor model shares:

* ``shift(a, dr, dc)`` moves the content of an array by ``(dr, dc)`` cells (``np.roll`` in a
  cyclic world, a zero-filled slice copy in a bounded one);
* ``step(belief, world, d)`` is one commanded cell move in direction ``d`` with *bounce-back*: the
  mass of every cell whose neighbour in direction ``d`` is open moves there, the rest stays put;
* ``translate(belief, world, dr, dc)`` composes unit steps (rows first, then columns), so a move of
  ``k`` cells stops at the first obstacle or border; in an obstacle-free cyclic world it is a
  single exact ``np.roll``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from slam.errors import ConfigError

DIRECTIONS: tuple[str, ...] = ("N", "E", "S", "W")
"""Direction (and heading) names, clockwise; index ``d`` is used everywhere for direction ``d``."""

OFFSETS: tuple[tuple[int, int], ...] = ((-1, 0), (0, 1), (1, 0), (0, -1))
"""``(d_row, d_col)`` of one cell move in each direction; row 0 is the top (north) row."""

OBSTACLE = "#"
"""Map character of an obstacle cell."""

UNLABELLED = "."
"""Map character of an open cell without a colour."""

HEADING_COUNTS: tuple[int, ...] = (1, 4)
"""Allowed sizes of the heading axis: 1 (state = cell) or 4 (state = cell, heading N/E/S/W)."""


def left_of(d: int) -> int:
    """Direction index 90° to the left of direction ``d``."""
    return (d - 1) % 4


def right_of(d: int) -> int:
    """Direction index 90° to the right of direction ``d``."""
    return (d + 1) % 4


@dataclass(frozen=True, eq=False)
class GridWorld:
    """A grid of labelled cells, optionally with obstacles, cyclic or bounded by walls."""

    labels: np.ndarray
    """``(R, C)`` int16 palette index of each cell; ``-1`` for obstacles and uncoloured cells."""
    blocked: np.ndarray
    """``(R, C)`` bool, True where the cell is an obstacle."""
    palette: tuple[str, ...] = ()
    """Colour names; ``labels`` index into this tuple."""
    cyclic: bool = False
    """True: the world wraps around at its sides; False: the border is a wall."""
    headings: int = 1
    """Size of the heading axis of the state (1 or 4)."""
    symbols: tuple[str, ...] = field(default=())
    """One map character per palette entry (for parsing and display); empty: first letters."""

    def __post_init__(self) -> None:
        labels = np.asarray(self.labels)
        blocked = np.asarray(self.blocked, dtype=bool)
        if labels.ndim != 2 or labels.shape != blocked.shape or labels.size == 0:
            raise ConfigError(
                f"world: labels and obstacles must be non-empty 2D arrays of one shape, found "
                f"{labels.shape} and {blocked.shape}"
            )
        if labels.size and (labels.min() < -1 or labels.max() >= len(self.palette)):
            raise ConfigError(
                f"world: labels must lie in -1..{len(self.palette) - 1}, found "
                f"{labels.min()}..{labels.max()}"
            )
        if self.headings not in HEADING_COUNTS:
            raise ConfigError(f"world.headings: expected 1 or 4, found {self.headings}")
        if blocked.all():
            raise ConfigError("world: every cell is an obstacle; the robot has nowhere to be")
        symbols = self.symbols or tuple(name[:1] for name in self.palette)
        if len(symbols) != len(self.palette):
            raise ConfigError(
                f"world: {len(symbols)} map symbols for {len(self.palette)} palette colours"
            )
        labels = np.where(blocked, -1, labels).astype(np.int16)
        labels.setflags(write=False)
        blocked = blocked.copy()
        blocked.setflags(write=False)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "blocked", blocked)
        object.__setattr__(self, "symbols", tuple(symbols))

    @property
    def shape(self) -> tuple[int, int]:
        """``(R, C)``: rows and columns of the grid."""
        return self.labels.shape  # type: ignore[return-value]

    @property
    def belief_shape(self) -> tuple[int, int, int]:
        """``(H, R, C)``: shape of a belief over the state space."""
        return (self.headings, *self.shape)

    @cached_property
    def open(self) -> np.ndarray:
        """``(R, C)`` bool, True on cells the robot can occupy."""
        return ~self.blocked

    @cached_property
    def open_count(self) -> int:
        """Number of open cells."""
        return int(self.open.sum())

    @cached_property
    def can_move(self) -> np.ndarray:
        """``(4, R, C)`` bool: from this open cell, the neighbour in direction ``d`` is open.

        In a bounded world a neighbour beyond the border does not exist (a wall); in a cyclic
        world the neighbour wraps around.
        """
        out = np.empty((4, *self.shape), dtype=bool)
        for d, (dr, dc) in enumerate(OFFSETS):
            # target_open[r, c] = open[r + dr, c + dc] (False beyond a border in a bounded world)
            out[d] = shift(self.open, -dr, -dc, self.cyclic) & self.open
        out.setflags(write=False)
        return out

    @cached_property
    def neighbour_blocked(self) -> np.ndarray:
        """``(4, R, C)`` bool: the neighbour in direction ``d`` is an obstacle or the border.

        This is the ground truth of the W/N/E/S obstacle sensor (there indexed in WNES order).
        """
        out = np.empty((4, *self.shape), dtype=bool)
        for d, (dr, dc) in enumerate(OFFSETS):
            out[d] = ~shift(self.open, -dr, -dc, self.cyclic)
        out.setflags(write=False)
        return out

    def uniform_belief(self) -> np.ndarray:
        """The uniform prior over open cells (and all headings), shape ``(H, R, C)``."""
        belief = np.zeros(self.belief_shape)
        belief[:, self.open] = 1.0 / (self.open_count * self.headings)
        return belief

    def colour_index(self, token: str) -> int:
        """Palette index of a colour given by name or map symbol (case-insensitive)."""
        wanted = token.strip().lower()
        for i, name in enumerate(self.palette):
            if wanted in (name.lower(), self.symbols[i].lower()):
                return i
        raise ConfigError(
            f"unknown colour {token!r}; expected one of {', '.join(self.palette) or '(none)'}"
        )

    def describe(self) -> str:
        """One line: size, topology, open cells, palette, headings."""
        rows, cols = self.shape
        kind = "cyclic" if self.cyclic else "bounded"
        text = f"{rows}×{cols} {kind} grid, {self.open_count} open cells"
        if self.palette:
            text += f", colours {'/'.join(self.palette)}"
        if self.headings > 1:
            text += f", {self.headings} headings per cell"
        return text


def world_from_rows(
    rows: Sequence[str],
    legend: dict[str, str] | None = None,
    cyclic: bool = False,
    headings: int = 1,
) -> GridWorld:
    """Build a world from map rows: one character per cell, ``#`` obstacle, ``.`` open, uncoloured.

    Every other character is a colour; ``legend`` maps characters to colour names (a character
    not in the legend is its own colour name). The palette lists colours in order of first
    appearance in the legend, then in the map.
    """
    if not rows or any(len(row) != len(rows[0]) for row in rows) or not rows[0]:
        bad = next((i for i, row in enumerate(rows) if len(row) != len(rows[0])), 0)
        where = f"world.map[{bad}]" if rows else "world.map"
        raise ConfigError(
            f"{where}: expected non-empty rows of equal length, found lengths "
            f"{[len(r) for r in rows]}"
        )
    legend = dict(legend or {})
    for char in legend:
        if len(char) != 1 or char in (OBSTACLE, UNLABELLED):
            raise ConfigError(
                f"world.legend: keys must be single map characters other than "
                f"'{OBSTACLE}' and '{UNLABELLED}', found {char!r}"
            )
    symbols: list[str] = list(legend)
    for row in rows:
        for char in row:
            if char not in (OBSTACLE, UNLABELLED) and char not in symbols:
                symbols.append(char)
    names = [legend.get(s, s) for s in symbols]
    if len(set(names)) != len(names):
        raise ConfigError(f"world.legend: two map characters share a colour name: {names}")
    index = {s: i for i, s in enumerate(symbols)}
    labels = np.array([[index.get(ch, -1) for ch in row] for row in rows], dtype=np.int16)
    blocked = np.array([[ch == OBSTACLE for ch in row] for row in rows], dtype=bool)
    return GridWorld(labels, blocked, tuple(names), cyclic, headings, tuple(symbols))


def random_colour_world(
    rows: int,
    cols: int,
    palette: Sequence[str],
    rng: np.random.Generator,
    counts: Sequence[int] | None = None,
    cyclic: bool = False,
    headings: int = 1,
) -> GridWorld:
    """A random colour map: each cell i.i.d. uniform over ``palette``, or exactly ``counts`` cells
    of each colour in a random arrangement."""
    if rows < 1 or cols < 1:
        raise ConfigError(f"world.random: rows and cols must be at least 1, found {rows}×{cols}")
    if len(palette) < 1:
        raise ConfigError("world.random.colours: expected at least one colour")
    if counts is None:
        labels = rng.integers(0, len(palette), size=(rows, cols)).astype(np.int16)
    else:
        if len(counts) != len(palette) or any(c < 0 for c in counts):
            raise ConfigError(
                f"world.random.counts: expected {len(palette)} non-negative counts, found "
                f"{list(counts)}"
            )
        if sum(counts) != rows * cols:
            raise ConfigError(
                f"world.random.counts: expected counts summing to {rows * cols} cells, found "
                f"{sum(counts)}"
            )
        flat = np.repeat(np.arange(len(palette), dtype=np.int16), counts)
        labels = rng.permutation(flat).reshape(rows, cols)
    blocked = np.zeros((rows, cols), dtype=bool)
    symbols = tuple(name[:1].upper() for name in palette)
    if len(set(symbols)) != len(symbols):
        symbols = tuple(str(i) for i in range(len(palette)))
    return GridWorld(labels, blocked, tuple(palette), cyclic, headings, symbols)


def shift(a: np.ndarray, dr: int, dc: int, cyclic: bool) -> np.ndarray:
    """Move the content of ``a`` by ``(dr, dc)`` cells along its last two axes.

    ``out[..., r + dr, c + dc] = a[..., r, c]``; cyclic: indices wrap; bounded: what leaves the
    grid is dropped and what enters is zero (callers never move mass over a border).
    """
    if cyclic:
        return np.roll(a, (dr, dc), axis=(-2, -1))
    out = np.zeros_like(a)
    rows, cols = a.shape[-2:]
    if abs(dr) >= rows or abs(dc) >= cols:
        return out
    src_r = slice(max(0, -dr), rows - max(0, dr))
    dst_r = slice(max(0, dr), rows - max(0, -dr))
    src_c = slice(max(0, -dc), cols - max(0, dc))
    dst_c = slice(max(0, dc), cols - max(0, -dc))
    out[..., dst_r, dst_c] = a[..., src_r, src_c]
    return out


def step(belief: np.ndarray, world: GridWorld, d: int) -> np.ndarray:
    """One commanded cell move in direction ``d`` with bounce-back at obstacles and borders.

    ``out = belief·¬m + shift(belief·m, d)`` where ``m`` marks the cells whose neighbour in
    direction ``d`` is open. Total probability is preserved exactly (up to rounding).
    """
    mask = world.can_move[d]
    moved = np.where(mask, belief, 0.0)
    dr, dc = OFFSETS[d]
    return belief - moved + shift(moved, dr, dc, world.cyclic)


def translate(belief: np.ndarray, world: GridWorld, dr: int, dc: int) -> np.ndarray:
    """Move the belief by ``(dr, dc)`` cells: ``|dr|`` unit steps N/S, then ``|dc|`` steps E/W.

    With bounce-back at every unit step a long move stops at the first obstacle or border. In a
    cyclic world without obstacles the unit steps compose to one exact ``np.roll``.
    """
    if dr == 0 and dc == 0:
        return belief.copy()
    if world.cyclic and not world.blocked.any():
        return np.roll(belief, (dr, dc), axis=(-2, -1))
    out = belief
    d_rows = 2 if dr > 0 else 0
    d_cols = 1 if dc > 0 else 3
    for _ in range(abs(dr)):
        out = step(out, world, d_rows)
    for _ in range(abs(dc)):
        out = step(out, world, d_cols)
    return out if out is not belief else belief.copy()
