"""ROS bag loader: ROS 1 ``.bag``, ROS 2 bag folders (sqlite3 or MCAP storage) and bare ``.mcap``.

This module owns reading ROS recordings into a :class:`~slam.io.log.Log` through the pure-Python
``rosbags`` library (no ROS installation): which topics become which stream, where the laser is
mounted, and the errors a bag that cannot be used produces. :func:`inspect_bag` describes a bag
(``slam data inspect``) with the same topic and frame resolution :func:`load_bag` uses.

Streams
-------
* ``sensor_msgs/LaserScan`` → :attr:`Log.scans`: any beam count, the geometry (``angle_min``,
  ``angle_increment``, ``range_min``, ``range_max``) from every message; a log whose beam
  count or geometry varies gets ``(N, B)`` NaN-padded angles. Scan time is ``header.stamp``
  (the record time when a driver left it zero). Readings below ``range_min``, negative, NaN or
  −inf are invalid beams (NaN, counted); +inf and readings at or beyond the message's
  ``range_max`` mean "no return" (REP 117): they keep their value, or become ``no_return``.
* ``sensor_msgs/MultiEchoLaserScan`` (Cartographer's demo bags) → :attr:`Log.scans` too, read
  like a LaserScan whose range per beam is the beam's **first** echo (as Cartographer's
  ``msg_conversion.cc`` takes it); the first echo then follows the LaserScan rules above, and
  a beam with no echo at all is an invalid beam (NaN, counted). ``meta["scan_type"]`` names the
  message type read.
* ``nav_msgs/Odometry`` → :attr:`Log.odometry` (pose and twist, sorted by stamp); without an
  Odometry topic, the ``odom → base`` transforms of ``/tf`` (velocities then by finite
  differences). The odometry pose at a scan is interpolated at the scan's stamp, or with
  ``odom_sync="latest"`` the last one at or before it.
* **No odometry.** A bag with laser scans but neither an Odometry topic nor a moving ``/tf``
  transform above the laser frame still loads: :attr:`Log.odometry` and
  :attr:`ScanStream.odometry` are ``None`` and ``meta["odom_source"]`` is ``"none"``. ``slam
  run`` then takes its odometry from matching the scans (``robot.odometry = "auto"``, with a
  warning; ``"log"`` refuses such a log; docs/slam.md, "A robot without odometry"). Only
  ``--odom-topic`` or ``--base-frame`` asking for odometry the bag lacks is an error.
* **Publication order.** In a ROS 1 bag each message carries the publisher's counter
  ``header.seq``. Scans are kept in that order (the order the driver published them, which is
  also the order of a CARMEN log's lines; the bag's order when the counter is missing or
  repeats). When the stamps of the scans or of the odometry run against that order, the clock
  glitched (intel: both streams, by up to 0.9 s): sorted by stamp the odometry zig-zags (675 m
  of path instead of 509 m, 799 steps over 0.1 m) and a scan's stamp can point to a pose a
  metre away. Then each stream's times are re-estimated from the order
  (:func:`in_order_times`) and the pose at a scan is looked up at those times
  (:func:`scan_odometry_in_order`, stored in :attr:`ScanStream.odometry`); the scans' own
  times stay their stamps. ROS 2 headers have no ``seq``: a ROS 2 bag is read in its order.
* ``tf2_msgs/TFMessage`` on ``/tf_static`` (else ``/tf``) → the laser's mounting in the robot
  frame, composed along the frame chain ``base → … → laser`` and projected to the plane (an
  upside-down laser, rolled by π, has its beam angles mirrored; a tilted one is an error).
* ``sensor_msgs/Imu`` (when there is exactly one such topic) → :attr:`Log.imu`, its angular
  velocity and linear acceleration rotated into the robot frame (the full 3D rotation of the
  chain ``robot → … → header.frame_id``, found as the laser's is) so that row 2 of
  ``angular_velocity`` is the yaw rate about the robot's z axis. Without such a chain they stay
  as recorded; ``meta["imu_frame"]``, ``meta["imu_rotated"]`` and ``meta["imu_frame_source"]``
  say which.

Topics are found by message type (LaserScan and MultiEchoLaserScan topics are both scan topics);
when a type has several topics the error lists them and asks for ``--scan-topic`` /
``--odom-topic``. The robot frame is the Odometry messages' ``child_frame_id`` (for tf odometry:
the first frame above the laser with a moving parent; without odometry: the top of the laser's
``/tf_static`` chain, else the laser frame itself, at offset zero) unless ``--base-frame`` names
it.

Reading streams the messages once (no whole-bag load): arrays are preallocated from the bag's
index counts and grow only when a count is unknown. LaserScan, MultiEchoLaserScan and Odometry
messages are decoded by a small ROS 1 / CDR decoder (five times faster than the generic
deserializer on intel), which is checked against ``rosbags``' deserializer on each topic's first
message and falls back to it when the bag's message definition differs.
"""

from __future__ import annotations

import bisect
import contextlib
import dataclasses
import importlib
import math
import re
import struct
import tempfile
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.config import LidarConfig
from slam.errors import DataError, UsageError
from slam.geometry import interpolate_poses
from slam.io.carmen import MAX_BEAMS as CARMEN_MAX_BEAMS
from slam.io.formats import BAG_FORMATS, detect_format
from slam.io.log import ImuStream, Log, OdometryStream, ScanStream, laser_offset_meta

F64 = NDArray[np.float64]

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
MULTI_ECHO_TYPE = "sensor_msgs/msg/MultiEchoLaserScan"
SCAN_TYPES = (SCAN_TYPE, MULTI_ECHO_TYPE)
"""Message types read as laser scans (a MultiEchoLaserScan beam's range: its first echo)."""
ODOM_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"
IMU_TYPE = "sensor_msgs/msg/Imu"
TF_TOPIC = "tf"
"""``--odom-topic`` value (also ``/tf``) that asks for odometry from the transforms."""
NO_ODOMETRY = "none"
"""``meta["odom_source"]`` of a bag without odometry (the run's odometry is then the laser's)."""

ODOM_SYNC = ("interpolate", "latest")
"""Values of :attr:`BagOptions.odom_sync`."""
WORLD_FRAMES = frozenset({"odom", "map", "earth", "world"})
"""Fixed frames of REP 105: never the robot's, even when tf_static hangs the laser from one."""
LASER_AT_ORIGIN = "not stated: the laser frame is the robot frame"
"""``meta["laser_offset_source"]`` of a bag without odometry whose tf_static does not mount the
laser on a robot frame: the laser's own frame is the robot's, at offset zero."""
MAX_BEAMS = CARMEN_MAX_BEAMS
"""Most beams a LaserScan may have: the bound of every loader (:data:`slam.io.carmen.MAX_BEAMS`)."""
MAX_TILT_DEG = 5.0
"""Largest angle between the laser's scan plane and the robot's floor plane."""
STANDARD_GRAVITY = 9.80665
"""m/s² per g (:class:`ImuStream` keeps accelerations in g)."""

_FORMAT_NAMES = {"ros1": "ROS 1 bag", "mcap": "MCAP file", "rosbag2": "ROS 2 bag"}


@dataclass(frozen=True)
class BagOptions:
    """What to read from a bag when it is ambiguous (``--scan-topic`` etc.)."""

    scan_topic: str | None = None
    """LaserScan or MultiEchoLaserScan topic; default: the only one."""
    odom_topic: str | None = None
    """Odometry topic, or ``tf`` for the transforms; default: the only Odometry topic, else tf,
    else none (:data:`NO_ODOMETRY`)."""
    base_frame: str | None = None
    """Robot frame; default: the Odometry ``child_frame_id`` (tf: the laser's moving ancestor;
    a bag without odometry: the top of the laser's tf_static chain, else the laser frame). Naming
    it asks for its odometry: a bag without any is then an error."""
    odom_sync: str = "interpolate"
    """Odometry pose at a scan: ``"interpolate"`` at the scan's stamp (what tf does) or
    ``"latest"``, the last odometry pose at or before it (what CARMEN logs record per scan)."""

    def __post_init__(self) -> None:
        if self.odom_sync not in ODOM_SYNC:
            raise UsageError(
                f"--odom-sync: expected one of {', '.join(ODOM_SYNC)}, found {self.odom_sync!r}"
            )


@dataclass(frozen=True)
class _Scan:
    stamp_ns: int
    frame: str
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: NDArray[np.float32]
    seq: int = -1
    """ROS 1 ``header.seq`` (the publisher's message counter); −1 in ROS 2 (no such field)."""


@dataclass(frozen=True)
class _Odom:
    stamp_ns: int
    frame: str
    child: str
    x: float
    y: float
    yaw: float
    speed: float
    yaw_rate: float
    seq: int = -1
    """ROS 1 ``header.seq``; −1 in ROS 2."""


@dataclass(frozen=True)
class _Edge:
    """One transform ``parent → child``: translation and unit quaternion ``(x, y, z, w)``."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]
    seq: int = -1
    """ROS 1 ``header.seq`` of the transform; −1 in ROS 2."""


@dataclass
class _Selection:
    """The connections a load reads and what they mean."""

    scan: list[Any]
    odom: list[Any]
    """Odometry connections; empty when odometry comes from tf."""
    tf: list[Any]
    tf_static: list[Any]
    imu: list[Any]
    scan_topic: str
    scan_type: str
    """The scan topic's message type (one of :data:`SCAN_TYPES`)."""
    odom_topic: str
    """The Odometry topic, ``"tf"``, or ``"none"`` (:data:`NO_ODOMETRY`: neither is in the bag)."""
    notes: list[str] = field(default_factory=list)


