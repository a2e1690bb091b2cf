"""The files of a run folder other tools read, and ``slam export`` of existing run folders.

This module owns the interoperable outputs of a run:

* ``trajectory.tum`` sorted by time (stable: equal times keep their order), as evo and the TUM
  tools require; when the log's clock runs backwards (CARMEN intel: 631 scans),
  ``trajectory_file_order.tum`` keeps the poses in file order and a warning says so;
* ``map.pgm`` + ``map.yaml`` (ROS map_server, :mod:`slam.io.mapserver`) and ``map_clean.png``
  (the occupancy picture without the trajectory drawn on it);
* KITTI poses (``slam export --format kitti``): one row-major 3×4 matrix per line, planar poses
  lifted to 3D (z = 0), with the times in a ``*_times.txt`` file beside it.

:func:`export_run` writes one of them for an existing run folder, never over an existing file
unless asked to, each file atomically.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError, UsageError
from slam.io.atomic import atomic_path, check_new_file, write_npz, write_text
from slam.io.log import count_non_monotonic
from slam.io.tum import format_tum, read_tum
from slam.trajectory import Trajectory

F64 = NDArray[np.float64]

EXPORT_FORMATS = ("pgm", "png", "npz", "tum", "kitti")
"""Formats of ``slam export``."""
EXPORT_DIR = "export"
"""Folder inside the run folder that ``slam export`` writes to by default."""
DEFAULT_NAMES = {
    "pgm": "map.pgm",
    "png": "map_clean.png",
    "npz": "occupancy.npz",
    "tum": "trajectory.tum",
    "kitti": "trajectory.kitti",
}


def time_order(times: F64) -> NDArray[np.int64]:
    """Indices that sort ``times`` (stable)."""
    return np.argsort(np.asarray(times, dtype=np.float64), kind="stable")


def clock_warning(times: F64) -> str | None:
    """The warning of a trajectory whose timestamps go backwards, or ``None``."""
    backwards = count_non_monotonic(np.asarray(times, dtype=np.float64))
    if not backwards:
        return None
    return (
        f"the log's clock runs backwards at {backwards} of {len(times)} poses: trajectory.tum is "
        f"sorted by time, trajectory_file_order.tum keeps the file order"
    )


def write_trajectories(folder: Path, trajectory: Trajectory) -> bool:
    """``trajectory.tum`` sorted by time and, when the order changed, ``trajectory_file_order.tum``;
    returns whether the file-order variant was written."""
    times, poses = trajectory.times, trajectory.poses
    order = time_order(times)
    write_text(Path(folder) / "trajectory.tum", _tum(times[order], poses[order]))
    if clock_warning(times) is None:
        return False
    write_text(Path(folder) / "trajectory_file_order.tum", _tum(times, poses))
    return True


def _tum(times: F64, poses: F64) -> str:
    return format_tum(Trajectory(times, poses))


def write_map_files(folder: Path, log_odds: Any, resolution: float, origin: Any) -> None:
    """``map.pgm`` + ``map.yaml`` and ``map_clean.png`` of a log-odds grid into ``folder``."""
    from slam.io.mapserver import write_map

    write_map(Path(folder) / "map.pgm", log_odds, resolution, origin)
    write_png(Path(folder) / "map_clean.png", clean_image(log_odds))


def clean_image(log_odds: Any) -> NDArray[np.uint8]:
    """The occupancy picture (occupied black, free white, unknown grey, +y up), no trajectory:
    the same grey levels as ``map.png`` (:meth:`slam.mapping.OccupancyGrid.to_image`)."""
    from slam.rowwise import by_rows

    def block(lo: NDArray[np.floating]) -> NDArray[np.uint8]:
        p = 1.0 - 1.0 / (1.0 + np.exp(np.asarray(lo, dtype=np.float64)))
        return (255.0 * (1.0 - p)).astype(np.uint8)

    return by_rows(block, np.asarray(log_odds), np.uint8, flip=True)


def write_png(path: Path, image: NDArray[np.uint8]) -> None:
    """Encode ``image`` as PNG and write it atomically."""
    import cv2

    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"{path}: PNG encoding failed")
    with atomic_path(Path(path)) as tmp:
        tmp.write_bytes(data.tobytes())


def format_kitti(poses: F64) -> str:
    """KITTI text of ``(N, 3)`` planar poses: ``r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz``."""
    poses = np.asarray(poses, dtype=np.float64)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    zero, one = np.zeros_like(c), np.ones_like(c)
    rows = np.column_stack(
        [c, -s, zero, poses[:, 0], s, c, zero, poses[:, 1], zero, zero, one, zero]
    )
    return "".join(" ".join(f"{v:.9e}" for v in row) + "\n" for row in rows.tolist())


# --- slam export --------------------------------------------------------------------------


def read_run_map(run_dir: Path) -> tuple[NDArray[np.float32], float, F64]:
    """``(log_odds, resolution, origin)`` of a run folder's ``map.npz`` (:func:`read_map_npz`)."""
    path = Path(run_dir) / "map.npz"
    if not path.is_file():
        raise DataError(
            f"{path}: not found (expected a run folder of slam run, which writes its map there)"
        )
    return read_map_npz(path)


