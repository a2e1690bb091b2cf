"""Sensor models of the discrete filter: the likelihood ``p(z | x)`` of an observation in every cell.

The Bayes update multiplies the belief by the likelihood of the observation ``z`` in each state
and renormalises: ``bel(x) ∝ p(z | x) · bel⁻(x)``. A sensor model here returns that likelihood as an
``(R, C)`` array (sensors see the cell, not the heading, so it broadcasts over the heading axis);
obstacle cells get likelihood 0 because the robot is never there.

Models:

* :class:`ColourSensor` — the cell's colour is reported correctly with probability ``p_correct``;
  the remaining ``1 − p_correct`` is spread evenly over the other ``K − 1`` colours, i.e. the
  confusion matrix ``M[i, j] = p_correct`` if ``i = j`` else ``(1 − p_correct)/(K − 1)``.
* :class:`ConfusionSensor` — a general confusion matrix ``M[true colour, observed symbol]`` with
  rows summing to 1; the likelihood of symbol ``z`` is ``M[label(x), z]``.
* :class:`WnesSensor` — four obstacle bits (West, North, East, South; 1 = obstacle sensed),
  independent given the cell, each with ``P(1 | obstacle) = p_obstacle_given_obstacle``,
  ``P(0 | obstacle) = 1 − p_obstacle_given_obstacle``, ``P(0 | open) = p_open_given_open`` and
  ``P(1 | open) = 1 − p_open_given_open``; the likelihood is the product over the four bits. The
  border of a bounded world counts as an obstacle.

Each model also *parses* observations from text (``"blue"``, ``"1000"``), *formats* them back, and
*samples* one given the true cell (for simulation), with a caller-supplied random generator.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from slam.discrete.world import GridWorld
from slam.errors import ConfigError

WNES_ORDER: tuple[int, ...] = (3, 0, 1, 2)
"""Direction indices (N=0, E=1, S=2, W=3) of the sensor's bits in West, North, East, South order."""


class SensorModel(Protocol):
    """What the filter needs from a sensor model."""

    def parse_observation(self, world: GridWorld, text: str) -> object:
        """Observation from text; :class:`~slam.errors.ConfigError` when malformed."""
        ...

    def format_observation(self, world: GridWorld, observation: object) -> str:
        """Observation as text (the inverse of :meth:`parse_observation`)."""
        ...

    def likelihood(self, world: GridWorld, observation: object) -> np.ndarray:
        """``(R, C)`` array ``p(z | cell)``; 0 on obstacles."""
        ...

    def sample(self, world: GridWorld, cell: tuple[int, int], rng: np.random.Generator) -> object:
        """Draw an observation in ``cell``."""
        ...

    def describe(self) -> str:
        """One line naming the model and its parameters."""
        ...


def _check_probability(name: str, value: float) -> None:
    if not 0.0 <= value <= 1.0:
        raise ConfigError(f"{name}: expected a probability in [0, 1], found {value}")


def _colour_labels(world: GridWorld, model: str) -> np.ndarray:
    unlabelled = world.open & (world.labels < 0)
    if unlabelled.any():
        r, c = np.argwhere(unlabelled)[0]
        raise ConfigError(
            f"{model} sensor: every open cell needs a colour; cell ({r}, {c}) has none"
        )
    return world.labels


