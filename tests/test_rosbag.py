"""The ROS bag / MCAP loader, format detection and ``slam data inspect`` on synthetic bags."""

from __future__ import annotations

import dataclasses
import gzip
import json
import math

import numpy as np
import pytest
from bagfixtures import (
    BagContent,
    Odom,
    Scan,
    Tf,
    straight_run,
    write_bare_mcap,
    write_ros1_bag,
    yaw_quaternion,
)

from slam.cli import main
from slam.config import load_config
from slam.errors import DataError, UsageError
from slam.io.formats import detect_format, run_config_name
from slam.io.plausibility import DataWarning
from slam.io.rosbag import BagOptions, in_order_times, load_bag, publication_order
from slam.scans import LogScans


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# --- format detection ---------------------------------------------------------------------


def test_detect_format_by_content_not_name(tmp_path):
    bag = write_ros1_bag(tmp_path / "a.bag", straight_run(3))
    assert detect_format(bag) == "ros1"
    assert detect_format(write_bare_mcap(tmp_path / "a.mcap", straight_run(3))) == "mcap"
    text = tmp_path / "log.bag"  # a CARMEN log named like a bag is still CARMEN
    text.write_text("# comment\nODOM 0 0 0 0 0 0 1.0 host 1.0\n")
    assert detect_format(text) == "carmen"
    gz = tmp_path / "log.dat"
    gz.write_bytes(gzip.compress(b"ODOM 0 0 0 0 0 0 1.0 host 1.0\n"))
    assert detect_format(gz) == "carmen"
    folder = tmp_path / "r2"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    assert detect_format(folder) == "rosbag2"
    assert detect_format(folder / "metadata.yaml") == "rosbag2"
    ece = tmp_path / "ece"
    ece.mkdir()
    (ece / "Encoders20.npz").write_bytes(b"PK\x03\x04")
    assert detect_format(ece) == "ece276a"


def test_detect_format_rejects_what_it_cannot_read(tmp_path):
    binary = tmp_path / "x.clf"
    binary.write_bytes(b"\x00\x01\x02binary")
    with pytest.raises(DataError, match=r"x\.clf: unknown format: found binary data"):
        detect_format(binary)
    # text in another encoding, or with a byte-order mark, is named as such (both were 'binary
    # data' or an unknown message type '\ufeff#')
    latin = tmp_path / "latin.clf"
    latin.write_bytes(b"# caf\xe9 log\nODOM 0 0 0 0 0 0 1 h 1\n")
    with pytest.raises(
        DataError, match=r"latin\.clf: line 1: non-UTF-8 byte 0xe9 \(byte offset 5\)"
    ):
        detect_format(latin)
    bom = tmp_path / "bom.clf"
    bom.write_bytes(b"\xef\xbb\xbf# log\nODOM 0 0 0 0 0 0 1 h 1\n")
    with pytest.raises(DataError, match=r"bom\.clf:1: a UTF-8 byte-order mark"):
        detect_format(bom)
    import gzip  # (review) inside a gzip too, as every benchmark log is

    for name, raw, said in (("latin", latin, "non-UTF-8 byte 0xe9"), ("bom", bom, "order mark")):
        packed = tmp_path / f"{name}.clf.gz"
        packed.write_bytes(gzip.compress(raw.read_bytes()))
        with pytest.raises(DataError, match=f"{said}.* \\(inside the gzip\\)"):
            detect_format(packed)
    db = tmp_path / "bag_0.db3"
    db.write_bytes(b"SQLite format 3\x00" + bytes(100))
    with pytest.raises(DataError, match="SQLite database"):
        detect_format(db)
    gz = tmp_path / "y.gz"
    gz.write_bytes(gzip.compress(bytes(range(256))))
    with pytest.raises(DataError, match="gzip file whose content is not text"):
        detect_format(gz)
    with pytest.raises(DataError, match="not found"):
        detect_format(tmp_path / "missing.bag")


def test_a_bag_never_picks_a_shipped_config_by_its_name(tmp_path):
    bag = write_ros1_bag(tmp_path / "intel.bag", straight_run(3))
    assert run_config_name(str(bag)) == ("intel", False)
    clf = tmp_path / "intel.clf"
    clf.write_text("ODOM 0 0 0 0 0 0 1.0 host 1.0\n")
    assert run_config_name(str(clf)) == ("intel", True)  # FLASER needs configs/intel.toml
    assert run_config_name("aces") == ("aces", True)


# --- loading ------------------------------------------------------------------------------


