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


SCOPES = (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)


def in_scope(scope: ast.AST) -> list[ast.AST]:
    """The nodes of ``scope``'s own body: not those of the functions and classes inside it
    (their names and defaults are the scope's, their bodies are scopes of their own)."""
    found = []
    todo = list(ast.iter_child_nodes(scope))
    while todo:
        node = todo.pop()
        found.append(node)
        if isinstance(node, SCOPES):
            decorators = [*getattr(node, "decorator_list", [])]
            args = node.args if not isinstance(node, ast.ClassDef) else None
            defaults = [*args.defaults, *[d for d in args.kw_defaults if d]] if args else []
            todo.extend([*decorators, *defaults])
        else:
            todo.extend(ast.iter_child_nodes(node))
    return found


def scope_names(scope: ast.AST) -> dict[str, object]:
    """What ``scope`` binds itself: a name imported from the package maps to the object it names
    (``from slam... import name [as alias]``; ``import slam[.x] [as alias]``, the module), any
    other binding (an assignment, a function, a class, a parameter, a loop, ``with`` or
    ``except`` target, another import) to None: a call of it is not the package's."""
    names: dict[str, object] = {}
    other: set[str] = set()
    if isinstance(scope, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
        a = scope.args
        params = [*a.posonlyargs, *a.args, *a.kwonlyargs, *filter(None, [a.vararg, a.kwarg])]
        other.update(p.arg for p in params)
    for node in in_scope(scope):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "slam":
            module = importlib.import_module(node.module)
            for alias in node.names:
                target = getattr(module, alias.name, None)
                if target is None:  # a submodule imported by name
                    target = importlib.import_module(f"{node.module}.{alias.name}")
                names[alias.asname or alias.name] = target
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] != "slam":
                    other.add(alias.asname or alias.name.split(".")[0])
                elif alias.asname:
                    names[alias.asname] = importlib.import_module(alias.name)
                else:  # `import slam.x` binds `slam`
                    importlib.import_module(alias.name)
                    names["slam"] = importlib.import_module("slam")
        elif isinstance(node, ast.ImportFrom):
            other.update(alias.asname or alias.name for alias in node.names)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            other.add(node.id)
        elif (
            isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
            or isinstance(node, ast.ExceptHandler)
            and node.name
        ):
            other.add(node.name)
    return {**names, **dict.fromkeys(other)}


def calls_with_names(scope: ast.AST, outer: dict[str, object]):
    """Every call in ``scope`` and the scopes inside it, with the names it sees (Python's rule:
    a scope's own bindings, else the enclosing functions' and the module's; a class body's are
    not seen by its methods)."""
    names = {**outer, **scope_names(scope)}
    for node in in_scope(scope):
        if isinstance(node, ast.Call):
            yield node, names
        if isinstance(node, SCOPES):
            yield from calls_with_names(node, outer if isinstance(scope, ast.ClassDef) else names)


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
    found = []
    for node, names in calls_with_names(ast.parse(source, filename=name), {}):
        hit = called(node.func, {k: v for k, v in names.items() if v is not None})
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
    """Each scope sees its own names: a parameter, an ``except`` target or a function defined
    in a scope shadows the import there (the call is not the package's, or not surely), and an
    alias imported in two functions is each function's own."""
    assert bad_calls(SHADOWED, "shadowed.py") == [
        "shadowed.py:23: f: too many positional arguments"
    ]


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
from slam.pipeline import RunRequest, run


def main(resolve_cache_dir=print):
    resolve_cache_dir("a", "b")


def other():
    try:
        pass
    except OSError as resolve_cache_dir:
        resolve_cache_dir(1, 2)
    run(RunRequest("intel", None, None), 1, 2, 3)  # the local run below, not the package's

    def run(*_):
        pass


def third():
    from slam.io.datadir import resolve_data_dir as f

    f(1, 2, 3)


def fourth():
    from slam.pipeline import RunRequest as f

    f("intel", None, None)
"""
