"""Cartographer's bags: ``sensor_msgs/MultiEchoLaserScan`` scans (the first echo of each beam)
and the IMU rotated into the robot frame, on synthetic bags and on intel's scans converted."""

from __future__ import annotations

import dataclasses
import math
import shlex
import struct
from pathlib import Path

import numpy as np
import pytest
from bagfixtures import (
    BagContent,
    Imu,
    Odom,
    Scan,
    Tf,
    echo_list,
    messages,
    straight_run,
    write_bare_mcap,
    write_ros1_bag,
    write_ros2_bag,
    yaw_quaternion,
)
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from test_rosbag import assert_same_log

from slam.cli import main
from slam.errors import DataError, UsageError
from slam.io import rosbag
from slam.io.rosbag import (
    MULTI_ECHO_TYPE,
    STANDARD_GRAVITY,
    BagOptions,
    inspect_bag,
    load_bag,
    open_bag,
)

WRITERS = {
    "ros1": lambda path, content, **kw: write_ros1_bag(path.with_suffix(".bag"), content, **kw),
    "ros2-sqlite3": lambda path, content, **kw: write_ros2_bag(path, content, **kw),
    "mcap": lambda path, content, **kw: write_bare_mcap(path.with_suffix(".mcap"), content, **kw),
}

# range_min 0.1, range_max 30: per beam the first echo written and the echo count
FIRST = [1.0, 2.0, 0.05, 30.0, 35.0, math.inf, -1.0, math.nan, 3.0, 4.0]
COUNTS = [1, 2, 3, 2, 1, 1, 1, 1, 0, 3]
LOADED = [1.0, 2.0, math.nan, 30.0, 35.0, math.inf, math.nan, math.nan, math.nan, 4.0]
"""What the loader makes of FIRST: below range_min, negative, NaN and no echo at all are invalid
(NaN); 30 (= range_max), 35 and +inf are "no return" and keep their value."""


def _echo_content(n: int = 4, counts=COUNTS, topic: str = "/horizontal_laser_2d") -> BagContent:
    """``n`` MultiEcho scans of FIRST / COUNTS (0.1 s apart), the laser 0.2 m ahead of
    base_link by /tf_static, no odometry (as in Cartographer's demo bags)."""
    content = BagContent()
    for k in range(n):
        ranges = [r + 0.01 * k if math.isfinite(r) and r > 0.1 else r for r in FIRST]
        content.scans.append(
            Scan(t=100.0 + 0.1 * k, ranges=ranges, angle_increment=math.pi / 16, echoes=counts,
                 topic=topic)
        )  # fmt: skip
    content.tf.append(Tf(t=100.0, parent="base_link", child="laser", x=0.2, static=True))
    return content


def _refusal(bag: Path, error: type[Exception]) -> str:
    """The message of the ``error`` that loading ``bag`` raises."""
    with pytest.raises(error) as info:
        load_bag(bag)
    return str(info.value)


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# --- loading ------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_multi_echo_scans_load_their_first_echoes(tmp_path, fmt):
    content = _echo_content()
    log = load_bag(WRITERS[fmt](tmp_path / "museum", content))
    s = log.scans
    assert len(s) == 4 and s.ranges.shape == (4, 10)
    expected = np.array([scan.ranges for scan in content.scans], dtype=np.float32)
    expected[:, np.isnan(LOADED)] = np.nan
    np.testing.assert_array_equal(s.ranges, expected)  # the first echoes, not the 2nd (+1.5 m)
    np.testing.assert_array_equal(s.ranges[0], np.array(LOADED, dtype=np.float32))
    assert s.invalid_beams == 4 * 4  # 0.05, -1, NaN and the beam without echo, in every scan
    assert np.count_nonzero(s.ranges >= s.no_return) == 3 * 4 and s.no_return == 30.0
    assert s.range_min == pytest.approx(0.1)
    np.testing.assert_allclose(s.angles, -math.pi / 2 + math.pi / 16 * np.arange(10), atol=1e-6)
    np.testing.assert_allclose(s.time, 100.0 + 0.1 * np.arange(4), atol=1e-9)
    np.testing.assert_allclose(s.laser_offset, [0.2, 0.0, 0.0], atol=1e-12)
    assert log.meta["scan_type"] == MULTI_ECHO_TYPE == "sensor_msgs/msg/MultiEchoLaserScan"
    assert log.meta["scan_topic"] == "/horizontal_laser_2d"
    assert log.meta["fast_decoder"] == "scan=True" and log.meta["odom_source"] == "none"
    assert log.summary()["scan_type"] == MULTI_ECHO_TYPE  # what `slam data verify` prints


