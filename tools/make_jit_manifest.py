#!/usr/bin/env python3
"""Write ``slam/jit_manifest.json``: what a cold ``slam run demo`` compiles, stage by stage.

Runs ``slam run demo`` (its default configuration), then ``slam eval`` of that run with the
quality grid's tiles found as on a building too large to allocate whole, in a child process on a
fresh numba cache
(``NUMBA_CACHE_DIR`` in a temporary folder, the background compiler off) and records every
outermost compilation: the kernel (``module.name``), its argument types, the pipeline stage it
happened in (:func:`slam.jit_background.reach_stage`) and its CPU seconds. The background compiler
(:mod:`slam.jit_background`) compiles the entries of the stages after the filter. The manifest
also keeps the SHA-256 of the source of every cached kernel of the package
(:func:`slam.jit_background.kernel_fingerprints`); ``tests/test_jit_background.py`` fails when
those differ from the sources (a kernel added, removed, renamed or edited, its parameters
included) until this tool is run again. It does not notice a caller passing other argument types
to an unchanged kernel: that costs speed only (the run compiles that signature itself and lists it
under ``compile_background.compiled_here`` in ``metrics.json``).

Usage::

    uv run python tools/make_jit_manifest.py          # about a cold run's time (1-2 min)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def collect(out: Path) -> None:
    """In the child: run the demo pipeline and write what it compiled to ``out`` (JSON)."""
    import slam.kernels.quality
    from slam import jit
    from slam.cli import main as slam_main
    from slam.config import load_config
    from slam.io.datadir import resolve_data_dir
    from slam.jit_background import kernel_fingerprints, reach_stage, type_to_json
    from slam.pipeline import RunRequest, execute

    data_dir = resolve_data_dir(None)
    with tempfile.TemporaryDirectory(prefix="slam-manifest-") as tmp:
        execute(RunRequest(name="demo", config=load_config("demo"), data_dir=data_dir,
                           out=Path(tmp) / "run"))  # fmt: skip
        # The demo's quality grid is small enough to be allocated whole; a larger building's
        # finds its tiles first (slam.kernels.quality.counts_over): score the run that way too,
        # so that the background compiler and `slam warmup` compile that kernel as well.
        reach_stage("finish")
        slam.kernels.quality.DENSE_BYTES = 0
        slam_main(["eval", str(Path(tmp) / "run"), "--json", "--data-dir", str(data_dir)])
    costs = {}
    for row in jit.compile_table():
        costs.setdefault(row["kernel"], []).append(row["cpu_s"])
    entries, seen = [], set()
    for name, stage, args in jit.compiled_signatures():
        if not name.startswith("slam."):
            continue
        try:
            signature = [type_to_json(t) for t in args]
        except ValueError as exc:  # left to the run itself to compile
            print(f"make_jit_manifest: {name} left out: {exc}", file=sys.stderr)
            continue
        key = (name, json.dumps(signature))
        if key in seen:
            continue
        seen.add(key)
        entries.append({"kernel": name, "stage": stage, "signature": signature,
                        "cpu_s": costs[name].pop(0) if costs.get(name) else None})  # fmt: skip
    out.write_text(json.dumps({"kernels": entries, "fingerprints": kernel_fingerprints()}))


def main() -> int:
    """Run the collection in a child process on a fresh cache and write the manifest."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "slam" / "jit_manifest.json")
    parser.add_argument("--collect", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.collect:
        collect(args.collect)
        return 0
    with tempfile.TemporaryDirectory(prefix="slam-manifest-") as tmp:
        raw = Path(tmp) / "compiled.json"
        env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba"),
                   SLAM_BACKGROUND_COMPILE="0")  # fmt: skip
        subprocess.run([sys.executable, __file__, "--collect", str(raw)], env=env, check=True)
        data = json.loads(raw.read_text())
    manifest = {
        "about": "written by tools/make_jit_manifest.py from a cold `slam run demo`; "
        "read by slam/jit_background.py",
        "kernels": data["kernels"],
        "fingerprints": data["fingerprints"],
    }
    args.out.write_text(json.dumps(manifest, indent=1) + "\n")
    stages: dict[str, int] = {}
    for entry in data["kernels"]:
        stages[entry["stage"]] = stages.get(entry["stage"], 0) + 1
    print(f"{args.out}: {len(data['kernels'])} compilations by stage {stages}, "
          f"{len(data['fingerprints'])} kernels fingerprinted")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
