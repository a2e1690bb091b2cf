"""The dataset registry: dataset names -> loader, files, expected figures; status and verification.

This module owns ``data/datasets.toml`` (its schema, declared as validated dataclasses with
:mod:`slam.validate`), the question "which files of
a dataset are under the data directory" (:func:`dataset_status`), loading a dataset by name
whatever its format (:func:`load_dataset`, which dispatches to the format's loader) and the checks
of ``slam data verify`` (:func:`verify_dataset`: sizes and sha256 where known, then the loader's
own validation, then counts and rates against the registry's expectations).

The data directory itself is chosen by :func:`slam.io.datadir.resolve_data_dir`.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from slam.errors import ConfigError, DataError
from slam.io.datadir import check_readable_dir, is_present, put_files_hint
from slam.resources import registry_path
from slam.validate import Rule, Validated, bounded, from_table, read_toml

if TYPE_CHECKING:
    from slam.config import Config
    from slam.io.log import Log

LOADERS: tuple[str, ...] = ("ece276a", "carmen")
"""Loaders the registry may name."""
RELATIONS_TIMES: tuple[str, ...] = ("log", "retime")
"""What a dataset's relations' times are: the log's scan times, or the original log's (re-timed)."""

FILE_STREAMS: tuple[str, ...] = (
    "encoders",
    "imu",
    "scans",
    "odometry",
    "rgb",
    "disparity",
    "rgb_images",
    "disparity_images",
    "relations",
)
"""Streams a registry file may provide."""

EXPECT_STREAMS: tuple[str, ...] = ("encoders", "imu", "scans", "odometry", "rgb", "disparity")
"""Streams an ``expect`` table may describe: the stream keys of :meth:`Log.summary`."""

RATE_TOLERANCE = 0.10
"""Relative deviation of a measured rate from the registry's nominal rate that verify accepts."""

STATES: tuple[str, ...] = ("present", "partial", "absent")
"""Values of :attr:`DatasetStatus.state`."""


def _is_relative(text: str) -> bool:
    """Whether ``text`` is a ``/``-separated path inside the data directory."""
    parts = text.rstrip("/").split("/")
    return not (text.startswith("/") or "\\" in text or any(p in ("", ".", "..") for p in parts))


_RELATIVE = "a path relative to the data directory (like 'ece276a/Encoders20.npz')"
_SHA256 = re.compile(r"[0-9a-fA-F]{64}\Z")


@dataclass(frozen=True)
class DataFile(Validated):
    """One file (or folder, when :attr:`path` ends with ``/``) of a dataset."""

    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(
            ("path", "size", "sha256"),
            lambda path, size, sha: not path.endswith("/") or (size is None and sha is None),
            "no size or sha256 on a folder (a path ending in /)",
            blame=("size",),
        ),
        Rule(
            ("path", "entries"),
            lambda path, entries: path.endswith("/") or entries is None,
            "entries only on a folder (a path ending in /)",
            blame=("entries",),
        ),
    )

    path: str = bounded(test=_is_relative, expected=_RELATIVE)
    """Location relative to the data directory, ``/``-separated."""
    streams: tuple[str, ...] = bounded(min_length=1, choices=FILE_STREAMS)
    """What it provides (see :data:`FILE_STREAMS`)."""
    size: int | None = bounded(None, ge=0)
    """Size in bytes, when known."""
    sha256: str | None = bounded(
        None, test=lambda v: bool(_SHA256.match(v)), expected="64 hex digits"
    )
    """SHA-256 of the contents (hex, lower case), when known."""
    entries: int | None = bounded(None, ge=0)
    """Folders: how many files it should hold, when known."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.sha256 is not None and self.sha256 != self.sha256.lower():
            object.__setattr__(self, "sha256", self.sha256.lower())

    @property
    def is_dir(self) -> bool:
        """Whether this entry is a folder."""
        return self.path.endswith("/")

    def location(self, data_dir: Path) -> Path:
        """Absolute location under ``data_dir``."""
        return Path(data_dir) / self.path.rstrip("/")


@dataclass(frozen=True)
class Expectation(Validated):
    """Figures a stream of a dataset should show once loaded."""

    count: int | None = bounded(None, ge=0)
    """Exact number of readings."""
    rate_hz: float | None = bounded(None, gt=0.0)
    """Nominal reading rate (Hz); verify accepts :data:`RATE_TOLERANCE` relative deviation."""


@dataclass(frozen=True)
class Dataset:
    """A dataset of the registry."""

    name: str
    loader: str
    """``"ece276a"`` or ``"carmen"``."""
    folder: str
    """Folder under the data directory."""
    files: tuple[DataFile, ...]
    description: str
    source: str
    """Where the files come from."""
    number: str | None = None
    """ECE276A dataset number (the ``NN`` in ``EncodersNN.npz``)."""
    relations: str | None = None
    """Ground-truth relations file, relative to the data directory (CARMEN)."""
    relations_times: str = "log"
    """``"log"``: the relations' times are the log's scan times; ``"retime"``: they are the
    original log's, which this copy lost (synthetic times), and are put back on its scans by
    :mod:`slam.eval.retime`."""
    expect: Mapping[str, Expectation] = field(default_factory=dict)
    """Expected figures per stream (keys of :meth:`Log.summary`)."""

    def file_for(self, stream: str) -> DataFile | None:
        """The file that provides ``stream``, if any."""
        return next((f for f in self.files if stream in f.streams), None)

    def log_file(self) -> DataFile:
        """The log file of a CARMEN dataset (the file providing scans)."""
        found = self.file_for("scans")
        if found is None:  # validated at load time, so only a hand-built Dataset gets here
            raise ConfigError(f"dataset {self.name}: no file provides scans")
        return found


@dataclass(frozen=True)
class DatasetStatus:
    """Which files of a dataset are under a data directory."""

    dataset: Dataset
    data_dir: Path
    state: str
    """``"present"`` (every file), ``"partial"`` (some) or ``"absent"`` (none)."""
    present: tuple[str, ...]
    """Registry paths found."""
    missing: tuple[str, ...]
    """Registry paths not found."""

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (what ``slam data list --json`` prints per dataset)."""
        return {
            "name": self.dataset.name,
            "loader": self.dataset.loader,
            "folder": self.dataset.folder,
            "status": self.state,
            "present": list(self.present),
            "missing": list(self.missing),
        }


