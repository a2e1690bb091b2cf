"""CARMEN loader: real benchmark logs (counts, rates, geometry) and every malformed-input case."""

from __future__ import annotations

import gzip
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slam.config import LidarConfig, load_config
from slam.errors import ConfigError, DataError
from slam.eval.relations import match_times
from slam.io.carmen import DEFAULT_NO_RETURN, DEFAULT_RANGE_MIN, load_carmen
from slam.io.log import Log
from slam.io.relations import read_relations

# --- real logs ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def intel(carmen_dir: Path) -> Log:
    return load_carmen(carmen_dir / "intel.clf.gz", name="intel", lidar=load_config("intel").lidar)


def test_intel_counts_rates_and_order(intel: Log):
    scans = intel.scans
    assert len(scans) == 13631
    assert scans.non_monotonic == 631
    assert scans.num_beams == 180
    assert scans.angles.shape == (180,)
    assert scans.angles[0] == pytest.approx(-np.pi / 2)
    assert scans.angles[-1] == pytest.approx(np.pi / 2)
    assert np.diff(scans.angles) == pytest.approx(np.full(179, np.pi / 179))
    assert scans.ranges.dtype == np.float32 and scans.ranges.shape == (13631, 180)
    assert scans.odometry.shape == (13631, 3) and scans.laser_pose.shape == (13631, 3)
    np.testing.assert_array_equal(scans.laser_offset, [0.0, 0.0, 0.0])
    assert scans.time[0] == pytest.approx(976052857.337530, abs=1e-6)
    summary = intel.summary()
    assert summary["scans"]["duration_s"] == pytest.approx(2691.296, abs=1e-3)
    assert summary["scans"]["rate_hz"] == pytest.approx(5.0645, abs=1e-3)
    assert summary["scans"]["no_return_beams"] == 68313  # the 81.83 m code, intel config
    assert summary["scans"]["invalid_beams"] == 0
    assert summary["odometry"]["count"] == 26915
    assert summary["comment_lines"] == 2
    assert summary["laser_offset_source"] == "log"
    assert scans.range_max == 27.0 and scans.no_return == 80.0


def test_intel_odometry_follows_file_order(intel: Log):
    # docs/data-formats.md §2: the odometry path is 508 m in file order, 661 m sorted by time.
    odom = intel.scans.odometry
    in_file_order = np.hypot(*np.diff(odom[:, :2], axis=0).T).sum()
    by_time = odom[np.argsort(intel.scans.time, kind="stable")]
    sorted_length = np.hypot(*np.diff(by_time[:, :2], axis=0).T).sum()
    assert in_file_order == pytest.approx(508, abs=1)
    assert sorted_length == pytest.approx(661, abs=1)


def test_relations_match_ipc_timestamps(intel: Log, carmen_dir: Path):
    relations = read_relations(carmen_dir / "relations" / "intel.relations")
    assert len(relations) == 2984
    for t in (relations.t1, relations.t2):
        assert np.all(match_times(intel.scans.time, t, tolerance=1e-9) >= 0)


@pytest.mark.parametrize(
    "name, scans, beams, odom, no_return_beams",
    [
        ("aces", 7374, 180, 7375, 11139),
        ("fr079", 4934, 360, 8951, 36881),
        ("mit-csail", 1988, 361, 0, 23711),
    ],
)
def test_other_logs_counts(carmen_dir, name, scans, beams, odom, no_return_beams):
    log = load_carmen(carmen_dir / f"{name}.clf.gz", name=name, lidar=load_config(name).lidar)
    assert len(log.scans) == scans
    assert log.scans.num_beams == beams
    assert log.scans.angles.shape == (beams,)
    assert log.scans.non_monotonic == 0
    assert log.summary()["scans"]["no_return_beams"] == no_return_beams
    assert (len(log.odometry) if log.odometry is not None else 0) == odom
    np.testing.assert_array_equal(log.scans.laser_offset, [0.0, 0.0, 0.0])
    if name == "mit-csail":
        # Relations match the ipc timestamps (to 5e-6 s); the logger stamps start at 0.09 s.
        rel = read_relations(carmen_dir / "relations" / "mit-csail.relations")
        assert np.all(match_times(log.scans.time, rel.t1, tolerance=1e-5) >= 0)
        assert log.scans.time[0] == pytest.approx(1134864629.895182, abs=1e-6)


def test_fr_clinic_mixes_180_and_181_beams(carmen_dir):
    from slam.io import sources

    ref = sources.resolve("fr-clinic", carmen_dir.parent, where="test")
    source = sources.load(ref, load_config("fr-clinic"), ("scans",))
    log, scans = source.log, source.log.scans
    assert len(scans) == 6917
    assert scans.angles.shape == (6917, 181)
    short = np.isnan(scans.angles[:, -1])
    assert np.count_nonzero(short) == 5169
    assert np.all(np.isnan(scans.ranges[short, -1]))
    # measured when it loads (configs/fr-clinic.toml declares no step): 1° beams, centred; the
    # 180-reading scans on the half degrees
    assert source.beam_step_deg == 1.0 and source.beam_geometry["best"] == "centred"
    first_short = scans.scan_angles(int(np.flatnonzero(short)[0]))
    first_long = scans.scan_angles(int(np.flatnonzero(~short)[0]))
    assert first_short[[0, 179]] == pytest.approx(np.deg2rad([-89.5, 89.5]))
    assert first_long[[0, 180]] == pytest.approx(np.deg2rad([-90.0, 90.0]))
    spread = load_carmen(carmen_dir / "fr-clinic.clf.gz", lidar=LidarConfig(fov_deg=180.0)).scans
    assert spread.scan_angles(int(np.flatnonzero(short)[0]))[179] == pytest.approx(np.pi / 2)
    assert scans.invalid_beams == 0  # NaN padding is not an invalid reading
    assert log.summary()["scans"]["no_return_beams"] == 5849 + 150066


