"""The sweep specification: logs × seeds × settings, the ``slam run`` options of every cell.

A specification comes from a TOML file (``slam sweep SPEC.toml``, layout in ``docs/sweep.md``)
and/or the command line (``--logs``, ``--seeds``, ``--set KEY=V1,V2``, the ``slam run`` options);
the command line wins. :func:`build_spec` checks every value and names the file and key of a bad
one (:class:`~slam.errors.UsageError`, exit 2); what needs the data directory (the logs, each
log's evaluation, each cell's configuration) :func:`slam.sweep.driver.check_sweep` checks before
any cell runs, and a configuration key or value of the file is named as the file gives it (``FILE:
[grid] rbpf.temperature``, not the ``--set`` a cell passes on). :meth:`SweepSpec.cells` expands
it into :class:`Cell` s, each one ordinary ``slam run`` argument list.

:meth:`SweepSpec.identity` is what makes two sweeps the same sweep (what a cell computes; not
where or how fast): a sweep folder remembers it, and a sweep of another identity is refused there.
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from slam.errors import ConfigError, UsageError

EXECUTORS = ("local", "ray")
"""Where cells run: a local process pool, or a Ray cluster."""

METRICS = ("auto", "relations", "ate", "quality")
"""How a cell is evaluated: ``auto`` picks relations when the log has a relations file, ATE when
it has a ground-truth trajectory, else the no-reference map quality score."""

RUN_OPTIONS: dict[str, type] = {
    "method": str,
    "particles": int,
    "every": int,
    "max_scans": int,
    "config": str,
    "no_texture": bool,
    "no_record": bool,
    "set": list,
}
"""The ``[run]`` keys of a spec: the options of ``slam run`` applied to every cell."""

SWEEP_KEYS = ("logs", "seeds", "out", "workers", "executor", "address", "evaluation")
"""The ``[sweep]`` keys of a spec."""

MAX_CELL_NAME = 120
"""Longest cell folder name; longer setting labels are shortened with a hash."""


@dataclass(frozen=True)
class Setting:
    """One setting of the sweep: a name and the ``--set`` overrides it adds to every cell."""

    name: str
    overrides: tuple[str, ...] = ()
    """``section.key=value`` strings (values as TOML literals). Those of a spec file or of a
    ``--set`` axis are :class:`~slam.config.Override` s naming where they were given (``FILE:
    [grid] rbpf.temperature``), so that a message about one names that, not a ``--set``."""
    values: tuple[tuple[str, Any], ...] = ()
    """The setting's values by key, for tables and plots."""
    seeds: tuple[int, ...] | None = None
    """Seeds of this setting alone (``None``: the sweep's)."""
    grid: bool = True
    """Whether it is a point of a ``[grid]`` (else a ``[[setting]]`` table)."""


@dataclass(frozen=True)
class RunOptions:
    """The ``slam run`` options of every cell."""

    method: str | None = None
    particles: int | None = None
    every: int | None = None
    max_scans: int | None = None
    config: Path | None = None
    no_texture: bool = False
    no_record: bool = False
    set: tuple[str, ...] = ()
    """``section.key=value`` strings; those of the spec file's ``[run] set`` are
    :class:`~slam.config.Override` s naming it (``FILE: [run] set map.resolution``)."""

    def argv(self) -> list[str]:
        """These options as ``slam run`` arguments."""
        out: list[str] = []
        for flag in ("method", "particles", "every", "max_scans"):
            value = getattr(self, flag)
            if value is not None:
                out += [f"--{flag.replace('_', '-')}", str(value)]
        if self.config is not None:
            out += ["--config", str(self.config)]
        if self.no_texture:
            out.append("--no-texture")
        if self.no_record:
            out.append("--no-record")
        for item in self.set:
            out += ["--set", item]
        return out


@dataclass(frozen=True)
class Cell:
    """One run of the sweep: a log, a seed and a setting."""

    name: str
    """Folder name inside the sweep folder."""
    log: str
    seed: int
    setting: Setting
    argv: tuple[str, ...]
    """``slam run`` arguments (without ``--out``)."""
    metric: str
    """``auto``, ``relations``, ``ate`` or ``quality``."""


