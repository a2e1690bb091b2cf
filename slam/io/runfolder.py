"""Which folders are slam's own: finished output folders, and partial folders of live or dead runs.

Two kinds of folder are recognised, and only these are ever replaced or removed:

* a **finished output folder** of a kind (:data:`KINDS`): a real folder (not a symbolic link)
  holding the kind's marker file (``.slam-run`` for ``slam run``, ``.slam-sim`` for ``slam sim``,
  ``.slam-localize`` for ``slam localize``) and the kind's required files (``metrics.json`` +
  ``config.toml`` for a run or localization folder, ``simulation.json`` for a simulated
  dataset). The marker is written last, just before the folder is renamed into place, so only
  complete outputs carry it. Below its two lines of text it lists, sorted, the relative path of
  every file and sub-folder (``/`` at the end) the folder then holds, itself included: exactly
  what slam wrote (:func:`write_marker`). ``--force`` replaces only such a folder, of the same
  kind, and only while it holds nothing slam did not write (:func:`foreign_entries`): every
  entry (recursively, links not followed) must be in the marker's list, or one of the names
  other slam commands add to a finished folder later (:attr:`OutputKind.added`: ``eval.json``,
  ``slam export``'s default files …), or the owner record of a partial folder. A marker of an
  earlier release has no list: then every entry must be one the kind's writer produces
  (:attr:`OutputKind.writes`). Anything else — a note of the user's, plots saved beside the
  outputs — makes ``--force`` refuse and leave the folder as it is;
* a **partial folder** ``.<name>.<random>.partial`` being assembled beside its destination
  (:func:`make_partial`). It holds an owner record ``.slam-partial`` (JSON: process id, host,
  boot id, the process's start time, the destination's name, the owner's user id) written the
  moment the folder is made. A partial folder is *stale* when its owner record names this host
  and a process that is gone (no such pid, another start time, or another boot) and the folder
  belongs to the current user; :func:`clean_stale_partials` removes stale ones, never a live
  one, never one without a readable owner record, never one of another user or host.

Removal (:func:`remove_owned_tree`) deletes the owner record last, so a removal that is itself
killed leaves a folder the next clean still recognises.
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import os
import secrets
import shutil
import socket
import stat
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

PARTIAL_SUFFIX = ".partial"
"""Suffix of a folder being assembled (``.<name>.<random>.partial``)."""

OWNER_FILE = ".slam-partial"
"""The owner record inside every partial folder."""

OWNER_RECORD_MAX_BYTES = 65536
"""An owner record larger than this is not ours (it is never read whole)."""


LIST_HEADER = (
    "What slam wrote here, one path a line (folders end in /); --force replaces this folder only "
    "while it holds nothing else:"
)
"""The line of a marker file after which its list of entries begins (:func:`write_marker`)."""

MARKER_MAX_BYTES = 64 * 2**20
"""A marker file larger than this is not read (its folder is not replaced)."""


@dataclass(frozen=True)
class OutputKind:
    """A kind of output folder slam writes and may replace with ``--force``.

    :attr:`writes` and :attr:`added` are shell-style patterns matched one path component at a
    time (``*`` never crosses a ``/``), a folder's ending in ``/``.
    """

    name: str
    """Short name (``run``, ``sim``)."""
    label: str
    """What people call it (``run folder``)."""
    marker: str
    """Marker file written into every finished folder of this kind."""
    required: tuple[str, ...]
    """Files every finished folder of this kind holds."""
    command: str
    """The command that writes it."""
    writes: tuple[str, ...] = ()
    """Every entry the kind's writer may produce: what a folder whose marker has no list
    (written by an earlier release) may hold to be replaced with ``--force``."""
    added: tuple[str, ...] = ()
    """Entries other slam commands write into a finished folder of this kind later (``slam
    eval``, ``slam texture``, ``slam export`` with its default names): not in the marker's list,
    yet slam's, so ``--force`` replaces them with the folder."""

    def marker_text(self) -> str:
        """The marker file's first lines (constant: outputs of the same inputs stay identical)."""
        return (
            f"This folder is a {self.label} written by `{self.command}`.\n"
            f"`{self.command} --force` may replace it (and only folders with this file and "
            f"{', '.join(self.required)}).\n"
        )


RUN_WRITES = (
    "config.toml",
    "metrics.json",
    "trajectory.tum",
    "trajectory_file_order.tum",
    "map.npz",
    "map.png",
    "map.pgm",
    "map.yaml",
    "map_clean.png",
    "quality.png",
    "texture.npz",
    "texture.png",
    "texture_overlay.png",
    "recording.rrd",
)
"""What ``slam run`` writes (:func:`slam.pipeline.execute`; ``tests/test_runfolder.py`` checks
that a real run's files are among them)."""

