"""The dataset registry: its contents, its validation, dataset status, loading and verification."""

from __future__ import annotations

import copy
import os
from pathlib import Path

import numpy as np
import pytest

from slam.errors import ConfigError, DataError
from slam.io.registry import (
    dataset_status,
    get_dataset,
    load_dataset,
    load_registry,
    parse_registry,
    verify_dataset,
)

NAMES = [
    "dataset20",
    "dataset21",
    "dataset23",
    "intel",
    "aces",
    "fr079",
    "fr-clinic",
    "mit-csail",
    "mit-killian",
]


# --- the shipped registry ---------------------------------------------------------------------


def test_shipped_registry_names_every_dataset():
    registry = load_registry()
    assert list(registry) == NAMES
    for name in NAMES[:3]:
        d = registry[name]
        assert (d.loader, d.folder, d.number) == ("ece276a", "ece276a", name[-2:])
        assert d.relations is None
    for name in NAMES[3:]:
        d = registry[name]
        assert (d.loader, d.folder, d.number) == ("carmen", "carmen", None)
        assert d.relations == f"carmen/relations/{name}.relations"
        assert d.file_for("relations").path == d.relations
    assert registry["mit-killian"].log_file().path == "carmen/mit-killian-synthtime.clf.gz"
    # only mit-killian's relations carry the times its shared copy lost
    assert [n for n in NAMES if registry[n].relations_times == "retime"] == ["mit-killian"]
    assert registry["intel"].log_file().path == "carmen/intel.clf.gz"
    assert registry["intel"].expect["scans"].count == 13631


def test_ece276a_entries_list_files_and_image_folders():
    d20 = get_dataset("dataset20")
    assert [f.path for f in d20.files] == [
        "ece276a/Encoders20.npz",
        "ece276a/Imu20.npz",
        "ece276a/Hokuyo20.npz",
        "ece276a/Kinect20.npz",
        "ece276a/dataRGBD/RGB20/",
        "ece276a/dataRGBD/Disparity20/",
    ]
    hokuyo = d20.file_for("scans")
    assert hokuyo.size is None and hokuyo.sha256 is None  # not obtained: nothing to copy
    assert d20.file_for("rgb_images").is_dir and d20.file_for("rgb_images").entries == 2289
    assert d20.expect["encoders"].count == 4956 and d20.expect["imu"].rate_hz == 100.0
    d23 = get_dataset("dataset23")
    assert [f.path for f in d23.files] == [
        "ece276a/Encoders23.npz",
        "ece276a/Imu23.npz",
        "ece276a/Hokuyo23.npz",
    ]


def test_registry_sizes_and_hashes_match_the_manifest(data_dir):
    manifest = {}
    for line in (data_dir / "MANIFEST.tsv").read_text().splitlines():
        path, size, sha = line.split("\t")
        manifest[path] = (int(size), sha)
    registered = {}
    for dataset in load_registry().values():
        for f in dataset.files:
            if f.size is not None:
                registered[f.path] = (f.size, f.sha256)
    for path, value in registered.items():
        assert manifest[path] == value, path
    # Every ECE276A and CARMEN log file of the shared data is registered (bags and the single
    # starter-kit scan are not datasets).
    logs = {
        p
        for p in manifest
        if p.startswith(("ece276a/", "carmen/")) and not p.startswith("carmen/bags/")
    }
    assert logs - set(registered) == {"ece276a/hokuyo_single_scan.npy"}


def test_unknown_dataset_lists_known_names():
    with pytest.raises(DataError) as info:
        get_dataset("dataset22")
    assert "unknown dataset 'dataset22'; known datasets: dataset20, dataset21" in str(info.value)
    assert "mit-killian" in str(info.value)


# --- validation -------------------------------------------------------------------------------


