"""Grid-localization scenarios: TOML files and the Udacity test vectors, run step by step.

A scenario is a world, a sensor model, a motion model, a prior and a sequence of steps
(``sense Z`` / ``move U``). This module owns

* reading scenario TOML files (``configs/grid/*.toml``) — data only, every table declared as a
  validated dataclass (:mod:`slam.validate`): an unknown key, a wrong type or a value out of its
  bounds is a :class:`~slam.errors.ConfigError` naming the file and the key; a world too large for
  the machine's memory is refused before it is allocated (:mod:`slam.budget`);
* reading ``gridloc/udacity_cases.json`` (cyclic world, uniform prior, per step MOVE then SENSE,
  motion "exact with ``p_move`` else stay", sensor correct with ``sensor_right``) into scenarios
  with their expected final posterior;
* finding a scenario by shipped name, ``udacity:<case>`` or path (:func:`resolve_scenario`);
* running a scenario (:func:`run_scenario`), which returns the belief after every step so that a
  recorder can log one posterior heat map per step;
* the classic text rendering of a posterior (percent with two decimals, obstacles as ``[]``).

Scenario TOML, all tables optional except ``[world]``::

    description = "..."
    [world]            # map = ["..#.", ...] (one char per cell: '#' obstacle, '.' open, else a
                       # colour), or a [world.random] table; cyclic = false; headings = 1 | 4;
                       # legend = { B = "blue", ... }
    [world.random]     # rows, cols, colours = [...], seed, counts = [...] (optional)
    [sensor]           # type = "colour" (p_correct) | "wnes" (p_obstacle_given_obstacle,
                       # p_open_given_open) | "confusion" (matrix, observations)
    [motion]           # type = "shift" (p_exact, p_undershoot, p_overshoot) | "move_or_stay"
                       # (p_move) | "drift" (p_forward, p_left, p_right) | "unknown_heading" |
                       # "heading" (p_move, p_turn)
    [prior]            # values = [...] or [[...], ...]; absent: uniform over open cells
    [run]              # steps = ["sense 0000", "move N", ...]; threshold = 0.999 (optional)
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from slam.budget import check_memory
from slam.discrete.filter import HistogramFilter, ImpossibleObservation, localized
from slam.discrete.motion import (
    DriftMotion,
    HeadingMotion,
    MotionModel,
    MoveOrStay,
    ShiftMotion,
    UnknownHeading,
)
from slam.discrete.sensors import ColourSensor, ConfusionSensor, SensorModel, WnesSensor
from slam.discrete.world import HEADING_COUNTS, GridWorld, random_colour_world, world_from_rows
from slam.errors import ConfigError, DataError, UsageError
from slam.resources import config_dir
from slam.validate import Rule, Validated, bounded, from_table, read_toml

UDACITY_FILE = Path("gridloc") / "udacity_cases.json"
"""Location of the Udacity test vectors inside the data directory."""

UDACITY_PREFIX = "udacity:"
"""Scenario names ``udacity:<case>`` select one case of :data:`UDACITY_FILE`."""

STEP_KINDS: tuple[str, ...] = ("sense", "move")
"""The two kinds of step: a measurement update or a prediction."""


@dataclass(frozen=True)
class Step:
    """One step of a scenario: ``sense`` an observation or ``move`` with an action."""

    kind: str
    """``"sense"`` or ``"move"``."""
    text: str
    """The observation or action as written (e.g. ``"1000"``, ``"N"``, ``"0,1"``)."""
    value: Any
    """The parsed observation or action the models consume."""


@dataclass(frozen=True, eq=False)
class Scenario:
    """Everything a grid-localization run needs."""

    name: str
    """Short name (file stem, or ``udacity:<case>``)."""
    world: GridWorld
    """The grid."""
    sensor: SensorModel | None
    """Sensor model (``None`` when the scenario never senses)."""
    motion: MotionModel | None
    """Motion model (``None`` when the scenario never moves)."""
    steps: tuple[Step, ...]
    """The sequence to run."""
    prior: np.ndarray | None = None
    """Prior belief, ``(R, C)`` or ``(H, R, C)``; ``None``: uniform over open cells."""
    threshold: float | None = None
    """Stop once one cell holds at least this probability (after a sense step)."""
    description: str = ""
    """One-line summary."""
    expected: np.ndarray | None = None
    """Expected final posterior (test vectors), ``(R, C)``."""
    source: str = ""
    """Where the scenario came from (file path, ``file#case``)."""

    def make_filter(self) -> HistogramFilter:
        """A fresh :class:`HistogramFilter` at the scenario's prior."""
        return HistogramFilter(self.world, self.sensor, self.motion, self.prior)


@dataclass(frozen=True, eq=False)
class StepRecord:
    """The belief right after one step (what a recorder logs as a heat map)."""

    index: int
    """0-based position in the scenario's steps."""
    after: str
    """``"sense"`` or ``"move"``."""
    action: str
    """The observation or action, formatted for people."""
    belief: np.ndarray
    """``(H, R, C)`` belief after the step."""

    @property
    def posterior(self) -> np.ndarray:
        """``(R, C)`` probability of each cell."""
        return self.belief.sum(axis=0)


@dataclass(eq=False)
class RunResult:
    """The history of one scenario run."""

    scenario: Scenario
    steps: list[StepRecord] = field(default_factory=list)
    """One record per executed step."""
    localized_cell: tuple[int, int] | None = None
    """Cell that first reached the threshold (stopping rule), if any."""
    localized_step: int | None = None
    """Index in :attr:`steps` of the sense step where it did."""

    @property
    def final(self) -> np.ndarray:
        """``(R, C)`` posterior after the last executed step."""
        if self.steps:
            return self.steps[-1].posterior
        return self.scenario.make_filter().posterior

    @property
    def expected_error(self) -> float | None:
        """Largest absolute difference to the scenario's expected posterior, if it has one."""
        if self.scenario.expected is None:
            return None
        return float(np.max(np.abs(self.final - self.scenario.expected)))


def format_observation(scenario: Scenario, step: Step) -> str:
    """How a step's observation or action is shown to people."""
    if step.kind == "sense" and scenario.sensor is not None:
        return scenario.sensor.format_observation(scenario.world, step.value)
    return step.text


def run_scenario(
    scenario: Scenario,
    on_step: Callable[[StepRecord], None] | None = None,
    stop_when_localized: bool = True,
) -> RunResult:
    """Run every step; record the belief after each (and call ``on_step`` with each record).

    With a scenario threshold and ``stop_when_localized``, the run ends after the first sense
    step whose posterior has a cell at or above the threshold.
    """
    bayes = scenario.make_filter()
    result = RunResult(scenario)
    for i, step in enumerate(scenario.steps):
        try:
            if step.kind == "sense":
                bayes.update(step.value)
            else:
                bayes.predict(step.value)
        except ImpossibleObservation as exc:
            raise ImpossibleObservation(
                f"{scenario.source or scenario.name}: step {i} ({step.kind} {step.text}): {exc}"
            ) from None
        record = StepRecord(i, step.kind, format_observation(scenario, step), bayes.belief.copy())
        result.steps.append(record)
        if on_step is not None:
            on_step(record)
        if scenario.threshold is not None and step.kind == "sense":
            cell = localized(bayes.belief, scenario.threshold)
            if cell is not None and result.localized_cell is None:
                result.localized_cell, result.localized_step = cell, i
                if stop_when_localized:
                    break
    return result


def format_table(posterior: np.ndarray, world: GridWorld) -> str:
    """Posterior in percent with two decimals, obstacles as ``[]``, one line per row."""
    lines = []
    for r in range(posterior.shape[0]):
        cells = [
            f"{'[]':>6}" if world.blocked[r, c] else f"{100.0 * posterior[r, c]:6.2f}"
            for c in range(posterior.shape[1])
        ]
        lines.append(" ".join(cells))
    return "\n".join(lines)


def step_title(record: StepRecord) -> str:
    """The classic assignment's table titles."""
    if record.after == "sense":
        return f"Filtering after Evidence {record.action}"
    return f"Prediction after Action {record.action}"


def posterior_json(posterior: np.ndarray, world: GridWorld) -> list[list[float | None]]:
    """Posterior as nested lists (probabilities, ``None`` on obstacles)."""
    return [
        [None if world.blocked[r, c] else float(posterior[r, c]) for c in range(posterior.shape[1])]
        for r in range(posterior.shape[0])
    ]


# --- TOML scenarios -------------------------------------------------------------------------


def _probability(default: float | Any = dataclasses.MISSING) -> Any:
    return bounded(default, ge=0.0, le=1.0)


@dataclass(frozen=True)
class _RandomWorldTable(Validated):
    """``[world.random]``: a random colour map."""

    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(
            ("colours", "counts"),
            lambda colours, counts: counts is None or len(counts) == len(colours),
            "one count per colour",
            blame=("counts",),
        ),
    )

    rows: int = bounded(ge=1, le=1_000_000)
    cols: int = bounded(ge=1, le=1_000_000)
    colours: tuple[str, ...] = bounded(min_length=1)
    seed: int = bounded(0, ge=0)
    counts: tuple[int, ...] | None = bounded(None, ge=0)