# --- reading the registry -------------------------------------------------------------------


def _one_log_file(loader: str, files: tuple[DataFile, ...]) -> bool:
    return loader != "carmen" or sum("scans" in f.streams for f in files) == 1


@dataclass(frozen=True)
class _DatasetTable(Validated):
    """A ``[datasets.NAME]`` table as written (its name is the table's key)."""

    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(
            ("loader", "number"),
            lambda loader, number: loader != "ece276a" or number is not None,
            "a dataset number for an ece276a dataset (e.g. number = 20)",
            blame=("number",),
        ),
        Rule(
            ("loader", "number"),
            lambda loader, number: loader == "ece276a" or number is None,
            "no number: only ece276a datasets have one",
            blame=("number",),
        ),
        Rule(
            ("relations", "files"),
            lambda relations, files: relations is None or relations in [f.path for f in files],
            "a relations file that is also listed under files",
            blame=("relations",),
        ),
        Rule(
            ("loader", "files"),
            _one_log_file,
            "exactly one file providing 'scans' (the log) in a carmen dataset",
            blame=("files",),
        ),
    )

    loader: str = bounded(choices=LOADERS)
    """``"ece276a"`` or ``"carmen"``."""
    folder: str = bounded(test=_is_relative, expected=_RELATIVE)
    files: tuple[DataFile, ...] = bounded(min_length=1, expected="a non-empty list of tables")
    description: str = bounded(min_length=1)
    source: str = bounded(min_length=1)
    number: int | str | None = bounded(
        None,
        test=lambda v: isinstance(v, int) or bool(re.fullmatch(r"[0-9A-Za-z_-]+", v)),
        expected="a dataset number such as 20",
    )
    relations: str | None = bounded(None, test=_is_relative, expected=_RELATIVE)
    relations_times: str = bounded("log", choices=RELATIONS_TIMES)
    expect: dict[str, Expectation] = bounded(factory=dict, choices=EXPECT_STREAMS)


@dataclass(frozen=True)
class _RegistryTable(Validated):
    """The whole ``datasets.toml``."""

    datasets: dict[str, Any] = bounded(
        test=lambda d: len(d) > 0, expected="at least one dataset table"
    )
    schema: int = bounded(1, choices=(1,))


def load_registry(path: Path | None = None) -> dict[str, Dataset]:
    """Read and validate the registry (default: the project's ``data/datasets.toml``).

    Raises :class:`ConfigError` naming the file and the offending key.
    """
    path = Path(path) if path is not None else registry_path()
    return parse_registry(read_toml(path, "dataset registry"), str(path))


def parse_registry(raw: Mapping[str, Any], source: str = "datasets.toml") -> dict[str, Dataset]:
    """Validate a parsed registry table; ``source`` prefixes every error message."""
    top = from_table(_RegistryTable, raw, source, "")
    return {name: _dataset(name, value, source) for name, value in top.datasets.items()}