def test_load_ros1_bag_geometry_odometry_and_mounting(tmp_path):
    log = load_bag(write_ros1_bag(tmp_path / "run.bag", straight_run(20, beams=90)))
    s = log.scans
    assert log.kind == "rosbag" and log.name == "run" and len(s) == 20
    assert s.angles.shape == (90,)
    assert s.angles[0] == pytest.approx(-math.pi / 2, abs=1e-7)
    assert s.angles[-1] == pytest.approx(math.pi / 2, abs=1e-6)
    assert s.range_min == pytest.approx(0.1) and s.no_return == pytest.approx(30.0)
    np.testing.assert_allclose(s.laser_offset, [0.2, 0.0, 0.0], atol=1e-12)
    assert log.meta["laser_offset_source"] == "tf_static"
    assert log.meta["odom_source"] == "/odom" and log.meta["base_frame"] == "base_link"
    assert log.meta["fast_decoder"] == "odom=True, scan=True"
    # beams beyond range_max (the side beams: 40 m written, range_max 30) are "no return"
    assert np.count_nonzero(s.ranges[0] >= s.no_return) == np.count_nonzero(
        np.cos(s.angles) <= 0.2
    ) + np.count_nonzero((np.cos(s.angles) > 0.2) & (5.0 / np.cos(s.angles) >= 30.0))
    np.testing.assert_allclose(s.time[:2], [100.01, 100.21], atol=1e-9)
    np.testing.assert_allclose(log.odometry.poses[:3, 0], [0.0, 0.1, 0.2])
    np.testing.assert_allclose(log.odometry.velocities[:, 0], 0.5)


def test_varying_beam_counts_pad_angles_and_ranges(tmp_path):
    content = straight_run(3, beams=90)
    content.scans[1] = Scan(t=100.21, ranges=[1.0] * 181, angle_min=-math.pi / 2)
    content.scans[2] = Scan(t=100.41, ranges=[2.0, -1.0, 0.05, math.nan, 3.0])
    log = load_bag(write_ros1_bag(tmp_path / "mixed.bag", content))
    s = log.scans
    assert s.ranges.shape == (3, 181) and s.angles.shape == (3, 181)
    assert s.num_beams == 181
    assert np.isnan(s.angles[0, 90:]).all() and np.isfinite(s.angles[0, :90]).all()
    np.testing.assert_allclose(s.scan_angles(1)[[0, 180]], [-math.pi / 2, math.pi / 2], atol=1e-6)
    assert np.isnan(s.ranges[2, 5:]).all()
    # -1 (negative), 0.05 (< range_min 0.1) and NaN are invalid; padding is not counted
    assert s.invalid_beams == 3
    np.testing.assert_array_equal(np.isnan(s.ranges[2, :5]), [False, True, True, True, False])


@pytest.mark.parametrize("range_max", [-1.0, 0.05, math.nan])
def test_a_range_max_below_range_min_is_named(tmp_path, range_max):
    """The bug: a LaserScan with range_max -1 was reported as "no scan has a valid beam" (the
    limits [0.1, -1) quoted as if they were the data's fault)."""
    content = straight_run(4)
    content.scans[2] = dataclasses.replace(content.scans[2], range_max=range_max)
    bag = write_ros1_bag(tmp_path / "limits.bag", content)
    with pytest.raises(DataError) as caught:
        load_bag(bag)
    assert str(caught.value) == (
        f"{bag}: /scan message at t = {content.scans[2].t:.6f} s (1 of 4 messages): expected a "
        f"range_max above range_min and 0 (m), found range_min 0.1, range_max {range_max:g}"
    )


def _laser_only(n: int = 20) -> BagContent:
    """straight_run(n) with its LaserScan topic alone: no Odometry, no /tf, no /tf_static."""
    content = straight_run(n)
    content.odom.clear()
    content.tf.clear()
    return content


def test_a_bag_without_odometry_loads_and_runs_on_laser_odometry(tmp_path, capsys):
    content = _laser_only(20)
    bag = write_ros1_bag(tmp_path / "noodom.bag", content)
    log = load_bag(bag)
    assert log.odometry is None and log.scans.odometry is None
    assert log.meta["odom_source"] == "none" and log.meta["odom_match"] == "none"
    # no tf_static: the laser frame is the robot frame, the laser at its origin
    assert log.meta["base_frame"] == "laser" and log.meta["laser_frame"] == "laser"
    assert log.meta["laser_offset_source"] == "not stated: the laser frame is the robot frame"
    np.testing.assert_array_equal(log.scans.laser_offset, [0.0, 0.0, 0.0])
    # the scans are the bag's: 20 scans of 90 beams, ranges and stamps as written
    assert len(log.scans) == 20 and log.scans.num_beams == 90 and log.scans.invalid_beams == 0
    written = np.array([s.ranges for s in content.scans], dtype=np.float32)
    np.testing.assert_array_equal(log.scans.ranges, written)
    np.testing.assert_allclose(log.scans.time, [s.t for s in content.scans], atol=1e-9)
    assert log.meta["fast_decoder"] == "scan=True"
    # the same scans as the bag with odometry, and the same log from a bare MCAP file
    with_odometry = load_bag(write_ros1_bag(tmp_path / "odom.bag", straight_run(20)))
    np.testing.assert_array_equal(log.scans.ranges, with_odometry.scans.ranges)
    np.testing.assert_array_equal(log.scans.angles, with_odometry.scans.angles)
    mcap = load_bag(write_bare_mcap(tmp_path / "noodom.mcap", content))
    assert_same_log(log, mcap, skip_meta=("scan_order",))
    # robot.odometry = "auto" (the default): the odometry comes from matching the scans
    with pytest.warns(DataWarning, match="the log has no odometry"):
        scans = LogScans.from_log(log, load_config(""))
    assert scans.odometry_source == "laser" and scans.odometry.shape == (20, 3)
    np.testing.assert_array_equal(scans.odometry[0], [0.0, 0.0, 0.0])
    # the wall 5 m ahead fixes x: the robot drives 0.1 m per scan
    np.testing.assert_allclose(scans.odometry[:, 0], 0.1 * np.arange(20), atol=0.02)
    # robot.odometry = "log" refuses it
    with pytest.raises(DataError, match="no odometry"):
        LogScans.from_log(log, load_config("", None, ['robot.odometry="log"']))
    code, out, _ = _run(capsys, "data", "inspect", str(bag))
    assert code == 0 and "slam run reads: scans /scan, odometry none (laser odometry)" in out