class _Mismatch(Exception):
    """The fast decoder does not fit this message (another definition): use rosbags'."""


# --- opening ------------------------------------------------------------------------------


def _damage_errors() -> tuple[type[BaseException], ...]:
    """What a damaged length field or compressed chunk raises while a bag is read."""
    zstd: tuple[type[BaseException], ...] = ()
    for module in ("compression.zstd", "backports.zstd"):  # what rosbags decompresses with
        with contextlib.suppress(ImportError, AttributeError):
            zstd = (importlib.import_module(module).ZstdError,)
            break
    return (
        OverflowError,  # a corrupt length field in an MCAP record
        MemoryError,  # ... gigabytes asked for, refused
        zlib.error,
        RuntimeError,  # a damaged compressed chunk (lz4: ROS 1 and MCAP)
        *zstd,  # ... (zstd: MCAP)
    )


def _reader_errors() -> tuple[type[BaseException], ...]:
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.serde import SerdeError
    from rosbags.typesys import TypesysError

    return (
        AnyReaderError,
        Reader1Error,
        Reader2Error,
        SerdeError,
        TypesysError,
        struct.error,
        EOFError,
        OSError,
        ValueError,
        KeyError,
        IndexError,
        AssertionError,
        TypeError,  # an MCAP file that ends right after its magic
        *_damage_errors(),
    )


@contextlib.contextmanager
def open_bag(path: Path) -> Iterator[tuple[Any, str]]:
    """The open ``rosbags`` reader of the bag at ``path`` and its format (``ros1``, ``mcap``,
    ``rosbag2``); every reader error (truncated, corrupt, unindexed) becomes one
    :class:`DataError` naming the file."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    fmt = detect_format(path)
    if fmt not in BAG_FORMATS:
        raise DataError(f"{path}: a {fmt} log, not a ROS bag or MCAP file")
    if fmt == "rosbag2" and path.name == "metadata.yaml":
        path = path.parent
    expected = {"ros1": ".bag", "mcap": ".mcap"}.get(fmt)
    with contextlib.ExitStack() as stack:
        read = path
        if expected and path.suffix != expected:  # the reader goes by the suffix: a link has it
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="slam-bag-")))
            read = folder / f"{path.stem or 'bag'}{expected}"
            read.symlink_to(path.resolve())
        store = Stores.ROS1_NOETIC if fmt == "ros1" else Stores.LATEST
        errors = _reader_errors()
        try:
            reader = AnyReader([read], default_typestore=get_typestore(store))
            reader.open()
        except errors as exc:
            raise _reader_failure(path, fmt, exc) from None
        try:
            yield reader, fmt
        except errors as exc:
            raise _reader_failure(path, fmt, exc) from None
        finally:
            with contextlib.suppress(Exception):
                reader.close()


_READER_MODULES = ("rosbags", "backports.zstd", "compression.zstd", "zstandard", "lz4", "mcap")
"""The bag readers' modules and their decompressors' (with their submodules)."""


def _reader_failure(path: Path, fmt: str, exc: BaseException) -> BaseException:
    """The :class:`DataError` of a reader's failure on a damaged file — or ``exc`` itself for a
    ``TypeError``, ``RuntimeError`` or ``MemoryError`` raised outside the readers' code (slam's
    own, within the ``with open_bag`` block): a bug or a real shortage of memory, not a damaged
    file."""
    if isinstance(exc, TypeError | RuntimeError | MemoryError) and not _raised_in_reader(exc):
        return exc
    return _read_error(path, fmt, exc)


def _raised_in_reader(exc: BaseException) -> bool:
    """Whether the innermost Python frame of ``exc``'s traceback is in the readers' modules."""
    tb = exc.__traceback__
    last = None
    while tb is not None:
        last, tb = tb, tb.tb_next
    module = str(last.tb_frame.f_globals.get("__name__", "")) if last is not None else ""
    return any(module == m or module.startswith(m + ".") for m in _READER_MODULES)


def _read_error(path: Path, fmt: str, exc: BaseException) -> DataError:
    def flat(args: tuple[Any, ...]) -> list[str]:  # a reader may wrap its message in a tuple
        return [t for a in args for t in (flat(a) if isinstance(a, tuple) else [str(a)])]

    text = " ".join(" ".join(flat(exc.args)).split()) or type(exc).__name__
    if isinstance(exc, TypeError):  # rosbags reading a record past the end of the file
        text = "it ends inside a record"
    elif isinstance(exc, MemoryError):  # a damaged length field
        text = "a record's length is more than memory holds"
    text = re.sub(r"\('([^']*)',\)", r"\1", text)  # "damaged: ('Header ...',)": a wrapped tuple
    signs = ("ndex", "runcat", "eader could not", "magic is invalid")
    repair = {"ros1": "`rosbag reindex` it", "mcap": "`mcap recover` it"}.get(
        fmt, "`ros2 bag reindex` it"
    )
    if isinstance(exc, EOFError | struct.error | TypeError) or any(s in text for s in signs):
        text += f"; the file looks truncated or unindexed (copy it again, or {repair})"
    elif isinstance(exc, _damage_errors()) or "nvalid data stream" in text:
        # a length or a compressed chunk that no whole file holds
        whole = _FORMAT_NAMES[fmt]
        text += f"; the file looks damaged: expected a whole {whole} (copy it again, or {repair})"
    return DataError(f"{path}: cannot read the {_FORMAT_NAMES[fmt]}: {text}")


def _topics(reader: Any) -> list[tuple[str, str, int]]:
    """``(topic, type, count)`` of every topic, sorted by topic."""
    seen: dict[str, tuple[str, int]] = {}
    for c in reader.connections:
        msgtype, count = seen.get(c.topic, (c.msgtype, 0))
        seen[c.topic] = (msgtype, count + c.msgcount)
    return sorted((t, m, n) for t, (m, n) in seen.items())


def _describe(topics: Sequence[tuple[str, str, int]]) -> str:
    return ", ".join(f"{t} ({m})" for t, m, _ in topics) or "none"


def _norm(topic: str) -> str:
    return topic if topic.startswith("/") else "/" + topic


# --- choosing topics ----------------------------------------------------------------------


def select_topics(path: Path, reader: Any, options: BagOptions) -> _Selection:
    """The connections of the scan, odometry, tf and IMU topics :func:`load_bag` reads.

    A bag with neither an Odometry topic nor /tf selects no odometry (:data:`NO_ODOMETRY`)
    unless ``--base-frame`` asks for the robot's. :class:`DataError` when the scans are missing
    (naming the topics that exist) or a named topic is not there; :class:`UsageError` when a
    type has several topics and no option says which (naming the option and the topics).
    """
    topics = _topics(reader)
    by_type: dict[str, list[str]] = {}
    for topic, msgtype, _ in topics:
        by_type.setdefault(msgtype, []).append(topic)
    conns = reader.connections

    scan_topic = _pick(path, topics, by_type, SCAN_TYPES, options.scan_topic, "--scan-topic")
    tf_topics = [t for t in by_type.get(TF_TYPE, []) if not t.endswith("tf_static")]
    static_topics = [t for t in by_type.get(TF_TYPE, []) if t.endswith("tf_static")]
    odom_choice = options.odom_topic
    if odom_choice is not None and _norm(odom_choice) == "/" + TF_TOPIC:
        odom_topic = TF_TOPIC
    elif odom_choice is None and not by_type.get(ODOM_TYPE):
        if tf_topics:
            odom_topic = TF_TOPIC
        elif options.base_frame is None:  # a laser alone: the run's odometry is the laser's
            odom_topic = NO_ODOMETRY
        else:
            raise DataError(
                f"{path}: no odometry: no {ODOM_TYPE} topic and no /tf transforms for the robot "
                f"frame {options.base_frame!r} (--base-frame); topics in the bag: {_describe(topics)}"
            )
    else:
        odom_topic = _pick(path, topics, by_type, (ODOM_TYPE,), odom_choice, "--odom-topic")
    imu_topics = by_type.get(IMU_TYPE, [])
    notes = []
    if len(imu_topics) > 1:
        notes.append(f"IMU not read: several {IMU_TYPE} topics ({', '.join(imu_topics)})")
    return _Selection(
        scan=[c for c in conns if c.topic == scan_topic],
        odom=[c for c in conns if c.topic == odom_topic] if odom_topic != TF_TOPIC else [],
        tf=[c for c in conns if c.topic in tf_topics],
        tf_static=[c for c in conns if c.topic in static_topics],
        imu=[c for c in conns if len(imu_topics) == 1 and c.topic == imu_topics[0]],
        scan_topic=scan_topic,
        scan_type=next(m for t, m, _ in topics if t == scan_topic),
        odom_topic=odom_topic,
        notes=notes,
    )


def _pick(
    path: Path,
    topics: Sequence[tuple[str, str, int]],
    by_type: dict[str, list[str]],
    msgtypes: Sequence[str],
    chosen: str | None,
    option: str,
) -> str:
    """The one topic of the types ``msgtypes`` (or the ``chosen`` one, which must have one)."""
    candidates = sorted(t for m in msgtypes for t in by_type.get(m, []))
    wanted = msgtypes[0] + " topic" + (f" (or {', '.join(msgtypes[1:])})" if msgtypes[1:] else "")
    if chosen is not None:
        match = [t for t, _, _ in topics if t in (chosen, _norm(chosen))]
        if not match:
            raise DataError(
                f"{path}: {option} {chosen}: no such topic; topics in the bag: {_describe(topics)}"
            )
        found = next(m for t, m, _ in topics if t == match[0])
        if found not in msgtypes:
            raise DataError(f"{path}: {option} {chosen}: expected a {wanted}, found {found}")
        return match[0]
    if not candidates:
        what = "laser scans" if SCAN_TYPE in msgtypes else "odometry"
        raise DataError(f"{path}: no {what}: no {wanted}; topics in the bag: {_describe(topics)}")
    if len(candidates) > 1:
        types = {m for t, m, _ in topics if t in candidates}
        if len(types) == 1:
            listed = f"{len(candidates)} {types.pop()} topics ({', '.join(candidates)})"
        else:
            mixed = [row for row in topics if row[0] in candidates]
            listed = f"{len(candidates)} laser scan topics ({_describe(mixed)})"
        raise UsageError(f"{path}: {listed}; choose one with {option} TOPIC")
    return candidates[0]


# --- decoding -----------------------------------------------------------------------------


def _ros1_string(raw: bytes, pos: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", raw, pos)
    end = pos + 4 + n
    if end > len(raw):
        raise _Mismatch
    return raw[pos + 4 : end].decode("utf-8", "replace"), end


def _cdr_string(raw: bytes, pos: int, e: str) -> tuple[str, int]:
    pos = _align(pos, 4)
    (n,) = struct.unpack_from(e + "I", raw, pos)
    end = pos + 4 + n
    if n < 1 or end > len(raw):
        raise _Mismatch
    return raw[pos + 4 : end - 1].decode("utf-8", "replace"), end


def _align(pos: int, size: int) -> int:
    """CDR alignment: offsets count from the end of the 4-byte encapsulation header."""
    return 4 + (pos - 4 + size - 1) // size * size


def _cdr_endian(raw: bytes) -> str:
    if len(raw) < 4 or raw[0] != 0 or raw[1] not in (0, 1):
        raise _Mismatch
    return "<" if raw[1] == 1 else ">"


def _end(raw: bytes, pos: int, padding: int) -> None:
    if not 0 <= len(raw) - pos <= padding:
        raise _Mismatch


def _head_ros1(raw: bytes) -> tuple[_Scan, int]:
    """The header and beam geometry of a ROS 1 LaserScan or MultiEchoLaserScan (ranges still
    empty) and the position of its ranges' count."""
    seq, sec, nsec = struct.unpack_from("<III", raw, 0)
    frame, pos = _ros1_string(raw, 12)
    amin, _, inc, _, _, rmin, rmax = struct.unpack_from("<7f", raw, pos)
    empty = np.empty(0, np.float32)
    return _Scan(sec * 10**9 + nsec, frame, amin, inc, rmin, rmax, empty, seq), pos + 28


