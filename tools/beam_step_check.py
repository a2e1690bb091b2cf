#!/usr/bin/env python3
"""Which beam geometry fits a CARMEN log whose FLASER lines mix 180 and 181 readings (fr-clinic).

FLASER lines carry no beam geometry. fr-clinic alternates between 180- and 181-reading scans of one
laser; the 181-reading ones are 1° apart from −90° to +90°. For sampled neighbouring pairs (one of
each count) this registers the 180-reading scan onto the 181-reading one by ICP (from the
odometry's relative pose) under each hypothesis for the 180-reading beams, and compares the
median point-to-segment residual per pair (docs/accuracy.md, "The beam step of the 180-reading logs").

A second check uses the filter's own matcher (``--matcher``, the check ``slam data calibrate``
prints: :func:`slam.calibration.check_beam_geometry`): every other pair of consecutive scans is
registered under each hypothesis, and the rotation found is compared with the odometry's: the
trimmed RMS difference, the pairs that fit, and the median difference by the pair's reading
counts. A wrong geometry for one count turns a 180-reading scan against a 181-reading one: the
two mixed kinds of pair then show opposite biases.

Usage::

    uv run python tools/beam_step_check.py fr-clinic [--max-range 15] [--pairs 800] [--json]
    uv run python tools/beam_step_check.py fr-clinic --matcher [--json]
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from slam.calibration import check_beam_geometry
from slam.config import load_config
from slam.io.carmen import load_carmen
from slam.io.datadir import resolve_data_dir
from slam.io.registry import get_dataset
from slam.pipeline import load_source
from slam.scans import LogScans

HYPOTHESES = {
    "spread 180/179 deg (default)": (np.arange(180) - 89.5) * np.deg2rad(180 / 179),
    "1 deg, centred": (np.arange(180) - 89.5) * np.deg2rad(1.0),
    "1 deg, from -90": (np.arange(180) - 90.0) * np.deg2rad(1.0),
    "1 deg, to +90": (np.arange(180) - 89.0) * np.deg2rad(1.0),
}
"""Angles of a 180-reading scan's beams under each hypothesis."""
ANGLES_181 = (np.arange(181) - 90.0) * np.deg2rad(1.0)


def _points(ranges: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
    keep = (ranges > 0.1) & (ranges < max_range)
    return np.c_[ranges[keep] * np.cos(angles[keep]), ranges[keep] * np.sin(angles[keep])]


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[2]), np.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, b[2] - a[2]])


def _moved(src: np.ndarray, x: np.ndarray) -> np.ndarray:
    c, s = np.cos(x[2]), np.sin(x[2])
    return src @ np.array([[c, s], [-s, c]]) + x[:2]


