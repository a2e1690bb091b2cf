"""Localization on a real log: intel's first 2500 scans (494 s) and the map ``slam run`` builds
from them. Tracking against the run's own accuracy, an initial pose 1 m and 20° off, global
localization from a few start times, a kidnapping, and determinism across thread counts."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from slam.config import load_config
from slam.geometry import relative
from slam.trajectory import Trajectory

SCANS = 2500


@pytest.fixture(scope="module")
def intel(carmen_dir, tmp_path_factory):
    """``(run folder, SLAM poses, LogScans, map)`` of intel's first scans."""
    import slam
    from slam.io import sources
    from slam.localize.maps import load_map
    from slam.scans import LogScans

    out = tmp_path_factory.mktemp("intel") / "run"
    result = slam.run(
        "intel", data_dir=carmen_dir.parent, out=out, max_scans=SCANS,
        overrides=["texture.enabled=false", "viz.record=false"],
    )  # fmt: skip
    config = load_config("intel", None, [f"filter.max_scans={SCANS}"])
    ref = sources.resolve("intel", carmen_dir.parent)
    scans = LogScans.from_log(sources.load(ref, config, ("scans",)).log, config)
    return out, result.trajectory.poses, scans, load_map(out)


def errors(poses, truth):
    e = relative(truth, poses)
    return np.hypot(e[:, 0], e[:, 1]), np.degrees(np.abs(e[:, 2]))


def localize(lmap, scans, first, stop, **kw):
    from slam.localize.localizer import Localizer
    from slam.localize.run import run_localizer

    localizer = Localizer(lmap, load_config("intel"), **kw)
    items = [(scans.scan(i), scans.odometry[i]) for i in range(first, stop)]
    return localizer, run_localizer(localizer, items)


def converged_at(trace, truth, hold_s=5.0):
    """Log time from the start after which the pose is localized and within 0.3 m / 5° for
    ``hold_s`` seconds (None if never)."""
    err, deg = errors(trace.poses, truth)
    good = trace.localized & (err <= 0.3) & (deg <= 5.0)
    for i in np.flatnonzero(good):
        ahead = trace.times <= trace.times[i] + hold_s
        ahead[:i] = False
        if good[ahead].all() and trace.times[-1] >= trace.times[i] + hold_s:
            return float(trace.times[i] - trace.times[0])
    return None


def test_tracking_is_as_accurate_as_the_slam_run(intel, carmen_dir):
    from slam.eval.relations import relation_errors
    from slam.io.relations import read_relations

    run, slam_poses, scans, lmap = intel
    _, trace = localize(lmap, scans, 0, SCANS, initial=(*slam_poses[0], 0.1))
    relations = read_relations(carmen_dir / "relations" / "intel.relations")
    ours = relation_errors(Trajectory(trace.times, trace.poses), relations)
    theirs = relation_errors(Trajectory(scans.times, slam_poses), relations)
    assert ours.count == theirs.count > 300  # the relations inside the first 494 s
    ratio = float(ours.trans.mean() / theirs.trans.mean())
    assert ratio <= 1.1, ratio
    assert float(np.degrees(ours.rot.mean())) <= 1.1 * float(np.degrees(theirs.rot.mean()))
    err, _ = errors(trace.poses, slam_poses)
    assert np.median(err) < 0.03
    assert trace.localized.mean() > 0.99 and not trace.lost.any()


@pytest.mark.parametrize("direction", [0, 1, 2, 3])
def test_initial_pose_off_by_1m_and_20deg_converges_within_10s(intel, direction):
    _, slam_poses, scans, lmap = intel
    first = 1000  # the robot drives here (at the log's start it stands in a featureless corridor)
    stop = int(np.searchsorted(scans.times, scans.times[first] + 30.0))
    truth = slam_poses[first]
    heading = truth[2] + direction * math.pi / 2
    guess = truth + [
        math.cos(heading),
        math.sin(heading),
        math.radians(20 if direction % 2 else -20),
    ]
    _, trace = localize(lmap, scans, first, stop, initial=guess, seed=direction)
    at = converged_at(trace, slam_poses[first:stop])
    assert at is not None and at <= 10.0, at


