"""``slam tune``: a random or grid search over declared ranges, run as a sweep.

The spec's ``[tune]`` table declares the search (``trials``, ``search = "random" | "grid"``,
``seed``) and ``[tune.ranges]`` the keys and their ranges: ``{min, max}`` (floats; ``log = true``
for a log-uniform draw, ``int = true`` for integers; ``steps`` points per key in a grid) or
``{values = [...]}``. Trial 0 is always the default configuration (the spec's ``[run]`` options
alone), so the report says what tuning bought. Every trial is a setting of one sweep over the
spec's logs and seeds (resumable like any sweep, on either executor); its objective is the mean
cell error (the relation metric's mean translation error where the log has relations, the ATE
RMSE for simulated logs, ``1 - map score`` otherwise). The best trial becomes a ready
``config.toml`` (its keys only: ``slam run LOG --config config.toml``), and the error-vs-wall
trade-off goes to ``tune.json`` (with the Pareto front), the printed table and ``tune.png``.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from slam.errors import UsageError
from slam.sweep.driver import pyplot, save_figure
from slam.sweep.spec import Setting, SweepSpec

SEARCHES = ("random", "grid")
TUNE_FILE = "tune.json"
CONFIG_FILE = "config.toml"
PLOT = "tune.png"
DEFAULT_TRIALS = 8
DEFAULT_STEPS = 3
MAX_STEPS = 10_000
"""Most grid points one range may have (``steps``)."""
MAX_TRIALS = 10_000
"""Most trials (cells per log and seed) one tune may have."""


@dataclass(frozen=True)
class Range:
    """A key's range: ``values``, or ``low``..``high`` (``log``, ``integer``)."""

    key: str
    values: tuple[Any, ...] = ()
    low: float = 0.0
    high: float = 0.0
    log: bool = False
    integer: bool = False
    steps: int = DEFAULT_STEPS

    def draw(self, rng: Any) -> Any:
        """One random value."""
        if self.values:
            return self.values[int(rng.integers(len(self.values)))]
        if self.integer:
            if self.log:
                return int(round(math.exp(rng.uniform(math.log(self.low), math.log(self.high)))))
            return int(rng.integers(int(self.low), int(self.high) + 1))
        if self.log:
            value = math.exp(rng.uniform(math.log(self.low), math.log(self.high)))
        else:
            value = rng.uniform(self.low, self.high)
        return float(f"{value:.4g}")

    def grid(self) -> list[Any]:
        """The grid points."""
        if self.values:
            return list(self.values)
        n = max(1, self.steps)
        if n == 1:
            points = [self.low]
        elif self.log:
            points = [self.low * (self.high / self.low) ** (i / (n - 1)) for i in range(n)]
        else:
            points = [self.low + (self.high - self.low) * i / (n - 1) for i in range(n)]
        if self.integer:
            return list(dict.fromkeys(int(round(p)) for p in points))
        return [float(f"{p:.4g}") for p in points]


@dataclass(frozen=True)
class TuneSpec:
    """The search of ``[tune]``."""

    ranges: tuple[Range, ...]
    trials: int = DEFAULT_TRIALS
    search: str = "random"
    seed: int = 0


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise UsageError(f"{where}: expected a number, found {value!r}")
    return float(value)


