"""The ECE276A loader: real files (counts, rates, durations) and every kind of bad input."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from slam.config import LidarConfig
from slam.errors import DataError, UsageError
from slam.io.ece276a import load_ece276a, read_npz, rgbd_dirs, stream_file

T0 = 1298445274.5
ANGLE_MIN = -2.356194490192345
ANGLE_MAX = 2.356194490192345
ANGLE_INCREMENT = (ANGLE_MAX - ANGLE_MIN) / 1080


# --- synthetic files in the documented format (docs/data-formats.md §1.1) -----------------


def write_encoders(folder: Path, nn: int = 20, n: int = 200, rate: float = 40.0, **keys) -> Path:
    """EncodersNN.npz: counts int16 (4, N), time_stamps float64 (N,)."""
    folder.mkdir(parents=True, exist_ok=True)
    data = {
        "counts": np.tile(np.array([[3], [2], [3], [2]], dtype=np.int16), (1, n)),
        "time_stamps": T0 + np.arange(n) / rate,
    }
    data.update(keys)
    path = folder / f"Encoders{nn}.npz"
    np.savez(path, **data)
    return path


def write_imu(folder: Path, nn: int = 20, n: int = 500, rate: float = 100.0, **keys) -> Path:
    """ImuNN.npz: angular_velocity (3, N), linear_acceleration (3, N), time_stamps (N,)."""
    folder.mkdir(parents=True, exist_ok=True)
    angular = np.zeros((3, n))
    angular[2] = 0.25
    data = {
        "angular_velocity": angular,
        "linear_acceleration": np.tile([[0.0], [0.0], [1.0]], (1, n)),
        "time_stamps": T0 + 0.2 + np.arange(n) / rate,
    }
    data.update(keys)
    path = folder / f"Imu{nn}.npz"
    np.savez(path, **data)
    return path


def write_hokuyo(
    folder: Path, nn: int = 20, n: int = 30, rate: float = 40.0, ranges=None, **keys
) -> Path:
    """HokuyoNN.npz exactly as documented: angle_* and range_* with shape (1, 1), ranges
    (1081, N) float32 metres, time_stamps (N,)."""
    folder.mkdir(parents=True, exist_ok=True)
    if ranges is None:
        ranges = np.full((1081, n), 5.0, dtype=np.float32)
        ranges += np.arange(1081, dtype=np.float32)[:, None] * 0.001
    data = {
        "angle_min": np.array([[ANGLE_MIN]]),
        "angle_max": np.array([[ANGLE_MAX]]),
        "angle_increment": np.array([[ANGLE_INCREMENT]]),
        "range_min": np.array([[0.1]]),
        "range_max": np.array([[30.0]]),
        "ranges": ranges,
        "time_stamps": T0 + 0.1 + np.arange(n) / rate,
    }
    data.update(keys)
    path = folder / f"Hokuyo{nn}.npz"
    np.savez(path, **data)
    return path


def write_kinect(folder: Path, nn: int = 20, rgb: int = 12, disparity: int = 14) -> Path:
    """KinectNN.npz: disparity_time_stamps (D,), rgb_time_stamps (R,)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"Kinect{nn}.npz"
    np.savez(
        path,
        disparity_time_stamps=T0 + 1 + np.arange(disparity) / 20.0,
        rgb_time_stamps=T0 + 1.01 + np.arange(rgb) / 19.0,
    )
    return path


