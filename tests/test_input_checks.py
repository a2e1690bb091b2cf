"""Hostile inputs that used to give silent wrong results, tracebacks or terabyte allocations.

Issue 11, items 4, 5, 6, 8, 9 and the loader/eval parts of 11. Each test says which item it covers
and what today's ``main`` (before the fix) does instead; every one of them fails there (the module
imports only what ``main`` has, so each fails for its own reason).
"""

from __future__ import annotations

import io
import json
import os
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from synthetic_logs import carmen_lines, flaser_line, path, write_carmen, write_ece276a

from slam.cli import main
from slam.config import load_config
from slam.errors import DataError, UsageError
from slam.io.carmen import load_carmen
from slam.io.ece276a import load_ece276a
from slam.io.tum import write_tum
from slam.trajectory import Trajectory

RUN = ["--no-record", "--no-texture", "--quiet"]


def one_line_error(capsys) -> str:
    """The stderr of a failed command: exactly one ``slam: error:`` line, no traceback."""
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("slam: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# --- item 4: scans without valid beams ------------------------------------------------------


def test_no_valid_beam_at_all_is_an_error_naming_the_file(carmen_dir, tmp_path, capsys):
    """Item 4: intel with lidar.range_min above every genuine reading. On main: exit 0 and a
    163 m path for 2.6 m of driving."""
    code = main(["run", "intel", "--data-dir", str(carmen_dir.parent), "--out",
                 str(tmp_path / "r"), "--max-scans", "300", "--set", "lidar.range_min=26.5",
                 *RUN])  # fmt: skip
    assert code == 2
    line = one_line_error(capsys)
    assert "intel.clf.gz: no scan has a valid beam" in line
    assert "[range_min, range_max) = [26.5, 27) m" in line
    assert "longest reading 81.83 m" in line
    assert not (tmp_path / "r").exists()


def test_all_nan_ranges_are_an_error(tmp_path, capsys):
    """Item 4: an ECE276A log whose every range is NaN. On main: exit 0 with a trajectory."""
    folder = write_ece276a(tmp_path / "d", ranges=np.full((1081, 200), np.nan, np.float32))
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    line = one_line_error(capsys)
    assert "Hokuyo20.npz: no scan has a valid beam" in line
    assert "of the 200 processed scans' 216200 readings, 216200 are invalid" in line


def test_many_sparse_scans_are_a_loud_warning(tmp_path, capsys):
    """Item 4: 60 % of the scans have no valid beam. On main: exit 0 and no warning at all (only
    filter.match_fallbacks in metrics.json)."""
    folder = write_ece276a(tmp_path / "d")
    hokuyo = folder / "Hokuyo20.npz"
    data = dict(np.load(hokuyo))
    data["ranges"][:, 80:] = np.nan
    np.savez(hokuyo, **data)
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 0
    captured = capsys.readouterr()
    expected = "120 of 200 processed scans (60%, more than checks.max_sparse_scan_share = 0.1)"
    assert expected in captured.err and expected not in captured.out
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert any(expected in w for w in metrics["warnings"])


# --- item 5: degenerate evaluations ---------------------------------------------------------


def _run_with(tmp_path: Path, times, poses) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    write_tum(
        run / "trajectory.tum", Trajectory(np.asarray(times, float), np.asarray(poses, float))
    )
    return run


def test_one_pose_reference_is_refused(tmp_path, capsys):
    """Item 5: a 1-pose reference 100 m off. On main: exit 0 and ATE rmse 0.0000 m."""
    run = _run_with(tmp_path, np.arange(10.0), np.zeros((10, 3)))
    reference = tmp_path / "ref.tum"
    write_tum(reference, Trajectory(np.array([5.0]), np.array([[100.0, 0.0, 0.0]])))
    assert main(["eval", str(run), "--reference", str(reference)]) == 2
    line = one_line_error(capsys)
    assert f"{run / 'trajectory.tum'}: only 1 pose time(s) match {reference}" in line
    assert "at least 3 matched poses at distinct times" in line
    assert not (run / "eval.json").exists()


def test_one_pose_estimate_is_refused(tmp_path, capsys):
    """Item 5: a 1-pose estimate. On main: exit 0 and ATE rmse 0.0000 m."""
    run = _run_with(tmp_path, [5.0], [[3.0, 4.0, 0.0]])
    reference = tmp_path / "ref.tum"
    write_tum(reference, Trajectory(np.arange(10.0), np.zeros((10, 3))))
    assert main(["eval", str(run), "--reference", str(reference)]) == 2
    assert "only 1 pose time(s) match" in one_line_error(capsys)


def test_poses_at_one_time_are_one_match(tmp_path, capsys):
    """Item 5: 50 estimate poses all at the same time (what all-equal Hokuyo timestamps give).
    On main: exit 0 and ATE 2e-16 m."""
    run = _run_with(tmp_path, np.full(50, 5.0), np.zeros((50, 3)))
    reference = tmp_path / "ref.tum"
    write_tum(reference, Trajectory(np.arange(10.0), np.c_[np.arange(10.0), np.zeros((10, 2))]))
    assert main(["eval", str(run), "--reference", str(reference)]) == 2
    assert "only 1 pose time(s) match" in one_line_error(capsys)


def test_zero_quaternion_is_refused_naming_the_line(tmp_path, capsys):
    """Item 5: a TUM line with qx = qy = qz = qw = 0. On main: accepted (yaw 0)."""
    run = _run_with(tmp_path, np.arange(10.0), np.zeros((10, 3)))
    reference = tmp_path / "ref.tum"
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    lines += [f"{t:.1f} {t:.1f} 0 0 0 0 0 1" for t in range(10)]
    lines[4] = "3.0 3.0 0 0 0 0 0 0"
    reference.write_text("\n".join(lines) + "\n")
    assert main(["eval", str(run), "--reference", str(reference)]) == 2
    line = one_line_error(capsys)
    assert f"{reference}:5: quaternion (qx qy qz qw) = (0 0 0 0) has norm 0" in line
    lines[4] = "3.0 3.0 0 0 0 0 0.5 0.5"  # norm 0.707
    reference.write_text("\n".join(lines) + "\n")
    assert main(["eval", str(run), "--reference", str(reference)]) == 2
    assert "has norm 0.707107; expected a unit quaternion (norm 1 ± 0.001)" in one_line_error(
        capsys
    )


def test_rpe_without_pairs_is_refused(tmp_path, capsys):
    """Item 5: --delta longer than the trajectory. On main: exit 0 with NaN RPE figures."""
    run = _run_with(tmp_path, np.arange(10.0), np.zeros((10, 3)))
    reference = tmp_path / "ref.tum"
    write_tum(reference, Trajectory(np.arange(10.0), np.zeros((10, 3))))
    code = main(["eval", str(run), "--reference", str(reference), "--delta", "100",
                 "--delta-unit", "seconds"])  # fmt: skip
    assert code == 2
    assert "lies 100 seconds apart" in one_line_error(capsys)


# --- item 6: time base ----------------------------------------------------------------------


def test_hokuyo_clock_offset_is_an_error(tmp_path, capsys):
    """Item 6: Hokuyo stamps shifted by 1e9 s (another clock) and by 1e18 s (where float64 makes
    them all equal). On main: exit 0, a warning on stdout only."""
    t = 1298445274.5 + np.arange(200) / 40.0
    folder = write_ece276a(tmp_path / "d", scan_times=t + 1e9)
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    line = one_line_error(capsys)
    assert "Hokuyo20.npz: key 'time_stamps': only 0 of 200 readings (0%) lie within" in line
    assert "Encoders20.npz: key 'time_stamps'" in line and "share a clock" in line
    folder = write_ece276a(tmp_path / "d", scan_times=t + 1e18)
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    assert "Hokuyo20.npz: key 'time_stamps': all 200 timestamps are equal" in one_line_error(capsys)


def test_equal_encoder_stamps_are_an_error(tmp_path, capsys):
    """Item 6: every encoder stamp equal. On main: exit 0 (a 0 m trajectory)."""
    folder = write_ece276a(tmp_path / "d", encoder_times=np.full(200, 1298445274.5))
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    line = one_line_error(capsys)
    assert "Encoders20.npz: key 'time_stamps': all 200 timestamps are equal" in line


def test_equal_hokuyo_stamps_are_an_error(tmp_path, capsys):
    """Items 5 and 6: every Hokuyo stamp equal. On main: exit 0, a 0 m path, ATE 2e-16."""
    folder = write_ece276a(tmp_path / "d", scan_times=np.full(200, 1298445276.0))
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    assert "Hokuyo20.npz: key 'time_stamps': all 200 timestamps are equal" in one_line_error(capsys)


def test_reversed_hokuyo_stamps_are_an_error(tmp_path, capsys):
    """Item 6: Hokuyo stamps in reverse order. On main: exit 0, no warning, ATE 50× worse."""
    t = 1298445274.5 + np.arange(200) / 40.0
    folder = write_ece276a(tmp_path / "d", scan_times=t[::-1].copy())
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    line = one_line_error(capsys)
    assert "Hokuyo20.npz: key 'time_stamps': 199 of 199 timestamp steps go backwards" in line
    assert "checks.strict_time = false accepts it" in line


def test_strict_time_false_accepts_with_warnings_on_stderr(tmp_path, capsys):
    """Item 6: the documented option that accepts a broken time base; its warnings go to stderr
    and metrics.json. On main: no such option (unknown section [checks])."""
    t = 1298445274.5 + np.arange(200) / 40.0
    folder = write_ece276a(tmp_path / "d", scan_times=t[::-1].copy())
    out = tmp_path / "r"
    code = main(["run", str(folder), "--out", str(out), "--set", "checks.strict_time=false",
                 *RUN])  # fmt: skip
    assert code == 0
    captured = capsys.readouterr()
    assert "slam: warning:" in captured.err and "go backwards" in captured.err
    assert "warning" not in captured.out
    warnings_ = json.loads((out / "metrics.json").read_text())["warnings"]
    assert any("199 of 199 timestamp steps go backwards" in w for w in warnings_)


def test_intel_backward_steps_are_counted_warnings(carmen_dir, tmp_path, capsys):
    """Item 6: intel's 631 backward scan timestamps (legitimate in CARMEN logs) run, with a
    counted warning on stderr and in metrics.json. On main: no warning anywhere."""
    out = tmp_path / "r"
    code = main(["run", "intel", "--data-dir", str(carmen_dir.parent), "--out", str(out),
                 "--max-scans", "30", *RUN])  # fmt: skip
    assert code == 0
    captured = capsys.readouterr()
    text = "intel.clf.gz: scan timestamps: 631 of 13630 timestamp steps go backwards (4.6%)"
    assert text in captured.err and text not in captured.out
    assert any(text in w for w in json.loads((out / "metrics.json").read_text())["warnings"])


# --- item 8: odometry jumps -----------------------------------------------------------------


def test_flaser_odometry_spike_names_the_line(tmp_path, capsys):
    """Item 8: one FLASER line with odometry x = 1e9. On main: the map tries to allocate
    1.7e8 TiB (MemoryError traceback)."""
    lines = carmen_lines(40)
    pose = path(40)[10].copy()
    pose[0] = 1e9
    lines[10] = flaser_line(np.full(180, 2.0), pose, 101.0)
    log = write_carmen(tmp_path, lines)
    assert main(["run", str(log), "--out", str(tmp_path / "r"), *RUN]) == 2
    line = one_line_error(capsys)
    assert f"{log}:12: scan odometry moves 1e+09 m from line 11 in 0.1 s" in line
    assert "more than checks.max_speed = 10 m/s" in line


def test_ten_km_jump_names_the_line(tmp_path, capsys):
    """Item 8: the odometry jumps 10 km between two lines and stays there. On main: the maps
    grow to 10 km (hundreds of MB per particle) or run out of memory."""
    poses = path(40)
    poses[20:, 0] += 10000.0
    angles = np.linspace(-np.pi / 2, np.pi / 2, 180)
    from synthetic_logs import ray_cast

    lines = [
        flaser_line(ray_cast(path(40)[k], angles), p, 100.0 + 0.1 * k) for k, p in enumerate(poses)
    ]
    log = write_carmen(tmp_path, lines)
    assert main(["run", str(log), "--out", str(tmp_path / "r"), *RUN]) == 2
    assert f"{log}:22: scan odometry moves 1e+04 m from line 21" in one_line_error(capsys)


def test_a_jump_in_the_odom_messages_names_the_line(tmp_path, capsys):
    """The bug: the ODOM messages (which robot.odometry_sync = "auto" may pick for the run's
    odometry) were never checked: one with x + 50 m ended in an online 'Slam.update: ...
    moves 15.4 m' naming no file, x = 1e9 in a memory estimate of 813 TiB."""
    angles = np.linspace(-np.pi / 2, np.pi / 2, 180)
    from synthetic_logs import ray_cast

    poses = path(40)
    lines = []
    for k, p in enumerate(poses):
        lines.append(flaser_line(ray_cast(p, angles), p, 100.0 + 0.1 * k))
        x = p[0] + (50.0 if k == 20 else 0.0)
        lines.append(f"ODOM {x} {p[1]} {p[2]} 0 0 0 {100.05 + 0.1 * k} h {100.05 + 0.1 * k}")
    log = write_carmen(tmp_path, lines)
    assert main(["run", str(log), "--out", str(tmp_path / "r"), *RUN]) == 2
    line = one_line_error(capsys)
    assert f"{log}:43: ODOM moves 50.05 m from line 41 in 0.1 s" in line
    assert line.endswith(
        'robot.odometry_sync = "scan" reads the poses written with the scans instead of these messages'
    )
    assert not (tmp_path / "r").exists()
    # a run that does not read the messages is not refused for them (review)
    scan_poses = ["--set", 'robot.odometry_sync="scan"']
    assert main(["run", str(log), "--out", str(tmp_path / "r"), *RUN, *scan_poses]) == 0


@pytest.mark.parametrize(
    "name", ["intel", "aces", "fr079", "fr-clinic", "mit-csail", "mit-killian", "dataset20"]
)
def test_real_logs_have_no_implausible_odometry_step(data_dir, name):
    """Item 8: the rule flags no step of the real logs (fastest: mit-csail, 4.5 m/s). On main:
    there is no rule (slam.io.plausibility does not exist)."""
    from slam.io.plausibility import first_jump, odometry_jump
    from slam.io.registry import load_dataset

    config = load_config(name)
    log = load_dataset(name, data_dir, need=(), config=config)
    assert odometry_jump(log, config) is None
    if log.scans is not None and log.scans.odometry is not None:
        found = first_jump(log.scans.time, log.scans.odometry[:, :2], 4.4)
        assert (found is not None) == (name == "mit-csail")  # the bound's margin is real


# --- item 9: sizes from headers and beam counts ---------------------------------------------


def test_beam_count_above_the_maximum_is_refused(tmp_path):
    """Item 9: a consistent line claiming more than 8192 beams (every scan would be padded to it).
    On main: loaded, padding all scans (2,000,000 beams took 24 GB)."""
    lines = carmen_lines(5)
    lines[2] = flaser_line(np.full(8193, 2.0), path(5)[2], 100.2)
    log = write_carmen(tmp_path, lines)
    with pytest.raises(
        DataError, match=r"room.clf:4: FLASER beam count: expected 1..8192, found 8193"
    ):
        load_carmen(log)


def test_padding_is_checked_against_the_memory_budget(tmp_path):
    """Item 9: the padded scan array is checked before it is allocated. On main: load_carmen
    has no memory budget (TypeError on the argument)."""
    log = write_carmen(tmp_path, carmen_lines(5))
    with pytest.raises(
        UsageError, match=r"room.clf: 5 scans padded to the widest scan's 180 beams"
    ):
        load_carmen(log, memory_share=1e-12)


def _npz_with_header(path: Path, arrays: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path, "w") as zf:
        for key, data in arrays.items():
            zf.writestr(f"{key}.npy", data)


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, array)
    return buf.getvalue()


