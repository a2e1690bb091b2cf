"""One validated configuration (issue 11, item 7, and the configuration parts of item 10).

Bounds are declared next to every field (:mod:`slam.validate`) and checked once when a
configuration is built; the dataset registry, the grid scenarios and the maze robot's options use
the same validator. Each item test names what today's ``main`` (before the fix) does instead;
every one of them fails there (checked: 2 control cases pass on main, the NaN CLI test makes
main's pytest segfault). The two fuzz tests: any value for any field gives a valid
configuration or one :class:`ConfigError`; any configuration that validates runs SLAM.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import re
import subprocess
import sys
import typing
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st
from synthetic_logs import carmen_lines, write_carmen

from slam.cli import main
from slam.config import Config, dumps, load_config
from slam.errors import ConfigError, UsageError

# Only what main has is imported at module level, so that each item test fails there for its own
# reason; the validator's own names are imported where they are used.


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("slam: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# --- item 7: every field bounded, one message ------------------------------------------------


@pytest.mark.parametrize(
    "override, message",
    [
        ("rbpf.temperature=nan", "rbpf.temperature: expected a finite number in [0.001, 1e+06], found nan"),
        ("rbpf.dmax=nan", "rbpf.dmax: expected a finite number in (0, 10], found nan"),
        ("filter.motion_alphas=[0.1, nan, 0.05, 0.1, 0.02]", "filter.motion_alphas[1]: expected a finite number in [0, 10], found nan"),
        ("map.resolution=0", "map.resolution: expected a finite number in [0.001, 10], found 0.0"),
        ("map.resolution=-0.05", "map.resolution: expected a finite number in [0.001, 10], found -0.05"),
        ("map.resolution=nan", "map.resolution: expected a finite number in [0.001, 10], found nan"),
        ("map.resolution=1e-5", "map.resolution: expected a finite number in [0.001, 10], found 1e-05"),
        ("map.initial_size_m=1e7", "map.initial_size_m: expected a finite number in (0, 10000], found 10000000.0"),
        ("rbpf.tile=1073741824", "rbpf.tile: expected a power of two in [2, 128], found 1073741824"),
        ("rbpf.tile=24", "rbpf.tile: expected a power of two in [2, 128], found 24"),
        ("rbpf.dmax=0", "rbpf.dmax: expected a finite number in (0, 10], found 0.0"),
        ("rbpf.update_distance=0", "rbpf.update_distance: expected a finite number in (0, 100], found 0.0"),
        ("rbpf.coarse_stride=0", "rbpf.coarse_stride: expected an integer in [1, 10000], found 0"),
        ("classic.xy_radius=-1", "classic.xy_radius: expected an integer in [0, 50], found -1"),
        ("filter.particles=1000000000", "filter.particles: expected an integer in [1, 100000], found 1000000000"),
        ("classic.yaw_steps=100000", "classic.yaw_steps: expected an integer in [0, 1000], found 100000"),
        ("classic.yaw_steps=1000", "classic.xy_radius, classic.yaw_steps: expected (2·xy_radius+1)²·(2·yaw_steps+1) ≤ 20000 offsets, found xy_radius=4, yaw_steps=1000"),
        ("map.log_odds_min=-20", None),
        ("map.log_odds_max=-1", "map.log_odds_max: expected a finite number in [0, 1000], found -1.0"),
        ("map.log_odds_max=0", "map.log_odds_min, map.occupied_threshold, map.log_odds_max: expected log_odds_min <= occupied_threshold < log_odds_max"),
        ("filter.motion_alphas=[0.1, -0.05, 0.05, 0.1, 0.02]", "filter.motion_alphas[1]: expected a finite number in [0, 10], found -0.05"),
        ("filter.motion_alphas=[0.1, 0.05]", "filter.motion_alphas: expected a list of 5 values, each a finite number in [0, 10], found (0.1, 0.05)"),
        ("rbpf.refine_passes=-1", "rbpf.refine_passes: expected an integer in [0, 100], found -1"),
        ("rbpf.refine_beams=-1", "rbpf.refine_beams: expected an integer in [0, 100000], found -1"),
        ("rbpf.match_beams=0", "rbpf.match_beams: expected an integer in [1, 100000], found 0"),
        ("rbpf.sigmas=[]", "rbpf.sigmas: expected a list of at least 1 values, each a finite number in (0, 10], found ()"),
        ("lidar.range_min=30", "lidar.range_min, lidar.range_max: expected range_min < range_max, found range_min=30.0, range_max=27.0"),
        ("rbpf.resolution=0.0001", "rbpf.resolution: expected 0 (use map.resolution) or a finite number in [0.001, 10], found 0.0001"),
        ("loops.search_step=0.0001", "expected (2·⌈search_xy/search_step⌉+1)²·(2·⌈search_th/search_th_step⌉+1) ≤ 1000000 candidate poses"),
        ("checks.max_memory_share=0", "checks.max_memory_share: expected a finite number in (0, 1], found 0.0"),
    ],
)  # fmt: skip
def test_out_of_bounds_values_name_key_bound_and_value(override, message):
    """Item 7: each value the issue lists. On main: NaN segfaults inside numba, the others give
    tracebacks, ask for terabytes, hang, or are silently accepted (no ConfigError)."""
    if message is None:  # in bounds: accepted (the control case, true on main as well)
        assert load_config("intel", overrides=[override]).map.log_odds_min == -20.0
        return
    with pytest.raises(ConfigError) as info:
        load_config("intel", overrides=[override])
    assert str(info.value).startswith(f"--set {override}: ")
    assert message in str(info.value)


def test_cli_refuses_nan_and_huge_particle_counts_in_one_line(capsys, tmp_path):
    """Item 7: `--set rbpf.temperature=nan` and `--particles 1000000000` on the command line. On
    main: exit 139 (segfault) and a run that asks for terabytes."""
    for args, said in (
        (["--set", "rbpf.temperature=nan"], "--set rbpf.temperature=nan: rbpf.temperature: "),
        (["--particles", "1000000000"], "--particles 1000000000: "),  # the option as typed
    ):
        assert main(["run", "intel", "--out", str(tmp_path / "r"), *args]) == 2
        assert f"slam: error: {said}expected " in one_line_error(capsys)
    assert not (tmp_path / "r").exists()


def test_every_field_declares_its_bounds():
    """Item 7: bounds sit next to every numeric and choice field (floats are finite, numbers have
    a range). On main: no field declares any (checks were scattered in __post_init__)."""
    undeclared = []
    for section, cls in _sections().items():
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if hints[f.name] is bool:
                continue
            bounds = f.metadata.get("bounds")
            limits = (bounds.gt, bounds.ge, bounds.lt, bounds.le, bounds.choices, bounds.test)
            if bounds is None or all(v is None for v in limits):
                undeclared.append(f"{section}.{f.name}")
    assert undeclared == []


def test_bounds_are_judged_on_the_merged_layers():
    """Item 7, a design check (not a regression; main also accepts this): bounds are checked once,
    on the merged layers, so overrides that are only consistent together are accepted (a
    per-layer check would refuse the first)."""
    config = load_config("intel", overrides=["lidar.range_min=30", "lidar.range_max=40",
                                             "lidar.no_return=80"])  # fmt: skip
    assert (config.lidar.range_min, config.lidar.range_max) == (30.0, 40.0)


def test_bad_value_in_a_file_names_the_file(tmp_path):
    """Item 7: the layer that set the value is named, with the key, the bound and the value."""
    path = tmp_path / "c.toml"
    path.write_text("[rbpf]\ndmax = 0.0\n")
    with pytest.raises(
        ConfigError,
        match=re.escape(f"{path}: rbpf.dmax: expected a finite number in (0, 10], found 0.0"),
    ):
        load_config(config_file=path)  # fmt: skip


def test_run_memory_estimate_refuses_before_allocating(carmen_dir, tmp_path, capsys):
    """Item 7: a run whose estimate exceeds checks.max_memory_share is refused before the maps
    exist. On main: no estimate (and no [checks] section)."""
    code = main(["run", "intel", "--data-dir", str(carmen_dir.parent), "--out", str(tmp_path / "r"),
                 "--max-scans", "20", "--particles", "100000", "--set", "checks.max_memory_share=0.01",
                 "--no-record"])  # fmt: skip
    assert code == 2
    line = one_line_error(capsys)
    said = (
        "intel (its odometry spans 0.0 m × 0.0 m; with maps of their smallest size): rbpf with "
        "100000 particles (scans 70.3 KiB"
    )
    assert said in line
    assert "checks.max_memory_share); use fewer particles (--particles)" in line


def test_run_memory_estimate_figures():
    """Item 7: the estimate's components for a known case (intel-sized: 13631 scans of 180
    beams, a 40 m × 30 m box, 27 m range)."""
    from slam.budget import check_memory, run_memory

    parts = run_memory(Config(), 13631, 180, 40.0, 30.0, 27.0)
    assert parts["scans"] == 13631 * 180 * 20
    side_x, side_y = 40 + 2 * (27 + 10 + 1), 30 + 2 * (27 + 10 + 1)
    assert parts["occupancy grid"] == pytest.approx(side_x / 0.05 * side_y / 0.05 * 16)
    tiles = (side_x / 0.8 + 1) * (side_y / 0.8 + 1)
    assert parts["particle-map tables"] == pytest.approx(2 * 30 * tiles * 4)
    assert parts["particle-map tiles"] == pytest.approx((tiles + 30 * 180) * 2048)
    assert "vacancy grid" not in parts  # off by default
    on = load_config("", overrides=["rbpf.vacate_after=2"])
    vacancy = run_memory(on, 13631, 180, 40.0, 30.0, 27.0)["vacancy grid"]
    assert vacancy == pytest.approx(side_x / 0.1 * side_y / 0.1 * 8)  # 4 bytes, twice growing
    with pytest.raises(
        UsageError, match=r"x would need about 1.0 GiB of memory; the limit is 1.0 MiB"
    ):
        check_memory(2**30, "x", "less", limit=2**20)


# --- the shared validator: registry, scenarios, maze options ---------------------------------


def test_registry_uses_the_same_bounds(tmp_path):
    """Item 7: one validator for the registry too. On main: a NaN rate was accepted (nan <= 0 is
    false)."""
    from slam.io.registry import parse_registry

    raw = {"datasets": {"toy": {"loader": "ece276a", "folder": "toy", "number": 7,
                                "description": "a toy", "source": "tests",
                                "expect": {"scans": {"rate_hz": math.nan}},
                                "files": [{"path": "toy/Hokuyo7.npz", "streams": ["scans"]}]}}}  # fmt: skip
    with pytest.raises(
        ConfigError,
        match=re.escape(
            "reg.toml: datasets.toy.expect.scans.rate_hz: expected a finite number > 0, found nan"
        ),
    ):
        parse_registry(raw, "reg.toml")  # fmt: skip


def test_scenario_uses_the_same_bounds(tmp_path):
    """Item 7: one validator for grid scenarios too. On main: a negative seed was a numpy
    ValueError traceback."""
    from slam.discrete.scenario import load_scenario

    path = tmp_path / "s.toml"
    path.write_text('[world.random]\nrows = 3\ncols = 3\ncolours = ["red", "green"]\nseed = -1\n')
    with pytest.raises(
        ConfigError,
        match=re.escape(f"{path}: world.random.seed: expected an integer ≥ 0, found -1"),
    ):
        load_scenario(path)  # fmt: skip


@pytest.mark.parametrize(
    "option, message",
    [
        ("payoff=abc", "--set payoff=abc: payoff: expected a number, found 'abc'"),
        ("payoff=nan", "--set payoff=nan: payoff: expected a finite number, found nan"),
        ("stride=2.5", "--set stride=2.5: stride: expected an integer, found 2.5"),
    ],
)
def test_maze_options_are_typed(data_dir, capsys, option, message):
    """Item 10: `slam maze run --set payoff=abc`. On main: a TypeError traceback (and NaN was
    accepted)."""
    assert (
        main(["maze", "run", "udacity/test_maze_01", "--data-dir", str(data_dir), "--set", option])
        == 2
    )
    assert one_line_error(capsys) == f"slam: error: {message}"  # fmt: skip


# --- item 10: configuration files and sizes ----------------------------------------------------


def test_non_utf8_toml_names_file_line_and_byte_offset(tmp_path, capsys):
    """Item 10: non-UTF-8 TOML in --config and in `slam grid run`. On main: UnicodeDecodeError
    tracebacks."""
    path = tmp_path / "bad.toml"
    path.write_bytes(b"[filter]\nparticles = 10\n# caf\xe9\n")
    expected = f"{path}:3: expected text, found the non-text byte 0xe9 (byte offset 29; the file must be UTF-8)"
    assert main(["run", "intel", "--config", str(path), "--out", str(tmp_path / "r")]) == 2
    assert one_line_error(capsys) == f"slam: error: {expected}"
    assert main(["grid", "run", str(path)]) == 2
    assert one_line_error(capsys) == f"slam: error: {expected}"  # fmt: skip


def test_huge_random_grid_world_is_refused_up_front(tmp_path, capsys):
    """Item 10: a 100000 × 100000 random world (80 GB of belief). On main: MemoryError
    traceback, or the OOM killer."""
    path = tmp_path / "huge.toml"
    path.write_text('[world.random]\nrows = 100000\ncols = 100000\ncolours = ["red", "green"]\n'
                    '[sensor]\ntype = "colour"\np_correct = 0.9\n[run]\nsteps = ["sense red"]\n')  # fmt: skip
    assert main(["grid", "run", str(path)]) == 2
    line = one_line_error(capsys)
    assert f"{path}: a 100000×100000 world with 1 heading(s) (10000000000 states) would need about 372.5 GiB" in line  # fmt: skip
    assert main(["grid", "study", "--sizes", "3,100000", "--quiet", "--out", str(tmp_path / "s.png")]) == 2  # fmt: skip
    assert "--sizes 3,100000: a 100000×100000 world" in one_line_error(capsys)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--duration", "0.02"],
            "--duration: expected a number of seconds in [1, 3600], found 0.02",
        ),
        (
            ["--duration", "10", "--rgbd-rate", "0.05"],
            "--rgbd-rate 0.05 over 10 s gives fewer than 2 Kinect frames",
        ),
        (["--rgbd-rate", "0.01"], "--rgbd-rate 0.01 over 45 s gives fewer than 2 Kinect frames"),
    ],
)
def test_sim_writes_no_dataset_a_run_cannot_read(tmp_path, capsys, argv, message):
    """The bugs: a log of 0.001–0.06 s (0–2 scans) or one without a Kinect frame was written
    (exit 0), and `slam run` on it failed on an empty 'time_stamps' key."""
    assert main(["sim", "small", "--out", str(tmp_path / "s"), *argv]) == 2
    assert message in one_line_error(capsys)
    assert not (tmp_path / "s").exists()


def test_sim_duration_is_bounded(tmp_path, capsys):
    """Item 10: `slam sim small --duration 1e9`. On main: the simulator starts allocating 10^12
    trajectory steps."""
    assert main(["sim", "small", "--duration", "1e9", "--out", str(tmp_path / "s")]) == 2
    assert one_line_error(capsys) == (
        "slam: error: --duration: expected a number of seconds in [1, 3600], found 1e+09"
    )
    from slam.budget import check_memory
    from slam.sim.dataset import SIM_BYTES_PER_SECOND

    with pytest.raises(UsageError, match=r"--duration 3000: a simulated log of 3000 s would need"):
        check_memory(3000 * SIM_BYTES_PER_SECOND, "--duration 3000: a simulated log of 3000 s",
                     "simulate a shorter log", limit=2**30)  # fmt: skip


# --- fuzz: any value, any field ---------------------------------------------------------------


def _sections() -> dict[str, type]:
    hints = typing.get_type_hints(Config)
    return {name: tp for name, tp in hints.items() if dataclasses.is_dataclass(tp)}


def _fields() -> list[tuple[str, str, typing.Any]]:
    out = []
    for section, cls in _sections().items():
        hints = typing.get_type_hints(cls)
        out += [(section, f.name, hints[f.name]) for f in dataclasses.fields(cls)]
    return out


FIELDS = _fields()

NASTY_FLOATS = st.sampled_from(
    [math.nan, math.inf, -math.inf, 1e308, -1e308, 1e-320, 0.0, -0.0, -1.0]
)
NUMBERS = st.one_of(
    NASTY_FLOATS,
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.sampled_from([0, 1, -1, 2**31, 2**62, 3, 1024]),
)  # fmt: skip
SCALARS = st.one_of(NUMBERS, st.booleans(), st.text(max_size=8), st.sampled_from(["rbpf", "imu", "mean", "distance"]))  # fmt: skip
VALUES = st.one_of(SCALARS, st.lists(NUMBERS, max_size=6), st.lists(SCALARS, max_size=3))


def _literal(value: typing.Any) -> str:
    """``value`` as the TOML literal a user would type after ``--set key=``."""
    from slam.config import _toml_value

    return _toml_value(value)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(FIELDS), VALUES), min_size=1, max_size=4))
def test_fuzz_any_value_gives_a_config_or_a_config_error(assignments):
    """Any value of any type (NaN, ±inf, huge, negative, strings, lists) for any field of any
    section, through ``--set``: a valid configuration or one ConfigError naming the key."""
    overrides = [f"{section}.{name}={_literal(value)}" for (section, name, _), value in assignments]
    try:
        config = load_config("intel", overrides=overrides)
    except ConfigError as exc:
        assert "\n" not in str(exc)
        assert any(f"{s}.{n}" in str(exc) for (s, n, _), _v in assignments), str(exc)
        return
    assert load_config(overrides=[]).__class__ is type(config)
    for (section, name, _), _value in assignments:  # what was accepted is in bounds
        problem = _problem(getattr(config, section), name)
        assert problem is None, problem


def _problem(section_obj: typing.Any, name: str) -> str | None:
    from slam.validate import Bounds, check_value, field_types

    f = next(f for f in dataclasses.fields(section_obj) if f.name == name)
    tp = field_types(type(section_obj))[name]
    return check_value(getattr(section_obj, name), tp, f.metadata.get("bounds", Bounds()))


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(list(_sections().values())), st.data())
def test_fuzz_direct_construction_only_raises_config_error(cls, data):
    """Building a section in Python with any values: the section or a ConfigError, nothing else."""
    types_ = {f.name: f.type for f in dataclasses.fields(cls)}
    names = data.draw(st.lists(st.sampled_from(sorted(types_)), max_size=3, unique=True))
    kwargs = {n: data.draw(st.one_of(SCALARS, st.tuples(NUMBERS, NUMBERS, NUMBERS))) for n in names}
    with contextlib.suppress(ConfigError):
        cls(**kwargs)


# --- fuzz: any configuration that validates runs ---------------------------------------------

COSTLY = {
    ("filter", "particles"): (1, 64),
    ("rbpf", "max_iterations"): (1, 50),
    ("classic", "xy_radius"): (0, 4),
    ("classic", "yaw_steps"): (0, 10),
}
"""Fields whose upper bound is allowed but slow (minutes for 20 scans): the run fuzz samples them
below these caps so it finishes in seconds; every other field spans its whole declared range."""


def _strategy_for(section: str, name: str, tp: typing.Any, bounds: typing.Any) -> st.SearchStrategy:
    if tp is bool:
        return st.booleans()
    if bounds.choices is not None:
        return st.sampled_from(bounds.choices)
    if (section, name) in COSTLY:
        lo, hi = COSTLY[(section, name)]
        return st.integers(lo, hi)
    if typing.get_origin(tp) in (typing.Union, __import__("types").UnionType):
        inner = next(a for a in typing.get_args(tp) if a is not type(None))
        return st.one_of(st.none(), _strategy_for(section, name, inner, bounds))
    if typing.get_origin(tp) is tuple:
        item = _strategy_for(section, name, typing.get_args(tp)[0], bounds)
        size = bounds.length
        return st.lists(item, min_size=size or bounds.min_length or 0, max_size=size or 4).map(
            tuple
        )
    if tp is int:
        lo = bounds.ge if bounds.ge is not None else (bounds.gt + 1 if bounds.gt is not None else 0)
        hi = bounds.le if bounds.le is not None else 10**6
        return st.integers(int(lo), int(hi)).filter(
            lambda v: not bounds.power_of_two or v & (v - 1) == 0
        )
    lo = bounds.ge if bounds.ge is not None else bounds.gt
    hi = bounds.le if bounds.le is not None else bounds.lt
    floats = st.floats(lo, hi, exclude_min=bounds.gt is not None, exclude_max=bounds.lt is not None)
    edges = st.sampled_from(
        [v for v in (lo, hi) if v is not None and bounds.gt != v and bounds.lt != v] or [1.0]
    )
    strategy = st.one_of(edges, floats)
    if bounds.test is not None:
        strategy = st.one_of(st.just(0.0), strategy).filter(bounds.test)
    return strategy  # fmt: skip


@st.composite
def valid_overrides(draw) -> dict[str, dict[str, typing.Any]]:
    """Random in-bounds values for a random handful of fields (rules may still refuse the mix:
    such draws are retried)."""
    from slam.validate import Bounds

    chosen = draw(st.lists(st.sampled_from(FIELDS), min_size=1, max_size=8, unique=True))
    table: dict[str, dict[str, typing.Any]] = {}
    for section, name, tp in chosen:
        if section in ("texture", "viz"):
            continue  # a CARMEN log has no RGB-D frames; the recording is off
        cls = _sections()[section]
        bounds = next(f for f in dataclasses.fields(cls) if f.name == name).metadata.get(
            "bounds", Bounds()
        )
        table.setdefault(section, {})[name] = draw(_strategy_for(section, name, tp, bounds))  # fmt: skip
    return table


RUNNER = """
import json, sys
from slam.cli import main
log, configs, out = sys.argv[1], json.loads(open(sys.argv[2]).read()), sys.argv[3]
for k, path in enumerate(configs):
    print("config", k, path, flush=True)
    code = main(["run", log, "--config", path, "--out", f"{out}/run{k}", "--max-scans", "20",
                 "--no-record", "--quiet"])
    print("exit", k, code, flush=True)
    if code not in (0, 2):
        sys.exit(10)
