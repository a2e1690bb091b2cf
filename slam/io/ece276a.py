"""Loader of the UCSD ECE276A robot logs (``EncodersNN.npz``, ``ImuNN.npz``, ``HokuyoNN.npz``,
``KinectNN.npz`` and the ``dataRGBD/`` image folders) into a :class:`~slam.io.log.Log`.

This module owns the file format of these logs (``docs/data-formats.md`` §1, "ECE276A robot
logs"; where they go: ``docs/data.md``): which keys each file holds, their shapes, dtypes and
units, and every check that a file really is what its name says. Files are read with ``allow_pickle=False``; anything a
user can get wrong (missing, empty, truncated or pickled file, missing key, wrong shape or dtype,
non-finite or implausibly spaced timestamps, inconsistent beam geometry) raises one
:class:`~slam.errors.DataError` that names the file and key, what was expected and what was found.

Invalid range readings (NaN, inf, negative, below ``range_min``) are not errors: they become NaN
and are counted in :attr:`ScanStream.invalid_beams`. RGB-D images are never read here; the
:class:`~slam.io.log.RgbdIndex` reads a frame only when asked.
"""

from __future__ import annotations

import math
import os
import re
import zipfile
import zlib
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.budget import DEFAULT_MEMORY_SHARE, check_memory, format_bytes
from slam.config import MAX_RANGE_M, LidarConfig
from slam.errors import DataError, UsageError
from slam.io.datadir import check_readable_dir, is_present, put_files_hint
from slam.io.log import (
    EncoderStream,
    ImuStream,
    Log,
    RgbdIndex,
    ScanStream,
    count_non_monotonic,
    valid_ranges,
)

STREAMS: tuple[str, ...] = ("encoders", "imu", "scans", "kinect")
"""Streams of an ECE276A log, each read from one file."""

DEFAULT_NEED: tuple[str, ...] = ("encoders", "imu")
"""Streams :func:`load_ece276a` requires unless told otherwise (enough for odometry)."""

ANGLE_TOLERANCE = 1e-3
"""How far (rad) ``angle_min + (B - 1) * angle_increment`` may be from ``angle_max``: a quarter
of the 0.25° step, far below any off-by-one-beam error (one full step, 4.4e-3 rad)."""


@dataclass(frozen=True)
class KeySpec:
    """One array an ECE276A file must hold."""

    key: str
    shape: str
    """Expected shape, as written in messages (``N`` is the reading count; the Hokuyo scalars
    may also be 0-d)."""
    dtype: str
    """Expected dtype, as written in messages."""
    meaning: str
    """Unit or typical value."""


@dataclass(frozen=True)
class StreamSpec:
    """The file of one stream: name pattern, keys and plausible rate."""

    stream: str
    pattern: str
    """File name with ``{nn}`` for the dataset number."""
    what: str
    """What the file holds, for messages."""
    keys: tuple[KeySpec, ...]
    rate_hz: tuple[float, float]
    """Plausible reading rate (Hz). Outside it the timestamps are not seconds (milli- or
    nanoseconds give rates 1000× off) or the file is not the stream its name says; the bounds are
    wide on purpose so that simulated logs at other rates still load."""

    def file_name(self, number: str) -> str:
        """File name of this stream for dataset ``number``."""
        return self.pattern.format(nn=number)

    def describe_keys(self) -> str:
        """The expected keys with shapes and dtypes, for messages."""
        return ", ".join(f"{k.key} {k.dtype} {k.shape} [{k.meaning}]" for k in self.keys)