def _head_cdr(raw: bytes) -> tuple[_Scan, int, str]:
    """:func:`_head_ros1` of a CDR message (no ``seq``), and its byte order."""
    e = _cdr_endian(raw)
    sec, nsec = struct.unpack_from(e + "iI", raw, 4)
    frame, pos = _cdr_string(raw, 12, e)
    pos = _align(pos, 4)
    amin, _, inc, _, _, rmin, rmax = struct.unpack_from(e + "7f", raw, pos)
    empty = np.empty(0, np.float32)
    return _Scan(sec * 10**9 + nsec, frame, amin, inc, rmin, rmax, empty), pos + 28, e


def _ranges(raw: bytes, pos: int, e: str, padding: int) -> NDArray[np.float32]:
    """A LaserScan's ``ranges`` (``float32[]`` at ``pos``), its ``intensities`` skipped to the
    message's end (up to ``padding`` bytes after it)."""
    (n,) = struct.unpack_from(e + "I", raw, pos)
    pos += 4
    if pos + 4 * n + 4 > len(raw):
        raise _Mismatch
    ranges = np.frombuffer(raw, e + "f4", n, pos)
    pos += 4 * n
    (m,) = struct.unpack_from(e + "I", raw, pos)
    _end(raw, pos + 4 + 4 * m, padding)
    return ranges


def _fast_decoders(
    read_ranges: Callable[[bytes, int, str, int], NDArray[np.float32]],
) -> tuple[Callable[[bytes], _Scan], Callable[[bytes], _Scan]]:
    """The ROS 1 and the CDR decoder of a scan type whose ranges ``read_ranges(raw, pos, byte
    order, padding)`` reads after the header and beam geometry (:func:`_head_ros1`)."""

    def ros1(raw: bytes) -> _Scan:
        head, pos = _head_ros1(raw)
        return dataclasses.replace(head, ranges=read_ranges(raw, pos, "<", 0))

    def cdr(raw: bytes) -> _Scan:
        head, pos, e = _head_cdr(raw)
        return dataclasses.replace(head, ranges=read_ranges(raw, pos, e, 3))

    return ros1, cdr


def _first_echoes(raw: bytes, pos: int, e: str, padding: int) -> NDArray[np.float32]:
    """The first echo of each beam of a MultiEchoLaserScan (NaN for a beam without echoes): the
    ``ranges`` and ``intensities`` lists of ``LaserEcho`` (``uint32`` count, then per beam a
    ``uint32`` count and that many ``float32``) from byte ``pos`` to the end of ``raw``.

    Every field is 4 bytes wide, so the rest of the message is read as one array of words (in
    CDR ``pos`` is 4-aligned, so no padding falls inside it; up to ``padding`` bytes may follow).
    The intensities are only skipped: at once when they have the ranges' echo counts.
    """
    size = (len(raw) - pos) // 4
    if size < 2:
        raise _Mismatch
    words = np.frombuffer(raw, e + "u4", size, pos)
    n = int(words[0])
    starts, after = _echo_starts(words, 1, n)
    if after >= size:
        raise _Mismatch
    counts = words[starts]
    if (
        int(words[after]) == n
        and 2 * after <= size
        and np.array_equal(words[starts + after], counts)
    ):
        end = 2 * after  # the intensities laid out like the ranges
    else:
        _, end = _echo_starts(words, after + 1, int(words[after]))
    _end(raw, pos + 4 * end, padding)
    first = np.full(n, np.nan, dtype=np.float32)
    has = counts > 0
    first[has] = words.view(e + "f4")[starts[has] + 1]
    return first


_ECHO_COUNT_MAX = 64
"""Largest echo count per beam the vectorised walk of :func:`_varying_echo_starts` expects."""


def _echo_starts(words: NDArray[np.uint32], start: int, n: int) -> tuple[NDArray[np.intp], int]:
    """Index in ``words`` of each of the ``n`` echo counts of a ``LaserEcho[]`` list whose first
    count is at ``start``, and the index just past the list.

    A lidar that reports the same number of echoes for every beam is indexed by one strided
    comparison; varying counts by :func:`_varying_echo_starts`, else by following the counts one
    by one (:func:`_walk_echo_starts`).
    """
    if n == 0:
        return np.zeros(0, dtype=np.intp), start
    if n > words.shape[0] - start:  # every beam takes at least its count's word
        raise _Mismatch
    stride = int(words[start]) + 1
    end = start + n * stride
    if end <= words.shape[0] and np.all(words[start:end:stride] == stride - 1):
        return np.arange(start, end, stride, dtype=np.intp), end
    rest = words[start:]
    heads, length = _varying_echo_starts(rest, n) or _walk_echo_starts(rest, n)
    return heads + start, start + length


def _varying_echo_starts(words: NDArray[np.uint32], n: int) -> tuple[NDArray[np.intp], int] | None:
    """The echo counts of a ``LaserEcho[]`` list starting at ``words[0]`` found without a loop,
    or ``None``.

    A count is a small word (at most :data:`_ECHO_COUNT_MAX`) that no earlier count's echoes
    cover: an echo's float32 bits are that small only for 0.0 (which covers nothing) or a
    subnormal. The chain ``next = count + 1 + words[count]`` is then checked from the first count
    to the last, so a wrong guess returns ``None`` instead of a wrong answer.
    """
    size = words.shape[0]
    small = np.flatnonzero(words <= _ECHO_COUNT_MAX)
    reach = np.minimum(small + words[small].astype(np.intp) + 1, size + 1)
    depth = np.bincount(small + 1, minlength=size + 2) - np.bincount(reach, minlength=size + 2)
    covered = np.cumsum(depth[:size]) > 0
    heads = small[~covered[small]][:n]
    if heads.shape[0] != n or heads[0] != 0:
        return None
    after = heads + 1 + words[heads].astype(np.intp)
    if not np.array_equal(heads[1:], after[:-1]) or after[-1] > size:
        return None
    return heads, int(after[-1])