@dataclass(frozen=True)
class SweepSpec:
    """A whole sweep (see the module docstring)."""

    logs: tuple[str, ...]
    seeds: tuple[int, ...]
    settings: tuple[Setting, ...]
    run: RunOptions = field(default_factory=RunOptions)
    evaluation: tuple[tuple[str, str], ...] = ()
    """Metric per log (``(log, metric)``; logs not named use ``auto``)."""
    out: Path | None = None
    workers: int | None = None
    executor: str = "local"
    address: str | None = None
    source: Path | None = None
    """The spec file, when there is one."""
    logs_where: str = "slam sweep logs"
    """Where the logs were given, for messages: ``FILE: [sweep] logs`` or ``--logs``."""
    address_where: str = "--address"
    """Where the address was given, for messages: ``FILE: [sweep] address`` or ``--address``."""

    def metric_of(self, log: str) -> str:
        """How cells of ``log`` are evaluated."""
        return dict(self.evaluation).get(log, "auto")

    def cells(self) -> list[Cell]:
        """Every cell, log-major, then setting, then seed."""
        cells: list[Cell] = []
        for log in self.logs:
            for setting in self.settings:
                for seed in setting.seeds if setting.seeds is not None else self.seeds:
                    argv = (log, *self.run.argv(), "--seed", str(seed))
                    argv += tuple(x for o in setting.overrides for x in ("--set", o))
                    name = cell_name(log, seed, setting, len(self.settings))
                    cells.append(Cell(name, log, seed, setting, argv, self.metric_of(log)))
        seen: dict[str, Cell] = {}
        for cell in cells:
            if cell.name in seen:
                raise UsageError(
                    f"{self.where('sweep')}: cells {seen[cell.name].argv} and {cell.argv} would "
                    f"share the folder {cell.name!r} (two logs with one name, or two settings "
                    "with one name)"
                )
            seen[cell.name] = cell
        return cells

    def where(self, key: str) -> str:
        """``FILE: [key]`` for messages (or the option when there is no file)."""
        return f"{self.source}: [{key}]" if self.source is not None else f"slam sweep ({key})"

    def identity(self) -> dict[str, Any]:
        """What the cells compute (see the module docstring), JSON-ready."""
        config = None
        if self.run.config is not None:
            try:
                digest = hashlib.sha256(Path(self.run.config).read_bytes()).hexdigest()
            except OSError:
                digest = None
            config = {"path": str(self.run.config), "sha256": digest}
        run = {k: getattr(self.run, k) for k in ("method", "particles", "every", "max_scans")}
        run.update(no_texture=self.run.no_texture, no_record=self.run.no_record)
        run.update(set=list(self.run.set), config=config)
        return {
            "logs": list(self.logs),
            "seeds": list(self.seeds),
            "settings": [
                {
                    "name": s.name,
                    "overrides": list(s.overrides),
                    "seeds": None if s.seeds is None else list(s.seeds),
                }
                for s in self.settings
            ],
            "run": run,
            "evaluation": {log: self.metric_of(log) for log in self.logs},
        }

    def digest(self) -> str:
        """A short hash of :meth:`identity`."""
        text = json.dumps(self.identity(), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:10]


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._=+,-]", "_", text)


def cell_name(log: str, seed: int, setting: Setting, n_settings: int) -> str:
    """``<log>-seed<seed>[-<setting>]`` with only file-name-safe characters."""
    stem = Path(log).name.split(".")[0] if ("/" in log or "." in log) else log
    name = f"{_safe(stem)}-seed{seed}"
    if n_settings > 1 or setting.overrides:
        label = _safe(setting.name)
        if len(name) + 1 + len(label) > MAX_CELL_NAME:
            digest = hashlib.sha256(setting.name.encode()).hexdigest()[:8]
            label = label[: MAX_CELL_NAME - len(name) - 10] + "-" + digest
        name += "-" + label
    return name


MAX_SEEDS = 10_000
"""Most seeds one sweep may list (a cell each): a typo such as ``0-99999999999`` is refused
before a list of that many is built."""


