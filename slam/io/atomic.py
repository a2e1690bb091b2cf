"""Atomic writes: outputs appear whole or not at all, and replace only what slam wrote.

Files are written to a temporary sibling and renamed into place. Output folders (a run folder,
a simulated dataset) are assembled in a partial sibling folder (:mod:`slam.io.runfolder`) and
renamed into place when complete, so an interrupted or failed command leaves no half-written
output behind. Everything is created with the modes ``mkdir`` and ``open`` give under the
process's umask (folders ``0o777 & ~umask``, files ``0o666 & ~umask``). :func:`write_png` is the
project's one PNG writer (run pictures, simulated frames, maze and grid-study plots).

The folder protocol (:func:`atomic_dir`):

* before any work, :func:`check_output_dir` refuses a destination that is a symbolic link, a
  file, under a file, a mount point, ends in ``..``, holds one of the command's inputs, or exists
  and is not empty — unless ``force`` is given and it is a finished output folder of the same
  kind (:func:`slam.io.runfolder.is_own_output`) that holds nothing slam did not write
  (:func:`slam.io.runfolder.foreign_entries`: a note or plots the user saved into it make
  ``--force`` refuse, naming them);
* stale partial folders of dead processes in the destination's parent are removed, and a live
  process writing the same destination makes this one stop (exit 2) before it starts;
* the final rename never replaces a folder that appeared meanwhile: ``renameat2`` with
  ``RENAME_NOREPLACE`` (Linux), else an exclusive ``mkdir`` of the destination followed by a
  rename onto that still-empty folder (a rename onto a non-empty folder fails). With ``force``
  the old folder is swapped out with ``RENAME_EXCHANGE`` (else moved aside first) and deleted
  only after checking it is the very folder (same device and inode) found to be ours, still
  holding nothing slam did not write (a file saved into it meanwhile makes the command fail and
  keeps the folder as it is);
* a finished output that could not be put at its destination that way (a folder appeared there,
  or the one to replace changed) is not lost: it is renamed to the first free ``<destination>-N``
  (N = 2, 3, …) and the error (exit 2) says where it is.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import secrets
import signal
import stat
import sys
import threading
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slam.errors import Terminated, UsageError, raise_pending_termination
from slam.io.runfolder import (
    OWNER_FILE,
    OutputKind,
    clean_stale_partials,
    foreign_entries,
    get_kind,
    is_own_output,
    live_writers,
    make_partial,
    remove_owned_tree,
    write_marker,
    write_owner,
)

OUTPUT_SPACE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO})
"""Errors writing an output that say where the output goes is unusable (full, read-only)."""


# --- files ---------------------------------------------------------------------------------


def _first_existing_ancestor(path: Path) -> Path:
    probe = Path(os.path.abspath(path)).parent
    while not os.path.lexists(probe) and probe.parent != probe:
        probe = probe.parent
    return probe


def check_output_file(path: Path, option: str = "output") -> Path:
    """``path`` if a file can be written there: not a folder, not under a file.

    An existing file (or symbolic link) at ``path`` is replaced by the rename; the target of a
    link is never written.
    """
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{path}: {option} expected a file name, found a folder")
    ancestor = _first_existing_ancestor(path)
    if not ancestor.is_dir():
        raise UsageError(f"{path}: {option} cannot be created: {ancestor} is a file")
    return path


def _temp_file(parent: Path, prefix: str, suffix: str) -> tuple[int, Path]:
    """A new file ``parent/<prefix><random><suffix>`` opened for writing, mode ``0o666 & ~umask``."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        path = parent / f"{prefix}{secrets.token_hex(4)}{suffix}"
        try:
            return os.open(path, flags, 0o666), path
        except FileExistsError:
            continue
    raise FileExistsError(f"{parent}: could not find a free temporary file name")


