"""Write a copy of a CARMEN log whose odometry is a few per cent off: a robustness check.

A user's robot is one we have never seen, and its wheel calibration is rarely as good as the
benchmark robots'. This tool rewrites a CARMEN log's odometry with every step's distance times
``--distance-scale`` and every step's turn times ``--turn-scale`` (the scans, times and every
other line as they are), so that ``slam run`` can be measured on the same building with worse
odometry (docs/accuracy.md, "Odometry a few per cent off"):

    uv run python tools/perturb_odometry.py ../shared/data/carmen/aces.clf.gz \\
        /tmp/perturbed/aces-d105.clf.gz --distance-scale 1.05
    uv run slam run /tmp/perturbed/aces-d105.clf.gz --seed 0 --no-texture
    uv run slam eval RUN --relations ../shared/data/carmen/relations/aces.relations

The ``ODOM`` stream and the poses of the ``FLASER`` lines are rewritten each along its own file
order, step by step (``pᵢ₊₁ = pᵢ ⊕ scaled(pᵢ⁻¹ ⊕ qᵢ₊₁)`` over the original poses ``q``), which
keeps the two consistent; each ``FLASER`` laser pose keeps its offset from the line's odometry
pose. Logs whose pose lines this does not rewrite (``ROBOTLASER1``, ``TRUEPOS``) are refused.
The output never replaces an existing file and is written whole or not at all; ``.gz`` outputs
are compressed. Exit code 2, one line naming the file and line, on bad input.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tools/log_copies.py
from log_copies import LogFileError, flaser_size, read_lines, write_new  # noqa: E402

UNSUPPORTED = ("ROBOTLASER1", "TRUEPOS")
"""Line types that carry poses this tool does not rewrite."""


class PerturbError(Exception):
    """Bad input: the message names the file (and line) and what was expected."""


Pose = tuple[float, float, float]


def _relative(a: Pose, b: Pose) -> Pose:
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, math.remainder(b[2] - a[2], math.tau))


def _compose(a: Pose, b: Pose) -> Pose:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (
        a[0] + c * b[0] - s * b[1],
        a[1] + s * b[0] + c * b[1],
        math.remainder(a[2] + b[2], math.tau),
    )


def rescaled(poses: list[Pose], distance: float, turn: float) -> list[Pose]:
    """``poses`` (in order) with every step's distance times ``distance`` and turn times
    ``turn``, from the same first pose."""
    out = poses[:1]
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        dx, dy, dth = _relative(a, b)
        out.append(_compose(out[-1], (distance * dx, distance * dy, turn * dth)))
    return out


def _pose(fields: list[str], at: int, where: str) -> Pose:
    try:
        x, y, th = (float(v) for v in fields[at : at + 3])
    except ValueError:
        raise PerturbError(
            f"{where}: expected a pose (three numbers), found {fields[at : at + 3]}"
        ) from None
    if not all(map(math.isfinite, (x, y, th))):
        raise PerturbError(f"{where}: the pose {fields[at : at + 3]} is not finite")
    return (x, y, th)


def _fmt(pose: Pose) -> list[str]:
    return [f"{v:.6f}" for v in pose]


def perturb_lines(lines: list[str], name: str, distance: float, turn: float) -> list[str]:
    """The log's ``lines`` with their odometry rescaled (module docstring); ``name`` is the file
    the messages name."""
    odom: list[tuple[int, Pose]] = []
    laser: list[tuple[int, Pose, Pose]] = []  # line, odometry pose, laser pose
    rows = [line.split() for line in lines]
    for k, fields in enumerate(rows):
        if not fields:
            continue
        where = f"{name}, line {k + 1}"
        kind = fields[0]
        if kind in UNSUPPORTED:
            raise PerturbError(f"{where}: {kind} lines carry poses this tool does not rewrite")
        if kind == "ODOM":
            if len(fields) < 4:
                raise PerturbError(
                    f"{where}: expected ODOM x y theta ..., found {len(fields)} fields"
                )
            odom.append((k, _pose(fields, 1, where)))
        elif kind == "FLASER":
            n = flaser_size(fields, where)
            laser.append((k, _pose(fields, n + 5, where), _pose(fields, n + 2, where)))
    if not odom and not laser:
        raise PerturbError(f"{name}: no ODOM or FLASER lines: not a CARMEN log with odometry")
    out = list(lines)
    for (k, _), pose in zip(odom, rescaled([p for _, p in odom], distance, turn), strict=True):
        fields = rows[k]
        out[k] = " ".join([fields[0], *_fmt(pose), *fields[4:]])
    new = rescaled([p for _, p, _ in laser], distance, turn)
    for (k, was, at), pose in zip(laser, new, strict=True):
        fields = list(rows[k])
        n = int(fields[1])
        fields[n + 2 : n + 5] = _fmt(_compose(pose, _relative(was, at)))
        fields[n + 5 : n + 8] = _fmt(pose)
        out[k] = " ".join(fields)
    return out


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, write the perturbed log; 0, or 2 with one line on bad input."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path, help="CARMEN log (.clf, .log, optionally .gz)")
    parser.add_argument("out", type=Path, help="new file to write (.gz: compressed)")
    parser.add_argument("--distance-scale", type=float, default=1.0, metavar="S")
    parser.add_argument("--turn-scale", type=float, default=1.0, metavar="S")
    args = parser.parse_args(argv)
    try:
        for flag, value in (
            ("--distance-scale", args.distance_scale),
            ("--turn-scale", args.turn_scale),
        ):
            if not (math.isfinite(value) and 0.5 <= value <= 2.0):
                raise PerturbError(f"{flag}: expected a factor from 0.5 to 2, found {value}")
        lines = read_lines(args.log)
        write_new(
            args.out, perturb_lines(lines, str(args.log), args.distance_scale, args.turn_scale)
        )
    except (PerturbError, LogFileError) as exc:
        print(f"perturb_odometry: error: {exc}", file=sys.stderr)
        return 2
    print(
        f"{args.out}: {args.log} with distances x{args.distance_scale:g}, turns x{args.turn_scale:g}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
