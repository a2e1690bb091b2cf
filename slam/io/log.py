"""The ``Log``: the one in-memory form of a robot log that every loader produces.

A ``Log`` holds time-stamped arrays per sensor stream. Streams a log does not have are ``None``.
Arrays are numpy end to end: float64 for times and poses, float32 for ranges. Loaders validate
shapes and dtypes before building these objects, so the pipeline can trust them.

Conventions
-----------
* Times are seconds (Unix time for the ECE276A logs, the logger's clock for CARMEN logs).
* ``ScanStream.ranges`` has shape ``(num_scans, num_beams)``; invalid beams (NaN, inf, negative,
  below ``range_min``, beyond :data:`MAX_VALID_RANGE_M`) are stored as NaN and counted in
  ``ScanStream.invalid_beams``. Readings at or
  beyond ``no_return`` mean "no return": they may clear free space but never mark an obstacle.
* Scans are kept in file order (CARMEN odometry follows file order, not timestamp order);
  ``ScanStream.non_monotonic`` counts the scans whose timestamp is below the previous one.
* Poses are ``(x, y, theta)`` rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

MAX_VALID_RANGE_M = 1000.0
"""Readings beyond this (m) are invalid beams: no 2D lidar measures a kilometre, so such values
come from corrupt files (and 1e308 does not even fit the float32 ranges are stored in)."""


@dataclass(frozen=True)
class EncoderStream:
    """Wheel encoder ticks per interval, rows FR, FL, RR, RL (ECE276A robot)."""

    time: F64
    """``(N,)`` reading times (s)."""
    counts: NDArray[np.int16]
    """``(4, N)`` ticks accumulated since the previous reading."""

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class ImuStream:
    """Inertial measurements."""

    time: F64
    """``(N,)`` sample times (s)."""
    angular_velocity: F64
    """``(3, N)`` body rates (rad/s); row 2 is the yaw rate."""
    linear_acceleration: F64
    """``(3, N)`` accelerations (g)."""

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class ScanStream:
    """2D laser scans with their beam geometry."""

    time: F64
    """``(N,)`` scan times in file order (s); a scan's label for relations."""
    ranges: F32
    """``(N, B)`` ranges (m); NaN marks invalid beams."""
    angles: F64
    """Beam angles in the laser frame (rad, counter-clockwise, 0 = forward): ``(B,)`` when every
    scan has the same geometry, ``(N, B)`` when a log mixes beam counts (rows NaN-padded, like
    ``ranges``)."""
    range_min: float
    """Shortest valid range (m)."""
    range_max: float
    """Longest range that counts as an obstacle hit (m)."""
    no_return: float
    """Readings at or beyond this mean "no return" (m)."""
    laser_offset: F64 = field(default_factory=lambda: np.zeros(3))
    """``(3,)`` laser pose in the robot frame."""
    odometry: F64 | None = None
    """``(N, 3)`` robot odometry pose at each scan, when the log carries it (CARMEN)."""
    laser_pose: F64 | None = None
    """``(N, 3)`` laser pose in the odometry frame at each scan, when the log carries it."""
    invalid_beams: int = 0
    """How many readings were NaN/inf/negative, below ``range_min`` or beyond
    :data:`MAX_VALID_RANGE_M` in the file."""
    lines: NDArray[np.int64] | None = None
    """``(N,)`` 1-based line number of each scan in its file, when the log is text (CARMEN)."""

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def non_monotonic(self) -> int:
        """How many scans have a timestamp smaller than the previous scan's."""
        return count_non_monotonic(self.time)

    @property
    def num_beams(self) -> int:
        """Beams per scan (the widest scan when beam counts vary)."""
        return int(self.ranges.shape[1])

    def scan_angles(self, i: int) -> F64:
        """Beam angles of scan ``i``."""
        return self.angles if self.angles.ndim == 1 else self.angles[i]

    def readings(self) -> NDArray[np.int64]:
        """``(N,)`` beams of each scan (the width of its row of ``angles``)."""
        if self.angles.ndim == 1:
            return np.full(len(self), self.angles.shape[0], dtype=np.int64)
        return np.count_nonzero(np.isfinite(self.angles), axis=1).astype(np.int64)