def write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = check_output_file(Path(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _temp_file(path.parent, f".{path.name}.", ".tmp")
    with _replacing(tmp, path), os.fdopen(fd, "wb") as fh:
        fh.write(data)


@contextlib.contextmanager
def _replacing(tmp: Path, path: Path) -> Iterator[None]:
    """Rename ``tmp`` to ``path`` when the block succeeds (after the block's own context
    managers have closed the file); otherwise remove ``tmp`` and raise again, an ``OSError``
    about ``tmp`` (or about no file) then naming ``path``, the file the caller asked for."""
    try:
        yield
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename in (None, str(tmp)):
            raise OSError(exc.errno, exc.strerror, str(path)) from None  # name the real file
        raise


def write_files(files: dict[Path, bytes]) -> None:
    """Write several files so that they appear only once all of them are complete (each to a
    temporary sibling, mode ``0o666 & ~umask``, then all renamed)."""
    temps: list[tuple[Path, Path]] = []
    try:
        for path, data in files.items():
            path = check_output_file(Path(path))
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = _temp_file(path.parent, f".{path.name}.", ".tmp")
            temps.append((tmp, path))
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
        for tmp, path in temps:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in temps:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise


def write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    write_bytes(path, text.encode("utf-8"))


def write_png(path: Path, image: Any, params: Sequence[int] = ()) -> None:
    """Encode ``image`` (OpenCV channel order: grey, BGR or BGRA) as PNG and write it atomically.

    ``params`` are OpenCV ``IMWRITE_PNG_*`` flag/value pairs (compression, filter); the file is
    PNG whatever the suffix of ``path``.
    """
    import cv2

    ok, data = cv2.imencode(".png", image, list(params))
    if not ok:  # pragma: no cover - OpenCV failure
        raise OSError(f"{path}: PNG encoding failed")
    write_bytes(path, data.tobytes())


NPZ_LEVEL = 1
"""zlib level of the ``.npz`` files the runs write (:func:`write_npz`). numpy's
``savez_compressed`` uses 6: fr-clinic's ``map.npz`` (5748 × 10705 float32 log-odds) took 2.87 s
to write at 6 and takes 0.74 s at 1, 17.4 MB instead of 13.8 MB (the ``map.pgm`` beside it is
61.5 MB); ``np.load`` reads either."""


def write_npz(path: Path, arrays: dict[str, Any], level: int = NPZ_LEVEL) -> None:
    """Write ``arrays`` to ``path`` as an ``.npz`` (what ``np.savez_compressed`` writes, at zlib
    ``level``; 0: stored uncompressed, as ``np.savez``), atomically. The members carry a fixed
    date (1980-01-01) instead of the time of writing, so that equal arrays give the same bytes.
    Object arrays are refused (no pickles)."""
    import zipfile

    import numpy as np

    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", allowZip64=True) as zf:
        for name, value in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            info.compress_type = zipfile.ZIP_DEFLATED if level > 0 else zipfile.ZIP_STORED
            # what ZipFile.open(name, "w") sets from the archive's compresslevel: the public
            # ZipInfo.compress_level from Python 3.13, the private _compresslevel before it (a
            # level that were ignored would deflate at 6: tests/test_atomic.py compares sizes)
            field = "compress_level" if hasattr(info, "compress_level") else "_compresslevel"
            setattr(info, field, level if level > 0 else None)
            with zf.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` if the block succeeds.

    For writers that insist on a file name of their own (``np.savez``, ``cv2.imwrite``): the
    temporary name keeps the final suffix so such writers pick the right format. The temporary
    file exists (empty, mode ``0o666 & ~umask``) when the block starts; writers that open it
    for writing keep that mode.
    """
    path = check_output_file(Path(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _temp_file(path.parent, f".{path.stem}.", path.suffix)
    os.close(fd)
    with _replacing(tmp, path):
        yield tmp


# --- renames that never replace ------------------------------------------------------------

_AT_FDCWD = -100
_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2
_renameat2_cache: list = []


def _renameat2_function():  # noqa: ANN202 - a ctypes function or None
    if not _renameat2_cache:
        fn = None
        if sys.platform.startswith("linux"):
            try:
                fn = ctypes.CDLL(None, use_errno=True).renameat2
                fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p]
                fn.argtypes += [ctypes.c_uint]
                fn.restype = ctypes.c_int
            except (OSError, AttributeError):
                fn = None
        _renameat2_cache.append(fn)
    return _renameat2_cache[0]


def _renameat2(src: Path, dst: Path, flags: int) -> bool:
    """``renameat2(src, dst, flags)``; ``False`` when the system or file system lacks it."""
    fn = _renameat2_function()
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), flags) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(src), None, str(dst))


def rename_noreplace(src: Path, dst: Path) -> None:
    """Rename folder ``src`` to ``dst``; :class:`FileExistsError` if ``dst`` exists, even if it
    appears while this runs (never replaced, not even an empty folder)."""
    if _renameat2(src, dst, _RENAME_NOREPLACE):
        return
    os.mkdir(dst, 0o700)  # claims the name: FileExistsError when taken
    try:
        os.rename(src, dst)  # onto our own empty claim; fails if anyone wrote into it
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.rmdir(dst)  # our claim, only while still empty
        if exc.errno in (errno.ENOTEMPTY, errno.EEXIST):
            raise FileExistsError(errno.EEXIST, "appeared meanwhile", str(dst)) from None
        raise


def _exchange(a: Path, b: Path) -> bool:
    """Swap ``a`` and ``b`` atomically; ``False`` when not supported here."""
    return _renameat2(a, b, _RENAME_EXCHANGE)


# --- output folders ------------------------------------------------------------------------


@dataclass(frozen=True)
class OutputPlan:
    """What :func:`check_output_dir` found at the destination."""

    path: Path
    kind: OutputKind
    existing: str
    """``"none"``, ``"empty"`` (an empty folder, replaced) or ``"own"`` (replaced with force)."""
    identity: tuple[int, int] | None = None
    """``(st_dev, st_ino)`` of the folder to replace (``"own"``)."""
    option: str = "--out"
    """The option that named the folder, for messages."""


def _contains(folder: Path, path: Path) -> bool:
    return path == folder or folder in path.parents


def check_output_dir(
    path: Path,
    kind: str | OutputKind = "run",
    force: bool = False,
    inputs: Iterable[Path | None] = (),
    option: str = "--out",
) -> OutputPlan:
    """Check that an output folder of ``kind`` may be written at ``path``; raise
    :class:`~slam.errors.UsageError` naming it otherwise (see the module docstring).

    ``inputs`` are the files and folders the command reads: ``path`` may not be one of them or
    an ancestor of one.
    """
    spec = get_kind(kind)
    path = Path(path)
    if path.name in ("", ".", ".."):
        raise UsageError(
            f"{path}: {option} expected a path ending in a new folder's name, found "
            f"{path.name or str(path)!r}"
        )
    if os.path.islink(path):
        raise UsageError(
            f"{path}: {option} is a symbolic link; slam never writes or replaces through a link "
            "(give the real folder)"
        )
    ancestor = _first_existing_ancestor(path)
    if not ancestor.is_dir():
        raise UsageError(f"{path}: {option} cannot be created: {ancestor} is a file")
    if not os.path.lexists(path):
        return OutputPlan(path, spec, "none")
    if not path.is_dir():
        raise UsageError(f"{path}: {option} expected a folder to create, found a file")
    if os.path.ismount(path):
        raise UsageError(
            f"{path}: {option} is a mount point; slam cannot replace it (write into a new "
            "folder inside it)"
        )
    resolved = path.resolve()
    for item in inputs:
        if item is not None and os.path.lexists(item) and _contains(resolved, Path(item).resolve()):
            raise UsageError(
                f"{path}: {option} holds an input of this command ({item}); slam never "
                f"replaces its inputs (choose another {option})"
            )
    if not any(path.iterdir()):
        return OutputPlan(path, spec, "empty")
    own = is_own_output(path, spec)
    if not force:
        hint = (
            "use --force to replace it"
            if own
            else f"it is not a {spec.label} of slam, so --force would not replace it either"
        )
        raise UsageError(f"{path}: output folder exists and is not empty ({hint})")
    if not own:
        raise UsageError(
            f"{path}: --force replaces only a {spec.label} written by `{spec.command}` (a folder "
            f"holding {spec.marker}, {' and '.join(spec.required)}); this folder is not one, so it "
            "was left alone"
        )
    check_only_ours(path, spec, option)
    st = os.lstat(path)
    return OutputPlan(path, spec, "own", (st.st_dev, st.st_ino), option)


FOREIGN_NAMED = 5
"""How many entries slam did not write a refusal names (then how many more there are)."""


def check_only_ours(
    path: Path, kind: str | OutputKind, option: str = "--out", late: bool = False
) -> None:
    """Raise :class:`~slam.errors.UsageError` when the finished output folder ``path`` of
    ``kind`` holds anything slam did not write (:func:`slam.io.runfolder.foreign_entries`) or
    its marker cannot be read: ``--force`` would delete it. ``late``: found once the new folder
    was complete (:func:`atomic_dir` then keeps that result beside ``path`` and says where)."""
    spec = get_kind(kind)
    outcome = "nothing was replaced" if late else "it was left alone"
    refusal = _NotCommitted if late else UsageError
    try:
        foreign = foreign_entries(path, spec)
    except OSError as exc:
        raise refusal(
            f"{path}: --force cannot tell what slam wrote into this {spec.label}: its marker "
            f"{spec.marker} cannot be read ({exc.strerror or exc}); {outcome}"
        ) from None
    if not foreign:
        return
    shown = [name if name.isprintable() else repr(name) for name in foreign]  # one line
    names = ", ".join(shown[:FOREIGN_NAMED])
    if len(foreign) > FOREIGN_NAMED:
        names += f" and {len(foreign) - FOREIGN_NAMED} more"
    raise refusal(
        f"{path}: --force replaces only what slam wrote, but this {spec.label} also holds "
        f"entries slam did not write ({names}); {outcome} (move them out or choose another "
        f"{option})"
    )


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT/SIGTERM/SIGHUP during a cleanup and deliver them after it (main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    signums = [signal.SIGINT, signal.SIGTERM] + (
        [signal.SIGHUP] if hasattr(signal, "SIGHUP") else []
    )
    previous = {}
    for signum in signums:
        handler = signal.getsignal(signum)
        if callable(handler):  # only signals that would raise; ignored/default stay as they are
            previous[signum] = signal.signal(signum, lambda s, f: pending.append(s))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for signum in pending[:1]:
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            raise Terminated(signum)


class _NotCommitted(UsageError):
    """The finished output could not be put at its path, which changed while the command ran:
    :func:`atomic_dir` keeps it beside that path (:func:`_keep_beside`) and says where."""


def _appeared(path: Path) -> UsageError:
    return _NotCommitted(
        f"{path}: another process created this folder while this command was running; nothing "
        "was replaced"
    )


def _changed(path: Path) -> UsageError:
    return _NotCommitted(
        f"{path}: the folder changed while this command was running (another process replaced "
        "it, or wrote into it); nothing was replaced"
    )


KEEP_TRIES = 1000
"""Sibling names ``<path>-2`` … tried for an output that could not be put at its path."""


def _keep_beside(staging: Path, path: Path) -> Path | None:
    """Rename the finished folder ``staging`` to the first free ``<path>-N`` (N = 2, 3, …), so
    that a result the command could not put at ``path`` is not lost; None when none was free."""
    for k in range(2, KEEP_TRIES + 2):
        candidate = path.with_name(f"{path.name}-{k}")
        try:
            rename_noreplace(staging, candidate)
        except FileExistsError:
            continue
        except OSError:
            return None
        with contextlib.suppress(OSError):
            os.unlink(candidate / OWNER_FILE)
        return candidate
    return None


def _same_folder(folder: Path, plan: OutputPlan) -> bool:
    """Whether ``folder`` is the very output folder ``plan`` found (device and inode, kind)."""
    try:
        st = os.lstat(folder)
    except OSError:
        return False
    same = stat.S_ISDIR(st.st_mode) and (st.st_dev, st.st_ino) == plan.identity
    return same and is_own_output(folder, plan.kind)


def _is_planned_folder(folder: Path, plan: OutputPlan) -> bool:
    """:func:`_same_folder`, still holding nothing slam did not write: safe to delete."""
    if not _same_folder(folder, plan):
        return False
    try:
        return not foreign_entries(folder, plan.kind)
    except OSError:
        return False


class _Staging:
    """The partial folder and whether what sits at its path is still ours to delete."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.ours = True


def _commit_new(staging: _Staging, plan: OutputPlan) -> None:
    path = plan.path
    if plan.existing == "empty":
        try:
            os.rmdir(path)  # only while still empty: whatever was put in it meanwhile stays
        except FileNotFoundError:
            pass
        except OSError as exc:
            if exc.errno in (errno.ENOTEMPTY, errno.EEXIST):
                raise _appeared(path) from None
            raise
    try:
        rename_noreplace(staging.path, path)
    except FileExistsError:
        raise _appeared(path) from None
    staging.ours = False  # renamed: the partial path is free again


def _commit_replacing(staging: _Staging, plan: OutputPlan) -> None:
    path, parent = plan.path, plan.path.parent
    if not os.path.lexists(path):  # removed meanwhile: nothing to replace
        _commit_new(staging, OutputPlan(path, plan.kind, "none"))
        return
    if _same_folder(path, plan):  # else the checks after the swap say what changed
        check_only_ours(path, plan.kind, plan.option, late=True)
    if _exchange(staging.path, path):
        if not _is_planned_folder(staging.path, plan):
            if not _exchange(staging.path, path):  # pragma: no cover - exchange just worked
                staging.ours = False
            raise _changed(path)
        with contextlib.suppress(OSError):
            write_owner(staging.path, path.name)  # a crash while deleting leaves a stale partial
        remove_owned_tree(staging.path)  # the replaced folder, now at the partial's name
        staging.ours = False
        return
    aside = parent / f".{path.name}.{secrets.token_hex(4)}.partial"
    os.rename(path, aside)  # a fresh name: nothing is replaced
    if not _is_planned_folder(aside, plan):
        with contextlib.suppress(OSError):
            if not os.path.lexists(path):
                os.rename(aside, path)  # put back whatever was there
        raise _changed(path)
    with contextlib.suppress(OSError):
        write_owner(aside, path.name)
    try:
        _commit_new(staging, OutputPlan(path, plan.kind, "none"))
    except BaseException:
        with contextlib.suppress(OSError):
            rename_noreplace(aside, path)
        raise
    remove_owned_tree(aside)


def _about_the_output(exc: BaseException, staging: Path) -> bool:
    """Whether ``exc`` says the output cannot be written (full, read-only) while writing into
    ``staging`` (or without naming a file, as writers of npz archives and recordings do)."""
    if not isinstance(exc, OSError) or exc.errno not in OUTPUT_SPACE_ERRNOS:
        return False
    return exc.filename is None or str(exc.filename).startswith(str(staging))


def _announce_cleaned(parent: Path) -> None:
    cleaned = clean_stale_partials(parent)
    if cleaned:
        print(
            f"slam: removed {len(cleaned)} stale partial folder(s) of interrupted runs in "
            f"{parent} (their processes are gone)",
            file=sys.stderr,
            flush=True,
        )


@contextlib.contextmanager
def atomic_dir(
    path: Path,
    overwrite: bool = False,
    *,
    kind: str | OutputKind = "run",
    inputs: Iterable[Path | None] = (),
    option: str = "--out",
) -> Iterator[Path]:
    """Yield a partial folder beside ``path``; rename it to ``path`` when the block succeeds.

    ``overwrite`` (``--force``) lets a finished output folder of ``kind`` be replaced, once the
    new one is complete; anything else at ``path`` is an error raised before any work is done,
    and a folder appearing at ``path`` meanwhile is never replaced (see the module docstring).
    The kind's marker is written into the folder just before the rename.
    """
    path = Path(path)
    inputs = tuple(inputs)
    plan = check_output_dir(path, kind, overwrite, inputs, option)
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # named as the user gave it, not as the folder that failed
        raise UsageError(f"{option} {path}: cannot make {exc.filename} ({exc.strerror})") from None
    _announce_cleaned(parent)
    writers = live_writers(parent, path.name)
    if writers:
        record = writers[0].record or {}
        raise UsageError(
            f"{path}: another slam process (pid {record.get('pid')}, started "
            f"{record.get('started', '?')}) is writing this folder; wait for it to finish or "
            f"choose another {option}"
        )
    staging: _Staging | None = None
    try:
        with _signals_deferred():  # no signal between the folder and the cleanup that owns it
            try:
                staging = _Staging(make_partial(parent, path.name))
            except OSError as exc:  # the hidden staging folder is not what the user named
                reason = exc.strerror or type(exc).__name__
                raise UsageError(f"{option} {path}: cannot write in {parent} ({reason})") from None
        yield staging.path
        raise_pending_termination()  # a signal whose exception a callback swallowed: no commit
        write_marker(staging.path, plan.kind)
        if plan.existing == "own":
            _commit_replacing(staging, plan)
        else:
            _commit_new(staging, plan)
        with contextlib.suppress(OSError):
            os.unlink(path / OWNER_FILE)
    except BaseException as exc:
        kept = None
        with _signals_deferred():
            if isinstance(exc, _NotCommitted) and staging is not None and staging.ours:
                kept = _keep_beside(staging.path, path)  # complete: kept, not deleted
                staging.ours = kept is None
            if staging is not None and staging.ours:
                remove_owned_tree(staging.path)
        if isinstance(exc, _NotCommitted):
            where = f"is in {kept} instead" if kept is not None else "was discarded"
            raise UsageError(f"{exc}; this command's result {where}") from None
        if staging is not None and _about_the_output(exc, staging.path):
            raise OSError(exc.errno, f"{exc.strerror}; nothing was written", str(path)) from None
        raise


def check_new_file(path: Path, option: str, force: bool) -> Path:
    """``path``, an output file a command is about to write: refused (:class:`UsageError`, one
    line naming ``option``) when it is a folder, or when it exists and ``force`` is not given —
    a run replaces no file it did not make, and a lone file carries no mark of who made it."""
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{option} {path}: expected a file name, found a folder")
    if os.path.lexists(path) and not force:
        raise UsageError(
            f"{option} {path}: exists; it was left alone (choose another name, or give --force "
            "to replace it)"
        )
    return path