def parse_seeds(value: Any, where: str) -> tuple[int, ...]:
    """Seeds from ``"0-3"``, ``"0,2,5"``, ``3`` or a list of integers: each in ``[0, 2**63)``,
    at most :data:`MAX_SEEDS` of them."""
    expected = f"{where}: expected seeds like 0-3, 0,2,5 or a list of integers in [0, 2**63)"
    ranges: list[tuple[int, int]] = []
    if isinstance(value, int) and not isinstance(value, bool):
        ranges = [(value, value)]
    elif isinstance(value, list) and value:
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            raise UsageError(f"{expected}, found {value!r}")
        ranges = [(v, v) for v in value]
    elif isinstance(value, str):
        for part in value.split(","):
            match = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
            if match is None:
                raise UsageError(f"{expected}, found {value!r}")
            lo, hi = int(match[1]), int(match[2] if match[2] is not None else match[1])
            if hi < lo:
                raise UsageError(f"{expected}, found {value!r}")
            ranges.append((lo, hi))
    if not ranges:
        raise UsageError(f"{expected}, found {value!r}")
    if any(lo < 0 or hi >= 2**63 for lo, hi in ranges):
        raise UsageError(f"{expected}, found {value!r}")
    count = sum(hi - lo + 1 for lo, hi in ranges)
    if count > MAX_SEEDS:
        raise UsageError(f"{where}: at most {MAX_SEEDS} seeds, found {count} in {value!r}")
    return tuple(seed for lo, hi in ranges for seed in range(lo, hi + 1))


def split_values(text: str) -> list[str]:
    """Split ``V1,V2,...`` at commas outside brackets and quotes (``[1,2],[3,4]`` is two)."""
    parts, depth, quote, current = [], 0, "", []
    for char in text:
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append("".join(current))
            current = []
            continue
        current.append(char)
    parts.append("".join(current))
    return [p.strip() for p in parts]


def _override(key: str, value: Any, where: str, label: str | None = None) -> str:
    """``key=value`` (value as a TOML literal); an :class:`~slam.config.Override` naming
    ``label`` when one is given (where the user gave it, for the configuration's messages)."""
    from slam.config import Override, _toml_value

    if not isinstance(key, str) or key.count(".") != 1:
        raise UsageError(
            f"{where}: expected a key section.key (e.g. rbpf.temperature), found {key!r}"
        )
    try:
        text = f"{key}={_toml_value(value)}"
    except ConfigError:
        raise UsageError(f"{where}: {key}: cannot use the value {value!r}") from None
    return Override(text, label) if label is not None else text


def grid_settings(
    axes: list[tuple[str, list[Any]]], where: str, labels: Mapping[str, str] | None = None
) -> tuple[Setting, ...]:
    """The cartesian product of ``(key, values)`` axes as settings named ``key=value,...``.

    Each override names where its axis was given: ``labels[key]``, else ``<where> <key>``
    (``FILE: [grid] rbpf.temperature``, ``--set rbpf.temperature``)."""
    from slam.config import _toml_value

    labels = {key: (labels or {}).get(key, f"{where} {key}") for key, _values in axes}

    for key, values in axes:
        if not isinstance(values, list) or not values:
            raise UsageError(
                f"{where}: {key}: expected a non-empty list of values, found {values!r}"
            )
    settings = []
    for combo in itertools.product(*(values for _key, values in axes)):
        pairs = tuple(zip((k for k, _v in axes), combo, strict=True))
        overrides = tuple(_override(k, v, where, labels[k]) for k, v in pairs)
        name = ",".join(f"{k.split('.', 1)[1]}={_toml_value(v)}" for k, v in pairs)
        settings.append(Setting(name or "default", overrides, pairs))
    return tuple(settings)


def _explicit_settings(items: Any, where: str) -> tuple[Setting, ...]:
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise UsageError(f"{where}: expected [[setting]] tables")
    settings = []
    for k, item in enumerate(items):
        here = f"{where} #{k + 1}"
        unknown = set(item) - {"name", "set", "seeds"}
        if unknown:
            raise UsageError(
                f"{here}: unknown key {sorted(unknown)[0]!r} (expected name, set, seeds)"
            )
        name = item.get("name")
        if not isinstance(name, str) or not name:
            raise UsageError(f"{here}: name: expected a non-empty string")
        values = item.get("set", {})
        if not isinstance(values, dict):
            raise UsageError(f"{here}: set: expected a table of section.key = value")
        pairs = tuple(values.items())
        overrides = tuple(_override(k, v, f"{here}: set", f"{here} set {k}") for k, v in pairs)
        seeds = parse_seeds(item["seeds"], f"{here}: seeds") if "seeds" in item else None
        settings.append(Setting(name, overrides, pairs, seeds, grid=False))
    return tuple(settings)


