"""``slam data list`` and ``slam data verify`` as a user runs them."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from slam.cli import main


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _rows(out: str) -> dict[str, list[str]]:
    """Table rows of ``slam data list`` by dataset name: [loader, status, missing]."""
    rows = {}
    for line in out.splitlines():
        parts = line.split(None, 3)
        if len(parts) == 4 and parts[1] in ("ece276a", "carmen"):
            rows[parts[0]] = parts[1:]
    return rows


def test_list_shows_the_shared_datasets(capsys, data_dir):
    code, out, err = _run(capsys, "data", "list", "--data-dir", str(data_dir))
    assert code == 0 and err == ""
    assert out.splitlines()[0] == f"data directory: {data_dir} (--data-dir)"
    rows = _rows(out)
    assert list(rows) == [
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
    assert rows["dataset20"] == [
        "ece276a",
        "partial",
        "Hokuyo20.npz, dataRGBD/RGB20/, dataRGBD/Disparity20/",
    ]
    assert rows["dataset23"] == ["ece276a", "partial", "Hokuyo23.npz"]
    for name in ("intel", "aces", "fr079", "fr-clinic", "mit-csail", "mit-killian"):
        assert rows[name] == ["carmen", "present", "-"]
    assert "6 present, 3 partial, 0 absent." in out


def test_list_uses_slam_data_dir(capsys, data_dir, monkeypatch):
    monkeypatch.setenv("SLAM_DATA_DIR", str(data_dir))
    code, out, _ = _run(capsys, "data", "list", "--json")
    report = json.loads(out)
    assert code == 0 and report["data_dir"] == str(data_dir) and report["data_dir_exists"]
    by_name = {d["name"]: d for d in report["datasets"]}
    assert by_name["dataset20"]["status"] == "partial"
    assert by_name["dataset20"]["missing"] == [
        "ece276a/Hokuyo20.npz",
        "ece276a/dataRGBD/RGB20/",
        "ece276a/dataRGBD/Disparity20/",
    ]
    assert by_name["intel"]["present"] == [
        "carmen/intel.clf.gz",
        "carmen/relations/intel.relations",
    ]


def test_list_without_a_data_directory(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("SLAM_DATA_DIR", raising=False)
    monkeypatch.chdir(tmp_path)
    code, out, _ = _run(capsys, "data", "list")
    assert code == 0
    assert out.splitlines()[0] == "data directory: data (default)"
    assert "does not exist: every dataset is absent" in out
    assert {row[1] for row in _rows(out).values()} == {"absent"}
    assert "0 present, 0 partial, 9 absent." in out


def test_list_unreadable_data_dir(capsys, tmp_path, monkeypatch):
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode: False if Path(p) == tmp_path else real_access(p, mode)
    )
    code, out, err = _run(capsys, "data", "list", "--data-dir", str(tmp_path))
    assert code == 2 and out == ""
    assert err == f"slam: error: {tmp_path}: cannot read the data directory (permission denied)\n"


def test_verify_partial_dataset20(capsys, data_dir):
    code, out, err = _run(capsys, "data", "verify", "dataset20", "--data-dir", str(data_dir))
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0] == f"dataset20 (ece276a) in {data_dir}: partial"
    assert "  ok       ece276a/Encoders20.npz  (25116 bytes, sha256 ok)" in lines
    assert "  missing  ece276a/Hokuyo20.npz" in lines
    assert "  missing  ece276a/dataRGBD/RGB20/" in lines
    encoders = next(line for line in lines if line.startswith("  encoders"))
    assert encoders.split()[1:7] == ["4956", "readings", "123.64", "s", "40.08", "Hz"]
    imu = next(line for line in lines if line.startswith("  imu"))
    assert imu.split()[1:7] == ["12187", "readings", "121.93", "s", "99.94", "Hz"]
    assert "  imu_ends_early_s: 1.423919" in lines
    assert lines[-1] == (
        "result: the files present check out; 3 missing (see docs/data.md for where to put them)"
    )


def test_verify_json(capsys, data_dir):
    code, out, _ = _run(
        capsys, "data", "verify", "dataset21", "--data-dir", str(data_dir), "--json"
    )
    report = json.loads(out)
    assert code == 0 and report["problems"] == []
    assert report["summary"]["encoders"]["count"] == 4789
    assert report["summary"]["imu"]["count"] == 11730
    assert report["summary"]["disparity"]["count"] == 2188
    assert report["summary"]["rgb"]["count"] == 2112


def test_verify_unknown_dataset(capsys, tmp_path):
    code, out, err = _run(capsys, "data", "verify", "dataset99", "--data-dir", str(tmp_path))
    assert code == 2 and out == ""
    assert err.startswith("slam: error: unknown dataset 'dataset99'; known datasets: dataset20")
    assert err.count("\n") == 1


def test_verify_absent_dataset(capsys, tmp_path):
    code, _, err = _run(capsys, "data", "verify", "dataset23", "--data-dir", str(tmp_path))
    assert code == 2
    assert err.startswith(f"slam: error: dataset23: none of its files is under {tmp_path}")


def _complete_dataset23(data_dir: Path, target: Path, ranges: np.ndarray) -> None:
    """``target``/ece276a with the real encoder and IMU files (linked, not copied) and a
    synthetic Hokuyo23.npz in the documented format."""
    folder = target / "ece276a"
    folder.mkdir(parents=True)
    for name in ("Encoders23.npz", "Imu23.npz"):
        (folder / name).symlink_to(data_dir / "ece276a" / name)
    n = ranges.shape[1]
    np.savez(
        folder / "Hokuyo23.npz",
        angle_min=np.array([[-2.356194490192345]]),
        angle_max=np.array([[2.356194490192345]]),
        angle_increment=np.array([[0.004363323129985824]]),
        range_min=np.array([[0.1]]),
        range_max=np.array([[30.0]]),
        ranges=ranges,
        time_stamps=1299175883.2 + np.arange(n) / 40.0,
    )


def test_verify_complete_dataset_counts_invalid_beams(capsys, data_dir, tmp_path):
    ranges = np.full((1081, 81), 4.0, dtype=np.float32)
    ranges[0, :3] = np.nan
    ranges[1, 0] = np.inf
    ranges[2, 0] = 0.01
    ranges[3, :] = 30.0
    _complete_dataset23(data_dir, tmp_path, ranges)
    code, out, err = _run(capsys, "data", "verify", "dataset23", "--data-dir", str(tmp_path))
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0] == f"dataset23 (ece276a) in {tmp_path}: present"
    scans = lines.index(next(line for line in lines if line.startswith("  scans")))
    assert lines[scans].split()[1:7] == ["81", "readings", "2.00", "s", "40.00", "Hz"]
    assert lines[scans + 1].strip() == (
        "1081 beams, invalid beams 5, no-return beams 81, non-monotonic 0"
    )
    assert lines[-1] == "result: all files present and sound"


def test_verify_bad_file_exits_2_naming_it(capsys, data_dir, tmp_path):
    _complete_dataset23(data_dir, tmp_path, np.full((1081, 10), 4.0, np.float32))
    hokuyo = tmp_path / "ece276a" / "Hokuyo23.npz"
    hokuyo.write_bytes(hokuyo.read_bytes()[:2000])  # truncated
    code, out, err = _run(capsys, "data", "verify", "dataset23", "--data-dir", str(tmp_path))
    assert code == 2
    assert "result: 1 problem(s)" in out
    assert err.startswith(f"slam: error: dataset23: 1 problem(s) found: {hokuyo}: ")
    assert err.count("\n") == 1


def test_verify_reports_a_changed_file(capsys, data_dir, tmp_path):
    folder = tmp_path / "ece276a"
    folder.mkdir()
    (folder / "Imu23.npz").symlink_to(data_dir / "ece276a" / "Imu23.npz")
    np.savez(
        folder / "Encoders23.npz",
        counts=np.zeros((4, 3809), np.int16),
        time_stamps=1299175883.0 + np.arange(3809) / 40.0,
    )
    size = (folder / "Encoders23.npz").stat().st_size
    code, out, err = _run(
        capsys, "data", "verify", "dataset23", "--data-dir", str(tmp_path), "--json"
    )
    assert code == 2
    report = json.loads(out)
    assert report["problems"] == [f"ece276a/Encoders23.npz: size {size} bytes, expected 20074"]
    assert "1 problem(s) found" in err


def test_verify_carmen_dataset(capsys, carmen_dir):
    code, out, err = _run(
        capsys, "data", "verify", "intel", "--data-dir", str(carmen_dir.parent), "--json"
    )
    report = json.loads(out)
    assert code == 0 and err == "" and report["problems"] == []
    scans = report["summary"]["scans"]
    assert scans["count"] == 13631 and scans["beams"] == 180
    assert scans["non_monotonic"] == 631
    assert scans["duration_s"] == pytest.approx(2691.3, abs=0.05)


def test_console_entry_point(data_dir):
    env = dict(os.environ, SLAM_DATA_DIR=str(data_dir))
    proc = subprocess.run(
        [sys.executable, "-m", "slam", "data", "list"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert _rows(proc.stdout)["dataset20"][1] == "partial"


@pytest.mark.parametrize(
    ("make", "found"),
    [
        (lambda p: p.mkdir(), "expected a file, found a folder"),
        (lambda p: os.mkfifo(p), "expected a file, found a named pipe"),
        (lambda p: p.symlink_to("/nonexistent"), "is a symbolic link to '/nonexistent', which"),
    ],
)
def test_something_else_where_a_log_should_be_is_named(capsys, tmp_path, make, found):
    """The bugs: `slam data verify` called a folder, a pipe or a broken link where aces' log
    should be 'missing' and exited 0; given as a path, `slam data inspect` (and `slam run`)
    waited for ever on the pipe, and a broken link was 'no such file or folder'."""
    log = tmp_path / "carmen" / "aces.clf.gz"
    log.parent.mkdir()
    make(log)
    code, _, err = _run(capsys, "data", "verify", "aces", "--data-dir", str(tmp_path))
    assert code == 2 and err == f"slam: error: {log}: {err.split(f'{log}: ', 1)[1]}"
    assert found in err and err.count("\n") == 1
    if not log.is_dir():
        for argv in (
            ["data", "inspect", str(log)],
            ["run", str(log), "--out", str(tmp_path / "r")],
        ):
            code, _, err = _run(capsys, *argv)
            assert code == 2 and found in err and err.count("\n") == 1
        assert not (tmp_path / "r").exists()


def test_inspect_says_a_registry_name_is_not_a_path(capsys, tmp_path, monkeypatch):
    """The bug: `slam data inspect intel` said 'intel: not found'."""
    monkeypatch.chdir(tmp_path)
    code, _, err = _run(capsys, "data", "inspect", "intel")
    assert code == 2
    assert err == (
        "slam: error: slam data inspect: 'intel' is a registry dataset, not a path: "
        "`slam data verify intel` summarises it, or give its file\n"
    )


def test_verify_says_a_path_is_not_a_registry_name(capsys, tmp_path, monkeypatch):
    """The bug: `slam data verify run.bag` said "unknown dataset 'run.bag'; known datasets: …",
    as if the file were a misspelt name; a name that is neither stays that error."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run.bag").write_bytes(b"")
    code, _, err = _run(capsys, "data", "verify", "run.bag")
    assert code == 2
    assert err == (
        "slam: error: slam data verify: 'run.bag' is a path, not a registry dataset: "
        "`slam data inspect run.bag` summarises a log file, `slam data list` names the "
        "datasets verify checks\n"
    )
    code, _, err = _run(capsys, "data", "verify", "nosuch")
    assert code == 2 and "unknown dataset 'nosuch'; known datasets: " in err