def parse_tune(data: dict[str, Any], where: str, args: Any = None) -> TuneSpec:
    """The ``[tune]`` table (and ``--trials`` / ``--search``), checked."""
    table = data.get("tune")
    if not isinstance(table, dict):
        raise UsageError(f"{where}: no [tune] table (slam tune needs [tune.ranges])")
    unknown = set(table) - {"trials", "search", "seed", "ranges"}
    if unknown:
        raise UsageError(f"{where}: [tune] unknown key {sorted(unknown)[0]!r}")
    ranges_table = table.get("ranges")
    if not isinstance(ranges_table, dict) or not ranges_table:
        raise UsageError(
            f'{where}: [tune.ranges] must declare at least one "section.key" = {{...}}'
        )
    ranges = []
    for key, item in ranges_table.items():
        here = f"{where}: [tune.ranges] {key}"
        if key.count(".") != 1:
            raise UsageError(f"{here}: expected a key section.key (e.g. rbpf.temperature)")
        if not isinstance(item, dict):
            raise UsageError(f"{here}: expected {{min = .., max = ..}} or {{values = [..]}}")
        extra = set(item) - {"min", "max", "log", "int", "steps", "values"}
        if extra:
            raise UsageError(f"{here}: unknown key {sorted(extra)[0]!r}")
        if "values" in item:
            values = item["values"]
            if not isinstance(values, list) or not values:
                raise UsageError(f"{here}: values: expected a non-empty list")
            ranges.append(Range(key, tuple(values)))
            continue
        if "min" not in item or "max" not in item:
            raise UsageError(f"{here}: expected min and max (or values)")
        low, high = _number(item["min"], f"{here}: min"), _number(item["max"], f"{here}: max")
        log, integer = bool(item.get("log", False)), bool(item.get("int", False))
        if not low < high or (log and low <= 0):
            raise UsageError(
                f"{here}: expected min < max (and min > 0 with log), found {low}, {high}"
            )
        steps = item.get("steps", DEFAULT_STEPS)
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= MAX_STEPS:
            raise UsageError(
                f"{here}: steps: expected an integer in [1, {MAX_STEPS}], found {steps!r}"
            )
        ranges.append(Range(key, (), low, high, log, integer, steps))
    for declared in ranges:
        _check_ends(declared, f"{where}: [tune.ranges] {declared.key}")
    trials = table.get("trials", DEFAULT_TRIALS)
    search = table.get("search", "random")
    seed = table.get("seed", 0)
    if args is not None and getattr(args, "trials", None) is not None:
        trials = args.trials
    if args is not None and getattr(args, "search", None) is not None:
        search = args.search
    if isinstance(trials, bool) or not isinstance(trials, int) or not 2 <= trials <= MAX_TRIALS:
        raise UsageError(
            f"{where}: [tune] trials: expected an integer in [2, {MAX_TRIALS}] (the default and "
            f"at least one more), found {trials!r}"
        )
    if search not in SEARCHES:
        raise UsageError(
            f"{where}: [tune] search: expected one of {', '.join(SEARCHES)}, found {search!r}"
        )
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise UsageError(f"{where}: [tune] seed: expected an integer, found {seed!r}")
    return TuneSpec(tuple(ranges), trials, search, seed)


def _check_ends(declared: Range, here: str) -> None:
    """Refuse a range whose key is no configuration key, or whose ``min``, ``max`` or one of
    whose ``values`` lies outside the key's bounds: named by the end, before any trial is drawn
    (a drawn value would name a number the user never wrote)."""
    from slam.config import section_types
    from slam.errors import ConfigError
    from slam.validate import Bounds, check_value, coerce, field_types

    section, name = declared.key.split(".")
    sections = section_types()
    if section not in sections:
        raise UsageError(
            f"{here}: unknown section [{section}]; expected one of {', '.join(sorted(sections))}"
        )
    types_ = field_types(sections[section])
    if name not in types_:
        raise UsageError(f"{here}: unknown key; expected one of {', '.join(sorted(types_))}")
    bounds = next(
        f.metadata.get("bounds", Bounds()) for f in fields(sections[section]) if f.name == name
    )
    if declared.values:
        ends = [(f"values[{i}]", v) for i, v in enumerate(declared.values)]
    else:
        ends = [("min", declared.low), ("max", declared.high)]
        if declared.integer:  # drawn as whole numbers between them: the ends must be whole
            for which, value in ends:
                if value != int(value):
                    raise UsageError(
                        f"{here}: {which}: expected a whole number with int = true, found {value}"
                    )
            ends = [(which, int(v)) for which, v in ends]
        elif types_[name] is int:
            raise UsageError(f"{here}: an integer key: add int = true (draws whole numbers)")
    for which, value in ends:
        try:
            typed = coerce(value, types_[name], here, which)
        except ConfigError as exc:
            raise UsageError(str(exc)) from None
        problem = check_value(typed, types_[name], bounds)
        if problem is not None:
            raise UsageError(f"{here}: {which}: expected {problem}, found {value!r}")


