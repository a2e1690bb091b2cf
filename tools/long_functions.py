"""List the functions of ``slam/`` longer than the project's limit and whether they say why.

The standard: a function over ~80 lines says in its docstring why it is long. A docstring gives
the reason when it contains the word "long" (``Long because …``, ``… is long: …``).

``uv run python tools/long_functions.py``: one line per long function, ``ok`` or ``NO REASON``;
exit 1 when any lacks a reason (``--limit N`` changes the limit, default 80).
"""

from __future__ import annotations

import argparse
import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
REASON = re.compile(r"\blong\b", re.IGNORECASE)


def long_functions(package: Path, limit: int) -> list[tuple[str, int, int, str, bool]]:
    """``(file, line, length, name, has_reason)`` of every function over ``limit`` lines."""
    out = []
    for path in sorted(package.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            length = node.end_lineno - node.lineno + 1
            if length > limit:
                doc = ast.get_docstring(node) or ""
                rel = str(path.relative_to(package.parent))
                out.append((rel, node.lineno, length, node.name, bool(REASON.search(doc))))
    return out


def main() -> int:
    """Print the list; exit 1 when a long function gives no reason."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--limit", type=int, default=80)
    args = parser.parse_args()
    rows = long_functions(ROOT / "slam", args.limit)
    for rel, line, length, name, ok in sorted(rows, key=lambda r: -r[2]):
        print(f"{length:4d}  {rel}:{line}  {name}  {'ok' if ok else 'NO REASON'}")
    missing = sum(not r[4] for r in rows)
    print(f"{len(rows)} functions over {args.limit} lines, {missing} without a reason")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