# --- small hand-written logs ----------------------------------------------------------------------


def flaser(ranges, pose=(0.0, 0.0, 0.0), odom=None, t=1.0, host="h") -> str:
    odom = pose if odom is None else odom
    fields = ["FLASER", str(len(ranges)), *map(str, ranges), *map(str, pose), *map(str, odom)]
    return " ".join([*fields, f"{t:.6f}", host, f"{t:.6f}"])


def odom_line(x, y, theta, t) -> str:
    return f"ODOM {x} {y} {theta} 0.1 0.2 0 {t:.6f} h {t + 0.5:.6f}"


def write(tmp_path: Path, lines: list[str], name: str = "log.clf") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_small_log_parses_exactly(tmp_path):
    lines = [
        "# a comment",
        "PARAM robot_width 0.5",
        odom_line(0.0, 0.0, 0.0, 9.5),
        flaser([1.0, 2.0, 3.0], pose=(0.1, 0.2, 0.3), odom=(0.0, 0.2, 0.3), t=10.0),
        "",
        flaser([4.0, 85.0, 5.0], pose=(1.1, 1.2, 1.3), odom=(1.0, 1.2, 1.3), t=9.0),
        "SYNC x",
        "PARAM other 1",
        flaser(["nan", "inf", "-1"], t=11.0),
        flaser(["0", "0.01", "0.07"], t=12.0),
    ]
    log = load_carmen(write(tmp_path, lines), lidar=LidarConfig(use_log_laser_pose=False))
    scans = log.scans
    assert log.kind == "carmen" and log.name == "log"
    np.testing.assert_array_equal(scans.time, [10.0, 9.0, 11.0, 12.0])
    assert scans.non_monotonic == 1
    np.testing.assert_allclose(scans.angles, [-np.pi / 2, 0.0, np.pi / 2])
    np.testing.assert_array_equal(scans.ranges[0], np.float32([1, 2, 3]))
    np.testing.assert_array_equal(scans.ranges[1], np.float32([4, 85, 5]))
    # nan, inf, negative, zero and 0.01 (< range_min 0.05) are invalid; 0.07 is valid.
    assert scans.invalid_beams == 5
    assert np.isnan(scans.ranges[2]).all() and np.isnan(scans.ranges[3, :2]).all()
    assert scans.ranges[3, 2] == np.float32(0.07)
    np.testing.assert_array_equal(scans.laser_pose[0], [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(scans.odometry[1], [1.0, 1.2, 1.3])
    assert scans.range_min == DEFAULT_RANGE_MIN
    assert scans.no_return == scans.range_max == DEFAULT_NO_RETURN
    assert log.summary()["scans"]["no_return_beams"] == 1  # the 85 m reading
    # use_log_laser_pose = false: the config's offset (ECE276A defaults) is used as is.
    np.testing.assert_array_equal(scans.laser_offset, [0.13323, 0.0, 0.0])
    np.testing.assert_array_equal(log.odometry.time, [9.5])
    np.testing.assert_array_equal(log.odometry.velocities, [[0.1, 0.2]])
    assert log.meta["comments"] == ["a comment"]
    assert log.meta["skipped"] == {"PARAM": 2, "SYNC": 1}
    assert log.meta["skipped_lines"] == 3
    assert log.summary()["skipped_types"] == "PARAM=2, SYNC=1"


def test_laser_offset_from_log_is_the_median(tmp_path):
    lines = []
    for k, theta in enumerate([0.0, 1.0, -2.0, 3.0, 0.5]):
        c, s = np.cos(theta), np.sin(theta)
        odom = (float(k), 2.0, theta)
        # laser 0.25 m ahead and 0.05 m left of the robot, turned by 0.1 rad
        laser = (k + 0.25 * c - 0.05 * s, 2.0 + 0.25 * s + 0.05 * c, theta + 0.1)
        lines.append(flaser([1.0, 1.0], pose=laser, odom=odom, t=k))
    lines.append(flaser([1.0, 1.0], pose=(9.0, 9.0, 2.0), odom=(0.0, 0.0, 0.0), t=9))  # outlier
    log = load_carmen(write(tmp_path, lines), lidar=LidarConfig(fov_deg=90.0))
    np.testing.assert_allclose(log.scans.laser_offset, [0.25, 0.05, 0.1], atol=1e-9)
    np.testing.assert_allclose(log.scans.angles, [-np.pi / 4, np.pi / 4])
    assert log.meta["laser_offset_x"] == pytest.approx(0.25)
    assert log.meta["laser_offset_source"] == "log"
    assert [log.meta[f"laser_offset_{k}"] for k in ("x", "y", "yaw")] == [
        float(v) for v in log.scans.laser_offset
    ]


def test_gzip_is_detected_by_magic_bytes(tmp_path):
    text = "\n".join([flaser([1.0, 2.0], t=1.0), flaser([3.0, 4.0], t=2.0)]) + "\n"
    plain = tmp_path / "plain.clf"
    plain.write_text(text)
    hidden = tmp_path / "compressed.clf"  # gzip content without a .gz suffix
    hidden.write_bytes(gzip.compress(text.encode()))
    a, b = load_carmen(plain), load_carmen(hidden)
    np.testing.assert_array_equal(a.scans.ranges, b.scans.ranges)
    np.testing.assert_array_equal(b.scans.time, [1.0, 2.0])


def test_mixed_beam_counts_pad_with_nan(tmp_path):
    lines = [flaser([1.0, 2.0, 3.0], t=1), flaser([1.0, 2.0], t=2), flaser([5.0, 6.0, 7.0], t=3)]
    scans = load_carmen(write(tmp_path, lines)).scans
    assert scans.angles.shape == (3, 3)
    np.testing.assert_allclose(scans.angles[1, :2], [-np.pi / 2, np.pi / 2])
    assert np.isnan(scans.angles[1, 2]) and np.isnan(scans.ranges[1, 2])
    np.testing.assert_array_equal(scans.ranges[2], np.float32([5, 6, 7]))
    assert scans.invalid_beams == 0


def robotlaser(ranges, remissions=(), start=-1.0, res=0.5, max_range=40.0, t=1.0) -> str:
    fields = ["ROBOTLASER1", "0", str(start), str(res * (len(ranges) - 1)), str(res)]
    fields += [str(max_range), "0.01", "0", str(len(ranges)), *map(str, ranges)]
    fields += [str(len(remissions)), *map(str, remissions)]
    fields += ["1.1", "2.0", "0.5", "1.0", "2.0", "0.5"]  # laser pose, robot pose
    fields += ["0.3", "0.1", "0.5", "0.2", "0.1", f"{t:.6f}", "host", f"{t:.6f}"]
    return " ".join(fields)


def test_robotlaser1_carries_its_geometry(tmp_path):
    lines = [robotlaser([1.0, 2.0, 3.0, 45.0], remissions=(0.5, 0.6), t=5.0)]
    lines.append(robotlaser([2.0, 2.5, 3.5, 4.5], t=6.0))
    log = load_carmen(write(tmp_path, lines))
    scans = log.scans
    np.testing.assert_allclose(scans.angles, [-1.0, -0.5, 0.0, 0.5])
    np.testing.assert_array_equal(scans.ranges[0], np.float32([1, 2, 3, 45]))
    np.testing.assert_array_equal(scans.odometry[0], [1.0, 2.0, 0.5])
    np.testing.assert_array_equal(scans.laser_pose[1], [1.1, 2.0, 0.5])
    np.testing.assert_allclose(scans.laser_offset, [0.1 * np.cos(0.5), -0.1 * np.sin(0.5), 0.0])
    assert scans.no_return == 40.0  # the declared max_range when the config gives none
    assert log.summary()["scans"]["no_return_beams"] == 1
    assert log.meta["robotlaser_scans"] == 2


def test_robotlaser1_angles_are_one_row_unless_the_lines_differ(tmp_path):
    """Lines that declare the same start and resolution share one angle row (a long log would
    otherwise hold an angle per reading); lines that differ keep an angle row per scan."""
    same = [robotlaser([1.0, 2.0, 3.0], t=t) for t in (1.0, 2.0, 3.0)]
    assert load_carmen(write(tmp_path, same)).scans.angles.shape == (3,)
    differ = [*same, robotlaser([1.0, 2.0, 3.0], start=-0.5, t=4.0)]
    angles = load_carmen(write(tmp_path, differ)).scans.angles
    assert angles.shape == (4, 3)
    np.testing.assert_allclose(angles[0], [-1.0, -0.5, 0.0])
    np.testing.assert_allclose(angles[3], [-0.5, 0.0, 0.5])


def test_a_negative_zero_start_keeps_its_sign_and_scans_come_before_odom_errors(tmp_path):
    """Lines share one angle row only when their start and step have the same bits: a start
    written ``-0.000000`` keeps its negative zero in the angles (as when every line had its own
    row). And the scans' errors (here the lidar limits) are named before a bad ODOM line, in the
    order the loader always checked them."""
    lines = [flaser([1.0], t=1.0), robotlaser([1.0, 2.0], start=0.0, res=-0.01, t=2.0)]
    lines.append(
        robotlaser([1.0, 2.0], start=-0.0, res=-0.01, t=3.0).replace(" -0.0 ", " -0.000000 ", 1)
    )
    angles = load_carmen(write(tmp_path, lines), lidar=LidarConfig(fov_deg=180.0)).scans.angles
    assert np.signbit(angles[2, 0]) and not np.signbit(angles[1, 0])
    bad = write(tmp_path, [robotlaser([1.0, 2.0], max_range=30.0), "ODOM 1 2"], "bad.clf")
    with pytest.raises(DataError, match=r"bad\.clf:2: ODOM line: expected 10 fields"):
        load_carmen(bad)
    with pytest.raises(ConfigError, match=r"lidar: expected range_min < range_max"):
        load_carmen(bad, lidar=LidarConfig(range_min=40.0))


@pytest.mark.parametrize("kind", ["ROBOTLASER1", "FLASER"])
def test_a_long_log_loads_in_a_few_bytes_a_reading(tmp_path, kind):
    """The loader lets the text, its lines and each layout's table go as soon as the next step
    holds what it needs, and converts and judges the readings (and FLASER's no-echo code) a
    block at a time: traced at its peak, a load costs 18 (ROBOTLASER1) and 17 (FLASER) bytes a
    reading here, the lines' text while their numbers are read into the table. It cost 49 when
    the whole text, the lines, the parser's growing buffer, a padded float64 copy, its masks and
    (ROBOTLASER1) an angle per reading were held at once."""
    import tracemalloc

    rng = np.random.default_rng(0)
    scans, beams = 16_000, 181
    values = np.round(rng.uniform(0.1, 30.0, (scans, beams)), 3)
    values[:, ::50] = 81.83  # FLASER: a no-echo code for the histogram to find
    make = robotlaser if kind == "ROBOTLASER1" else flaser
    path = write(tmp_path, [make(row.tolist(), t=1.0 + 0.025 * k) for k, row in enumerate(values)])
    tracemalloc.start()
    try:
        log = load_carmen(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    readings = scans * beams
    assert log.scans.ranges.shape == (scans, beams)
    assert peak / readings < 24.0, f"{peak / readings:.1f} bytes a reading"


def rawlaser(ranges, remissions=(), start=-1.0, res=0.5, max_range=40.0, t=1.0) -> str:
    fields = ["RAWLASER1", "0", str(start), str(res * (len(ranges) - 1)), str(res)]
    fields += [str(max_range), "0.01", "0", str(len(ranges)), *map(str, ranges)]
    fields += [str(len(remissions)), *map(str, remissions)]
    return " ".join([*fields, f"{t:.6f}", "host", f"{t:.6f}"])


def test_rawlaser1_scans_are_placed_by_the_odom_stream(tmp_path):
    """A log of raw scans (RAWLASER1, no pose) and ODOM messages: the scans keep their own
    geometry and range limit, their odometry is the stream at their times, and the laser sits
    on the odometry point unless the configuration says where."""
    from slam.config import RobotConfig
    from slam.odometry import scan_odometry

    lines = [odom_line(0.0, 0.0, 0.0, 0.0), odom_line(1.0, 0.5, 0.2, 2.0)]
    lines += [rawlaser([1.0, 2.0, 3.0, 45.0], remissions=(0.5, 0.6), t=0.5)]
    lines += [rawlaser([2.0, 2.5, 3.5, 4.5], t=1.0)]
    log = load_carmen(write(tmp_path, lines))
    scans = log.scans
    np.testing.assert_allclose(scans.angles, [-1.0, -0.5, 0.0, 0.5])
    np.testing.assert_array_equal(scans.ranges[0], np.float32([1, 2, 3, 45]))
    np.testing.assert_array_equal(scans.time, [0.5, 1.0])
    assert scans.odometry is None and scans.laser_pose is None
    np.testing.assert_allclose(
        scan_odometry(log, RobotConfig()), [[0.25, 0.125, 0.05], [0.5, 0.25, 0.1]]
    )
    np.testing.assert_array_equal(scans.laser_offset, [0.0, 0.0, 0.0])
    assert log.meta["laser_offset_source"] == "not stated"
    assert scans.no_return == 40.0  # the declared max_range
    assert log.meta["rawlaser_scans"] == 2 and log.meta["skipped_lines"] == 0
    mounted = LidarConfig(use_log_laser_pose=False, x=0.2, y=0.0, yaw=0.0)
    np.testing.assert_array_equal(
        load_carmen(write(tmp_path, lines), lidar=mounted).scans.laser_offset, [0.2, 0.0, 0.0]
    )


def test_rawlaser1_beside_flaser_is_skipped(tmp_path):
    """A logger that writes a scan as FLASER and again as RAWLASER1: the FLASER lines are the
    scans, the raw ones are counted as skipped."""
    lines = [flaser([1.0, 2.0, 3.0], t=1.0), rawlaser([1.0, 2.0, 3.0], t=1.0)]
    log = load_carmen(write(tmp_path, lines))
    assert len(log.scans) == 1 and log.scans.odometry is not None
    assert log.meta["skipped"] == {"RAWLASER1": 1} and log.meta["rawlaser_scans"] == 0


def test_rawlaser1_without_odom_loads_without_odometry(tmp_path):
    """Raw scans and no ODOM line: a log without odometry (``slam run`` then matches the scans,
    tests/test_laser_odometry.py); a malformed line is still one error naming it."""
    path = write(tmp_path, [rawlaser([1.0, 2.0], t=1.0), rawlaser([1.5, 2.5], t=2.0)])
    log = load_carmen(path)
    assert log.odometry is None and log.scans.odometry is None
    np.testing.assert_array_equal(log.scans.ranges, np.float32([[1.0, 2.0], [1.5, 2.5]]))
    assert log.meta["rawlaser_scans"] == 2 and log.meta["odom_messages"] == 0
    bad = write(tmp_path, [odom_line(0, 0, 0, 0.0), rawlaser([1.0, 2.0], t=1.0) + " 7"], "bad.clf")
    with pytest.raises(
        DataError, match=r"bad\.clf:2: RAWLASER1 line: expected 15 fields, found 16"
    ):
        load_carmen(bad)


def test_slam_runs_on_a_log_of_raw_scans(tmp_path):
    """The synthetic room as RAWLASER1 lines and an ODOM stream: ``slam run`` tracks the path."""
    from synthetic_logs import path as room_path
    from synthetic_logs import ray_cast

    from slam.cli import main

    poses = room_path(120)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    lines = []
    for k, pose in enumerate(poses):
        t = 100.0 + 0.1 * k
        lines.append(odom_line(*pose, t))
        r = [f"{v:.3f}" for v in ray_cast(pose, angles)]
        lines.append(rawlaser(r, start=-np.pi / 2, res=np.pi / 180, max_range=30.0, t=t))
    log = write(tmp_path, lines, "raw.clf")
    out = tmp_path / "run"
    assert main(["run", str(log), "--out", str(out), "--no-texture", "--no-record", "--quiet"]) == 0
    from slam.io.tum import read_tum

    got = read_tum(out / "trajectory.tum")
    assert len(got) == 120
    assert np.abs(got.poses[:, :2] - poses[:, :2]).max() < 0.05


def test_a_run_prints_the_warnings_found_when_the_log_loaded(tmp_path, capsys):
    """The note of a log mixing 180- and 181-reading scans is a warning like the others: ``slam
    run`` prints it on stderr and keeps it in ``metrics.json``'s ``warnings``."""
    import json

    from synthetic_logs import path as room_path
    from synthetic_logs import ray_cast

    from slam.cli import main

    lines = []
    for k, pose in enumerate(room_path(30)):
        n = 180 + k % 2
        r = [f"{v:.3f}" for v in ray_cast(pose, np.linspace(-np.pi / 2, np.pi / 2, n))]
        lines.append(flaser(r, pose=tuple(pose), t=100.0 + 0.1 * k))
    log = write(tmp_path, lines, "mixed.clf")
    out = tmp_path / "run"
    argv = ["run", str(log), "--out", str(out), "--no-texture", "--no-record", "--quiet"]
    assert main([*argv, "--set", "lidar.measure_beam_step=false"]) == 0
    note = f"{log}: scans of 180 and 181 readings, the 180-reading ones spread over the field"
    stderr = capsys.readouterr().err
    assert f"slam: warning: {note}" in stderr
    warnings = json.loads((out / "metrics.json").read_text())["warnings"]
    assert [w for w in warnings if w.startswith(note)] and len(warnings) == stderr.count("warning:")


# --- malformed input: each error names the file and line ------------------------------------------

GOOD = flaser([1.0, 2.0, 3.0], t=1.0)


@pytest.mark.parametrize(
    "bad_line, message",
    [
        (flaser([1.0, 2.0, 3.0]).replace("FLASER 3", "FLASER 4"), r"expected 15 fields.*found 14"),
        (flaser([1.0, 2.0]).replace(" 2.0 ", " "), r"expected 13 fields.*found 12"),
        (flaser([1.0, "1.5x", 3.0]), r"range 2 \(field 4\): expected a number, found '1.5x'"),
        (flaser([1.0, 2.0], odom=(0.0, "abc", 0.0)), r"odom_y \(field 9\): expected a number"),
        (flaser([1.0, 2.0]).replace("FLASER 2", "FLASER two"), r"beam count: expected an integer"),
        (
            flaser([1.0, 2.0]).replace("FLASER 2", "FLASER -2"),
            r"beam count: expected 1..8192, found -2",
        ),
        ("FLASER", r"FLASER line ends before its beam count"),
        (flaser([1.0, 2.0], pose=("nan", 0.0, 0.0)), r"x \(field 5\): expected a finite number"),
        (flaser([1.0], t=float("inf")), r"ipc_timestamp \(field 10\): expected a finite number"),
        ("ODOM 1 2 3 0 0 0 5.0 h", r"ODOM line: expected 10 fields.*found 9"),
        ("ODOM 1 2 three 0 0 0 5.0 h 5.0", r"ODOM theta \(field 4\): expected a number"),
        ("3.0 FLASER 2 1 1", r"expected a message type such as FLASER or ODOM"),
        (robotlaser([1.0, 2.0]).replace(" 2 1.0 2.0 0 ", " 2 1.0 2.0 x "), r"remission count"),
        (robotlaser([1.0, 2.0]).replace("host", "host extra"), r"expected 26 fields, found 27"),
    ],
)
def test_bad_line_names_file_and_line(tmp_path, bad_line, message):
    path = write(tmp_path, ["# header", GOOD, GOOD, bad_line, GOOD])
    with pytest.raises(DataError, match=rf"log\.clf:4: .*{message}"):
        load_carmen(path)


def test_bad_line_found_deep_in_a_large_group(tmp_path):
    lines = [flaser([1.0, 2.0], t=float(k)) for k in range(500)]
    lines[377] = flaser([1.0, "bad"], t=377.0)
    with pytest.raises(DataError, match=r"log\.clf:378: FLASER range 2 \(field 4\).*'bad'"):
        load_carmen(write(tmp_path, lines))


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", r"no scans"),
        (b"# only a comment\nODOM 1 2 3 0 0 0 5 h 5\n", r"no scans .*found 1 ODOM, 1 comment"),
        (b"FLASER 1 1.0 0 0 0 0 0 0 1.0 h 1.0\n\xff\xfe\n", r"log\.clf:2: expected text"),
    ],
)
def test_empty_or_not_text(tmp_path, content, message):
    path = tmp_path / "log.clf"
    path.write_bytes(content)
    with pytest.raises(DataError, match=message):
        load_carmen(path)


def test_truncated_gzip_names_the_file(tmp_path):
    data = gzip.compress(("\n".join([GOOD] * 200) + "\n").encode())
    path = tmp_path / "cut.clf.gz"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=r"cut\.clf\.gz: truncated gzip"):
        load_carmen(path)


