"""CARMEN log loader: ``.clf`` / ``.log`` text, optionally gzip-compressed, into a :class:`Log`.

This module owns the CARMEN text format (``docs/data-formats.md`` §2, "CARMEN logs"): which
messages become which stream, the beam geometry of ``FLASER`` lines, the "no return" semantics of
their ranges and the errors a malformed file produces.

Messages
--------
* ``# ...``: comment lines, kept in ``log.meta["comments"]`` and counted in
  ``log.meta["comment_lines"]``.
* ``ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp`` → :attr:`Log.odometry`.
* ``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ipc_timestamp hostname
  logger_timestamp`` → :attr:`Log.scans`. The line carries no geometry: its ``n`` beams span
  ``fov_deg`` (default 180°) centred on 0, step ``fov / (n − 1)``, or with ``beam_step_deg``
  set are centred on 0 that far apart.
* ``ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode n r_1..r_n
  n_remissions rem_1.. laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
  forward_safety_dist side_safety_dist turn_axis ipc_timestamp hostname logger_timestamp``
  → :attr:`Log.scans`, beam ``k`` at ``start_angle + k · angular_res``.
* ``RAWLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode n r_1..r_n
  n_remissions rem_1.. ipc_timestamp hostname logger_timestamp`` → :attr:`Log.scans`, read only
  when the log has no FLASER or ROBOTLASER1 line (a logger that writes both writes the same
  scans twice): beam ``k`` at ``start_angle + k · angular_res``; the line carries no pose, so
  the scans' odometry is the ``ODOM`` stream interpolated at their times (a log of raw scans
  without ``ODOM`` lines has none: ``slam run`` then matches the scans for it,
  :mod:`slam.laser_odometry`) and the laser sits on the odometry point (the log states no mount;
  with ``lidar.use_log_laser_pose = false``, ``lidar.x``, ``lidar.y``, ``lidar.yaw``;
  ``slam data calibrate`` measures it).
* Any other message type (``PARAM``, ``SYNC``, ``RAWLASER2``, ...) is counted and skipped:
  ``log.meta["skipped"]`` maps type to count, ``log.meta["skipped_lines"]`` is the total.

Scans stay in FILE order: the odometry written in the scan lines follows file order, not
timestamp order (intel: 631 scans have a timestamp below their predecessor's). A scan's time is
its ``ipc_timestamp``, the timestamp the Kümmerle relations files use: on intel, aces, fr079 and
fr-clinic both timestamps are equal and every relation ``t1``/``t2`` equals a scan's timestamp
exactly; on mit-csail the ``logger_timestamp`` counts from the start of logging (0.09 s, 0.27 s,
...) while every relation ``t1``/``t2`` matches an ``ipc_timestamp`` within 5e-6 s.

Parsing is vectorised: the text is split into lines once, each line is classified by its first
token, scan lines are grouped by their layout (beam count) and each group's numeric fields are
converted by one :func:`numpy.loadtxt` call per :data:`PARSE_ROWS` lines into one table. Only
when a call fails does a bisection over the group find the first bad line so the error can name
it. Each step lets go of what the next no longer needs (the text once split, a group's lines once
its table is read), so a load holds about two copies of the log's text at its peak.
"""

from __future__ import annotations

import gzip
import re
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.budget import DEFAULT_MEMORY_SHARE, check_memory
from slam.config import MAX_RANGE_M, LidarConfig
from slam.errors import ConfigError, DataError
from slam.geometry import relative, wrap_angle
from slam.io.log import Log, OdometryStream, ScanStream, laser_offset_meta, valid_ranges
from slam.io.text import decode_utf8, read_input

F64 = NDArray[np.float64]