# --- real files -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "nn, encoders, imu, disparity, rgb, enc_duration, imu_duration",
    [
        (20, 4956, 12187, 2407, 2289, 123.637, 121.932),
        (21, 4789, 11730, 2188, 2112, 119.403, 117.358),
        (23, 3809, 9416, None, None, 94.963, 94.205),
    ],
)
def test_real_logs_counts_rates_durations(
    ece276a_dir, nn, encoders, imu, disparity, rgb, enc_duration, imu_duration
):
    log = load_ece276a(ece276a_dir, nn)
    assert log.name == f"dataset{nn}" and log.kind == "ece276a"
    assert log.encoders.counts.shape == (4, encoders)
    assert log.encoders.counts.dtype == np.int16
    assert log.imu.angular_velocity.shape == (3, imu)
    summary = log.summary()
    assert summary["encoders"]["count"] == encoders
    assert summary["imu"]["count"] == imu
    assert summary["encoders"]["duration_s"] == pytest.approx(enc_duration, abs=1e-3)
    assert summary["imu"]["duration_s"] == pytest.approx(imu_duration, abs=1e-3)
    assert summary["encoders"]["rate_hz"] == pytest.approx(40.0, rel=0.005)
    assert summary["imu"]["rate_hz"] == pytest.approx(100.0, rel=0.002)
    # The IMU stops 1.4-1.8 s before the encoders (docs/data-formats.md §1.1): never extrapolated
    # silently.
    assert 1.4 < log.meta["imu_ends_early_s"] < 1.8
    assert log.meta["encoders_non_monotonic"] == 0 and log.meta["imu_non_monotonic"] == 0
    assert log.scans is None  # Hokuyo files are absent from the shared data
    if disparity is None:
        assert log.rgbd is None and "rgbd_images" not in log.meta
    else:
        assert summary["disparity"]["count"] == disparity
        assert summary["rgb"]["count"] == rgb
        rgb_dir, disparity_dir = rgbd_dirs(ece276a_dir, nn)
        assert log.meta["rgbd_images"] == f"missing: {rgb_dir}/, {disparity_dir}/"
        assert log.rgbd.rgb_path(0) == ece276a_dir / f"dataRGBD/RGB{nn}/rgb{nn}_1.png"
        assert log.rgbd.disparity_path(disparity - 1) == (
            ece276a_dir / f"dataRGBD/Disparity{nn}/disparity{nn}_{disparity}.png"
        )


def test_real_encoder_ticks_match_the_published_file(ece276a_dir):
    log = load_ece276a(ece276a_dir, "20", need=("encoders",))
    # Fixed figures of Encoders20.npz: total ticks per wheel over the run.
    raw = np.load(ece276a_dir / "Encoders20.npz", allow_pickle=False)
    np.testing.assert_array_equal(log.encoders.counts, raw["counts"])
    assert log.encoders.time[0] == pytest.approx(1298445274.541885)


def test_missing_hokuyo_names_file_keys_and_where_to_put_it(ece276a_dir):
    with pytest.raises(DataError) as info:
        load_ece276a(ece276a_dir, 20, need=("encoders", "imu", "scans"))
    message = str(info.value)
    assert f"missing {ece276a_dir / 'Hokuyo20.npz'} " in message
    assert "ranges float (1081, N)" in message
    assert "angle_increment float (1, 1)" in message
    assert "time_stamps float64 (N,)" in message
    assert "--data-dir" in message and "SLAM_DATA_DIR" in message
    assert "ece276a/Hokuyo20.npz" in message
    assert "Encoders20" not in message  # only what is missing is named


# --- synthetic logs ---------------------------------------------------------------------------