def test_truncated_text_names_the_last_line(tmp_path):
    text = "\n".join([GOOD, GOOD, GOOD])
    path = tmp_path / "log.clf"
    path.write_text(text[:-12])  # cut inside the last line
    with pytest.raises(DataError, match=r"log\.clf:3: FLASER line: expected 14 fields"):
        load_carmen(path)


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(DataError, match=r"nope\.clf: CARMEN log not found"):
        load_carmen(tmp_path / "nope.clf")
    with pytest.raises(DataError, match=r"is a folder, expected a CARMEN log file"):
        load_carmen(tmp_path)


@pytest.mark.skipif(os.geteuid() == 0, reason="root can read files without permission")
def test_unreadable_file(tmp_path):
    path = write(tmp_path, [GOOD])
    path.chmod(0)
    try:
        with pytest.raises(DataError, match=r"log\.clf: cannot read CARMEN log"):
            load_carmen(path)
    finally:
        path.chmod(0o644)


def test_read_error_is_a_data_error(tmp_path, monkeypatch):
    """Whoever runs the tests (root reads anything), an OS read error becomes one DataError."""
    path = write(tmp_path, [GOOD])

    def refuse(self):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "read_bytes", refuse)
    with pytest.raises(DataError, match=r"log\.clf: cannot read CARMEN log \(Permission denied\)"):
        load_carmen(path)