def _walk_echo_starts(words: NDArray[np.uint32], n: int) -> tuple[NDArray[np.intp], int]:
    """The echo counts of a ``LaserEcho[]`` list starting at ``words[0]``, followed one by one."""
    counts = words.tolist()
    offsets = [0] * n
    p = 0
    for i in range(n):
        if p >= len(counts):
            raise _Mismatch
        offsets[i] = p
        p += 1 + counts[p]
    if p > len(counts):
        raise _Mismatch
    return np.asarray(offsets, dtype=np.intp), p


def _yaw(qx: float, qy: float, qz: float, qw: float) -> float:
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _odom_ros1(raw: bytes) -> _Odom:
    seq, sec, nsec = struct.unpack_from("<III", raw, 0)
    frame, pos = _ros1_string(raw, 12)
    child, pos = _ros1_string(raw, pos)
    x, y, _, qx, qy, qz, qw = struct.unpack_from("<7d", raw, pos)
    pos += 56 + 288
    vx, _, _, _, _, wz = struct.unpack_from("<6d", raw, pos)
    _end(raw, pos + 48 + 288, 0)
    return _Odom(sec * 10**9 + nsec, frame, child, x, y, _yaw(qx, qy, qz, qw), vx, wz, seq)


def _odom_cdr(raw: bytes) -> _Odom:
    e = _cdr_endian(raw)
    sec, nsec = struct.unpack_from(e + "iI", raw, 4)
    frame, pos = _cdr_string(raw, 12, e)
    child, pos = _cdr_string(raw, pos, e)
    pos = _align(pos, 8)
    x, y, _, qx, qy, qz, qw = struct.unpack_from(e + "7d", raw, pos)
    pos += 56 + 288
    vx, _, _, _, _, wz = struct.unpack_from(e + "6d", raw, pos)
    _end(raw, pos + 48 + 288, 7)
    return _Odom(sec * 10**9 + nsec, frame, child, x, y, _yaw(qx, qy, qz, qw), vx, wz)


def _seconds(ns: int) -> float:
    """Nanoseconds as seconds, rounded once (``ns * 1e-9`` is off by an ulp on Unix times)."""
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return sec + nsec / 1e9


def _stamp(header: Any) -> int:
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)


def _seq(header: Any) -> int:
    """``header.seq`` (ROS 1), −1 when the header has none (ROS 2)."""
    return int(getattr(header, "seq", -1))


def _scan_msg(msg: Any, ranges: Any = None) -> _Scan:
    """A rosbags LaserScan message as a :class:`_Scan` (``ranges``: instead of its own)."""
    return _Scan(
        _stamp(msg.header),
        msg.header.frame_id,
        float(msg.angle_min),
        float(msg.angle_increment),
        float(msg.range_min),
        float(msg.range_max),
        np.asarray(msg.ranges if ranges is None else ranges, dtype=np.float32),
        _seq(msg.header),
    )


def _multi_echo_msg(msg: Any) -> _Scan:
    """A MultiEchoLaserScan as a scan of its first echoes (NaN where a beam has none)."""
    return _scan_msg(msg, [e.echoes[0] if len(e.echoes) else np.nan for e in msg.ranges])


def _odom_msg(msg: Any) -> _Odom:
    p, q, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    return _Odom(
        _stamp(msg.header),
        msg.header.frame_id,
        msg.child_frame_id,
        float(p.x),
        float(p.y),
        _yaw(q.x, q.y, q.z, q.w),
        float(t.linear.x),
        float(t.angular.z),
        _seq(msg.header),
    )


def _decoder(
    reader: Any, fast: Callable[[bytes], Any], slow: Callable[[Any], Any], msgtype: str
) -> Callable[[bytes], Any]:
    """``fast`` once it agrees with rosbags' deserializer on the first message, else ``slow``."""
    state: dict[str, Any] = {}

    def generic(raw: bytes) -> Any:
        return slow(reader.deserialize(raw, msgtype))

    def decode(raw: bytes) -> Any:
        chosen = state.get("fn")
        if chosen is None:
            reference = generic(raw)
            try:
                candidate = fast(raw)
            except (_Mismatch, struct.error, ValueError):
                candidate = None
            same = candidate is not None and _same(candidate, reference)
            state["fn"] = chosen = fast if same else generic
            state["fast"] = same
            return reference
        try:
            return chosen(raw)
        except (_Mismatch, struct.error, ValueError):
            return generic(raw)

    decode.state = state  # type: ignore[attr-defined]
    return decode


def _same(a: Any, b: Any) -> bool:
    for name in a.__dataclass_fields__:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            if x.shape != y.shape or not np.array_equal(x, y, equal_nan=True):
                return False
        elif x != y and not (isinstance(x, float) and math.isnan(x) and math.isnan(y)):
            return False
    return True


_Decode = Callable[[bytes], _Scan]
_SCAN_DECODERS: dict[str, tuple[_Decode, _Decode, Callable[[Any], _Scan]]] = {
    SCAN_TYPE: (*_fast_decoders(_ranges), _scan_msg),
    MULTI_ECHO_TYPE: (*_fast_decoders(_first_echoes), _multi_echo_msg),
}
"""Per scan message type: the fast ROS 1 and CDR decoders and the converter of rosbags' message."""


# --- transforms ---------------------------------------------------------------------------


def _edges(msg: Any) -> list[_Edge]:
    out = []
    for t in msg.transforms:
        tr, q = t.transform.translation, t.transform.rotation
        out.append(
            _Edge(
                t.header.frame_id.lstrip("/"),
                t.child_frame_id.lstrip("/"),
                (float(tr.x), float(tr.y), float(tr.z)),
                (float(q.x), float(q.y), float(q.z), float(q.w)),
                _seq(t.header),
            )
        )
    return out


def _matrix(edge: _Edge) -> NDArray[np.float64]:
    """4×4 homogeneous transform of ``edge`` (child frame → parent frame)."""
    x, y, z, w = edge.rotation
    norm = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    m = np.eye(4)
    m[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    m[:3, 3] = edge.translation
    return m


def _chain(parents: dict[str, _Edge], base: str, frame: str) -> list[_Edge] | None:
    """Edges from ``base`` down to ``frame`` (walking up from ``frame``), or ``None``."""
    chain: list[_Edge] = []
    current = frame
    while current != base:
        edge = parents.get(current)
        if edge is None or len(chain) > 64:
            return None
        chain.append(edge)
        current = edge.parent
    return chain[::-1]


def _compose(edges: Sequence[_Edge]) -> NDArray[np.float64]:
    """4×4 transform of the chain ``edges`` (its last child frame → its first parent frame)."""
    m = np.eye(4)
    for edge in edges:
        m = m @ _matrix(edge)
    return m


def mounting(path: Path, edges: Sequence[_Edge]) -> tuple[F64, bool]:
    """``((x, y, yaw), upside_down)`` of the transform along ``edges`` projected to the plane.

    A laser rolled by π (mounted upside down) scans the plane mirrored: ``upside_down`` tells the
    caller to negate its beam angles. :class:`DataError` when the scan plane tilts more than
    :data:`MAX_TILT_DEG` from the robot's.
    """
    m = _compose(edges)
    normal_z = float(m[2, 2])
    if abs(normal_z) < math.cos(math.radians(MAX_TILT_DEG)):
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, abs(normal_z)))))
        names = " → ".join([edges[0].parent, *(e.child for e in edges)])
        raise DataError(
            f"{path}: the laser's scan plane ({names}) is tilted {tilt:.1f}° from the robot's "
            f"floor plane; expected at most {MAX_TILT_DEG:g}° (a 2D laser scanning the floor plane)"
        )
    yaw = math.atan2(m[1, 0], m[0, 0])
    offset = np.array([m[0, 3], m[1, 3], yaw])
    offset[np.abs(offset) < 1e-12] = 0.0
    return offset, normal_z < 0


# --- growing arrays -----------------------------------------------------------------------


class _Rows:
    """A ``(capacity, width)`` array filled row by row; doubles when full, widens on demand."""

    def __init__(self, capacity: int, width: int, dtype: Any, fill: float = 0.0) -> None:
        self.fill = fill
        self.data = np.full((max(capacity, 16), width), fill, dtype=dtype)
        self.n = 0

    def append(self, values: Any, width: int | None = None) -> None:
        if self.n == self.data.shape[0]:
            grown = np.full((2 * self.n, self.data.shape[1]), self.fill, dtype=self.data.dtype)
            grown[: self.n] = self.data
            self.data = grown
        if width is not None and width > self.data.shape[1]:
            wider = np.full((self.data.shape[0], width), self.fill, dtype=self.data.dtype)
            wider[:, : self.data.shape[1]] = self.data
            self.data = wider
        if width is None:
            self.data[self.n] = values
        else:
            self.data[self.n, :width] = values
        self.n += 1

    def array(self) -> NDArray[Any]:
        return self.data if self.n == self.data.shape[0] else self.data[: self.n].copy()


# --- loading ------------------------------------------------------------------------------


@dataclass
class _ScanRows:
    time: _Rows
    geometry: _Rows
    """``(angle_min, angle_increment, range_min, range_max, beams)`` per scan."""
    ranges: _Rows
    seq: _Rows
    """``header.seq`` per scan (−1 without one)."""
    frames: set[str] = field(default_factory=set)
    record_time_stamps: int = 0


