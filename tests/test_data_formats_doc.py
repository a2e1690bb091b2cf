"""docs/data-formats.md states the constants the code uses: the ECE276A keys, the robot, the
Kinect, the CARMEN defaults, map_server thresholds and the matching tolerances."""

from __future__ import annotations

import math
import re
from pathlib import Path

from slam.config import LidarConfig, RobotConfig, TextureConfig
from slam.eval.relations import DEFAULT_TOLERANCE_S
from slam.io import carmen, ece276a, mapserver, tum
from slam.io.rosbag import MAX_TILT_DEG, STANDARD_GRAVITY
from slam.kinect import KinectModel

DOC = (Path(__file__).resolve().parent.parent / "docs" / "data-formats.md").read_text()


def section(number: str) -> str:
    """The text of ``## number.`` / ``### number`` up to the next heading of any level."""
    (body,) = re.findall(rf"^#+ {re.escape(number)}[. ].*?\n(.*?)(?=^#)", DOC + "\n#", re.M | re.S)
    return body


def short(value: float) -> str:
    """``1e-3`` for 0.001: how the page writes tolerances."""
    return f"{value:.0e}".replace("e-0", "e-")


def test_ece276a_table_lists_every_key_of_the_loader():
    rows = [line.split(" | ") for line in section("1.1").splitlines() if line.startswith("| ")]
    documented: dict[str, set[str]] = {}
    current = ""
    for cells in rows[1:]:  # rows[0] is the header
        current = cells[0].strip("| `") or current
        for key in re.findall(r"`(\w+)`", cells[1]):
            documented.setdefault(current, set()).add(key)
    expected = {
        spec.pattern.replace("{nn}", "NN"): {k.key for k in spec.keys}
        for spec in ece276a.SPECS.values()
    }
    assert documented == expected
    for spec in ece276a.SPECS.values():
        low, high = spec.rate_hz
        assert f"{low:g}–{high:g} Hz" in section("1.1"), spec.stream
    assert f"within {short(ece276a.ANGLE_TOLERANCE)} rad" in section("1.1")


def test_robot_and_lidar_constants():
    robot, lidar = RobotConfig(), LidarConfig()
    text = section("1.3")
    assert math.isclose(robot.meters_per_tick, math.pi * 0.254 / 360)
    assert f"= {robot.meters_per_tick:.7f} m" in text
    assert f"= {robot.track_width} m" in text
    assert f"`lidar.x = {lidar.x}`" in text and lidar.y == 0.0 and lidar.yaw == 0.0
    assert f"low-passed at {robot.imu_lowpass_hz:g} Hz" in text
    assert f"`robot.max_imu_gap_s` ({robot.max_imu_gap_s} s)" in text


def test_kinect_constants():
    k, texture = KinectModel(), TextureConfig()
    text = section("1.4")
    assert f"Focal length {k.fx} px" in text and k.fx == k.fy
    assert f"column {k.cx}, row {k.cy}" in text
    assert f"`dd = {k.disparity_scale} · d + {k.disparity_offset}`" in text.replace("−", "-")
    assert f"`depth = {k.depth_numerator} / dd`" in text
    rgb = f"(526.37 · i + {k.rgb_row_offset:g} − {k.rgb_row_dd} · dd) / {k.rgb_norm}"
    assert k.rgb_gain == 526.37 and rgb in text
    assert f"(526.37 · j + {k.rgb_col_offset:g}) / {k.rgb_norm}" in text
    assert f"{k.invalid_disparity} gives" in text
    assert f"measures {k.min_depth}–{k.max_depth:g} m" in text
    assert f"uses {texture.min_depth}–{texture.max_depth:g} m" in text
    pose = (texture.camera_x, texture.camera_y, texture.camera_z)
    assert pose == (k.x, k.y, k.z) and f"({k.x}, {k.y}, {k.z}) m" in text
    assert f"pitch {k.pitch} rad" in text and f"yaw {k.yaw} rad" in text and k.roll == 0.0
    assert f"`texture.floor_height` ({texture.floor_height} m)" in text
    assert f"`texture.pair_tolerance_s` ({texture.pair_tolerance_s} s)" in section("1.2")


def test_carmen_map_and_matching_constants():
    text = section("2")
    assert f"more\nthan {carmen.MAX_BEAMS} readings" in text
    assert f"`lidar.range_min` ({carmen.DEFAULT_RANGE_MIN} m)" in text
    assert f"no return at {carmen.DEFAULT_NO_RETURN:g} m" in text
    assert carmen.DEFAULT_FOV_DEG == 180.0 and "(180° for every log here)" in text
    assert f"within {short(DEFAULT_TOLERANCE_S)} s" in section("3")
    assert f"norm within {short(tum.QUATERNION_TOLERANCE)} of 1" in section("4")
    yaml = mapserver.map_yaml_text("map.pgm", 0.05, (1.0, 2.0, 0.0))
    keys = [line.split(":")[0] for line in yaml.splitlines()]
    documented = re.search(r"```yaml\n(.*?)```", section("5"), re.S)[1]
    assert [line.split(":")[0] for line in documented.splitlines()] == keys
    assert f"occupied_thresh: {mapserver.OCCUPIED_THRESH}" in documented
    assert f"free_thresh: {mapserver.FREE_THRESH}" in documented
    pixels = (mapserver.OCCUPIED_PIXEL, mapserver.FREE_PIXEL, mapserver.UNKNOWN_PIXEL)
    assert "{} occupied,\n{} free, {} unknown".format(*pixels) in section("5")
    assert f"tilted more than {MAX_TILT_DEG:g}°" in section("7")
    assert f"({STANDARD_GRAVITY} m/s²)" in section("7")
