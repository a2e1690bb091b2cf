"""Configuration loading, overrides, validation and the TOML round trip."""

import re

import numpy as np
import pytest

from slam.config import Config, dumps, load_config, parse_override
from slam.errors import ConfigError


def test_defaults_are_the_robot_constants():
    c = Config()
    assert c.robot.meters_per_tick == pytest.approx(0.0022166, abs=1e-7)
    assert c.lidar.x == pytest.approx(0.13323)


def test_overrides_parse_toml_literals():
    c = load_config(overrides=["filter.particles=100", "robot.yaw_source=encoders"])
    assert c.filter.particles == 100
    assert c.robot.yaw_source == "encoders"
    assert parse_override("map.resolution=0.1") == ("map", "resolution", 0.1)


@pytest.mark.parametrize(
    "override, message",
    [
        ("filter.particles=abc", "filter.particles: expected an integer, found 'abc'"),
        ("filter.particles=0", "filter.particles: expected an integer in [1, 100000], found 0"),
        (  # TOML's integers are 64-bit: a run's config.toml must read back
            "filter.seed=9223372036854775808",
            "filter.seed: expected an integer in [0, 2**63), found 9223372036854775808",
        ),
        ("nosuch.key=1", "unknown section [nosuch]"),
        ("filter.nosuch=1", "filter.nosuch: unknown key; expected one of"),
        ("filter.method=magic", "filter.method: expected one of"),
        ("particles", "expected section.key=value"),
        ("filter.seed=-1", "filter.seed: expected an integer in [0, 2**63), found -1"),
        ("loops.stride=0", "loops.stride: expected an integer in [1, 1000000], found 0"),
        ("loops.search_xy=0", "loops.search_xy: expected a finite number in (0, 100], found 0.0"),
        (
            "loops.min_correction=-0.1",
            "min_correction: expected a finite number in [0, 1000], found -0.1",
        ),
        (
            "loops.min_fit=1.5",
            "--set loops.min_fit=1.5: loops.min_fit: expected a finite number in [0, 1], found 1.5",
        ),
    ],
)
def test_bad_overrides_name_the_key(override, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_config(overrides=[override])


def test_dump_and_reload_is_identical(tmp_path):
    c = load_config("somewhere", overrides=["filter.particles=7", "lidar.fov_deg=180"])
    path = tmp_path / "config.toml"
    path.write_text(dumps(c))
    assert load_config(config_file=path) == c


def test_bad_toml_file_names_the_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[filter\nparticles = 3")
    with pytest.raises(ConfigError, match="bad.toml: invalid TOML"):
        load_config(config_file=path)


def test_an_option_is_named_as_typed_and_a_set_as_set(tmp_path, capsys):
    """``--every 0`` and ``--particles -3`` are reported as the user typed them (on main:
    "--set filter.every=0: ...", an option never typed); a real ``--set`` keeps its wording."""
    from slam.cli import main

    out = tmp_path / "o"
    for args, message in (
        (["--every", "0"], "--every 0: expected an integer in [1, 1000000], found 0"),
        (["--particles", "-3"], "--particles -3: expected an integer in [1, 100000], found -3"),
        (["--max-scans", "-1"], "--max-scans -1: expected an integer ≥ 0, found -1"),
        (
            ["--set", "filter.every=0"],
            "--set filter.every=0: filter.every: expected an integer in [1, 1000000], found 0",
        ),
    ):
        assert main(["run", "demo", "--out", str(out), "--quiet", *args]) == 2
        assert capsys.readouterr().err == f"slam: error: {message}\n"
        assert not out.exists()


def test_a_set_value_with_a_line_break_is_refused(tmp_path, capsys):
    """The bug: ``--set $'map.resolution=0.1\\n[filter]\\nparticles = -5'`` ran (exit 0) with
    everything after the line break dropped; now one error naming the key, nothing written."""
    from slam.cli import main

    text = "map.resolution=0.1\n[filter]\nparticles = -5"
    with pytest.raises(ConfigError, match=r"^--set map.resolution: expected one value on one"):
        parse_override(text)
    out = tmp_path / "o"
    for command in (
        ["run", "demo", "--out", str(out), "--quiet", "--set", text],
        ["sweep", "--logs", "demo", "--out", str(out), "--set", "map.resolution=0.1\nx=1"],
    ):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert err.startswith("slam: error: --set map.resolution: expected one value on one line")
        assert len(err.splitlines()) == 1
        assert not out.exists()


def test_slam_run_names_its_keyword_options():
    import slam

    with pytest.raises(ConfigError) as info:
        slam.run("demo", every=0)
    assert str(info.value) == "slam.run(every=0): expected an integer in [1, 1000000], found 0"
    with pytest.raises(
        ConfigError, match=re.escape("slam.run(seed=-2): expected an integer in [0, 2**63)")
    ):
        slam.run("demo", seed=-2)


def test_overrides_given_as_one_string_are_refused():
    """A str is not read character by character (on main: "--set 'r': expected section.key=...")."""
    import slam
    from slam.errors import UsageError

    expected = (
        "overrides: expected a list of 'section.key=value' strings, found the string "
        "'rbpf.temperature=20'"
    )
    with pytest.raises(UsageError) as info:
        slam.run("demo", overrides="rbpf.temperature=20")
    assert str(info.value) == expected
    with pytest.raises(UsageError) as info:
        slam.load_config("intel", None, "rbpf.temperature=20")
    assert str(info.value) == expected
    with pytest.raises(UsageError, match=r"strings, found an item 3 \(int\)"):
        load_config(overrides=["filter.every=2", 3])
    assert load_config(overrides=("filter.every=2",)).filter.every == 2  # any iterable of str
    for wrong, kind in ((b"filter.every=2", "bytes"), ({"filter.every=2": 1}, "dict")):
        with pytest.raises(UsageError, match=rf"strings, found {kind}$"):
            load_config(overrides=wrong)


@pytest.mark.parametrize("seed", [1.9, "x", True])
def test_a_seed_that_is_not_a_whole_number_is_refused(seed):
    """``Slam(seed=1.9)`` is not silently seed 1, ``slam.run(seed="x")`` not a bare ValueError."""
    import slam
    from slam.errors import UsageError

    with pytest.raises(
        UsageError, match=rf"^Slam\(seed\): expected an integer ≥ 0, found {seed!r}$"
    ):
        slam.Slam(seed=seed)
    with pytest.raises(UsageError, match=r"^slam\.run\(seed\): expected an integer ≥ 0"):
        slam.run("demo", seed=seed)
    assert slam.Slam(seed=np.int64(3)).config.filter.seed == 3
    with pytest.raises(UsageError, match=r"^Slam\(seed\): expected an integer ≥ 0, found -1$"):
        slam.Slam(seed=-1)


def test_a_key_outside_any_section_of_a_config_file(tmp_path):
    """On main: "unknown section [particles]"."""
    path = tmp_path / "mine.toml"
    path.write_text("particles = 40\n\n[filter]\nevery = 2\n")
    with pytest.raises(ConfigError) as info:
        load_config(config_file=path)
    assert str(info.value) == (
        f"{path}: 'particles' is a key outside any section; expected [section] tables such as "
        "[filter] (did you mean filter.particles?)"
    )
    path.write_text("enabled = true\n")  # a key of several sections: no guess
    with pytest.raises(ConfigError) as info:
        load_config(config_file=path)
    message = str(info.value)
    assert message.startswith(f"{path}: 'enabled' is a key outside any section; expected ")
    assert "[filter], [lidar]" in message and "did you mean" not in message
    assert "('enabled' is a key of " in message and "[texture]" in message
    path.write_text("nosuch = 1\n")
    with pytest.raises(ConfigError, match="'nosuch' is a key outside any section") as info:
        load_config(config_file=path)
    assert "is a key of" not in str(info.value)
    path.write_text("[nosuch]\nkey = 1\n")  # a table of an unknown name is still that
    with pytest.raises(ConfigError, match=re.escape("unknown section [nosuch]")):
        load_config(config_file=path)
    path.write_text("filter.particles = 40\n")  # a dotted key is the table [filter]
    assert load_config(config_file=path).filter.particles == 40


def test_a_dataset_name_in_the_wrong_letter_case_is_an_error():
    """On main ``load_config("Intel")`` returned the defaults; an unknown name still does."""
    with pytest.raises(ConfigError) as info:
        load_config("Intel")
    assert str(info.value) == "no configuration 'Intel'; did you mean 'intel'?"
    with pytest.raises(ConfigError, match="no configuration 'DATASET20'; did you mean 'dataset20'"):
        load_config("DATASET20")
    with pytest.raises(ConfigError, match="no configuration 'intel '; did you mean 'intel'"):
        load_config("intel ")
    assert load_config("intel").lidar.no_return == 80.0
    own = load_config("my-building")  # no configs/my-building.toml: the defaults, named
    assert own.dataset == "my-building" and own.lidar == Config().lidar


@pytest.mark.parametrize("name", ["intel.toml", "configs/intel.toml"])
def test_a_file_name_given_as_the_dataset_is_an_error(name):
    """``load_config("configs/intel.toml")`` is not silently the defaults: a file is config_file
    (a log's path, as docs/api.md's example gives, still loads the defaults)."""
    with pytest.raises(ConfigError) as info:
        load_config(name)
    assert str(info.value) == (
        f"dataset {name!r}: expected a dataset's name such as 'intel'; a configuration file is "
        "given as config_file (--config FILE)"
    )
    assert load_config("logs/my-building.clf").lidar == Config().lidar
    assert load_config(None).dataset == ""  # type: ignore[arg-type]
