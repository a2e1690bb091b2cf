"""Reading a CARMEN log and writing a new copy of it: what the robustness tools share.

``tools/perturb_odometry.py`` (the odometry rescaled), ``tools/perturb_ranges.py`` (noisier
readings) and ``tools/crop_log.py`` (the first records dropped) read a log as text lines,
gzipped or not (by its content), and write their copy whole or not at all, never over an
existing file, compressed when its name ends in ``.gz``.
Errors are :class:`LogFileError`, one line naming the file and what was expected.
"""

from __future__ import annotations

import gzip
import os
import tempfile
from pathlib import Path


class LogFileError(Exception):
    """A log that cannot be read as text, or an output that cannot be written new."""


def read_lines(path: Path) -> list[str]:
    """The lines of the log ``path`` (without their line ends), gunzipped when it is gzip."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise LogFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError) as exc:
            raise LogFileError(f"{path}: a gzip file that does not decompress: {exc}") from None
    try:
        return raw.decode("utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise LogFileError(f"{path}: not a text log (byte {exc.start} is not UTF-8)") from None


def write_new(path: Path, lines: list[str]) -> None:
    """Write ``lines`` to ``path`` whole (a temporary file in its folder, then linked into
    place), never replacing a file; gzip-compressed when the name ends in ``.gz``."""
    if path.exists() or path.is_symlink():
        raise LogFileError(f"{path}: exists; the output is never replaced (choose another name)")
    if not path.parent.is_dir():
        raise LogFileError(f"{path.parent}: no such folder for the output")
    data = ("\n".join(lines) + "\n").encode("utf-8")
    if path.suffix == ".gz":
        data = gzip.compress(data, mtime=0)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # as a plain open() would create it, not mkstemp's 0600
        os.link(tmp, path)  # fails if the output appeared meanwhile: never replaced
    except FileExistsError:
        raise LogFileError(
            f"{path}: exists; the output is never replaced (choose another name)"
        ) from None
    finally:
        os.unlink(tmp)


def flaser_size(fields: list[str], where: str) -> int:
    """The number of readings of a ``FLASER`` line split into ``fields``, checked against the
    line's length (the readings, then six pose numbers and the time); ``where`` names the file
    and line in the :class:`LogFileError` a malformed line raises."""
    try:
        n = int(fields[1])
    except (IndexError, ValueError):
        raise LogFileError(
            f"{where}: expected FLASER num_readings ..., found {fields[:2]}"
        ) from None
    if n < 0 or len(fields) < n + 8:
        raise LogFileError(
            f"{where}: expected {n + 8} fields or more for {n} readings, found {len(fields)}"
        )
    return n