def _forged_hokuyo(folder: Path, ranges_member: bytes) -> Path:
    """Hokuyo20.npz with real scalars and times and the given raw ``ranges.npy`` member."""
    write_ece276a(folder)
    path = folder / "Hokuyo20.npz"
    members = {k: _npy(v) for k, v in np.load(path).items() if k != "ranges"}
    members["ranges"] = ranges_member
    _npz_with_header(path, members)
    return path


def test_npz_header_claiming_745_gib_is_refused_in_run_and_verify(tmp_path, capsys):
    """Item 9: a member header claiming shape (4, 10^11). On main: numpy allocates 745 GiB
    (MemoryError traceback) in `run` and `data verify`."""
    small = _npy(np.zeros((4, 10), np.float64))
    forged = small.replace(b"(4, 10)", b"(4, 100000000000)")
    header_len = int.from_bytes(forged[8:10], "little")  # keep the header length right
    forged = (
        forged[:10] + forged[10 : 10 + header_len].ljust(header_len) + forged[10 + header_len :]
    )
    path = _forged_hokuyo(tmp_path / "d", forged)
    with pytest.raises(DataError, match=r"key 'ranges': its header claims shape \(4, 100000000000\) of "
                       r"float64 \(2.9 TiB\), but the archive holds \d+ B for it"):  # fmt: skip
        load_ece276a(tmp_path / "d", 20, need=("scans",))
    assert main(["run", str(tmp_path / "d"), "--out", str(tmp_path / "r"), *RUN]) == 2
    assert f"{path}: key 'ranges': its header claims shape" in one_line_error(capsys)
    from slam.io.registry import parse_registry, verify_dataset

    registry = parse_registry(
        {"datasets": {"toy": {"loader": "ece276a", "folder": "d", "number": 20,
                              "description": "toy", "source": "test",
                              "files": [{"path": "d/Hokuyo20.npz", "streams": ["scans"]}]}}}
    )  # fmt: skip
    report = verify_dataset("toy", tmp_path, registry=registry, config=load_config())
    assert any("its header claims shape (4, 100000000000)" in p for p in report["problems"])


