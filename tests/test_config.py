"""Configuration loading, overrides, validation and the TOML round trip."""

import re

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
        ("nosuch.key=1", "unknown section [nosuch]"),
        ("filter.nosuch=1", "filter.nosuch: unknown key; expected one of"),
        ("filter.method=magic", "filter.method: expected one of"),
        ("particles", "expected section.key=value"),
        ("filter.seed=-1", "filter.seed: expected an integer ≥ 0, found -1"),
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
