"""Declarative validation of the project's configuration tables: bounds live next to each field.

Every table a user writes — the run configuration (:mod:`slam.config`, ``configs/*.toml``,
``--config``, ``--set``), the dataset registry (:mod:`slam.io.registry`, ``data/datasets.toml``),
the grid scenarios (:mod:`slam.discrete.scenario`, ``configs/grid/*.toml``) and the maze robot's
``--set`` options — is a frozen dataclass whose fields declare their bounds beside their default::

    @dataclass(frozen=True)
    class MapConfig(Validated):
        SECTION: ClassVar[str] = "map"
        RULES: ClassVar[tuple[Rule, ...]] = (
            Rule(("log_odds_min", "log_odds_max"), lambda lo, hi: lo < hi, "log_odds_min < log_odds_max"),
        )

        resolution: float = bounded(0.05, gt=0.0, le=10.0)
        \"\"\"Cell size (m).\"\"\"

This module owns

* the bounds (:class:`Bounds`, declared with :func:`bounded`): type, finiteness, ``>``/``≥``/``<``/
  ``≤``, choices, powers of two, tuple lengths, and a free-form test for the rare field that needs
  one (a relative path, a hex digest);
* cross-field rules (:class:`Rule`);
* the check itself, run once when a :class:`Validated` dataclass is built (``__post_init__``);
* building a dataclass from a parsed TOML table (:func:`from_table`): unknown keys, missing
  required keys and wrong types are errors naming the key, nested tables and lists of tables
  become nested dataclasses;
* reading TOML files (:func:`read_toml`) and ``KEY=VALUE`` literals (:func:`parse_literal`).

Every failure is ONE :class:`~slam.errors.ConfigError` naming the source (file or ``--set``), the
key, the bound and the value, e.g. ``--set map.resolution=0: map.resolution: expected a finite
number in (0, 10], found 0.0``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from slam.errors import ConfigError
from slam.io.text import decode_utf8, read_input


class FieldError(ConfigError):
    """A field (or a rule over fields) failed its bound; :attr:`fields` names them."""

    def __init__(self, prefix: str, fields: tuple[str, ...], detail: str) -> None:
        self.fields = fields
        self.detail = detail
        names = ", ".join(f"{prefix}{f}" for f in fields)
        super().__init__(f"{names}: {detail}")


def _interval_end(
    strict_mark: str, strict: float | None, mark: str, value: float | None
) -> tuple[str, float] | None:
    """One end of an interval as ``(bracket, number)``: the strict bound when there is one, else
    the inclusive one, else None (unbounded)."""
    if strict is not None:
        return strict_mark, strict
    if value is not None:
        return mark, value
    return None


@dataclass(frozen=True)
class Bounds:
    """What a field's value must be, beyond its annotated type."""

    gt: float | None = None
    """Numbers (each item of a tuple): strictly greater than this."""
    ge: float | None = None
    """... at least this."""
    lt: float | None = None
    """... strictly less than this."""
    le: float | None = None
    """... at most this."""
    finite: bool = True
    """Floats: NaN and ±inf are refused (every float field of the project is finite)."""
    choices: tuple[Any, ...] | None = None
    """The value (each item of a tuple) is one of these."""
    power_of_two: bool = False
    """Integers: a power of two."""
    length: int | None = None
    """Tuples: exactly this many items."""
    min_length: int | None = None
    """Tuples, strings: at least this many items (characters)."""
    test: Callable[[Any], bool] | None = None
    """A last check on the (typed) value for what the above cannot say."""
    expected: str | None = None
    """Replaces the generated description of the bound in messages (goes with :attr:`test`)."""

    def describe_number(self, kind: str) -> str:
        """``"a finite number in (0, 10]"``, ``"an integer ≥ 1"``, ...: the bound of one number."""
        noun = {"int": "an integer", "float": "a finite number" if self.finite else "a number"}[
            kind
        ]
        if self.power_of_two:
            noun = "a power of two"
        low = _interval_end("(", self.gt, "[", self.ge)
        high = _interval_end(")", self.lt, "]", self.le)
        if low and high:
            return f"{noun} in {low[0]}{_num(low[1])}, {_num(high[1])}{high[0]}"
        if low:
            return f"{noun} {'>' if low[0] == '(' else '≥'} {_num(low[1])}"
        if high:
            return f"{noun} {'<' if high[0] == ')' else '≤'} {_num(high[1])}"
        return noun


