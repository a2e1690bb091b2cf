"""What a log path is, decided by its content: ROS bags, MCAP, CARMEN text, ECE276A folders.

This module owns format detection: :func:`detect_format` looks at magic bytes and folder
contents, never at the file name alone, so a wrong guess never ends in a parse error of another
format (``intel.orig.bag`` used to be parsed as CARMEN text). The names it returns are the
:data:`FORMATS`; loaders are chosen from them (:func:`slam.pipeline.load_source`).

=============  ===============================================================================
format         recognised by
=============  ===============================================================================
``ros1``       the first 13 bytes ``#ROSBAG V2.0\\n`` (ROS 1 bag)
``mcap``       the first 8 bytes ``\\x89MCAP0\\r\\n`` (a bare MCAP file, e.g. ``ros2 bag``'s
               storage file or one written by the ``mcap`` library)
``rosbag2``    a folder holding ``metadata.yaml`` (a ROS 2 bag, sqlite3 or MCAP storage), or
               that ``metadata.yaml`` itself
``carmen``     gzip magic ``\\x1f\\x8b`` whose stream starts with text, or a file starting with
               text (CARMEN ``.clf``/``.log``)
``ece276a``    a folder holding exactly one ``EncodersNN.npz``
=============  ===============================================================================

Anything else (an SQLite file on its own, a zip, a folder without either marker) is a
:class:`~slam.errors.DataError` that says what was found and what would have been accepted.
"""

from __future__ import annotations

import zlib
from pathlib import Path

from slam.errors import DataError

FORMATS: tuple[str, ...] = ("ros1", "mcap", "rosbag2", "carmen", "ece276a")
"""Names :func:`detect_format` returns."""

BAG_FORMATS: tuple[str, ...] = ("ros1", "mcap", "rosbag2")
"""Formats read by :mod:`slam.io.rosbag` (their geometry comes from the messages)."""

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
GZIP_MAGIC = b"\x1f\x8b"
SQLITE_MAGIC = b"SQLite format 3\x00"
ZIP_MAGIC = b"PK\x03\x04"
ROSBAG2_METADATA = "metadata.yaml"

_PEEK = 4096
"""Bytes read (and, for gzip, decompressed) to decide."""

_ACCEPTED = (
    "a ROS 1 bag, an MCAP file, a ROS 2 bag folder (metadata.yaml), a CARMEN log "
    "(.clf/.log, optionally gzip) or an ECE276A folder (EncodersNN.npz)"
)


def detect_format(path: Path) -> str:
    """The format of the log at ``path`` (one of :data:`FORMATS`), judged by its content.

    Raises :class:`DataError` naming the path when it is missing, unreadable or none of them.
    """
    path = Path(path)
    try:
        if path.is_dir():
            return _folder_format(path)
        if not path.is_file():
            from slam.io.datadir import is_present

            if not is_present(path):  # a pipe, a socket, a broken link: one error naming it
                raise FileNotFoundError
        with open(path, "rb") as fh:
            head = fh.read(_PEEK)
    except FileNotFoundError:
        raise DataError(f"{path}: not found (expected {_ACCEPTED})") from None
    except PermissionError:
        raise DataError(f"{path}: cannot read (permission denied)") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if head.startswith(ROS1_MAGIC):
        return "ros1"
    if head.startswith(b"#ROSBAG V"):
        version = head.split(b"\n", 1)[0].decode("ascii", "replace")
        raise DataError(
            f"{path}: a ROS bag of version {version[len('#ROSBAG V') :]!r}; only version 2.0 "
            f"(ROS 1 since 2010) can be read"
        )
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if path.name == ROSBAG2_METADATA:
        return "rosbag2"
    if head.startswith(SQLITE_MAGIC):
        hint = (
            f"pass its folder {path.parent}"
            if (path.parent / ROSBAG2_METADATA).is_file()
            else "a ROS 2 bag needs its folder with metadata.yaml"
        )
        raise DataError(f"{path}: an SQLite database (a ROS 2 bag's storage file?); {hint}")
    if head.startswith(GZIP_MAGIC):
        inner = _gunzip_head(head)
        problem = None if inner is None else _text_problem(path, inner, " (inside the gzip)")
        if problem is not None:
            raise DataError(problem)
        if inner is None or not _looks_like_text(inner):
            raise DataError(
                f"{path}: a gzip file whose content is not text; expected a gzipped CARMEN log"
            )
        return "carmen"
    if not head:
        raise DataError(f"{path}: empty file (expected {_ACCEPTED})")
    problem = _text_problem(path, head)
    if problem is not None:
        raise DataError(problem)
    if _looks_like_text(head):
        return "carmen"
    kind = "a zip archive (.npz?)" if head.startswith(ZIP_MAGIC) else "binary data"
    raise DataError(
        f"{path}: unknown format: found {kind} starting with {head[:8]!r}; expected {_ACCEPTED}"
    )