def test_corrupt_npy_header_gives_a_clean_message(tmp_path):
    """Items 9 and 11: a header whose shape is not a literal. On main: the message shows
    `<ast.Name object at 0x…>`."""
    forged = _npy(np.zeros((4, 10))).replace(b"(4, 10)", b"(a, 10)")
    path = _forged_hokuyo(tmp_path / "d", forged)
    with pytest.raises(DataError) as info:
        load_ece276a(tmp_path / "d", 20, need=("scans",))
    assert str(info.value) == (
        f"{path}: key 'ranges' has a corrupt .npy header (not the shape/dtype dictionary numpy "
        "writes); the file is damaged"
    )


# --- item 11: loader and eval messages ------------------------------------------------------


def test_npz_that_is_a_folder_or_a_symlink_loop_says_what_it_is(tmp_path, capsys):
    """Item 11: on main both are reported as "missing … Put the file there"."""
    folder = write_ece276a(tmp_path / "d")
    hokuyo = folder / "Hokuyo20.npz"
    hokuyo.unlink()
    hokuyo.mkdir()
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    assert f"{hokuyo}: expected a file, found a folder" in one_line_error(capsys)
    hokuyo.rmdir()
    os.symlink(hokuyo, hokuyo)
    assert main(["run", str(folder), "--out", str(tmp_path / "r"), *RUN]) == 2
    assert f"{hokuyo}: is a symbolic link loop, expected a file" in one_line_error(capsys)