def test_inconsistent_lidar_config_is_a_config_error(tmp_path):
    path = write(tmp_path, [GOOD])
    with pytest.raises(
        ConfigError, match=r"lidar.range_max, lidar.no_return: expected range_max <= no_return"
    ):
        load_carmen(path, lidar=LidarConfig(range_max=90.0, no_return=80.0))
    with pytest.raises(ConfigError, match=r"lidar.fov_deg"):
        load_carmen(path, lidar=LidarConfig(fov_deg=0.0))


# --- fuzzing: the parser either parses or raises DataError ---------------------------------------

BASE = [
    "# comment",
    odom_line(0.0, 0.0, 0.0, 0.5),
    flaser([1.0, 2.0, 3.0], pose=(0.1, 0.0, 0.0), t=1.0),
    flaser([1.5, 2.5, 3.5], t=2.0),
    robotlaser([1.0, 2.0], remissions=(0.3,), t=3.0),
    "PARAM a b",
]
TOKENS = st.sampled_from(
    ["FLASER", "ODOM", "ROBOTLASER1", "#", "0", "1", "3", "-1", "2.5", "1e999", "nan", "inf",
     "-inf", "x", "1_0", "0x1f", "", " ", "\t", "\x00", "é", "\u00a0", "\x1c", "\r", "99999999999"]
)  # fmt: skip


