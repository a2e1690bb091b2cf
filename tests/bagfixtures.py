"""Synthetic ROS 1 bags, ROS 2 bags and MCAP files for the bag loader tests (rosbags' writers).

Not a test module: helpers imported by ``test_rosbag.py``, ``test_rosbag_multiecho.py`` and
``test_mapserver.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Scan:
    t: float
    ranges: Sequence[float]
    angle_min: float = -math.pi / 2
    angle_increment: float | None = None
    range_min: float = 0.1
    range_max: float = 30.0
    frame: str = "laser"
    topic: str = "/scan"
    echoes: int | Sequence[int] = 0
    """0: a ``sensor_msgs/LaserScan``. Otherwise a ``sensor_msgs/MultiEchoLaserScan`` with this
    many echoes per beam (or one count per beam, 0 for a beam without echo): the first echo of a
    beam is its ``ranges`` value, the others lie :data:`ECHO_STEP` m farther each."""


ECHO_STEP = 1.5
"""Metres between a MultiEcho beam's successive echoes in the fixtures (so the first one differs)."""


@dataclass
class Odom:
    t: float
    x: float
    y: float
    yaw: float
    speed: float = 0.0
    yaw_rate: float = 0.0
    topic: str = "/odom"
    frame: str = "odom"
    child: str = "base_link"


@dataclass
class Tf:
    t: float
    parent: str
    child: str
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    static: bool = False


@dataclass
class Imu:
    """A ``sensor_msgs/Imu`` message: rates (rad/s) and accelerations (m/s²) in ``frame``."""

    t: float
    gyro: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel: tuple[float, float, float] = (0.0, 0.0, 9.80665)
    frame: str = "imu_link"
    topic: str = "/imu"
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    """``(x, y, z, w)``."""


@dataclass
class BagContent:
    scans: list[Scan] = field(default_factory=list)
    odom: list[Odom] = field(default_factory=list)
    tf: list[Tf] = field(default_factory=list)
    imu: list[Imu] = field(default_factory=list)
    extra: dict[str, str] = field(default_factory=dict)
    """topic -> msgtype of empty std_msgs/String topics with one message each."""


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def messages(ts, content: BagContent):
    """``(topic, msgtype, record time, message)`` of ``content`` built with the typestore ``ts``,
    sorted by time."""
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]

    def header(t: float, frame: str, seq: int):
        sec = int(math.floor(t))
        stamp = Time(sec=sec, nanosec=int(round((t - sec) * 1e9)))
        if "seq" in Header.__dataclass_fields__:  # ROS 1 only
            return Header(seq=seq, stamp=stamp, frame_id=frame)
        return Header(stamp=stamp, frame_id=frame)

    Vec, Quat, Point = (
        T["geometry_msgs/msg/Vector3"],
        T["geometry_msgs/msg/Quaternion"],
        T["geometry_msgs/msg/Point"],
    )
    out = []
    for i, s in enumerate(content.scans):
        n = len(s.ranges)
        inc = s.angle_increment if s.angle_increment is not None else math.pi / max(n - 1, 1)
        geometry = dict(
            header=header(s.t, s.frame, i),
            angle_min=s.angle_min,
            angle_max=s.angle_min + inc * (n - 1),
            angle_increment=inc,
            time_increment=0.0,
            scan_time=0.0,
            range_min=s.range_min,
            range_max=s.range_max,
        )
        if not isinstance(s.echoes, int) or s.echoes > 0:
            ranges, intensities = _echo_lists(T, s)
            msgtype = "sensor_msgs/msg/MultiEchoLaserScan"
            msg = T[msgtype](**geometry, ranges=ranges, intensities=intensities)
        else:
            msgtype = "sensor_msgs/msg/LaserScan"
            msg = T[msgtype](
                **geometry,
                ranges=np.asarray(s.ranges, dtype=np.float32),
                intensities=np.zeros(0, dtype=np.float32),
            )
        out.append((s.topic, msgtype, s.t, msg))
    for i, m in enumerate(content.imu):
        msg = T["sensor_msgs/msg/Imu"](
            header=header(m.t, m.frame, i),
            orientation=Quat(*_xyzw(m.orientation)),
            orientation_covariance=np.zeros(9),
            angular_velocity=Vec(*m.gyro),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=Vec(*m.accel),
            linear_acceleration_covariance=np.zeros(9),
        )
        out.append((m.topic, "sensor_msgs/msg/Imu", m.t, msg))
    for i, o in enumerate(content.odom):
        pose = T["geometry_msgs/msg/Pose"](
            position=Point(x=o.x, y=o.y, z=0.0), orientation=Quat(*_xyzw(yaw_quaternion(o.yaw)))
        )
        twist = T["geometry_msgs/msg/Twist"](
            linear=Vec(x=o.speed, y=0.0, z=0.0), angular=Vec(x=0.0, y=0.0, z=o.yaw_rate)
        )
        msg = T["nav_msgs/msg/Odometry"](
            header=header(o.t, o.frame, i),
            child_frame_id=o.child,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
        )
        out.append((o.topic, "nav_msgs/msg/Odometry", o.t, msg))
    for i, e in enumerate(content.tf):
        transform = T["geometry_msgs/msg/Transform"](
            translation=Vec(x=e.x, y=e.y, z=e.z), rotation=Quat(*_xyzw(e.quaternion))
        )
        stamped = T["geometry_msgs/msg/TransformStamped"](
            header=header(e.t, e.parent, i), child_frame_id=e.child, transform=transform
        )
        topic = "/tf_static" if e.static else "/tf"
        out.append((topic, "tf2_msgs/msg/TFMessage", e.t, T["tf2_msgs/msg/TFMessage"]([stamped])))
    for topic, msgtype in content.extra.items():
        out.append((topic, msgtype, 100.5, T[msgtype](data="x")))
    out.sort(key=lambda m: m[2])
    return out


