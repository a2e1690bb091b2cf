"""Locating the data directory (user datasets) and a writable cache (generated datasets).

The data directory is ``--data-dir`` if given, else ``$SLAM_DATA_DIR``, else ``./data``. It may be
read-only (CI points it at a shared folder), and it holds the user's data only: generated data
such as the simulator's demo goes to the cache, ``$SLAM_CACHE_DIR`` if set, else
``$XDG_CACHE_HOME/slam``, else ``~/.cache/slam`` — never into the data directory.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from slam.errors import DataError, UsageError

DATA_DIR_ENV = "SLAM_DATA_DIR"
CACHE_DIR_ENV = "SLAM_CACHE_DIR"


def resolve_data_dir(cli_value: str | Path | None = None) -> Path:
    """The data directory: ``cli_value``, else ``$SLAM_DATA_DIR``, else ``./data``."""
    if cli_value:
        return Path(cli_value).expanduser()
    env = os.environ.get(DATA_DIR_ENV)
    if env:
        return Path(env).expanduser()
    return Path("data")


def resolve_cache_dir() -> Path:
    """A writable folder for generated datasets (see the module docstring for the order)."""
    env = os.environ.get(CACHE_DIR_ENV)
    if env:
        folder = Path(env).expanduser()
        if folder.exists() and not folder.is_dir():
            raise UsageError(
                f"${CACHE_DIR_ENV} = {env}: expected a folder for the generated datasets, found "
                "a file"
            )
        return folder
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "slam"


def check_readable_dir(folder: Path, what: str = "folder") -> bool:
    """Whether ``folder`` exists; :class:`DataError` naming it when it exists but cannot be read
    (no read or search permission) or is not a folder."""
    folder = Path(folder)
    try:
        if not folder.exists():
            return False
        if not folder.is_dir():
            raise DataError(f"{folder}: expected the {what}, found a file")
    except PermissionError:
        raise DataError(f"{folder}: cannot read the {what} (permission denied)") from None
    if not os.access(folder, os.R_OK | os.X_OK):
        raise DataError(f"{folder}: cannot read the {what} (permission denied)")
    return True


def _kind(mode: int) -> str:
    """What a non-regular file is, for messages."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a regular file" if stat.S_ISREG(mode) else "not a regular file"


def is_present(path: Path, *, folder: bool = False, strict: bool = True) -> bool:
    """Whether ``path`` is an existing file (a folder when ``folder``).

    ``False`` when nothing is there. Something else in its place (a folder where a file is
    expected or the reverse, a symbolic link loop, a link to nothing, a pipe) is a
    :class:`DataError` naming the path and what it is (``strict``; else ``False``, for listings);
    so is a parent that cannot be searched.
    """
    path = Path(path)
    try:
        if path.is_dir() if folder else path.is_file():
            return True
        if not strict:
            return False
        try:
            link = path.lstat()
        except FileNotFoundError:
            return False
        if stat.S_ISLNK(link.st_mode):
            try:
                target = path.stat()
            except OSError as exc:
                if exc.errno == errno.ELOOP:
                    raise DataError(
                        f"{path}: is a symbolic link loop, expected a "
                        f"{'folder' if folder else 'file'}"
                    ) from None
                raise DataError(
                    f"{path}: is a symbolic link to {os.readlink(path)!r}, which does not "
                    f"exist (expected a {'folder' if folder else 'file'})"
                ) from None
            mode = target.st_mode
        else:
            mode = link.st_mode
    except PermissionError:
        raise DataError(f"{path}: cannot read (permission denied)") from None
    expected = "a folder" if folder else "a file"
    raise DataError(f"{path}: expected {expected}, found {_kind(mode)}")


def put_files_hint(inside: str, count: int = 1) -> str:
    """The end of a "missing file" message: where the ``count`` files named by ``inside`` (paths
    relative to a data directory) should go."""
    return (
        f"Put the file{'s' if count > 1 else ''} there, or point --data-dir (or {DATA_DIR_ENV}) "
        f"at a data directory that has {inside}; see docs/data.md"
    )
