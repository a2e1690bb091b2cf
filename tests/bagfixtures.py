"""Synthetic ROS 1 bags, ROS 2 bags and MCAP files for the bag loader tests (rosbags' writers).

Not a test module: helpers imported by ``test_rosbag.py`` and ``test_mapserver.py``.
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
class BagContent:
    scans: list[Scan] = field(default_factory=list)
    odom: list[Odom] = field(default_factory=list)
    tf: list[Tf] = field(default_factory=list)
    extra: dict[str, str] = field(default_factory=dict)
    """topic -> msgtype of empty std_msgs/String topics with one message each."""


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def _messages(ts, content: BagContent):
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
        msg = T["sensor_msgs/msg/LaserScan"](
            header=header(s.t, s.frame, i),
            angle_min=s.angle_min,
            angle_max=s.angle_min + inc * (n - 1),
            angle_increment=inc,
            time_increment=0.0,
            scan_time=0.0,
            range_min=s.range_min,
            range_max=s.range_max,
            ranges=np.asarray(s.ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )
        out.append((s.topic, "sensor_msgs/msg/LaserScan", s.t, msg))
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


def _xyzw(q):
    x, y, z, w = q
    return (x, y, z, w)


def write_ros1_bag(path: Path, content: BagContent) -> Path:
    """A ROS 1 bag (rosbags' writer, ROS 1 Noetic definitions) holding ``content``."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)  # has no tf2_msgs: add TFMessage
    ts.register(
        get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    )
    with Writer(path) as writer:
        conns = {}
        for topic, msgtype, t, msg in _messages(ts, content):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], int(round(t * 1e9)), ts.serialize_ros1(msg, msgtype))
    return path


def write_bare_mcap(path: Path, content: BagContent) -> Path:
    """A bare MCAP file written with the ``mcap`` library (ros2msg schemas, CDR messages)."""
    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    with open(path, "wb") as fh:
        writer = Writer(fh)
        writer.start(profile="ros2", library="slam-tests")
        channels: dict[str, int] = {}
        for topic, msgtype, t, msg in _messages(ts, content):
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