def _num(value: float) -> str:
    if value == 2**63 and isinstance(value, int):  # a 64-bit integer's bound, as written
        return "2**63"
    return f"{value:g}" if isinstance(value, float) else str(value)


def bounded(
    default: Any = dataclasses.MISSING,
    *,
    factory: Callable[[], Any] | Any = dataclasses.MISSING,
    **bounds: Any,
) -> Any:
    """A dataclass field with ``default`` (or a ``factory`` of defaults) and its :class:`Bounds`
    (the keyword arguments)."""
    return dataclasses.field(
        default=default, default_factory=factory, metadata={"bounds": Bounds(**bounds)}
    )


@dataclass(frozen=True)
class Rule:
    """A condition over several fields, checked after each field passed its own bounds."""

    fields: tuple[str, ...]
    """Field names; their values are the test's arguments, in this order."""
    test: Callable[..., bool]
    """True when the values are consistent."""
    text: str
    """What the rule requires, for messages (``"log_odds_min < log_odds_max"``)."""
    blame: tuple[str, ...] | None = None
    """The fields a message names (default: all of :attr:`fields`)."""


class Validated:
    """Mixin of a frozen dataclass whose fields' bounds and :attr:`RULES` are checked when built.

    ``SECTION`` prefixes the field names in messages (``"map"`` gives ``map.resolution``); a
    dataclass built by :func:`from_table` is named by its place in the table instead.
    """

    SECTION: ClassVar[str] = ""
    RULES: ClassVar[tuple[Rule, ...]] = ()

    def __post_init__(self) -> None:
        check(self)


def check(obj: Any) -> None:
    """Check every field of the dataclass ``obj`` against its annotated type and bounds, then its
    class's rules; :class:`FieldError` naming the first that fails (for a list, the item)."""
    cls = type(obj)
    prefix = f"{cls.SECTION}." if getattr(cls, "SECTION", "") else ""
    hints = _hints(cls)
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        tp = hints[f.name]
        bounds = f.metadata.get("bounds", Bounds())
        item = _failing_item(value, tp, bounds)
        if item is not None:
            index, item_value, expected = item
            raise FieldError(
                prefix, (f"{f.name}{index}",), f"expected {expected}, found {item_value!r}"
            )
        problem = _check_value(value, tp, bounds)
        if problem is not None:
            raise FieldError(prefix, (f.name,), f"expected {problem}, found {value!r}")
    for rule in getattr(cls, "RULES", ()):
        values = [getattr(obj, name) for name in rule.fields]
        if not rule.test(*values):
            named = rule.blame or rule.fields
            if len(named) == 1:
                found = repr(getattr(obj, named[0]))
            else:
                found = ", ".join(f"{name}={getattr(obj, name)!r}" for name in named)
            raise FieldError(prefix, named, f"expected {rule.text}, found {found}")


def _failing_item(value: Any, tp: Any, bounds: Bounds) -> tuple[str, Any, str] | None:
    """``("[i]", item, expected)`` for the first item of a list (or ``(".key", key, ...)`` for the
    first key of a table) that is out of its bounds, else ``None``."""
    if _is_optional(tp) and value is not None:
        tp = next(a for a in typing.get_args(tp) if a is not type(None))
    origin = typing.get_origin(tp)
    if origin is tuple and isinstance(value, tuple) and bounds.expected is None:
        item_tp = typing.get_args(tp)[0]
        for i, v in enumerate(value):
            if _check_scalar(v, item_tp, bounds):
                return f"[{i}]", v, _describe_scalar(item_tp, bounds)
    if origin is dict and isinstance(value, Mapping) and bounds.choices is not None:
        for key in value:
            if key not in bounds.choices:
                return f".{key}", key, "one of " + ", ".join(str(c) for c in bounds.choices)
    return None


def describe(tp: Any, bounds: Bounds) -> str:
    """What a value of annotated type ``tp`` within ``bounds`` is, for messages and docs."""
    if bounds.expected is not None:
        return bounds.expected
    args = typing.get_args(tp)
    if _is_optional(tp):
        inner = next(a for a in args if a is not type(None))
        return f"{describe(inner, bounds)} (or unset)"
    if typing.get_origin(tp) is tuple:
        item = args[0]
        one = _describe_scalar(item, bounds)
        if bounds.length is not None:
            return f"a list of {bounds.length} values, each {one}"
        if bounds.min_length:
            return f"a list of at least {bounds.min_length} values, each {one}"
        return f"a list of values, each {one}"
    return _describe_scalar(tp, bounds)