def _raw() -> dict:
    return {
        "schema": 1,
        "datasets": {
            "toy": {
                "loader": "ece276a",
                "folder": "toy",
                "number": 7,
                "description": "a toy",
                "source": "tests",
                "expect": {"encoders": {"count": 10, "rate_hz": 40}},
                "files": [
                    {"path": "toy/Encoders7.npz", "streams": ["encoders"], "size": 3},
                    {"path": "toy/dataRGBD/RGB7/", "streams": ["rgb_images"], "entries": 2},
                ],
            },
            "log": {
                "loader": "carmen",
                "folder": "c",
                "relations": "c/r.relations",
                "description": "a log",
                "source": "tests",
                "files": [
                    {"path": "c/a.clf", "streams": ["scans", "odometry"]},
                    {"path": "c/r.relations", "streams": ["relations"]},
                ],
            },
        },
    }


def test_minimal_registry_parses():
    registry = parse_registry(_raw(), "reg.toml")
    assert registry["toy"].number == "7"
    assert registry["toy"].expect["encoders"].rate_hz == 40.0
    assert registry["log"].log_file().path == "c/a.clf"


def _set(raw: dict, dotted: str, value) -> dict:
    raw = copy.deepcopy(raw)
    *parents, last = dotted.split(".")
    node = raw
    for part in parents:
        node = node[int(part)] if isinstance(node, list) else node[part]
    if value is _DELETE:
        del node[last]
    elif isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return raw


_DELETE = object()


@pytest.mark.parametrize(
    "dotted, value, message",
    [
        ("schema", 2, "reg.toml: schema: expected 1, found 2"),
        ("datasets", {}, "datasets: expected at least one dataset"),
        ("datasets.toy.loader", "rosbag", "datasets.toy.loader: expected one of ece276a, carmen"),
        ("datasets.toy.loader", _DELETE, "datasets.toy.loader: required key is missing"),
        (
            "datasets.toy.relations_times",
            "shift",
            "datasets.toy.relations_times: expected one of log, retime, found 'shift'",
        ),
        ("datasets.toy.colour", "red", "datasets.toy.colour: unknown key"),
        (
            "datasets.toy.number",
            _DELETE,
            "datasets.toy.number: expected a dataset number for an ece276a dataset",
        ),
        (
            "datasets.toy.number",
            1.5,
            "datasets.toy.number: expected an integer or a string, found 1.5",
        ),
        (
            "datasets.log.number",
            3,
            "datasets.log.number: expected no number: only ece276a datasets have one, found 3",
        ),
        ("datasets.toy.files", [], "datasets.toy.files: expected a non-empty list"),
        ("datasets.toy.files.0.path", "/abs/Encoders7.npz", "files\\[0\\].path: expected a path"),
        ("datasets.toy.files.0.path", "toy/../x.npz", "files\\[0\\].path: expected a path"),
        ("datasets.toy.files.0.path", "other/E.npz", "files\\[0\\].path: expected a path inside"),
        ("datasets.toy.files.0.size", -1, "files\\[0\\].size: expected an integer ≥ 0, found -1"),
        ("datasets.toy.files.0.size", True, "files\\[0\\].size: expected an integer, found True"),
        ("datasets.toy.files.0.sha256", "abc", "files\\[0\\].sha256: expected 64 hex digits"),
        (
            "datasets.toy.files.0.streams",
            ["lidar"],
            "files\\[0\\].streams\\[0\\]: expected one of encoders, .*, found 'lidar'",
        ),
        (
            "datasets.toy.files.0.entries",
            4,
            "files\\[0\\].entries: expected entries only on a folder",
        ),
        (
            "datasets.toy.files.1.size",
            4,
            "files\\[1\\].size: expected no size or sha256 on a folder .*, found 4",
        ),
        (
            "datasets.toy.files.1",
            {"path": "toy/Encoders7.npz", "streams": ["imu"]},
            "'toy/Encoders7.npz' is listed twice",
        ),
        (
            "datasets.toy.expect.lidar",
            {"count": 1},
            "datasets.toy.expect.lidar: expected one of encoders, .*, found 'lidar'",
        ),
        (
            "datasets.toy.expect.encoders.rate_hz",
            0,
            "expect.encoders.rate_hz: expected a finite number > 0, found 0.0",
        ),
        ("datasets.toy.expect.encoders.hz", 1, "expect.encoders.hz: unknown key"),
        (
            "datasets.log.relations",
            "c/other",
            "datasets.log.relations: expected a relations file that is also listed under files, found 'c/other'",
        ),
        ("datasets.log.files.1.streams", ["scans"], "exactly one file providing 'scans'"),
        ("datasets.log.description", "", "datasets.log.description: expected a non-empty string"),
    ],
)
def test_registry_errors_name_the_key(dotted, value, message):
    with pytest.raises(ConfigError, match=message):
        parse_registry(_set(_raw(), dotted, value), "reg.toml")