@st.composite
def mutated_logs(draw) -> bytes:
    lines = list(BASE)
    for _ in range(draw(st.integers(1, 4))):
        k = draw(st.integers(0, len(lines) - 1))
        tokens = lines[k].split(" ")
        op = draw(st.sampled_from(["drop", "insert", "replace", "truncate", "line", "dup"]))
        pos = draw(st.integers(0, len(tokens) - 1))
        if op == "drop":
            del tokens[pos]
        elif op == "insert":
            tokens.insert(pos, draw(TOKENS))
        elif op == "replace":
            tokens[pos] = draw(st.one_of(TOKENS, st.text(max_size=6)))
        elif op == "truncate":
            tokens = tokens[:pos]
        elif op == "line":
            lines.insert(k, " ".join(draw(st.lists(TOKENS, max_size=8))))
        else:
            lines.insert(k, lines[k])
        if op not in ("line", "dup"):
            lines[k] = " ".join(tokens)
    data = "\n".join(lines).encode("utf-8", errors="surrogatepass")
    if draw(st.booleans()):
        data = data[: draw(st.integers(0, len(data)))]
    return data


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.one_of(mutated_logs(), st.binary(max_size=300)), compress=st.booleans())
def test_fuzz_parses_or_raises_data_error(tmp_path, data, compress):
    path = tmp_path / "fuzz.clf"
    path.write_bytes(gzip.compress(data) if compress else data)
    try:
        log = load_carmen(path)
    except DataError:
        return
    scans = log.scans
    assert scans.ranges.dtype == np.float32
    assert scans.ranges.shape[0] == scans.time.shape[0] == scans.odometry.shape[0] > 0
    assert np.all(np.isfinite(scans.time)) and np.all(np.isfinite(scans.odometry))
    assert scans.invalid_beams == int(np.count_nonzero(np.isnan(scans.ranges))) - int(
        np.count_nonzero(np.isnan(scans.angles)) if scans.angles.ndim == 2 else 0
    )


