#!/usr/bin/env python3
"""The README's picture of each benchmark log, from the runs behind ``docs/bench/slam.json``.

For every log of ``tools/bench.py slam`` (the entries with a ``sweep_dir``), seed 0's
``quality.png`` — the map, the path coloured by the map-quality score of each stretch, the
returns that conflict with the other stretches' map and the worst stretches circled and labelled
(docs/evaluation.md) — is scaled to at most ``--size`` pixels on its longer side and written to
``docs/images/slam-<log>.png``. Run it after ``tools/bench.py slam`` has written the JSON, on the
machine that holds its sweep folders.

Usage::

    uv run python tools/bench_pictures.py [--bench docs/bench/slam.json] [--size 800]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2

from slam.io.atomic import write_png

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"


def picture_logs(bench: dict) -> dict[str, Path]:
    """Log name → seed 0's run folder, for every SLAM bench entry with a sweep folder."""
    out = {}
    for key, entry in bench["benches"].items():
        if key.startswith("slam.") and isinstance(entry, dict) and entry.get("sweep_dir"):
            log = key.removeprefix("slam.")
            out[log] = Path(entry["sweep_dir"]) / f"{log}-seed0-rbpf"
    return out


def scaled(image, size: int):
    """``image`` scaled (area averaging) so that its longer side is at most ``size`` pixels."""
    h, w = image.shape[:2]
    f = min(1.0, size / max(h, w))
    if f == 1.0:
        return image
    return cv2.resize(image, (round(w * f), round(h * f)), interpolation=cv2.INTER_AREA)


def main() -> int:
    """Write the pictures; exit 2, writing none, on a bench file that is not the bench's JSON or
    naming the first run folder without a ``quality.png``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bench", type=Path, default=ROOT / "docs" / "bench" / "slam.json")
    parser.add_argument("--size", type=int, default=800, help="longer side, pixels")
    args = parser.parse_args()
    if args.size < 1:
        print(f"--size: expected a positive number of pixels, found {args.size}", file=sys.stderr)
        return 2
    try:
        logs = picture_logs(json.loads(args.bench.read_text()))
    except (OSError, ValueError, KeyError, AttributeError, TypeError) as exc:
        print(f"{args.bench}: expected the JSON tools/bench.py slam writes (a 'benches' object), "
              f"found {type(exc).__name__}: {exc}", file=sys.stderr)  # fmt: skip
        return 2
    if not logs:
        print(f"{args.bench}: expected SLAM benches with a sweep_dir, found none", file=sys.stderr)
        return 2
    images = {}
    for log, run in logs.items():
        image = cv2.imread(str(run / "quality.png"), cv2.IMREAD_COLOR)
        if image is None:
            print(f"{run / 'quality.png'}: expected the bench run's quality picture, found none "
                  "(run tools/bench.py slam on this machine first)", file=sys.stderr)  # fmt: skip
            return 2
        images[log] = scaled(image, args.size)
    for log, image in images.items():  # every picture read before any is written
        path = OUT / f"slam-{log}.png"
        write_png(path, image, [cv2.IMWRITE_PNG_COMPRESSION, 9])
        print(f"{path.relative_to(ROOT)}: {image.shape[1]}x{image.shape[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