def test_global_localization_from_three_start_times(intel):
    _, slam_poses, scans, lmap = intel
    for first in (700, 1400, 2000):
        stop = min(int(np.searchsorted(scans.times, scans.times[first] + 60.0)), SCANS)
        localizer, trace = localize(lmap, scans, first, stop, seed=first)
        phase = trace.phase
        assert phase[0] == 0 and localizer.counters["histogram_steps"] >= 1
        handover = int(np.argmax(phase == 1))
        assert handover > 0 and trace.times[handover] - trace.times[0] < 30.0
        err, deg = errors(trace.poses, slam_poses[first:stop])
        assert err[handover] < 0.3 and deg[handover] < 5.0
        late = trace.times >= trace.times[handover] + 10.0
        assert late.any() and np.all(err[late] < 0.3) and np.all(deg[late] < 5.0)


def test_kidnapping_is_noticed_and_recovered(intel):
    from slam.localize.localizer import Localizer
    from slam.localize.run import run_localizer, splice

    _, slam_poses, scans, lmap = intel
    first, second = (300, 1200), (2000, 2500)
    jump = np.hypot(*(slam_poses[second[0], :2] - slam_poses[first[1] - 1, :2]))
    assert jump > 15.0  # the robot is carried 19.6 m away and turned round
    localizer = Localizer(lmap, load_config("intel"), initial=(*slam_poses[first[0]], 0.1))
    trace = run_localizer(localizer, splice(scans, first, second))
    n = first[1] - first[0]
    assert not trace.lost[:n].any() and trace.localized[:n].mean() > 0.99
    t_jump = trace.times[n]
    lost = np.flatnonzero(trace.lost[n:])
    assert lost.size >= 1 and trace.times[n + lost[0]] - t_jump <= 10.0
    assert not trace.localized[n + lost[0]]
    truth = np.concatenate([slam_poses[slice(*first)], slam_poses[slice(*second)]])
    err, deg = errors(trace.poses, truth)
    recovered = np.flatnonzero(trace.localized[n:] & (err[n:] < 0.3) & (deg[n:] < 5.0))
    assert recovered.size and trace.times[n + recovered[0]] - t_jump < 30.0
    assert localizer.counters["reseeds"] >= 1
    # right after the alarm the histogram's mode is the kidnapping prior around the tracked pose:
    # lying in it is no false alarm where the tracked pose does not explain the scan
    assert localizer.counters["false_alarms"] == 0
    assert err[-1] < 0.1 and deg[-1] < 2.0


@pytest.mark.parametrize("mode", ["tracking", "global"])
def test_a_seed_fixes_the_result_whatever_the_thread_count(intel, tmp_path, mode):
    run, slam_poses, _, _ = intel
    x, y, theta = slam_poses[0]
    start = [f"--initial={x},{y},{theta}"] if mode == "tracking" else ["--global"]
    outputs = []
    for threads in ("1", "2"):
        out = tmp_path / f"t{threads}"
        env = dict(os.environ, NUMBA_NUM_THREADS=threads)
        cmd = [sys.executable, "-m", "slam", "localize", "intel", "--map", str(run), *start,
               "--max-scans", "450", "--seed", "7", "--no-record", "--quiet", "--out", str(out)]  # fmt: skip
        subprocess.run(cmd, env=env, check=True, capture_output=True)
        outputs.append(out)
    a, b = outputs
    assert (a / "trajectory.tum").read_bytes() == (b / "trajectory.tum").read_bytes()
    with np.load(a / "localization.npz") as da, np.load(b / "localization.npz") as db:
        for key in da.files:
            assert np.array_equal(da[key], db[key], equal_nan=True), key
        if mode == "global":
            assert (da["phase"] == 0).any()  # the histogram filter ran