ADDED_TO_RUNS = (
    "eval.json",  # slam eval (slam.eval.report.EVAL_FILE), also the sweep's
    "quality.png",  # slam eval (slam.eval.quality_run.PICTURE)
    "texture.npz",  # slam texture RUN_DIR
    "texture.png",
    "texture_overlay.png",
    "export/",  # slam export's default files (slam.io.exports.EXPORT_DIR, DEFAULT_NAMES)
    "export/map.pgm",
    "export/map.yaml",
    "export/map_clean.png",
    "export/occupancy.npz",
    "export/trajectory.tum",
    "export/trajectory.kitti",
    "export/trajectory_times.txt",
)
"""What other slam commands write into a finished run or localization folder."""

SIM_WRITES = (
    "Encoders*.npz",  # slam.io.ece276a.SPECS, dataset number for *
    "Imu*.npz",
    "Hokuyo*.npz",
    "Kinect*.npz",
    "groundtruth.tum",
    "groundtruth_map.npz",
    "groundtruth_map.png",
    "groundtruth_texture.npz",
    "groundtruth_texture.png",
    "simulation.json",
    "dataRGBD/",  # slam.io.ece276a.rgbd_dirs and rgbd_patterns
    "dataRGBD/RGB*/",
    "dataRGBD/RGB*/rgb*_*.png",
    "dataRGBD/Disparity*/",
    "dataRGBD/Disparity*/disparity*_*.png",
)
"""What ``slam sim`` writes (:func:`slam.sim.dataset.write_dataset`)."""

LOCALIZE_WRITES = (
    "config.toml",
    "metrics.json",
    "trajectory.tum",
    "trajectory_file_order.tum",
    "localization.npz",
    "map.png",
    "recording.rrd",
)
"""What ``slam localize`` writes (:func:`slam.localize.run.localize`)."""

KINDS: dict[str, OutputKind] = {
    "run": OutputKind(
        "run",
        "run folder",
        ".slam-run",
        ("metrics.json", "config.toml"),
        "slam run",
        writes=RUN_WRITES,
        added=ADDED_TO_RUNS,
    ),
    "sim": OutputKind(
        "sim",
        "simulated dataset",
        ".slam-sim",
        ("simulation.json",),
        "slam sim",
        writes=SIM_WRITES,
    ),
    "localize": OutputKind(
        "localize",
        "localization folder",
        ".slam-localize",
        ("metrics.json", "config.toml"),
        "slam localize",
        writes=LOCALIZE_WRITES,
        added=ADDED_TO_RUNS,
    ),
}
"""Every kind of output folder, by name."""


def get_kind(kind: str | OutputKind) -> OutputKind:
    """``kind`` itself, or the :data:`KINDS` entry of that name."""
    return kind if isinstance(kind, OutputKind) else KINDS[kind]


