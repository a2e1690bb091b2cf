"""The documentation's commands and settings exist: every ``--option`` written after ``slam
<command>`` in the README and ``docs/`` is an option of that command, and every setting written
as ``section.key = value`` (or ``--set section.key=value``) there, in the sweep specs and in the
shipped configurations is a key of that section. A renamed option or key fails here, not in a
user's terminal."""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

import pytest

from slam.cli import build_parser
from slam.config import section_types

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SETTING_FILES = [
    *PAGES,
    *sorted((ROOT / "tools" / "sweeps").glob("*.toml")),
    *sorted((ROOT / "configs").glob("*.toml")),
]
PLACEHOLDERS = {"key"}  # `section.key=value`: the form, not a key


def command_parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> dict:
    """Every (sub-)command's parser by its words (``("data", "inspect")``)."""
    found = {path: parser}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found.update(command_parsers(sub, (*path, name)))
    return found


COMMAND = re.compile(r"(?:`|^(?:\$ )?(?:\w+=\S+ )*)(?:uv run )?(slam [^`\n#>|]*)", re.M)


def unknown_options(text: str, name: str, parsers: dict) -> list[str]:
    """The ``--options`` of the ``slam ...`` commands in ``text`` (inline code or a line of a
    code block) that the command they follow does not have."""
    found = []
    for match in COMMAND.finditer(text):
        words = match.group(1).split()
        path: tuple[str, ...] = ()
        while len(path) + 1 < len(words) and (*path, words[len(path) + 1]) in parsers:
            path = (*path, words[len(path) + 1])
        if not path:
            continue
        options = {s for a in parsers[path]._actions for s in a.option_strings}
        for word in words[len(path) + 1 :]:
            option = word.strip("[](),.;:'\"").split("=")[0]
            if option.startswith("--") and len(option) > 2 and option not in options:
                line = text.count("\n", 0, match.start()) + 1
                found.append(f"{name}:{line}: slam {' '.join(path)} has no {option}")
    return found


def unknown_settings(text: str, name: str, sections: dict[str, set[str]]) -> list[str]:
    """The ``section.key =`` settings in ``text`` whose section has no such key."""
    setting = re.compile(r"\b(" + "|".join(sections) + r")\.([a-z_][a-z0-9_]*)\s*=")
    return [
        f"{name}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(1)}.{m.group(2)}"
        for m in setting.finditer(text)
        if m.group(2) not in sections[m.group(1)] and m.group(2) not in PLACEHOLDERS
    ]


@pytest.fixture(scope="module")
def parsers() -> dict:
    return command_parsers(build_parser())


@pytest.fixture(scope="module")
def sections() -> dict[str, set[str]]:
    return {n: {f.name for f in dataclasses.fields(t)} for n, t in section_types().items()}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_documented_option_exists(page, parsers):
    assert unknown_options(page.read_text(), page.name, parsers) == []


@pytest.mark.parametrize("path", SETTING_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_documented_setting_exists(path, sections):
    assert unknown_settings(path.read_text(), path.name, sections) == []


def test_the_checks_find_a_renamed_option_and_key(parsers, sections):
    text = (
        "Run `slam run intel --seed 1 --no-recrd` or\n\n"
        "```\nuv run slam data inspect x.bag --scan-topic /scan --odom /odom\n```\n"
        "with `rbpf.probe_evidence = 0.03` and `--set loops.solver_iterations=300`.\n"
    )
    assert unknown_options(text, "t.md", parsers) == [
        "t.md:1: slam run has no --no-recrd",
        "t.md:4: slam data inspect has no --odom",
    ]
    assert unknown_settings(text, "t.md", sections) == ["t.md:6: rbpf.probe_evidence"]


def test_the_pages_name_options_and_settings_to_check(parsers):
    """The checks see the pages' commands (not a pattern that matches nothing)."""
    commands = [m.group(1) for p in PAGES for m in COMMAND.finditer(p.read_text())]
    assert len(commands) > 300
    assert sum(w.startswith("--") for c in commands for w in c.split()) > 120
