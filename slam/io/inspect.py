"""``slam data inspect``: what a log file or folder holds, and how ``slam run`` would read it.

This module owns the inspection report of any log path: its format (by content,
:func:`slam.io.formats.detect_format`), per stream or topic what it holds, and the command that
runs it. Bags are described from their index and record times (:func:`slam.io.rosbag.inspect_bag`);
CARMEN logs and ECE276A folders are loaded with their loader and summarised
(:meth:`slam.io.log.Log.summary`).
"""

from __future__ import annotations

import shlex
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from slam.io.formats import BAG_FORMATS, detect_format, run_config_name
from slam.io.log import beams_text
from slam.io.rosbag import BagOptions

FORMAT_NAMES = {
    "ros1": "ROS 1 bag",
    "mcap": "MCAP file",
    "rosbag2": "ROS 2 bag",
    "carmen": "CARMEN log",
    "ece276a": "ECE276A dataset folder",
}


def inspect_path(path: Path, options: BagOptions | None = None) -> dict[str, Any]:
    """The JSON-ready report of ``slam data inspect`` for ``path``."""
    path = Path(path)
    fmt = detect_format(path)
    if fmt in BAG_FORMATS:
        from slam.io.rosbag import inspect_bag

        return inspect_bag(path, options)
    from slam.config import load_config
    from slam.io.sources import refuse_bag_options

    refuse_bag_options(options, str(path), fmt)

    dataset, shipped = run_config_name(str(path))
    config = load_config(dataset if shipped else "")
    if fmt == "carmen":
        from slam.io.carmen import load_carmen

        log = load_carmen(path, name=dataset, lidar=config.lidar)
    else:
        from slam.io.ece276a import load_ece276a

        number = next(path.glob("Encoders*.npz")).stem[len("Encoders") :]
        log = load_ece276a(path, number, need=(), name=dataset, lidar=config.lidar)
    command = f"slam run {shlex.quote(str(path))}"
    run: dict[str, Any] = {"command": command}
    if log.scans is None:
        run["command"] += " --method odometry"
    else:
        run["odometry"] = _odometry_read(log)
    summary = log.summary()
    return {
        "path": str(path),
        "format": fmt,
        "streams": {k: v for k, v in summary.items() if isinstance(v, dict)},
        "notes": {
            k: v
            for k, v in summary.items()
            if not isinstance(v, dict) and k not in ("name", "kind")
        },
        "run": run,
    }


def _odometry_read(log: Any) -> str:
    """Which odometry ``slam run`` reads from a log with scans (``robot.odometry = "auto"``)."""
    from slam.odometry import has_odometry, moving_stream, never_moves

    written = log.scans.odometry
    if not has_odometry(log):
        return "none in the log: laser odometry (scan matching)"
    if written is not None and never_moves(written):
        if moving_stream(log):
            return "the odometry messages at the scans' times (the scans' poses never move)"
        return "the scans' poses never move: laser odometry (scan matching)"
    if log.encoders is not None:
        return "encoders + IMU"
    if written is None:
        return "the odometry messages at the scans' times"
    if log.odometry is not None:
        return "the poses written with the scans, or the odometry messages (robot.odometry_sync)"
    return "the poses written with the scans"


def _clock(seconds: float) -> str:
    """Seconds, with the UTC date when they look like Unix time (CARMEN clocks start near 0)."""
    if seconds < 3e8:
        return f"{seconds:.3f}"
    try:
        stamp = datetime.fromtimestamp(seconds, UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    except (OverflowError, OSError, ValueError):
        return f"{seconds:.3f}"
    return f"{seconds:.3f} ({stamp})"


def format_inspection(report: dict[str, Any]) -> str:
    """The human-readable form of an :func:`inspect_path` report."""
    name = FORMAT_NAMES.get(report["format"], report["format"])
    lines = [f"{report['path']}: {name}"]
    if "topics" in report:
        lines.append(
            f"time span: {report['duration_s']:.3f} s, from {_clock(report['start_s'])} "
            f"to {_clock(report['end_s'])}; {report['messages']} messages"
        )
        lines.append("topics:")
        width = max((len(t["topic"]) for t in report["topics"]), default=5)
        twidth = max((len(t["type"]) for t in report["topics"]), default=4)
        for t in report["topics"]:
            lines.append(
                f"  {t['topic']:<{width}}  {t['type']:<{twidth}}  {t['count']:>7} msgs  "
                f"{t['rate_hz']:8.2f} Hz"
            )
        lines.append("tf frames:")
        if not report["tf"]:
            lines.append("  (none)")
        for e in report["tf"]:
            kind = "tf_static" if e["static"] else "tf"
            lines.append(f"  {e['parent']} -> {e['child']}  ({kind}, {e['count']} transforms)")
    else:
        lines.append("streams:")
        for stream, info in report["streams"].items():
            extra = f", {beams_text(info)}" if "beams" in info else ""
            if info.get("count"):
                lines.append(
                    f"  {stream:<10} {info['count']:>7} readings  {info['duration_s']:9.2f} s  "
                    f"{info['rate_hz']:7.2f} Hz{extra}"
                )
            else:
                lines.append(f"  {stream:<10} 0 readings")
    run = report["run"]
    if run.get("command"):
        if "scan_topic" in run:
            kind = (
                " (MultiEchoLaserScan: first echoes)"
                if "MultiEcho" in run.get("scan_type", "")
                else ""
            )
            reads = f"scans {run['scan_topic']}{kind}, odometry {run['odom_source']}"
            if "imu_topic" in run:
                gyro = (
                    " (its gyro turns the laser odometry)" if "laser" in run["odom_source"] else ""
                )
                reads += f", IMU {run['imu_topic']}{gyro}"
            lines.append(f"slam run reads: {reads}")
        elif "odometry" in run:
            lines.append(f"slam run reads: odometry {run['odometry']}")
        lines.append(f"run it: {run['command']}")
    else:
        lines.append(f"slam run cannot use it as it is: {run['error']}")
    return "\n".join(lines) + "\n"