@dataclass
class _Streams:
    """What one pass over the bag collected."""

    scans: _ScanRows
    odom: _Rows | None
    """``(time, x, y, yaw, speed, yaw_rate, seq)`` per Odometry message."""
    odom_children: set[str]
    dynamic: dict[tuple[str, str], _Rows]
    """``(time, x, y, yaw, seq)`` per ``(parent, child)`` transform of /tf."""
    first_edge: dict[tuple[str, str], _Edge]
    imu: ImuStream | None
    fast_decoder: dict[str, bool]
    imu_frames: set[str] = field(default_factory=set)
    """``header.frame_id`` of the Imu messages."""


def _odometry_at_scans(
    stream: ScanStream,
    odometry: OdometryStream | None,
    published: NDArray[np.float64] | None,
    ordered: bool,
    odom_sync: str,
) -> tuple[ScanStream, bool, int, int]:
    """The odometry pose at each scan: ``(stream, glitches, scan_glitches, odom_glitches)``.

    When the scans have a publication order (``ordered``) and either stream's stamps run against
    it, both streams' times are rebuilt from that order (:func:`scan_odometry_in_order`);
    otherwise the loader's interpolation stands, or with ``odom_sync == "latest"`` the latest
    odometry message at or before each scan, as CARMEN FLASER lines carry it. Without odometry
    the stream is returned as it is (``ScanStream.odometry`` stays ``None``).
    """
    if odometry is None or published is None:
        return stream, False, 0, 0
    glitches = ordered and (
        bool(np.any(np.diff(stream.time) < 0)) or bool(np.any(np.diff(published[:, 0]) < 0))
    )
    if glitches:  # stamps run against the publication order: times from that order
        poses, scan_glitches, odom_glitches = scan_odometry_in_order(
            stream.time, published[:, 0], published[:, 1:4], odom_sync
        )
        return dataclasses.replace(stream, odometry=poses), True, scan_glitches, odom_glitches
    if odom_sync == "latest":
        last = np.searchsorted(odometry.time, stream.time, side="right") - 1
        last = np.clip(last, 0, len(odometry.time) - 1)
        stream = dataclasses.replace(stream, odometry=odometry.poses[last].copy())
    return stream, False, 0, 0


def load_bag(
    path: Path,
    *,
    name: str | None = None,
    lidar: LidarConfig | None = None,
    options: BagOptions | None = None,
) -> Log:
    """Read the ROS bag / ROS 2 bag folder / MCAP file at ``path`` into a :class:`Log`.

    ``options`` choose topics and the robot frame (see :class:`BagOptions`). ``lidar`` may
    override the range limits (``range_min``, ``range_max``, ``no_return``: default from the
    messages) and, with ``use_log_laser_pose = false``, the mounting (``x``, ``y``, ``yaw``:
    default from tf). ``log.meta`` records the topics, frames, where the mounting came from
    and whether the fast decoder was used.

    A bag without odometry (no Odometry topic, no moving /tf transform above the laser) loads
    with ``log.odometry`` and ``log.scans.odometry`` ``None`` and ``meta["odom_source"] ==
    "none"``; ``slam run`` then runs on laser odometry (``robot.odometry = "auto"``).

    Raises :class:`DataError` naming the file when it cannot be read, lacks scans, or lacks the
    odometry ``options`` ask for (``odom_topic``, ``base_frame``); :class:`UsageError` when a
    topic choice is ambiguous.

    Long because it is the loader's one readable sequence (open, choose topics, read tf, stream,
    find the robot and its odometry, order, mount, sync, describe); each step is a call, and most
    of the length is ``meta``.
    """
    path = Path(path)
    lidar = lidar or LidarConfig()
    options = options or BagOptions()
    with open_bag(path) as (reader, fmt):
        sel = select_topics(path, reader, options)
        static = _read_tf(reader, sel.tf_static)
        first_scan = _first(reader, sel.scan, sel.scan_type, _SCAN_DECODERS[sel.scan_type][2])
        if first_scan is None:
            raise DataError(f"{path}: {sel.scan_topic} holds no messages")
        laser_frame = first_scan.frame.lstrip("/")
        base = options.base_frame
        if base is None and sel.odom:
            first_odom = _first(reader, sel.odom, ODOM_TYPE, _odom_msg)
            base = (first_odom.child.lstrip("/") if first_odom else "") or "base_link"
        parents = {e.child: e for e in static}
        need_tf = _need_tf(reader, sel, lidar, parents, base, laser_frame)
        _drop_unread_indexes(reader, [*sel.scan, *sel.odom, *sel.imu, *(sel.tf if need_tf else [])])
        streams = _stream(reader, sel, need_tf, path)

    scans = streams.scans
    notes = list(sel.notes)
    base, odometry, odom_source, published = _robot_odometry(
        path, sel, options, streams, parents, laser_frame, base, notes
    )
    offset, upside_down, offset_source = _laser_offset(
        path, lidar, parents, streams, base, laser_frame
    )
    if odometry is None and offset_source == "same frame":
        offset_source = LASER_AT_ORIGIN
    imu, imu_meta = _imu_in_robot_frame(streams, parents, base, notes)
    scan_order = publication_order(scans.seq.array()[:, 0])
    moved = _reorder_scans(scans, scan_order)
    stream = _scan_stream(path, sel.scan_topic, scans, lidar, offset, upside_down)
    stream, glitches, scan_glitches, odom_glitches = _odometry_at_scans(
        stream, odometry, published, scan_order is not None, options.odom_sync
    )
    meta: dict[str, Any] = {
        "format": fmt,
        "scan_topic": sel.scan_topic,
        "scan_type": sel.scan_type,
        "scan_order": "bag" if scan_order is None else "header.seq",
        "scans_reordered": moved,
        "odom_source": odom_source,
        "odom_sync": options.odom_sync,
        "odom_match": (
            NO_ODOMETRY if odometry is None else "in publication order" if glitches else "by stamp"
        ),
        "scan_stamp_glitches": scan_glitches,
        "odom_stamp_glitches": odom_glitches,
        "base_frame": base,
        "laser_frame": laser_frame,
        **laser_offset_meta(offset_source, offset),
        "laser_upside_down": int(upside_down),
        "scan_stamps_from_record_time": scans.record_time_stamps,
        "fast_decoder": ", ".join(f"{k}={v}" for k, v in sorted(streams.fast_decoder.items())),
    }
    if sel.imu:
        meta["imu_topic"] = sel.imu[0].topic
    meta.update(imu_meta)
    if notes:
        meta["notes"] = "; ".join(notes)
    return Log(
        name=name or bag_stem(path),
        kind="rosbag",
        source=path,
        scans=stream,
        odometry=odometry,
        imu=imu,
        meta=meta,
    )


def in_order_times(stamps: F64) -> tuple[F64, int]:
    """Times of messages given in publication order, with the clock's glitches taken out, and
    how many stamps were glitches.

    A topic's messages are published in the order of their ``header.seq``, so their true times
    never decrease in that order. The stamps kept are a longest nondecreasing run of them (not
    necessarily contiguous); each other stamp runs against the order of its neighbours and is
    replaced by the time linearly interpolated, by publication index, between the nearest kept
    stamps before and after it (the first or last kept stamp at the ends). Stamps already in
    order are returned unchanged.

    A stamp no smaller than every stamp before it and no larger than every one after it belongs
    to a longest run; between two such stamps the run is the longest among the stamps within
    their range (:func:`_longest_nondecreasing`), which keeps the search to the glitches.
    """
    t = np.asarray(stamps, dtype=np.float64)
    n = t.shape[0]
    if n < 2 or not np.any(np.diff(t) < 0):
        return t.copy(), 0
    kept = (t >= np.maximum.accumulate(t)) & (t <= np.minimum.accumulate(t[::-1])[::-1])
    loose = np.flatnonzero(~kept)
    for run in np.split(loose, np.flatnonzero(np.diff(loose) > 1) + 1):
        first, end = int(run[0]), int(run[-1]) + 1
        low = t[first - 1] if first > 0 else -np.inf
        high = t[end] if end < n else np.inf
        inside = run[(t[run] >= low) & (t[run] <= high)]
        if inside.size:
            kept[inside[_longest_nondecreasing(t[inside].tolist())]] = True
    index = np.arange(n, dtype=np.float64)
    return np.interp(index, index[kept], t[kept]), int(n - np.count_nonzero(kept))


def _longest_nondecreasing(values: list[float]) -> list[int]:
    """Indices of a longest nondecreasing subsequence of ``values`` (patience sorting)."""
    tails: list[float] = []  # tails[j]: smallest last value of a nondecreasing run of length j+1
    tail_index: list[int] = []
    previous = [-1] * len(values)
    for i, x in enumerate(values):
        j = bisect.bisect_right(tails, x)
        if j == len(tails):
            tails.append(x)
            tail_index.append(i)
        else:
            tails[j] = x
            tail_index[j] = i
        previous[i] = tail_index[j - 1] if j > 0 else -1
    out: list[int] = []
    i = tail_index[-1] if tail_index else -1
    while i >= 0:
        out.append(i)
        i = previous[i]
    return out[::-1]


