"""Motion models of the discrete filter: the prediction ``bel⁻(x') = Σ_x p(x' | x, u) · bel(x)``.

Every model here is a mixture of deterministic moves on the grid (see :mod:`slam.discrete.world`
for ``shift``, ``step`` with bounce-back and ``translate``), so the prediction is a weighted sum of
shifted copies of the belief — a convolution in a cyclic world — and preserves total probability.

Models and their actions:

* :class:`ShiftMotion` — the tutorial's inexact motion in a cyclic 1D world: commanded move ``U``
  cells happens exactly with ``p_exact``, one cell short (``U − 1``) with ``p_undershoot``, one
  cell long (``U + 1``) with ``p_overshoot``: ``bel⁻ = Σ_k p_k · shift(bel, U + k)``. Action ``"2"``
  (columns, 1D) or ``"dr,dc"`` (2D; the under/overshoot is one cell along the command's signs).
* :class:`MoveOrStay` — the Udacity model: the commanded ``(dr, dc)`` move happens with ``p_move``,
  otherwise the robot stays: ``bel⁻ = p_move · shift(bel, u) + (1 − p_move) · bel``.
* :class:`DriftMotion` — command N/E/S/W: ``p_forward`` in the commanded direction, ``p_left`` and
  ``p_right`` drift 90° to either side, the rest stays; a move into an obstacle or the border
  bounces back (the robot stays in its cell).
* :class:`UnknownHeading` — the robot moves to one of its reachable neighbours, uniformly:
  ``p(x' | x) = 1 / n(x)`` for each of the ``n(x)`` open neighbours (edge cells have fewer); a cell
  with no open neighbour keeps its mass. Action ``"any"``.
* :class:`HeadingMotion` — state (cell, heading): ``"F"`` moves one cell along the heading with
  ``p_move`` (bounce-back at obstacles), else stays; ``"L"``/``"R"`` turn 90° with ``p_turn``, else
  the heading is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from slam.discrete.world import (
    DIRECTIONS,
    OFFSETS,
    GridWorld,
    left_of,
    right_of,
    shift,
    step,
    translate,
)
from slam.errors import ConfigError

TOLERANCE = 1e-9
"""Slack allowed when checking that a model's probabilities sum to at most 1."""


class MotionModel(Protocol):
    """What the filter needs from a motion model."""

    def check(self, world: GridWorld) -> None:
        """Raise :class:`ConfigError` unless the model fits ``world``."""
        ...

    def parse_action(self, world: GridWorld, text: str) -> object:
        """Action from text; :class:`ConfigError` when malformed."""
        ...

    def predict(self, belief: np.ndarray, world: GridWorld, action: object) -> np.ndarray:
        """The predicted belief ``Σ_x p(x' | x, u) · bel(x)``, shape ``(H, R, C)``."""
        ...

    def describe(self) -> str:
        """One line naming the model and its parameters."""
        ...


def _check_probabilities(model: str, **values: float) -> float:
    for name, value in values.items():
        if not 0.0 <= value <= 1.0:
            raise ConfigError(f"motion.{name}: expected a probability in [0, 1], found {value}")
    total = sum(values.values())
    if total > 1.0 + TOLERANCE:
        raise ConfigError(f"motion ({model}): {' + '.join(values)} = {total:g}; expected at most 1")
    return total


def _require_cell_state(world: GridWorld, model: str) -> None:
    if world.headings != 1:
        raise ConfigError(
            f"motion {model}: works on cell states; this world has {world.headings} headings "
            f"per cell (use motion type 'heading')"
        )


def parse_offset(world: GridWorld, text: str) -> tuple[int, int]:
    """A move ``"k"`` (``k`` columns, only in 1D worlds) or ``"dr,dc"`` (``"[0, 1]"`` too)."""
    parts = [p for p in text.replace("[", " ").replace("]", " ").replace(",", " ").split() if p]
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        numbers = []
    if len(numbers) == 2:
        return numbers[0], numbers[1]
    if len(numbers) == 1 and world.shape[0] == 1:
        return 0, numbers[0]
    expected = "'dr,dc'" + (" or a column count 'k'" if world.shape[0] == 1 else "")
    raise ConfigError(f"move {text!r}: expected {expected} (integers)")