def test_synthetic_log_loads_every_stream(tmp_path):
    write_encoders(tmp_path)
    write_imu(tmp_path)
    write_hokuyo(tmp_path, n=30)
    write_kinect(tmp_path)
    log = load_ece276a(tmp_path, 20, need=("encoders", "imu", "scans", "kinect"), name="synth")
    assert log.name == "synth" and log.source == tmp_path
    scans = log.scans
    assert scans.ranges.shape == (30, 1081) and scans.ranges.dtype == np.float32
    assert scans.ranges[0, 0] == pytest.approx(5.0) and scans.ranges[7, 1080] == pytest.approx(6.08)
    assert scans.angles.shape == (1081,)
    assert scans.angles[0] == pytest.approx(ANGLE_MIN)
    assert scans.angles[540] == pytest.approx(0.0, abs=1e-12)
    assert scans.angles[-1] == pytest.approx(ANGLE_MAX)
    assert (scans.range_min, scans.range_max, scans.no_return) == (0.1, 30.0, 30.0)
    np.testing.assert_allclose(scans.laser_offset, [0.13323, 0.0, 0.0])
    assert scans.invalid_beams == 0 and scans.non_monotonic == 0
    summary = log.summary()
    assert summary["scans"]["count"] == 30
    assert summary["scans"]["rate_hz"] == pytest.approx(40.0)
    assert summary["scans"]["duration_s"] == pytest.approx(29 / 40)
    assert summary["rgb"]["count"] == 12 and summary["disparity"]["count"] == 14
    assert log.meta["imu_ends_early_s"] == pytest.approx((199 / 40) - (0.2 + 499 / 100))


def test_hokuyo_scalars_may_be_zero_dimensional(tmp_path):
    write_hokuyo(tmp_path, angle_min=np.float64(ANGLE_MIN), range_max=np.array(25.0))
    log = load_ece276a(tmp_path, 20, need=("scans",))
    assert log.scans.angles[0] == pytest.approx(ANGLE_MIN)
    assert log.scans.range_max == 25.0 and log.scans.no_return == 25.0


def test_lidar_config_overrides_offset_and_range_semantics(tmp_path):
    write_hokuyo(tmp_path)
    lidar = LidarConfig(x=0.2, y=-0.01, yaw=0.05, range_min=0.5, no_return=25.0)
    scans = load_ece276a(tmp_path, 20, need=("scans",), lidar=lidar).scans
    np.testing.assert_allclose(scans.laser_offset, [0.2, -0.01, 0.05])
    assert (scans.range_min, scans.range_max, scans.no_return) == (0.5, 30.0, 25.0)


def test_invalid_ranges_become_nan_and_are_counted(tmp_path):
    ranges = np.full((1081, 4), 2.0, dtype=np.float32)
    ranges[0, 0] = np.nan
    ranges[1, 0] = np.inf
    ranges[2, 1] = -np.inf
    ranges[3, 1] = -1.0
    ranges[4, 2] = 0.05  # below range_min 0.1
    ranges[5, 2] = 0.1  # exactly range_min: valid
    ranges[6, 3] = 30.0  # range_max: valid, counts as "no return"
    ranges[7, 3] = 42.0  # beyond range_max: kept, "no return"
    write_hokuyo(tmp_path, n=4, ranges=ranges)
    log = load_ece276a(tmp_path, 20, need=("scans",))
    scans = log.scans
    assert scans.invalid_beams == 5
    assert np.isnan(scans.ranges).sum() == 5
    assert np.isnan(scans.ranges[[0, 0, 1, 1, 2], [0, 1, 2, 3, 4]]).all()
    assert scans.ranges[2, 5] == pytest.approx(0.1)
    assert scans.ranges[3, 7] == 42.0
    summary = log.summary()["scans"]
    assert summary["invalid_beams"] == 5 and summary["no_return_beams"] == 2


def test_non_monotonic_timestamps_are_counted_not_fatal(tmp_path):
    time = T0 + np.arange(30) / 40.0
    time[[10, 20]] = time[[10, 20]] - 0.1  # two scans stamped before their predecessor
    write_hokuyo(tmp_path, time_stamps=time)
    enc_time = T0 + np.arange(200) / 40.0
    enc_time[50] -= 0.5
    write_encoders(tmp_path, time_stamps=enc_time)
    log = load_ece276a(tmp_path, 20, need=("scans", "encoders"))
    assert log.scans.non_monotonic == 2
    assert log.meta["encoders_non_monotonic"] == 1
    np.testing.assert_array_equal(log.scans.time, time)  # file order is kept