def mixed_widths(readings: NDArray[np.int64]) -> int | None:
    """``n − 1`` when the scans of ``readings`` (beams per scan) are of two widths, ``n`` and
    ``n − 1`` (fr-clinic's 181 and 180), else ``None``."""
    counts = np.unique(readings)
    if counts.size != 2 or counts[1] != counts[0] + 1 or counts[0] < 2:
        return None
    return int(counts[0])


@dataclass(frozen=True)
class OdometryStream:
    """Odometry messages (CARMEN ``ODOM``): poses in the odometry frame."""

    time: F64
    """``(N,)`` message times (s)."""
    poses: F64
    """``(N, 3)`` odometry poses."""
    velocities: F64
    """``(N, 2)`` translational (m/s) and rotational (rad/s) velocity."""
    lines: NDArray[np.int64] | None = None
    """``(N,)`` 1-based line of each message in its file (``None``: not from a text log)."""

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class RgbdIndex:
    """Index of the RGB-D frames of a log; images are read only when asked for.

    Frame ``k`` (0-based) of the RGB stream is the file ``rgb_dir / rgb_pattern.format(k + 1)``
    taken at ``rgb_time[k]``; likewise for disparity.
    """

    rgb_time: F64
    """``(R,)`` RGB frame times (s)."""
    disparity_time: F64
    """``(D,)`` disparity frame times (s)."""
    rgb_dir: Path
    """Folder of the RGB PNG files."""
    disparity_dir: Path
    """Folder of the disparity PNG files."""
    rgb_pattern: str
    """File name of RGB frame k (1-based) as a ``str.format`` pattern, e.g. ``rgb20_{}.png``."""
    disparity_pattern: str
    """File name of disparity frame k (1-based), e.g. ``disparity20_{}.png``."""

    def rgb_path(self, k: int) -> Path:
        """Path of RGB frame ``k`` (0-based)."""
        return self.rgb_dir / self.rgb_pattern.format(k + 1)

    def disparity_path(self, k: int) -> Path:
        """Path of disparity frame ``k`` (0-based)."""
        return self.disparity_dir / self.disparity_pattern.format(k + 1)

    def load_rgb(self, k: int) -> NDArray[np.uint8]:
        """RGB frame ``k`` as ``(480, 640, 3)`` uint8 in RGB order (C-contiguous, read by
        :func:`slam.io.png.read_rgb`); :class:`DataError` if unreadable."""
        from slam.io.png import read_rgb

        path = self.rgb_path(k)
        image = read_rgb(path)
        if image is None:
            raise DataError(
                f"{path}: missing, not a readable PNG or a grey one (RGB frame {k + 1})"
            )
        return image

    def load_disparity(self, k: int) -> NDArray[np.uint16]:
        """Disparity frame ``k`` as ``(480, 640)`` uint16; :class:`DataError` if unreadable."""
        from slam.io.png import read_unchanged

        path = self.disparity_path(k)
        image = read_unchanged(path)
        if image is None:
            raise DataError(f"{path}: missing or not a readable PNG (disparity frame {k + 1})")
        if image.dtype != np.uint16 or image.ndim != 2:
            raise DataError(
                f"{path}: expected a single-channel uint16 disparity PNG, "
                f"found {image.dtype} with shape {image.shape}"
            )
        return image