MAP_KEYS = ("log_odds", "resolution", "origin")
"""The arrays of a run's ``map.npz``."""


def read_npz_arrays(path: Path, keys: tuple[str, ...]) -> dict[str, NDArray[Any]]:
    """Every array of the ``.npz`` archive ``path`` (no pickles); one :class:`DataError` naming
    the file when it is no such archive (empty, foreign, damaged) or lacks one of ``keys``."""
    import zipfile

    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if head != b"PK\x03\x04":
        found = "an empty file" if not head else f"a file starting {head!r}"
        raise DataError(f"{path}: expected an .npz archive (a zip of arrays), found {found}")
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in keys if k not in data.files]
            if missing:
                raise DataError(
                    f"{path}: expected keys {', '.join(keys)}; missing {', '.join(missing)} "
                    f"(found {', '.join(data.files) or 'none'})"
                )
            arrays = {}
            for k in data.files:
                try:
                    arrays[k] = np.asarray(data[k])
                except ValueError as exc:  # numpy refuses an object array without pickle
                    if "allow_pickle" not in str(exc):
                        raise
                    raise DataError(
                        f"{path}: key {k!r}: expected a numeric array, found pickled objects "
                        "(refused: a pickle can run code)"
                    ) from None
            return arrays
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(f"{path}: not a readable .npz archive ({exc})") from None


def read_map_npz(path: Path) -> tuple[NDArray[np.float32], float, F64]:
    """``(log_odds, resolution, origin)`` of the ``map.npz`` at ``path``, every reader's one
    reader: a 2-D, non-empty, finite ``log_odds``, one finite ``resolution`` > 0, two finite
    numbers ``origin``; else one :class:`DataError` naming the file and the key (a damaged,
    empty or foreign file too; never a pickle)."""
    arrays = read_npz_arrays(path, MAP_KEYS)
    log_odds, resolution, origin = arrays["log_odds"], arrays["resolution"], arrays["origin"]
    if (
        log_odds.ndim != 2
        or min(log_odds.shape) < 1
        or not np.issubdtype(log_odds.dtype, np.number)
    ):
        raise DataError(
            f"{path}: key 'log_odds': expected a non-empty 2-D numeric array, found "
            f"{log_odds.dtype} of shape {log_odds.shape}"
        )
    if not np.all(np.isfinite(log_odds)):
        raise DataError(f"{path}: key 'log_odds': holds NaN or infinite values")
    numeric = np.issubdtype(resolution.dtype, np.number)
    if resolution.size != 1 or not numeric or not 0 < float(resolution.reshape(())) < np.inf:
        raise DataError(
            f"{path}: key 'resolution': expected one finite number > 0 (m), found {resolution!r}"
        )
    if (
        origin.shape != (2,)
        or not np.issubdtype(origin.dtype, np.number)
        or not np.all(np.isfinite(origin))
    ):
        raise DataError(f"{path}: key 'origin': expected 2 finite numbers (x, y), found {origin!r}")
    return (
        log_odds.astype(np.float32),
        float(resolution.reshape(())),
        origin.astype(np.float64),
    )