"""


@pytest.fixture(scope="module")
def room_log(tmp_path_factory) -> Path:
    return write_carmen(tmp_path_factory.mktemp("room"), carmen_lines(40))


@settings(
    max_examples=2,
    deadline=None,
    phases=[Phase.explicit, Phase.generate],  # no shrinking: an example is 8 subprocess runs
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(st.lists(valid_overrides(), min_size=8, max_size=8))
def test_fuzz_every_valid_config_runs_slam(room_log, tmp_path_factory, tables):
    """Any configuration that validates runs 20 scans of a small log in a subprocess (a segfault
    fails the test instead of killing pytest): exit 0, or exit 2 with one line (a memory
    estimate may refuse), never a crash or a traceback."""
    folder = tmp_path_factory.mktemp("fuzz")
    paths = []
    for k, table in enumerate(tables):
        try:
            config = load_config(
                "",
                overrides=[
                    f"{s}.{n}={_literal(v)}" for s, t in table.items() for n, v in t.items()
                ],
            )
        except ConfigError:
            continue  # a cross-field rule refused the mix: not a valid configuration
        path = folder / f"config{k}.toml"
        path.write_text(dumps(config))
        paths.append(str(path))
    listing = folder / "configs.json"
    listing.write_text(json.dumps(paths))
    proc = subprocess.run([sys.executable, "-c", RUNNER, str(room_log), str(listing), str(folder)],
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert proc.returncode == 0, (
        f"exit {proc.returncode}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
    )
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith("slam: error:")]
    exits = re.findall(r"^exit \d+ (\d+)$", proc.stdout, flags=re.M)
    assert len(exits) == len(paths) and exits.count("2") == len(errors)  # fmt: skip


def test_a_vanishing_search_step_is_a_config_error_not_an_overflow():
    """Found by the run fuzz: ``loops.search_th_step = 1e-323`` made the search-size rule raise
    OverflowError (``math.ceil(inf)``) instead of refusing the value."""
    with pytest.raises(ConfigError, match="candidate poses"):
        load_config("", overrides=["loops.search_th_step=1e-323"])


@pytest.mark.parametrize(
    "key", ["backend.keyframe_path", "backend.submap_length", "loops.pass_shift_step",
            "quality.stretch_m"],
)  # fmt: skip
def test_a_spacing_too_fine_to_lay_out_is_refused(key):
    """A spacing along the path that would lay out billions of keyframes, submaps, shifts or
    stretches (the fuzz above drew ``backend.keyframe_path = 1e-323``, and the run crashed in
    NumPy) is refused when the configuration is built, with the key named."""
    with pytest.raises(ConfigError, match=key.split(".")[1]):
        load_config("", overrides=[f"{key}=1e-323"])


def test_maps_over_a_drifting_odometry_warn_instead_of_refusing(monkeypatch):
    """The bug: the estimate sized the maps by the odometry's bounding box, which drift
    inflates: mit-killian's 599 × 521 m gave 4.4 GiB for a run that peaks at 0.7 GiB, refused on
    a machine of 8.5 GB. Now only what maps of their smallest size cannot fit is refused; the
    rest is a warning, and the maps' growth is checked as they grow."""
    import warnings

    import slam.budget
    from slam.io.plausibility import DataWarning
    from slam.pipeline import _check_memory

    config = Config()
    drifted = np.array([[0.0, 0.0, 0.0], [600.0, 520.0, 0.0]])
    small = run_memory_total(config, np.zeros((2, 3)))
    large = run_memory_total(config, drifted)
    monkeypatch.setattr(slam.budget, "memory_limit", lambda share=0.5: int((small + large) / 2))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _check_memory("bldg", 1000, 361, drifted, 80.0, config)
    (warning,) = caught
    assert warning.category is DataWarning
    assert str(warning.message).startswith("bldg (its odometry spans 600.0 m × 520.0 m): maps over")
    assert "going on" in str(warning.message)
    # the maps' growth is then checked against the run's own share (review: it read 0.5)
    from slam.budget import growth_share
    from slam.mapping import OccupancyGrid

    grid = OccupancyGrid(config.map)
    monkeypatch.setattr(slam.budget, "memory_limit", lambda share=0.5: int(share * 2**30))
    with growth_share(0.01), pytest.raises(UsageError, match=r"checks\.max_memory_share\)"):
        grid.ensure_contains(-200.0, -200.0, 200.0, 200.0)  # 8000 × 8000 cells, 256 MB
    grid.ensure_contains(-200.0, -200.0, 200.0, 200.0)  # within 0.5 of the same machine: grows
    monkeypatch.setattr(slam.budget, "memory_limit", lambda share=0.5: int(small / 2))
    with pytest.raises(UsageError, match=r"with maps of their smallest size\): rbpf with 30"):
        _check_memory("bldg", 1000, 361, drifted, 80.0, config)


def run_memory_total(config: Config, poses: np.ndarray) -> float:
    """The whole estimate of a 1000-scan, 361-beam run over ``poses``' extent, 80 m of reach."""
    from slam.budget import run_memory

    span = poses[:, :2].max(axis=0) - poses[:, :2].min(axis=0)
    return sum(run_memory(config, 1000, 361, float(span[0]), float(span[1]), 80.0).values())
