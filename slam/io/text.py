"""Reading and decoding the files the loaders read, with errors that name the file (and line)."""

from __future__ import annotations

from pathlib import Path

from slam.errors import DataError, SlamError


def decode_utf8(path: Path, raw: bytes, error: type[SlamError] = DataError) -> str:
    """``raw`` (the contents of ``path``) as UTF-8 text; ``error`` naming the file, the line, the
    offending byte and its offset in the file when it is not text."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        lineno = raw.count(b"\n", 0, exc.start) + 1
        raise error(
            f"{path}:{lineno}: expected text, found the non-text byte 0x{raw[exc.start]:02x} "
            f"(byte offset {exc.start}; the file must be UTF-8)"
        ) from None


def read_input(
    path: Path,
    missing: str,
    folder: str | None,
    unreadable: str,
    error: type[SlamError] = DataError,
) -> bytes:
    """The bytes of the input file ``path``; ``error`` ``"{path}: {missing}"`` when it does not
    exist, ``"{path}: {folder}"`` when it is a folder (``folder`` None: as any other reason),
    ``"{path}: {unreadable} (reason)"`` when it cannot be read."""
    try:
        return path.read_bytes()
    except OSError as exc:
        if isinstance(exc, FileNotFoundError):
            message = missing
        elif isinstance(exc, IsADirectoryError) and folder is not None:
            message = folder
        else:
            message = f"{unreadable} ({exc.strerror or exc})"
        raise error(f"{path}: {message}") from None