def test_rgbd_images_present_incomplete_and_lazy(tmp_path):
    import cv2

    write_kinect(tmp_path, rgb=3, disparity=2)
    rgb_dir, disparity_dir = rgbd_dirs(tmp_path, 20)
    rgb_dir.mkdir(parents=True)
    disparity_dir.mkdir(parents=True)
    image = np.zeros((480, 640, 3), dtype=np.uint8)
    image[:, :, 2] = 200  # red in OpenCV's BGR order
    for k in (1, 2, 3):
        cv2.imwrite(str(rgb_dir / f"rgb20_{k}.png"), image)
    cv2.imwrite(str(disparity_dir / "disparity20_1.png"), np.full((480, 640), 700, np.uint16))
    log = load_ece276a(tmp_path, 20, need=("kinect",))
    assert log.meta["rgbd_images"] == f"incomplete: {disparity_dir}/ holds 1 of 2 frames"
    cv2.imwrite(str(disparity_dir / "disparity20_2.png"), np.full((480, 640), 701, np.uint16))
    log = load_ece276a(tmp_path, 20, need=("kinect",))
    assert log.meta["rgbd_images"] == "present"
    assert log.rgbd.load_rgb(2)[0, 0].tolist() == [200, 0, 0]  # RGB order
    assert int(log.rgbd.load_disparity(1)[5, 5]) == 701


def test_only_needed_streams_must_exist(tmp_path):
    write_encoders(tmp_path)
    log = load_ece276a(tmp_path, 20, need=("encoders",))
    assert log.imu is None and log.scans is None and log.rgbd is None
    with pytest.raises(DataError, match=r"missing .*Imu20\.npz \(Imu20\.npz holds IMU readings"):
        load_ece276a(tmp_path, 20)


def test_missing_streams_are_reported_in_one_error(tmp_path):
    with pytest.raises(DataError) as info:
        load_ece276a(tmp_path / "ece276a", 21, need=("encoders", "imu", "scans"))
    message = str(info.value)
    assert message.startswith("dataset21: missing ")
    for name in ("Encoders21.npz", "Imu21.npz", "Hokuyo21.npz"):
        assert str(tmp_path / "ece276a" / name) in message
    assert "Put the files there" in message


def test_unknown_stream_and_bad_number_are_usage_errors(tmp_path):
    with pytest.raises(UsageError, match="unknown ECE276A stream.*lidar"):
        load_ece276a(tmp_path, 20, need=("lidar",))
    with pytest.raises(UsageError, match="dataset number '../20'"):
        load_ece276a(tmp_path, "../20")


def test_stream_file_names():
    assert stream_file(Path("d"), 20, "scans") == Path("d/Hokuyo20.npz")
    assert stream_file(Path("d"), "23", "kinect") == Path("d/Kinect23.npz")


# --- bad files --------------------------------------------------------------------------------


def test_empty_file(tmp_path):
    (tmp_path / "Encoders20.npz").write_bytes(b"")
    with pytest.raises(DataError, match=r"Encoders20\.npz: file is empty"):
        load_ece276a(tmp_path, 20, need=())