def test_a_bag_without_odometry_takes_the_mount_from_tf_static(tmp_path):
    content = _laser_only(5)
    content.tf = [
        Tf(t=100.0, parent="odom", child="base_footprint", static=True),  # a fixed frame: not the robot
        Tf(t=100.0, parent="base_footprint", child="base_link", x=0.05, static=True),
        Tf(t=100.0, parent="base_link", child="laser", x=0.3, y=-0.1,
           quaternion=yaw_quaternion(0.1), static=True),
    ]  # fmt: skip
    log = load_bag(write_ros1_bag(tmp_path / "mounted.bag", content))
    assert log.odometry is None and log.scans.odometry is None
    assert log.meta["odom_source"] == "none"
    assert log.meta["base_frame"] == "base_footprint"
    assert log.meta["laser_offset_source"] == "tf_static"
    np.testing.assert_allclose(log.scans.laser_offset, [0.35, -0.1, 0.1], atol=1e-12)
    assert (log.meta["laser_offset_x"], log.meta["laser_offset_yaw"]) == pytest.approx((0.35, 0.1))
    assert len(log.scans) == 5 and log.scans.num_beams == 90


def test_tf_without_a_moving_transform_above_the_laser_is_no_odometry(tmp_path, capsys):
    content = _laser_only(5)
    content.tf = [Tf(t=100.0, parent="base_link", child="laser", x=0.2, static=True)] + [
        Tf(t=100.0 + 0.2 * k, parent="odom", child="base_footprint", x=0.1 * k) for k in range(6)
    ]  # /tf moves base_footprint, which nothing links to the laser
    bag = write_ros1_bag(tmp_path / "loose.bag", content)
    log = load_bag(bag)
    assert log.odometry is None and log.scans.odometry is None
    assert log.meta["odom_source"] == "none" and log.meta["base_frame"] == "base_link"
    np.testing.assert_allclose(log.scans.laser_offset, [0.2, 0.0, 0.0], atol=1e-12)
    assert "no moving /tf transform above the laser frame 'laser'" in log.meta["notes"]
    assert "odom → base_footprint" in log.meta["notes"]
    _, out, _ = _run(capsys, "data", "inspect", str(bag))
    assert "odometry none (laser odometry)" in out
    # asked for odometry the bag does not have: the errors name the file and what was found
    with pytest.raises(
        DataError, match=r"loose\.bag: no odometry: .*\(moving transforms: odom → base_footprint\)"
    ):
        load_bag(bag, options=BagOptions(odom_topic="tf"))
    with pytest.raises(DataError, match=r"no odometry for the robot frame 'base_link'"):
        load_bag(bag, options=BagOptions(base_frame="base_link"))
    with pytest.raises(DataError, match=r"--odom-topic /odom: no such topic; topics in the bag"):
        load_bag(bag, options=BagOptions(odom_topic="/odom"))


def test_asking_for_odometry_a_laser_only_bag_lacks_is_an_error(tmp_path, capsys):
    bag = write_ros1_bag(tmp_path / "alone.bag", _laser_only(3))
    with pytest.raises(DataError, match="no odometry") as info:
        load_bag(bag, options=BagOptions(base_frame="base_link"))
    message = str(info.value)
    assert "alone.bag" in message and "/scan (sensor_msgs/msg/LaserScan)" in message
    assert "'base_link' (--base-frame)" in message
    with pytest.raises(
        DataError,
        match=r"alone\.bag: no odometry: .*laser frame 'laser' \(moving transforms: none\)",
    ):
        load_bag(bag, options=BagOptions(odom_topic="tf"))
    with pytest.raises(DataError, match=r"--odom-topic /odom: no such topic"):
        load_bag(bag, options=BagOptions(odom_topic="/odom"))
    code, _, err = _run(
        capsys,
        "run",
        str(bag),
        "--base-frame",
        "base_link",
        "--out",
        str(tmp_path / "o"),
        "--quiet",
    )
    assert code == 2 and len(err.strip().splitlines()) == 1 and "no odometry" in err
    assert not (tmp_path / "o").exists()