SPECS: dict[str, StreamSpec] = {
    "encoders": StreamSpec(
        "encoders",
        "Encoders{nn}.npz",
        "wheel encoder counts",
        (
            KeySpec("counts", "(4, N)", "int16", "ticks per interval, rows FR, FL, RR, RL"),
            KeySpec("time_stamps", "(N,)", "float64", "s"),
        ),
        (5.0, 500.0),
    ),
    "imu": StreamSpec(
        "imu",
        "Imu{nn}.npz",
        "IMU readings",
        (
            KeySpec("angular_velocity", "(3, N)", "float", "rad/s"),
            KeySpec("linear_acceleration", "(3, N)", "float", "g"),
            KeySpec("time_stamps", "(N,)", "float64", "s"),
        ),
        (10.0, 2000.0),
    ),
    "scans": StreamSpec(
        "scans",
        "Hokuyo{nn}.npz",
        "Hokuyo LiDAR scans",
        (
            KeySpec("angle_min", "(1, 1)", "float", "-2.356194490192345 rad"),
            KeySpec("angle_max", "(1, 1)", "float", "2.356194490192345 rad"),
            KeySpec("angle_increment", "(1, 1)", "float", "0.00436332 rad"),
            KeySpec("range_min", "(1, 1)", "float", "0.1 m"),
            KeySpec("range_max", "(1, 1)", "float", "30 m"),
            KeySpec("ranges", "(1081, N)", "float", "m"),
            KeySpec("time_stamps", "(N,)", "float64", "s"),
        ),
        (2.0, 200.0),
    ),
    "kinect": StreamSpec(
        "kinect",
        "Kinect{nn}.npz",
        "Kinect frame timestamps",
        (
            KeySpec("disparity_time_stamps", "(D,)", "float64", "s"),
            KeySpec("rgb_time_stamps", "(R,)", "float64", "s"),
        ),
        (1.0, 100.0),
    ),
}
"""The file of every stream (``docs/data-formats.md`` §1.1)."""


def stream_file(folder: Path, number: int | str, stream: str) -> Path:
    """Path of the file holding ``stream`` (one of :data:`STREAMS`) of dataset ``number``."""
    return Path(folder) / SPECS[stream].file_name(_number(number))


def dataset_numbers(folder: Path) -> list[str]:
    """The dataset numbers ``NN`` whose files (``EncodersNN.npz``, ``ImuNN.npz``, ``HokuyoNN.npz``,
    ``KinectNN.npz``) are in ``folder``, sorted; empty when there are none (or no such folder)."""
    patterns = [
        re.compile(re.escape(prefix) + "(.+)" + re.escape(suffix) + r"\Z")
        for prefix, _, suffix in (spec.pattern.partition("{nn}") for spec in SPECS.values())
    ]
    try:
        names = [entry.name for entry in os.scandir(folder)]
    except OSError:
        return []
    return sorted({m.group(1) for name in names for p in patterns if (m := p.match(name))})


def rgbd_dirs(folder: Path, number: int | str) -> tuple[Path, Path]:
    """The RGB and disparity image folders of dataset ``number``."""
    nn = _number(number)
    base = Path(folder) / "dataRGBD"
    return base / f"RGB{nn}", base / f"Disparity{nn}"


def rgbd_patterns(number: int | str) -> tuple[str, str]:
    """Names of the RGB and disparity images of dataset ``number``, with ``{}`` for the frame
    index (counted from 1)."""
    nn = _number(number)
    return f"rgb{nn}_{{}}.png", f"disparity{nn}_{{}}.png"


def load_ece276a(
    folder: Path,
    number: int | str,
    *,
    need: Collection[str] = DEFAULT_NEED,
    name: str | None = None,
    lidar: LidarConfig | None = None,
    memory_share: float = DEFAULT_MEMORY_SHARE,
) -> Log:
    """Load ECE276A dataset ``number`` from ``folder`` into a :class:`Log`.

    Every stream whose file exists is loaded and validated; a stream named in ``need`` whose file
    is missing raises one :class:`DataError` that lists each missing file, its expected keys and
    where to put it. ``lidar`` supplies the laser mounting offset and may override the range limits
    stored in the Hokuyo file (``no_return`` defaults to ``range_max``). ``Log.meta`` records the
    dataset number, non-monotonic timestamp counts of the encoder and IMU streams, how long the
    IMU stops before the encoders, and whether the RGB-D image folders are there
    (``meta["rgbd_images"]``: ``"present"`` or ``"missing: <dirs>"``). An array larger than
    ``memory_share`` of the machine's memory is refused before it is read (:func:`read_npz`).
    """
    folder = Path(folder)
    nn = _number(number)
    unknown = sorted(set(need) - set(STREAMS))
    if unknown:
        raise UsageError(
            f"unknown ECE276A stream(s) {', '.join(unknown)}; expected some of {', '.join(STREAMS)}"
        )
    check_readable_dir(folder, "ECE276A data folder")  # absent: every file is then missing
    lidar = lidar or LidarConfig()
    paths = {s: folder / SPECS[s].file_name(nn) for s in STREAMS}
    exists = {s: is_present(p) for s, p in paths.items()}
    missing = [s for s in STREAMS if s in need and not exists[s]]
    if missing:
        raise DataError(_missing_message(name or f"dataset{nn}", folder, nn, missing))

    meta: dict[str, Any] = {"dataset_number": nn}
    encoders = imu = scans = rgbd = None
    if exists["encoders"]:
        encoders = _load_encoders(paths["encoders"], meta, memory_share)
    if exists["imu"]:
        imu = _load_imu(paths["imu"], meta, memory_share)
    if exists["scans"]:
        scans = _load_scans(paths["scans"], lidar, memory_share)
    if exists["kinect"]:
        rgbd = _load_kinect(paths["kinect"], folder, nn, meta, memory_share)
    if encoders is not None and imu is not None:
        meta["imu_ends_early_s"] = round(float(encoders.time[-1] - imu.time[-1]), 6)
    return Log(
        name=name or f"dataset{nn}",
        kind="ece276a",
        source=folder,
        encoders=encoders,
        imu=imu,
        scans=scans,
        rgbd=rgbd,
        meta=meta,
    )