@dataclass(frozen=True)
class ShiftMotion:
    """Exact / undershoot / overshoot kernel around the commanded move."""

    p_exact: float = 0.8
    """Probability of moving exactly the commanded number of cells."""
    p_undershoot: float = 0.1
    """Probability of moving one cell less."""
    p_overshoot: float = 0.1
    """Probability of moving one cell more."""

    def __post_init__(self) -> None:
        total = _check_probabilities(
            "shift",
            p_exact=self.p_exact,
            p_undershoot=self.p_undershoot,
            p_overshoot=self.p_overshoot,
        )
        if abs(total - 1.0) > TOLERANCE:
            raise ConfigError(
                f"motion (shift): p_exact + p_undershoot + p_overshoot = {total:g}; expected 1"
            )

    def check(self, world: GridWorld) -> None:
        """Cell states only."""
        _require_cell_state(world, "shift")

    def parse_action(self, world: GridWorld, text: str) -> tuple[int, int]:
        """``"k"`` in a 1D world, else ``"dr,dc"``."""
        return parse_offset(world, text)

    def kernel(self, action: tuple[int, int]) -> list[tuple[float, tuple[int, int]]]:
        """``[(probability, (dr, dc)), …]`` of the exact, undershoot and overshoot moves."""
        dr, dc = action
        unit = (int(np.sign(dr)), int(np.sign(dc))) if (dr or dc) else (0, 1)
        return [
            (self.p_exact, (dr, dc)),
            (self.p_undershoot, (dr - unit[0], dc - unit[1])),
            (self.p_overshoot, (dr + unit[0], dc + unit[1])),
        ]

    def predict(self, belief: np.ndarray, world: GridWorld, action: object) -> np.ndarray:
        """``Σ_k p_k · translate(bel, U + k)`` (a circular convolution in a cyclic world)."""
        out = np.zeros_like(belief)
        for p, (dr, dc) in self.kernel(action):  # type: ignore[arg-type]
            if p:
                out += p * translate(belief, world, dr, dc)
        return out

    def describe(self) -> str:
        """One line naming the model."""
        return (
            f"shift motion, exact {self.p_exact:g}, undershoot {self.p_undershoot:g}, "
            f"overshoot {self.p_overshoot:g}"
        )


@dataclass(frozen=True)
class MoveOrStay:
    """The commanded move happens with ``p_move``, otherwise the robot stays."""

    p_move: float = 1.0
    """Probability that the move happens."""

    def __post_init__(self) -> None:
        _check_probabilities("move_or_stay", p_move=self.p_move)

    def check(self, world: GridWorld) -> None:
        """Cell states only."""
        _require_cell_state(world, "move_or_stay")

    def parse_action(self, world: GridWorld, text: str) -> tuple[int, int]:
        """``"k"`` in a 1D world, else ``"dr,dc"``."""
        return parse_offset(world, text)

    def predict(self, belief: np.ndarray, world: GridWorld, action: object) -> np.ndarray:
        """``p_move · translate(bel, u) + (1 − p_move) · bel``."""
        dr, dc = action  # type: ignore[misc]
        return self.p_move * translate(belief, world, dr, dc) + (1.0 - self.p_move) * belief

    def describe(self) -> str:
        """One line naming the model."""
        return f"moves with p = {self.p_move:g}, else stays"


def parse_direction(text: str) -> int:
    """Direction index of ``"N"``, ``"E"``, ``"S"`` or ``"W"`` (case-insensitive)."""
    wanted = text.strip().upper()
    if wanted not in DIRECTIONS:
        raise ConfigError(f"move {text!r}: expected one of {', '.join(DIRECTIONS)}")
    return DIRECTIONS.index(wanted)


@dataclass(frozen=True)
class DriftMotion:
    """Commanded direction with drift to the left and right, bounce-back at obstacles."""

    p_forward: float = 0.8
    """Probability of moving in the commanded direction."""
    p_left: float = 0.1
    """Probability of drifting one cell 90° to the left of the command."""
    p_right: float = 0.1
    """Probability of drifting one cell 90° to the right of the command."""

    def __post_init__(self) -> None:
        _check_probabilities(
            "drift", p_forward=self.p_forward, p_left=self.p_left, p_right=self.p_right
        )

    @property
    def p_stay(self) -> float:
        """Probability of not moving at all (what the three moves leave)."""
        return max(0.0, 1.0 - self.p_forward - self.p_left - self.p_right)

    def check(self, world: GridWorld) -> None:
        """Cell states only."""
        _require_cell_state(world, "drift")

    def parse_action(self, world: GridWorld, text: str) -> int:
        """``"N"``, ``"E"``, ``"S"`` or ``"W"``."""
        return parse_direction(text)

    def predict(self, belief: np.ndarray, world: GridWorld, action: object) -> np.ndarray:
        """``p_f·step(bel, d) + p_l·step(bel, left(d)) + p_r·step(bel, right(d)) + p_stay·bel``."""
        d = int(action)  # type: ignore[call-overload]
        out = self.p_stay * belief
        for p, direction in (
            (self.p_forward, d),
            (self.p_left, left_of(d)),
            (self.p_right, right_of(d)),
        ):
            if p:
                out += p * step(belief, world, direction)
        return out

    def describe(self) -> str:
        """One line naming the model."""
        return (
            f"drift motion, forward {self.p_forward:g}, left {self.p_left:g}, "
            f"right {self.p_right:g}, bounce-back at obstacles"
        )