@dataclass(frozen=True, eq=False)
class ConfusionSensor:
    """General colour sensor: ``matrix[i, j] = P(observe symbol j | cell colour i)``."""

    matrix: np.ndarray
    """``(K, Z)`` row-stochastic matrix, K = number of colours in the world's palette."""
    observations: tuple[str, ...] = ()
    """Names of the Z observable symbols; empty: the world's palette (square matrix)."""

    def __post_init__(self) -> None:
        m = np.asarray(self.matrix, dtype=float)
        if m.ndim != 2 or m.size == 0:
            raise ConfigError(
                f"sensor.matrix: expected a non-empty 2D matrix, found shape {m.shape}"
            )
        if not np.isfinite(m).all() or (m < 0).any():
            raise ConfigError("sensor.matrix: expected finite non-negative probabilities")
        sums = m.sum(axis=1)
        if not np.allclose(sums, 1.0, atol=1e-9):
            bad = int(np.argmax(np.abs(sums - 1.0)))
            raise ConfigError(f"sensor.matrix: row {bad} sums to {float(sums[bad]):g}; expected 1")
        if self.observations and len(self.observations) != m.shape[1]:
            raise ConfigError(
                f"sensor.observations: {len(self.observations)} names for a matrix with "
                f"{m.shape[1]} columns"
            )
        m.setflags(write=False)
        object.__setattr__(self, "matrix", m)

    def _symbols(self, world: GridWorld) -> tuple[str, ...]:
        if self.observations:
            return self.observations
        if self.matrix.shape != (len(world.palette), len(world.palette)):
            raise ConfigError(
                f"sensor.matrix: expected {len(world.palette)}×{len(world.palette)} for the "
                f"world's colours {', '.join(world.palette)}, found "
                f"{self.matrix.shape[0]}×{self.matrix.shape[1]}"
            )
        return world.palette

    def check(self, world: GridWorld) -> None:
        """Raise :class:`ConfigError` unless this sensor fits ``world``."""
        _colour_labels(world, "confusion")
        if self.matrix.shape[0] != len(world.palette):
            raise ConfigError(
                f"sensor.matrix: expected one row per colour ({len(world.palette)}: "
                f"{', '.join(world.palette)}), found {self.matrix.shape[0]}"
            )
        self._symbols(world)

    def parse_observation(self, world: GridWorld, text: str) -> int:
        """Index of the observed symbol (name or, for palette symbols, the map character)."""
        symbols = self._symbols(world)
        wanted = text.strip().lower()
        for j, name in enumerate(symbols):
            if wanted == name.lower():
                return j
        if not self.observations:
            return world.colour_index(text)
        raise ConfigError(f"unknown observation {text!r}; expected one of {', '.join(symbols)}")

    def format_observation(self, world: GridWorld, observation: object) -> str:
        """Name of the observed symbol."""
        return self._symbols(world)[int(observation)]  # type: ignore[call-overload]

    def likelihood(self, world: GridWorld, observation: object) -> np.ndarray:
        """``M[label(x), z]`` on open cells, 0 on obstacles."""
        labels = _colour_labels(world, "confusion")
        column = self.matrix[:, int(observation)]  # type: ignore[call-overload]
        return np.where(world.open, column[np.maximum(labels, 0)], 0.0)

    def sample(self, world: GridWorld, cell: tuple[int, int], rng: np.random.Generator) -> int:
        """Draw a symbol from the row of the cell's colour."""
        row = self.matrix[world.labels[cell]]
        return int(rng.choice(row.size, p=row))

    def describe(self) -> str:
        """One line naming the model."""
        k, z = self.matrix.shape
        return f"confusion-matrix colour sensor ({k} colours × {z} symbols)"


@functools.lru_cache(maxsize=64)
def _colour_confusion(p_correct: float, colours: int) -> ConfusionSensor:
    return ConfusionSensor(ColourSensor(p_correct).confusion(colours))


@dataclass(frozen=True)
class ColourSensor:
    """Colour sensor: correct with ``p_correct``, else one of the other colours uniformly."""

    p_correct: float
    """Probability of reporting the cell's true colour."""

    def __post_init__(self) -> None:
        _check_probability("sensor.p_correct", self.p_correct)

    def confusion(self, colours: int) -> np.ndarray:
        """The ``(K, K)`` confusion matrix of this sensor for ``K = colours``."""
        if colours < 2:
            raise ConfigError(
                f"colour sensor: a world needs at least 2 colours to be sensed, found {colours}"
            )
        off = (1.0 - self.p_correct) / (colours - 1)
        matrix = np.full((colours, colours), off)
        np.fill_diagonal(matrix, self.p_correct)
        return matrix

    def _as_confusion(self, world: GridWorld) -> ConfusionSensor:
        return _colour_confusion(self.p_correct, len(world.palette))

    def check(self, world: GridWorld) -> None:
        """Raise :class:`ConfigError` unless this sensor fits ``world``."""
        _colour_labels(world, "colour")
        self.confusion(len(world.palette))

    def parse_observation(self, world: GridWorld, text: str) -> int:
        """Palette index of the colour named (or drawn as a map character) by ``text``."""
        return world.colour_index(text)

    def format_observation(self, world: GridWorld, observation: object) -> str:
        """Colour name."""
        return world.palette[int(observation)]  # type: ignore[call-overload]

    def likelihood(self, world: GridWorld, observation: object) -> np.ndarray:
        """``p_correct`` on cells of the observed colour, ``(1 − p_correct)/(K − 1)`` elsewhere."""
        return self._as_confusion(world).likelihood(world, observation)

    def sample(self, world: GridWorld, cell: tuple[int, int], rng: np.random.Generator) -> int:
        """Draw a colour reading in ``cell``."""
        return self._as_confusion(world).sample(world, cell, rng)

    def describe(self) -> str:
        """One line naming the model."""
        return f"colour sensor, P(correct) = {self.p_correct:g}"