@dataclass(frozen=True)
class _WorldTable(Validated):
    """``[world]``."""

    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(
            ("map", "random"),
            lambda rows, random: (rows is None) != (random is None),
            "exactly one of map = [...] or a [world.random] table",
        ),
    )

    map: tuple[str, ...] | None = None
    random: _RandomWorldTable | None = None
    legend: dict[str, str] = bounded(factory=dict)
    cyclic: bool = False
    headings: int = bounded(1, choices=HEADING_COUNTS)


@dataclass(frozen=True)
class _RunTable(Validated):
    """``[run]``."""

    steps: tuple[str, ...] = ()
    threshold: float | None = bounded(None, gt=0.0, le=1.0)


@dataclass(frozen=True)
class _PriorTable(Validated):
    """``[prior]``."""

    values: Any = bounded()


@dataclass(frozen=True)
class _ScenarioTable(Validated):
    """A whole scenario file; sensor and motion tables are read by their ``type``."""

    world: _WorldTable = bounded()
    description: str = ""
    sensor: dict[str, Any] | None = None
    motion: dict[str, Any] | None = None
    prior: _PriorTable | None = None
    run: _RunTable | None = None


@dataclass(frozen=True)
class _ColourTable(Validated):
    type: str
    p_correct: float = _probability()