@dataclass(frozen=True)
class Log:
    """One robot log in memory: whichever streams the source has."""

    name: str
    """Dataset name (registry name or file stem)."""
    kind: str
    """Loader that produced it: ``"ece276a"`` or ``"carmen"``."""
    source: Path | None = None
    """File or folder it was read from."""
    encoders: EncoderStream | None = None
    imu: ImuStream | None = None
    scans: ScanStream | None = None
    odometry: OdometryStream | None = None
    rgbd: RgbdIndex | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    """Loader notes (e.g. CARMEN comment lines, skipped message types)."""

    def streams(self) -> dict[str, Any]:
        """The streams present, by name."""
        names = ("encoders", "imu", "scans", "odometry", "rgbd")
        return {n: getattr(self, n) for n in names if getattr(self, n) is not None}

    def summary(self) -> dict[str, Any]:
        """Counts, durations, rates and gaps of every stream (what ``slam data verify`` prints)."""
        out: dict[str, Any] = {"name": self.name, "kind": self.kind}
        for name, stream in self.streams().items():
            if isinstance(stream, RgbdIndex):
                out["rgb"] = _time_summary(stream.rgb_time)
                out["disparity"] = _time_summary(stream.disparity_time)
                continue
            info = _time_summary(stream.time)
            if isinstance(stream, ScanStream):
                info["beams"] = stream.num_beams
                widths, scans = np.unique(stream.readings(), return_counts=True)
                if widths.size > 1:  # beam counts that change within the log
                    info["beam_counts"] = {
                        str(w): int(c) for w, c in zip(widths, scans, strict=True)
                    }
                info["invalid_beams"] = stream.invalid_beams
                info["no_return_beams"] = int(np.count_nonzero(stream.ranges >= stream.no_return))
                info["non_monotonic"] = stream.non_monotonic
            out[name] = info
        out.update({k: v for k, v in self.meta.items() if isinstance(v, int | float | str)})
        return out


def beams_text(info: dict[str, Any]) -> str:
    """``"180 beams"``, or ``"beams 180 (7372 scans), 90 (3 scans)"`` where they vary, of a
    stream summary (:meth:`Log.summary`)."""
    counts = info.get("beam_counts")
    if not counts:
        return f"{info['beams']} beams"
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], -int(kv[0])))
    return "beams " + ", ".join(f"{w} ({c} scan{'s' if c > 1 else ''})" for w, c in ranked)


def valid_ranges(ranges: NDArray[Any], range_min: float) -> tuple[F32, int]:
    """``ranges`` as float32 with every invalid reading (NaN, inf, negative, below ``range_min``,
    beyond :data:`MAX_VALID_RANGE_M`) set to NaN, and how many there were.

    Readings are judged in their own precision before the cast, so an absurd value (1e308)
    becomes NaN instead of overflowing (and warning) on the way to float32.
    """
    ranges = np.atleast_1d(np.asarray(ranges))
    out = np.empty(ranges.shape, dtype=np.float32)
    count = 0
    # a block of rows at a time (a transposed view is read as it is): the masks and the
    # full-precision intermediate of a block, not of a whole log
    for first in range(0, ranges.shape[0], VALID_ROWS):
        block = ranges[first : first + VALID_ROWS]
        with np.errstate(invalid="ignore"):
            invalid = ~np.isfinite(block) | (block < range_min) | (block < 0.0)
            invalid |= block > MAX_VALID_RANGE_M
        out[first : first + VALID_ROWS] = np.where(invalid, np.nan, block)
        count += int(np.count_nonzero(invalid))
    return out, count


VALID_ROWS = 4096
"""Rows (scans) :func:`valid_ranges` judges at a time."""


def laser_offset_meta(source: str, offset: F64) -> dict[str, str | float]:
    """The ``meta`` entries of a log's laser mounting: where the offset came from
    (``laser_offset_source``) and the ``(3,)`` offset itself (``laser_offset_x``, ``_y``,
    ``_yaw``), as CARMEN and bag loaders record them."""
    x, y, yaw = (float(v) for v in offset)
    return {
        "laser_offset_source": source,
        "laser_offset_x": x,
        "laser_offset_y": y,
        "laser_offset_yaw": yaw,
    }


def count_non_monotonic(time: F64) -> int:
    """How many readings of ``time`` have a timestamp smaller than the previous one's."""
    return int(np.count_nonzero(np.diff(time) < 0))


def _time_summary(time: F64) -> dict[str, Any]:
    n = int(time.shape[0])
    if n == 0:
        return {"count": 0}
    dt = np.diff(time)
    duration = float(time.max() - time.min())
    positive = dt[dt > 0]
    return {
        "count": n,
        "start": float(time[0]),
        "duration_s": duration,
        "rate_hz": float((n - 1) / duration) if duration > 0 else 0.0,
        "median_dt_s": float(np.median(positive)) if positive.size else 0.0,
        "max_gap_s": float(positive.max()) if positive.size else 0.0,
        "backward_steps": int(np.count_nonzero(dt < 0)),
    }
