"""TUM trajectory files: ``timestamp tx ty tz qx qy qz qw`` per line, ``#`` comments.

Planar poses are written with z = 0 and a yaw-only quaternion, the form evo and most SLAM tools
read. Timestamps keep microseconds (CARMEN relations match scans to 1e-4 s). Trajectories are
:class:`slam.trajectory.Trajectory` values both ways. A file read must hold finite numbers and
unit quaternions (norm 1 ± :data:`QUATERNION_TOLERANCE`): a zero or unnormalised quaternion has
no rotation to read, and is an error naming the line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from slam.errors import DataError
from slam.geometry import quaternion_to_yaw, yaw_to_quaternion
from slam.io.atomic import write_text
from slam.io.text import decode_utf8, read_input
from slam.trajectory import Trajectory

_TUM_LINE = "%.6f %.6f %.6f 0.000000 %.9f %.9f %.9f %.9f"

QUATERNION_TOLERANCE = 1e-3
"""How far from 1 a quaternion's norm may be: files written with 4 decimals stay within 2e-4."""


def format_tum(trajectory: Trajectory) -> str:
    """TUM text of a planar trajectory."""
    times, poses = trajectory.times, trajectory.poses
    rows = np.column_stack([times, poses[:, :2], yaw_to_quaternion(poses[:, 2])]).tolist()
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    lines += [_TUM_LINE % tuple(row) for row in rows]  # Python floats format faster than numpy
    return "\n".join(lines) + "\n"


def write_tum(path: Path, trajectory: Trajectory) -> None:
    """Write a planar trajectory to ``path`` atomically."""
    write_text(Path(path), format_tum(trajectory))


def read_tum(path: Path, distinct_times: bool = False) -> Trajectory:
    """Read a TUM file: the trajectory, with yaw from the quaternion (it unpacks as
    ``times, poses``); z, roll and pitch are not read (planar poses).

    ``distinct_times`` (a reference trajectory): a time written twice with the same pose (within
    :data:`SAME_POSE_M` and :data:`SAME_POSE_RAD`) is read once; with another pose it is an error
    naming both lines (which pose holds there is not for the reader to guess).
    """
    path = Path(path)
    raw = read_input(path, "trajectory file not found", None, "cannot read trajectory")
    text = decode_utf8(path, raw)
    rows = []
    linenos = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        if len(fields) != 8:
            raise DataError(
                f"{path}:{lineno}: expected 8 columns 'timestamp tx ty tz qx qy qz qw', "
                f"found {len(fields)}"
            )
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            names = ("timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw")
            column = next(i for i, f in enumerate(fields) if not _is_number(f))
            raise DataError(
                f"{path}:{lineno}: column {column + 1} ({names[column]}): expected a number, "
                f"found {fields[column]!r}"
            ) from None
        linenos.append(lineno)
    if not rows:
        raise DataError(f"{path}: no poses (expected lines 'timestamp tx ty tz qx qy qz qw')")
    data = np.asarray(rows)
    if not np.all(np.isfinite(data)):
        bad = int(np.argmax(~np.all(np.isfinite(data), axis=1)))
        raise DataError(f"{path}:{linenos[bad]}: pose {bad + 1} has a NaN or infinite value")
    norm = np.linalg.norm(data[:, 4:8], axis=1)
    off = np.abs(norm - 1.0) > QUATERNION_TOLERANCE
    if off.any():
        bad = int(np.argmax(off))
        q = " ".join(f"{v:g}" for v in data[bad, 4:8])
        raise DataError(
            f"{path}:{linenos[bad]}: quaternion (qx qy qz qw) = ({q}) has norm {norm[bad]:.6g}; "
            f"expected a unit quaternion (norm 1 ± {QUATERNION_TOLERANCE:g})"
        )
    poses = np.stack([data[:, 1], data[:, 2], quaternion_to_yaw(data[:, 4:8])], axis=-1)
    if distinct_times:
        keep = _first_of_each_time(path, data[:, 0], poses, linenos)
        return Trajectory(data[keep, 0], poses[keep])
    return Trajectory(data[:, 0], poses)


SAME_POSE_M = 1e-5
"""Two poses of one time this close (m) are the same pose written twice."""
SAME_POSE_RAD = 1e-5
"""... and this close in heading (rad)."""


def _first_of_each_time(
    path: Path, times: np.ndarray, poses: np.ndarray, linenos: list[int]
) -> np.ndarray:
    """Indices of the first pose of each time, in file order; :class:`DataError` naming both
    lines when a time comes again with another pose."""
    _, first, inverse = np.unique(times, return_index=True, return_inverse=True)
    again = np.flatnonzero(first[inverse] != np.arange(times.size))
    if again.size:
        ref = first[inverse[again]]
        step = np.hypot(*(poses[again, :2] - poses[ref, :2]).T)
        turn = np.abs(np.angle(np.exp(1j * (poses[again, 2] - poses[ref, 2]))))
        other = np.flatnonzero((step > SAME_POSE_M) | (turn > SAME_POSE_RAD))
        if other.size:
            k = int(other[0])
            raise DataError(
                f"{path}:{linenos[again[k]]}: time {times[again[k]]:.6f} again (first at line "
                f"{linenos[ref[k]]}) with another pose ({step[k]:.6g} m, "
                f"{np.rad2deg(turn[k]):.4g}° away); a reference holds one pose per time"
            )
    return np.sort(first)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