@dataclass(frozen=True)
class UnknownHeading:
    """Move to one of the reachable neighbours, each with the same probability."""

    def check(self, world: GridWorld) -> None:
        """Cell states only."""
        _require_cell_state(world, "unknown_heading")

    def parse_action(self, world: GridWorld, text: str) -> None:
        """The only action is ``"any"`` (or an empty move)."""
        if text.strip().lower() not in ("", "any"):
            raise ConfigError(
                f"move {text!r}: the unknown-heading model has no commands; use 'move any'"
            )
        return None

    def predict(self, belief: np.ndarray, world: GridWorld, action: object = None) -> np.ndarray:
        """``bel⁻(x') = Σ_{x → x'} bel(x) / n(x)``; cells with ``n(x) = 0`` keep their mass."""
        reach = world.can_move
        count = reach.sum(axis=0)
        share = np.divide(belief, count, out=np.zeros_like(belief), where=count > 0)
        out = np.where(count == 0, belief, 0.0)
        for d, (dr, dc) in enumerate(OFFSETS):
            out += shift(np.where(reach[d], share, 0.0), dr, dc, world.cyclic)
        return out

    def sample(
        self,
        world: GridWorld,
        state: tuple[int, int, int],
        action: object,
        rng: np.random.Generator,
    ) -> tuple[int, int, int]:
        """Draw the next state: one of the reachable neighbours, uniformly (else stay)."""
        h, r, c = state
        choices = [d for d in range(4) if world.can_move[d, r, c]]
        if not choices:
            return state
        dr, dc = OFFSETS[choices[int(rng.integers(len(choices)))]]
        rows, cols = world.shape
        return h, (r + dr) % rows, (c + dc) % cols

    def describe(self) -> str:
        """One line naming the model."""
        return "unknown heading: uniform over the reachable neighbours"


_NO_WEIGHTS = np.ones((1, 1))
_NO_WEIGHTS.setflags(write=False)  # same numba signature as the filter's read-only likelihoods

HEADING_ACTIONS: tuple[str, ...] = ("F", "L", "R")
"""Actions of :class:`HeadingMotion`: forward, turn left, turn right."""


@dataclass(frozen=True)
class HeadingMotion:
    """State (cell, heading): forward along the heading, or turn 90° left or right."""

    p_move: float = 0.9
    """Probability that a forward command moves one cell (else the robot stays)."""
    p_turn: float = 0.9
    """Probability that a turn command turns 90° (else the heading is unchanged)."""

    def __post_init__(self) -> None:
        _check_probabilities("heading", p_move=self.p_move)
        _check_probabilities("heading", p_turn=self.p_turn)

    def check(self, world: GridWorld) -> None:
        """Needs a world with 4 headings per cell."""
        if world.headings != 4:
            raise ConfigError(f"motion heading: needs world.headings = 4, found {world.headings}")

    def parse_action(self, world: GridWorld, text: str) -> int:
        """``"F"`` (forward), ``"L"`` (turn left) or ``"R"`` (turn right)."""
        wanted = text.strip().upper()
        if wanted not in HEADING_ACTIONS:
            raise ConfigError(
                f"move {text!r}: expected F (forward), L (turn left) or R (turn right)"
            )
        return HEADING_ACTIONS.index(wanted)

    def predict_into(
        self,
        belief: np.ndarray,
        world: GridWorld,
        action: object,
        out: np.ndarray,
        likelihood: np.ndarray | None = None,
    ) -> float:
        """Write the prediction into ``out`` in one numba pass (times ``likelihood`` when given:
        a fused predict + update, not yet normalised); return the total of ``out``."""
        from slam.discrete import kernels

        weighted = likelihood is not None
        weights = likelihood if weighted else _NO_WEIGHTS
        kind = int(action)  # type: ignore[call-overload]
        if kind == 0:
            return kernels.heading_forward(
                belief, world.can_move, self.p_move, world.cyclic, weights, weighted, out
            )
        return kernels.heading_turn(
            belief, self.p_turn, -1 if kind == 1 else 1, weights, weighted, out
        )

    def predict(self, belief: np.ndarray, world: GridWorld, action: object) -> np.ndarray:
        """Forward: ``bel⁻[h] = (1 − p)·bel[h] + p·step(bel[h], h)``; turn left/right:
        ``bel⁻[h] = (1 − p)·bel[h] + p·bel[h ± 1]``, a roll of the heading axis."""
        out = np.empty_like(belief)
        self.predict_into(belief, world, action, out)
        return out

    def describe(self) -> str:
        """One line naming the model."""
        return f"heading motion, forward succeeds {self.p_move:g}, turn succeeds {self.p_turn:g}"