def test_a_multi_echo_bag_loads_like_the_laser_scan_bag_of_its_first_echoes(tmp_path):
    multi = _echo_content(6)
    plain = _echo_content(6)
    for scan in plain.scans:  # a LaserScan of the first echoes: NaN where a beam has no echo
        scan.echoes = 0
        scan.ranges = [math.nan if k == 0 else r for r, k in zip(scan.ranges, COUNTS, strict=True)]
    a = load_bag(write_ros1_bag(tmp_path / "multi.bag", multi))
    b = load_bag(write_ros1_bag(tmp_path / "plain.bag", plain))
    assert a.meta["scan_type"] == MULTI_ECHO_TYPE
    assert b.meta["scan_type"] == "sensor_msgs/msg/LaserScan"
    assert_same_log(a, b, skip_meta=("scan_type",))


# --- the fast decoder ---------------------------------------------------------------------

LAYOUTS = {
    "one echo": ([1.0, 2.0, 3.0], 1),
    "three echoes": ([1.0, 2.0, 3.0], 3),
    "varying": (FIRST, COUNTS),
    "zero-valued echoes": ([0.0, 0.0, 1.0, 0.0, 2.0], [3, 1, 0, 2, 2]),
    "no echo at all": ([1.0, 2.0], [0, 0]),
    "no beams": ([], []),
    "many echoes": ([1.0, 2.0, 3.0], [70, 1, 2]),  # beyond _ECHO_COUNT_MAX: walked one by one
}


def _serialized(ts, content: BagContent, ros1: bool) -> list[tuple[bytes, list[float]]]:
    """``(raw, first echoes)`` of every MultiEcho scan of ``content``, serialized by rosbags (CDR:
    little- and big-endian), with its intensities as written (the ranges' echo counts), none,
    and one per beam."""
    Echo = ts.types["sensor_msgs/msg/LaserEcho"]
    out = []
    for _, msgtype, _, written in messages(ts, content):
        first = [e.echoes[0] if len(e.echoes) else math.nan for e in written.ranges]
        single = [Echo(echoes=np.array([7.0], dtype=np.float32)) for _ in written.ranges]
        for intensities in (written.intensities, [], single):
            msg = dataclasses.replace(written, intensities=intensities)
            if ros1:
                out.append((bytes(ts.serialize_ros1(msg, msgtype)), first))
                continue
            for little in (True, False):
                out.append((bytes(ts.serialize_cdr(msg, msgtype, little_endian=little)), first))
    return out


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize("frame", ["l", "la", "las", "lase"])  # every CDR alignment
def test_fast_decoder_equals_the_rosbags_deserializer(layout, frame):
    ranges, counts = LAYOUTS[layout]
    content = BagContent(scans=[Scan(t=100.25, ranges=ranges, echoes=counts, frame=frame)])
    for ros1 in (True, False):
        ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        fast = rosbag._SCAN_DECODERS[MULTI_ECHO_TYPE][0 if ros1 else 1]
        deserialize = ts.deserialize_ros1 if ros1 else ts.deserialize_cdr
        for raw, first in _serialized(ts, content, ros1):
            decoded = fast(raw)
            reference = rosbag._multi_echo_msg(deserialize(raw, MULTI_ECHO_TYPE))
            assert rosbag._same(decoded, reference), (layout, frame, ros1)
            np.testing.assert_array_equal(decoded.ranges, np.array(first, dtype=np.float32))
            assert decoded.frame == frame and decoded.stamp_ns == 100_250_000_000
            assert decoded.range_max == 30.0 and decoded.angle_min == np.float32(-math.pi / 2)
            with pytest.raises(rosbag._Mismatch):  # one byte more or less is another message
                fast(raw + bytes(4))
            with pytest.raises((rosbag._Mismatch, ValueError, IndexError, struct.error)):
                fast(raw[:-4])