def _describe_scalar(tp: Any, bounds: Bounds) -> str:
    if bounds.choices is not None:
        if len(bounds.choices) == 1:
            return str(bounds.choices[0])
        return "one of " + ", ".join(str(c) for c in bounds.choices)
    if tp is bool:
        return "true or false"
    if tp is int:
        return bounds.describe_number("int")
    if tp is float:
        return bounds.describe_number("float")
    if tp is str:
        return "a non-empty string" if bounds.min_length else "a string"
    if dataclasses.is_dataclass(tp):
        return "a table"
    return str(tp)


def _is_optional(tp: Any) -> bool:
    return typing.get_origin(tp) in (typing.Union, types.UnionType) and type(
        None
    ) in typing.get_args(tp)


def check_value(value: Any, tp: Any, bounds: Bounds) -> str | None:
    """``None`` when ``value`` fits the annotated type ``tp`` and ``bounds``; else the
    description of what was expected."""
    return _check_value(value, tp, bounds)


def _check_value(value: Any, tp: Any, bounds: Bounds) -> str | None:
    if _is_optional(tp):
        if value is None:
            return None
        inner = next(a for a in typing.get_args(tp) if a is not type(None))
        return _check_value(value, inner, bounds)
    if typing.get_origin(tp) is tuple:
        item = typing.get_args(tp)[0]
        if not isinstance(value, tuple):
            return describe(tp, bounds)
        if bounds.length is not None and len(value) != bounds.length:
            return describe(tp, bounds)
        if bounds.min_length is not None and len(value) < bounds.min_length:
            return describe(tp, bounds)
        if any(_check_scalar(v, item, bounds) for v in value):
            return describe(tp, bounds)
        if bounds.test is not None and not bounds.test(value):
            return describe(tp, bounds)
        return None
    if typing.get_origin(tp) is dict or dataclasses.is_dataclass(tp):
        # nested tables checked themselves when built; keys were checked by _failing_item
        if bounds.min_length is not None and len(value) < bounds.min_length:
            return describe(tp, bounds)
        if bounds.test is not None and not bounds.test(value):
            return describe(tp, bounds)
        return None
    if _check_scalar(value, tp, bounds):
        return describe(tp, bounds)
    if bounds.test is not None and not bounds.test(value):
        return describe(tp, bounds)
    return None


def _check_scalar(value: Any, tp: Any, bounds: Bounds) -> bool:
    """True when ``value`` does NOT fit the scalar type ``tp`` and ``bounds``."""
    if tp is bool:
        return not isinstance(value, bool)
    if tp is str:
        if not isinstance(value, str):
            return True
        if bounds.min_length is not None and len(value.strip()) < bounds.min_length:
            return True
        return bounds.choices is not None and value not in bounds.choices
    if tp is int or tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            return True
        if tp is int and not isinstance(value, int):
            return True
        if isinstance(value, float) and bounds.finite and not math.isfinite(value):
            return True
        if isinstance(value, float) and math.isnan(value):
            return True  # NaN fails every comparison: never a valid number
        if bounds.gt is not None and not value > bounds.gt:
            return True
        if bounds.ge is not None and not value >= bounds.ge:
            return True
        if bounds.lt is not None and not value < bounds.lt:
            return True
        if bounds.le is not None and not value <= bounds.le:
            return True
        if bounds.power_of_two and (value < 1 or value & (value - 1)):
            return True
        return bounds.choices is not None and value not in bounds.choices
    return False


def _hints(cls: type) -> dict[str, Any]:
    cached = cls.__dict__.get("_validate_hints")
    if cached is None:
        cached = typing.get_type_hints(cls)
        type.__setattr__(cls, "_validate_hints", cached)
    return cached


# --- building from TOML tables ----------------------------------------------------------------


def _where(source: str, key: str) -> str:
    return f"{source}: {key}" if source and key else source or key