def test_eval_no_overlap_names_the_trajectory_file(tmp_path, capsys):
    """Item 11: on main the reference case says "no estimate pose lies within the reference's
    time range" without any file, and the relations case does not name the trajectory."""
    run = _run_with(tmp_path, 1000.0 + np.arange(10.0), np.zeros((10, 3)))
    reference = tmp_path / "ref.tum"
    write_tum(reference, Trajectory(np.arange(10.0), np.zeros((10, 3))))
    assert main(["eval", str(run), "--reference", str(reference)]) == 2
    line = one_line_error(capsys)
    assert (
        f"{run / 'trajectory.tum'}: none of its poses lies within the time span of {reference}"
        in line
    )
    relations = tmp_path / "r.relations"
    relations.write_text("1.0 2.0 0.1 0 0 0 0 0\n")
    assert main(["eval", str(run), "--relations", str(relations)]) == 2
    line = one_line_error(capsys)
    assert (
        f"{relations}: none of its 1 relations matches two poses of {run / 'trajectory.tum'}"
        in line
    )


def test_absurd_ranges_are_invalid_beams_without_numpy_warnings(tmp_path):
    """Item 11: a 1e308 range. On main: numpy's "overflow encountered in cast" RuntimeWarning
    leaks (CARMEN and ECE276A), and the reading becomes inf."""
    lines = carmen_lines(5)
    lines[1] = flaser_line([1e308, *np.full(179, 2.0)], path(5)[1], 100.1)
    log = write_carmen(tmp_path, lines)
    ranges = np.full((1081, 200), 5.0)
    ranges[7, 3] = 1e308
    write_ece276a(tmp_path / "d", ranges=ranges)  # float64, as a file may hold
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        carmen = load_carmen(log).scans
        ece = load_ece276a(tmp_path / "d", 20, need=("scans",)).scans
    assert np.isnan(carmen.ranges[1, 0]) and carmen.invalid_beams == 1
    assert np.isnan(ece.ranges[3, 7]) and ece.invalid_beams == 1