def _echo_lists(T, s: Scan) -> tuple[list, list]:
    """``ranges`` and ``intensities`` (``LaserEcho[]``) of a MultiEcho scan: beam ``i`` has
    ``counts[i]`` echoes ``r, r + ECHO_STEP, …`` and intensities ``100 + i, 200 + i, …``."""
    n = len(s.ranges)
    counts = [s.echoes] * n if isinstance(s.echoes, int) else list(s.echoes)
    assert len(counts) == n, "one echo count per beam"
    Echo = T["sensor_msgs/msg/LaserEcho"]
    ranges, intensities = [], []
    for i, (r, k) in enumerate(zip(s.ranges, counts, strict=True)):
        ranges.append(Echo(echoes=echo_list(r, k)))
        intensities.append(Echo(echoes=(100.0 * np.arange(1, k + 1) + i).astype(np.float32)))
    return ranges, intensities


def echo_list(first: float, count: int) -> np.ndarray:
    """``count`` float32 echoes: ``first`` exactly (its bits kept), then each :data:`ECHO_STEP`
    m farther."""
    echoes = np.float32(first) + np.float32(ECHO_STEP) * np.arange(count, dtype=np.float32)
    echoes[:1] = np.float32(first)
    return echoes


def _xyzw(q):
    x, y, z, w = q
    return (x, y, z, w)


def _typestore(store, types: dict | None):
    """rosbags' typestore ``store``, with the message definitions ``types`` (a rosbags
    ``Typesdict``, e.g. from ``get_types_from_msg``) added or replacing the store's own."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(store)
    if not types:
        return ts
    custom = get_typestore(Stores.EMPTY)
    custom.register({**ts.fielddefs, **types})
    return custom


def write_ros1_bag(path: Path, content: BagContent, types: dict | None = None) -> Path:
    """A ROS 1 bag (rosbags' writer, ROS 1 Noetic definitions, or ``types`` instead) holding
    ``content``."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg

    tf = get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    ts = _typestore(Stores.ROS1_NOETIC, {**tf, **(types or {})})  # Noetic has no tf2_msgs
    with Writer(path) as writer:
        conns = {}
        for topic, msgtype, t, msg in messages(ts, content):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], int(round(t * 1e9)), ts.serialize_ros1(msg, msgtype))
    return path


def write_bare_mcap(path: Path, content: BagContent, types: dict | None = None) -> Path:
    """A bare MCAP file written with the ``mcap`` library (ros2msg schemas of ROS 2 Humble, or
    ``types`` instead; CDR messages)."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores

    ts = _typestore(Stores.ROS2_HUMBLE, types)
    with open(path, "wb") as fh:
        writer = Writer(fh)
        writer.start(profile="ros2", library="slam-tests")
        channels: dict[str, int] = {}
        for topic, msgtype, t, msg in messages(ts, content):
            if topic not in channels:
                msgdef, _ = ts.generate_msgdef(msgtype, ros_version=2)
                schema = writer.register_schema(
                    name=msgtype, encoding="ros2msg", data=msgdef.encode()
                )
                channels[topic] = writer.register_channel(
                    topic=topic, message_encoding="cdr", schema_id=schema
                )
            stamp = int(round(t * 1e9))
            writer.add_message(
                channel_id=channels[topic],
                log_time=stamp,
                publish_time=stamp,
                data=bytes(ts.serialize_cdr(msg, msgtype)),
            )
        writer.finish()
    return path


def write_ros2_bag(
    path: Path, content: BagContent, storage: str = "sqlite3", types: dict | None = None
) -> Path:
    """A ROS 2 bag folder (rosbags' writer, ROS 2 Humble definitions or ``types`` instead, CDR)
    with ``storage`` ``sqlite3`` or ``mcap``."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores

    ts = _typestore(Stores.ROS2_HUMBLE, types)
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        conns = {}
        for topic, msgtype, t, msg in messages(ts, content):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], int(round(t * 1e9)), bytes(ts.serialize_cdr(msg, msgtype)))
    return path


def straight_run(n: int = 20, beams: int = 90, dt: float = 0.2) -> BagContent:
    """A robot driving 0.1 m per scan along x in front of a wall 5 m ahead."""
    content = BagContent()
    angles = -math.pi / 2 + np.arange(beams) * math.pi / (beams - 1)
    for k in range(n):
        t = 100.0 + k * dt
        x = 0.1 * k
        with np.errstate(divide="ignore"):
            r = np.where(np.cos(angles) > 0.2, (5.0 - x) / np.cos(angles), np.inf)
        content.scans.append(Scan(t=t + 0.01, ranges=np.minimum(r, 40.0).tolist()))
        content.odom.append(Odom(t=t, x=x, y=0.0, yaw=0.0, speed=0.5))
    content.odom.append(Odom(t=100.0 + n * dt, x=0.1 * n, y=0.0, yaw=0.0, speed=0.5))
    content.tf.append(Tf(t=100.0, parent="base_link", child="laser", x=0.2, static=True))
    return content