@dataclass(frozen=True)
class _WnesTable(Validated):
    type: str
    p_obstacle_given_obstacle: float = _probability(0.85)
    p_open_given_open: float = _probability(0.95)


@dataclass(frozen=True)
class _ConfusionTable(Validated):
    type: str
    matrix: Any = bounded()
    observations: tuple[str, ...] = ()


@dataclass(frozen=True)
class _ShiftTable(Validated):
    type: str
    p_exact: float = _probability(0.8)
    p_undershoot: float = _probability(0.1)
    p_overshoot: float = _probability(0.1)


@dataclass(frozen=True)
class _MoveOrStayTable(Validated):
    type: str
    p_move: float = _probability(1.0)


@dataclass(frozen=True)
class _DriftTable(Validated):
    type: str
    p_forward: float = _probability(0.8)
    p_left: float = _probability(0.1)
    p_right: float = _probability(0.1)


@dataclass(frozen=True)
class _UnknownHeadingTable(Validated):
    type: str


@dataclass(frozen=True)
class _HeadingTable(Validated):
    type: str
    p_move: float = _probability(0.9)
    p_turn: float = _probability(0.9)


_SENSOR_TABLES: dict[str, type] = {
    "colour": _ColourTable,
    "wnes": _WnesTable,
    "confusion": _ConfusionTable,
}
_MOTION_TABLES: dict[str, type] = {
    "shift": _ShiftTable,
    "move_or_stay": _MoveOrStayTable,
    "drift": _DriftTable,
    "unknown_heading": _UnknownHeadingTable,
    "heading": _HeadingTable,
}

SENSOR_TYPES: tuple[str, ...] = tuple(_SENSOR_TABLES)
"""Values of ``sensor.type``."""

