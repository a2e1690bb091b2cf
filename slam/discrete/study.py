"""``slam grid study``: how fast and how reliably the colour-grid robot localizes itself.

The teaching reports run one map. This study runs many: for each grid side ``n`` and sensor error
``e`` it draws ``trials`` random ``n × n`` maps (each cell one of ``colours`` colours, i.i.d.
uniform), a random true start cell, and simulates the colour-grid robot of the Tampere report:

1. sense: the sensor reports the true colour with ``1 − e``, each other colour with ``e/(K − 1)``;
   the filter updates;
2. stop if one cell holds at least ``threshold`` (the robot declares that cell);
3. move: the robot steps to a uniformly chosen reachable neighbour (unknown heading); the filter
   predicts with the same model.

A trial that has not declared a cell after ``max_steps`` observations counts as not localized.
Per ``(n, e)`` the study reports the fraction localized, the number of observations until the
declaration (median and mean over localized trials) and how often the declared cell is the true
one. Every trial has its own generator seeded by ``(seed, n, e-index, trial)``, so results do not
depend on the order or selection of the other configurations.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from slam.discrete.filter import HistogramFilter, localized, sample_motion
from slam.discrete.motion import UnknownHeading
from slam.discrete.plot import Series, legend_strip, line_chart, side_by_side
from slam.discrete.sensors import ColourSensor
from slam.discrete.world import random_colour_world
from slam.errors import UsageError

COLOUR_NAMES: tuple[str, ...] = (
    "blue",
    "green",
    "red",
    "white",
    "black",
    "yellow",
    "cyan",
    "magenta",
)
"""Names given to the study's colours (the first ``colours`` are used)."""


@dataclass(frozen=True)
class StudyConfig:
    """Parameters of the study; the defaults run in a few seconds."""

    sizes: tuple[int, ...] = (3, 5, 10, 20, 50)
    """Grid sides ``n`` (maps are ``n × n``)."""
    errors: tuple[float, ...] = (0.001, 0.002, 0.005, 0.05)
    """Sensor error probabilities ``e`` (P(correct) = 1 − e)."""
    colours: int = 4
    """Number of colours ``K``."""
    trials: int = 20
    """Random maps per (size, error)."""
    max_steps: int = 100
    """Observations allowed before a trial counts as not localized."""
    threshold: float = 0.999
    """Declare the position when one cell holds at least this probability."""
    seed: int = 0
    """Base seed of every trial's generator."""

    def __post_init__(self) -> None:
        if not self.sizes or min(self.sizes) < 1:
            listed = ",".join(str(v) for v in self.sizes) or "nothing"
            raise UsageError(f"--sizes: expected grid sides ≥ 1, found {listed}")
        if not self.errors or not all(0.0 <= e < 1.0 for e in self.errors):
            listed = ",".join(f"{v:g}" for v in self.errors) or "nothing"
            raise UsageError(f"--errors: expected probabilities in [0, 1), found {listed}")
        if not 2 <= self.colours <= len(COLOUR_NAMES):
            raise UsageError(f"--colours: expected 2..{len(COLOUR_NAMES)}, found {self.colours}")
        for option, value in (("--trials", self.trials), ("--max-steps", self.max_steps)):
            if value < 1:
                raise UsageError(f"{option}: expected at least 1, found {value}")
        if not 0.0 < self.threshold <= 1.0:
            raise UsageError(f"--threshold: expected (0, 1], found {self.threshold:g}")
        if not 0 <= self.seed < 2**63:
            bound = "≥ 0" if self.seed < 0 else "below 2**63"
            raise UsageError(f"--seed: expected an integer {bound}, found {self.seed}")


@dataclass(frozen=True)
class TrialResult:
    """One simulated robot on one random map."""

    steps: int | None
    """Observations until a cell reached the threshold; ``None`` if it never did."""
    correct: bool
    """The declared cell is the true one (False when not localized)."""
    tracked: bool
    """At the trial's last observation the most probable cell is the true one."""


