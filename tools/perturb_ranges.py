"""Write a copy of a CARMEN log whose laser ranges are noisier: a robustness check.

The benchmark logs were recorded with SICK scanners (about a centimetre of range noise); a
user's laser may be a cheaper one whose readings scatter by a few centimetres and by a share of
the range. This tool adds Gaussian noise to every ``FLASER`` reading, with standard deviation
``--sigma-m + --sigma-rel × range`` (seeded by ``--seed``: the same arguments give the same file),
so that ``slam run`` can be measured on the same building with a noisier laser
(docs/accuracy.md, "A noisier laser"):

    uv run python tools/perturb_ranges.py ../shared/data/carmen/aces.clf.gz \\
        /tmp/perturbed/aces-n2.clf.gz --sigma-m 0.02 --sigma-rel 0.01
    uv run slam run /tmp/perturbed/aces-n2.clf.gz --seed 0 --no-texture
    uv run slam eval RUN --relations ../shared/data/carmen/relations/aces.relations

Readings of 0 and readings at the log's largest value (the code of a beam with no return, or
the scanner's maximum) are left as they are, so that what the log says about no return is kept;
a noisy reading is clipped at 0 and kept below that largest value. Every other line and field
(poses, times) is as it was. The output never replaces an existing file and is written whole or
not at all; ``.gz`` outputs are compressed. Exit code 2, one line naming the file and line, on
bad input.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/log_copies.py
from log_copies import LogFileError, flaser_size, read_lines, write_new  # noqa: E402


class PerturbError(Exception):
    """Bad input: the message names the file (and line) and what was expected."""


def _readings(fields: list[str], where: str) -> list[float]:
    """The readings of a ``FLASER`` line's ``fields``."""
    n = flaser_size(fields, where)
    try:
        values = [float(v) for v in fields[2 : n + 2]]
    except ValueError:
        raise PerturbError(f"{where}: expected {n} numbers as readings") from None
    if not all(math.isfinite(v) and v >= 0.0 for v in values):
        raise PerturbError(f"{where}: a reading is negative or not finite")
    return values


def perturb_lines(
    lines: list[str], name: str, sigma_m: float, sigma_rel: float, seed: int
) -> list[str]:
    """The log's ``lines`` with noisy readings (module docstring); ``name`` is the file the
    messages name."""
    scans: list[tuple[int, list[str], list[float]]] = []
    for k, line in enumerate(lines):
        fields = line.split()
        if fields and fields[0] == "FLASER":
            scans.append((k, fields, _readings(fields, f"{name}, line {k + 1}")))
    if not scans:
        raise PerturbError(f"{name}: no FLASER lines: not a CARMEN laser log")
    top = max((max(r, default=0.0) for _, _, r in scans), default=0.0)
    rng = np.random.default_rng(seed)
    out = list(lines)
    for k, fields, readings in scans:
        r = np.asarray(readings, dtype=np.float64)
        noisy = r + rng.standard_normal(r.size) * (sigma_m + sigma_rel * r)
        noisy = np.clip(noisy, 0.0, np.nextafter(top, 0.0))
        keep = (r <= 0.0) | (r >= top)
        noisy = np.where(keep, r, noisy)
        n = len(readings)
        values = [fields[2 + j] if keep[j] else f"{noisy[j]:.3f}" for j in range(n)]
        out[k] = " ".join([*fields[:2], *values, *fields[n + 2 :]])
    return out


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, write the perturbed log; 0, or 2 with one line on bad input."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path, help="CARMEN log (.clf, .log, optionally .gz)")
    parser.add_argument("out", type=Path, help="new file to write (.gz: compressed)")
    parser.add_argument("--sigma-m", type=float, default=0.0, metavar="M", help="metres")
    parser.add_argument("--sigma-rel", type=float, default=0.0, metavar="S", help="share of range")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    args = parser.parse_args(argv)
    try:
        for flag, value, most in (
            ("--sigma-m", args.sigma_m, 1.0),
            ("--sigma-rel", args.sigma_rel, 0.2),
        ):
            if not (math.isfinite(value) and 0.0 <= value <= most):
                raise PerturbError(f"{flag}: expected a value from 0 to {most:g}, found {value}")
        if args.seed < 0:
            raise PerturbError(f"--seed: expected a whole number 0 or above, found {args.seed}")
        lines = read_lines(args.log)
        noisy = perturb_lines(lines, str(args.log), args.sigma_m, args.sigma_rel, args.seed)
        write_new(args.out, noisy)
    except (PerturbError, LogFileError) as exc:
        print(f"perturb_ranges: error: {exc}", file=sys.stderr)
        return 2
    print(
        f"{args.out}: {args.log} with range noise {args.sigma_m:g} m + {args.sigma_rel:g} x range"
        f" (seed {args.seed})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