def test_registry_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "datasets.toml"
    bad.write_text("[datasets.x\nloader = 1")
    with pytest.raises(ConfigError, match=f"{bad}: invalid TOML"):
        load_registry(bad)
    with pytest.raises(ConfigError, match="nothing.toml: dataset registry not found"):
        load_registry(tmp_path / "nothing.toml")
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"schema = 1\n# \xff\n")
    with pytest.raises(
        ConfigError, match=f"{binary}:2: expected text, found the non-text byte 0xff"
    ):
        load_registry(binary)


# --- status -----------------------------------------------------------------------------------


def test_status_present_partial_absent(tmp_path):
    registry = parse_registry(_raw())
    toy = registry["toy"]
    assert dataset_status(toy, tmp_path / "nowhere").state == "absent"
    status = dataset_status(toy, tmp_path)
    assert (status.state, status.present) == ("absent", ())
    assert status.missing == ("toy/Encoders7.npz", "toy/dataRGBD/RGB7/")
    (tmp_path / "toy").mkdir()
    (tmp_path / "toy/Encoders7.npz").write_bytes(b"abc")
    status = dataset_status(toy, tmp_path)
    assert (status.state, status.missing) == ("partial", ("toy/dataRGBD/RGB7/",))
    (tmp_path / "toy/dataRGBD/RGB7").mkdir(parents=True)
    status = dataset_status(toy, tmp_path)
    assert (status.state, status.missing) == ("present", ())
    assert status.as_dict() == {
        "name": "toy",
        "loader": "ece276a",
        "folder": "toy",
        "status": "present",
        "present": ["toy/Encoders7.npz", "toy/dataRGBD/RGB7/"],
        "missing": [],
    }


def test_a_file_is_not_a_folder_entry(tmp_path):
    toy = parse_registry(_raw())["toy"]
    (tmp_path / "toy/dataRGBD").mkdir(parents=True)
    (tmp_path / "toy/dataRGBD/RGB7").write_text("a file where a folder belongs")
    assert dataset_status(toy, tmp_path).missing == ("toy/Encoders7.npz", "toy/dataRGBD/RGB7/")


def test_real_status(data_dir):
    registry = load_registry()
    d20 = dataset_status(registry["dataset20"], data_dir)
    assert d20.state == "partial"
    assert d20.missing == (
        "ece276a/Hokuyo20.npz",
        "ece276a/dataRGBD/RGB20/",
        "ece276a/dataRGBD/Disparity20/",
    )
    assert dataset_status(registry["dataset23"], data_dir).missing == ("ece276a/Hokuyo23.npz",)
    for name in NAMES[3:]:
        assert dataset_status(registry[name], data_dir).state == "present"


def test_unreadable_data_dir(tmp_path):
    toy = parse_registry(_raw())["toy"]
    (tmp_path / "toy").mkdir()
    (tmp_path / "toy").chmod(0)
    try:
        if os.access(tmp_path / "toy", os.R_OK):
            pytest.skip("running as root: chmod 000 does not make a folder unreadable")
        with pytest.raises(DataError, match="toy: cannot read the folder of dataset toy"):
            dataset_status(toy, tmp_path)
    finally:
        (tmp_path / "toy").chmod(0o755)


