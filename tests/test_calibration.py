"""slam.calibration: the odometry the laser agrees with, and the laser's mount, on synthetic logs
whose answers are known (a robot turning in the box room of ``synthetic_logs``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from synthetic_logs import ray_cast, write_carmen

from slam.calibration import (
    CalibrationSettings,
    check_beam_geometry,
    estimate_mount,
    odometry_disagreement,
    pair_motions,
    synchronise_odometry,
    turning_pairs,
)
from slam.config import load_config
from slam.geometry import compose, interpolate_poses, relative

PERIOD = 0.1  # s between scans
ANGLES = np.linspace(-np.pi / 2, np.pi / 2, 181)


def truth(t: np.ndarray) -> np.ndarray:
    """The robot's pose at times ``t``: wandering near the room's centre, turning back and forth
    at a varying rate (so a lag between odometry and laser shows in the rotations)."""
    x = 1.5 * np.sin(0.21 * t)
    y = 1.0 * np.sin(0.33 * t) - 0.5
    theta = 1.2 * np.sin(0.5 * t) + 0.3 * np.sin(1.7 * t)
    return np.stack([x, y, theta], axis=1)


def laser_hits(poses: np.ndarray, mount: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Laser-frame returns of scans taken from ``poses ⊕ mount``."""
    out = []
    for pose in poses:
        r = ray_cast(compose(pose, mount), ANGLES)
        ok = np.isfinite(r)
        out.append((r[ok] * np.cos(ANGLES[ok]), r[ok] * np.sin(ANGLES[ok])))
    return out


@pytest.fixture(scope="module")
def turning_robot():
    times = np.arange(400) * PERIOD
    hits = laser_hits(truth(times), np.zeros(3))
    stream_times = np.arange(0.0, times[-1] + 1.0, 0.03)
    return times, hits, stream_times


def test_stale_written_poses_give_way_to_the_stream(turning_robot):
    times, hits, stream_times = turning_robot
    written = truth(times - 0.08)  # each scan got the odometry of 80 ms before it
    stream = (stream_times, truth(stream_times))
    poses, sync = synchronise_odometry(lambda k: hits[k], times, written, stream, load_config())
    assert sync.source == "stream" and abs(sync.lag_s) <= 0.021
    assert sync.disagreement_deg < 0.8 * sync.scan_disagreement_deg  # the matcher: 0.2° of noise
    assert sync.pairs > 300
    np.testing.assert_allclose(poses, interpolate_poses(*stream, times + sync.lag_s))


def test_a_late_stream_is_read_at_its_lag(turning_robot):
    times, hits, stream_times = turning_robot
    written = truth(times - 0.1)
    stream = (stream_times + 0.1, truth(stream_times))  # every message stamped 0.1 s late
    _, sync = synchronise_odometry(lambda k: hits[k], times, written, stream, load_config())
    assert sync.source == "stream" and sync.lag_s == pytest.approx(0.1, abs=0.021)


def test_exact_written_poses_are_kept(turning_robot):
    """The stream read at its lag is as good as the written poses, not 10 % better: the written
    poses stay, to the bit."""
    times, hits, stream_times = turning_robot
    written = truth(times)
    stream = (stream_times + 0.1, truth(stream_times))
    poses, sync = synchronise_odometry(lambda k: hits[k], times, written, stream, load_config())
    assert sync.source == "scan" and sync.lag_s == 0.0
    assert sync.stream_lag_s == pytest.approx(0.1, abs=0.021)
    assert poses is written


def test_too_few_fitting_pairs_keep_the_written_poses():
    times = np.arange(5) * PERIOD
    written = truth(times)
    empty = (np.zeros(0), np.zeros(0))
    stream = (times, truth(times))
    poses, sync = synchronise_odometry(lambda k: empty, times, written, stream, load_config())
    assert poses is written and sync.source == "scan" and sync.pairs == 0


