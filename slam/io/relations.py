"""Ground-truth relations files (Kümmerle et al. 2009) into :class:`Relations`.

This module owns the file format: one relation per line, ``t1 t2 x y z roll pitch yaw``, the true
motion from the robot pose at time ``t1`` to the pose at ``t2`` expressed in the frame of the
``t1`` pose; ``#`` starts a comment line. Only the planar part (x, y, yaw) is kept. The metric
itself lives in :mod:`slam.eval.relations`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError
from slam.io.text import decode_utf8, read_input

F64 = NDArray[np.float64]

COLUMNS = ("t1", "t2", "x", "y", "z", "roll", "pitch", "yaw")
"""The eight columns of a relations line."""


@dataclass(frozen=True)
class Relations:
    """Relative-motion ground truth: relation ``k`` is the motion from the pose at ``t1[k]`` to
    the pose at ``t2[k]``, in the frame of the ``t1[k]`` pose."""

    t1: F64
    """``(K,)`` time of the first pose (s)."""
    t2: F64
    """``(K,)`` time of the second pose (s)."""
    x: F64
    """``(K,)`` forward motion (m)."""
    y: F64
    """``(K,)`` leftward motion (m)."""
    yaw: F64
    """``(K,)`` heading change (rad)."""
    source: Path | None = None
    """File the relations were read from."""

    def __len__(self) -> int:
        return int(self.t1.shape[0])

    @property
    def motions(self) -> F64:
        """``(K, 3)`` relations as SE(2) poses ``(x, y, yaw)``."""
        return np.stack([self.x, self.y, self.yaw], axis=-1)


def read_relations(path: Path) -> Relations:
    """Read a relations file; :class:`DataError` names the file and line of any bad entry."""
    path = Path(path)
    raw = read_input(
        path,
        "relations file not found",
        "is a folder, expected a relations file",
        "cannot read relations file",
    )
    text = decode_utf8(path, raw)

    rows: list[str] = []
    linenos: list[int] = []
    for lineno, raw in enumerate(text.split("\n"), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        found = len(line.split())
        if found != len(COLUMNS):
            raise DataError(
                f"{path}:{lineno}: expected {len(COLUMNS)} columns '{' '.join(COLUMNS)}', "
                f"found {found}"
            )
        rows.append(line)
        linenos.append(lineno)
    if not rows:
        raise DataError(f"{path}: no relations (expected lines '{' '.join(COLUMNS)}')")

    try:
        values = np.loadtxt(rows, comments=None, ndmin=2, dtype=np.float64)
    except ValueError:
        values = None
    if values is None or values.shape != (len(rows), len(COLUMNS)):
        raise DataError(_first_bad_field(path, rows, linenos))
    finite = np.isfinite(values)
    if not finite.all():
        row, col = np.argwhere(~finite)[0]
        raise DataError(
            f"{path}:{linenos[row]}: {COLUMNS[col]}: expected a finite number, "
            f"found {values[row, col]}"
        )
    return Relations(
        t1=values[:, 0].copy(),
        t2=values[:, 1].copy(),
        x=values[:, 2].copy(),
        y=values[:, 3].copy(),
        yaw=values[:, 7].copy(),
        source=path,
    )


def _first_bad_field(path: Path, rows: list[str], linenos: list[int]) -> str:
    """Message naming the first line and column that is not a number (error path only)."""
    for row, lineno in zip(rows, linenos, strict=True):
        for col, token in enumerate(row.split()):
            try:
                np.loadtxt([token], comments=None, ndmin=1, dtype=np.float64)
            except ValueError:
                shown = token if len(token) <= 40 else token[:40] + "..."
                return f"{path}:{lineno}: {COLUMNS[col]}: expected a number, found {shown!r}"
    return f"{path}: relations could not be read as numbers"