@dataclass(frozen=True)
class StudyRow:
    """Summary of the trials of one (size, error)."""

    size: int
    error: float
    trials: int
    localized: int
    """Trials that declared a cell within ``max_steps``."""
    correct: int
    """Localized trials whose declared cell was the true one."""
    tracked: int
    """Trials whose most probable cell at the last observation was the true one."""
    median_steps: float
    """Median observations until the declaration (localized trials; ``nan`` if none)."""
    mean_steps: float
    """Mean observations until the declaration (localized trials; ``nan`` if none)."""
    seconds: float
    """Wall time of these trials."""

    @property
    def localized_rate(self) -> float:
        """Fraction of trials localized."""
        return self.localized / self.trials

    @property
    def tracked_rate(self) -> float:
        """Fraction of trials whose most probable cell at the end was the true one."""
        return self.tracked / self.trials

    @property
    def correct_rate(self) -> float:
        """Fraction of localized trials that declared the true cell (``nan`` if none)."""
        return self.correct / self.localized if self.localized else float("nan")


def run_trial(
    size: int, error: float, config: StudyConfig, rng: np.random.Generator
) -> TrialResult:
    """Simulate one robot on one random ``size × size`` colour map."""
    world = random_colour_world(size, size, COLOUR_NAMES[: config.colours], rng)
    sensor = ColourSensor(1.0 - error)
    motion = UnknownHeading()
    bayes = HistogramFilter(world, sensor, motion)
    state = (0, int(rng.integers(size)), int(rng.integers(size)))
    for k in range(1, config.max_steps + 1):
        bayes.update(sensor.sample(world, state[1:], rng))
        cell = localized(bayes.belief, config.threshold)
        if cell is not None:
            return TrialResult(k, cell == state[1:], cell == state[1:])
        if k == config.max_steps:
            break
        state = sample_motion(world, motion, state, None, rng)
        bayes.predict(None)
    best = np.unravel_index(int(np.argmax(bayes.posterior)), world.shape)
    return TrialResult(None, False, (int(best[0]), int(best[1])) == state[1:])


def run_study(config: StudyConfig, progress: Callable[[int], None] | None = None) -> list[StudyRow]:
    """All (size, error) configurations; ``progress(n)`` is called after every ``n`` trials."""
    rows = []
    for size in config.sizes:
        for ei, error in enumerate(config.errors):
            start = time.perf_counter()
            results = []
            for t in range(config.trials):
                rng = np.random.default_rng([config.seed, size, ei, t])
                results.append(run_trial(size, error, config, rng))
                if progress is not None:
                    progress(1)
            steps = np.array([r.steps for r in results if r.steps is not None], dtype=float)
            rows.append(
                StudyRow(
                    size=size,
                    error=error,
                    trials=config.trials,
                    localized=int(steps.size),
                    correct=sum(r.correct for r in results),
                    tracked=sum(r.tracked for r in results),
                    median_steps=float(np.median(steps)) if steps.size else float("nan"),
                    mean_steps=float(steps.mean()) if steps.size else float("nan"),
                    seconds=time.perf_counter() - start,
                )
            )
    return rows


def format_rows(rows: Sequence[StudyRow], config: StudyConfig) -> str:
    """The study's table (one line per size and error)."""
    head = (
        f"{'grid':>7} {'error':>6} {'trials':>6} {'localized':>9} {'median':>7} {'mean':>7} "
        f"{'correct':>8} {'argmax':>7}"
    )
    lines = [
        f"Colour grid, {config.colours} colours, unknown heading, declare at max ≥ "
        f"{config.threshold:g}, at most {config.max_steps} observations",
        "",
        head,
        f"{'':>7} {'':>6} {'':>6} {'':>9} {'steps':>7} {'steps':>7} {'':>8} {'= true':>7}",
    ]
    for r in rows:
        median = f"{r.median_steps:7.1f}" if r.localized else f"{'-':>7}"
        mean = f"{r.mean_steps:7.1f}" if r.localized else f"{'-':>7}"
        correct = f"{100 * r.correct_rate:7.1f}%" if r.localized else f"{'-':>8}"
        lines.append(
            f"{f'{r.size}×{r.size}':>7} {r.error:6g} {r.trials:6d} "
            f"{100 * r.localized_rate:8.1f}% {median} {mean} {correct} "
            f"{100 * r.tracked_rate:6.1f}%"
        )
    lines += [
        "",
        "localized: trials in which one cell reached the threshold; steps: observations until",
        "then; correct: the declared cell was the true one; argmax = true: the most probable",
        "cell at the trial's last observation was the true one.",
        "Ceiling: after a move the threshold t is reachable only if e/((K-1)(1-e)) <= (1-t)/t,",
        f"i.e. e <= {ceiling_error(config.colours, config.threshold):.5f} here (see docs/grid.md).",
    ]
    return "\n".join(lines)