@pytest.mark.parametrize("keep", [0.05, 0.3, 0.6, 0.95])
def test_truncated_file(tmp_path, keep):
    path = write_imu(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(DataError, match=r"Imu20\.npz: .*(not a readable npz|truncated)"):
        load_ece276a(tmp_path, 20, need=())


def test_garbage_and_npy_instead_of_npz(tmp_path):
    (tmp_path / "Encoders20.npz").write_bytes(b"this is not a zip archive at all" * 10)
    with pytest.raises(DataError, match=r"Encoders20\.npz: not a readable npz archive"):
        load_ece276a(tmp_path, 20, need=())
    with open(tmp_path / "Encoders20.npz", "wb") as fh:
        np.save(fh, np.zeros(3))
    with pytest.raises(DataError, match="expected an npz archive.*single .npy array"):
        load_ece276a(tmp_path, 20, need=())


def test_pickled_npz_is_refused(tmp_path):
    np.savez(
        tmp_path / "Encoders20.npz",
        counts=np.array([{"ticks": 1}, None], dtype=object),
        time_stamps=np.arange(3.0),
    )
    with pytest.raises(DataError, match="contains pickled objects; refusing to load"):
        load_ece276a(tmp_path, 20, need=())


def test_pickle_file_is_refused(tmp_path):
    import pickle

    (tmp_path / "Kinect20.npz").write_bytes(pickle.dumps({"rgb_time_stamps": [1.0]}))
    with pytest.raises(DataError, match=r"Kinect20\.npz: contains pickled objects"):
        load_ece276a(tmp_path, 20, need=())


def test_missing_key_names_key_and_keys_found(tmp_path):
    np.savez(tmp_path / "Encoders20.npz", time_stamps=T0 + np.arange(10) / 40, ticks=np.zeros(3))
    with pytest.raises(DataError, match="missing key 'counts'; found keys: 'time_stamps', 'ticks'"):
        load_ece276a(tmp_path, 20, need=())


@pytest.mark.parametrize(
    "writer, keys, message",
    [
        (
            write_encoders,
            {"counts": np.zeros((3, 200), np.int16)},
            r"'counts' must have shape \(4, N\) with N = 200 \(the length of 'time_stamps'\), found \(3, 200\)",
        ),
        (
            write_encoders,
            {"counts": np.zeros((4, 199), np.int16)},
            r"'counts' must have shape \(4, N\) with N = 200",
        ),
        (
            write_encoders,
            {"time_stamps": np.zeros((2, 200))},
            r"'time_stamps' must have shape \(N,\), found \(2, 200\)",
        ),
        (
            write_imu,
            {"angular_velocity": np.zeros((500, 3))},
            r"'angular_velocity' must have shape \(3, N\) with N = 500 \(the length of 'time_stamps'\), found \(500, 3\)",
        ),
        (
            write_hokuyo,
            {"ranges": np.ones((30, 1081), np.float32)},
            r"'ranges' must have shape \(beams, N\) = \(1081, N\) with N = 30 \(the length of 'time_stamps'\), found \(30, 1081\)",
        ),
        (
            write_hokuyo,
            {"angle_min": np.array([ANGLE_MIN, 0.0])},
            r"'angle_min' must be a single number .* found shape \(2,\)",
        ),
        (
            write_hokuyo,
            {"ranges": np.ones((1000, 30), np.float32)},
            r"beam geometry does not match.*expected 1081 beams, found 1000",
        ),
        (write_hokuyo, {"angle_max": np.array([[2.0]])}, r"angle_max = 2\.000000 rad"),
        (
            write_hokuyo,
            {"angle_increment": np.array([[0.0]])},
            "'angle_increment' must be positive",
        ),
        (write_hokuyo, {"range_min": np.array([[40.0]])}, r"range_min = 40\.0, range_max = 30\.0"),
        (
            write_encoders,
            {"time_stamps": np.array([], dtype=np.float64), "counts": np.zeros((4, 0), np.int16)},
            "'time_stamps' is empty",
        ),
    ],
)
def test_wrong_shapes(tmp_path, writer, keys, message):
    writer(tmp_path, **keys)
    with pytest.raises(DataError, match=message):
        load_ece276a(tmp_path, 20, need=())


@pytest.mark.parametrize(
    "writer, keys, message",
    [
        (
            write_encoders,
            {"counts": np.ones((4, 200), np.float64)},
            "'counts' must be integer encoder ticks .int16., found dtype float64",
        ),
        (
            write_encoders,
            {"counts": np.full((4, 200), 70000, np.int32)},
            "'counts' holds values outside int16",
        ),
        (
            write_encoders,
            {"time_stamps": np.array(["t"] * 200)},
            "'time_stamps' must be numeric .float64 seconds., found dtype <U1",
        ),
        (
            write_imu,
            {"linear_acceleration": np.full((3, 500), "1")},
            "'linear_acceleration' must be numeric",
        ),
        (write_hokuyo, {"ranges": np.full((1081, 30), True)}, "'ranges' must be numeric"),
        (write_hokuyo, {"range_max": np.array([["30"]])}, "'range_max' must be numeric"),
        (write_kinect, None, None),
    ],
)
def test_wrong_dtypes(tmp_path, writer, keys, message):
    if keys is None:  # complex timestamps are not real seconds
        np.savez(
            tmp_path / "Kinect20.npz",
            disparity_time_stamps=np.arange(5) + 0j,
            rgb_time_stamps=np.arange(5.0),
        )
        message = "'disparity_time_stamps' must be numeric"
    else:
        writer(tmp_path, **keys)
    with pytest.raises(DataError, match=message):
        load_ece276a(tmp_path, 20, need=())


def test_non_finite_and_implausible_timestamps(tmp_path):
    time = T0 + np.arange(500) / 100.0
    time[7] = np.nan
    write_imu(tmp_path, time_stamps=time)
    with pytest.raises(DataError, match="1 non-finite timestamp.*first at index 7"):
        load_ece276a(tmp_path, 20, need=())
    write_imu(tmp_path, time_stamps=(T0 + np.arange(500) / 100.0) * 1000)  # milliseconds
    with pytest.raises(DataError, match=r"implies 0\.1 Hz readings, expected 10-2000 Hz"):
        load_ece276a(tmp_path, 20, need=())
    write_imu(tmp_path, angular_velocity=np.full((3, 500), np.inf))
    with pytest.raises(DataError, match="'angular_velocity' has 1500 non-finite"):
        load_ece276a(tmp_path, 20, need=())


def test_read_npz_reads_only_the_asked_keys(tmp_path):
    path = write_encoders(tmp_path, extra=np.array([1, 2, 3]))
    out = read_npz(path, ["counts"])
    assert list(out) == ["counts"] and out["counts"].shape == (4, 200)


def _unreadable(folder: Path) -> None:
    folder.chmod(0)
    if os.access(folder, os.R_OK):
        folder.chmod(0o755)
        pytest.skip("running as root: chmod 000 does not make a folder unreadable")


def test_unreadable_folder(tmp_path):
    folder = tmp_path / "ece276a"
    write_encoders(folder)
    _unreadable(folder)
    try:
        with pytest.raises(DataError, match=f"{folder}: cannot read the ECE276A data folder"):
            load_ece276a(folder, 20)
    finally:
        folder.chmod(0o755)


def test_unreadable_folder_without_permission_bits(tmp_path, monkeypatch):
    # The same check as above, for machines where tests run as root (os.access is what it asks).
    folder = tmp_path / "ece276a"
    write_encoders(folder)
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode: False if Path(p) == folder else real_access(p, mode)
    )
    with pytest.raises(
        DataError, match=f"{folder}: cannot read the ECE276A data folder .permission denied."
    ):
        load_ece276a(folder, 20)