def test_a_diverging_map_is_refused_before_it_is_allocated():
    """Item 8 (the allocation it caused): a map asked to cover 1e7 m. On main: numpy's
    MemoryError traceback (or the OOM killer)."""
    from slam.config import MapConfig
    from slam.mapping import OccupancyGrid, ParticleMaps

    grid = OccupancyGrid(MapConfig())
    with pytest.raises(UsageError, match=r"an occupancy grid of 100000\d\d m × 40 m would need"):
        grid.ensure_contains(-20.0, -10.0, 1e7, 10.0)
    maps = ParticleMaps(30, 0.05, 0.3)
    with pytest.raises(UsageError, match=r"30 particle-map tables of .* would need about"):
        maps.ensure_contains(-1e7, -1e7, 1e7, 1e7)


def test_a_beam_count_that_changes_is_shown(tmp_path, capsys):
    """The bug: a log whose scans change from 180 to 90 beams was summarised as '180 beams' by
    `slam data inspect` (and fr-clinic's 180/181 as '181 beams')."""
    from synthetic_logs import ray_cast

    poses = path(30)
    lines = []
    for k, p in enumerate(poses):
        angles = np.linspace(-np.pi / 2, np.pi / 2, 180 if k < 20 else 90)
        lines.append(flaser_line(ray_cast(p, angles), p, 100.0 + 0.1 * k))
    log = write_carmen(tmp_path, lines)
    assert main(["data", "inspect", str(log)]) == 0
    assert ", beams 180 (20 scans), 90 (10 scans)" in capsys.readouterr().out