def test_the_mount_is_found_from_the_turns():
    mount = np.array([0.25, 0.03, 0.02])
    times = np.arange(400) * PERIOD
    robot = truth(times)
    hits = laser_hits(robot, mount)
    settings = CalibrationSettings()
    pairs = turning_pairs(times, robot, settings)
    assert len(pairs) > 50
    laser, kept = pair_motions(lambda k: hits[k], robot, pairs, load_config(), settings)
    pairs = pairs[kept]
    odo = relative(robot[pairs[:, 0]], robot[pairs[:, 1]])
    est = estimate_mount(laser, odo, np.zeros(3), settings)
    assert est.x == pytest.approx(0.25, abs=0.01)
    assert est.y == pytest.approx(0.03, abs=0.01)
    assert est.yaw == pytest.approx(0.02, abs=0.005)
    assert est.std_x < 0.01 and est.residual_m < 0.5 * est.residual_stated_m
    with pytest.raises(ValueError, match="at least 10"):
        estimate_mount(laser[:5], odo[:5], np.zeros(3), settings)


def test_the_disagreement_matches_as_many_returns_as_the_registration(turning_robot, monkeypatch):
    """``pair_motions(..., match_beams)`` matches at most that many of scan ``j``'s returns,
    evenly spread, on a field of every return of scan ``i``; ``odometry_disagreement`` matches
    with ``rbpf.register_beams`` of them (the registration the smoothing weighs against the
    odometry), and fewer beams measure a larger disagreement (more of the matcher's noise)."""
    import slam.calibration as calibration

    times, hits, _ = turning_robot
    robot = truth(times)
    counts = np.array([h[0].size for h in hits])
    assert counts.min() > 120  # every scan has more returns than the caps below
    seen: dict[str, list[int]] = {"field": [], "matched": []}
    insert, match = calibration.ParticleMaps.insert_scans, calibration.match_one

    def spy_insert(self, poses, scan_hits, *args):
        seen["field"].append(scan_hits.shape[1])
        return insert(self, poses, scan_hits, *args)

    def spy_match(view, pose, ex, ey, *args):
        seen["matched"].append(ex.size)
        return match(view, pose, ex, ey, *args)

    monkeypatch.setattr(calibration.ParticleMaps, "insert_scans", spy_insert)
    monkeypatch.setattr(calibration, "match_one", spy_match)
    pairs = np.stack([np.arange(0, 398, 7), np.arange(1, 399, 7)], axis=1)
    settings = CalibrationSettings()
    every, _ = pair_motions(lambda k: hits[k], robot, pairs, load_config(), settings)
    assert sorted(seen["field"]) == sorted(counts[pairs[:, 0]])  # (ranges of pairs on threads:
    assert sorted(seen["matched"]) == sorted(counts[pairs[:, 1]])  # in any order)
    seen["field"].clear(), seen["matched"].clear()
    fewer, _ = pair_motions(lambda k: hits[k], robot, pairs, load_config(), settings, 100)
    assert sorted(seen["field"]) == sorted(counts[pairs[:, 0]])
    assert seen["matched"] == [100] * len(pairs)
    true = relative(robot[pairs[:, 0]], robot[pairs[:, 1]])
    errors = []
    for found in (every, fewer):  # both the true motions, up to the matcher's noise
        errors.append(np.median(np.hypot(*(found - true)[:, :2].T)))
        errors.append(np.median(np.abs(found - true)[:, 2]))
    assert max(errors[0], errors[2]) < 0.01 and max(errors[1], errors[3]) < 0.005  # m, rad

    seen["matched"].clear()
    config = load_config(None, None, ["rbpf.register_beams=120"])
    odometry_disagreement(lambda k: hits[k], robot, config, CalibrationSettings(pairs=40))
    assert seen["matched"] == [120] * 40


def odom_line(pose: np.ndarray, t: float) -> str:
    p = " ".join(f"{v:.6f}" for v in pose)
    return f"ODOM {p} 0 0 0 {t:.6f} host {t:.6f}"


def flaser(ranges: np.ndarray, pose: np.ndarray, t: float) -> str:
    nums = " ".join(f"{r:.3f}" for r in np.where(np.isfinite(ranges), ranges, 81.91))
    p = " ".join(f"{v:.6f}" for v in pose)
    return f"FLASER {len(ranges)} {nums} {p} {p} {t:.6f} host {t:.6f}"