def test_unreadable_file(tmp_path):
    path = write_encoders(tmp_path)
    path.chmod(0)
    if os.access(path, os.R_OK):
        pytest.skip("running as root: chmod 000 does not make a file unreadable")
    try:
        with pytest.raises(DataError, match=r"Encoders20\.npz: cannot read .permission denied."):
            load_ece276a(tmp_path, 20, need=())
    finally:
        path.chmod(0o644)


def test_a_file_where_the_folder_should_be(tmp_path):
    (tmp_path / "ece276a").write_text("not a folder")
    with pytest.raises(DataError, match="expected the ECE276A data folder, found a file"):
        load_ece276a(tmp_path / "ece276a", 20)


# --- units a student's own recording may be in ---------------------------------------------


def test_hokuyo_in_millimetres_or_degrees_is_named(tmp_path):
    """The bugs: ranges in millimetres loaded as scans of "no return" readings (a run then made
    an empty map, exit 0), a range_max in millimetres ended in a 32.7 TiB memory refusal, and
    angles in degrees reached the scans unnamed."""
    write_hokuyo(tmp_path / "mm", ranges=np.full((1081, 30), 5000.0, dtype=np.float32))
    with pytest.raises(DataError) as caught:
        load_ece276a(tmp_path / "mm", 20, need=("scans",))
    assert str(caught.value) == (
        f"{tmp_path / 'mm' / 'Hokuyo20.npz'}: key 'ranges': the median reading is 5000, 167 times "
        "range_max = 30 m: expected metres (millimetres? divide by 1000)"
    )
    write_hokuyo(tmp_path / "mm2", range_max=np.array([[30000.0]]))
    with pytest.raises(
        DataError, match=r"key 'range_max': expected metres \(at most 1000\), found 30000"
    ):
        load_ece276a(tmp_path / "mm2", 20, need=("scans",))
    degrees = {"angle_min": np.array([[-135.0]]), "angle_max": np.array([[135.0]]),
               "angle_increment": np.array([[0.25]])}  # fmt: skip
    write_hokuyo(tmp_path / "deg", **degrees)
    with pytest.raises(
        DataError,
        match=r"Hokuyo20.npz: keys 'angle_min', 'angle_max': expected radians spanning at most 2π, found -135 .. 135 \(degrees\?",
    ):
        load_ece276a(tmp_path / "deg", 20, need=("scans",))