def test_unreadable_dirs_without_permission_bits(tmp_path, monkeypatch):
    # What chmod 000 does for a normal user, for machines where the tests run as root.
    toy = parse_registry(_raw())["toy"]
    (tmp_path / "toy").mkdir()
    denied = {tmp_path / "toy"}
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode: False if Path(p) in denied else real_access(p, mode)
    )
    with pytest.raises(DataError, match=f"{tmp_path / 'toy'}: cannot read the folder of dataset"):
        dataset_status(toy, tmp_path)
    denied.add(tmp_path)
    with pytest.raises(DataError, match=f"{tmp_path}: cannot read the data directory"):
        dataset_status(toy, tmp_path)
    with pytest.raises(DataError, match=f"{tmp_path}: cannot read the data directory"):
        load_dataset("dataset20", tmp_path)


def test_data_dir_that_is_a_file(tmp_path):
    path = tmp_path / "data"
    path.write_text("")
    with pytest.raises(DataError, match=f"{path}: expected the data directory, found a file"):
        dataset_status(get_dataset("intel"), path)


# --- loading and verification -----------------------------------------------------------------


def test_load_dataset_dispatches_to_the_ece276a_loader(ece276a_dir):
    log = load_dataset("dataset20", ece276a_dir.parent)
    assert log.name == "dataset20" and log.kind == "ece276a"
    assert len(log.encoders) == 4956 and len(log.imu) == 12187
    with pytest.raises(DataError, match=r"dataset20: missing .*Hokuyo20\.npz .*ranges"):
        load_dataset("dataset20", ece276a_dir.parent, need=("encoders", "imu", "scans"))


def _write_hokuyo(path: Path, n: int = 5) -> None:
    """A small Hokuyo file in the documented format (angles (1, 1), ranges (1081, N))."""
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(
        path,
        angle_min=np.array([[-2.356194490192345]]),
        angle_max=np.array([[2.356194490192345]]),
        angle_increment=np.array([[0.004363323129985824]]),
        range_min=np.array([[0.1]]),
        range_max=np.array([[30.0]]),
        ranges=np.full((1081, n), 3.0, dtype=np.float32),
        time_stamps=1000.0 + np.arange(n) / 40.0,
    )


def test_load_dataset_applies_the_dataset_config(tmp_path):
    from slam.config import load_config

    _write_hokuyo(tmp_path / "ece276a/Hokuyo20.npz")
    log = load_dataset("dataset20", tmp_path, need=("scans",))  # configs/dataset20.toml
    assert log.encoders is None and len(log.scans) == 5
    np.testing.assert_allclose(log.scans.laser_offset, [0.13323, 0.0, 0.0])
    assert log.scans.no_return == 30.0
    config = load_config("dataset20", overrides=["lidar.x=0.3", "lidar.no_return=20.0"])
    log = load_dataset("dataset20", tmp_path, need=("scans",), config=config)
    np.testing.assert_allclose(log.scans.laser_offset, [0.3, 0.0, 0.0])
    assert log.scans.no_return == 20.0


def test_verify_partial_real_dataset(data_dir):
    report = verify_dataset("dataset20", data_dir)
    assert report["status"] == "partial" and report["problems"] == []
    assert report["missing"] == [
        "ece276a/Hokuyo20.npz",
        "ece276a/dataRGBD/RGB20/",
        "ece276a/dataRGBD/Disparity20/",
    ]
    assert [(f["path"], f["size"], f["sha256"]) for f in report["files"]] == [
        ("ece276a/Encoders20.npz", 25116, "ok"),
        ("ece276a/Imu20.npz", 586272, "ok"),
        ("ece276a/Kinect20.npz", 18120, "ok"),
    ]
    summary = report["summary"]
    assert summary["encoders"]["count"] == 4956 and summary["imu"]["count"] == 12187
    assert summary["rgb"]["count"] == 2289 and summary["disparity"]["count"] == 2407