def test_two_scan_topics_ask_for_scan_topic(tmp_path, capsys):
    content = straight_run(6)
    content.scans += [Scan(t=s.t + 0.05, ranges=s.ranges[:45], topic="/scan_rear")
                      for s in content.scans]  # fmt: skip
    bag = write_ros1_bag(tmp_path / "two.bag", content)
    with pytest.raises(UsageError, match=r"--scan-topic") as info:
        load_bag(bag)
    assert "/scan, /scan_rear" in str(info.value)
    rear = load_bag(bag, options=BagOptions(scan_topic="/scan_rear"))
    assert rear.scans.num_beams == 45 and rear.meta["scan_topic"] == "/scan_rear"
    assert load_bag(bag, options=BagOptions(scan_topic="scan")).scans.num_beams == 90
    with pytest.raises(DataError, match="--scan-topic /nope: no such topic"):
        load_bag(bag, options=BagOptions(scan_topic="/nope"))
    with pytest.raises(DataError, match="expected a sensor_msgs/msg/LaserScan topic"):
        load_bag(bag, options=BagOptions(scan_topic="/odom"))
    code, _, err = _run(capsys, "run", str(bag), "--out", str(tmp_path / "o"), "--quiet")
    assert code == 2 and "choose one with --scan-topic TOPIC" in err


def test_truncated_bag_one_line_exit_2_nothing_written(tmp_path, capsys):
    whole = write_ros1_bag(tmp_path / "whole.bag", straight_run(40))
    data = whole.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=r"cut\.bag: cannot read the ROS 1 bag"):
        load_bag(cut)
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = _run(capsys, "run", str(cut), "--out", str(tmp_path / "run"), "--quiet")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "cut.bag" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_odometry_only_through_tf(tmp_path):
    content = straight_run(10)
    content.odom.clear()
    content.tf = [
        Tf(t=100.0, parent="base_link", child="laser", x=0.3, y=-0.1,
           quaternion=yaw_quaternion(0.1), static=True),
    ] + [Tf(t=100.0 + 0.2 * k, parent="odom", child="base_link", x=0.1 * k,
            quaternion=yaw_quaternion(0.01 * k)) for k in range(12)]  # fmt: skip
    log = load_bag(write_ros1_bag(tmp_path / "tf.bag", content))
    assert log.meta["odom_source"] == "tf:odom->base_link"
    assert log.meta["base_frame"] == "base_link"
    np.testing.assert_allclose(log.scans.laser_offset, [0.3, -0.1, 0.1], atol=1e-12)
    np.testing.assert_allclose(log.odometry.poses[:, 0], 0.1 * np.arange(12), atol=1e-12)
    np.testing.assert_allclose(log.odometry.poses[:, 2], 0.01 * np.arange(12), atol=1e-12)
    speed = 0.5 * np.cos(0.01 * np.arange(11))  # forward: along the heading at the step's start
    np.testing.assert_allclose(log.odometry.velocities[1:, 0], speed, rtol=1e-9)
    np.testing.assert_allclose(log.odometry.velocities[1:, 1], 0.05, rtol=1e-9)


def test_upside_down_laser_mirrors_angles_and_a_tilted_one_is_an_error(tmp_path):
    content = straight_run(3)
    content.tf[0] = Tf(t=100.0, parent="base_link", child="laser", x=0.2,
                       quaternion=(1.0, 0.0, 0.0, 0.0), static=True)  # fmt: skip  # roll = π
    log = load_bag(write_ros1_bag(tmp_path / "flip.bag", content))
    assert log.meta["laser_upside_down"] == 1
    assert log.scans.angles[0] == pytest.approx(math.pi / 2, abs=1e-7)
    half = math.radians(10.0) / 2  # pitched 10°
    content.tf[0] = Tf(t=100.0, parent="base_link", child="laser",
                       quaternion=(0.0, math.sin(half), 0.0, math.cos(half)), static=True)  # fmt: skip
    with pytest.raises(DataError, match=r"tilted 10\.0°"):
        load_bag(write_ros1_bag(tmp_path / "tilt.bag", content))


def test_missing_mounting_names_the_frames(tmp_path):
    content = straight_run(3)
    content.tf.clear()
    with pytest.raises(
        DataError, match="no transform from the robot frame 'base_link' to the laser"
    ):
        load_bag(write_ros1_bag(tmp_path / "nomount.bag", content))


def test_bare_mcap_loads_like_the_ros1_bag(tmp_path):
    content = straight_run(15, beams=90)
    ros1 = load_bag(write_ros1_bag(tmp_path / "a.bag", content))
    mcap = load_bag(write_bare_mcap(tmp_path / "a.mcap", content))
    assert mcap.meta["format"] == "mcap" and mcap.meta["fast_decoder"] == "odom=True, scan=True"
    assert (ros1.meta["scan_order"], mcap.meta["scan_order"]) == ("header.seq", "bag")
    assert_same_log(ros1, mcap, skip_meta=("scan_order",))