def _nearest(p: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d2 = ((p[:, None, :] - dst[None, :, :]) ** 2).sum(-1)
    idx = d2.argmin(1)
    return np.sqrt(d2[np.arange(p.shape[0]), idx]), idx


def icp_residual(
    src: np.ndarray, dst: np.ndarray, start: np.ndarray, iterations: int = 25
) -> float:
    """Median point-to-segment distance (m) of ``src`` registered onto the ordered scan ``dst``
    by point-to-point ICP from ``start`` (the best 80 % of the pairs each iteration)."""
    x = start.astype(np.float64).copy()
    for _ in range(iterations):
        p = _moved(src, x)
        dist, idx = _nearest(p, dst)
        keep = dist < max(0.2, np.percentile(dist, 80))
        q, pp = dst[idx[keep]], p[keep]
        mp, mq = pp.mean(0), q.mean(0)
        h = (pp - mp).T @ (q - mq)
        ang = np.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
        c, s = np.cos(ang), np.sin(ang)
        r = np.array([[c, -s], [s, c]])
        t = mq - r @ mp
        x = np.array([*(r @ x[:2] + t), x[2] + ang])
    p = _moved(src, x)
    _, idx = _nearest(p, dst)
    best = np.full(p.shape[0], np.inf)
    for step in (-1, 1):  # the segments to the nearest point's neighbours in scan order
        a, b = dst[idx], dst[np.clip(idx + step, 0, dst.shape[0] - 1)]
        ab = b - a
        length2 = (ab**2).sum(1)
        ok = (length2 > 1e-12) & (length2 < 0.3**2)
        t = np.clip(((p - a) * ab).sum(1) / np.where(ok, length2, 1.0), 0.0, 1.0)
        dd = np.hypot(*(p - (a + t[:, None] * ab)).T)
        best = np.where(ok, np.minimum(best, dd), best)
    return float(np.median(best[np.isfinite(best)]))


def _matcher_report(name: str, config, as_json: bool) -> int:
    """``--matcher``: :func:`slam.calibration.check_beam_geometry` on log ``name``, printed."""
    log = load_source(name, resolve_data_dir(None), config).log
    check = check_beam_geometry(LogScans.from_log(log, config), config)
    if check is None:
        widths = ", ".join(str(w) for w in np.unique(log.scans.readings()))
        print(f"{log.source or name}: expected scans of two widths, n and n - 1 readings, found "
              f"scans of {widths} readings", file=sys.stderr)  # fmt: skip
        return 2
    if as_json:
        print(json.dumps({"log": name, **check.as_dict()}, indent=2))
        return 0
    short = check.short
    for geometry, row in check.rows.items():
        medians = ", ".join(
            f"median {label} {row[key]:+.3f}"
            for key, label in (
                ("short_to_long_deg", f"{short}->{short + 1}"),
                ("long_to_short_deg", f"{short + 1}->{short}"),
            )  # fmt: skip
            if key in row
        )
        print(
            f"{geometry:10s} rotation vs odometry {row['rotation_rms_deg']:.3f} deg RMS over "
            f"{row['pairs_fitted']} pairs; {medians} deg"
        )
    return 0


def main() -> int:
    """Print (or emit as JSON) the residuals per hypothesis and the paired comparison."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", help="registry name of a CARMEN log with 180/181 readings")
    parser.add_argument("--max-range", type=float, default=15.0, help="readings used (m)")
    parser.add_argument("--pairs", type=int, default=800, help="pairs sampled (seed 0)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument(
        "--matcher", action="store_true", help="the filter's matcher against the odometry instead"
    )
    args = parser.parse_args()
    config = load_config(args.log)
    if args.matcher:
        return _matcher_report(args.log, config, args.json)
    path = resolve_data_dir(None) / get_dataset(args.log).log_file().path
    scans = load_carmen(path, lidar=config.lidar).scans
    if scans.angles.ndim != 2 or scans.ranges.shape[1] != 181:
        print(f"{path}: expected FLASER lines of 180 and 181 readings", file=sys.stderr)
        return 2
    ranges = np.asarray(scans.ranges, dtype=np.float64)
    counts = np.where(np.isnan(scans.angles[:, -1]), 180, 181)
    change = np.flatnonzero(counts[1:] != counts[:-1])
    change = change[change > 0]
    rng = np.random.default_rng(0)
    chosen = rng.choice(change, size=min(args.pairs, change.size), replace=False)
    residuals: dict[str, list[float]] = {k: [] for k in HYPOTHESES}
    for i in chosen:
        j180, j181 = (i, i + 1) if counts[i] == 180 else (i + 1, i)
        dst = _points(ranges[j181], ANGLES_181, args.max_range)
        if dst.shape[0] < 100:
            continue
        start = _relative(scans.odometry[j181], scans.odometry[j180])
        for name, angles in HYPOTHESES.items():
            src = _points(ranges[j180, :180], angles, args.max_range)
            residuals[name].append(icp_residual(src, dst, start))
    base = np.array(residuals[next(iter(HYPOTHESES))])
    report = {"log": args.log, "max_range_m": args.max_range, "pairs": int(base.size)}
    for name, values in residuals.items():
        v = np.array(values)
        diff = v - base
        report[name] = {
            "median_residual_cm": round(float(np.median(v)) * 100, 3),
            "minus_default_cm": round(float(diff.mean()) * 100, 3),
            "standard_error_cm": round(float(diff.std() / np.sqrt(diff.size)) * 100, 3),
            "better_than_default_share": round(float((diff < 0).mean()), 3),
        }
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for name in HYPOTHESES:
            r = report[name]
            print(
                f"{name:30s} median {r['median_residual_cm']:.3f} cm, vs default "
                f"{r['minus_default_cm']:+.3f} ± {r['standard_error_cm']:.3f} cm, "
                f"better in {r['better_than_default_share'] * 100:.0f} % of {report['pairs']} pairs"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