def test_beam_step_spaces_flaser_beams_whatever_their_count(tmp_path):
    """fr-clinic mixes 180- and 181-reading FLASER lines of one laser: with ``beam_step_deg``
    both are centred on straight ahead 1° apart (the default spreads each over ``fov_deg``)."""
    lines = [flaser([1.0] * 180, t=1.0), flaser([1.0] * 181, t=2.0)]
    path = write(tmp_path, lines)
    stepped = load_carmen(path, lidar=LidarConfig(beam_step_deg=1.0)).scans.angles
    spread = load_carmen(path, lidar=LidarConfig()).scans.angles
    np.testing.assert_allclose(np.diff(stepped[0, :180]), np.deg2rad(1.0), atol=1e-12)
    np.testing.assert_allclose(np.diff(stepped[1]), np.deg2rad(1.0), atol=1e-12)
    np.testing.assert_allclose(stepped[0, [0, 179]], np.deg2rad([-89.5, 89.5]), atol=1e-12)
    np.testing.assert_allclose(stepped[1, [0, 180]], np.deg2rad([-90.0, 90.0]), atol=1e-12)
    np.testing.assert_allclose(spread[0, [0, 179]], np.deg2rad([-90.0, 90.0]), atol=1e-12)
    np.testing.assert_allclose(np.diff(spread[0, :180]), np.deg2rad(180 / 179), atol=1e-12)