def test_varying_echo_counts_are_indexed_without_a_loop_and_checked():
    def word(x: float) -> int:
        return int(np.float32(x).view(np.uint32))

    # counts 2, 0, 1 (echoes 1.0 and 0.0, none, 2.5), then the next list's count 1
    words = np.array([2, word(1.0), word(0.0), 0, 1, word(2.5), 1], dtype=np.uint32)
    heads, end = rosbag._varying_echo_starts(words, 3)
    np.testing.assert_array_equal(heads, [0, 3, 4])
    assert end == 6
    walked, walked_end = rosbag._walk_echo_starts(words, 3)
    np.testing.assert_array_equal(walked, heads)
    assert walked_end == end
    # an echo whose bits are a small number (a subnormal float) hides a count: refused, walked
    words = np.array([1, 3, 1, 5], dtype=np.uint32)
    assert rosbag._varying_echo_starts(words, 2) is None
    heads, end = rosbag._echo_starts(words, 0, 2)
    np.testing.assert_array_equal(heads, [0, 2])
    assert end == 4


DOUBLE_RANGE_MAX = """std_msgs/Header header
float32 angle_min
float32 angle_max
float32 angle_increment
float32 time_increment
float32 scan_time
float32 range_min
float64 range_max
sensor_msgs/LaserEcho[] ranges
sensor_msgs/LaserEcho[] intensities
"""


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_another_message_definition_falls_back_to_rosbags(tmp_path, fmt):
    types = get_types_from_msg(DOUBLE_RANGE_MAX, MULTI_ECHO_TYPE)  # range_max as float64
    log = load_bag(WRITERS[fmt](tmp_path / "odd", _echo_content(), types=types))
    standard = load_bag(WRITERS[fmt](tmp_path / "std", _echo_content()))
    assert log.meta["fast_decoder"] == "scan=False"
    assert standard.meta["fast_decoder"] == "scan=True"
    assert_same_log(log, standard, skip_meta=("fast_decoder",))


# --- choosing the topic -------------------------------------------------------------------


def _two_lasers() -> BagContent:
    """A horizontal MultiEcho laser of 10 beams and a vertical one of 5, as in Cartographer's
    2D backpack bags."""
    content = _echo_content(5)
    vertical = _echo_content(5, counts=[2, 0, 1, 1, 3], topic="/vertical_laser_2d")
    for scan in vertical.scans:
        scan.ranges, scan.frame, scan.t = scan.ranges[:5], "vertical_laser", scan.t + 0.05
    content.scans += vertical.scans
    content.tf.append(Tf(t=100.0, parent="base_link", child="vertical_laser", static=True))
    return content


def test_two_multi_echo_topics_ask_for_scan_topic(tmp_path, capsys):
    bag = write_ros1_bag(tmp_path / "museum.bag", _two_lasers())
    with pytest.raises(UsageError, match=r"--scan-topic") as info:
        load_bag(bag)
    assert str(info.value) == (
        f"{bag}: 2 sensor_msgs/msg/MultiEchoLaserScan topics "
        "(/horizontal_laser_2d, /vertical_laser_2d); choose one with --scan-topic TOPIC"
    )
    horizontal = load_bag(bag, options=BagOptions(scan_topic="/horizontal_laser_2d"))
    vertical = load_bag(bag, options=BagOptions(scan_topic="vertical_laser_2d"))
    assert horizontal.scans.ranges.shape == (5, 10) and vertical.scans.ranges.shape == (5, 5)
    assert horizontal.meta["laser_frame"] == "laser"
    assert vertical.meta["laser_frame"] == "vertical_laser"
    assert vertical.meta["scan_topic"] == "/vertical_laser_2d"
    assert vertical.scans.invalid_beams == 5 * 2  # 0.05 and the beam without echo
    code, _, err = _run(capsys, "run", str(bag), "--out", str(tmp_path / "o"), "--quiet")
    assert code == 2 and "choose one with --scan-topic TOPIC" in err
    assert not (tmp_path / "o").exists()