def trial_settings(
    tune: TuneSpec, where: str = "[tune]", ranges: str = "[tune.ranges]"
) -> tuple[Setting, ...]:
    """Trial 0 (the default), then ``trials - 1`` random draws or the grid's points; a bad value
    of a key names ``<ranges> <key>`` (``FILE: [tune.ranges] rbpf.temperature``)."""
    import numpy as np

    from slam.sweep.spec import _override

    settings = [Setting("trial000-default")]
    if tune.search == "grid":
        grids = [r.grid() for r in tune.ranges]
        size = math.prod(len(g) for g in grids)  # before the points: a typo may make billions
        if size > tune.trials - 1:
            fix = f"raise trials to {size + 1} or " if size + 1 <= MAX_TRIALS else ""
            raise UsageError(
                f"{where}: the grid has {size} points but trials = {tune.trials} (one is the "
                f"default): {fix}lower the steps"
            )
        points = list(itertools.product(*grids))
    else:
        rng = np.random.default_rng(tune.seed)
        points, seen = [], set()
        for _ in range(100 * tune.trials):
            if len(points) == tune.trials - 1:
                break
            point = tuple(r.draw(rng) for r in tune.ranges)
            if point not in seen:
                seen.add(point)
                points.append(point)
    for k, point in enumerate(points, start=1):
        pairs = tuple(zip((r.key for r in tune.ranges), point, strict=True))
        overrides = tuple(_override(key, value, where, f"{ranges} {key}") for key, value in pairs)
        settings.append(Setting(f"trial{k:03d}", overrides, pairs))
    return tuple(settings)


def rank_trials(rows: list[dict[str, Any]], settings: tuple[Setting, ...]) -> list[dict[str, Any]]:
    """Per trial: mean error and wall over its cells (only trials whose cells all succeeded are
    ranked), and whether it is on the Pareto front of error vs wall."""
    trials = []
    for setting in settings:
        mine = [r for r in rows if r["setting"] == setting.name]
        ok = [r for r in mine if r["status"] == "ok" and r.get("error") is not None]
        entry: dict[str, Any] = {
            "trial": setting.name,
            "values": dict(setting.values),
            "cells": len(mine),
        }
        if mine and len(ok) == len(mine):
            errors = [float(r["error"]) for r in ok]
            walls = [float(r.get("wall_s") or 0.0) for r in ok]
            entry["error_mean"] = sum(errors) / len(errors)
            entry["error_std"] = math.sqrt(
                sum((e - entry["error_mean"]) ** 2 for e in errors) / len(errors)
            )
            entry["wall_mean_s"] = sum(walls) / len(walls)
        else:
            entry["failed"] = len(mine) - len(ok)
        trials.append(entry)
    ranked = [t for t in trials if "error_mean" in t]
    for t in ranked:
        t["pareto"] = not any(
            o is not t
            and o["error_mean"] <= t["error_mean"]
            and o["wall_mean_s"] <= t["wall_mean_s"]
            and (o["error_mean"] < t["error_mean"] or o["wall_mean_s"] < t["wall_mean_s"])
            for o in ranked
        )
    return trials


