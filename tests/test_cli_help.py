"""The command parsers: descriptions from the module docstrings, required sub-command groups."""

from __future__ import annotations

import argparse
import importlib

import pytest

from slam.cli import build_parser, command_modules
from slam.commands._common import add_actions, add_command, doc_description


def _commands() -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def test_doc_description_takes_the_paragraphs_after_the_first() -> None:
    doc = "``slam x``: one line.\n\nSecond ``a``.\n\n* third\n"
    assert doc_description(doc) == "Second 'a'.\n\n* third\n"
    roles = "One.\n\nSee :func:`slam.io.x.read` and :class:`~slam.Slam`."
    assert doc_description(roles) == "See 'slam.io.x.read' and 'slam.Slam'."
    assert doc_description("only one line") is None
    assert doc_description(None) is None


def test_every_command_describes_itself_with_its_module_docstring() -> None:
    commands = _commands()
    assert sorted(commands) == sorted(command_modules())
    for name, parser in commands.items():
        doc = importlib.import_module(f"slam.commands.{name}").__doc__
        assert parser.description == doc_description(doc), name
        assert parser.description, name
        assert "``" not in parser.description, name
        assert ":func:" not in parser.description and ":class:" not in parser.description, name


def test_layout_keeps_line_breaks_and_default_rewraps() -> None:
    top = argparse.ArgumentParser(prog="t")
    sub = add_actions(top, "cmd", "COMMAND")
    doc = "One line.\n\n* a\n* b\n"
    kept = add_command(sub, "kept", doc, "kept help", layout=True).format_help()
    wrapped = add_command(sub, "wrapped", doc, "wrapped help").format_help()
    assert "* a\n* b\n" in kept
    assert "* a * b\n" in wrapped


@pytest.mark.parametrize("argv", [["grid"], ["data"], ["maze"], ["runs"], []])
def test_a_missing_sub_command_is_a_usage_error(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    assert "required" in capsys.readouterr().err


def test_the_parser_does_not_import_numba_or_rerun() -> None:
    # `slam --help`, `slam data list`: building every command's arguments must stay light
    # (numba's import alone took 0.7-1.1 s of a 1.1-1.9 s `slam --help` here)
    import subprocess
    import sys

    from cli_process import cli_env

    code = (
        "import sys; from slam.cli import build_parser; build_parser(); "
        "print(sorted(m for m in ('numba', 'rerun', 'llvmlite') if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], env=cli_env(), capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_the_maze_robots_named_for_the_parser_are_the_robots() -> None:
    from slam.maze import DEFAULT_ROBOT, ROBOT_NAMES
    from slam.maze.robots import ROBOTS

    assert tuple(ROBOTS) == ROBOT_NAMES and DEFAULT_ROBOT in ROBOTS
    maze = _commands()["maze"]
    run = next(a for a in maze._actions if isinstance(a, argparse._SubParsersAction)).choices["run"]
    robot = next(a for a in run._actions if a.dest == "robot")
    assert list(robot.choices) == list(ROBOTS) and robot.default == DEFAULT_ROBOT


def test_the_run_help_names_every_file_a_run_writes(monkeypatch: pytest.MonkeyPatch) -> None:
    """``slam run --help`` lists what a run writes (on main it left out quality.png,
    recording.rrd, texture.npz's siblings and trajectory_file_order.tum), and when."""
    monkeypatch.setenv("COLUMNS", "1000")  # no line break inside an option name
    text = " ".join(_commands()["run"].format_help().split())
    for name in (
        "config.toml", "metrics.json", "trajectory.tum", "trajectory_file_order.tum", "map.npz",
        "map.png", "map_clean.png", "map.pgm/map.yaml", "quality.png", "recording.rrd",
        "texture.npz", "texture.png", "texture_overlay.png",
    ):  # fmt: skip
        assert name in text, name
    assert "quality.png (the map-quality picture, unless quality.enabled = false)" in text
    assert "recording.rrd (the rerun recording, unless --no-record)" in text


def test_the_data_summary_names_its_sub_commands() -> None:
    from slam.cli import COMMANDS

    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    line = next(c.help for c in action._choices_actions if c.dest == "data")
    assert line == COMMANDS["data"].help
    for action_name in ("list", "verify", "inspect", "calibrate"):
        assert action_name in line, action_name
    data = _commands()["data"]
    assert "inspect what a log holds; calibrate a log's odometry" in " ".join(
        (data.description or "").split()
    )