def test_a_laser_scan_and_a_multi_echo_topic_are_two_scan_topics(tmp_path):
    content = _echo_content(3)
    content.scans += [Scan(t=s.t + 0.05, ranges=s.ranges, angle_increment=math.pi / 16)
                      for s in _echo_content(3).scans]  # fmt: skip  # LaserScan on /scan
    bag = write_ros1_bag(tmp_path / "both.bag", content)
    assert (
        "2 laser scan topics (/horizontal_laser_2d (sensor_msgs/msg/MultiEchoLaserScan), "
        "/scan (sensor_msgs/msg/LaserScan)); choose one with --scan-topic TOPIC"
    ) in _refusal(bag, UsageError)
    multi = load_bag(bag, options=BagOptions(scan_topic="/horizontal_laser_2d"))
    plain = load_bag(bag, options=BagOptions(scan_topic="/scan"))
    assert (multi.meta["scan_type"], plain.meta["scan_type"]) == (
        MULTI_ECHO_TYPE,
        "sensor_msgs/msg/LaserScan",
    )
    assert multi.scans.invalid_beams == 3 * 4 and plain.scans.invalid_beams == 3 * 3
    with pytest.raises(
        DataError,
        match=r"--scan-topic /tf_static: expected a sensor_msgs/msg/LaserScan topic "
        r"\(or sensor_msgs/msg/MultiEchoLaserScan\), found tf2_msgs/msg/TFMessage",
    ):
        load_bag(bag, options=BagOptions(scan_topic="/tf_static"))


def test_no_scan_topic_names_both_types(tmp_path):
    bag = write_ros1_bag(tmp_path / "none.bag", BagContent(odom=[Odom(0.0, 0, 0, 0)]))
    assert (
        "no laser scans: no sensor_msgs/msg/LaserScan topic (or "
        "sensor_msgs/msg/MultiEchoLaserScan); topics in the bag: /odom (nav_msgs/msg/Odometry)"
    ) in _refusal(bag, DataError)


def test_inspect_lists_a_multi_echo_topic_as_the_scans_and_its_command_runs(tmp_path, capsys):
    bag = write_ros1_bag(tmp_path / "museum.bag", _two_lasers())
    report = inspect_bag(bag)
    assert "--scan-topic" in report["run"]["error"] and report["run"]["command"] is None
    report = inspect_bag(bag, BagOptions(scan_topic="/horizontal_laser_2d"))
    types = {t["topic"]: (t["type"], t["count"]) for t in report["topics"]}
    assert types["/horizontal_laser_2d"] == (MULTI_ECHO_TYPE, 5)
    assert types["/vertical_laser_2d"] == (MULTI_ECHO_TYPE, 5)
    run = report["run"]
    assert run["scan_topic"] == "/horizontal_laser_2d" and run["scan_type"] == MULTI_ECHO_TYPE
    assert run["odom_source"] == "none (laser odometry)"
    assert run["command"] == f"slam run {bag} --scan-topic /horizontal_laser_2d"
    code, out, _ = _run(capsys, "data", "inspect", str(bag), "--scan-topic", "/horizontal_laser_2d")
    reads = "slam run reads: scans /horizontal_laser_2d (MultiEchoLaserScan: first echoes), "
    assert code == 0 and reads + "odometry none (laser odometry)" in out
    # the suggested command runs (on laser odometry: the bag has none)
    single = write_ros1_bag(tmp_path / "walk.bag", _multi_echo_walk())
    command = inspect_bag(single)["run"]["command"]
    assert command == f"slam run {single}"
    out_dir = tmp_path / "run"
    code, _, err = _run(capsys, *shlex.split(command)[1:], "--out", str(out_dir), "--quiet",
                        "--no-record")  # fmt: skip
    assert "the log has no odometry" in err
    assert code == 0 and (out_dir / "map.pgm").is_file()
    poses = [line for line in (out_dir / "trajectory.tum").read_text().splitlines()
             if not line.startswith("#")]  # fmt: skip
    assert len(poses) == 10


def _multi_echo_walk() -> BagContent:
    """straight_run(10) without odometry, its scans written as MultiEcho with two echoes."""
    content = straight_run(10)
    content.odom.clear()
    for scan in content.scans:
        scan.echoes = 2
    return content


# --- the IMU in the robot frame -----------------------------------------------------------

GYRO = (0.1, 0.2, 0.3)
ACCEL = (0.5, 0.0, -STANDARD_GRAVITY)


def _with_imu(frame: str = "imu_link", mounts: list[Tf] | None = None) -> BagContent:
    content = _echo_content(3)
    content.imu = [Imu(t=100.0 + 0.01 * k, gyro=GYRO, accel=ACCEL, frame=frame) for k in range(20)]
    content.tf += mounts or []
    return content