def read_spec_file(path: Path) -> dict[str, Any]:
    """The TOML of a spec file; unreadable or malformed is one line naming it."""
    from slam.io.text import read_input

    data = read_input(
        Path(path),
        "spec file not found",
        "expected a spec file (TOML), found a folder",
        "cannot read",
        UsageError,
    )
    try:
        return tomllib.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UsageError(f"{path}: not valid TOML ({exc})") from None


def _typed(value: Any, tp: type, where: str) -> Any:
    ok = isinstance(value, tp) and not (tp is int and isinstance(value, bool))
    if not ok:
        raise UsageError(f"{where}: expected {tp.__name__}, found {value!r}")
    return value


def spec_from_toml(data: dict[str, Any], source: Path | None) -> SweepSpec:
    """A spec from the TOML tables of a spec file (``[sweep]``, ``[run]``, ``[grid]``,
    ``[[setting]]``); paths are relative to the file's folder. ``[tune]`` is read by
    :mod:`slam.sweep.tune`."""
    here = str(source) if source is not None else "spec"
    base = source.parent if source is not None else Path.cwd()
    unknown = set(data) - {"sweep", "run", "grid", "setting", "tune"}
    if unknown:
        raise UsageError(
            f"{here}: unknown table [{sorted(unknown)[0]}] (expected sweep, run, grid, setting, tune)"
        )
    sweep = data.get("sweep", {})
    if not isinstance(sweep, dict):
        raise UsageError(f"{here}: [sweep] must be a table")
    for key in sweep:
        if key not in SWEEP_KEYS:
            raise UsageError(
                f"{here}: [sweep] unknown key {key!r} (expected {', '.join(SWEEP_KEYS)})"
            )
    logs, evaluation = _logs_and_evaluation(sweep, here, base)
    seeds = parse_seeds(sweep["seeds"], f"{here}: [sweep] seeds") if "seeds" in sweep else (0,)
    run = _run_options(data.get("run", {}), here, base)
    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise UsageError(f'{here}: [grid] must be a table of "section.key" = [values]')
    if grid and "setting" in data:
        raise UsageError(f"{here}: give either [grid] or [[setting]] tables, not both")
    if "setting" in data:
        settings = _explicit_settings(data["setting"], f"{here}: [[setting]]")
    else:
        settings = grid_settings(list(grid.items()), f"{here}: [grid]")
    out = sweep.get("out")
    workers = sweep.get("workers")
    address = sweep.get("address")
    return SweepSpec(
        logs=logs,
        seeds=seeds,
        settings=settings,
        run=run,
        evaluation=evaluation,
        out=base / _typed(out, str, f"{here}: [sweep] out") if out is not None else None,
        workers=_typed(workers, int, f"{here}: [sweep] workers") if workers is not None else None,
        executor=sweep.get("executor", "local"),
        address=_typed(address, str, f"{here}: [sweep] address") if address is not None else None,
        source=source,
        logs_where=f"{here}: [sweep] logs",
        address_where=f"{here}: [sweep] address",
    )


def _logs_and_evaluation(
    sweep: dict[str, Any], here: str, base: Path
) -> tuple[tuple[str, ...], tuple[tuple[str, str], ...]]:
    """``[sweep] logs`` and ``[sweep.evaluation]``, checked; an evaluation must name one of the
    logs when the file gives them (else :func:`build_spec` checks it against the sweep's)."""
    logs = sweep.get("logs", [])
    if isinstance(logs, str):
        logs = [x.strip() for x in logs.split(",") if x.strip()]
    if not isinstance(logs, list) or not all(isinstance(x, str) and x for x in logs):
        raise UsageError(f"{here}: [sweep] logs: expected a list of dataset names or paths")
    logs = tuple(_log_path(x, base) for x in logs)
    evaluation = sweep.get("evaluation", {})
    if not isinstance(evaluation, dict):
        raise UsageError(f"{here}: [sweep] evaluation: expected a table log = metric")
    for log, metric in evaluation.items():
        if metric not in METRICS:
            raise UsageError(
                f"{here}: [sweep.evaluation] {log}: expected one of {', '.join(METRICS)}, found {metric!r}"
            )
    pairs = tuple((_log_path(k, base), v) for k, v in evaluation.items())
    if logs:
        check_evaluation_logs(pairs, logs, f"{here}: [sweep.evaluation]")
    return logs, pairs


