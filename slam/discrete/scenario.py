"""Grid-localization scenarios: TOML files and the Udacity test vectors, run step by step.

A scenario is a world, a sensor model, a motion model, a prior and a sequence of steps
(``sense Z`` / ``move U``). This module owns

* reading scenario TOML files (``configs/grid/*.toml``) — data only, parsed with ``tomllib``, every
  key validated: an unknown key or a wrong type is a :class:`~slam.errors.ConfigError` naming the
  file and the key;
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

import json
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

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
from slam.discrete.world import GridWorld, random_colour_world, world_from_rows
from slam.errors import ConfigError, DataError, UsageError
from slam.resources import config_dir

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


class _Table:
    """A TOML table being validated: typed getters, unknown keys rejected, errors name the key."""

    def __init__(self, source: str, where: str, data: Any) -> None:
        if not isinstance(data, Mapping):
            raise ConfigError(f"{source}: [{where}] must be a table, found {data!r}")
        self.source, self.where, self.data = source, where, dict(data)

    def fail(self, key: str, message: str) -> ConfigError:
        return ConfigError(f"{self.source}: {self.where}.{key}: {message}")

    def allow(self, *keys: str) -> None:
        for key in self.data:
            if key not in keys:
                raise ConfigError(
                    f"{self.source}: unknown key {self.where}.{key}; expected one of "
                    f"{', '.join(sorted(keys))}"
                )

    def has(self, key: str) -> bool:
        return key in self.data

    def number(self, key: str, default: float | None = None) -> float:
        value = self.data.get(key, default)
        if value is None:
            raise self.fail(key, "missing; expected a number")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"expected a number, found {value!r}")
        return float(value)

    def integer(self, key: str, default: int | None = None) -> int:
        value = self.data.get(key, default)
        if value is None:
            raise self.fail(key, "missing; expected an integer")
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"expected an integer, found {value!r}")
        return value

    def boolean(self, key: str, default: bool) -> bool:
        value = self.data.get(key, default)
        if not isinstance(value, bool):
            raise self.fail(key, f"expected true or false, found {value!r}")
        return value

    def string(self, key: str, default: str | None = None) -> str:
        value = self.data.get(key, default)
        if value is None:
            raise self.fail(key, "missing; expected a string")
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, found {value!r}")
        return value

    def strings(self, key: str) -> list[str]:
        value = self.data.get(key)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise self.fail(key, f"expected a list of strings, found {value!r}")
        return value

    def integers(self, key: str) -> list[int]:
        value = self.data.get(key)
        if not isinstance(value, list) or not all(
            isinstance(v, int) and not isinstance(v, bool) for v in value
        ):
            raise self.fail(key, f"expected a list of integers, found {value!r}")
        return value

    def matrix(self, key: str) -> np.ndarray:
        value = self.data.get(key)
        if not isinstance(value, list) or not value:
            raise self.fail(key, f"expected a non-empty list of numbers, found {value!r}")
        rows = value if isinstance(value[0], list) else [value]
        ok = all(isinstance(row, list) and len(row) == len(rows[0]) for row in rows) and all(
            isinstance(v, int | float) and not isinstance(v, bool) for row in rows for v in row
        )
        if not ok:
            raise self.fail(key, "expected a list of numbers or a list of equal-length rows")
        return np.array(rows, dtype=float)

    def table(self, key: str) -> _Table:
        return _Table(self.source, f"{self.where}.{key}", self.data.get(key))

    def choice(self, key: str, choices: tuple[str, ...]) -> str:
        value = self.string(key)
        if value not in choices:
            raise self.fail(key, f"expected one of {', '.join(choices)}, found {value!r}")
        return value


def _parse_world(t: _Table) -> GridWorld:
    t.allow("map", "random", "legend", "cyclic", "headings")
    cyclic = t.boolean("cyclic", False)
    headings = t.integer("headings", 1)
    if headings not in (1, 4):
        raise t.fail("headings", f"expected 1 or 4, found {headings}")
    if t.has("map") == t.has("random"):
        raise ConfigError(f"{t.source}: [world] needs exactly one of map = [...] or [world.random]")
    try:
        if t.has("map"):
            legend: dict[str, str] = {}
            if t.has("legend"):
                lt = t.table("legend")
                legend = {key: lt.string(key) for key in lt.data}
            return world_from_rows(t.strings("map"), legend, cyclic, headings)
        r = t.table("random")
        r.allow("rows", "cols", "colours", "seed", "counts")
        counts = r.integers("counts") if r.has("counts") else None
        rng = np.random.default_rng(r.integer("seed", 0))
        return random_colour_world(
            r.integer("rows"),
            r.integer("cols"),
            r.strings("colours"),
            rng,
            counts,
            cyclic,
            headings,
        )
    except ConfigError as exc:
        if str(exc).startswith(t.source):
            raise
        raise ConfigError(f"{t.source}: {exc}") from None


SENSOR_TYPES: tuple[str, ...] = ("colour", "wnes", "confusion")
"""Values of ``sensor.type``."""

MOTION_TYPES: tuple[str, ...] = ("shift", "move_or_stay", "drift", "unknown_heading", "heading")
"""Values of ``motion.type``."""


def _parse_sensor(t: _Table) -> SensorModel:
    kind = t.choice("type", SENSOR_TYPES)
    try:
        if kind == "colour":
            t.allow("type", "p_correct")
            return ColourSensor(t.number("p_correct"))
        if kind == "wnes":
            t.allow("type", "p_obstacle_given_obstacle", "p_open_given_open")
            return WnesSensor(
                t.number("p_obstacle_given_obstacle", 0.85), t.number("p_open_given_open", 0.95)
            )
        t.allow("type", "matrix", "observations")
        names = tuple(t.strings("observations")) if t.has("observations") else ()
        return ConfusionSensor(t.matrix("matrix"), names)
    except ConfigError as exc:
        if str(exc).startswith(t.source):
            raise
        raise ConfigError(f"{t.source}: {exc}") from None


def _parse_motion(t: _Table) -> MotionModel:
    kind = t.choice("type", MOTION_TYPES)
    try:
        if kind == "shift":
            t.allow("type", "p_exact", "p_undershoot", "p_overshoot")
            return ShiftMotion(
                t.number("p_exact", 0.8),
                t.number("p_undershoot", 0.1),
                t.number("p_overshoot", 0.1),
            )
        if kind == "move_or_stay":
            t.allow("type", "p_move")
            return MoveOrStay(t.number("p_move", 1.0))
        if kind == "drift":
            t.allow("type", "p_forward", "p_left", "p_right")
            return DriftMotion(
                t.number("p_forward", 0.8), t.number("p_left", 0.1), t.number("p_right", 0.1)
            )
        if kind == "unknown_heading":
            t.allow("type")
            return UnknownHeading()
        t.allow("type", "p_move", "p_turn")
        return HeadingMotion(t.number("p_move", 0.9), t.number("p_turn", 0.9))
    except ConfigError as exc:
        if str(exc).startswith(t.source):
            raise
        raise ConfigError(f"{t.source}: {exc}") from None


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


def _parse_prior(t: _Table, world: GridWorld) -> np.ndarray:
    t.allow("values")
    values = t.matrix("values")
    if values.shape != world.shape:
        raise t.fail(
            "values",
            f"expected {world.shape[0]}×{world.shape[1]} values, found {values.shape[0]}×{values.shape[1]}",
        )
    if (values < 0).any() or not values.sum() > 0:
        raise t.fail("values", "expected non-negative probabilities with a positive sum")
    if (values[world.blocked] > 0).any():
        raise t.fail("values", "obstacle cells must have prior probability 0")
    return values / values.sum()


def scenario_from_toml(data: Mapping[str, Any], source: str, name: str) -> Scenario:
    """Build a scenario from parsed TOML ``data`` (``source`` names the file in errors)."""
    top = _Table(source, "scenario", data)
    top.allow("description", "world", "sensor", "motion", "prior", "run")
    if not top.has("world"):
        raise ConfigError(f"{source}: missing [world] table")
    description = top.string("description", "")
    world = _parse_world(_Table(source, "world", data["world"]))
    sensor = _parse_sensor(_Table(source, "sensor", data["sensor"])) if top.has("sensor") else None
    motion = _parse_motion(_Table(source, "motion", data["motion"])) if top.has("motion") else None
    for model, table in ((sensor, "sensor"), (motion, "motion")):
        if model is not None:
            try:
                model.check(world)  # type: ignore[attr-defined]
            except ConfigError as exc:
                raise ConfigError(f"{source}: [{table}] {exc}") from None
    prior = (
        _parse_prior(_Table(source, "prior", data["prior"]), world) if top.has("prior") else None
    )
    steps: tuple[Step, ...] = ()
    threshold = None
    if top.has("run"):
        run = _Table(source, "run", data["run"])
        run.allow("steps", "threshold")
        if run.has("steps"):
            steps = parse_steps(run.strings("steps"), world, sensor, motion, source)
        if run.has("threshold"):
            threshold = run.number("threshold")
            if not 0.0 < threshold <= 1.0:
                raise run.fail("threshold", f"expected a probability in (0, 1], found {threshold}")
    return Scenario(name, world, sensor, motion, steps, prior, threshold, description, None, source)


def load_scenario(path: Path) -> Scenario:
    """Read and validate a scenario TOML file."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: scenario file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read scenario ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None
    return scenario_from_toml(data, str(path), path.stem)


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
        if not isinstance(case, dict):
            raise _case_error(path, where, f"expected an object, found {case!r}")
        missing = {"name", "colors", "measurements", "motions", "sensor_right", "p_move"} - set(
            case
        )
        if missing:
            raise _case_error(path, where, f"missing keys {', '.join(sorted(missing))}")
        colours = case["colors"]
        if (
            not isinstance(colours, list)
            or not colours
            or not all(
                isinstance(row, list)
                and row
                and all(isinstance(c, str) and len(c) == 1 for c in row)
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