def test_an_upside_down_imu_is_rotated_into_the_robot_frame(tmp_path):
    roll_pi = Tf(t=100.0, parent="base_link", child="imu_link", z=0.1,
                 quaternion=(1.0, 0.0, 0.0, 0.0), static=True)  # fmt: skip
    log = load_bag(write_ros1_bag(tmp_path / "flip.bag", _with_imu(mounts=[roll_pi])))
    imu = log.imu
    assert imu.angular_velocity.shape == (3, 20)
    # rolled by π: x stays, y and z flip; the yaw rate about the robot's z axis is -0.3 rad/s
    np.testing.assert_allclose(imu.angular_velocity.T, [[0.1, -0.2, -0.3]] * 20, atol=1e-12)
    np.testing.assert_allclose(imu.linear_acceleration.T, [[0.5 / STANDARD_GRAVITY, 0.0, 1.0]] * 20,
                               atol=1e-12)  # fmt: skip  # in g: gravity now along +z
    assert log.meta["imu_topic"] == "/imu" and log.meta["imu_frame"] == "imu_link"
    assert log.meta["imu_rotated"] is True and log.meta["imu_frame_source"] == "tf_static"
    assert "notes" not in log.meta


def test_the_imu_rotation_is_the_whole_chain_in_3d(tmp_path):
    mounts = [
        Tf(t=100.0, parent="base_link", child="imu_mount", quaternion=yaw_quaternion(math.pi / 2),
           static=True),
        Tf(t=100.0, parent="imu_mount", child="imu_link", quaternion=(1.0, 0.0, 0.0, 0.0),
           static=True),
    ]  # fmt: skip
    log = load_bag(write_bare_mcap(tmp_path / "chain.mcap", _with_imu(mounts=mounts)))
    # Rz(π/2) · Rx(π) = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]
    np.testing.assert_allclose(log.imu.angular_velocity[:, 0], [0.2, 0.1, -0.3], atol=1e-12)
    np.testing.assert_allclose(log.imu.linear_acceleration[:, 0] * STANDARD_GRAVITY,
                               [0.0, 0.5, STANDARD_GRAVITY], atol=1e-12)  # fmt: skip
    assert log.meta["imu_rotated"] is True


def test_an_imu_mounted_by_tf_alone_is_found_there(tmp_path):
    content = straight_run(5)  # Odometry topic and the laser on tf_static: /tf not needed for them
    content.imu = [Imu(t=100.0 + 0.1 * k, gyro=GYRO, accel=ACCEL) for k in range(10)]
    content.tf += [Tf(t=100.0 + 0.2 * k, parent="base_link", child="imu_link",
                      quaternion=(1.0, 0.0, 0.0, 0.0)) for k in range(5)]  # fmt: skip
    log = load_bag(write_ros1_bag(tmp_path / "tfimu.bag", content))
    assert log.meta["odom_source"] == "/odom" and log.meta["imu_frame_source"] == "tf"
    np.testing.assert_allclose(log.imu.angular_velocity[:, 0], [0.1, -0.2, -0.3], atol=1e-12)


def test_an_imu_without_a_chain_stays_as_recorded(tmp_path):
    log = load_bag(write_ros1_bag(tmp_path / "loose.bag", _with_imu()))  # no base_link → imu_link
    np.testing.assert_array_equal(log.imu.angular_velocity.T, [GYRO] * 20)
    np.testing.assert_allclose(log.imu.linear_acceleration[:, 0] * STANDARD_GRAVITY, ACCEL)
    assert log.meta["imu_frame"] == "imu_link" and log.meta["imu_rotated"] is False
    assert log.meta["imu_frame_source"] == "none"
    assert log.meta["notes"] == (
        "IMU readings as recorded, not rotated into the robot frame: no transform from the "
        "robot frame 'base_link' to the IMU frame 'imu_link'"
    )
    unnamed = load_bag(write_ros1_bag(tmp_path / "unnamed.bag", _with_imu(frame="")))
    np.testing.assert_array_equal(unnamed.imu.angular_velocity.T, [GYRO] * 20)
    assert unnamed.meta["imu_rotated"] is False
    assert unnamed.meta["notes"].endswith("its messages name no frame")
    mixed = _with_imu()
    for k, m in enumerate(mixed.imu):
        m.frame = "imu_a" if k % 2 else "imu_b"
    mixed.tf += [Tf(t=100.0, parent="base_link", child=f, static=True) for f in ("imu_a", "imu_b")]
    two = load_bag(write_ros1_bag(tmp_path / "two.bag", mixed))
    np.testing.assert_array_equal(two.imu.angular_velocity.T, [GYRO] * 20)
    assert two.meta["imu_frame"] == "imu_a, imu_b" and two.meta["imu_rotated"] is False
    assert two.meta["notes"].endswith("its messages name several frames (imu_a, imu_b)")
    robot = load_bag(write_ros1_bag(tmp_path / "robot.bag", _with_imu(frame="base_link")))
    np.testing.assert_array_equal(robot.imu.angular_velocity.T, [GYRO] * 20)
    assert robot.meta["imu_frame_source"] == "same frame" and robot.meta["imu_rotated"] is False
    assert "notes" not in robot.meta