def test_a_gyro_in_degrees_per_second_is_named(tmp_path):
    """The bug: a gyro read in deg/s was taken as rad/s: the run turned 57 times too far and
    exited 0 without a warning. The wheels turn 0.5 rad/s here."""
    from slam.config import load_config
    from slam.io.plausibility import check_plausibility

    config = load_config("")
    n = 800  # 20 s of encoders turning on the spot, right wheels forward, left back
    ticks = round(0.25 * config.robot.track_width / 40 / config.robot.meters_per_tick)
    counts = np.tile(np.array([[ticks], [-ticks], [ticks], [-ticks]], dtype=np.int16), (1, n))
    write_encoders(tmp_path, n=n, counts=counts)
    for rate, refused in ((0.5, False), (np.degrees(0.5), True)):  # rad/s, then deg/s
        angular = np.zeros((3, 2100))
        angular[2] = rate
        write_imu(tmp_path, n=2100, angular_velocity=angular)
        log = load_ece276a(tmp_path, 20, need=("encoders", "imu"))
        if not refused:
            check_plausibility(log, config)
            continue
        with pytest.raises(
            DataError,
            match=r"Imu20.npz: key 'angular_velocity': the gyro turns the robot \d+ times as far as its wheels .* expected rad/s \(degrees per second",
        ):
            check_plausibility(log, config)


def test_kinect_times_matter_only_to_a_run_that_makes_a_texture(tmp_path):
    """The bug: Kinect time stamps on another clock stopped `slam run --no-texture` (and dead
    reckoning), which never read them."""
    from slam.config import load_config
    from slam.io.plausibility import check_plausibility

    write_encoders(tmp_path)
    write_imu(tmp_path)
    path = write_kinect(tmp_path)
    with np.load(path) as k:
        shifted = {name: k[name] + 1000.0 for name in k.files}
    np.savez(path, **shifted)
    log = load_ece276a(tmp_path, 20, need=("encoders", "imu", "kinect"))
    with pytest.raises(DataError, match="Kinect20.npz: key 'rgb_time_stamps'"):
        check_plausibility(log, load_config(""))
    assert check_plausibility(log, load_config("", overrides=["texture.enabled=false"])) == []