def test_verify_reports_size_hash_count_and_rate_problems(tmp_path):
    raw = _raw()
    raw["datasets"]["toy"]["files"] = [
        {"path": "toy/Encoders7.npz", "streams": ["encoders"], "size": 1},
        {"path": "toy/Imu7.npz", "streams": ["imu"], "sha256": "0" * 64},
    ]
    raw["datasets"]["toy"]["expect"] = {
        "encoders": {"count": 10, "rate_hz": 40},
        "imu": {"count": 100, "rate_hz": 50},
    }
    registry = parse_registry(raw)
    folder = tmp_path / "toy"
    folder.mkdir()
    np.savez(
        folder / "Encoders7.npz",
        counts=np.ones((4, 12), np.int16),
        time_stamps=np.arange(12) / 40.0,
    )
    np.savez(
        folder / "Imu7.npz",
        angular_velocity=np.zeros((3, 100)),
        linear_acceleration=np.zeros((3, 100)),
        time_stamps=np.arange(100) / 100.0,
    )
    report = verify_dataset("toy", tmp_path, registry=registry)
    size = (folder / "Encoders7.npz").stat().st_size
    from slam.io.registry import sha256_of

    digest = sha256_of(folder / "Imu7.npz")
    assert report["status"] == "present"
    assert report["problems"] == [
        f"toy/Encoders7.npz: size {size} bytes, expected 1",
        f"toy/Imu7.npz: sha256 {digest}, expected {'0' * 64}",
        "encoders: 12 readings, expected 10",
        "imu: 100.00 Hz, expected 50 Hz ± 10%",
    ]


def test_verify_bad_file_and_absent_dataset(tmp_path):
    registry = parse_registry(_raw())
    with pytest.raises(DataError, match="toy: none of its files is under"):
        verify_dataset("toy", tmp_path, registry=registry)
    (tmp_path / "toy").mkdir()
    (tmp_path / "toy/Encoders7.npz").write_bytes(b"PK\x03\x04 truncated")
    report = verify_dataset("toy", tmp_path, registry=registry)
    assert report["status"] == "partial"
    assert report["problems"][0] == "toy/Encoders7.npz: size 14 bytes, expected 3"
    assert "Encoders7.npz: not a readable npz archive" in report["problems"][1]


def test_load_and_verify_a_carmen_dataset(carmen_dir):
    log = load_dataset("mit-csail", carmen_dir.parent, need=("scans",))
    assert log.kind == "carmen" and log.name == "mit-csail"
    assert len(log.scans) == 1988 and log.scans.num_beams == 361
    with pytest.raises(DataError, match="mit-csail.clf.gz: the log has no odometry stream"):
        load_dataset("mit-csail", carmen_dir.parent, need=("scans", "odometry"))
    report = verify_dataset("mit-csail", carmen_dir.parent)
    assert report["status"] == "present" and report["problems"] == []
    assert report["summary"]["scans"]["count"] == 1988
    assert [f["sha256"] for f in report["files"]] == ["ok", "ok"]


def test_verify_with_only_the_relations_file(tmp_path, carmen_dir):
    (tmp_path / "carmen/relations").mkdir(parents=True)
    (tmp_path / "carmen/relations/intel.relations").symlink_to(
        carmen_dir / "relations/intel.relations"
    )
    report = verify_dataset("intel", tmp_path)
    assert report["status"] == "partial" and report["missing"] == ["carmen/intel.clf.gz"]
    assert report["problems"] == [] and report["summary"] == {}
    with pytest.raises(DataError, match=r"intel: missing .*carmen/intel\.clf\.gz \(a CARMEN log"):
        load_dataset("intel", tmp_path)


def test_ece276a_registry_paths_match_the_loader():
    from slam.io.ece276a import rgbd_dirs, stream_file

    for name in ("dataset20", "dataset21", "dataset23"):
        d = get_dataset(name)
        root = Path("/d")
        for stream in ("encoders", "imu", "scans"):
            registered = d.file_for(stream).location(root)
            assert registered == stream_file(root / d.folder, d.number, stream)
        if d.file_for("rgb") is not None:
            assert d.file_for("rgb").location(root) == stream_file(
                root / d.folder, d.number, "kinect"
            )
            rgb_dir, disparity_dir = rgbd_dirs(root / d.folder, d.number)
            assert d.file_for("rgb_images").location(root) == rgb_dir
            assert d.file_for("disparity_images").location(root) == disparity_dir