# --- real data ----------------------------------------------------------------------------


def test_intel_scans_as_multi_echo_load_bit_for_bit(carmen_dir, tmp_path):
    """intel's first 300 /scan messages, copied as they are and converted to MultiEcho (each beam
    1 to 3 echoes, the first its LaserScan range), load to the same scans."""
    src = carmen_dir / "bags" / "intel.orig.bag"
    if not src.is_file():
        pytest.skip(f"{src} is absent")
    plain, multi = _intel_copies(src, tmp_path, 300)
    a, b = load_bag(plain), load_bag(multi)
    assert (a.meta["scan_type"], b.meta["scan_type"]) == (
        "sensor_msgs/msg/LaserScan",
        MULTI_ECHO_TYPE,
    )
    assert a.meta["fast_decoder"] == b.meta["fast_decoder"] == "scan=True"
    assert len(a.scans) == 300 and a.scans.num_beams == 180
    assert a.meta["scans_reordered"] == b.meta["scans_reordered"] > 0  # header.seq order
    assert_same_log(a, b, skip_meta=("scan_type",))  # ranges equal bit for bit, NaN for NaN
    assert a.scans.invalid_beams == b.scans.invalid_beams


def _intel_copies(src: Path, out: Path, count: int) -> tuple[Path, Path]:
    """Two ROS 1 bags of ``src``'s /tf_static and first ``count`` /scan messages: the messages
    copied, and the scans rewritten as MultiEchoLaserScan."""
    from rosbags.rosbag1 import Writer

    ts = get_typestore(Stores.ROS1_NOETIC)
    Echo, Multi = ts.types["sensor_msgs/msg/LaserEcho"], ts.types[MULTI_ECHO_TYPE]
    plain_path, multi_path = out / "intel300.bag", out / "intel300_multiecho.bag"
    with (
        open_bag(src) as (reader, _),
        Writer(plain_path) as plain,
        Writer(multi_path) as multi,
    ):
        conns = [c for c in reader.connections if c.topic in ("/scan", "/tf_static")]
        copies: dict[str, tuple] = {}
        scans = 0
        for conn, stamp, raw in reader.messages(connections=conns):
            if conn.topic not in copies:
                same = {"msgdef": conn.msgdef.data, "md5sum": conn.digest}
                converted = {"typestore": ts} if conn.topic == "/scan" else same
                msgtype = MULTI_ECHO_TYPE if conn.topic == "/scan" else conn.msgtype
                copies[conn.topic] = (
                    plain.add_connection(conn.topic, conn.msgtype, **same),
                    multi.add_connection(conn.topic, msgtype, **converted),
                )
            to_plain, to_multi = copies[conn.topic]
            plain.write(to_plain, stamp, raw)
            if conn.topic != "/scan":
                multi.write(to_multi, stamp, raw)
                continue
            m = reader.deserialize(raw, conn.msgtype)
            echoes = [Echo(echoes=echo_list(r, 1 + i % 3)) for i, r in enumerate(m.ranges)]
            fields = ("header", "angle_min", "angle_max", "angle_increment", "time_increment",
                      "scan_time", "range_min", "range_max")  # fmt: skip
            message = Multi(**{f: getattr(m, f) for f in fields}, ranges=echoes, intensities=[])
            multi.write(to_multi, stamp, bytes(ts.serialize_ros1(message, MULTI_ECHO_TYPE)))
            scans += 1
            if scans == count:
                break
    return plain_path, multi_path