def check_once_or_axis(spec: SweepSpec) -> None:
    """Refuse a key given one value for every cell (``--set`` or ``[run] set``) and also as an
    axis of the settings: each cell's setting comes after it and would override it unseen."""
    axes = {key for setting in spec.settings for key, _value in setting.values}
    for item in spec.run.set:
        key = str(item).split("=", 1)[0].strip()
        if key in axes:
            said = getattr(item, "option", None) or f"--set {item}"
            raise UsageError(
                f"{said}: {key} is also an axis of the sweep's settings, whose values each cell "
                "takes instead; give it in one place"
            )


def check_evaluation_logs(
    evaluation: tuple[tuple[str, str], ...], logs: tuple[str, ...], where: str
) -> None:
    """Refuse a per-log evaluation of a log the sweep does not run (a typo would otherwise leave
    that log on ``auto`` without a word): one line naming it and the logs there are."""
    for log, _metric in evaluation:
        if log not in logs:
            near = difflib.get_close_matches(log, logs, n=1)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            raise UsageError(
                f"{where} {log}: not a log of the sweep; expected one of its logs "
                f"({', '.join(logs)}), found {log!r}{hint}"
            )


def _run_options(table: Any, here: str, base: Path) -> RunOptions:
    """The ``[run]`` table, checked; its ``set`` items name ``FILE: [run] set KEY``."""
    if not isinstance(table, dict):
        raise UsageError(f"{here}: [run] must be a table")
    values: dict[str, Any] = {}
    for key, value in table.items():
        if key not in RUN_OPTIONS:
            raise UsageError(
                f"{here}: [run] unknown key {key!r} (expected {', '.join(RUN_OPTIONS)})"
            )
        values[key] = _typed(value, RUN_OPTIONS[key], f"{here}: [run] {key}")
    _check_filter_options(values, here)
    if "config" in values:
        values["config"] = base / values["config"]
    if "set" in values:
        from slam.config import Override

        items = []
        for item in values["set"]:
            key = item.split("=", 1)[0].strip() if isinstance(item, str) else ""
            if not isinstance(item, str) or "=" not in item or key.count(".") != 1:
                raise UsageError(
                    f"{here}: [run] set: expected 'section.key=value' strings "
                    f"(e.g. 'map.resolution=0.05'), found {item!r}"
                )
            items.append(Override(item, f"{here}: [run] set {key}"))
        values["set"] = tuple(items)
    return RunOptions(**values)


def _check_filter_options(values: Mapping[str, Any], here: str) -> None:
    """Refuse a ``[run]`` method, particle count, scan step or scan limit outside the bounds of
    the ``[filter]`` field it sets, naming the spec's key (not the ``--particles`` it becomes)."""
    from slam.config import FilterConfig
    from slam.validate import FieldError

    for key in ("method", "particles", "every", "max_scans"):
        if key in values:
            try:
                FilterConfig(**{key: values[key]})
            except FieldError as exc:
                raise UsageError(f"{here}: [run] {key}: {exc.detail}") from None


def _log_path(log: str, base: Path) -> str:
    """A log given as a relative path in a spec file is relative to the file's folder."""
    if ("/" in log or log.startswith(".")) and not Path(log).is_absolute():
        return str(base / log)
    return log