def _regular_file(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False


def is_own_output(folder: Path, kind: str | OutputKind) -> bool:
    """Whether ``folder`` is a finished output folder of ``kind`` (see the module docstring)."""
    spec = get_kind(kind)
    folder = Path(folder)
    try:
        if not stat.S_ISDIR(os.lstat(folder).st_mode):
            return False
    except OSError:
        return False
    return _regular_file(folder / spec.marker) and all(
        _regular_file(folder / name) for name in spec.required
    )


def _walk(
    folder: Path, descend: Callable[[str], bool], unreadable: list[str] | None = None
) -> Iterator[str]:
    """The relative path of every entry under ``folder``, a folder's ending in
    ``/``, symbolic links not followed (they are files here); a sub-folder is entered only when
    ``descend(its path)``. A folder that cannot be listed raises :class:`OSError`, or, with
    ``unreadable``, is appended to it (its path)."""
    pending = [""]
    while pending:
        prefix = pending.pop()
        try:
            with os.scandir(Path(folder) / prefix) as it:
                entries = [(e.name, e.is_dir(follow_symlinks=False)) for e in it]
        except OSError:
            if unreadable is None or not prefix:
                raise
            unreadable.append(prefix)
            continue
        for name, is_dir in entries:
            rel = f"{prefix}{name}/" if is_dir else prefix + name
            yield rel
            if is_dir and descend(rel):
                pending.append(rel)


def list_entries(folder: Path) -> list[str]:
    """The relative path of every file and sub-folder under ``folder`` (a folder's ending in
    ``/``; symbolic links not followed, listed as files), sorted. Not the owner record of a
    partial folder (removed once the folder is in place), nor names with a line break (a marker
    cannot list them: they count as not slam's)."""
    return sorted(
        rel
        for rel in _walk(folder, lambda rel: True)
        if rel != OWNER_FILE and "\n" not in rel and "\r" not in rel
    )


def marker_content(kind: str | OutputKind, entries: Iterable[str]) -> str:
    """The marker file of ``kind`` listing ``entries`` (the marker itself added): its constant
    lines, :data:`LIST_HEADER`, then the entries sorted, one a line."""
    spec = get_kind(kind)
    names = sorted({*entries, spec.marker})
    return spec.marker_text() + LIST_HEADER + "\n" + "".join(f"{name}\n" for name in names)


def write_marker(folder: Path, kind: str | OutputKind) -> None:
    """Write ``kind``'s marker file into ``folder`` (the last step before it is renamed), listing
    every entry the folder holds (:func:`list_entries`): what slam wrote."""
    spec = get_kind(kind)
    text = marker_content(spec, list_entries(folder))
    fd = os.open(Path(folder) / spec.marker, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
    with os.fdopen(fd, "w", encoding="utf-8", errors="surrogateescape") as fh:
        fh.write(text)


def read_marker_list(folder: Path, kind: str | OutputKind) -> frozenset[str] | None:
    """The entries the marker of ``folder`` lists; ``None`` when it has no list (a marker of an
    earlier release). :class:`OSError` when it cannot be read or is over
    :data:`MARKER_MAX_BYTES`."""
    path = Path(folder) / get_kind(kind).marker
    with open(path, "rb") as fh:
        data = fh.read(MARKER_MAX_BYTES + 1)
    if len(data) > MARKER_MAX_BYTES:
        raise OSError(f"{path}: larger than {MARKER_MAX_BYTES} bytes")
    lines = data.decode("utf-8", errors="surrogateescape").split("\n")
    if LIST_HEADER not in lines:
        return None
    return frozenset(line for line in lines[lines.index(LIST_HEADER) + 1 :] if line)


def _matches(path: str, patterns: Iterable[str]) -> bool:
    """Whether relative ``path`` (``/`` at the end for a folder) matches one of ``patterns``,
    component by component."""
    parts = path.split("/")
    for pattern in patterns:
        pattern_parts = pattern.split("/")
        if len(pattern_parts) == len(parts) and all(
            fnmatch.fnmatchcase(part, want) for part, want in zip(parts, pattern_parts, strict=True)
        ):
            return True
    return False


def foreign_entries(folder: Path, kind: str | OutputKind) -> list[str]:
    """The entries under the finished output folder ``folder`` of ``kind`` that slam did not
    write (see the module docstring), sorted: of a folder that is not slam's only the folder is
    named (``plots/``); a sub-folder that cannot be listed counts as not slam's. Raises
    :class:`OSError` when ``folder`` or its marker cannot be read."""
    spec = get_kind(kind)
    listed = read_marker_list(folder, spec)
    allowed = spec.added if listed is not None else (*spec.writes, *spec.added)
    own = (listed or frozenset()) | {spec.marker, OWNER_FILE}

    def slams(rel: str) -> bool:
        return rel in own or _matches(rel, allowed)

    unreadable: list[str] = []
    found = [rel for rel in _walk(folder, slams, unreadable) if not slams(rel)]
    return sorted(found + unreadable)


# --- owner records -------------------------------------------------------------------------


def _boot_id() -> str | None:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip() or None
    except OSError:
        return None


def process_start_ticks(pid: int) -> int | None:
    """Start time of process ``pid`` in clock ticks since boot (Linux ``/proc``), else ``None``.

    Together with the pid it names one process: a pid reused later has another start time.
    """
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    try:  # the command name (field 2) may hold spaces and parentheses: split after the last ')'
        return int(text[text.rindex(")") + 2 :].split()[19])
    except (ValueError, IndexError):
        return None


def owner_record(target: str) -> dict[str, Any]:
    """The owner record of a partial folder this process makes for destination ``target``."""
    pid = os.getpid()
    return {
        "pid": pid,
        "host": socket.gethostname(),
        "boot_id": _boot_id(),
        "process_start": process_start_ticks(pid),
        "uid": os.geteuid(),
        "target": target,
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def write_owner(folder: Path, target: str) -> None:
    """Write this process's owner record into ``folder``."""
    fd = os.open(Path(folder) / OWNER_FILE, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(owner_record(target), fh)


def read_owner(folder: Path) -> dict[str, Any] | None:
    """The owner record of ``folder``; ``None`` when there is none or it is not ours."""
    path = Path(folder) / OWNER_FILE
    try:
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_size > OWNER_RECORD_MAX_BYTES:
            return None
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict):
        return None
    if not isinstance(record.get("pid"), int) or not isinstance(record.get("host"), str):
        return None
    return record


def owner_state(record: dict[str, Any]) -> str:
    """``"live"``, ``"gone"`` or ``"unknown"`` (another host: its processes cannot be seen)."""
    if record.get("host") != socket.gethostname():
        return "unknown"
    boot = _boot_id()
    if boot is not None and record.get("boot_id") not in (None, boot):
        return "gone"  # recorded before the last reboot
    pid = int(record["pid"])
    if pid <= 0:
        return "unknown"
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return "gone"
    except PermissionError:
        pass  # exists, another user's
    recorded, now = record.get("process_start"), process_start_ticks(pid)
    if isinstance(recorded, int) and now is not None and recorded != now:
        return "gone"  # the pid was reused by another process
    return "live"


# --- partial folders -----------------------------------------------------------------------


def make_partial(parent: Path, target: str) -> Path:
    """Create ``parent/.<target>.<random>.partial`` with this process's owner record.

    The folder's mode is ``0o777`` less the umask (as ``mkdir`` makes any folder).
    """
    parent = Path(parent)
    for _ in range(100):
        folder = parent / f".{target}.{secrets.token_hex(4)}{PARTIAL_SUFFIX}"
        try:
            os.mkdir(folder, 0o777)
        except FileExistsError:
            continue
        try:
            write_owner(folder, target)
        except BaseException:
            with contextlib.suppress(OSError):  # an owner record cut short: not ours to read
                os.unlink(folder / OWNER_FILE)
            with contextlib.suppress(OSError):
                os.rmdir(folder)
            raise
        return folder
    raise FileExistsError(f"{parent}: could not find a free name for a partial folder")


@dataclass(frozen=True)
class PartialFolder:
    """A partial folder found in a parent folder, with its owner's state."""

    path: Path
    record: dict[str, Any] | None
    """The owner record; ``None`` when unreadable (not ours: left alone)."""
    state: str
    """``"live"``, ``"gone"``, ``"unknown"`` (another host), ``"foreign"`` (no owner record
    or another user's)."""

    @property
    def stale(self) -> bool:
        """Whether it may be removed: its owner is gone."""
        return self.state == "gone"


def find_partials(parent: Path) -> list[PartialFolder]:
    """Every ``.*.partial`` folder directly in ``parent``, sorted by name."""
    found: list[PartialFolder] = []
    try:
        entries = sorted(os.scandir(parent), key=lambda e: e.name)
    except (FileNotFoundError, NotADirectoryError):
        return found
    for entry in entries:
        if not (entry.name.startswith(".") and entry.name.endswith(PARTIAL_SUFFIX)):
            continue
        if not entry.is_dir(follow_symlinks=False):
            continue
        path = Path(entry.path)
        record = read_owner(path)
        try:
            mine = entry.stat(follow_symlinks=False).st_uid == os.geteuid()
        except OSError:
            mine = False
        if record is None or not mine or record.get("uid", os.geteuid()) != os.geteuid():
            found.append(PartialFolder(path, record, "foreign"))
        else:
            found.append(PartialFolder(path, record, owner_state(record)))
    return found


def live_writers(parent: Path, target: str) -> list[PartialFolder]:
    """Partial folders in ``parent`` of other live processes writing destination ``target``."""
    return [
        p
        for p in find_partials(parent)
        if p.state == "live"
        and p.record is not None
        and p.record.get("target") == target
        and p.record.get("pid") != os.getpid()
    ]


def remove_owned_tree(folder: Path) -> bool:
    """Delete ``folder`` (never following symbolic links), its owner record last; return
    whether it is gone. Errors are not raised: this runs while another error is on its way."""
    folder = Path(folder)
    try:
        entries = list(os.scandir(folder))
    except FileNotFoundError:
        return True
    except OSError:
        return False
    for entry in entries:
        if entry.name == OWNER_FILE:
            continue
        with contextlib.suppress(OSError):
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path, ignore_errors=True)
            else:
                os.unlink(entry.path)
    with contextlib.suppress(OSError):
        os.unlink(folder / OWNER_FILE)
    try:
        os.rmdir(folder)
    except FileNotFoundError:
        return True
    except OSError:
        return False
    return True


def folder_size(folder: Path) -> int:
    """Bytes of the regular files under ``folder`` (not following links)."""
    total = 0
    for root, _dirs, files in os.walk(folder):
        for name in files:
            with contextlib.suppress(OSError):
                st = os.lstat(os.path.join(root, name))
                if stat.S_ISREG(st.st_mode):
                    total += st.st_size
    return total


def clean_stale_partials(parent: Path, dry_run: bool = False) -> list[PartialFolder]:
    """Remove the stale partial folders in ``parent`` (unless ``dry_run``); return them."""
    stale = [p for p in find_partials(parent) if p.stale]
    if not dry_run:
        for partial in stale:
            remove_owned_tree(partial.path)
    return stale