DEFAULT_FOV_DEG = 180.0
"""FLASER field of view when the config gives none: every log here spans −90°..+90°."""
DEFAULT_NO_RETURN = 80.0
"""Readings at or beyond this mean "no return" when the config gives none: SICK scanners write
their maximum codes (81.83 m, 81.91 m) for beams without an echo."""
NO_RETURN_BAND_M = 0.5
"""The no-echo code is looked for this close below the log's longest reading (m)."""
NO_RETURN_MIN_SHARE = 1e-3
"""A 1 cm bin of that band holds a no-echo code when it has at least this share of the readings
(and :data:`NO_RETURN_MIN_COUNT` of them): genuine readings that far out are rare and spread."""
NO_RETURN_MIN_COUNT = 100
"""... and at least this many readings (see :data:`NO_RETURN_MIN_SHARE`)."""
DEFAULT_RANGE_MIN = 0.05
"""Shortest valid reading when the config gives none (m): below every genuine reading of the
benchmark logs (the shortest is 0.12 m, on fr079), so zero readings count as invalid beams."""

MAX_BEAMS = 8192
"""Most readings (and remissions) one scan line may declare: 16 times the densest 2D lidar of the
benchmark logs (361 beams), and 8 times a 0.25° / 360° scanner. A larger count is a corrupt line,
refused before every scan is padded to it."""

ASSEMBLY_BYTES_PER_READING = 16
"""Memory one padded reading costs while the scans are assembled: its float32 value, a layout
group's judged copy, and a float64 angle where the scans' angles differ (the parsed tables, sized
by the file, are already held)."""

GZIP_MAGIC = b"\x1f\x8b"

_MESSAGE_TYPE = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")

_FLASER_TAIL = (
    "x",
    "y",
    "theta",
    "odom_x",
    "odom_y",
    "odom_theta",
    "ipc_timestamp",
    "hostname",
    "logger_timestamp",
)
_ODOM_FIELDS = (
    "ODOM",
    "x",
    "y",
    "theta",
    "tv",
    "rv",
    "accel",
    "ipc_timestamp",
    "hostname",
    "logger_timestamp",
)
_ROBOTLASER_HEAD = (
    "ROBOTLASER1",
    "laser_type",
    "start_angle",
    "fov",
    "angular_res",
    "max_range",
    "accuracy",
    "remission_mode",
    "num_readings",
)
_ROBOTLASER_TAIL = (
    "laser_x",
    "laser_y",
    "laser_theta",
    "robot_x",
    "robot_y",
    "robot_theta",
    "tv",
    "rv",
    "forward_safety_dist",
    "side_safety_dist",
    "turn_axis",
    "ipc_timestamp",
    "hostname",
    "logger_timestamp",
)


_RAWLASER_TAIL = ("ipc_timestamp", "hostname", "logger_timestamp")


@dataclass(frozen=True)
class _Lines:
    """Lines of one message layout: their text and 1-based line numbers in the file."""

    text: list[str]
    lineno: list[int]


@dataclass(frozen=True)
class _ScanGroup:
    """Scans of one layout, parsed: where they go in file order and their arrays."""

    order: NDArray[np.int64]
    """1-based line numbers (sorting them gives file order)."""
    ranges: F64
    angles: F64
    """``(n,)`` shared by the group or ``(L, n)`` per scan (ROBOTLASER1 and RAWLASER1 lines
    whose start or resolution change)."""
    laser_pose: F64 | None
    """``(L, 3)`` laser pose in the odometry frame (None: RAWLASER1 lines carry none)."""
    odometry: F64 | None
    """``(L, 3)`` robot odometry pose (None: RAWLASER1)."""
    time: F64
    max_range: F64 | None = None
    """ROBOTLASER1, RAWLASER1: the range limit each line declares."""