def scan_odometry_in_order(
    scan_stamps: F64, odom_stamps: F64, odom_poses: F64, sync: str
) -> tuple[F64, int, int]:
    """Odometry pose ``(N, 3)`` at each scan when the stamps run against the publication order,
    and how many scan and odometry stamps were glitches.

    Scans and odometry messages are both given in publication order (``header.seq``). Each
    stream's times come from :func:`in_order_times`; the odometry pose at a scan is then
    interpolated at the scan's in-order time (``sync="interpolate"``) or the last one at or
    before it (``"latest"``), as :func:`load_bag` does with the stamps of a well-behaved bag.
    """
    scan_time, scan_glitches = in_order_times(scan_stamps)
    odom_time, odom_glitches = in_order_times(odom_stamps)
    if sync == "latest":
        last = np.clip(np.searchsorted(odom_time, scan_time, side="right") - 1, 0, None)
        poses = odom_poses[last].copy()
    else:
        poses = interpolate_poses(odom_time, odom_poses, scan_time)
    return poses, scan_glitches, odom_glitches


def _reorder_scans(scans: _ScanRows, order: NDArray[np.int64] | None) -> int:
    """Put the scan rows in ``order`` (in place: the ranges are not copied); how many moved."""
    if order is None:
        return 0
    moved = order != np.arange(order.shape[0])
    if not np.any(moved):
        return 0
    for rows in (scans.time, scans.geometry, scans.seq):
        rows.data[: rows.n] = rows.data[: rows.n][order]
    ranges = scans.ranges.data
    done = ~moved
    for start in np.flatnonzero(moved):  # follow each cycle of the permutation
        if done[start]:
            continue
        keep = ranges[start].copy()
        i = start
        while order[i] != start:
            ranges[i] = ranges[order[i]]
            done[i] = True
            i = order[i]
        ranges[i] = keep
        done[i] = True
    return int(np.count_nonzero(moved))


def bag_stem(path: Path) -> str:
    """The name of a bag: its file (or folder) name without ``.bag`` / ``.mcap`` / ``.db3``."""
    path = Path(path)
    if path.name == "metadata.yaml":
        path = path.parent
    name = path.name
    for suffix in (".bag", ".mcap", ".db3"):
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


def _drop_unread_indexes(reader: Any, keep: Sequence[Any]) -> None:
    """Free the ROS 1 reader's per-message index entries of topics the pass does not read.

    ``rosbags`` keeps one Python tuple per message of the bag (130 bytes each: 9 MB on intel, as
    much as its scans); dropping the unread ones (intel: the /tf copy of /odom) keeps the load
    within twice the loaded arrays. Relies on ``Reader.indexes`` (rosbags 0.11, pinned).
    """
    wanted = {c.id for c in keep}
    for sub in getattr(reader, "readers", ()):
        indexes = getattr(sub, "indexes", None)
        if isinstance(indexes, dict):
            for cid in indexes:
                if cid not in wanted:
                    indexes[cid] = []


def _first(reader: Any, conns: list[Any], msgtype: str, convert: Callable[[Any], Any]) -> Any:
    for _, _, raw in reader.messages(connections=conns):
        return convert(reader.deserialize(raw, msgtype))
    return None


def _need_tf(
    reader: Any,
    sel: _Selection,
    lidar: LidarConfig,
    parents: dict[str, _Edge],
    base: str | None,
    laser: str,
) -> bool:
    """Whether the pass reads /tf: for odometry from the transforms (or none known yet), or for a
    laser or IMU frame that tf_static does not hang below the robot frame ``base``."""
    if not sel.odom or base is None:
        return True
    frames = [laser] if lidar.use_log_laser_pose else []
    if sel.imu:
        imu_frame = _first(reader, sel.imu, IMU_TYPE, lambda m: m.header.frame_id.lstrip("/"))
        if imu_frame:
            frames.append(imu_frame)
    return any(f != base and _chain(parents, base, f) is None for f in frames)


def _read_tf(reader: Any, conns: list[Any]) -> list[_Edge]:
    edges: list[_Edge] = []
    if conns:
        for _, _, raw in reader.messages(connections=conns):
            edges.extend(_edges(reader.deserialize(raw, TF_TYPE)))
    return edges


def _stream(reader: Any, sel: _Selection, need_tf: bool, path: Path) -> _Streams:
    """One pass over the selected topics, filling preallocated per-topic arrays."""
    n_scan = sum(c.msgcount for c in sel.scan)
    scans = _ScanRows(
        _Rows(n_scan, 1, np.float64),
        _Rows(n_scan, 5, np.float64),
        _Rows(n_scan, 1, np.float32, np.nan),
        _Rows(n_scan, 1, np.int64),
    )
    out = _Streams(
        scans=scans,
        odom=_Rows(sum(c.msgcount for c in sel.odom), 7, np.float64) if sel.odom else None,
        odom_children=set(),
        dynamic={},
        first_edge={},
        imu=None,
        fast_decoder={},
    )
    imu_rows = _Rows(sum(c.msgcount for c in sel.imu), 7, np.float64) if sel.imu else None
    is2 = reader.is2
    ros1, cdr, convert = _SCAN_DECODERS[sel.scan_type]
    scan_decode = _decoder(reader, cdr if is2 else ros1, convert, sel.scan_type)
    odom_decode = _decoder(reader, _odom_cdr if is2 else _odom_ros1, _odom_msg, ODOM_TYPE)
    kinds = {id(c): "scan" for c in sel.scan}
    kinds.update({id(c): "odom" for c in sel.odom})
    kinds.update({id(c): "imu" for c in sel.imu})
    if need_tf:
        kinds.update({id(c): "tf" for c in sel.tf})
    selected = [c for c in reader.connections if id(c) in kinds]
    for conn, record_ns, raw in reader.messages(connections=selected):
        kind = kinds[id(conn)]
        if kind == "scan":
            _add_scan(scans, scan_decode(raw), record_ns, f"{path}: {conn.topic}")
        elif kind == "odom":
            o = odom_decode(raw)
            out.odom_children.add(o.child)
            t = _seconds(o.stamp_ns or record_ns)
            row = [t, o.x, o.y, o.yaw, o.speed, o.yaw_rate, o.seq]
            out.odom.append(row)  # type: ignore[union-attr]
        elif kind == "tf":
            for e in _edges(reader.deserialize(raw, TF_TYPE)):
                key = (e.parent, e.child)
                if key not in out.dynamic:
                    out.dynamic[key] = _Rows(1024, 5, np.float64)
                    out.first_edge[key] = e
                x, y, z, w = e.rotation
                out.dynamic[key].append(
                    [
                        _seconds(record_ns),
                        e.translation[0],
                        e.translation[1],
                        _yaw(x, y, z, w),
                        e.seq,
                    ]
                )
        else:
            m = reader.deserialize(raw, IMU_TYPE)
            out.imu_frames.add(m.header.frame_id)
            av, la = m.angular_velocity, m.linear_acceleration
            t = _seconds(_stamp(m.header) or record_ns)
            imu_rows.append([t, av.x, av.y, av.z, la.x, la.y, la.z])  # type: ignore[union-attr]
    out.fast_decoder["scan"] = scan_decode.state.get("fast", False)  # type: ignore[attr-defined]
    if sel.odom:
        out.fast_decoder["odom"] = odom_decode.state.get("fast", False)  # type: ignore[attr-defined]
    if imu_rows is not None and imu_rows.n:
        a = imu_rows.array()
        out.imu = ImuStream(
            time=a[:, 0].copy(),
            angular_velocity=np.ascontiguousarray(a[:, 1:4].T),
            linear_acceleration=np.ascontiguousarray(a[:, 4:7].T / STANDARD_GRAVITY),
        )
    return out


def _add_scan(scans: _ScanRows, s: _Scan, record_ns: int, topic: str) -> None:
    n = int(s.ranges.shape[0])
    if n > MAX_BEAMS:
        raise DataError(
            f"{topic}: scan {scans.time.n + 1} has {n} beams; expected at most {MAX_BEAMS}"
        )
    if not (math.isfinite(s.angle_min) and math.isfinite(s.angle_increment)):
        raise DataError(
            f"{topic}: scan {scans.time.n + 1}: expected finite angle_min and angle_increment, "
            f"found {s.angle_min} and {s.angle_increment}"
        )
    if s.angle_increment == 0 and n > 1:
        raise DataError(
            f"{topic}: scan {scans.time.n + 1}: angle_increment is 0, so all {n} beams would "
            "point the same way; expected the angle between neighbouring beams (rad)"
        )
    stamp = s.stamp_ns
    if stamp == 0:
        stamp = record_ns
        scans.record_time_stamps += 1
    scans.frames.add(s.frame.lstrip("/"))
    scans.time.append(_seconds(stamp))
    scans.geometry.append([s.angle_min, s.angle_increment, s.range_min, s.range_max, n])
    scans.ranges.append(s.ranges, width=n)
    scans.seq.append(s.seq)


