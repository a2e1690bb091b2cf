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
    """Every name a module imports from the package, at the top or inside a function: ``from
    slam... import name [as alias]`` (resolved to the object it names) and ``import slam[.x]
    [as alias]`` (to the module the name is bound to)."""
    names: dict[str, object] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "slam":
            module = importlib.import_module(node.module)
            for alias in node.names:
                target = getattr(module, alias.name, None)
                if target is None:  # a submodule imported by name
                    target = importlib.import_module(f"{node.module}.{alias.name}")
                names[alias.asname or alias.name] = target
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "slam":
                    module = importlib.import_module(alias.name)
                    if alias.asname:
                        names[alias.asname] = module
                    else:  # `import slam.x` binds `slam`
                        names["slam"] = importlib.import_module("slam")
    return names


def bound_here(tree: ast.AST) -> set[str]:
    """The names the module binds itself (assignments, functions, classes, parameters, loop and
    ``with`` targets): where one shadows an import, which object a call names is not known."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
    return names


def called(func: ast.expr, imported: dict[str, object]) -> tuple[str, object] | None:
    """The name written and the package's object a call's ``func`` names (``f``, ``module.f``,
    ``slam.x.Class``), or None where it is not one of them."""
    chain = []
    while isinstance(func, ast.Attribute):
        chain.append(func.attr)
        func = func.value
    if not isinstance(func, ast.Name) or func.id not in imported:
        return None
    target = imported[func.id]
    for attr in reversed(chain):
        if not inspect.ismodule(target):
            return None  # a method of an object: its class is not known from the source
        try:
            target = getattr(target, attr)
        except AttributeError:
            name = f"{target.__name__}.{attr}"
            target = importlib.import_module(name)  # a submodule not imported yet (or an error)
    return ".".join([func.id, *reversed(chain)]), target


def bad_calls(source: str, name: str) -> list[str]:
    """The calls in a tool's ``source`` (its file ``name``) to the package's callables whose
    arguments do not bind to their signatures."""
    tree = ast.parse(source, filename=name)
    shadowed = bound_here(tree)
    imported = {k: v for k, v in slam_imports(tree).items() if k not in shadowed}
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        hit = called(node.func, imported)
        if hit is None or not callable(hit[1]) or inspect.ismodule(hit[1]):
            continue
        if any(isinstance(a, ast.Starred) for a in node.args) or any(
            k.arg is None for k in node.keywords
        ):
            continue  # *args / **kwargs: the count is not known from the source
        try:
            signature = inspect.signature(hit[1])
        except (TypeError, ValueError):  # a builtin or a numba dispatcher without one
            continue
        try:
            signature.bind(*range(len(node.args)), **{k.arg: None for k in node.keywords})
        except TypeError as error:
            found.append(f"{name}:{node.lineno}: {hit[0]}: {error}")
    return found


def test_there_are_tools_to_check():
    assert len(SCRIPTS) > 20
    assert any(path.parent.name == "benches" for path in SCRIPTS)


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: str(p.relative_to(TOOLS)))
def test_every_call_to_the_package_binds_to_its_signature(path):
    assert bad_calls(path.read_text(), str(path.relative_to(TOOLS))) == []


def test_a_call_with_a_stale_signature_is_found():
    """The check itself: ``resolve_cache_dir`` takes no argument (it once took the data dir)."""
    assert sorted(bad_calls(STALE, "stale.py")) == [
        "stale.py:10: datadir.resolve_cache_dir: too many positional arguments",
        "stale.py:11: slam.io.datadir.resolve_cache_dir: too many positional arguments",
        "stale.py:4: resolve_cache_dir: too many positional arguments",
        "stale.py:6: RunRequest: got an unexpected keyword argument 'dataset'",
        "stale.py:9: slam.Slam: too many positional arguments",
    ]


def test_a_name_the_tool_binds_itself_is_not_taken_for_the_import():
    assert bad_calls(SHADOWED, "shadowed.py") == []


STALE = """from slam.io.datadir import resolve_cache_dir
from slam.pipeline import RunRequest

folder = resolve_cache_dir("data")
ok = resolve_cache_dir()
request = RunRequest("intel", None, None, dataset="intel")
import slam
import slam.io.datadir as datadir
slam.Slam(None, None, None, None)
datadir.resolve_cache_dir(1)
slam.io.datadir.resolve_cache_dir(2)
"""

SHADOWED = """from slam.io.datadir import resolve_cache_dir


def main(resolve_cache_dir=print):
    resolve_cache_dir("a", "b")
"""