MOTION_TYPES: tuple[str, ...] = tuple(_MOTION_TABLES)
"""Values of ``motion.type``."""

GRID_BYTES_PER_STATE = 40
"""Memory one state (cell × heading) of a grid world costs while the filter runs: the float64
belief, its spare buffer, a likelihood and two motion temporaries (8 bytes each)."""


def _typed(table: Mapping[str, Any], source: str, where: str, specs: dict[str, type]) -> Any:
    """The table read as the dataclass its ``type`` names."""
    if "type" not in table:
        raise ConfigError(f"{source}: {where}.type: required key is missing")
    kind = table["type"]
    if kind not in specs:
        raise ConfigError(
            f"{source}: {where}.type: expected one of {', '.join(specs)}, found {kind!r}"
        )
    return from_table(specs[kind], table, source, where)


def _matrix(value: Any, source: str, key: str) -> np.ndarray:
    """A list of numbers or a list of equal-length rows, as a 2-D float array."""
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{source}: {key}: expected a non-empty list of numbers, found {value!r}")
    rows = value if isinstance(value[0], list) else [value]
    ok = all(isinstance(row, list) and len(row) == len(rows[0]) for row in rows) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)
        for row in rows
        for v in row
    )
    if not ok:
        raise ConfigError(
            f"{source}: {key}: expected a list of finite numbers or a list of equal-length rows"
        )
    return np.array(rows, dtype=float)


def check_world_memory(rows: int, cols: int, headings: int, source: str) -> None:
    """Refuse (before allocating) a world whose filter would not fit in memory (:mod:`slam.budget`)."""
    states = rows * cols * headings
    check_memory(
        states * GRID_BYTES_PER_STATE,
        f"{source}: a {rows}×{cols} world with {headings} heading(s) ({states} states)",
        "use a smaller world",
    )


@contextmanager
def _naming(source: str) -> Iterator[None]:
    """A :class:`~slam.errors.ConfigError` raised inside names ``source`` (the scenario file)
    first, unless it already does."""
    try:
        yield
    except ConfigError as exc:
        if str(exc).startswith(source):
            raise
        raise ConfigError(f"{source}: {exc}") from None


def _parse_world(t: _WorldTable, source: str) -> GridWorld:
    with _naming(source):
        if t.map is not None:
            check_world_memory(
                len(t.map), max((len(r) for r in t.map), default=0), t.headings, source
            )
            return world_from_rows(list(t.map), dict(t.legend), t.cyclic, t.headings)
        r = t.random
        assert r is not None  # guaranteed by the _WorldTable rule
        check_world_memory(r.rows, r.cols, t.headings, source)
        rng = np.random.default_rng(r.seed)
        counts = None if r.counts is None else list(r.counts)
        return random_colour_world(
            r.rows, r.cols, list(r.colours), rng, counts, t.cyclic, t.headings
        )


def _parse_sensor(table: Mapping[str, Any], source: str) -> SensorModel:
    t = _typed(table, source, "sensor", _SENSOR_TABLES)
    with _naming(source):
        if isinstance(t, _ColourTable):
            return ColourSensor(t.p_correct)
        if isinstance(t, _WnesTable):
            return WnesSensor(t.p_obstacle_given_obstacle, t.p_open_given_open)
        return ConfusionSensor(_matrix(t.matrix, source, "sensor.matrix"), t.observations)


def _parse_motion(table: Mapping[str, Any], source: str) -> MotionModel:
    t = _typed(table, source, "motion", _MOTION_TABLES)
    with _naming(source):
        if isinstance(t, _ShiftTable):
            return ShiftMotion(t.p_exact, t.p_undershoot, t.p_overshoot)
        if isinstance(t, _MoveOrStayTable):
            return MoveOrStay(t.p_move)
        if isinstance(t, _DriftTable):
            return DriftMotion(t.p_forward, t.p_left, t.p_right)
        if isinstance(t, _UnknownHeadingTable):
            return UnknownHeading()
        return HeadingMotion(t.p_move, t.p_turn)