def apply_command_line(spec: SweepSpec, args: Any) -> SweepSpec:
    """``spec`` with the values of the command line (``--logs``, ``--seeds``, ``--set``, the
    ``slam run`` options, ``--out``, ``--workers``, ``--executor``, ``--address``)."""
    changes: dict[str, Any] = {}
    if getattr(args, "logs", None):
        changes["logs"] = tuple(x.strip() for x in args.logs.split(",") if x.strip())
        changes["logs_where"] = "--logs"
    if getattr(args, "seeds", None) is not None:
        changes["seeds"] = parse_seeds(args.seeds, "--seeds")
    run = {}
    for flag in ("method", "particles", "every", "max_scans"):
        if getattr(args, flag, None) is not None:
            run[flag] = getattr(args, flag)
    if getattr(args, "config", None) is not None:
        run["config"] = Path(args.config)
    for flag in ("no_texture", "no_record"):
        if getattr(args, flag, False):
            run[flag] = True
    axes: list[tuple[str, list[Any]]] = []
    for text in getattr(args, "set", None) or []:
        from slam.config import parse_literal

        if "=" not in text:
            raise UsageError(f"--set {text!r}: expected section.key=V1[,V2,...]")
        key, raw = text.split("=", 1)
        try:
            values = [parse_literal(v) for v in split_values(raw)]
        except ConfigError as exc:
            raise UsageError(f"--set {key.strip()}: {exc}") from None
        if len(values) == 1:
            run["set"] = (*run.get("set", spec.run.set), _override(key.strip(), values[0], "--set"))
        else:
            axes.append((key.strip(), values))
    if run:
        changes["run"] = replace(spec.run, **run)
    if axes:
        if any(not s.grid for s in spec.settings):
            raise UsageError("--set with several values cannot be combined with [[setting]] tables")
        grid = dict(_axes_of(spec.settings))
        grid.update(dict(axes))
        labels = {k: v for k, v in _labels_of(spec.settings).items() if k not in dict(axes)}
        changes["settings"] = grid_settings(list(grid.items()), "--set", labels)
    for flag in ("out", "workers", "executor", "address"):
        if getattr(args, flag, None) is not None:
            changes[flag] = getattr(args, flag)
    if getattr(args, "address", None) is not None:
        changes["address_where"] = "--address"
    return replace(spec, **changes)


def _axes_of(settings: tuple[Setting, ...]) -> list[tuple[str, list[Any]]]:
    """The grid axes that produced ``settings`` (``[]`` for the lone default setting)."""
    axes: dict[str, list[Any]] = {}
    for setting in settings:
        for key, value in setting.values:
            if value not in axes.setdefault(key, []):
                axes[key].append(value)
    return list(axes.items())


def _labels_of(settings: tuple[Setting, ...]) -> dict[str, str]:
    """Where each grid axis of ``settings`` was given (its overrides' labels), by key."""
    from slam.config import Override

    return {
        key: override.option
        for setting in settings
        for (key, _value), override in zip(setting.values, setting.overrides, strict=False)
        if isinstance(override, Override)
    }


def build_spec(path: Path | None, args: Any) -> SweepSpec:
    """The spec of ``slam sweep [SPEC.toml] [options]``, checked (see the module docstring)."""
    data = read_spec_file(path) if path is not None else {}
    from_file = spec_from_toml(data, path)
    spec = apply_command_line(from_file, args)
    if not spec.logs:
        raise UsageError(f"{spec.where('sweep')}: no logs (give [sweep] logs or --logs intel,aces)")
    if not from_file.logs:  # the file's evaluation is of the command line's logs, or of logs
        # that another --logs runs: only a name that is no dataset at all is a typo
        from slam.io.registry import load_registry

        names = {*load_registry(), "demo"}
        typos = tuple((log, m) for log, m in spec.evaluation if log not in names)
        check_evaluation_logs(typos, spec.logs, spec.where("sweep.evaluation"))
    if not spec.settings:
        spec = replace(spec, settings=(Setting("default"),))
    check_once_or_axis(spec)
    if spec.executor not in EXECUTORS:
        raise UsageError(
            f"{spec.where('sweep')} executor: expected one of {', '.join(EXECUTORS)}, found {spec.executor!r}"
        )
    if spec.workers is not None and spec.workers < 1:
        raise UsageError(
            f"{spec.where('sweep')} workers: expected at least 1, found {spec.workers}"
        )
    if spec.address is not None and spec.executor != "ray":
        raise UsageError(
            f"{spec.where('sweep')} address: the address of a Ray cluster needs executor "
            f"'ray' (found {spec.executor!r})"
        )
    if spec.address is not None:
        from slam.sweep.executors import ray_endpoint

        ray_endpoint(spec.address, spec.address_where)
    return spec
