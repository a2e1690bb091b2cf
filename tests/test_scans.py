"""Scans as the filter sees them: the Scan value, its defaults, the growing ScanSequence."""

from __future__ import annotations

import numpy as np
import pytest

from slam.config import LidarConfig
from slam.errors import DataError, UsageError
from slam.scans import Scan, ScanSequence, nominal_scan_period

LIDAR = LidarConfig(x=0.1, y=0.0, yaw=0.0, range_min=0.2, range_max=5.0, no_return=8.0)


def test_scan_from_angle_range_and_validation():
    scan = Scan.from_angle_range(3.0, [1.0, 2.0, 3.0], -0.5, 0.25)
    np.testing.assert_allclose(scan.angles, [-0.5, -0.25, 0.0])
    assert scan.ranges.dtype == np.float32 and scan.num_beams == 3
    with pytest.raises(DataError, match="3 ranges for 2 beam angles"):
        Scan(0.0, [1.0, 2.0, 3.0], [0.0, 0.1])
    with pytest.raises(DataError, match="time must be a finite number"):
        Scan(np.nan, [1.0], [0.0])
    with pytest.raises(DataError, match="laser_offset must be 3 finite numbers"):
        Scan(0.0, [1.0], [0.0], laser_offset=[0.0, 0.0])


def test_scan_keeps_a_copy_of_the_callers_arrays():
    ranges = np.array([1.0, 2.0])
    scan = Scan(0.0, ranges, np.zeros(2))
    ranges[:] = 9.0  # a driver reusing its buffer
    np.testing.assert_array_equal(scan.ranges, [1.0, 2.0])


def test_a_read_only_array_of_the_scans_dtype_is_kept_not_copied():
    """A read-only float32 ranges / float64 angles array (a log's own, shared by its scans) is
    kept as it is; one of another dtype is converted, a writeable one copied."""
    ranges = np.array([1.0, 2.0], dtype=np.float32)
    angles = np.array([0.0, 0.5])
    ranges.flags.writeable = angles.flags.writeable = False
    scan = Scan(0.0, ranges, angles)
    assert scan.ranges is ranges and scan.angles is angles
    as_f64 = ranges.astype(np.float64)
    as_f64.flags.writeable = False
    converted = Scan(0.0, as_f64, angles)
    assert converted.ranges.dtype == np.float32 and not np.shares_memory(converted.ranges, as_f64)


def test_the_scans_of_a_log_share_its_arrays_read_only():
    """LogScans gives each scan read-only views of the log's ranges and beam angles: no copy
    per scan (the demo's 4960 scans of 1081 beams held 64 MB of copies), and no way to change
    the log through a scan."""
    from slam.config import load_config
    from slam.io.log import Log, ScanStream
    from slam.scans import LogScans

    n, beams = 6, 30
    ranges = np.full((n, beams), 2.0, dtype=np.float32)
    angles = np.linspace(-1.0, 1.0, beams)
    odometry = np.c_[np.arange(n) * 0.1, np.zeros(n), np.zeros(n)]
    stream = ScanStream(np.arange(n, dtype=np.float64), ranges, angles, 0.1, 5.0, 8.0,
                        odometry=odometry)  # fmt: skip
    config = load_config("", None, ['robot.odometry_sync="scan"'])
    scans = LogScans.from_log(Log("t", "carmen", scans=stream), config)
    scan = scans.scan(3)
    assert np.shares_memory(scan.ranges, ranges) and np.shares_memory(scan.angles, angles)
    assert not scan.ranges.flags.writeable and not scan.angles.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        scan.ranges[0] = 1.0
    assert ranges.flags.writeable  # the log's own array is untouched
    np.testing.assert_array_equal(scan.ranges, ranges[3])


def test_resolved_fills_what_the_scan_leaves_out_from_the_lidar_section():
    scan = Scan(0.0, [1.0], [0.0], range_max=12.0).resolved(LIDAR)
    assert (scan.range_min, scan.range_max, scan.no_return) == (0.2, 8.0, 8.0)  # capped
    np.testing.assert_array_equal(scan.laser_offset, [0.1, 0.0, 0.0])
    bare = Scan(0.0, [1.0], [0.0]).resolved(LidarConfig(x=0.0))
    assert (bare.range_min, bare.range_max, bare.no_return) == (0.0, np.inf, np.inf)
    assert bare.resolved(LIDAR) is bare  # nothing left to fill
    with pytest.raises(UsageError, match="call scan.resolved"):
        Scan(0.0, [1.0], [0.0]).endpoints()