def rows_json(rows: Sequence[StudyRow]) -> list[dict]:
    """Rows as JSON-ready dicts (``None`` for undefined statistics)."""

    def clean(v: float) -> float | None:
        return None if not np.isfinite(v) else round(float(v), 6)

    return [
        {
            "size": r.size,
            "error": r.error,
            "trials": r.trials,
            "localized": r.localized,
            "correct": r.correct,
            "localized_rate": clean(r.localized_rate),
            "correct_rate": clean(r.correct_rate),
            "tracked": r.tracked,
            "tracked_rate": clean(r.tracked_rate),
            "median_steps": clean(r.median_steps),
            "mean_steps": clean(r.mean_steps),
            "seconds": round(r.seconds, 3),
        }
        for r in rows
    ]


def ceiling_error(colours: int, threshold: float) -> float:
    """Largest sensor error at which a cell can reach ``threshold`` right after a move.

    After an unknown-heading move every cell ``x'`` shares the mass of each predecessor with at
    least one other neighbour, whose likelihood is at least ``e/(K − 1)`` against ``x'``'s at most
    ``1 − e``; so ``bel(x') ≥ t`` needs ``e/((K − 1)(1 − e)) ≤ (1 − t)/t``.
    """
    q = (1.0 - threshold) / threshold * (colours - 1)
    return q / (1.0 + q)


def study_figure(rows: Sequence[StudyRow], config: StudyConfig) -> np.ndarray:
    """Four panels against the grid side: localized %, median observations, declared correct %,
    argmax-is-true %; one line per sensor error."""
    panels: dict[str, list[Series]] = {"localized": [], "steps": [], "correct": [], "tracked": []}
    for error in config.errors:
        mine = [r for r in rows if r.error == error]
        x = [r.size for r in mine]
        label = f"error {error:g}"
        panels["localized"].append(Series(label, x, [100 * r.localized_rate for r in mine]))
        panels["steps"].append(Series(label, x, [r.median_steps for r in mine]))
        panels["correct"].append(Series(label, x, [100 * r.correct_rate for r in mine]))
        panels["tracked"].append(Series(label, x, [100 * r.tracked_rate for r in mine]))
    log_x = max(config.sizes) / min(config.sizes) >= 4
    x_label = "grid side n (n x n cells)"
    t = f"{config.threshold:g}"
    percent = (0.0, 105.0)
    common = {"log_x": log_x, "legend": False}
    top = side_by_side(
        [
            line_chart(
                panels["localized"], f"Trials with a cell >= {t} (%)", x_label, "%",
                y_range=percent, **common,
            ),
            line_chart(
                panels["steps"], f"Observations until a cell >= {t} (median)", x_label,
                "observations", **common,
            ),
        ]
    )  # fmt: skip
    bottom = side_by_side(
        [
            line_chart(
                panels["correct"], "Declared cell is the true one (%)", x_label, "%",
                y_range=percent, **common,
            ),
            line_chart(
                panels["tracked"], "Most probable cell is the true one at the end (%)",
                x_label, "%", y_range=percent, **common,
            ),
        ]
    )  # fmt: skip
    labels = [s.label for s in panels["steps"]]
    return np.concatenate([legend_strip(labels, top.shape[1]), top, bottom], axis=0)