def load_carmen(
    path: Path,
    *,
    name: str | None = None,
    lidar: LidarConfig | None = None,
    memory_share: float = DEFAULT_MEMORY_SHARE,
) -> Log:
    """Read a CARMEN log (plain text or gzip, detected by its magic bytes) into a :class:`Log`.

    ``lidar`` supplies what FLASER lines do not carry: ``fov_deg`` (default 180) or
    ``beam_step_deg``,
    ``range_min`` (default :data:`DEFAULT_RANGE_MIN`), ``no_return`` (default: the declared
    ``max_range`` for ROBOTLASER1-only logs, else the no-echo code read from the range histogram,
    :func:`no_return_code`, else :data:`DEFAULT_NO_RETURN`) and ``range_max`` (default
    ``no_return``). The laser offset in the robot frame is the median of
    ``relative(odometry pose, laser pose)`` over the log when ``lidar.use_log_laser_pose`` is true
    (the default), else ``(lidar.x, lidar.y, lidar.yaw)``; it is reported in ``log.meta``.

    Raises :class:`DataError` naming the file (and the line number for a malformed line) when
    the file is missing, unreadable, truncated, malformed or holds no scan, or when a line
    declares more than :data:`MAX_BEAMS` readings; :class:`~slam.errors.UsageError` when the
    scans padded to the widest one would exceed ``memory_share`` of the machine's memory.
    """
    path = Path(path)
    lidar = lidar or LidarConfig()
    # The memory of a long log: the text, then its lines, then each group's table are let go as
    # soon as the next step holds what it needs (a 20-minute 1081-beam log: 2.2 GB → 0.8 GB).
    text = _read_text(path)
    lines = text.split("\n")
    del text
    comments, skipped, odom, flaser, robotlaser, rawlaser = _group_lines(path, lines)
    del lines
    flaser_scans = sum(len(g.lineno) for g in flaser.values())
    robotlaser_scans = sum(len(g.lineno) for g in robotlaser.values())
    raw_scans = sum(len(g.lineno) for g in rawlaser.values())
    odom_messages = len(odom.text)
    if flaser or robotlaser:
        if raw_scans:  # the same laser's scans again, without their poses
            skipped["RAWLASER1"] = raw_scans
        rawlaser = {}
    if not (flaser or robotlaser or rawlaser):
        raise DataError(
            f"{path}: no scans (expected FLASER, ROBOTLASER1 or RAWLASER1 lines; found "
            f"{odom_messages} ODOM, {len(comments)} comment and "
            f"{sum(skipped.values())} other lines)"
        )
    groups = [_parse_flaser(path, n, flaser.pop(n), lidar) for n in list(flaser)]
    groups += [_parse_robotlaser(path, *key, robotlaser.pop(key)) for key in list(robotlaser)]
    groups += [_parse_rawlaser(path, *key, rawlaser.pop(key)) for key in list(rawlaser)]
    scans, offset_source = _assemble_scans(path, groups, lidar, memory_share)
    del groups
    odometry = _parse_odom(path, odom) if odom.text else None

    meta: dict[str, Any] = {
        "comments": comments,
        "comment_lines": len(comments),
        "flaser_scans": flaser_scans,
        "robotlaser_scans": robotlaser_scans,
        "rawlaser_scans": raw_scans if not flaser_scans and not robotlaser_scans else 0,
        "odom_messages": odom_messages,
        "skipped": dict(sorted(skipped.items())),
        "skipped_lines": sum(skipped.values()),
        "skipped_types": ", ".join(f"{k}={v}" for k, v in sorted(skipped.items())) or "none",
        "scan_time": "ipc_timestamp",
        **laser_offset_meta(offset_source, scans.laser_offset),
    }
    return Log(
        name=name or _stem(path),
        kind="carmen",
        source=path,
        scans=scans,
        odometry=odometry,
        meta=meta,
    )


Layouts = dict[tuple[int, int], _Lines]
"""ROBOTLASER1 or RAWLASER1 lines by ``(num_readings, num_remissions)``."""


def _group_lines(
    path: Path, lines: list[str]
) -> tuple[list[str], dict[str, int], _Lines, dict[int, _Lines], Layouts, Layouts]:
    """Sort a log's lines by message: ``(comments, skipped counts per type, ODOM lines, FLASER
    lines per beam count, ROBOTLASER1 lines per layout, RAWLASER1 lines per layout)``, each
    line kept with its number."""
    comments: list[str] = []
    skipped: dict[str, int] = {}
    odom = _Lines([], [])
    flaser: dict[int, _Lines] = {}
    robotlaser: Layouts = {}
    rawlaser: Layouts = {}
    for lineno, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line:
            continue
        if line[0] == "#":
            comments.append(line[1:].strip())
            continue
        head = line.split(None, 2)
        kind = head[0]
        if kind == "FLASER":
            n = _beam_count(path, lineno, head, 1, "FLASER")
            group = flaser.setdefault(n, _Lines([], []))
        elif kind == "ODOM":
            group = odom
        elif kind == "ROBOTLASER1":
            key = _laser_layout(path, lineno, line, kind)
            group = robotlaser.setdefault(key, _Lines([], []))
        elif kind == "RAWLASER1":
            key = _laser_layout(path, lineno, line, kind)
            group = rawlaser.setdefault(key, _Lines([], []))
        else:
            if not _MESSAGE_TYPE.match(kind):
                raise DataError(
                    f"{path}:{lineno}: expected a message type such as FLASER or ODOM "
                    f"or a '#' comment, found {_clip(kind)!r}"
                )
            skipped[kind] = skipped.get(kind, 0) + 1
            continue
        group.text.append(line)
        group.lineno.append(lineno)
    return comments, skipped, odom, flaser, robotlaser, rawlaser