def test_hits_and_rays_follow_the_range_semantics():
    # beams: a hit straight ahead, one too short, one beyond range_max (free space only),
    # a "no return", and NaN
    ranges = [1.0, 0.1, 6.0, 8.0, np.nan]
    angles = [0.0, 0.0, np.pi / 2, np.pi, 0.0]
    scan = Scan(0.0, ranges, angles).resolved(LIDAR)
    ex, ey = scan.hits()
    np.testing.assert_allclose(ex, [1.1])  # 0.1 m laser offset ahead of the robot centre
    np.testing.assert_allclose(ey, [0.0], atol=1e-7)
    ends, hit = scan.rays(free_range_no_return=2.0)
    np.testing.assert_array_equal(hit, [True, False, False])
    np.testing.assert_allclose(ends, [[1.1, 0.0], [0.1, 5.0], [-1.9, 0.0]], atol=1e-6)
    ends, hit = scan.rays(free_range_no_return=0.0)  # "no return" clears nothing
    assert hit.tolist() == [True, False]


def test_the_ray_table_is_every_scans_rays_to_the_bit():
    """ScanSequence.ray_table (the final map's one pass over its scans) gives what Scan.rays
    gives scan by scan: scans of 7 to 12 beams with every kind of reading, their own limits and
    laser poses, a scan with no ray at all, with and without thinning."""
    rng = np.random.default_rng(11)
    seq = ScanSequence()
    for k in range(40):
        n = int(rng.integers(7, 13))
        ranges = rng.uniform(0.05, 10.0, n)
        ranges[rng.random(n) < 0.15] = np.nan
        ranges[rng.random(n) < 0.15] = 8.0  # "no return" under LIDAR
        if k == 17:
            ranges[:] = np.nan
        angles = np.sort(rng.uniform(-2.0, 2.0, n))
        own = {"range_max": 4.0, "laser_offset": rng.normal(0.0, 0.2, 3)} if k % 3 == 0 else {}
        seq.append(Scan(0.1 * k, ranges, angles, **own).resolved(LIDAR), [k, 0.0, 0.0])
    steps = np.array([3, 0, 17, 5, 5, *range(6, 40, 2)])
    for free, stride in ((2.0, 1), (0.0, 1), (3.0, 3)):
        ends, hit, offsets = seq.ray_table(steps, free, stride)
        assert offsets[0] == 0 and offsets[-1] == ends.shape[0] == hit.shape[0] > 100
        for i, k in enumerate(steps):
            want_ends, want_hit = seq.rays(int(k), free, stride)
            a, b = offsets[i], offsets[i + 1]
            assert ends[a:b].tobytes() == want_ends.tobytes()
            assert hit[a:b].tolist() == want_hit.tolist()
        assert offsets[3] == offsets[2]  # scan 17: no ray
    assert hit.any() and not hit.all()


def _scans_for_endpoints(seed: int) -> list[Scan]:
    """Scans of one laser (shared beam angles) and some of another (their own angles, width,
    limits or laser pose), with every kind of reading, ranges exactly at the limits among them."""
    rng = np.random.default_rng(seed)
    shared = np.linspace(-2.0, 2.0, 12)
    out = []
    for k in range(30):
        n = 12 if k % 5 else int(rng.integers(0, 15))
        ranges = rng.uniform(0.05, 10.0, n)
        ranges[rng.random(n) < 0.15] = np.nan
        ranges[rng.random(n) < 0.1] = 0.2  # exactly range_min: a return
        ranges[rng.random(n) < 0.1] = 5.0  # exactly range_max: not one
        angles = shared.copy() if n == 12 else np.sort(rng.uniform(-2.0, 2.0, n))
        own: dict = {"laser_offset": rng.normal(0.0, 0.2, 3)} if k % 7 == 3 else {}
        if k % 4 == 1:  # 5.1 as float32 is below 5.1: not a return, compared in float32
            own["range_max"] = 5.1
            ranges[rng.random(n) < 0.2] = 5.1
        out.append(Scan(0.1 * k, ranges, angles, **own).resolved(LIDAR))
    return out


def _endpoints_one_by_one(scan: Scan) -> tuple[np.ndarray, np.ndarray]:
    """Scan.endpoints as it was written before the batch formula: one scan, its limits as
    Python floats (numpy compares a float32 array with them in float32)."""
    r, a = scan.ranges, scan.angles
    ok = np.isfinite(r) & np.isfinite(a) & (r >= scan.range_min) & (r < scan.range_max)
    lx, ly, lt = scan.laser_offset
    rr = np.where(ok, r, np.nan).astype(np.float32)
    return (
        (lx + rr * np.cos(lt + a)).astype(np.float32),
        (ly + rr * np.sin(lt + a)).astype(np.float32),
    )