def test_a_beam_step_beyond_a_full_turn_is_one_clear_error(tmp_path):
    path = write(tmp_path, [flaser([1.0] * 181, t=1.0)])
    with pytest.raises(
        ConfigError, match=r"log\.clf: lidar\.beam_step_deg: expected at most 2° .* 181 beams"
    ):
        load_carmen(path, lidar=LidarConfig(beam_step_deg=2.5))
    assert load_carmen(path, lidar=LidarConfig(beam_step_deg=2.0)).scans.angles[
        -1
    ] == pytest.approx(np.pi)


def test_no_return_code_is_the_pile_at_the_top_of_the_histogram():
    from slam.io.carmen import no_return_code

    rng = np.random.default_rng(0)
    genuine = rng.uniform(0.2, 26.37, 100_000)
    genuine[0] = 26.37
    # a SICK code far above every genuine reading (intel): halfway between the two
    assert no_return_code(np.r_[genuine, np.full(3000, 81.83)]) == pytest.approx(54.1)
    # a code just above the longest genuine reading (aces): 49.91 ... 50.00
    aces = np.r_[rng.uniform(0.3, 49.91, 100_000), 49.91, np.full(800, 50.0)]
    assert no_return_code(aces) == pytest.approx(49.955)
    # a pile spread over a few values, with a stray reading beyond it (mit-killian)
    spread = np.r_[genuine, 51.01, np.full(70, 51.05), np.full(1000, 51.06), np.full(120, 51.11)]
    assert no_return_code(np.r_[spread, 51.22]) == pytest.approx(51.03)
    # genuine readings up to the code itself (fr-clinic): 81.82 genuine, 81.83 and 81.91 codes
    clinic = np.r_[
        rng.uniform(0.5, 81.82, 100_000), 81.82, np.full(500, 81.83), np.full(9000, 81.91)
    ]
    assert no_return_code(clinic) == pytest.approx(81.825)
    # no pile: nothing to read (the documented default applies)
    assert no_return_code(genuine) is None
    assert no_return_code(np.r_[genuine, 85.0]) is None  # one long reading is not a code
    assert no_return_code(np.full(10, np.nan)) is None
    assert no_return_code(np.full(500, 30.0)) is None  # nothing below the pile


def test_no_return_code_reads_a_log_in_blocks_as_one_array(monkeypatch):
    """Several arrays (a log's layout groups, 2-D) judged a few hundred readings at a time give
    the code the whole log gives at once: the pile found in a block of its own, the longest
    reading below it in another block or in the band."""
    import slam.io.carmen as carmen

    rng = np.random.default_rng(1)
    genuine = rng.uniform(0.2, 26.37, 6_000)
    genuine[0] = 26.37
    clinic = np.r_[rng.uniform(0.5, 81.82, 6_000), 81.82, np.full(60, 81.83), np.full(900, 81.91)]
    aces = np.r_[rng.uniform(0.3, 49.91, 6_000), 49.91, np.full(100, 50.0)]
    cases = {
        "far code": np.r_[genuine, np.full(300, 81.83)],
        "code in the band": clinic,
        "code above the band's floor": aces,
        "no pile": np.r_[genuine, 85.0],
    }
    whole = {name: carmen.no_return_code(r) for name, r in cases.items()}
    assert whole["far code"] == pytest.approx(54.1)
    assert whole["code in the band"] == pytest.approx(81.825)
    assert whole["code above the band's floor"] == pytest.approx(49.955)
    assert whole["no pile"] is None
    monkeypatch.setattr(carmen, "NO_RETURN_BLOCK", 256)
    for name, r in cases.items():
        cut = r.size // 3 // 7 * 7
        parts = [r[:cut].reshape(-1, 7), r[cut:]]
        assert carmen.no_return_code(parts) == whole[name], name


@pytest.mark.parametrize(
    "name, file, no_return_beams",
    [
        ("intel", "intel", 68313),
        ("aces", "aces", 11139),
        ("fr079", "fr079", 36881),
        ("mit-csail", "mit-csail", 23711),
        ("fr-clinic", "fr-clinic", 5849 + 150066),
        ("mit-killian", "mit-killian-synthtime", 39739),  # the spike and 14 longer readings
    ],
)
def test_a_log_without_its_config_finds_its_no_echo_code(carmen_dir, name, file, no_return_beams):
    """Loaded as a building we have never seen (no configs/<log>.toml), every benchmark log
    tells its no-echo readings from its genuine ones as its hand-read configuration does."""
    configured = load_carmen(carmen_dir / f"{file}.clf.gz", lidar=load_config(name).lidar)
    unseen = load_carmen(carmen_dir / f"{file}.clf.gz")
    assert unseen.summary()["scans"]["no_return_beams"] == no_return_beams
    assert configured.summary()["scans"]["no_return_beams"] == no_return_beams
    hits = lambda s: np.isfinite(s.ranges) & (s.ranges < s.range_max)  # noqa: E731
    np.testing.assert_array_equal(hits(unseen.scans), hits(configured.scans))