def test_a_carmen_run_uses_and_reports_the_stream(tmp_path, capsys):
    """A CARMEN log whose scan lines carry the last ODOM pose before them: ``slam run`` reads the
    stream instead (``metrics.json``), ``slam data calibrate`` says so, and
    ``robot.odometry_sync = "scan"`` keeps the written poses."""
    from slam.cli import main

    times = 100.0 + np.arange(300) * PERIOD
    odom_times = 100.0 + np.arange(-2, 1000) * 0.03
    lines = []
    for t in odom_times[odom_times < times[0]]:
        lines.append(odom_line(truth(np.array([t - 100.0]))[0], t))
    for k, t in enumerate(times):
        before = odom_times[odom_times < t][-1]
        held = truth(np.array([before - 100.0]))[0]
        pose = truth(np.array([t - 100.0]))[0]
        lines.append(flaser(ray_cast(pose, ANGLES), held, t))
        nxt = times[k + 1] if k + 1 < len(times) else t + PERIOD
        for u in odom_times[(odom_times >= t) & (odom_times < nxt)]:
            lines.append(odom_line(truth(np.array([u - 100.0]))[0], u))
    log = write_carmen(tmp_path, lines)
    out = tmp_path / "run"
    assert main(["run", str(log), "--out", str(out), "--no-texture", "--no-record", "--quiet"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["odometry_sync"]["source"] == "stream"
    assert abs(metrics["odometry_sync"]["lag_s"]) <= 0.021
    capsys.readouterr()
    assert main(["data", "calibrate", str(log)]) == 0
    text = capsys.readouterr().out
    assert 'robot.odometry_sync = "auto": the messages at' in text
    assert "laser     measured at x" in text
    assert main(["data", "calibrate", str(log), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["odometry_sync"]["source"] == "stream" and report["scans"] == 300
    assert abs(report["mount"]["x"]) < 0.03  # the laser sits on the odometry point here
    kept = tmp_path / "kept"
    args = ["run", str(log), "--out", str(kept), "--no-texture", "--no-record", "--quiet"]
    assert main([*args, "--set", 'robot.odometry_sync="scan"']) == 0
    assert "odometry_sync" not in json.loads((kept / "metrics.json").read_text())


def test_calibrate_without_turns_is_one_line_and_exit_2(tmp_path, capsys):
    """A log that never turns cannot show the laser's mount: one line naming the file, exit 2."""
    from synthetic_logs import carmen_lines

    from slam.cli import main

    log = write_carmen(tmp_path, carmen_lines(40))  # a gentle curve, no turn of 0.1 rad
    assert main(["data", "calibrate", str(log)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert str(log) in err[0] and "turning scan pairs fitted; at least 10 are needed" in err[0]


def test_a_bad_odometry_sync_names_the_key(tmp_path, capsys):
    from synthetic_logs import carmen_lines

    from slam.cli import main

    log = write_carmen(tmp_path, carmen_lines(40))
    args = ["run", str(log), "--out", str(tmp_path / "r"), "--set", 'robot.odometry_sync="late"']
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "robot.odometry_sync" in err and "auto, scan, stream" in err
    assert not (tmp_path / "r").exists()


def test_the_pairs_do_not_depend_on_the_thread_count(turning_robot):
    import numba

    times, hits, stream_times = turning_robot
    written = truth(times - 0.08)
    stream = (stream_times, truth(stream_times))
    before = numba.get_num_threads()
    got = []
    try:
        for n in (1, 2):
            numba.set_num_threads(n)
            got.append(
                synchronise_odometry(lambda k: hits[k], times, written, stream, load_config())
            )
    finally:
        numba.set_num_threads(before)
    (p1, s1), (p2, s2) = got
    np.testing.assert_array_equal(p1, p2)
    assert s1 == s2


def test_odometry_disagreement_measures_the_odometry_noise(turning_robot):
    from slam.calibration import odometry_disagreement

    times, hits, _ = turning_robot
    exact = truth(times)
    along0, across0, th0, pairs = odometry_disagreement(lambda k: hits[k], exact, load_config())
    assert pairs > 300 and max(along0, across0) < 0.01 and np.degrees(th0) < 0.4  # the matcher's
    noise = np.random.default_rng(1).normal(0.0, [0.0, 0.0, 0.01], exact.shape)
    th1 = odometry_disagreement(lambda k: hits[k], exact + noise, load_config()).heading
    assert th1 > 2.0 * th0  # heading noise of 0.01 rad per scan: about 0.8° between two scans
    empty = (np.zeros(0), np.zeros(0))
    nothing = odometry_disagreement(lambda k: empty, exact, load_config())
    assert nothing.pairs == 0 and np.isnan(nothing.along) and np.isnan(nothing.heading)


def test_odometry_disagreement_tells_along_from_across(turning_robot):
    """Odometry that misjudges each step's length by 2 cm (slip) but never moves sideways: the
    disagreement along the heading reads the error (trimmed, with the matcher's own 5 mm), across
    it and in heading stays the matcher's own."""
    times, hits, _ = turning_robot
    exact = truth(times)
    steps = relative(exact[:-1], exact[1:])
    steps[:, 0] += np.random.default_rng(4).normal(0.0, 0.02, len(steps))
    odometry = [exact[0]]
    for step in steps:
        odometry.append(compose(odometry[-1], step))
    measured = odometry_disagreement(lambda k: hits[k], np.array(odometry), load_config())
    clean = odometry_disagreement(lambda k: hits[k], exact, load_config())
    assert clean.along < 0.007 and 0.014 < measured.along < 0.024
    assert abs(measured.across - clean.across) < 0.001
    assert abs(measured.heading - clean.heading) < 0.2 * clean.heading


def test_the_smoothing_stage_runs_by_default(tmp_path):
    from synthetic_logs import carmen_lines

    from slam.cli import main

    log = write_carmen(tmp_path, carmen_lines(120))
    base = ["run", str(log), "--no-texture", "--no-record", "--quiet"]
    off = ["--set", "rbpf.smooth_odometry=false"]
    assert main([*base, "--out", str(tmp_path / "plain"), *off]) == 0
    assert main([*base, "--out", str(tmp_path / "smooth")]) == 0
    plain = json.loads((tmp_path / "plain" / "metrics.json").read_text())["filter"]
    smooth = json.loads((tmp_path / "smooth" / "metrics.json").read_text())["filter"]
    assert "odometry_disagreement_along_m" not in plain
    assert smooth["odometry_disagreement_along_m"] < 0.02  # the synthetic odometry is exact
    assert smooth["odometry_disagreement_across_m"] < 0.02
    assert smooth["range_noise_m"] < 0.002 and smooth["smooth_scale"] == 1.0  # millimetre ranges


def test_a_noisy_laser_is_trusted_less_against_the_odometry(tmp_path, capsys):
    """The turning robot's room read with 3 cm of range noise: the run measures it (``range_noise_m``) and
    smooths with the registration's sigmas at least noise / ``rbpf.smooth_noise_ref`` times
    larger; ``slam data calibrate`` prints the scatter and what it does."""
    from slam.cli import main

    rng = np.random.default_rng(8)
    times = 100.0 + np.arange(300) * PERIOD
    lines = []
    for t, pose in zip(times, truth(times - 100.0), strict=True):
        ranges = ray_cast(pose, ANGLES)
        lines.append(flaser(ranges + rng.normal(0.0, 0.03, ranges.size), pose, t))
    log = write_carmen(tmp_path, lines)
    out = tmp_path / "run"
    assert main(["run", str(log), "--out", str(out), "--no-texture", "--no-record", "--quiet"]) == 0
    stats = json.loads((out / "metrics.json").read_text())["filter"]
    assert abs(stats["range_noise_m"] / 0.03 - 1.0) < 0.15
    assert stats["smooth_scale"] >= stats["range_noise_m"] / 0.01 - 0.01  # both rounded
    capsys.readouterr()
    assert main(["data", "calibrate", str(log), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    noise, steps = report["range_noise"], report["odometry_steps"]
    assert noise["noise_m"] == stats["range_noise_m"] and noise["reference_m"] == 0.01
    assert noise["multiple"] == pytest.approx(noise["noise_m"] / 0.01, abs=1e-3)
    # the odometry's steps as the run's smoothing measured them (the same function and scans)
    assert steps["along_m"] == stats["odometry_disagreement_along_m"]
    assert steps["across_m"] == stats["odometry_disagreement_across_m"]
    assert steps["heading_deg"] == stats["odometry_disagreement_deg"]
    assert steps["pairs"] > 200 and steps["factor"] == 2.0
    assert main(["data", "calibrate", str(log)]) == 0
    text = capsys.readouterr().out
    assert f"ranges    scatter {noise['noise_m']:.4f} m" in text
    assert f"counts {noise['multiple']:.2f} times less against the odometry" in text
    assert (
        f"steps     the odometry differs from the matcher between consecutive scans by "
        f"{steps['along_m']:.4f} m along the heading, {steps['across_m']:.4f} m across" in text
    )
    assert "weighs each odometry step by 2 times these" in text
    assert main(["data", "calibrate", str(log), "--set", "rbpf.smooth_odometry=false"]) == 0
    assert "rbpf.smooth_odometry = false: not used" in capsys.readouterr().out
    assert main(["data", "calibrate", str(log), "--set", "rbpf.smooth_noise_ref=0"]) == 0
    assert "ranges    not measured (rbpf.smooth_noise_ref = 0" in capsys.readouterr().out


class _MixedScans:
    """The part of a :class:`slam.scans.LogScans` that :func:`check_beam_geometry` reads: scans
    alternating between 181 readings (−90°..+90°) and 180 (the half degrees between, as a SICK
    LMS's interlaced sweeps give), cast in the synthetic room along a turning path with exact
    odometry; the loader's angles for the short scans are the spread ones (it cannot know)."""

    def __init__(self, n: int) -> None:
        from types import SimpleNamespace

        from slam.io.log import ScanStream

        self.odometry = np.c_[
            np.linspace(-1.0, 1.0, n), np.linspace(-0.5, 0.3, n), 0.05 * np.arange(n)
        ]
        self.indices = np.arange(n)
        self.ranges = np.full((n, 181), np.nan)
        angles = np.full((n, 181), np.nan)
        long = np.deg2rad(np.arange(181) - 90.0)
        short = np.deg2rad(np.arange(180) - 89.5)
        for k in range(n):
            true = long if k % 2 == 0 else short
            self.ranges[k, : true.size] = ray_cast(self.odometry[k], true)
            angles[k, : true.size] = long if k % 2 == 0 else np.linspace(-np.pi / 2, np.pi / 2, 180)
        stream = ScanStream(np.arange(n, dtype=np.float64), self.ranges.astype(np.float32),
                            angles, 0.05, 30.0, 30.0)  # fmt: skip
        self.log = SimpleNamespace(scans=stream)

    def __len__(self) -> int:
        return len(self.indices)

    def scan(self, k: int):
        from slam.scans import Scan

        angles = self.log.scans.angles[k]
        return Scan(float(k), self.ranges[k], angles, 0.05, 30.0, 30.0, np.zeros(3))


def test_the_beam_check_finds_the_interlaced_geometry():
    check = check_beam_geometry(_MixedScans(30), load_config(""), every=1)
    assert check is not None and check.short == 180
    assert check.fov_deg == pytest.approx(180.0)
    assert check.best == "centred" and check.beam_step_deg == pytest.approx(1.0)
    rows = check.rows
    assert rows["centred"]["pairs_fitted"] == 29
    assert rows["centred"]["rotation_rms_deg"] < 0.15  # the matcher's own noise: about 0.1°
    for wrong in ("from_first", "to_last"):
        assert rows[wrong]["rotation_rms_deg"] > 0.4  # half a degree on every pair
        assert rows[wrong]["short_to_long_deg"] * rows[wrong]["long_to_short_deg"] < 0
    assert abs(rows["centred"]["short_to_long_deg"]) < 0.1
    assert json.loads(json.dumps(check.as_dict()))["best"] == "centred"


def test_the_beam_check_leaves_logs_of_one_width_alone():
    scans = _MixedScans(6)
    scans.log.scans.angles[1::2, 180] = np.pi / 2  # the short scans get a 181st reading
    assert check_beam_geometry(scans, load_config("")) is None


def test_a_run_reads_an_interlaced_log_with_its_measured_beam_step(tmp_path):
    """``slam run`` of a log of interlaced sweeps (no configuration): the beam step measured
    when the log loads is in the run's ``config.toml`` and ``metrics.json``, and the run is the
    run with that step declared, bit for bit."""
    from synthetic_logs import carmen_lines

    from slam.cli import main

    log = write_carmen(tmp_path, carmen_lines(80, interlaced=True))
    base = ["run", str(log), "--no-texture", "--no-record", "--quiet"]
    assert main([*base, "--out", str(tmp_path / "measured")]) == 0
    declared = ["--set", "lidar.beam_step_deg=1.0"]
    assert main([*base, "--out", str(tmp_path / "declared"), *declared]) == 0
    config = (tmp_path / "measured" / "config.toml").read_text()
    assert "beam_step_deg = 1.0\n" in config
    metrics = json.loads((tmp_path / "measured" / "metrics.json").read_text())
    assert metrics["beam_geometry"]["applied"] is True
    assert metrics["beam_geometry"]["best"] == "centred"
    assert metrics["warnings"] == []
    assert "beam_geometry" not in json.loads((tmp_path / "declared" / "metrics.json").read_text())
    measured = (tmp_path / "measured" / "trajectory.tum").read_bytes()
    assert measured == (tmp_path / "declared" / "trajectory.tum").read_bytes()


def test_calibrate_says_the_run_measures_the_beam_step(tmp_path, capsys):
    """``slam data calibrate`` of a log of interlaced sweeps shows every geometry and says that
    a run reads the log with the measured step; with the measurement off it prints the
    ``--set`` that declares it."""
    from synthetic_logs import path

    from slam.cli import main

    halves, wholes = np.deg2rad(np.arange(180) - 89.5), np.deg2rad(np.arange(181) - 90.0)
    drive = path(120)  # along the walls (the geometries differ), then a turn on the spot
    spin = np.repeat(drive[-1:], 12, axis=0)
    spin[:, 2] += 0.12 * np.arange(1, 13)  # turning pairs for the mount
    poses = np.vstack([drive, spin])
    lines = [flaser(ray_cast(p, halves if k % 2 else wholes), p, 100.0 + PERIOD * k)
             for k, p in enumerate(poses)]  # fmt: skip
    log = write_carmen(tmp_path, lines)
    capsys.readouterr()
    assert main(["data", "calibrate", str(log), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["beam_step_deg"] == 1.0 and report["beam_step_measured"] is True
    assert report["beam_geometry"]["best"] == "centred"
    assert main(["data", "calibrate", str(log)]) == 0
    out = capsys.readouterr().out
    assert "centred fits best; `slam run` measures it when the log loads and reads the log with " \
        "lidar.beam_step_deg = 1" in out  # fmt: skip
    off = ["--set", "lidar.measure_beam_step=false"]
    assert main(["data", "calibrate", str(log), *off]) == 0
    assert "centred fits best: --set lidar.beam_step_deg=1 declares it" in capsys.readouterr().out


def test_a_stream_only_log_reads_its_odometry_at_the_lag_the_laser_agrees_with(tmp_path):
    """Raw scans (RAWLASER1, no pose of their own) and an odometry stream whose messages carry
    the pose of 0.1 s before their stamp: ``slam run`` reads the stream 0.1 s after each scan
    (``metrics.json``: ``written`` false), ``robot.odometry_sync = "scan"`` keeps the stream
    at the scans' times."""
    from slam.cli import main

    times = 100.0 + np.arange(300) * PERIOD
    odom_times = 100.0 + np.arange(-5, 1000) * 0.03
    lines = [odom_line(truth(np.array([u - 100.0 - 0.1]))[0], u) for u in odom_times]
    for t in times:
        ranges = ray_cast(truth(np.array([t - 100.0]))[0], ANGLES)
        nums = " ".join(f"{r:.3f}" for r in np.where(np.isfinite(ranges), ranges, 81.91))
        step = float(ANGLES[1] - ANGLES[0])
        head = f"RAWLASER1 0 {ANGLES[0]} {step * (ANGLES.size - 1)} {step} 81.9 0.01 0"
        lines.append(f"{head} {ANGLES.size} {nums} 0 {t:.6f} host {t:.6f}")
    lines.sort(key=lambda line: float(line.split()[-1]))  # the log in time order
    log = write_carmen(tmp_path, lines)
    base = ["run", str(log), "--no-texture", "--no-record", "--quiet"]
    assert main([*base, "--out", str(tmp_path / "auto")]) == 0
    sync = json.loads((tmp_path / "auto" / "metrics.json").read_text())["odometry_sync"]
    assert sync["source"] == "stream" and sync["written"] is False
    assert abs(sync["lag_s"] - 0.1) <= 0.021
    assert sync["disagreement_deg"] < 0.8 * sync["scan_disagreement_deg"]  # at lag 0
    assert (
        main([*base, "--out", str(tmp_path / "kept"), "--set", 'robot.odometry_sync="scan"']) == 0
    )
    assert "odometry_sync" not in json.loads((tmp_path / "kept" / "metrics.json").read_text())


def _room_scans(n: int) -> np.ndarray:
    """``(n, 181)`` noise-free ranges of the synthetic room from the truth path."""
    return np.array([ray_cast(p, ANGLES) for p in truth(np.arange(n) * PERIOD)])


def test_range_noise_reads_the_lasers_scatter():
    """Gaussian noise of 5 mm, 1 cm and 3 cm added to the room's scans is read back within
    10 % (the room's corners and grazing walls fall in the larger half that is left out), the
    noise-free scans read under a millimetre, and NaN readings are passed over."""
    from slam.calibration import range_noise

    clean = _room_scans(200)
    rng = np.random.default_rng(4)
    assert range_noise(clean)[0] < 0.001
    for sigma in (0.005, 0.01, 0.03):
        noisy = clean + rng.normal(0.0, sigma, clean.shape)
        noise, triples = range_noise(noisy)
        assert triples > 5000 and abs(noise / sigma - 1.0) < 0.1, (sigma, noise)
        noisy[rng.random(noisy.shape) < 0.2] = np.nan
        assert abs(range_noise(noisy)[0] / sigma - 1.0) < 0.1
    # a laser that reads in steps of 5 cm: the steps alone read nothing, noise under them does
    assert range_noise(np.round(clean / 0.05) * 0.05)[0] < 1e-9
    dithered = np.round((clean + rng.normal(0.0, 0.01, clean.shape)) / 0.05) * 0.05
    assert 0.012 < range_noise(dithered)[0] < 0.02


def test_range_noise_uses_readings_of_half_a_metre_to_three_and_needs_a_triple():
    from slam.calibration import range_noise

    clean = _room_scans(50)
    noise, triples = range_noise(clean + 5.0)  # every reading beyond 3 m
    assert np.isnan(noise) and triples == 0
    assert np.isnan(range_noise(np.full((4, 2), 1.0))[0])  # two beams: no triple
    assert range_noise(clean, near=0.5, far=3.0)[1] > range_noise(clean, near=0.5, far=1.0)[1]


def test_calibrate_says_when_no_step_was_measured():
    """A log whose consecutive scans never fit (or a single scan): the ``steps`` line says the
    odometry's steps were not measured, and the JSON holds nulls, not NaN."""
    from slam.calibration import Disagreement
    from slam.commands.data import _steps_line, _steps_report
    from slam.config import RbpfConfig

    nan = float("nan")
    report = _steps_report(Disagreement(nan, nan, nan, 0), RbpfConfig())
    assert report["along_m"] is None and report["across_m"] is None and report["pairs"] == 0
    assert json.loads(json.dumps(report)) == report  # plain JSON
    assert "not measured" in _steps_line(report)
    measured = _steps_report(Disagreement(0.012, 0.006, 0.004, 900), RbpfConfig())
    assert measured["heading_deg"] == round(np.degrees(0.004), 3)
    assert "0.0120 m along the heading, 0.0060 m across and 0.229°" in _steps_line(measured)