@dataclass(frozen=True)
class WnesSensor:
    """Four independent obstacle bits, West, North, East, South (1 = obstacle sensed)."""

    p_obstacle_given_obstacle: float = 0.85
    """P(bit = 1 | obstacle or border in that direction)."""
    p_open_given_open: float = 0.95
    """P(bit = 0 | open cell in that direction)."""

    def __post_init__(self) -> None:
        _check_probability("sensor.p_obstacle_given_obstacle", self.p_obstacle_given_obstacle)
        _check_probability("sensor.p_open_given_open", self.p_open_given_open)

    def check(self, world: GridWorld) -> None:
        """Any world fits."""

    def parse_observation(self, world: GridWorld, text: str) -> tuple[int, int, int, int]:
        """Four bits in WNES order: ``"1000"``, ``"1 0 0 0"`` or ``"[1, 0, 0, 0]"``."""
        digits = [ch for ch in text if ch not in " ,[]"]
        if len(digits) != 4 or any(ch not in "01" for ch in digits):
            raise ConfigError(
                f"WNES observation {text!r}: expected four bits West, North, East, South, e.g. 1000"
            )
        return tuple(int(ch) for ch in digits)  # type: ignore[return-value]

    def format_observation(self, world: GridWorld, observation: object) -> str:
        """Bits as ``[w, n, e, s]`` (the classic assignment's notation)."""
        return "[" + ", ".join(str(b) for b in observation) + "]"  # type: ignore[union-attr]

    def bit_probabilities(self) -> np.ndarray:
        """``P[truth, bit]``: rows truth open/obstacle, columns sensed 0/1."""
        po, pe = self.p_obstacle_given_obstacle, self.p_open_given_open
        return np.array([[pe, 1.0 - pe], [1.0 - po, po]])

    def likelihood(self, world: GridWorld, observation: object) -> np.ndarray:
        """``∏_b P(z_b | truth_b)`` over the four bits, 0 on obstacles."""
        table = self.bit_probabilities()
        out = np.where(world.open, 1.0, 0.0)
        for bit, d in zip(observation, WNES_ORDER, strict=True):  # type: ignore[call-overload]
            truth = world.neighbour_blocked[d]
            out *= np.where(truth, table[1, bit], table[0, bit])
        return out

    def sample(
        self, world: GridWorld, cell: tuple[int, int], rng: np.random.Generator
    ) -> tuple[int, int, int, int]:
        """Draw the four bits in ``cell``."""
        table = self.bit_probabilities()
        u = rng.random(4)
        bits = []
        for k, d in enumerate(WNES_ORDER):
            truth = int(world.neighbour_blocked[d][cell])
            bits.append(int(u[k] < table[truth, 1]))
        return tuple(bits)  # type: ignore[return-value]

    def describe(self) -> str:
        """One line naming the model and its four probabilities."""
        po, pe = self.p_obstacle_given_obstacle, self.p_open_given_open
        return (
            f"WNES obstacle sensor, P(1|obstacle) = {po:g}, P(0|obstacle) = {1 - po:g}, "
            f"P(0|open) = {pe:g}, P(1|open) = {1 - pe:g}"
        )