# --- files and messages ---------------------------------------------------------------------


def _number(number: int | str) -> str:
    text = str(number).strip()
    if not text or any(c in text for c in "/\\{}") or text in (".", ".."):
        raise UsageError(f"ECE276A dataset number {number!r}: expected e.g. 20 or '20'")
    return text


def _missing_message(label: str, folder: Path, nn: str, missing: list[str]) -> str:
    files = [SPECS[s].file_name(nn) for s in missing]
    details = "; ".join(
        f"{SPECS[s].file_name(nn)} holds {SPECS[s].what}: {SPECS[s].describe_keys()}"
        for s in missing
    )
    where = ", ".join(str(folder / f) for f in files)
    inside = " and ".join(f"{folder.name}/{f}" for f in files)
    return f"{label}: missing {where} ({details}). " + put_files_hint(inside, len(files))


_READ_ERRORS = (OSError, EOFError, ValueError, zipfile.BadZipFile, zlib.error, KeyError)


def read_npz(
    path: Path, keys: Collection[str], memory_share: float = DEFAULT_MEMORY_SHARE
) -> dict[str, NDArray[Any]]:
    """Read ``keys`` from the npz archive ``path`` without unpickling anything.

    Raises :class:`DataError` naming the file when it is empty, truncated, not an npz archive,
    holds pickled (object) arrays, or lacks one of ``keys`` (the message lists the keys found).
    Each key's ``.npy`` header is read first (:func:`_check_member`): a corrupt header, or a
    shape whose size the archive member cannot hold, is an error before anything is allocated,
    and an array larger than ``memory_share`` of the machine's memory is refused.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
    except PermissionError:
        raise DataError(f"{path}: cannot read (permission denied)") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror})") from None
    if size == 0:
        raise DataError(f"{path}: file is empty; expected an npz archive")
    try:
        with open(path, "rb") as fh:
            head = fh.read(6)
    except PermissionError:
        raise DataError(f"{path}: cannot read (permission denied)") from None
    if head[:1] == b"\x80":
        raise DataError(f"{path}: contains pickled objects; refusing to load")
    if not head.startswith((b"PK", b"\x93NUMPY")):
        raise DataError(
            f"{path}: not a readable npz archive (it does not start like a zip or .npy file)"
        )
    try:
        archive = np.load(path, allow_pickle=False)
    except PermissionError:
        raise DataError(f"{path}: cannot read (permission denied)") from None
    except ValueError as exc:
        if "pickle" in str(exc).lower():
            raise DataError(f"{path}: contains pickled objects; refusing to load") from None
        raise DataError(f"{path}: not a readable npz archive ({exc})") from None
    except _READ_ERRORS as exc:
        raise DataError(f"{path}: not a readable npz archive ({_reason(exc)})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise DataError(f"{path}: expected an npz archive (np.savez), found a single .npy array")
    with archive:
        found = list(archive.files)
        absent = [k for k in keys if k not in found]
        if absent:
            raise DataError(
                f"{path}: missing key {', '.join(repr(k) for k in absent)}; "
                f"found keys: {', '.join(repr(k) for k in found) or 'none'}"
            )
        out = {}
        for key in keys:
            _check_member(path, archive.zip, key, memory_share)
            try:
                out[key] = archive[key]
            except ValueError as exc:
                if "pickle" in str(exc).lower():
                    raise DataError(
                        f"{path}: key {key!r} contains pickled objects; refusing to load"
                    ) from None
                raise DataError(f"{path}: key {key!r} is unreadable ({exc})") from None
            except _READ_ERRORS as exc:
                raise DataError(
                    f"{path}: key {key!r} is unreadable, the file looks truncated or corrupt "
                    f"({_reason(exc)})"
                ) from None
    return out


def _check_member(
    path: Path, archive: zipfile.ZipFile | None, key: str, memory_share: float
) -> None:
    """Read the ``.npy`` header of ``key`` and check its size before the array is read.

    The header's shape × item size must fit in the member's uncompressed size (a header claiming
    10¹¹ values in a small file is corrupt, not a reason to allocate 745 GiB) and in the memory
    budget (:mod:`slam.budget`).
    """
    if archive is None:
        return
    name = f"{key}.npy"
    try:
        info = archive.getinfo(name)
        with archive.open(name) as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                raise DataError(
                    f"{path}: key {key!r} has .npy format version {version[0]}.{version[1]}; "
                    "expected 1.0 or 2.0 (what numpy writes for numeric arrays)"
                )
            offset = fh.tell()
    except KeyError:
        return  # not a member under that name: numpy's own lookup reports it
    except DataError:
        raise
    except (ValueError, SyntaxError, TypeError):
        raise DataError(
            f"{path}: key {key!r} has a corrupt .npy header (not the shape/dtype dictionary "
            "numpy writes); the file is damaged"
        ) from None
    except _READ_ERRORS as exc:
        raise DataError(
            f"{path}: key {key!r} is unreadable, the file looks truncated or corrupt "
            f"({_reason(exc)})"
        ) from None
    if dtype.hasobject:
        raise DataError(f"{path}: key {key!r} contains pickled objects; refusing to load")
    count = math.prod(int(n) for n in shape)
    nbytes = count * dtype.itemsize
    available = info.file_size - offset
    if nbytes > available:
        raise DataError(
            f"{path}: key {key!r}: its header claims shape {tuple(shape)} of {dtype} "
            f"({format_bytes(nbytes)}), but the archive holds {format_bytes(max(available, 0))} "
            "for it; the file is truncated or corrupt"
        )
    check_memory(
        2 * nbytes,  # the array and the loader's converted copy
        f"{path}: key {key!r} (shape {tuple(shape)} of {dtype})",
        "use a smaller file",
        share=memory_share,
        setting="checks.max_memory_share",
    )


def _reason(exc: BaseException) -> str:
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# --- array checks ---------------------------------------------------------------------------


def _numeric(path: Path, key: str, array: NDArray[Any], expected: str) -> None:
    if array.dtype.kind not in "iuf":
        raise DataError(
            f"{path}: key {key!r} must be numeric ({expected}), found dtype {array.dtype}"
        )


def _times(path: Path, key: str, array: NDArray[Any], spec: StreamSpec) -> NDArray[np.float64]:
    """Validate a timestamp vector: numeric, 1-D, non-empty, finite, plausible rate."""
    _numeric(path, key, array, "float64 seconds")
    if array.ndim == 2 and 1 in array.shape:
        array = array.reshape(-1)  # (1, N) or (N, 1) is the same vector
    if array.ndim != 1:
        raise DataError(f"{path}: key {key!r} must have shape (N,), found {array.shape}")
    if array.shape[0] == 0:
        raise DataError(f"{path}: key {key!r} is empty; expected at least one reading")
    time = array.astype(np.float64)
    bad = ~np.isfinite(time)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise DataError(
            f"{path}: key {key!r} has {int(bad.sum())} non-finite timestamp(s), "
            f"the first at index {first}"
        )
    dt = np.diff(time)
    positive = dt[dt > 0]
    if positive.size:
        rate = 1.0 / float(np.median(positive))
        low, high = spec.rate_hz
        if not low <= rate <= high:
            raise DataError(
                f"{path}: key {key!r} implies {rate:.4g} Hz readings, expected {low:g}-{high:g} Hz "
                f"for {spec.what}; are the timestamps in seconds?"
            )
    return time


def _columns(path: Path, key: str, array: NDArray[Any], rows: int, n: int) -> None:
    if array.ndim != 2 or array.shape[0] != rows or array.shape[1] != n:
        raise DataError(
            f"{path}: key {key!r} must have shape ({rows}, N) with N = {n} "
            f"(the length of 'time_stamps'), found {array.shape}"
        )


def _scalar(path: Path, key: str, array: NDArray[Any]) -> float:
    _numeric(path, key, array, "a float")
    if array.size != 1:
        raise DataError(
            f"{path}: key {key!r} must be a single number (shape (1, 1) or scalar), "
            f"found shape {array.shape}"
        )
    value = float(array.reshape(-1)[0])
    if not np.isfinite(value):
        raise DataError(f"{path}: key {key!r} must be finite, found {value}")
    return value


def _load_encoders(path: Path, meta: dict[str, Any], memory_share: float) -> EncoderStream:
    spec = SPECS["encoders"]
    raw = read_npz(path, [k.key for k in spec.keys], memory_share)
    time = _times(path, "time_stamps", raw["time_stamps"], spec)
    counts = raw["counts"]
    if counts.dtype.kind not in "iu":
        raise DataError(
            f"{path}: key 'counts' must be integer encoder ticks (int16), found dtype {counts.dtype}"
        )
    _columns(path, "counts", counts, 4, time.shape[0])
    info = np.iinfo(np.int16)
    if counts.size and (counts.min() < info.min or counts.max() > info.max):
        raise DataError(
            f"{path}: key 'counts' holds values outside int16 "
            f"({int(counts.min())}..{int(counts.max())}); expected ticks per interval"
        )
    meta["encoders_non_monotonic"] = count_non_monotonic(time)
    return EncoderStream(time=time, counts=np.ascontiguousarray(counts, dtype=np.int16))


def _load_imu(path: Path, meta: dict[str, Any], memory_share: float) -> ImuStream:
    spec = SPECS["imu"]
    raw = read_npz(path, [k.key for k in spec.keys], memory_share)
    time = _times(path, "time_stamps", raw["time_stamps"], spec)
    arrays = {}
    for key in ("angular_velocity", "linear_acceleration"):
        array = raw[key]
        _numeric(path, key, array, "float")
        _columns(path, key, array, 3, time.shape[0])
        values = np.ascontiguousarray(array, dtype=np.float64)
        if not np.isfinite(values).all():
            bad = int(np.count_nonzero(~np.isfinite(values)))
            raise DataError(f"{path}: key {key!r} has {bad} non-finite value(s)")
        arrays[key] = values
    meta["imu_non_monotonic"] = count_non_monotonic(time)
    return ImuStream(
        time=time,
        angular_velocity=arrays["angular_velocity"],
        linear_acceleration=arrays["linear_acceleration"],
    )


def _load_scans(path: Path, lidar: LidarConfig, memory_share: float) -> ScanStream:
    spec = SPECS["scans"]
    raw = read_npz(path, [k.key for k in spec.keys], memory_share)
    time = _times(path, "time_stamps", raw["time_stamps"], spec)
    n = time.shape[0]
    ranges_in = raw["ranges"]
    _numeric(path, "ranges", ranges_in, "float metres")
    if ranges_in.ndim != 2 or ranges_in.shape[1] != n:
        raise DataError(
            f"{path}: key 'ranges' must have shape (beams, N) = (1081, N) with N = {n} "
            f"(the length of 'time_stamps'), found {ranges_in.shape}"
        )
    beams = ranges_in.shape[0]
    angle_min = _scalar(path, "angle_min", raw["angle_min"])
    angle_max = _scalar(path, "angle_max", raw["angle_max"])
    increment = _scalar(path, "angle_increment", raw["angle_increment"])
    if increment <= 0:
        raise DataError(f"{path}: key 'angle_increment' must be positive, found {increment}")
    if angle_max - angle_min > 2 * np.pi + ANGLE_TOLERANCE:
        raise DataError(
            f"{path}: keys 'angle_min', 'angle_max': expected radians spanning at most 2π, found "
            f"{angle_min:g} .. {angle_max:g} (degrees? the Hokuyo's are -2.356194 .. 2.356194 rad)"
        )
    last = angle_min + (beams - 1) * increment
    if abs(last - angle_max) > ANGLE_TOLERANCE:
        raise DataError(
            f"{path}: beam geometry does not match the ranges: angle_min + ({beams} - 1) * "
            f"angle_increment = {last:.6f} rad, but angle_max = {angle_max:.6f} rad "
            f"(expected {round((angle_max - angle_min) / increment) + 1} beams, found {beams})"
        )
    file_min = _scalar(path, "range_min", raw["range_min"])
    file_max = _scalar(path, "range_max", raw["range_max"])
    range_min = file_min if lidar.range_min is None else float(lidar.range_min)
    range_max = file_max if lidar.range_max is None else float(lidar.range_max)
    if not 0 <= range_min < range_max:
        raise DataError(
            f"{path}: range limits must satisfy 0 <= range_min < range_max, found "
            f"range_min = {range_min}, range_max = {range_max}"
        )
    if file_max > MAX_RANGE_M:
        raise DataError(
            f"{path}: key 'range_max': expected metres (at most {MAX_RANGE_M:g}), found "
            f"{file_max:g} (millimetres? the Hokuyo's is 30 m)"
        )
    _check_range_unit(path, ranges_in, file_max)
    no_return = range_max if lidar.no_return is None else float(lidar.no_return)

    ranges, invalid_beams = valid_ranges(ranges_in.T, range_min)  # (N, beams), read in blocks
    angles = angle_min + increment * np.arange(beams, dtype=np.float64)
    return ScanStream(
        time=time,
        ranges=ranges,
        angles=angles,
        range_min=range_min,
        range_max=range_max,
        no_return=no_return,
        laser_offset=np.array([lidar.x, lidar.y, lidar.yaw], dtype=np.float64),
        invalid_beams=invalid_beams,
    )


RANGE_UNIT_FACTOR = 10.0
"""A Hokuyo file whose median valid reading is this many times its ``range_max`` holds
another unit than metres (millimetres: 1000 times)."""


def _check_range_unit(path: Path, ranges: NDArray, range_max: float) -> None:
    """Refuse ranges whose median positive finite reading is :data:`RANGE_UNIT_FACTOR` times
    ``range_max`` or more: millimetres (or centimetres) for metres, which would otherwise load as
    scans of "no return" readings and a run of an empty map."""
    sample = np.asarray(ranges[:, :: max(1, ranges.shape[1] // 200)], dtype=np.float64)
    readings = sample[np.isfinite(sample) & (sample > 0)]
    if readings.size and float(np.median(readings)) >= RANGE_UNIT_FACTOR * range_max:
        raise DataError(
            f"{path}: key 'ranges': the median reading is {float(np.median(readings)):g}, "
            f"{float(np.median(readings)) / range_max:.0f} times range_max = {range_max:g} m: "
            "expected metres (millimetres? divide by 1000)"
        )


def _load_kinect(
    path: Path, folder: Path, nn: str, meta: dict[str, Any], memory_share: float
) -> RgbdIndex:
    spec = SPECS["kinect"]
    raw = read_npz(path, [k.key for k in spec.keys], memory_share)
    disparity_time = _times(path, "disparity_time_stamps", raw["disparity_time_stamps"], spec)
    rgb_time = _times(path, "rgb_time_stamps", raw["rgb_time_stamps"], spec)
    rgb_dir, disparity_dir = rgbd_dirs(folder, nn)
    rgb_pattern, disparity_pattern = rgbd_patterns(nn)
    meta["rgb_non_monotonic"] = count_non_monotonic(rgb_time)
    meta["disparity_non_monotonic"] = count_non_monotonic(disparity_time)
    meta["rgbd_images"] = _image_status(
        [
            (rgb_dir, rgb_pattern, rgb_time.shape[0]),
            (disparity_dir, disparity_pattern, disparity_time.shape[0]),
        ]
    )
    return RgbdIndex(
        rgb_time=rgb_time,
        disparity_time=disparity_time,
        rgb_dir=rgb_dir,
        disparity_dir=disparity_dir,
        rgb_pattern=rgb_pattern,
        disparity_pattern=disparity_pattern,
    )


def _image_status(dirs: list[tuple[Path, str, int]]) -> str:
    """``"present"``, else which image folders are missing, unreadable or hold too few frames
    (``dirs``: folder, image name pattern with ``{}`` for the index, expected frame count).

    The text starts with ``"missing: "`` when a folder is absent, so later stages (texture mapping)
    can skip with a warning that names the folders.
    """
    missing, other = [], []
    for directory, pattern, expected in dirs:
        prefix, suffix = pattern.split("{}")
        try:
            if not directory.is_dir():
                missing.append(f"{directory}/")
                continue
            found = sum(
                1
                for entry in os.scandir(directory)
                if entry.name.startswith(prefix) and entry.name.endswith(suffix)
            )
        except PermissionError:
            other.append(f"unreadable: {directory}/")
            continue
        if found < expected:
            other.append(f"incomplete: {directory}/ holds {found} of {expected} frames")
    parts = ([f"missing: {', '.join(missing)}"] if missing else []) + other
    return "; ".join(parts) if parts else "present"