def assert_same_log(a, b, skip_meta: tuple[str, ...] = ()) -> None:
    """Every array and field of two logs' streams are equal (meta may name another format, and
    differ in the keys of ``skip_meta``)."""
    assert a.streams().keys() == b.streams().keys()
    for name, stream in a.streams().items():
        other = b.streams()[name]
        for key, value in vars(stream).items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(value, vars(other)[key], err_msg=f"{name}.{key}")
            else:
                assert value == vars(other)[key], f"{name}.{key}"
    skip = {"format", *skip_meta}
    assert {k: v for k, v in a.meta.items() if k not in skip} == {
        k: v for k, v in b.meta.items() if k not in skip
    }


# --- inspect ------------------------------------------------------------------------------


def test_data_inspect_shows_topics_rates_frames_and_the_command(tmp_path, capsys):
    content = straight_run(20)
    content.extra["/chatter"] = "std_msgs/msg/String"
    bag = write_ros1_bag(tmp_path / "walk.bag", content)
    code, out, _ = _run(capsys, "data", "inspect", str(bag))
    assert code == 0
    assert "ROS 1 bag" in out
    lines = {line.split()[0]: line for line in out.splitlines() if line.startswith("  /")}
    assert "sensor_msgs/msg/LaserScan" in lines["/scan"] and " 20 msgs" in lines["/scan"]
    assert "5.00 Hz" in lines["/scan"] and "5.00 Hz" in lines["/odom"]
    assert "base_link -> laser  (tf_static, 1 transforms)" in out
    assert "slam run reads: scans /scan, odometry /odom" in out
    assert f"run it: slam run {bag}" in out
    code, out, _ = _run(capsys, "data", "inspect", str(bag), "--json")
    report = json.loads(out)
    scan = next(t for t in report["topics"] if t["topic"] == "/scan")
    assert scan["count"] == 20 and scan["rate_hz"] == pytest.approx(5.0)
    assert report["duration_s"] == pytest.approx(4.0, abs=0.02)


def test_data_inspect_reports_why_a_bag_cannot_run(tmp_path, capsys):
    content = straight_run(4)
    content.scans += [Scan(t=s.t, ranges=s.ranges, topic="/scan2") for s in content.scans]
    bag = write_ros1_bag(tmp_path / "two.bag", content)
    code, out, _ = _run(capsys, "data", "inspect", str(bag))
    assert code == 0 and "slam run cannot use it as it is" in out and "--scan-topic" in out
    code, out, _ = _run(capsys, "data", "inspect", str(bag), "--scan-topic", "/scan2")
    assert f"run it: slam run {bag} --scan-topic /scan2" in out
    # the frames too (the bug: inspect said "run it" for a laser frame no transform reaches,
    # and the run then stopped)
    content = straight_run(4)
    for scan in content.scans:
        scan.frame = "hokuyo_link"
    bag = write_ros1_bag(tmp_path / "frame.bag", content)
    code, out, _ = _run(capsys, "data", "inspect", str(bag))
    assert code == 0 and "run it:" not in out
    assert (
        f"slam run cannot use it as it is: {bag}: no transform from the robot frame 'base_link' "
        "to the laser frame 'hokuyo_link'"
    ) in out


def test_data_inspect_carmen_log(tmp_path, capsys):
    clf = tmp_path / "tiny.clf"
    clf.write_text(
        "ODOM 0 0 0 0 0 0 1.0 host 1.0\n"
        "FLASER 3 1.0 2.0 3.0 0 0 0 0 0 0 1.1 host 1.1\n"
        "FLASER 3 1.0 2.0 3.0 0 0 0 0 0 0 1.3 host 1.3\n"
    )
    code, out, _ = _run(capsys, "data", "inspect", str(clf))
    assert code == 0 and "CARMEN log" in out and "scans" in out and "3 beams" in out
    assert f"run it: slam run {clf}" in out


def test_odometry_topic_for_another_frame_is_an_error(tmp_path):
    content = straight_run(3)
    for o in content.odom:
        o.child = "base_footprint"
    with pytest.raises(DataError, match="no transform from the robot frame 'base_footprint'"):
        load_bag(write_ros1_bag(tmp_path / "fp.bag", content))
    content.tf.append(Tf(t=100.0, parent="base_footprint", child="base_link", static=True))
    log = load_bag(write_ros1_bag(tmp_path / "fp2.bag", content))
    np.testing.assert_allclose(log.scans.laser_offset, [0.2, 0.0, 0.0])
    with pytest.raises(DataError, match="describes frame base_footprint, not the robot frame"):
        load_bag(tmp_path / "fp2.bag", options=BagOptions(base_frame="base_link"))


def test_odom_topic_tf_can_be_forced(tmp_path):
    content = straight_run(5)
    content.tf += [Tf(t=100.0 + 0.2 * k, parent="odom", child="base_link", x=1.0 + k)
                   for k in range(7)]  # fmt: skip
    log = load_bag(
        write_ros1_bag(tmp_path / "both.bag", content), options=BagOptions(odom_topic="tf")
    )
    assert log.meta["odom_source"] == "tf:odom->base_link"
    assert log.odometry.poses[0, 0] == pytest.approx(1.0)