def _folder_format(path: Path) -> str:
    if (path / ROSBAG2_METADATA).is_file():
        return "rosbag2"
    encoders = sorted(p.name for p in path.glob("Encoders*.npz"))
    if len(encoders) == 1:
        return "ece276a"
    if encoders:
        raise DataError(
            f"{path}: expected one EncodersNN.npz in an ECE276A dataset folder, "
            f"found {len(encoders)} ({', '.join(encoders)})"
        )
    raise DataError(
        f"{path}: a folder with neither metadata.yaml (ROS 2 bag) nor EncodersNN.npz (ECE276A); "
        f"expected {_ACCEPTED}"
    )


def _gunzip_head(head: bytes) -> bytes | None:
    """The first decompressed bytes of a gzip stream that starts with ``head``."""
    try:
        return zlib.decompressobj(wbits=31).decompress(head, _PEEK)
    except zlib.error:
        return None


def _text_problem(path: Path, data: bytes, where: str = "") -> str | None:
    """What keeps text that is almost a CARMEN log from being one (a UTF-8 byte-order mark,
    another encoding than UTF-8), as a message, else ``None``."""
    if data.startswith(b"\xef\xbb\xbf"):
        return (
            f"{path}:1: a UTF-8 byte-order mark before the first line{where}; a CARMEN log is "
            "plain text: save it without the mark"
        )
    if not _looks_like_text(data) and _looks_like_text(data.decode("latin-1").encode("utf-8")):
        return f"{path}: {_first_non_utf8(data)}{where}; a CARMEN log is UTF-8 (ASCII) text"
    return None


def _first_non_utf8(data: bytes) -> str:
    """``"line L: non-UTF-8 byte 0xNN (byte offset K)"`` of the first such byte in ``data``."""
    try:
        data.decode("utf-8")
        return "no non-UTF-8 byte"
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        return f"line {line}: non-UTF-8 byte 0x{data[exc.start]:02x} (byte offset {exc.start})"


def _looks_like_text(data: bytes) -> bool:
    """UTF-8 without control bytes other than tab, CR and LF (the last character may be cut)."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(data) - 3:  # not just a multi-byte character cut by the peek
            return False
        text = data[: exc.start].decode("utf-8")
    return all(c >= " " or c in "\t\r\n" for c in text)


def run_config_name(name: str) -> tuple[str, bool]:
    """``(dataset name, use its shipped config)`` of ``slam run NAME`` for a NAME that may be a path.

    A registry name (or anything that is not an existing path) is its own dataset name and uses
    ``configs/<name>.toml``. A CARMEN log or ECE276A folder given by path is named by its file
    name up to the first dot and uses that shipped configuration when there is one: FLASER
    lines carry no beam geometry, so ``slam run data/carmen/intel.clf.gz`` needs
    ``configs/intel.toml`` as ``slam run intel`` does. A bag or MCAP file carries its geometry
    (LaserScan fields, tf_static): it is named by :func:`slam.io.rosbag.bag_stem` (``intel.orig``
    for ``intel.orig.bag``) and never picks up a shipped configuration, whatever it is called;
    ``--config`` and ``--set`` still apply. A file name that differs from a shipped configuration's
    only by letter case (``Intel.clf.gz``) picks up none (:func:`slam.config.case_variant`).
    """
    from slam.config import case_variant

    path = Path(name)
    if not path.exists():
        return name, True
    fmt = detect_format(path)
    if fmt in BAG_FORMATS:
        from slam.io.rosbag import bag_stem

        return bag_stem(path), False
    stem = path.name.split(".")[0]
    return stem, case_variant(stem) is None