def parse_steps(
    texts: list[str],
    world: GridWorld,
    sensor: SensorModel | None,
    motion: MotionModel | None,
    source: str,
    key: str = "run.steps",
) -> tuple[Step, ...]:
    """Parse ``"sense Z"`` / ``"move U"`` lines against the models; errors name the entry."""
    steps = []
    for i, text in enumerate(texts):
        where = f"{source}: {key}[{i}]"
        kind, _, arg = text.strip().partition(" ")
        kind = kind.lower()
        if kind not in STEP_KINDS:
            raise ConfigError(
                f"{where}: expected 'sense <observation>' or 'move <action>', found {text!r}"
            )
        model = sensor if kind == "sense" else motion
        if model is None:
            table = "sensor" if kind == "sense" else "motion"
            raise ConfigError(f"{where}: {text!r} needs a [{table}] table")
        try:
            if kind == "sense":
                value = sensor.parse_observation(world, arg)  # type: ignore[union-attr]
            else:
                value = motion.parse_action(world, arg)  # type: ignore[union-attr]
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        steps.append(Step(kind, arg.strip(), value))
    return tuple(steps)


def _parse_prior(t: _PriorTable, world: GridWorld, source: str) -> np.ndarray:
    values = _matrix(t.values, source, "prior.values")
    if values.shape != world.shape:
        raise ConfigError(
            f"{source}: prior.values: expected {world.shape[0]}×{world.shape[1]} values, "
            f"found {values.shape[0]}×{values.shape[1]}"
        )
    if (values < 0).any() or not values.sum() > 0:
        raise ConfigError(
            f"{source}: prior.values: expected non-negative probabilities with a positive sum"
        )
    if (values[world.blocked] > 0).any():
        raise ConfigError(f"{source}: prior.values: obstacle cells must have prior probability 0")
    return values / values.sum()


def scenario_from_toml(data: Mapping[str, Any], source: str, name: str) -> Scenario:
    """Build a scenario from parsed TOML ``data`` (``source`` names the file in errors)."""
    top = from_table(_ScenarioTable, data, source, "")
    world = _parse_world(top.world, source)
    sensor = _parse_sensor(top.sensor, source) if top.sensor is not None else None
    motion = _parse_motion(top.motion, source) if top.motion is not None else None
    for model, table in ((sensor, "sensor"), (motion, "motion")):
        if model is not None:
            try:
                model.check(world)  # type: ignore[attr-defined]
            except ConfigError as exc:
                raise ConfigError(f"{source}: [{table}] {exc}") from None
    prior = _parse_prior(top.prior, world, source) if top.prior is not None else None
    run = top.run or _RunTable()
    steps = parse_steps(list(run.steps), world, sensor, motion, source)
    return Scenario(
        name, world, sensor, motion, steps, prior, run.threshold, top.description, None, source
    )


def load_scenario(path: Path) -> Scenario:
    """Read and validate a scenario TOML file."""
    path = Path(path)
    return scenario_from_toml(read_toml(path, "scenario file"), str(path), path.stem)


def shipped_dir() -> Path:
    """Folder of the shipped scenarios (``configs/grid``)."""
    return config_dir() / "grid"


def shipped_scenarios() -> dict[str, Path]:
    """Shipped scenario names and files."""
    folder = shipped_dir()
    if not folder.is_dir():
        return {}
    return {p.stem: p for p in sorted(folder.glob("*.toml"))}


# --- Udacity test vectors -------------------------------------------------------------------


def _case_error(path: Path, where: str, message: str) -> DataError:
    return DataError(f"{path}: {where}: {message}")


