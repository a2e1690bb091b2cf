"""The scripts under ``tools/`` call the package's functions with arguments their signatures take.

The tools (the benches, the reference makers, the analysis scripts) run for minutes on the real
logs, so the suite does not run most of them; a function of ``slam`` whose signature changed
would break them silently until the next bench. This test reads every tool's source, finds the
calls to names it imports from ``slam``, and binds each call's arguments to the signature.
"""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parent.parent / "tools"
SCRIPTS = sorted(TOOLS.rglob("*.py"))


def slam_imports(tree: ast.AST) -> dict[str, object]:
    """Every name a module imports from the package (``from slam... import name [as alias]``,
    at the top or inside a function), resolved to the object it names."""
    names: dict[str, object] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "slam":
            module = importlib.import_module(node.module)
            for alias in node.names:
                target = getattr(module, alias.name, None)
                if target is None:  # a submodule imported by name
                    target = importlib.import_module(f"{node.module}.{alias.name}")
                names[alias.asname or alias.name] = target
    return names


def bad_calls(source: str, name: str) -> list[str]:
    """The calls in a tool's ``source`` (its file ``name``) to the package's callables whose
    arguments do not bind to their signatures."""
    tree = ast.parse(source, filename=name)
    imported = slam_imports(tree)
    found = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
            continue
        target = imported.get(node.func.id)
        if target is None or not callable(target) or inspect.ismodule(target):
            continue
        if any(isinstance(a, ast.Starred) for a in node.args) or any(
            k.arg is None for k in node.keywords
        ):
            continue  # *args / **kwargs: the count is not known from the source
        try:
            signature = inspect.signature(target)
        except (TypeError, ValueError):  # a builtin or a numba dispatcher without one
            continue
        try:
            signature.bind(*range(len(node.args)), **{k.arg: None for k in node.keywords})
        except TypeError as error:
            found.append(f"{name}:{node.lineno}: {node.func.id}: {error}")
    return found


def test_there_are_tools_to_check():
    assert len(SCRIPTS) > 20
    assert any(path.parent.name == "benches" for path in SCRIPTS)


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: str(p.relative_to(TOOLS)))
def test_every_call_to_the_package_binds_to_its_signature(path):
    assert bad_calls(path.read_text(), str(path.relative_to(TOOLS))) == []


def test_a_call_with_a_stale_signature_is_found():
    """The check itself: ``resolve_cache_dir`` takes no argument (it once took the data dir)."""
    assert bad_calls(STALE, "stale.py") == [
        "stale.py:4: resolve_cache_dir: too many positional arguments",
        "stale.py:6: RunRequest: got an unexpected keyword argument 'dataset'",
    ]


STALE = """from slam.io.datadir import resolve_cache_dir
from slam.pipeline import RunRequest

folder = resolve_cache_dir("data")
ok = resolve_cache_dir()
request = RunRequest("intel", None, None, dataset="intel")
"""