def _dataset(name: str, value: Any, source: str) -> Dataset:
    key = f"datasets.{name}"
    table = from_table(_DatasetTable, value, source, key)
    folder = table.folder.rstrip("/")
    paths = [f.path for f in table.files]
    for i, f in enumerate(table.files):
        if not f.path.startswith(folder + "/"):
            raise ConfigError(
                f"{source}: {key}.files[{i}].path: expected a path inside the dataset folder "
                f"{table.folder!r}, found {f.path!r}"
            )
    duplicate = next((p for p in paths if paths.count(p) > 1), None)
    if duplicate:
        raise ConfigError(f"{source}: {key}.files: {duplicate!r} is listed twice")
    return Dataset(
        name=name,
        loader=table.loader,
        folder=folder,
        files=table.files,
        description=table.description,
        source=table.source,
        number=None if table.number is None else str(table.number),
        relations=table.relations,
        relations_times=table.relations_times,
        expect=table.expect,
    )


def get_dataset(name: str, registry: Mapping[str, Dataset] | None = None) -> Dataset:
    """The registry entry ``name``; :class:`DataError` listing the known names otherwise."""
    registry = load_registry() if registry is None else registry
    if name not in registry:
        raise DataError(
            f"unknown dataset {name!r}; known datasets: {', '.join(registry)} "
            f"(see `slam data list`)"
        )
    return registry[name]


# --- what is on disk ------------------------------------------------------------------------


def _exists(entry: DataFile, data_dir: Path, strict: bool = True) -> bool:
    return is_present(entry.location(data_dir), folder=entry.is_dir, strict=strict)


def dataset_status(dataset: Dataset, data_dir: Path, strict: bool = False) -> DatasetStatus:
    """Which of ``dataset``'s files are under ``data_dir``: present, partial or absent.

    A missing data directory or dataset folder makes the dataset absent; one that exists but
    cannot be read raises :class:`DataError` naming it. Something else where a file should be (a
    folder, a pipe, a link to nothing) counts as missing in a listing, and is a
    :class:`DataError` naming it and what it is with ``strict`` (``slam data verify``).
    """
    data_dir = Path(data_dir)
    present: list[str] = []
    missing: list[str] = []
    if check_readable_dir(data_dir, "data directory") and check_readable_dir(
        data_dir / dataset.folder, f"folder of dataset {dataset.name}"
    ):
        for entry in dataset.files:
            parent = entry.location(data_dir).parent
            if parent != data_dir / dataset.folder:
                check_readable_dir(parent, f"folder of {entry.path}")
            (present if _exists(entry, data_dir, strict=strict) else missing).append(entry.path)
    else:
        missing = [f.path for f in dataset.files]
    if not missing:
        state = "present"
    elif not present:
        state = "absent"
    else:
        state = "partial"
    return DatasetStatus(dataset, data_dir, state, tuple(present), tuple(missing))


# --- loading --------------------------------------------------------------------------------


def load_dataset(
    name: str,
    data_dir: Path,
    *,
    need: Collection[str] | None = None,
    config: Config | None = None,
    registry: Mapping[str, Dataset] | None = None,
) -> Log:
    """Load registry dataset ``name`` from ``data_dir`` with its format's loader.

    ``need`` names the streams that must be present (ECE276A: ``encoders``, ``imu``, ``scans``,
    ``kinect``; default: the loader's own default, encoders and IMU. CARMEN: ``scans``,
    ``odometry``; default: none beyond the log file). ``config`` (default: the dataset's shipped
    configuration, ``configs/<name>.toml``) supplies the lidar geometry and range semantics.
    ``registry`` replaces the project's registry (tests, other registries).
    """
    from slam.config import load_config

    dataset = get_dataset(name, registry)
    data_dir = Path(data_dir)
    check_readable_dir(data_dir, "data directory")
    folder = data_dir / dataset.folder
    check_readable_dir(folder, f"folder of dataset {name}")
    config = config if config is not None else load_config(name)

    if dataset.loader == "ece276a":
        from slam.io.ece276a import DEFAULT_NEED, load_ece276a

        assert dataset.number is not None  # guaranteed by the registry validation
        return load_ece276a(
            folder,
            dataset.number,
            need=DEFAULT_NEED if need is None else need,
            name=name,
            lidar=config.lidar,
            memory_share=config.checks.max_memory_share,
        )

    from slam.io.carmen import load_carmen

    path = dataset.log_file().location(data_dir)
    if not _exists(dataset.log_file(), data_dir):
        raise DataError(
            f"{name}: missing {path} (a CARMEN log, {dataset.description}). "
            + put_files_hint(dataset.log_file().path)
        )
    log = load_carmen(
        path, name=name, lidar=config.lidar, memory_share=config.checks.max_memory_share
    )
    absent = [s for s in (need or ()) if s not in log.streams()]
    if absent:
        raise DataError(
            f"{path}: the log has no {', '.join(absent)} stream; "
            f"found {', '.join(log.streams()) or 'none'}"
        )
    return log