def best_trial(trials: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The trial of least mean error (ties: less wall time, then the earlier trial)."""
    ranked = [t for t in trials if "error_mean" in t]
    if not ranked:
        return None
    return min(ranked, key=lambda t: (t["error_mean"], t["wall_mean_s"]))


def config_text(
    spec: SweepSpec, best: dict[str, Any], default: dict[str, Any] | None, source: str
) -> str:
    """The best trial as a ready configuration file: the ``[run]`` options that shape results
    (method, particles, ``set``) and the tuned keys, by section."""
    from slam.config import _toml_value, parse_override

    values: dict[str, dict[str, Any]] = {}
    run = spec.run
    for key, flag in (("filter.method", run.method), ("filter.particles", run.particles)):
        if flag is not None:
            section, name = key.split(".")
            values.setdefault(section, {})[name] = flag
    for text in run.set:
        section, name, value = parse_override(text)
        values.setdefault(section, {})[name] = value
    for key, value in best["values"].items():
        section, name = key.split(".", 1)
        values.setdefault(section, {})[name] = value
    lines = [
        f"# Best trial of `slam tune {source}`: {best['trial']}, mean error "
        f"{best['error_mean']:.6g} over {best['cells']} cells"
        + (
            f" (default: {default['error_mean']:.6g})"
            if default and "error_mean" in default
            else ""
        ),
        "# Use it with: slam run LOG --config config.toml"
        + (f" (on top of {run.config}: pass that one's keys too)" if run.config else ""),
    ]
    for section, table in values.items():
        lines += ["", f"[{section}]"]
        lines += [f"{name} = {_toml_value(value)}" for name, value in table.items()]
    return "\n".join(lines) + "\n"


def format_trials(trials: list[dict[str, Any]], best: dict[str, Any] | None) -> str:
    """The printed trade-off table, best first."""
    lines = [f"{'trial':<18} {'error mean ± std':>22} {'wall (s)':>9}  front  values"]
    order = sorted(trials, key=lambda t: (t.get("error_mean", math.inf), t.get("wall_mean_s", 0)))
    for t in order:
        values = ", ".join(f"{k}={v}" for k, v in t["values"].items()) or "(default)"
        if "error_mean" not in t:
            lines.append(f"{t['trial']:<18} {'failed':>22} {'':>9}  {'':5}  {values}")
            continue
        err = f"{t['error_mean']:.4f} ± {t['error_std']:.4f}"
        mark = "best" if t is best else ("*" if t["pareto"] else "")
        lines.append(f"{t['trial']:<18} {err:>22} {t['wall_mean_s']:>9.1f}  {mark:5}  {values}")
    return "\n".join(lines) + "\n"


def write_tune_plot(folder: Path, trials: list[dict[str, Any]]) -> str | None:
    """``tune.png``: mean error vs mean wall time per trial, the Pareto front joined."""
    plt = pyplot()
    if plt is None:
        return f"matplotlib is not installed (uv sync --extra plot): {PLOT} skipped"

    ranked = [t for t in trials if "error_mean" in t]
    if not ranked:
        return f"no finished trial: {PLOT} not drawn"
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.scatter([t["wall_mean_s"] for t in ranked], [t["error_mean"] for t in ranked], c="tab:blue")
    for t in ranked:
        ax.annotate(
            t["trial"].replace("trial", ""), (t["wall_mean_s"], t["error_mean"]), fontsize=7
        )
    front = sorted((t for t in ranked if t["pareto"]), key=lambda t: t["wall_mean_s"])
    ax.plot(
        [t["wall_mean_s"] for t in front],
        [t["error_mean"] for t in front],
        "r--",
        label="Pareto front",
    )
    ax.set_xlabel("mean wall time per cell (s)")
    ax.set_ylabel("mean error")
    ax.set_title("slam tune: error vs wall time")
    ax.legend()
    save_figure(plt, fig, folder / PLOT)
    return None


def tune_spec_for(spec: SweepSpec, tune: TuneSpec) -> SweepSpec:
    """The sweep whose settings are the trials."""
    file = f"{spec.source}: " if spec.source else ""
    return replace(spec, settings=trial_settings(tune, f"{file}[tune]", f"{file}[tune.ranges]"))


def report(spec: SweepSpec, outcome: Any) -> dict[str, Any]:
    """Rank the trials, write ``tune.json`` and ``config.toml``; return the report."""
    from slam.io.atomic import write_text

    trials = rank_trials(outcome.rows, spec.settings)
    best = best_trial(trials)
    default = trials[0]
    result = {"trials": trials, "best": best, "default": default}
    source = str(spec.source) if spec.source else "SPEC"
    if best is not None:
        write_text(outcome.folder / CONFIG_FILE, config_text(spec, best, default, source))
        result["config"] = str(outcome.folder / CONFIG_FILE)
    write_text(outcome.folder / TUNE_FILE, json.dumps(result, indent=2) + "\n")
    return result