def _check_case(path: Path, where: str, case: Any) -> None:
    """The shape of one entry of ``cases_2d`` (keys, colour rows, lists, numbers): a
    :class:`DataError` naming ``path`` and ``where`` otherwise."""
    if not isinstance(case, dict):
        raise _case_error(path, where, f"expected an object, found {case!r}")
    missing = {"name", "colors", "measurements", "motions", "sensor_right", "p_move"} - set(case)
    if missing:
        raise _case_error(path, where, f"missing keys {', '.join(sorted(missing))}")
    colours = case["colors"]
    if (
        not isinstance(colours, list)
        or not colours
        or not all(
            isinstance(row, list) and row and all(isinstance(c, str) and len(c) == 1 for c in row)
            for row in colours
        )
    ):
        raise _case_error(path, f"{where}.colors", "expected rows of one-letter colours")
    measurements, motions = case["measurements"], case["motions"]
    if not isinstance(measurements, list) or not isinstance(motions, list):
        raise _case_error(path, where, "measurements and motions must be lists")
    if len(measurements) != len(motions):
        raise _case_error(
            path, where, f"{len(motions)} motions for {len(measurements)} measurements"
        )
    for key in ("sensor_right", "p_move"):
        if isinstance(case[key], bool) or not isinstance(case[key], int | float):
            raise _case_error(path, f"{where}.{key}", f"expected a number, found {case[key]!r}")


def load_udacity_cases(path: Path) -> list[Scenario]:
    """The 2D cases of ``udacity_cases.json`` as scenarios with their expected posteriors.

    Cyclic world of the case's colours, uniform prior, per motion/measurement pair a MOVE (exact
    with ``p_move``, else stay) then a SENSE (correct with ``sensor_right``; the cases have two
    colours, so "the rest spread over the other colours" is the course's ``1 − sensor_right``).
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(
            f"{path}: Udacity test vectors not found (see the data directory)"
        ) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: cannot read JSON ({exc})") from None
    cases = data.get("cases_2d") if isinstance(data, dict) else None
    if not isinstance(cases, list):
        raise _case_error(path, "cases_2d", "expected a list of cases")
    scenarios = []
    for i, case in enumerate(cases):
        where = f"cases_2d[{i}]"
        _check_case(path, where, case)
        colours, measurements, motions = case["colors"], case["measurements"], case["motions"]
        source = f"{path}#{case['name']}"
        try:
            world = world_from_rows(["".join(row) for row in colours], cyclic=True)
            sensor = ColourSensor(float(case["sensor_right"]))
            motion = MoveOrStay(float(case["p_move"]))
            texts: list[str] = []
            for k, (move, seen) in enumerate(zip(motions, measurements, strict=True)):
                if not (isinstance(move, list) and len(move) == 2):
                    raise ConfigError(f"motions[{k}]: expected [drow, dcol], found {move!r}")
                texts += [f"move {move[0]},{move[1]}", f"sense {seen}"]
            steps = parse_steps(texts, world, sensor, motion, f"case {case['name']}", "steps")
            sensor.check(world)
        except ConfigError as exc:
            raise _case_error(path, where, str(exc)) from None
        expected = np.asarray(case.get("expected"), dtype=float) if "expected" in case else None
        if expected is not None and expected.shape != world.shape:
            raise _case_error(path, f"{where}.expected", f"expected shape {world.shape}")
        scenarios.append(
            Scenario(
                f"{UDACITY_PREFIX}{case['name']}",
                world,
                sensor,
                motion,
                steps,
                None,
                None,
                "Udacity CS373 lesson 1 histogram-filter test vector",
                expected,
                source,
            )
        )
    return scenarios


def resolve_scenario(name: str, data_dir: Path | None = None) -> Scenario:
    """A scenario by shipped name, ``udacity:<case>`` (from the data directory) or TOML path."""
    if name.startswith(UDACITY_PREFIX):
        if data_dir is None:
            raise UsageError(f"{name}: Udacity cases need the data directory (--data-dir)")
        cases = {s.name: s for s in load_udacity_cases(Path(data_dir) / UDACITY_FILE)}
        if name not in cases:
            raise UsageError(f"{name}: no such case; expected one of {', '.join(cases)}")
        return cases[name]
    shipped = shipped_scenarios()
    if name in shipped:
        return load_scenario(shipped[name])
    path = Path(name)
    if path.suffix == ".toml" or path.exists():
        return load_scenario(path)
    raise UsageError(
        f"unknown scenario {name!r}; expected a TOML file, udacity:<case> or one of "
        f"{', '.join(shipped) or '(none shipped)'}"
    )