def _stem(path: Path) -> str:
    name = path.name
    for suffix in (".gz", ".clf", ".log"):
        if name.endswith(suffix) and len(name) > len(suffix):
            name = name[: -len(suffix)]
    return name


def _clip(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[:limit] + "..."


def _read_text(path: Path) -> str:
    """The file's text; gzip is recognised by its magic bytes whatever the suffix."""
    raw = read_input(
        path,
        "CARMEN log not found",
        "is a folder, expected a CARMEN log file (.clf/.log)",
        "cannot read CARMEN log",
    )
    if raw[:2] == GZIP_MAGIC:
        try:
            raw = gzip.decompress(raw)
        except EOFError:
            raise DataError(
                f"{path}: truncated gzip file (the compressed stream ends early); download it again"
            ) from None
        except (OSError, zlib.error) as exc:
            raise DataError(f"{path}: corrupt gzip file ({exc})") from None
    return decode_utf8(path, raw)


def _beam_count(path: Path, lineno: int, tokens: Sequence[str], index: int, kind: str) -> int:
    """The beam count field ``tokens[index]`` as a positive integer."""
    if len(tokens) <= index:
        raise DataError(f"{path}:{lineno}: {kind} line ends before its beam count")
    token = tokens[index]
    try:
        n = int(token)
    except ValueError:
        raise DataError(
            f"{path}:{lineno}: {kind} beam count: expected an integer, found {_clip(token)!r}"
        ) from None
    if not 1 <= n <= MAX_BEAMS:
        raise DataError(f"{path}:{lineno}: {kind} beam count: expected 1..{MAX_BEAMS}, found {n}")
    return n


def _laser_layout(path: Path, lineno: int, line: str, kind: str) -> tuple[int, int]:
    """``(num_readings, num_remissions)`` of a ROBOTLASER1 or RAWLASER1 line (``kind``): what
    fixes its layout (both start with the same nine fields, readings and remissions)."""
    tokens = line.split()
    n = _beam_count(path, lineno, tokens, 8, kind)
    if len(tokens) <= 9 + n:
        raise DataError(
            f"{path}:{lineno}: {kind} declares {n} readings but the line ends after "
            f"{len(tokens)} fields, before its remission count"
        )
    token = tokens[9 + n]
    try:
        nrem = int(token)
    except ValueError:
        raise DataError(
            f"{path}:{lineno}: {kind} remission count (field {10 + n}): expected an "
            f"integer, found {_clip(token)!r}"
        ) from None
    if not 0 <= nrem <= MAX_BEAMS:
        raise DataError(
            f"{path}:{lineno}: {kind} remission count: expected 0..{MAX_BEAMS}, found {nrem}"
        )
    return n, nrem


def _parse_table(
    path: Path,
    kind: str,
    lines: _Lines,
    ncols: int,
    skip: Sequence[int],
    field_name: Callable[[int], str],
    finite: Callable[[int], bool],
) -> F64:
    """Numeric fields of lines that all have ``ncols`` fields: ``(L, ncols − len(skip))``.

    Columns in ``skip`` (message type, host name) are not converted; ``finite(col)`` says
    whether a column must hold a finite number (poses, times) or may hold NaN/inf (ranges).
    """
    for line, lineno in zip(lines.text, lines.lineno, strict=True):
        found = len(line.split())
        if found != ncols:
            raise DataError(
                f"{path}:{lineno}: {kind} line: expected {ncols} fields"
                f"{_layout_hint(kind, ncols)}, found {found}"
            )
    usecols = [c for c in range(ncols) if c not in set(skip)]
    values = np.empty((len(lines.text), len(usecols)))
    for first in range(0, len(lines.text), PARSE_ROWS):  # the parser's buffers of a block only
        block = _loadtxt(lines.text[first : first + PARSE_ROWS], usecols)
        if block is None:
            lineno, message = _locate_bad_line(lines, usecols, field_name)
            raise DataError(f"{path}:{lineno}: {kind} {message}")
        values[first : first + block.shape[0]] = block
    must_be_finite = np.array([finite(c) for c in usecols])
    bad = ~np.isfinite(values[:, must_be_finite])
    if bad.any():
        row, k = np.argwhere(bad)[0]
        col = np.asarray(usecols)[must_be_finite][k]
        raise DataError(
            f"{path}:{lines.lineno[row]}: {kind} {field_name(col)} (field {col + 1}): "
            f"expected a finite number, found {values[row, usecols.index(col)]}"
        )
    return values


PARSE_ROWS = 1024
"""Lines one :func:`numpy.loadtxt` call converts."""


def _layout_hint(kind: str, ncols: int) -> str:
    if kind == "FLASER":
        return f" (FLASER n=<{ncols - 11}> beams + 11)"
    if kind == "ODOM":
        return " (ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp)"
    return ""


def _loadtxt(text: list[str], usecols: list[int]) -> F64 | None:
    """One C-level conversion of the lines; ``None`` if any field is not a number."""
    try:
        values = np.loadtxt(text, usecols=usecols, comments=None, ndmin=2, dtype=np.float64)
    except ValueError:
        return None
    if values.shape != (len(text), len(usecols)):
        return None
    return values


def _locate_bad_line(
    lines: _Lines, usecols: list[int], field_name: Callable[[int], str]
) -> tuple[int, str]:
    """Bisect a group that failed to convert down to its first bad line and field."""
    lo, hi = 0, len(lines.text)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if _loadtxt(lines.text[lo:mid], usecols) is None:
            hi = mid
        else:
            lo = mid
    tokens = lines.text[lo].split()
    for col in usecols:
        if _loadtxt([tokens[col]], [0]) is None:
            return lines.lineno[lo], (
                f"{field_name(col)} (field {col + 1}): expected a number, "
                f"found {_clip(tokens[col])!r}"
            )
    return lines.lineno[lo], "line: its fields could not be read as numbers"


def _flaser_field(n: int) -> Callable[[int], str]:
    def name(col: int) -> str:
        if col == 0:
            return "message type"
        if col == 1:
            return "beam count"
        if col < n + 2:
            return f"range {col - 1}"
        return _FLASER_TAIL[col - n - 2]

    return name


def _parse_flaser(path: Path, n: int, lines: _Lines, lidar: LidarConfig) -> _ScanGroup:
    ncols = n + 11
    values = _parse_table(
        path,
        "FLASER",
        lines,
        ncols,
        skip=(0, n + 9),
        field_name=_flaser_field(n),
        finite=lambda col: col < 2 or col >= n + 2,
    )
    # values columns: 0 n, 1..n ranges, n+1..n+6 poses, n+7 ipc, n+8 logger
    fov = np.deg2rad(lidar.fov_deg if lidar.fov_deg is not None else DEFAULT_FOV_DEG)
    step = fov / (n - 1) if n > 1 else 0.0
    if lidar.beam_step_deg is not None:
        if lidar.beam_step_deg * (n - 1) > 360.0:
            raise ConfigError(
                f"{path}: lidar.beam_step_deg: expected at most {360.0 / max(n - 1, 1):g}° for "
                f"its FLASER lines of {n} beams (a span of at most 360°), found "
                f"{lidar.beam_step_deg:g}° ({lidar.beam_step_deg * (n - 1):g}° in all)"
            )
        step = np.deg2rad(lidar.beam_step_deg)  # fov_deg is not used then
    angles = (np.arange(n) - (n - 1) / 2.0) * step
    return _ScanGroup(
        order=np.asarray(lines.lineno, dtype=np.int64),
        ranges=values[:, 1 : n + 1],
        angles=angles,
        laser_pose=values[:, n + 1 : n + 4],
        odometry=values[:, n + 4 : n + 7],
        time=values[:, n + 7],
    )


def _robotlaser_field(
    n: int, nrem: int, tail: tuple[str, ...] = _ROBOTLASER_TAIL
) -> Callable[[int], str]:
    def name(col: int) -> str:
        if col < 9:
            return _ROBOTLASER_HEAD[col]
        if col < 9 + n:
            return f"range {col - 8}"
        if col == 9 + n:
            return "num_remissions"
        if col < 10 + n + nrem:
            return f"remission {col - 9 - n}"
        return tail[col - 10 - n - nrem]

    return name


def _parse_rawlaser(path: Path, n: int, nrem: int, lines: _Lines) -> _ScanGroup:
    """RAWLASER1 lines of one layout: ROBOTLASER1's head, readings and remissions, then only
    ``ipc_timestamp hostname logger_timestamp`` (no pose)."""
    base = 10 + n + nrem
    values = _parse_table(
        path,
        "RAWLASER1",
        lines,
        base + 3,
        skip=(0, base + 1),
        field_name=_robotlaser_field(n, nrem, _RAWLASER_TAIL),
        finite=lambda col: col < 9 or col == 9 + n or col >= base,
    )
    # values column c-1 holds file column c for c <= base; the logger stamp is last.
    start, res, max_range = values[:, 1], values[:, 3], values[:, 4]
    return _ScanGroup(
        order=np.asarray(lines.lineno, dtype=np.int64),
        ranges=values[:, 8 : 8 + n],
        angles=_beam_angles(start, res, n),
        laser_pose=None,
        odometry=None,
        time=values[:, base - 1],
        max_range=max_range,
    )


def _parse_robotlaser(path: Path, n: int, nrem: int, lines: _Lines) -> _ScanGroup:
    ncols = 24 + n + nrem
    base = 10 + n + nrem
    values = _parse_table(
        path,
        "ROBOTLASER1",
        lines,
        ncols,
        skip=(0, base + 12),
        field_name=_robotlaser_field(n, nrem),
        finite=lambda col: col < 9 or col == 9 + n or col >= base,
    )
    # values column c-1 holds file column c for c < base + 12; the logger stamp is last.
    # The declared fov is implied by start, resolution and count; the count is authoritative.
    start, res, max_range = values[:, 1], values[:, 3], values[:, 4]
    angles = _beam_angles(start, res, n)
    tail = values[:, base - 1 :]
    return _ScanGroup(
        order=np.asarray(lines.lineno, dtype=np.int64),
        ranges=values[:, 8 : 8 + n],
        angles=angles,
        laser_pose=tail[:, 0:3],
        odometry=tail[:, 3:6],
        time=tail[:, 11],
        max_range=max_range,
    )


def _beam_angles(start: F64, res: F64, n: int) -> F64:
    """The beam angles of lines declaring ``start`` and ``res``: one ``(n,)`` row when every line
    declares the same (8 bytes a reading fewer on a long log), else ``(L, n)``; the same values."""
    same = start.size and _same_bits(start) and _same_bits(res)  # -0.0 is not 0.0 here
    if same:
        return start[0] + res[0] * np.arange(n)
    return start[:, None] + res[:, None] * np.arange(n)[None, :]


def _same_bits(values: F64) -> bool:
    """Whether every value of ``values`` has the first one's bits."""
    bits = values.view(np.int64)
    return bool(np.all(bits == bits[0]))


def no_return_code(ranges: F64 | Sequence[F64]) -> float | None:
    """Where a log's "no echo" readings start, read from its range histogram, or None.

    A laser writes a code for a beam without an echo: its maximum reading (SICK: 81.83 m,
    81.91 m) or a value of its own (aces: 50.00 m; mit-killian: a spike over 51.05–51.12 m). Such
    a code is a pile of equal readings at the top of the histogram; genuine readings that far out
    are few and spread. Among the readings (to the millimetre) within :data:`NO_RETURN_BAND_M` of
    the longest one, a value read at least :data:`NO_RETURN_MIN_SHARE` of all readings (and
    :data:`NO_RETURN_MIN_COUNT`) is a pile; the lowest pile grows down through the next values
    while they are read a tenth as often; the threshold is halfway between the pile and the
    longest reading below it (aces 49.955 m, mit-killian 51.03 m, fr-clinic 81.825 m, intel
    54.1 m). None when the top of the histogram holds no pile.

    ``ranges`` is one array or several (a log's layout groups), read a block at a time: a
    log's readings are judged without a copy of them all.
    """
    parts = [ranges] if isinstance(ranges, np.ndarray) else list(ranges)
    count, longest = 0, -np.inf
    for block in _reading_blocks(parts):
        readings = block[(block > 0.0) & (block <= MAX_RANGE_M)]  # NaN, 1e308: not readings
        count += readings.size
        if readings.size:
            longest = max(longest, float(readings.max()))
    if count == 0:
        return None
    # rounding is monotonic: the longest rounded reading is the longest reading rounded
    top = float(np.round(np.array([longest]), 3)[0])
    band: list[F64] = []
    below_band = -np.inf  # the longest rounded reading under the band
    for block in _reading_blocks(parts):
        r = np.round(block[(block > 0.0) & (block <= MAX_RANGE_M)], 3)
        inside = r >= top - NO_RETURN_BAND_M
        band.append(r[inside])
        if not inside.all():
            below_band = max(below_band, float(r[~inside].max()))
    values, counts = np.unique(np.concatenate(band), return_counts=True)
    need = max(NO_RETURN_MIN_COUNT, NO_RETURN_MIN_SHARE * count)
    piles = np.flatnonzero(counts >= need)
    if piles.size == 0:
        return None
    first = int(piles[0])
    while first > 0 and counts[first - 1] >= 0.1 * need:
        first -= 1
    below = float(values[first - 1]) if first > 0 else below_band
    if below == -np.inf:
        return None
    return round(0.5 * (below + float(values[first])), 4)


NO_RETURN_BLOCK = 1 << 18
"""Readings :func:`no_return_code` judges at a time."""


def _reading_blocks(parts: list[F64]) -> Iterator[F64]:
    """Each array of ``parts`` in blocks of whole rows of about :data:`NO_RETURN_BLOCK`
    readings."""
    for part in parts:
        row = max(1, int(np.prod(part.shape[1:])))
        step = max(1, NO_RETURN_BLOCK // row)
        for first in range(0, part.shape[0], step):
            yield part[first : first + step]


def _lidar_limits(lidar: LidarConfig, groups: list[_ScanGroup]) -> tuple[float, float, float]:
    """``(range_min, range_max, no_return)`` from the config, else the log's declared range
    limit (ROBOTLASER1), else its no-echo code (:func:`no_return_code`), else the documented
    defaults."""
    if lidar.fov_deg is not None and not 0.0 < lidar.fov_deg <= 360.0:
        raise ConfigError(f"lidar.fov_deg: expected a value in (0, 360], found {lidar.fov_deg}")
    range_min = DEFAULT_RANGE_MIN if lidar.range_min is None else lidar.range_min
    if lidar.no_return is not None:
        no_return = lidar.no_return
    elif all(g.max_range is not None for g in groups):
        no_return = min(float(np.min(g.max_range)) for g in groups if g.max_range is not None)
    else:
        code = no_return_code([g.ranges for g in groups])
        no_return = DEFAULT_NO_RETURN if code is None else code
        if not range_min < no_return:
            no_return = DEFAULT_NO_RETURN
    range_max = no_return if lidar.range_max is None else lidar.range_max
    if not range_min < range_max <= no_return:
        raise ConfigError(
            "lidar: expected range_min < range_max <= no_return, found "
            f"range_min={range_min}, range_max={range_max}, no_return={no_return}"
        )
    return range_min, range_max, no_return


def _assemble_scans(
    path: Path, groups: list[_ScanGroup], lidar: LidarConfig, memory_share: float
) -> tuple[ScanStream, str]:
    """Merge the layout groups back into file order and build the :class:`ScanStream`."""
    range_min, range_max, no_return = _lidar_limits(lidar, groups)
    order = np.concatenate([g.order for g in groups])
    position = np.empty(order.shape[0], dtype=np.int64)
    position[np.argsort(order, kind="stable")] = np.arange(order.shape[0])
    total = order.shape[0]
    width = max(g.ranges.shape[1] for g in groups)
    check_memory(
        total * width * ASSEMBLY_BYTES_PER_READING,
        f"{path}: {total} scans padded to the widest scan's {width} beams",
        "check the file for a corrupt beam count",
        share=memory_share,
        setting="checks.max_memory_share",
    )

    posed = all(g.odometry is not None for g in groups)  # RAWLASER1 lines carry no pose
    time = np.empty(total)
    laser_pose = np.empty((total, 3))
    odometry = np.empty((total, 3))
    shared = _shared_angles(groups)
    angles = shared if shared is not None else np.full((total, width), np.nan)
    if len(groups) == 1:  # in file order, as wide as the log: judged into place
        stored, invalid_beams = valid_ranges(groups[0].ranges, range_min)
    else:  # each group judged on its own (the rule is per reading), padding left NaN
        stored = np.full((total, width), np.nan, dtype=np.float32)
        invalid_beams = 0
    start = 0
    for g in groups:
        rows = position[start : start + g.order.shape[0]]
        start += g.order.shape[0]
        n = g.ranges.shape[1]
        time[rows] = g.time
        if posed:
            laser_pose[rows] = g.laser_pose
            odometry[rows] = g.odometry
        if len(groups) > 1:
            judged, invalid = valid_ranges(g.ranges, range_min)
            stored[rows, :n] = judged
            invalid_beams += invalid
        if shared is None:
            angles[rows, :n] = g.angles

    if lidar.use_log_laser_pose and posed:
        offset = _median_offset(odometry, laser_pose)
        source = "log"
    elif lidar.use_log_laser_pose:  # RAWLASER1: the log states no mount; at the odometry point
        offset = np.zeros(3)
        source = "not stated"
    else:
        offset = np.array([lidar.x, lidar.y, lidar.yaw], dtype=np.float64)
        source = "config"
    scans = ScanStream(
        time=time,
        ranges=stored,
        angles=angles,
        range_min=float(range_min),
        range_max=float(range_max),
        no_return=float(no_return),
        laser_offset=offset,
        odometry=odometry if posed else None,
        laser_pose=laser_pose if posed else None,
        invalid_beams=invalid_beams,
        lines=np.sort(order),
    )
    return scans, source


def _shared_angles(groups: list[_ScanGroup]) -> F64 | None:
    """The one ``(B,)`` angle vector every scan uses, or ``None`` if scans differ."""
    first = groups[0].angles
    candidate = first if first.ndim == 1 else first[0]
    for g in groups:
        rows = g.angles[None, :] if g.angles.ndim == 1 else g.angles
        if rows.shape[1] != candidate.shape[0] or not np.array_equal(
            rows, np.broadcast_to(candidate, rows.shape)
        ):
            return None
    return candidate.copy()


def _median_offset(odometry: F64, laser_pose: F64) -> F64:
    """Median laser pose in the robot frame over the log (yaw taken around its circular mean)."""
    rel = relative(odometry, laser_pose)
    mean_yaw = float(np.arctan2(np.sin(rel[:, 2]).mean(), np.cos(rel[:, 2]).mean()))
    yaw = mean_yaw + float(np.median(wrap_angle(rel[:, 2] - mean_yaw)))
    offset = np.array([np.median(rel[:, 0]), np.median(rel[:, 1]), float(wrap_angle(yaw))])
    offset[np.abs(offset) < 1e-12] = 0.0
    return offset


def _parse_odom(path: Path, lines: _Lines) -> OdometryStream:
    values = _parse_table(
        path,
        "ODOM",
        lines,
        len(_ODOM_FIELDS),
        skip=(0, 8),
        field_name=lambda col: _ODOM_FIELDS[col],
        finite=lambda col: True,
    )
    # values columns: x y theta tv rv accel ipc logger
    return OdometryStream(
        time=values[:, 6].copy(),
        poses=values[:, 0:3].copy(),
        velocities=values[:, 3:5].copy(),
        lines=np.asarray(lines.lineno, dtype=np.int64),
    )