def test_the_endpoint_table_is_every_scans_endpoints_to_the_bit():
    """ScanSequence.endpoint_table (the registration's one pass over its scans) and
    Scan.endpoints give the endpoints of the one-scan formula, bit for bit, and the table
    leaves each scan its row: scans sharing their beam directions (computed once) and scans
    with their own, of other widths (none at all among them), some already computed before
    the call."""
    want = [_endpoints_one_by_one(scan) for scan in _scans_for_endpoints(5)]
    seq = ScanSequence()
    for k, scan in enumerate(_scans_for_endpoints(5)):
        seq.append(scan, [k, 0.0, 0.0])
    seq.scan(4).endpoints(), seq.scan(9).endpoints()  # known before: copied
    steps = np.array([4, 0, 1, 1, 5, 10, *range(11, 30), 9])
    ex, ey = seq.endpoint_table(steps)
    assert ex.dtype == ey.dtype == np.float32
    assert ex.shape == (len(steps), max(seq.scan(int(k)).num_beams for k in steps))
    for i, k in enumerate(steps):
        wx, wy = want[k]
        assert ex[i, : wx.size].tobytes() == wx.tobytes()
        assert ey[i, : wy.size].tobytes() == wy.tobytes()
        assert np.isnan(ex[i, wx.size :]).all() and np.isnan(ey[i, wy.size :]).all()
        got = seq.scan(int(k)).endpoints()  # the scan keeps the row (or its own)
        assert got[0].tobytes() == wx.tobytes() and got[1].tobytes() == wy.tobytes()
    assert np.isfinite(ex).sum() > 100 and np.isnan(ex[:, :12]).any()
    empty = seq.endpoint_table(np.array([], dtype=np.int64))
    assert empty[0].shape == (0, 0)


def test_scan_sequence_grows_and_keeps_every_scan():
    seq = ScanSequence(capacity=2)
    for k in range(5):
        scan = Scan(10.0 + 0.1 * k, [1.0, 2.0], [0.0, 0.5], index=100 + k).resolved(LIDAR)
        assert seq.append(scan, [k, 0.0, 0.0]) == k
    assert len(seq) == 5 and seq.num_beams == 2
    np.testing.assert_allclose(seq.times, 10.0 + 0.1 * np.arange(5))
    np.testing.assert_array_equal(seq.odometry[:, 0], np.arange(5))
    np.testing.assert_array_equal(seq.indices, 100 + np.arange(5))
    np.testing.assert_array_equal(seq.laser_offset, [0.1, 0.0, 0.0])
    assert seq.scan_period() == pytest.approx(0.1)
    np.testing.assert_allclose(seq.hits(3)[0], [1.1, 0.1 + 2.0 * np.cos(0.5)], rtol=1e-6)
    with pytest.raises(UsageError, match="resolve it"):
        seq.append(Scan(0.0, [1.0], [0.0]), [0.0, 0.0, 0.0])
    with pytest.raises(DataError, match="odometry must be a finite pose"):
        seq.append(Scan(0.0, [1.0], [0.0]).resolved(LIDAR), [0.0, np.nan, 0.0])


def test_nominal_scan_period_ignores_steps_back_in_time():
    assert nominal_scan_period([0.0, 0.1, 0.2, 0.15, 0.3, 0.4]) == pytest.approx(0.1)
    assert nominal_scan_period([1.0]) == 0.0


def test_readings_pad_the_scans_to_one_width_with_nan():
    """ScanSequence.readings: each scan's ranges and angles in its row, NaN beyond its beams,
    as wide as the widest scan asked for, or ``width`` when that is wider."""
    seq = ScanSequence()
    for k, n in enumerate((3, 5, 2)):
        ranges = np.arange(1.0, n + 1.0)
        seq.append(Scan(0.1 * k, ranges, np.linspace(-1.0, 1.0, n)).resolved(LIDAR), [k, 0, 0])
    r, a = seq.readings([2, 0])
    assert r.shape == a.shape == (2, 3) and r.dtype == a.dtype == np.float64
    assert r[0, :2].tolist() == [1.0, 2.0] and np.isnan(r[0, 2]) and np.isnan(a[0, 2])
    assert r[1].tolist() == [1.0, 2.0, 3.0] and a[1].tolist() == [-1.0, 0.0, 1.0]
    r, a = seq.readings([0], width=5)
    assert r.shape == (1, 5) and np.isnan(r[0, 3:]).all() and np.isnan(a[0, 3:]).all()
    assert seq.readings([], width=4)[0].shape == (0, 4)


def test_the_scans_of_one_laser_share_one_angle_array():
    """A driver's angles (a writable array, as np.linspace gives) are copied into each Scan; the
    sequence keeps one array for a run of equal ones: 8 bytes a reading otherwise (415 MB over
    a 20-minute log of 1081-beam scans)."""
    angles = np.linspace(-2.0, 2.0, 1081)
    seq = ScanSequence()
    for k in range(3):
        seq.append(Scan(0.1 * k, np.full(1081, 2.0), angles).resolved(LidarConfig()), np.zeros(3))
    seq.append(Scan(0.3, np.full(1081, 2.0), angles + 0.01).resolved(LidarConfig()), np.zeros(3))
    first = seq.scan(0).angles
    assert seq.scan(1).angles is first and seq.scan(2).angles is first
    assert seq.scan(3).angles is not first  # other beams keep their own
    np.testing.assert_array_equal(seq.scan(1).angles, angles)
    with pytest.raises(ValueError, match="read-only"):  # (review) no write reaches another scan
        seq.scan(2).angles[0] = 0.5
