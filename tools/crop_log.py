"""Write a CARMEN log that starts part-way through another: a robustness check.

A user's run starts wherever the robot happens to be, and its first loop is one the benchmark
run never made in that order. This tool writes a copy of a CARMEN log without the records
before a fraction of them (comment lines kept), so that ``slam run`` meets the same building
from another start: the map grows in another order, the first loops are others, and a long one
may come back tens of metres off (docs/slam.md, "A run started elsewhere"):

    uv run python tools/crop_log.py ../shared/data/carmen/fr-clinic.clf.gz \\
        /tmp/crop/fr-clinic-from33.clf.gz --from 0.33
    uv run slam run /tmp/crop/fr-clinic-from33.clf.gz --seed 0 --no-texture
    uv run slam eval RUN --relations ../shared/data/carmen/relations/fr-clinic.relations

``slam eval`` matches each relation to the run's poses by time, so the relations before the
cut are left unmatched and the figures are those of the cut log. The output never replaces an
existing file and is written whole or not at all; ``.gz`` outputs are compressed. Exit code 2,
one line naming the file, on bad input.
"""

from __future__ import annotations

import argparse
import gzip
import os
import sys
import tempfile
from pathlib import Path


class CropError(Exception):
    """Bad input: the message names the file and what was expected."""


def crop_lines(lines: list[str], start: float) -> list[str]:
    """``lines`` of a CARMEN log without its records before the fraction ``start`` of them
    (``0 ≤ start < 1``); comment lines (``#``) are kept, in their places."""
    records = [k for k, line in enumerate(lines) if line.strip() and not line.startswith("#")]
    first = records[int(len(records) * start)] if records else len(lines)
    return [
        line for k, line in enumerate(lines) if k >= first or not line.strip() or line[0] == "#"
    ]


def _read(path: Path) -> list[str]:
    try:
        opener = gzip.open if path.suffix == ".gz" else open
        with opener(path, "rt", encoding="utf-8", errors="strict") as f:
            return f.readlines()
    except (OSError, UnicodeDecodeError, EOFError) as exc:
        raise CropError(f"{path}: cannot read it as a CARMEN log ({exc})") from exc


def _write(path: Path, lines: list[str]) -> None:
    """Write ``lines`` to ``path`` whole or not at all, never over an existing file."""
    if path.exists():
        raise CropError(f"{path}: exists; this tool never replaces a file")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as raw:
            data = "".join(lines).encode("utf-8")
            raw.write(gzip.compress(data, mtime=0) if path.suffix == ".gz" else data)
        os.link(tmp, path)  # fails if the file appeared meanwhile
    except FileExistsError as exc:
        raise CropError(f"{path}: exists; this tool never replaces a file") from exc
    finally:
        os.unlink(tmp)


def main(argv: list[str] | None = None) -> int:
    """Command line: ``crop_log.py IN OUT --from FRACTION``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", type=Path, help="CARMEN log (.clf or .clf.gz)")
    parser.add_argument("out", type=Path, help="the cut copy (not replaced if it exists)")
    parser.add_argument(
        "--from", dest="start", type=float, required=True,
        help="fraction of the records dropped from the start (0 ≤ FRACTION < 1)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    try:
        if not 0.0 <= args.start < 1.0:
            raise CropError(f"--from: expected a fraction in [0, 1), found {args.start}")
        lines = _read(args.log)
        if not any(line.strip() and not line.startswith("#") for line in lines):
            raise CropError(f"{args.log}: expected CARMEN records, found none")
        _write(args.out, crop_lines(lines, args.start))
    except CropError as exc:
        print(f"crop_log: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