def test_odom_messages_order_is_by_stamp(tmp_path):
    content = straight_run(4)
    content.odom = [Odom(t=100.0 + 0.2 * k, x=float(k), y=0.0, yaw=0.0) for k in range(6)]
    content.odom[2].t, content.odom[3].t = content.odom[3].t, content.odom[2].t
    # written in record order = stamp order; the loader's odometry is sorted by stamp
    log = load_bag(write_ros1_bag(tmp_path / "o.bag", content))
    assert np.all(np.diff(log.odometry.time) > 0)


def test_scan_without_content_types(tmp_path):
    bag = write_ros1_bag(tmp_path / "empty.bag", BagContent(odom=[Odom(0.0, 0, 0, 0)]))
    with pytest.raises(DataError, match="no laser scans: no sensor_msgs/msg/LaserScan topic"):
        load_bag(bag)


def test_odom_sync_latest_takes_the_last_odometry_before_each_scan(tmp_path):
    bag = write_ros1_bag(tmp_path / "s.bag", straight_run(10))
    interpolated = load_bag(bag)
    latest = load_bag(bag, options=BagOptions(odom_sync="latest"))
    assert interpolated.scans.odometry is None  # odometry.py interpolates at the stamps
    # scans are stamped 0.01 s after the odometry message k (x = 0.1 k)
    np.testing.assert_allclose(latest.scans.odometry[:, 0], 0.1 * np.arange(10), atol=1e-12)
    assert latest.meta["odom_sync"] == "latest"
    with pytest.raises(UsageError, match="--odom-sync: expected one of interpolate, latest"):
        BagOptions(odom_sync="nearest")


def _glitched_run() -> BagContent:
    """straight_run(20) whose clock jumps ahead by 0.7 s while scans 8–9 and odometry messages
    8–9 are published, and stamps scan 14 0.5 s early (its odometry is not affected)."""
    content = straight_run(20)
    for k in (8, 9):
        content.scans[k].t += 0.7
        content.odom[k].t += 0.7
    content.scans[14].t -= 0.5
    return content


@pytest.mark.parametrize("sync", ["interpolate", "latest"])
def test_stamps_against_the_publication_order_keep_scans_in_seq_order(tmp_path, sync):
    content = _glitched_run()
    log = load_bag(write_ros1_bag(tmp_path / "g.bag", content), options=BagOptions(odom_sync=sync))
    s = log.scans
    # scans in header.seq order, with their own (glitched) stamps
    np.testing.assert_allclose(s.time, [c.t for c in content.scans], atol=1e-9)
    assert log.meta["scan_order"] == "header.seq" and log.meta["scans_reordered"] == 6
    assert log.meta["odom_match"] == "in publication order"
    assert (log.meta["scan_stamp_glitches"], log.meta["odom_stamp_glitches"]) == (3, 2)
    # the pose at each scan is the one of its true time: 0.01 s after odometry message k
    expected = 0.1 * np.arange(20) + (0.005 if sync == "interpolate" else 0.0)
    np.testing.assert_allclose(s.odometry[:, 0], expected, atol=1e-9)
    # what the stamps alone give: scan 14 at x = 0.9 (stamp 102.31), two scans ahead at 1.6
    naive = np.interp(s.time, log.odometry.time, log.odometry.poses[:, 0])
    assert abs(naive[14] - expected[14]) > 0.45