def test_a_clock_that_leaps_a_day_is_an_error(tmp_path, capsys):
    """The bug: 1e12 s added to the scans' times from the middle of a log ran to the end and
    reported '1083151406246.2x real time'; `slam data inspect` showed 0.00 Hz."""
    from synthetic_logs import ray_cast

    angles = np.linspace(-np.pi / 2, np.pi / 2, 180)
    poses = path(40)
    lines = [
        flaser_line(ray_cast(p, angles), p, 100.0 + 0.1 * k + (1e12 if k >= 20 else 0.0))
        for k, p in enumerate(poses)
    ]
    log = write_carmen(tmp_path, lines)
    assert main(["run", str(log), "--out", str(tmp_path / "r"), *RUN]) == 2
    assert (
        f"{log}: scan timestamps: the clock steps 1e+12 s forward between readings 19 and 20"
        in one_line_error(capsys)
    )
    assert not (tmp_path / "r").exists()


def test_calibrate_refuses_what_run_refuses(tmp_path, capsys):
    """The bug: `slam data calibrate` on a log whose timestamps all run backwards recommended an
    odometry, exit 0, where `slam run` refuses the log."""
    from synthetic_logs import ray_cast

    angles = np.linspace(-np.pi / 2, np.pi / 2, 180)
    poses = path(40)
    lines = [flaser_line(ray_cast(p, angles), p, 200.0 - 0.1 * k) for k, p in enumerate(poses)]
    log = write_carmen(tmp_path, lines)
    assert main(["data", "calibrate", str(log)]) == 2
    assert "39 of 39 timestamp steps go backwards" in one_line_error(capsys)