def test_tracking_without_odometry(intel, carmen_dir):
    """A robot without odometry: ``update(scan)`` alone, laser odometry standing in, tracks the
    map as well as the SLAM run that made it (relations 2.5 % above it, median 1.2 cm)."""
    from slam.eval.relations import relation_errors
    from slam.io.relations import read_relations
    from slam.localize.localizer import Localizer
    from slam.localize.run import run_localizer

    _, slam_poses, scans, lmap = intel
    localizer = Localizer(lmap, load_config("intel"), initial=(*slam_poses[0], 0.1))
    trace = run_localizer(localizer, [(scans.scan(i), None) for i in range(SCANS)])
    relations = read_relations(carmen_dir / "relations" / "intel.relations")
    ours = relation_errors(Trajectory(trace.times, trace.poses), relations)
    theirs = relation_errors(Trajectory(scans.times, slam_poses), relations)
    ratio = float(ours.trans.mean() / theirs.trans.mean())
    err, _ = errors(trace.poses, slam_poses)
    assert ratio <= 1.1, ratio
    assert np.median(err) < 0.03
    assert trace.localized.mean() > 0.99 and not trace.lost.any()
    assert localizer._laser.matched == SCANS - 1


def test_tracking_without_odometry_turns_with_a_gyro(intel):
    """``update(scan, imu=...)`` without odometry: the laser odometry turns with the gyro fed up
    to each scan, the same poses as the batch laser odometry given the same IMU stream (what
    ``slam localize`` computes on a log with one), and the map is tracked."""
    from slam.io.log import ImuStream
    from slam.laser_odometry import laser_odometry
    from slam.localize.localizer import Localizer

    _, slam_poses, scans, lmap = intel
    n = 300
    times = scans.times[:n]
    samples = np.arange(times[0], times[-1], 0.01)
    heading = np.interp(samples, np.maximum.accumulate(times), np.unwrap(slam_poses[:n, 2]))
    rates = np.gradient(heading, samples)
    config = load_config("intel")
    localizer = Localizer(lmap, config, initial=(*slam_poses[0], 0.1))
    fed = 0
    for i in range(n):
        upto = max(fed, int(np.searchsorted(samples, times[i], side="right")))  # clock glitches
        last = localizer.update(scans.scan(i), imu=(samples[fed:upto], rates[fed:upto]))
        fed = upto
    imu = ImuStream(samples, np.vstack([0 * rates, 0 * rates, rates]), np.zeros((3, rates.size)))
    batch, made = laser_odometry([scans.scan(i) for i in range(n)], config, imu)
    np.testing.assert_array_equal(np.array(localizer._laser.poses), batch)
    assert localizer._laser.gyro_turns == made.gyro_turns == 252  # 47 starts after clock glitches
    assert made.gyro_set_aside_at is None and made.gyro_agreement[0] > 0.85  # 0.884
    err, _ = errors(np.array([last.pose]), slam_poses[n - 1 : n])
    assert err[0] < 0.05


def test_odometry_is_given_for_every_scan_or_for_none(intel):
    from slam.errors import UsageError
    from slam.localize.localizer import Localizer

    _, slam_poses, scans, lmap = intel
    localizer = Localizer(lmap, load_config("intel"), initial=(*slam_poses[0], 0.1))
    localizer.update(scans.scan(0))
    with pytest.raises(UsageError, match="earlier scans came without odometry"):
        localizer.update(scans.scan(1), scans.odometry[1])
    given = Localizer(lmap, load_config("intel"), initial=(*slam_poses[0], 0.1))
    given.update(scans.scan(0), scans.odometry[0])
    with pytest.raises(UsageError, match="earlier scans came with odometry"):
        given.update(scans.scan(1))
    strict = Localizer(lmap, load_config("intel", None, ['robot.odometry="log"']))
    with pytest.raises(UsageError, match='robot.odometry = "log"'):
        strict.update(scans.scan(0))