def test_in_order_times_replace_the_stamps_that_break_the_order():
    times, glitches = in_order_times(np.array([0.0, 1.0, 2.0, 9.0, 4.0, 5.0, 1.5, 7.0]))
    np.testing.assert_allclose(times, [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
    assert glitches == 2
    same, none = in_order_times(np.array([0.0, 0.0, 1.0]))
    np.testing.assert_array_equal(same, [0.0, 0.0, 1.0])
    assert none == 0


def test_publication_order_needs_distinct_sequence_numbers():
    np.testing.assert_array_equal(publication_order(np.array([5, 3, 4])), [1, 2, 0])
    assert publication_order(np.array([0, 1, 1])) is None  # two publishers
    assert publication_order(np.array([-1, -1])) is None  # ROS 2: no seq


# --- odometry and scans a bag should not have -----------------------------------------------


def test_a_nan_odometry_pose_names_the_message(tmp_path, capsys):
    """The bug: one NaN x in /odom reached the numba kernels of the odometry synchronisation
    and the run died of a segmentation fault (exit 139, a partial folder left)."""
    content = straight_run(20)
    content.odom[5].x = math.nan
    bag = write_ros1_bag(tmp_path / "nan.bag", content)
    out = tmp_path / "out"
    code, _, err = _run(capsys, "run", str(bag), "--no-record", "--no-texture", "--out", str(out))
    assert code == 2 and not out.exists()
    assert err == (
        f"slam: error: {bag}: /odom: message 6: expected a finite stamp and pose, found "
        "t=101.0, x=nan, y=0.0, yaw=0.0 (1 such message(s))\n"
    )


def test_an_odometry_jump_in_a_bag_is_refused_before_the_run(tmp_path, capsys):
    """The bug: one /odom x of 1e9 m went on to a memory estimate of 1.1 PiB, blamed on the
    trajectory; the jump rule of CARMEN logs did not look at a bag's odometry topic."""
    content = straight_run(20)
    content.odom[5].x = 1e9
    bag = write_ros1_bag(tmp_path / "jump.bag", content)
    code, _, err = _run(capsys, "run", str(bag), "--no-record", "--out", str(tmp_path / "o"))
    assert code == 2
    assert err.startswith(
        f"slam: error: {bag}: /odom at t=101.000000 moves 1e+09 m from the reading before in 0.2 s"
    ), err
    assert "more than checks.max_speed = 10 m/s" in err


def test_a_zero_angle_increment_is_refused(tmp_path):
    content = straight_run(5)
    content.scans[2].angle_increment = 0.0
    bag = write_ros1_bag(tmp_path / "zero.bag", content)
    with pytest.raises(DataError) as caught:
        load_bag(bag)
    assert str(caught.value) == (
        f"{bag}: /scan: scan 3: angle_increment is 0, so all 90 beams would point the same "
        "way; expected the angle between neighbouring beams (rad)"
    )


def test_data_inspect_of_an_empty_bag_shows_no_time_span(tmp_path, capsys):
    bag = write_ros1_bag(tmp_path / "empty.bag", BagContent())
    code, out, _ = _run(capsys, "data", "inspect", str(bag))
    assert code == 0
    assert "time span: 0.000 s, from 0.000 to 0.000; 0 messages" in out


def test_slam_eval_reads_a_bag_run_with_the_topics_the_run_chose(tmp_path, capsys):
    """The bug: a run made with --scan-topic could not be scored (slam eval re-read the bag
    without it and stopped at the two scan topics); the run now records its bag options."""
    content = straight_run(30)
    content.scans += [Scan(t=s.t + 0.05, ranges=s.ranges[:45], topic="/scan_rear")
                      for s in content.scans]  # fmt: skip
    bag = write_ros1_bag(tmp_path / "two.bag", content)
    out = tmp_path / "o"
    code, _, err = _run(capsys, "run", str(bag), "--scan-topic", "/scan_rear", "--no-record",
                        "--no-texture", "--out", str(out), "--quiet")  # fmt: skip
    assert code == 0, err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["bag_options"] == {"scan_topic": "/scan_rear", "odom_topic": None,
                                      "base_frame": None, "odom_sync": "interpolate"}  # fmt: skip
    code, printed, err = _run(capsys, "eval", str(out), "--json")
    assert code == 0, err
    report = json.loads(printed)
    assert report["dataset"] == str(bag) and report["poses"] == 30
    assert report["quality"]["returns"] > 500  # the rear laser's 45 beams, read again


def test_a_bag_named_otherwise_is_read_by_its_content(tmp_path, monkeypatch):
    """The reader goes by the suffix, and a ROS 1 bag or an MCAP file named otherwise was
    refused ("rename or link it"), against data.md's "whatever its name": it is read through a
    link of the right name in a temporary folder, and the log keeps its own name."""
    import tempfile

    links = tmp_path / "links"  # where the temporary folders of the links go
    links.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(links))
    content = straight_run(5)
    bag = write_ros1_bag(tmp_path / "a.bag", content).rename(tmp_path / "robot.dat")
    mcap = write_bare_mcap(tmp_path / "b.mcap", content).rename(tmp_path / "robot-mcap")
    for path in (bag, mcap):
        log = load_bag(path)
        assert log.name == path.name and log.source == path and len(log.scans) == 5
    cut = tmp_path / "cut.dat"  # and on the way out of an error
    cut.write_bytes(bag.read_bytes()[:300])
    with pytest.raises(DataError, match=r"cut\.dat: cannot read the ROS 1 bag"):
        load_bag(cut)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "cut.dat",
        "links",
        "robot-mcap",
        "robot.dat",
    ]
    assert not any(links.iterdir())


def test_damage_messages_are_one_line_with_the_truncation_hint(tmp_path):
    whole = write_ros1_bag(tmp_path / "whole.bag", straight_run(10))
    head = tmp_path / "head.bag"
    head.write_bytes(whole.read_bytes()[:13])
    mcap = write_bare_mcap(tmp_path / "whole.mcap", straight_run(40))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    for path in (head, cut):
        with pytest.raises(DataError) as caught:
            load_bag(path)
        message = str(caught.value)
        assert message.startswith(f"{path}: cannot read the ") and "\n" not in message
        assert "('" not in message and "looks truncated" in message, message


def test_an_mcap_file_that_ends_after_its_magic_is_one_clear_error(tmp_path, capsys):
    """The bug: rosbags raised a TypeError (exit 1, a traceback) on a file holding only the
    MCAP magic; a damaged length field says what was expected."""
    magic = tmp_path / "magic.mcap"
    magic.write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(DataError) as caught:
        load_bag(magic)
    assert str(caught.value) == (
        f"{magic}: cannot read the MCAP file: it ends inside a record; the file looks truncated "
        "or unindexed (copy it again, or `mcap recover` it)"
    )
    code, out, err = _run(capsys, "data", "inspect", str(magic))
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1