def coerce(value: Any, tp: Any, source: str, key: str) -> Any:
    """``value`` (from a TOML table) as annotated type ``tp``: ints become floats where a float is
    expected, lists become tuples, tables become nested dataclasses (:func:`from_table`).
    :class:`ConfigError` naming ``source`` and ``key`` when the type does not fit (bounds are
    checked later, when the dataclass is built)."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        for arg in options:
            try:
                return coerce(value, arg, source, key)
            except ConfigError:
                if len(options) == 1:
                    raise
        kinds = " or ".join(_type_name(a) for a in options)
        raise ConfigError(f"{_where(source, key)}: expected {kinds}, found {value!r}")
    if origin is tuple:
        (item, *_) = typing.get_args(tp)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{_where(source, key)}: expected a list, found {value!r}")
        return tuple(coerce(v, item, source, f"{key}[{i}]") for i, v in enumerate(value))
    if origin is dict:
        _, item = typing.get_args(tp)
        if not isinstance(value, Mapping):
            raise ConfigError(f"{_where(source, key)}: expected a table, found {value!r}")
        return {k: coerce(v, item, source, f"{key}.{k}") for k, v in value.items()}
    if dataclasses.is_dataclass(tp):
        return from_table(tp, value, source, key)  # type: ignore[arg-type]
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{_where(source, key)}: expected a number, found {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{_where(source, key)}: expected an integer, found {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{_where(source, key)}: expected true or false, found {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{_where(source, key)}: expected a string, found {value!r}")
        return value
    if tp is Any:
        return value
    raise ConfigError(f"{_where(source, key)}: unsupported type {tp!r}")


def _type_name(tp: Any) -> str:
    names = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}
    if tp in names:
        return names[tp]
    return "a list" if typing.get_origin(tp) is tuple else "a table"


def field_types(cls: type) -> dict[str, Any]:
    """Annotated type of every field of the dataclass ``cls``."""
    hints = _hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def from_table(cls: type, table: Any, source: str, where: str, ignore: tuple[str, ...] = ()) -> Any:
    """Build the dataclass ``cls`` from a parsed TOML ``table`` found at ``where`` in ``source``.

    Keys are the dataclass's fields (those in ``ignore`` are left to the caller); an unknown key,
    a missing key without a default, a value of the wrong type or out of its bounds is one
    :class:`ConfigError` naming ``source`` and the dotted key.
    """
    if not isinstance(table, Mapping):
        raise ConfigError(f"{_where(source, where)}: expected a table, found {table!r}")
    types_ = field_types(cls)
    prefix = f"{where}." if where else ""
    for key in table:
        if key not in types_ and key not in ignore:
            raise ConfigError(
                f"{_where(source, prefix + str(key))}: unknown key; expected one of "
                f"{', '.join(sorted(types_))}"
            )
    values = {}
    for f in dataclasses.fields(cls):
        if f.name in table:
            values[f.name] = coerce(table[f.name], types_[f.name], source, prefix + f.name)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{_where(source, prefix + f.name)}: required key is missing")
    return build(cls, values, source, where)


def build(cls: type, values: Mapping[str, Any], source: str, where: str) -> Any:
    """``cls(**values)``, with a bound failure re-worded to name ``source`` and ``where``."""
    try:
        return cls(**values)
    except FieldError as exc:
        prefix = f"{where}." if where else ""
        names = ", ".join(f"{prefix}{f}" for f in exc.fields)
        raise ConfigError(f"{_where(source, names)}: {exc.detail}") from None


# --- reading ----------------------------------------------------------------------------------


def read_toml(path: Path, what: str = "config file") -> dict[str, Any]:
    """Read the TOML file ``path`` (``what`` it is, for messages); :class:`ConfigError` naming the
    file when it is missing, unreadable, not UTF-8 text (with the line and byte offset) or not
    valid TOML."""
    path = Path(path)
    raw = read_input(
        path,
        f"{what} not found",
        f"expected a {what} (TOML), found a folder",
        f"cannot read {what}",
        ConfigError,
    )
    text = decode_utf8(path, raw, ConfigError)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None


def parse_literal(text: str) -> Any:
    """A ``KEY=VALUE`` right-hand side: a TOML literal (``3``, ``0.5``, ``true``, ``"x"``,
    ``[1, 2]``), else the bare text as a string. Never evaluated. A line break is refused
    (:class:`ConfigError`): the lines after it would be read as more TOML, or dropped."""
    stripped = text.strip()
    if "\n" in stripped or "\r" in stripped:
        raise ConfigError(f"expected one value on one line, found a line break in {stripped!r}")
    try:
        return tomllib.loads(f"v = {stripped}")["v"]
    except tomllib.TOMLDecodeError:
        return stripped
