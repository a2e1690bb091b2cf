"""Write a CARMEN log that starts part-way through another: a robustness check.

A user's run starts wherever the robot happens to be, and its first loop is one the benchmark
run never made in that order. This tool writes a copy of a CARMEN log without the records
before a fraction of them (comment lines kept), so that ``slam run`` meets the same building
from another start: the map grows in another order, the first loops are others, and a long one
may come back tens of metres off (docs/accuracy.md, "A run started elsewhere"):

    mkdir -p /tmp/crop
    uv run python tools/crop_log.py ../shared/data/carmen/fr-clinic.clf.gz \\
        /tmp/crop/fr-clinic-from33.clf.gz --from 0.33
    uv run slam run /tmp/crop/fr-clinic-from33.clf.gz --seed 0 --no-texture
    uv run slam eval RUN --relations ../shared/data/carmen/relations/fr-clinic.relations

``slam eval`` matches each relation to the run's poses by time, so the relations before the
cut are left unmatched and the figures are those of the cut log. The output never replaces an
existing file and is written whole or not at all; ``.gz`` outputs are compressed (both as
``tools/perturb_odometry.py`` does: ``tools/log_copies.py``). Exit code 2, one line naming the
file, on bad input.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/log_copies.py
from log_copies import LogFileError, read_lines, write_new  # noqa: E402


def crop_lines(lines: list[str], start: float) -> list[str]:
    """``lines`` of a CARMEN log without its records before the fraction ``start`` of them
    (``0 ≤ start < 1``); comment (``#``) and blank lines are kept, in their places."""
    records = [k for k, line in enumerate(lines) if line.strip() and not line.startswith("#")]
    first = records[int(len(records) * start)] if records else len(lines)
    return [
        line for k, line in enumerate(lines) if k >= first or not line.strip() or line[0] == "#"
    ]


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
        if not (math.isfinite(args.start) and 0.0 <= args.start < 1.0):
            raise LogFileError(f"--from: expected a fraction in [0, 1), found {args.start}")
        lines = read_lines(args.log)
        if not any(line.strip() and not line.startswith("#") for line in lines):
            raise LogFileError(f"{args.log}: expected CARMEN records, found none")
        write_new(args.out, crop_lines(lines, args.start))
    except LogFileError as exc:
        print(f"crop_log: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