# --- verification ---------------------------------------------------------------------------


def sha256_of(path: Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's contents."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def _check_file(entry: DataFile, data_dir: Path) -> dict[str, Any]:
    """Size, hash or entry-count check of one present registry entry."""
    location = entry.location(data_dir)
    result: dict[str, Any] = {"path": entry.path, "status": "ok", "problems": []}
    try:
        if entry.is_dir:
            count = sum(1 for e in os.scandir(location) if e.is_file())
            result["entries"] = count
            if entry.entries is not None and count < entry.entries:
                result["problems"].append(f"holds {count} files, expected {entry.entries}")
        else:
            size = location.stat().st_size
            result["size"] = size
            if entry.size is not None and size != entry.size:
                result["problems"].append(f"size {size} bytes, expected {entry.size}")
            elif entry.sha256 is not None:
                digest = sha256_of(location)
                result["sha256"] = "ok" if digest == entry.sha256 else digest
                if digest != entry.sha256:
                    result["problems"].append(f"sha256 {digest}, expected {entry.sha256}")
    except PermissionError:
        result["problems"].append("cannot read (permission denied)")
    except OSError as exc:
        result["problems"].append(f"cannot read ({exc.strerror})")
    if result["problems"]:
        result["status"] = "bad"
    return result


def _check_expectations(dataset: Dataset, summary: Mapping[str, Any]) -> list[str]:
    problems = []
    for stream, expected in dataset.expect.items():
        info = summary.get(stream)
        if not isinstance(info, Mapping):
            continue  # its file is missing, which the file list already reports
        count = info.get("count", 0)
        if expected.count is not None and count != expected.count:
            problems.append(f"{stream}: {count} readings, expected {expected.count}")
        rate = info.get("rate_hz")
        nominal = expected.rate_hz
        if (
            nominal is not None
            and rate is not None
            and abs(rate - nominal) > RATE_TOLERANCE * nominal
        ):
            problems.append(
                f"{stream}: {rate:.2f} Hz, expected {nominal:g} Hz ± {RATE_TOLERANCE:.0%}"
            )
    return problems


def verify_dataset(
    name: str,
    data_dir: Path,
    *,
    config: Config | None = None,
    registry: Mapping[str, Dataset] | None = None,
) -> dict[str, Any]:
    """Check dataset ``name`` under ``data_dir`` and summarise it (``slam data verify``).

    Checks every present file's size and sha256 where the registry knows them (folders: their
    file count), loads what is present with the format's loader (keys, shapes, dtypes, timestamps
    and rates are validated there) and compares reading counts and rates with the registry.
    Returns a JSON-ready report: ``status``, ``files``, ``missing``, ``summary`` (from
    :meth:`Log.summary`), ``problems`` (empty when everything present checks out; they include
    the time-base and odometry checks of :mod:`slam.io.plausibility`) and ``warnings``. Raises
    :class:`DataError` when no file of the dataset is present. ``registry`` replaces the
    project's registry.
    """
    dataset = get_dataset(name, registry)
    data_dir = Path(data_dir)
    status = dataset_status(dataset, data_dir, strict=True)
    if status.state == "absent":
        raise DataError(
            f"{name}: none of its files is under {data_dir} (expected "
            f"{', '.join(status.missing)}); see docs/data.md for where to put them, or point "
            f"--data-dir (or SLAM_DATA_DIR) at the folder that holds them"
        )
    files = [_check_file(f, data_dir) for f in dataset.files if f.path in status.present]
    problems = [f"{f['path']}: {p}" for f in files for p in f["problems"]]
    summary: dict[str, Any] = {}
    warnings: list[str] = []
    if dataset.loader == "carmen" and dataset.log_file().path in status.missing:
        pass  # only the relations file is there: nothing to load
    else:
        from slam.config import load_config
        from slam.io.plausibility import check_plausibility

        config = config if config is not None else load_config(name)
        try:
            log = load_dataset(name, data_dir, need=(), config=config, registry=registry)
        except DataError as exc:
            problems.append(str(exc))
        else:
            summary = log.summary()
            problems.extend(_check_expectations(dataset, summary))
            try:
                warnings = check_plausibility(log, config)
            except DataError as exc:
                problems.append(str(exc))
    return {
        "name": name,
        "loader": dataset.loader,
        "data_dir": str(data_dir),
        "status": status.state,
        "files": files,
        "missing": list(status.missing),
        "summary": summary,
        "problems": problems,
        "warnings": warnings,
    }