def _robot_odometry(
    path: Path,
    sel: _Selection,
    options: BagOptions,
    streams: _Streams,
    parents: dict[str, _Edge],
    laser: str,
    base: str | None,
    notes: list[str],
) -> tuple[str, OdometryStream | None, str, F64 | None]:
    """The robot frame, the odometry stream, its source and the odometry in publication order
    (:func:`_odometry`); ``base`` is the frame known before the pass (``--base-frame``, the
    Odometry messages' child), ``None`` for tf odometry or none.

    A bag without odometry (:data:`NO_ODOMETRY`, or /tf moving no frame above the laser and no
    option asking for it) gives ``(robot frame, None, "none", None)``: the robot frame is then
    the top of the laser's tf_static chain (:func:`_static_base`).
    """
    if base is None and sel.odom_topic == TF_TOPIC:
        base = _tf_base(path, parents, streams.dynamic, laser, options, notes)
    if base is None:
        return _static_base(parents, laser), None, NO_ODOMETRY, None
    odometry, source, published = _odometry(path, sel, streams, base)
    return base, odometry, source, published


def _tf_base(
    path: Path,
    parents: dict[str, _Edge],
    dynamic: dict[tuple[str, str], _Rows],
    laser: str,
    options: BagOptions,
    notes: list[str],
) -> str | None:
    """The robot frame for tf odometry: the first frame above the laser with a moving parent.

    Without one the bag has no odometry (``None``, and a line in ``notes`` saying what /tf
    holds), unless ``--odom-topic tf`` asked for it: then a :class:`DataError`.
    """
    parent_of = {child: edge.parent for child, edge in parents.items()}
    base = _moving_ancestor(parent_of, {child for _, child in dynamic}, laser)
    if base is not None:
        return base
    found = (
        f"no {ODOM_TYPE} topic, and no moving /tf transform above the laser frame {laser!r} "
        f"(moving transforms: {_edge_list(dynamic) or 'none'})"
    )
    if options.odom_topic is not None:
        raise DataError(f"{path}: no odometry: {found}; pass --base-frame or --odom-topic")
    notes.append(f"no odometry: {found}; --base-frame or --odom-topic names the robot's")
    return None


def _moving_ancestor(parent_of: dict[str, str], moving: set[str], laser: str) -> str | None:
    """The first frame at or above ``laser`` (along the static ``parent_of``) that is in
    ``moving`` (the children of /tf transforms), or ``None``."""
    current: str | None = laser
    seen = 0
    while current is not None and seen < 64:
        if current in moving:
            return current
        current = parent_of.get(current)
        seen += 1
    return None


def _static_base(parents: dict[str, _Edge], laser: str) -> str:
    """The robot frame of a bag without odometry: the top of the laser's tf_static chain (below
    any :data:`WORLD_FRAMES`), or the laser frame itself when tf_static does not mount it."""
    current = laser
    for _ in range(64):
        edge = parents.get(current)
        if edge is None or edge.parent in WORLD_FRAMES:
            break
        current = edge.parent
    return current


def _edge_list(dynamic: dict[tuple[str, str], _Rows]) -> str:
    return ", ".join(f"{p} → {c}" for p, c in sorted(dynamic))


def _odometry(
    path: Path, sel: _Selection, streams: _Streams, base: str
) -> tuple[OdometryStream, str, F64]:
    """The odometry stream (sorted by stamp), its source, and ``(time, x, y, yaw)`` per message
    in publication order (``header.seq`` when usable, else the stamp order)."""
    dynamic = streams.dynamic
    if streams.odom is not None:
        a = streams.odom.array()
        if a.shape[0] == 0:
            raise DataError(f"{path}: {sel.odom_topic} holds no messages")
        _check_finite(a, f"{path}: {sel.odom_topic}")
        children = {c.lstrip("/") for c in streams.odom_children} - {""}
        if children and base not in children:
            raise DataError(
                f"{path}: {sel.odom_topic} describes frame {', '.join(sorted(children))}, "
                f"not the robot frame {base!r} (--base-frame)"
            )
        published = _published(a, 6)
        if np.any(np.diff(a[:, 0]) < 0):
            a = a[np.argsort(a[:, 0], kind="stable")]
        return (
            OdometryStream(
                time=a[:, 0].copy(), poses=a[:, 1:4].copy(), velocities=a[:, 4:6].copy()
            ),
            sel.odom_topic,
            a[:, :4] if published is None else published,
        )
    edges = [k for k in dynamic if k[1] == base]
    if len(edges) != 1:
        found = "none" if not edges else ", ".join(f"{p} → {c}" for p, c in edges)
        raise DataError(
            f"{path}: no odometry for the robot frame {base!r}: expected one moving /tf transform "
            f"to it, found {found} (moving transforms: {_edge_list(dynamic) or 'none'})"
        )
    a = dynamic[edges[0]].array()
    _check_finite(a, f"{path}: /tf {edges[0][0]} → {base}")
    published = _published(a, 4)
    order = np.argsort(a[:, 0], kind="stable")
    a = a[order]
    return (
        OdometryStream(time=a[:, 0].copy(), poses=a[:, 1:4].copy(), velocities=_velocities(a)),
        f"tf:{edges[0][0]}->{base}",
        a[:, :4] if published is None else published,
    )


def _check_finite(rows: F64, where: str) -> None:
    """Refuse odometry rows ``(time, x, y, yaw, ...)`` with a stamp or pose that is not finite,
    naming the message (1-based, in the bag's order) and its values: a NaN pose would reach the
    numba kernels, which do not check."""
    bad = ~np.isfinite(rows[:, :4]).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        t, x, y, yaw = (float(v) for v in rows[i, :4])
        raise DataError(
            f"{where}: message {i + 1}: expected a finite stamp and pose, found t={t}, x={x}, "
            f"y={y}, yaw={yaw} ({int(bad.sum())} such message(s))"
        )


def _published(rows: F64, seq_column: int) -> F64 | None:
    """``(time, x, y, yaw)`` of odometry rows in ``header.seq`` order, or ``None`` when the
    sequence numbers are unusable (:func:`publication_order`)."""
    order = publication_order(rows[:, seq_column].astype(np.int64))
    return None if order is None else rows[order, :4]


def publication_order(seq: NDArray[np.int64]) -> NDArray[np.int64] | None:
    """The order in which a topic's messages were published: by ROS 1 ``header.seq``, the
    publisher's counter. ``None`` when the counter cannot tell: a message without one (ROS 2
    headers have no ``seq``) or a number seen twice (several publishers, a restarted node)."""
    if seq.shape[0] == 0 or np.any(seq < 0):
        return None
    order = np.argsort(seq, kind="stable")
    if np.any(np.diff(seq[order]) == 0):
        return None
    return order


def _velocities(a: F64) -> F64:
    """Forward speed and yaw rate of tf odometry by finite differences (0 where dt is 0)."""
    out = np.zeros((a.shape[0], 2))
    if a.shape[0] < 2:
        return out
    dt = np.diff(a[:, 0])
    dx, dy = np.diff(a[:, 1]), np.diff(a[:, 2])
    dth = np.angle(np.exp(1j * np.diff(a[:, 3])))
    forward = np.cos(a[:-1, 3]) * dx + np.sin(a[:-1, 3]) * dy
    ok = dt > 0
    out[1:, 0][ok] = forward[ok] / dt[ok]
    out[1:, 1][ok] = dth[ok] / dt[ok]
    return out


def _laser_offset(
    path: Path,
    lidar: LidarConfig,
    parents: dict[str, _Edge],
    streams: _Streams,
    base: str,
    laser: str,
) -> tuple[F64, bool, str]:
    if not lidar.use_log_laser_pose:
        return np.array([lidar.x, lidar.y, lidar.yaw], dtype=np.float64), False, "config"
    if base == laser:
        return np.zeros(3), False, "same frame"
    chain, source = _find_chain(parents, streams, base, laser)
    if chain is None:
        static = ", ".join(f"{e.parent} → {e.child}" for e in parents.values()) or "none"
        raise DataError(
            f"{path}: no transform from the robot frame {base!r} to the laser frame {laser!r} "
            f"(tf_static: {static}; tf: {_edge_list(streams.dynamic) or 'none'}); pass --base-frame, or "
            f"set lidar.use_log_laser_pose = false and lidar.x/y/yaw (--set)"
        )
    offset, upside_down = mounting(path, chain)
    return offset, upside_down, source


def _find_chain(
    parents: dict[str, _Edge], streams: _Streams, base: str, frame: str
) -> tuple[list[_Edge] | None, str]:
    """The edges from ``base`` down to ``frame`` and where they came from: ``tf_static``, else
    ``tf`` (with the first /tf transform of each moving frame), else ``(None, "none")``."""
    chain = _chain(parents, base, frame)
    if chain is not None:
        return chain, "tf_static"
    moving = {child: edge for (_, child), edge in streams.first_edge.items()}
    chain = _chain({**moving, **parents}, base, frame)
    return chain, "none" if chain is None else "tf"