def test_damaged_mcap_bytes_are_one_clear_error_wherever_they_are(tmp_path):
    """Eight bytes overwritten with 0xff every 13 bytes through a whole MCAP file: each damage
    is one DataError naming the file (before: a zstd chunk's damage escaped as a ZstdError, a
    length field's as a MemoryError)."""
    whole = write_bare_mcap(tmp_path / "whole.mcap", straight_run(10)).read_bytes()
    kinds = set()
    for at in range(8, len(whole), 13):
        damaged = bytearray(whole)
        damaged[at : at + 8] = b"\xff" * 8
        path = tmp_path / "damaged.mcap"
        path.write_bytes(bytes(damaged))
        try:
            load_bag(path)
        except DataError as exc:
            message = str(exc)
            assert message.startswith(f"{path}: "), message
            assert "\n" not in message
            kinds.add("damaged" if "looks damaged: expected a whole MCAP file" in message else "")
    assert "damaged" in kinds


@pytest.mark.parametrize("error", [TypeError("x"), RuntimeError("y"), MemoryError()])
def test_slams_own_errors_inside_a_readable_bag_are_not_called_damage(tmp_path, monkeypatch, error):
    """The review's find: a TypeError, RuntimeError or MemoryError raised by slam's own code
    while a whole file is read was reported as a damaged file; only the readers' are."""
    import slam.io.rosbag as rosbag

    path = write_bare_mcap(tmp_path / "ok.mcap", straight_run(10))

    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr(rosbag, "_stream", fail)
    with pytest.raises(type(error)):
        load_bag(path)


def test_bag_options_on_a_log_that_is_no_bag_are_refused(tmp_path, capsys):
    """The bug: `slam run aces --scan-topic /front/scan` ran and ignored the option."""
    log = tmp_path / "room.clf"
    log.write_text("ODOM 0 0 0 0 0 0 1.0 host 1.0\n")
    out = tmp_path / "o"
    code, _, err = _run(capsys, "run", str(log), "--scan-topic", "/front", "--out", str(out))
    assert code == 2 and not out.exists()
    assert (
        err
        == "slam: error: --scan-topic: options of a ROS bag or MCAP file, but room is a carmen log\n"
    )
    code, _, err = _run(
        capsys, "data", "inspect", str(log), "--odom-topic", "tf", "--odom-sync", "latest"
    )
    assert code == 2
    assert err == (
        f"slam: error: --odom-topic, --odom-sync: options of a ROS bag or MCAP file, but {log} is a carmen log\n"
    )


def test_data_calibrate_takes_the_bag_options(tmp_path, capsys):
    """The bug: on a bag of two scan topics `slam data calibrate` asked for --scan-topic, which
    it did not have."""
    content = straight_run(30)
    content.scans += [Scan(t=s.t + 0.05, ranges=s.ranges[:45], topic="/scan_rear")
                      for s in content.scans]  # fmt: skip
    bag = write_ros1_bag(tmp_path / "two.bag", content)
    code, _, err = _run(capsys, "data", "calibrate", str(bag))
    assert code == 2 and "choose one with --scan-topic TOPIC" in err
    # with the option it reads the rear laser and goes on to the measurement, which a straight
    # run without a turn cannot make
    code, _, err = _run(capsys, "data", "calibrate", str(bag), "--scan-topic", "/scan_rear")
    assert code == 2
    assert err == (
        f"slam: error: {bag}: the laser's mount: 0 turning scan pairs fitted; at least 10 are "
        "needed\n"
    )


def test_data_inspect_finds_the_odometry_jump_the_run_stops_at(tmp_path, capsys):
    content = straight_run(20)
    content.odom[5].x = 1e9
    bag = write_ros1_bag(tmp_path / "jump.bag", content)
    code, out, _ = _run(capsys, "data", "inspect", str(bag))
    assert code == 0 and "run it:" not in out
    assert f"slam run cannot use it as it is: {bag}: /odom at t=101.000000 moves 1e+09 m" in out


def test_odometry_in_bursts_is_no_jump(tmp_path):
    """intel's bag publishes its odometry in bursts (median step 1 ms, mean 0.1 s): a step of
    5 cm in 3 ms is 16 m/s against the median's floor, and no corrupt reading."""
    from slam.config import Config
    from slam.io.plausibility import odometry_jump

    content = straight_run(20)
    for k, odom in enumerate(content.odom):  # pairs 1 ms apart, 0.4 s between the pairs
        odom.t = 100.0 + 0.4 * (k // 2) + 0.001 * (k % 2)
        odom.x = 0.1 * k
    log = load_bag(write_ros1_bag(tmp_path / "bursts.bag", content))
    assert odometry_jump(log, Config()) is None
    content.odom[7].x += 5.0
    log = load_bag(write_ros1_bag(tmp_path / "bursts-jump.bag", content))
    assert "moves 5.1 m" in odometry_jump(log, Config())
