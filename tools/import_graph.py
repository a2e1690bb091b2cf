"""Who imports whom inside ``slam``: the table in ``docs/architecture.md``, kept true by a test.

The table lists, for every top-level module or package of ``slam``, the other top-level parts it
imports when it is imported (module level) and those it imports only inside a function (lazy:
loaded when that function runs, so importing the first does not pull them in). Run::

    uv run python tools/import_graph.py           # print the table
    uv run python tools/import_graph.py --write   # rewrite it in docs/architecture.md
    uv run python tools/import_graph.py --check   # exit 1 when the doc differs from the code
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
BEGIN, END = "<!-- imports:begin -->", "<!-- imports:end -->"


def _part(module: str) -> str:
    """The top-level part of ``slam`` a dotted module name belongs to (``slam.io.carmen`` → ``io``)."""
    pieces = module.split(".")
    return pieces[1] if len(pieces) > 1 else "slam"


def _imported(node: ast.AST, module: str, is_package: bool) -> list[str]:
    """The ``slam`` modules an import statement names (relative imports resolved)."""
    if isinstance(node, ast.ImportFrom):
        if node.level:
            base = module.split(".")
            keep = len(base) - node.level + (1 if is_package else 0)
            return [".".join(base[:keep] + ([node.module] if node.module else []))]
        return [node.module] if node.module and node.module.split(".")[0] == "slam" else []
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.split(".")[0] == "slam"]
    return []


def import_graph(package: Path = ROOT / "slam") -> dict[str, tuple[set[str], set[str]]]:
    """``{part: (module-level imports, lazy-only imports)}`` over the parts of ``slam``."""
    eager: dict[str, set[str]] = defaultdict(set)
    lazy: dict[str, set[str]] = defaultdict(set)
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package.parent).with_suffix("")
        module = ".".join(rel.parts[:-1] if path.name == "__init__.py" else rel.parts)
        source = _part(module)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        top = {id(n) for n in tree.body}
        for node in ast.walk(tree):
            for name in _imported(node, module, path.name == "__init__.py"):
                target = _part(name)
                if target != source:
                    (eager if id(node) in top else lazy)[source].add(target)
                eager.setdefault(source, set())
    return {k: (eager[k], lazy[k] - eager[k]) for k in sorted(eager)}


def table() -> str:
    """The Markdown table of :func:`import_graph`."""
    rows = ["| part of `slam` | imports | only inside functions |", "|---|---|---|"]
    for part, (now, later) in import_graph().items():
        fmt = ", ".join(f"`{p}`" for p in sorted(now)) or "—"
        fmt_lazy = ", ".join(f"`{p}`" for p in sorted(later)) or "—"
        rows.append(f"| `{part}` | {fmt} | {fmt_lazy} |")
    return "\n".join(rows)


def _with_table(text: str) -> str:
    start, end = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:start] + "\n" + table() + "\n" + text[end:]


def main(argv: list[str] | None = None) -> int:
    """Print, write or check the table (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite the table in the doc")
    parser.add_argument("--check", action="store_true", help="exit 1 when the doc is stale")
    args = parser.parse_args(argv)
    if not (args.write or args.check):
        print(table())
        return 0
    text = DOC.read_text(encoding="utf-8")
    fresh = _with_table(text)
    if args.check:
        if fresh != text:
            print(f"{DOC}: the import table differs from the code; run {__file__} --write")
            return 1
        return 0
    DOC.write_text(fresh, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