def test_a_log_mixing_two_widths_gets_a_note_until_its_beam_step_is_declared(tmp_path):
    """fr-clinic's 180- and 181-reading lines in miniature, with the measurement off: without
    ``lidar.beam_step_deg`` the run's warnings say what the shorter scans are taken as and which
    command measures them."""
    from slam.io import sources

    lines = [flaser([1.0 + 0.01 * i] * (180 + i % 2), t=1.0 + i) for i in range(6)]
    path = write(tmp_path, lines)
    ref = sources.resolve(str(path), tmp_path, where="test")
    off = load_config("", None, ["lidar.measure_beam_step=false"])
    source = sources.load(ref, off, ("scans",))
    assert source.notes == [
        f"{path}: scans of 180 and 181 readings, the 180-reading ones spread over the field of "
        "view like the others; if one laser takes both (a SICK LMS's interlaced sweeps), "
        "`slam data calibrate` measures which angles they have (lidar.beam_step_deg)"
    ]
    assert source.beam_geometry is None and source.configured(off) is off
    stepped = load_config("", None, ["lidar.beam_step_deg=1.0"])
    assert sources.load(ref, stepped, ("scans",)).notes == []
    one = write(tmp_path, [flaser([1.0] * 181, t=1.0 + i) for i in range(4)], "one.clf")
    ref_one = sources.resolve(str(one), tmp_path, where="test")
    assert sources.load(ref_one, load_config(""), ("scans",)).notes == []
    assert sources.load(ref_one, load_config(""), ("scans",)).beam_geometry is None


def test_a_beam_geometry_measured_on_too_few_pairs_is_not_applied(tmp_path):
    """Six scans of a featureless wall: the measurement runs (``lidar.measure_beam_step``, the
    default) but fits too few pairs to decide, so the log keeps the spread geometry and the
    warning says it was measured and not applied."""
    from slam.io import sources

    lines = [flaser([1.0 + 0.01 * i] * (180 + i % 2), t=1.0 + i) for i in range(6)]
    path = write(tmp_path, lines)
    ref = sources.resolve(str(path), tmp_path, where="test")
    config = load_config("")
    source = sources.load(ref, config, ("scans",))
    measured = source.beam_geometry
    assert measured is not None and measured["applied"] is False
    rows = measured["geometries"]
    fitted = rows[measured["best"]]["pairs_fitted"]
    assert fitted < 50
    assert source.notes == [
        f"{path}: scans of 180 and 181 readings, the 180-reading ones spread over the field of "
        f"view like the others: their beam geometry was measured ({measured['best']} fits best, "
        f"{fitted} pairs fitted; centred {rows['centred']['rotation_rms_deg']:.3f}° against "
        f"spread {rows['spread']['rotation_rms_deg']:.3f}°; `slam data calibrate` shows each "
        "geometry) but not applied (lidar.beam_step_deg declares one)"
    ]
    assert source.beam_step_deg is None and source.configured(config) is config
    spread = np.deg2rad(np.linspace(-90.0, 90.0, 180))
    np.testing.assert_allclose(source.log.scans.angles[0, :180], spread)  # scan 0: 180 readings


def test_an_interlaced_log_is_read_with_its_measured_beam_step(tmp_path):
    """A SICK LMS's interlaced sweeps in the synthetic room (181 whole degrees, then the 180 half
    degrees between): loading it measures the beam geometry, finds the centred 1° step and reads
    the log with it, as ``lidar.beam_step_deg = 1`` declares it; the configuration the run then
    records says so."""
    from synthetic_logs import carmen_lines, write_carmen

    from slam.io import sources

    path = write_carmen(tmp_path, carmen_lines(80, interlaced=True))
    ref = sources.resolve(str(path), tmp_path, where="test")
    config = load_config("")
    source = sources.load(ref, config, ("scans",))
    measured = source.beam_geometry
    assert measured["applied"] is True and measured["best"] == "centred"
    assert measured["short"] == 180 and measured["beam_step_deg"] == 1.0
    rows = measured["geometries"]
    assert rows["centred"]["pairs_fitted"] >= 50
    for other in ("spread", "from_first", "to_last"):
        assert rows["centred"]["rotation_rms_deg"] < rows[other]["rotation_rms_deg"]
    assert source.notes == [] and source.beam_step_deg == 1.0
    assert source.configured(config).lidar.beam_step_deg == 1.0
    declared = sources.load(ref, load_config("", None, ["lidar.beam_step_deg=1.0"]), ("scans",))
    np.testing.assert_array_equal(source.log.scans.angles, declared.log.scans.angles)
    np.testing.assert_allclose(
        source.log.scans.angles[1, :180], np.deg2rad(np.arange(180) - 89.5), atol=1e-12
    )


def test_a_measured_beam_step_keeps_the_users_settings():
    """The configuration a measured beam step is added to keeps every setting the user gave,
    even one the dataset's shipped file also sets."""
    from slam.io.sources import Source

    config = load_config("fr-clinic", None, ["lidar.range_max=8", "filter.seed=3"])
    got = Source(log=None, beam_step_deg=1.0).configured(config)  # type: ignore[arg-type]
    assert got.lidar.range_max == 8.0 and got.filter.seed == 3
    assert got.lidar.beam_step_deg == 1.0 and got.dataset == "fr-clinic"
