#!/usr/bin/env python3
"""Benchmarks of the toolkit: speed and memory, as JSON.

Each module in ``tools/benches/`` defines ``benches() -> dict[str, Callable[[], dict]]``; a bench
returns the figures it measured (seconds, rates, sizes). Every bench runs in a fresh subprocess so
its peak resident memory (``peak_rss_mb``) is its own and numba compilation of earlier benches
does not leak into its timings (kernels are compiled in a warm-up inside the bench when it matters).

Usage::

    uv run python tools/bench.py                 # all benches, JSON to stdout
    uv run python tools/bench.py load slam       # only benches whose name contains a pattern
    uv run python tools/bench.py --list
    uv run python tools/bench.py --out bench.json

The README's tables and figures are generated from this output as saved in ``docs/bench/``
(``--out docs/bench/<group>.json``) by ``tools/readme_tables.py``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from benches._util import cpu_model

BENCH_DIR = Path(__file__).resolve().parent / "benches"


def _load_benches() -> dict[str, Callable[[], dict]]:
    found: dict[str, Callable[[], dict]] = {}
    for path in sorted(BENCH_DIR.glob("*.py")):
        if path.name.startswith("_"):
            continue
        spec = importlib.util.spec_from_file_location(f"benches.{path.stem}", path)
        assert spec and spec.loader
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        for name, fn in module.benches().items():
            found[f"{path.stem}.{name}"] = fn
    return found


def _run_one(name: str) -> dict:
    fn = _load_benches()[name]
    start = time.perf_counter()
    result = fn()
    result.setdefault("bench_wall_s", round(time.perf_counter() - start, 3))
    result["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    return result


def main() -> int:
    """Run the selected benches, each in its own process, and print or write their JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("patterns", nargs="*", help="run benches whose name contains one of these")
    parser.add_argument("--list", action="store_true", help="list bench names and exit")
    parser.add_argument("--out", type=Path, help="write the JSON here as well")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.one:
        print(json.dumps(_run_one(args.one)))
        return 0
    names = sorted(_load_benches())
    if args.patterns:
        names = [n for n in names if any(p in n for p in args.patterns)]
    if args.list:
        print("\n".join(names))
        return 0
    report = {
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "platform": platform.platform(),
            "cpu": cpu_model(),
            "numba_threads": os.environ.get("NUMBA_NUM_THREADS", "default"),
        },
        "benches": {},
    }
    failed = False
    for name in names:
        print(f"bench: {name} ...", file=sys.stderr, flush=True)
        proc = subprocess.run(
            [sys.executable, __file__, "--one", name], capture_output=True, text=True
        )
        if proc.returncode != 0:
            failed = True
            report["benches"][name] = {"error": proc.stderr.strip().splitlines()[-1:]}
            print(proc.stderr, file=sys.stderr)
            continue
        report["benches"][name] = json.loads(proc.stdout.strip().splitlines()[-1])
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