def export_run(run_dir: Path, fmt: str, out: Path | None = None, force: bool = False) -> list[Path]:
    """Write ``fmt`` (one of :data:`EXPORT_FORMATS`) of the run folder ``run_dir``; return the
    files written.

    ``out`` is the file to write (default ``run_dir/export/<standard name>``); ``pgm`` also
    writes the ``.yaml`` beside it, ``kitti`` a ``<stem>_times.txt``. An existing file is an
    error unless ``force``.
    """
    run_dir = Path(run_dir)
    if fmt not in EXPORT_FORMATS:
        raise UsageError(f"--format: expected one of {', '.join(EXPORT_FORMATS)}, found {fmt!r}")
    if not run_dir.is_dir():
        found = "a file" if run_dir.exists() else "nothing"
        raise DataError(f"{run_dir}: expected a run folder, found {found}")
    target = Path(out) if out is not None else run_dir / EXPORT_DIR / DEFAULT_NAMES[fmt]
    if target.is_dir():
        raise UsageError(f"--out {target}: expected a file path, found a folder")
    suffix = {"pgm": ".pgm", "png": ".png", "npz": ".npz"}.get(fmt)
    if suffix is not None and target.suffix.lower() != suffix:
        raise UsageError(f"--out {target}: expected a {suffix} name for --format {fmt}")
    companions = {
        "pgm": [target.with_suffix(".yaml")],
        "kitti": [target.with_name(target.stem + "_times.txt")],
    }.get(fmt, [])
    written = [target, *companions]
    own = run_dir.resolve()
    for path in written:  # the run's own files are its inputs, never an export's output
        if path.resolve().parent == own:
            raise UsageError(
                f"--out {target}: {path.name} would be written into the run folder itself, "
                f"beside the files export reads; write to {run_dir / EXPORT_DIR} or elsewhere"
            )
    for path in written:
        check_new_file(path, "--out" if path == target else "--out's companion", force)
    if fmt in ("pgm", "png", "npz"):
        log_odds, resolution, origin = read_run_map(run_dir)
        if fmt == "pgm":
            from slam.io.mapserver import write_map

            write_map(target, log_odds, resolution, origin)
        elif fmt == "png":
            write_png(target, clean_image(log_odds))
        else:
            _write_occupancy_npz(target, log_odds, resolution, origin)
        return written
    times, poses = read_tum(run_dir / "trajectory.tum")
    order = time_order(times)
    if fmt == "tum":
        write_text(target, _tum(times[order], poses[order]))
    else:
        write_text(target, format_kitti(poses[order]))
        write_text(companions[0], "".join(f"{t:.6f}\n" for t in times[order]))
    return written


def _write_occupancy_npz(path: Path, log_odds: Any, resolution: float, origin: F64) -> None:
    """``occupancy`` (int8 100/0/−1 like ``nav_msgs/OccupancyGrid``, rows from the smallest y),
    ``probability``, ``log_odds``, ``resolution``, ``origin`` ``[x, y, yaw]``."""
    from slam.io.mapserver import trinary

    probability = 1.0 - 1.0 / (1.0 + np.exp(log_odds.astype(np.float64)))
    arrays = {
        "occupancy": trinary(log_odds),
        "probability": probability.astype(np.float32),
        "log_odds": log_odds,
        "resolution": np.float64(resolution),
        "origin": np.array([origin[0], origin[1], 0.0]),
    }
    write_npz(path, arrays)