def _imu_in_robot_frame(
    streams: _Streams, parents: dict[str, _Edge], base: str, notes: list[str]
) -> tuple[ImuStream | None, dict[str, Any]]:
    """The IMU readings rotated into the robot frame ``base`` and the ``meta`` entries saying so.

    The rotation is the full 3D one of the chain ``base → … → IMU frame`` (:func:`_find_chain`),
    so row 2 of ``angular_velocity`` becomes the yaw rate about the robot's z axis. Readings in
    the robot frame itself stay as they are; so do those without a chain (a line in ``notes``).
    """
    imu = streams.imu
    if imu is None:
        return None, {}
    frames = sorted({f.lstrip("/") for f in streams.imu_frames})
    frame = frames[0] if len(frames) == 1 else ""
    chain: list[_Edge] | None = None
    source = "none"
    if frame == base:
        source = "same frame"
    elif frame:
        chain, source = _find_chain(parents, streams, base, frame)
    meta = {
        "imu_frame": ", ".join(frames),
        "imu_rotated": chain is not None,
        "imu_frame_source": source,
    }
    if source == "none":
        why = (
            f"its messages name several frames ({', '.join(frames)})"
            if len(frames) > 1
            else f"no transform from the robot frame {base!r} to the IMU frame {frame!r}"
            if frame
            else "its messages name no frame"
        )
        notes.append(f"IMU readings as recorded, not rotated into the robot frame: {why}")
    if chain is None:
        return imu, meta
    rotation = _compose(chain)[:3, :3]
    return dataclasses.replace(
        imu,
        angular_velocity=rotation @ imu.angular_velocity,
        linear_acceleration=rotation @ imu.linear_acceleration,
    ), meta


def _scan_stream(
    path: Path,
    topic: str,
    scans: _ScanRows,
    lidar: LidarConfig,
    offset: F64,
    upside_down: bool,
) -> ScanStream:
    """Arrays of the scans with invalid beams marked and the shared or per-scan angles."""
    if len(scans.frames) > 1:
        raise DataError(
            f"{path}: {topic} mixes laser frames ({', '.join(sorted(scans.frames))}); "
            f"expected one laser per topic"
        )
    geometry = scans.geometry.array()
    time = scans.time.array()[:, 0].copy()
    ranges = scans.ranges.array()
    if ranges.shape[1] == 0 or not np.any(geometry[:, 4] > 0):
        raise DataError(f"{path}: {topic}: every scan has 0 beams")
    amin, inc, rmin, rmax, beams = geometry.T
    bad = np.flatnonzero(~(np.isfinite(rmin) & (rmax > rmin) & (rmax > 0)))  # NaN fails too
    if bad.size:  # REP 117: range_max is the laser's longest reading, past range_min
        k = int(bad[0])
        raise DataError(
            f"{path}: {topic} message at t = {time[k]:.6f} s ({bad.size} of {len(time)} messages): "
            f"expected a range_max above range_min and 0 (m), found range_min {rmin[k]:g}, "
            f"range_max {rmax[k]:g}"
        )
    beams = beams.astype(np.int64)
    width = ranges.shape[1]
    range_min = float(np.min(rmin)) if lidar.range_min is None else lidar.range_min
    no_return = float(np.max(rmax)) if lidar.no_return is None else lidar.no_return
    range_max = no_return if lidar.range_max is None else lidar.range_max
    invalid = 0
    for start in range(0, ranges.shape[0], _BLOCK):  # blocks bound the temporaries' memory
        rows = slice(start, start + _BLOCK)
        invalid += _mark_beams(
            ranges[rows], beams[rows], rmin[rows], rmax[rows], range_min, no_return
        )
    sign = -1.0 if upside_down else 1.0
    same = np.all(amin == amin[0]) and np.all(inc == inc[0]) and np.all(beams == beams[0])
    if same:
        angles = sign * (amin[0] + inc[0] * np.arange(width))
    else:
        angles = sign * (amin[:, None] + inc[:, None] * np.arange(width)[None, :])
        angles[np.arange(width)[None, :] >= beams[:, None]] = np.nan
    return ScanStream(
        time=time,
        ranges=ranges,
        angles=angles,
        range_min=range_min,
        range_max=float(range_max),
        no_return=float(no_return),
        laser_offset=offset,
        invalid_beams=invalid,
    )


_BLOCK = 2048
"""Scans whose beams :func:`_mark_beams` classifies at a time."""


def _mark_beams(
    ranges: NDArray[np.float32],
    beams: NDArray[np.int64],
    rmin: F64,
    rmax: F64,
    range_min: float,
    no_return: float,
) -> int:
    """In place: readings at or beyond their message's ``range_max`` (and +inf) become "no
    return" (at least ``no_return``), invalid ones NaN; padding beams stay NaN. Returns how many
    readings were invalid."""
    padded = np.arange(ranges.shape[1])[None, :] >= beams[:, None]
    with np.errstate(invalid="ignore"):
        beyond = ranges >= rmax[:, None].astype(np.float32)
        beyond &= ~padded
        ranges[beyond] = np.maximum(ranges[beyond], np.float32(no_return))
        row_min = np.maximum(rmin, range_min)[:, None].astype(np.float32)
        invalid = ~np.isfinite(ranges) | (ranges < row_min) | (ranges < 0)
    invalid &= ~padded
    invalid &= ~beyond
    ranges[invalid] = np.nan
    return int(np.count_nonzero(invalid))


# --- inspection ---------------------------------------------------------------------------


def inspect_bag(path: Path, options: BagOptions | None = None) -> dict[str, Any]:
    """What the bag at ``path`` holds (``slam data inspect``): per topic its type, message count,
    rate and time span; the frames of ``/tf`` and ``/tf_static``; and what ``slam run`` would
    read from it (or the error it would stop with: the bag is loaded as the run loads it, so a
    frame chain or a mount the run refuses is found here too). Reads every message's record time
    and deserializes the tf messages, then loads the bag."""
    path = Path(path)
    options = options or BagOptions()
    with open_bag(path) as (reader, fmt):
        topics = _topics(reader)
        spans: dict[str, list[float]] = {}
        counts: dict[str, int] = {}
        tf_edges: dict[tuple[str, str, bool], int] = {}
        for conn, record_ns, raw in reader.messages():
            span = spans.setdefault(conn.topic, [math.inf, -math.inf])
            t = _seconds(record_ns)
            span[0], span[1] = min(span[0], t), max(span[1], t)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            if conn.msgtype == TF_TYPE:
                static = conn.topic.endswith("tf_static")
                for e in _edges(reader.deserialize(raw, TF_TYPE)):
                    key = (e.parent, e.child, static)
                    tf_edges[key] = tf_edges.get(key, 0) + 1
        start, end = _seconds(reader.start_time), _seconds(reader.end_time)
        if not counts:  # an empty bag: the readers' start and end are their sentinels
            start = end = 0.0
        try:
            sel = select_topics(path, reader, options)
            plan: dict[str, Any] = {
                "scan_topic": sel.scan_topic,
                "scan_type": sel.scan_type,
                "odom_source": _planned_odometry(reader, sel, options, tf_edges),
            }
            if sel.imu:
                plan["imu_topic"] = sel.imu[0].topic
            plan["command"] = _command(path, options)
        except (DataError, UsageError) as exc:
            plan = {"error": str(exc), "command": None}
    if plan["command"] is not None:  # the frames, the mount, the odometry: what the run reads
        from slam.config import Config
        from slam.io.plausibility import odometry_jump

        try:
            jump = odometry_jump(load_bag(path, options=options), Config())
        except (DataError, UsageError) as exc:
            jump = str(exc)
        if jump is not None:
            plan = {"error": jump, "command": None}
    rows = []
    for topic, msgtype, _ in topics:
        first, last = spans.get(topic, [math.nan, math.nan])
        n = counts.get(topic, 0)
        duration = last - first if n else 0.0
        rows.append(
            {
                "topic": topic,
                "type": msgtype,
                "count": n,
                "rate_hz": round((n - 1) / duration, 3) if n > 1 and duration > 0 else 0.0,
                "first_s": first if n else None,
                "last_s": last if n else None,
            }
        )
    return {
        "path": str(path),
        "format": fmt,
        "start_s": start,
        "end_s": end,
        "duration_s": round(end - start, 6),
        "messages": sum(counts.values()),
        "topics": rows,
        "tf": [
            {"parent": p, "child": c, "static": s, "count": n}
            for (p, c, s), n in sorted(tf_edges.items())
        ],
        "run": plan,
    }


def _planned_odometry(
    reader: Any, sel: _Selection, options: BagOptions, tf_edges: dict[tuple[str, str, bool], int]
) -> str:
    """The odometry :func:`load_bag` reads: the Odometry topic, ``tf``, or none (the run's is
    then the laser's), decided as it does from the frames of /tf and /tf_static."""
    source = sel.odom_topic
    if source == TF_TOPIC and options.odom_topic is None and options.base_frame is None:
        first = _first(reader, sel.scan, sel.scan_type, _SCAN_DECODERS[sel.scan_type][2])
        parent_of = {c: p for p, c, static in tf_edges if static}
        moving = {c for _, c, static in tf_edges if not static}
        if (
            first is not None
            and _moving_ancestor(parent_of, moving, first.frame.lstrip("/")) is None
        ):
            source = NO_ODOMETRY
    return f"{NO_ODOMETRY} (laser odometry)" if source == NO_ODOMETRY else source


def _command(path: Path, options: BagOptions) -> str:
    import shlex

    parts = ["slam", "run", shlex.quote(str(path))]
    for flag, value in (
        ("--scan-topic", options.scan_topic),
        ("--odom-topic", options.odom_topic),
        ("--base-frame", options.base_frame),
        ("--odom-sync", None if options.odom_sync == "interpolate" else options.odom_sync),
    ):
        if value is not None:
            parts += [flag, shlex.quote(value)]
    return " ".join(parts)
