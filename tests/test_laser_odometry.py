"""Laser odometry: a robot without odometry, in a batch run, online, and from the CLI."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from synthetic_logs import path as room_path
from synthetic_logs import ray_cast

import slam
from slam.cli import main
from slam.errors import DataError, UsageError
from slam.geometry import relative
from slam.io.carmen import load_carmen
from slam.io.plausibility import DataWarning
from slam.io.tum import read_tum
from slam.laser_odometry import LaserOdometry, laser_odometry
from slam.odometry import has_odometry
from slam.scans import LogScans, scan_pauses

ANGLES = np.linspace(-np.pi / 2, np.pi / 2, 181)


def room_scan(pose: np.ndarray, t: float) -> slam.Scan:
    """The synthetic room seen from ``pose`` at time ``t``, as a resolved scan."""
    scan = slam.Scan(t, ray_cast(pose, ANGLES), ANGLES, range_min=0.05, range_max=30.0)
    return scan.resolved(slam.load_config("").lidar)


def flaser_lines(poses: np.ndarray, odometry: bool) -> list[str]:
    """FLASER lines of the room from ``poses``, their odometry fields the poses or zeros."""
    lines = []
    for k, pose in enumerate(poses):
        ranges = " ".join(f"{r:.3f}" for r in ray_cast(pose, ANGLES))
        odo = " ".join(f"{v:.6f}" for v in (pose if odometry else np.zeros(3)))
        t = 100.0 + 0.1 * k
        lines.append(f"FLASER 181 {ranges} {odo} {odo} {t:.6f} host {t:.6f}")
    return lines


def rawlaser_lines(poses: np.ndarray) -> list[str]:
    """RAWLASER1 lines of the room from ``poses``: scans without a pose, and no ODOM line."""
    lines = []
    for k, pose in enumerate(poses):
        ranges = " ".join(f"{r:.3f}" for r in ray_cast(pose, ANGLES))
        t = 100.0 + 0.1 * k
        head = f"RAWLASER1 0 {-np.pi / 2} {np.pi} {np.pi / 180} 30.0 0.01 0 181"
        lines.append(f"{head} {ranges} 0 {t:.6f} host {t:.6f}")
    return lines


def in_first_frame(poses: np.ndarray) -> np.ndarray:
    return relative(np.broadcast_to(poses[0], poses.shape), poses)


def test_laser_odometry_follows_the_room_path():
    """Scan matching alone follows a 6 m path through the room to 4.2 cm and 0.23° (its first
    step, from a standing start, is 3 cm short: the unsigned field's pull towards the cells of
    the first scan's returns, docs/accuracy.md)."""
    truth = room_path(120)
    poses, made = laser_odometry(
        [room_scan(p, 0.1 * k) for k, p in enumerate(truth)], slam.Config()
    )
    error = poses - in_first_frame(truth)
    assert made.matched == 119 and made.kept_prediction == 0 and made.searched == 0
    assert np.abs(error[:, :2]).max() < 0.05
    assert np.abs(error[:, 2]).max() < 0.005


def test_a_turn_in_a_gap_of_the_log_is_found_by_the_search():
    """The robot turns 60° in place while the log records nothing: the constant-velocity start
    is 60° off, the search over every heading finds the turn (to 0.25°; the position is 11 cm
    off, where the new view's returns meet the earlier scans' sparse returns on the walls it
    saw at a grazing angle)."""
    truth = room_path(40)
    turned = truth[-1] + np.array([0.0, 0.0, np.pi / 3])
    truth = np.vstack([truth, turned, turned + np.array([0.05 * np.cos(turned[2]), 0, 0])])
    odometry = LaserOdometry(slam.Config())
    poses = np.array([odometry.pose_at(room_scan(p, 0.1 * k)) for k, p in enumerate(truth)])
    error = poses - in_first_frame(truth)
    assert odometry.searched >= 1 and odometry.kept_prediction == 0
    assert np.abs(error[40:, 2]).max() < 0.005
    assert np.abs(error[40:, :2]).max() < 0.15


def test_a_log_whose_odometry_never_moves_runs_on_laser_odometry(tmp_path):
    """CARMEN FLASER lines with all-zero poses: "auto" warns and matches the scans; "log" keeps
    the zeros (the log's odometry, as asked)."""
    truth = room_path(120)
    log_path = tmp_path / "still.clf"
    log_path.write_text("\n".join(flaser_lines(truth, odometry=False)) + "\n")
    log = load_carmen(log_path)
    assert has_odometry(log)
    with pytest.warns(DataWarning, match="the log's odometry never moves"):
        scans = LogScans.from_log(log, slam.load_config(""))
    assert scans.odometry_source == "laser" and scans.laser_odometry["matched"] == 119
    assert np.abs(scans.odometry[:, :2] - in_first_frame(truth)[:, :2]).max() < 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        kept = LogScans.from_log(log, slam.load_config("", None, ['robot.odometry="log"']))
    assert kept.odometry_source == "log" and not np.any(kept.odometry)


def test_slam_run_on_raw_scans_without_odometry(tmp_path, capsys, monkeypatch):
    """RAWLASER1 lines and no ODOM line: the log loads without odometry, ``slam run`` says it
    matches the scans and tracks the path, and tells the stages so (the recovery stage starts
    again only from dead reckoning); with ``robot.odometry = "log"`` it is one error."""
    import slam.stages

    truth = room_path(120)
    log_path = tmp_path / "raw.clf"
    log_path.write_text("\n".join(rawlaser_lines(truth)) + "\n")
    log = load_carmen(log_path)
    assert log.odometry is None and log.scans.odometry is None and not has_odometry(log)
    out = tmp_path / "run"
    seen = []
    recover = slam.stages.Recovery.run

    def watching(self, output, config):
        seen.append(output.scans.odometry_source)
        return recover(self, output, config)

    monkeypatch.setattr(slam.stages.Recovery, "run", watching)
    assert (
        main(["run", str(log_path), "--out", str(out), "--no-texture", "--no-record", "--quiet"])
        == 0
    )
    assert seen == ["laser"]
    assert "the log has no odometry" in capsys.readouterr().err
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["odometry_source"] == "laser"
    counts = metrics["laser_odometry"]
    assert counts["matched"] == 119 and counts["kept_prediction"] == 0 and counts["seconds"] > 0
    got = read_tum(out / "trajectory.tum")
    assert len(got) == 120
    assert np.abs(got.poses[:, :2] - in_first_frame(truth)[:, :2]).max() < 0.03
    refused = tmp_path / "refused"
    args = ["run", str(log_path), "--out", str(refused), "--set", 'robot.odometry="log"', "--quiet"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{log_path}: the log has no odometry" in err[0] and "laser" in err[0]
    assert not refused.exists()
    with pytest.raises(DataError, match="no odometry"):
        LogScans.from_log(log, slam.load_config("", None, ['robot.odometry="log"']))


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """The simulator's small loop (30 s, no RGB-D) with ground truth."""
    from slam.sim.dataset import SimOptions, generate_dataset

    folder = tmp_path_factory.mktemp("laser_odometry") / "small"
    generate_dataset(folder, SimOptions(scenario="small", seed=7, duration=30.0, rgbd=False))
    return folder


@pytest.mark.parametrize("gyro", [True, False])
def test_online_without_odometry_equals_the_batch_run(small, gyro):
    """``Slam.update(scan)`` with no odometry and no encoder reading makes the laser odometry a
    batch run with ``robot.odometry = "laser"`` computes beforehand: the same run, bit for bit —
    with the gyro fed up to each scan's time (``imu=``) as the batch reads the log's IMU, and
    without it."""
    settings = ['robot.odometry="laser"', "filter.particles=16"]
    config = slam.load_config(
        "", None, [*settings, f"robot.laser_odometry_gyro={str(gyro).lower()}"]
    )
    batch = slam.run(str(small), config, seed=3, max_scans=400)
    assert batch.metrics["odometry_source"] == "laser"
    log = slam.pipeline.load_source(str(small), Path("."), config).log
    source = LogScans.from_log(log, config)
    imu_times, gyro_z = log.imu.time, log.imu.angular_velocity[2]
    s = slam.Slam(config, seed=3, scan_period=source.scan_period())
    fed = 0
    for k, (scan, _) in enumerate(source):
        if k == 400:
            break
        upto = int(np.searchsorted(imu_times, scan.time, side="right"))
        s.update(scan, imu=(imu_times[fed:upto], gyro_z[fed:upto]))
        fed = upto
    assert s.scans.odometry_source == "laser"  # what the recovery stage reads
    online = s.finish()
    np.testing.assert_array_equal(online.trajectory.poses, batch.trajectory.poses)
    np.testing.assert_array_equal(online.grid.log_odds, batch.grid.log_odds)
    counts = online.stats["laser_odometry"]
    assert counts["matched"] == 399 and batch.metrics["laser_odometry"]["matched"] == 399
    assert counts.get("gyro_turns", 0) == batch.metrics["laser_odometry"].get("gyro_turns", 0)
    assert counts.get("gyro_turns", 0) == (399 if gyro else 0)
    assert batch.metrics["ate_rmse"] < 0.05


def test_odometry_is_given_for_every_scan_or_for_none():
    s = slam.Slam()
    s.update(room_scan(room_path(3)[0], 0.0))
    with pytest.raises(UsageError, match="earlier scans came without odometry"):
        s.update(room_scan(room_path(3)[1], 0.1), odometry=np.zeros(3))
    s = slam.Slam()
    s.update(room_scan(room_path(3)[0], 0.0), odometry=np.zeros(3))
    with pytest.raises(UsageError, match="earlier scans came with odometry"):
        s.update(room_scan(room_path(3)[1], 0.1))
    strict = slam.Slam(slam.load_config("", None, ['robot.odometry="log"']))
    with pytest.raises(UsageError, match='robot.odometry = "log"'):
        strict.update(room_scan(room_path(3)[0], 0.0))


def test_a_pause_in_which_the_robot_turned_is_named_in_a_warning(tmp_path):
    """The scans pause for 3 s (30 scan periods) after scan 39: where the robot stood still
    meanwhile, nothing is said; where it turned 60°, laser odometry names the pause."""
    np.testing.assert_array_equal(scan_pauses([0.0, 0.1, 0.2, 3.2, 3.3, 4.2]), [2])
    np.testing.assert_array_equal(scan_pauses([0.0, 0.1, 0.2, 0.9, 1.0]), [])  # under 1 s
    np.testing.assert_array_equal(scan_pauses([0.0, 2.0, 4.0, 5.5, 7.5]), [])  # 5 periods: 10 s
    path = room_path(40)
    for turn, warned in ((0.0, False), (np.pi / 3, True)):
        turned = path[-1] + np.array([0.0, 0.0, turn])
        poses = np.vstack([path, np.repeat(turned[None], 20, axis=0)])
        lines = flaser_lines(poses, odometry=False)
        for k in range(40, 60):  # the scans after the pause: 2.9 s later
            fields = lines[k].split()
            t = float(fields[-3]) + 2.9
            fields[-3], fields[-1] = f"{t:.6f}", f"{t:.6f}"
            lines[k] = " ".join(fields)
        log_path = tmp_path / f"paused{turn:.2f}.clf"
        log_path.write_text("\n".join(lines) + "\n")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            LogScans.from_log(load_carmen(log_path), slam.load_config(""))
        texts = [str(w.message) for w in caught]
        said = [t for t in texts if "pause(s) in the scans" in t]
        assert bool(said) == warned, texts
        if warned:
            assert "after 1 pause(s) in the scans the next scan did not fit" in said[0]
            assert "the longest 3.00 s at 3.9 s into the log" in said[0]


def test_calibrate_on_a_log_without_odometry(tmp_path, capsys):
    """``slam data calibrate`` on raw scans alone: it says the laser odometry stands in, does not
    measure a mount against it, and prints the warning as ``slam run`` does."""
    log_path = tmp_path / "raw.clf"
    log_path.write_text("\n".join(rawlaser_lines(room_path(120))) + "\n")
    assert main(["data", "calibrate", str(log_path)]) == 0
    captured = capsys.readouterr()
    assert "odometry  none of the log's: laser odometry (scan matching) stands in" in captured.out
    assert "not measured: laser odometry turns with the laser" in captured.out
    assert captured.err.startswith("slam: warning: raw: the log has no odometry")
    assert main(["data", "calibrate", str(log_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["odometry_source"] == "laser" and report["mount"] is None
    assert report["odometry_steps"]["pairs"] == 119


def test_inspect_says_which_odometry_a_run_reads(tmp_path, capsys):
    raw = tmp_path / "raw.clf"
    raw.write_text("\n".join(rawlaser_lines(room_path(20))) + "\n")
    still = tmp_path / "still.clf"
    still.write_text("\n".join(flaser_lines(room_path(20), odometry=False)) + "\n")
    moving = tmp_path / "moving.clf"
    moving.write_text("\n".join(flaser_lines(room_path(20), odometry=True)) + "\n")
    said = {}
    for log in (raw, still, moving):
        assert main(["data", "inspect", str(log)]) == 0
        said[log.stem] = capsys.readouterr().out.splitlines()[-2]
    assert said["raw"] == "slam run reads: odometry none in the log: laser odometry (scan matching)"
    assert said["still"].endswith("the scans' poses never move: laser odometry (scan matching)")
    assert said["moving"] == "slam run reads: odometry the poses written with the scans"


def test_dead_reckoning_of_a_log_without_odometry_is_its_laser_odometry(tmp_path):
    """``slam run --method odometry`` on raw scans alone draws the laser odometry, one pose per
    scan, as the filter would receive it."""
    truth = room_path(60)
    log_path = tmp_path / "raw.clf"
    log_path.write_text("\n".join(rawlaser_lines(truth)) + "\n")
    out = tmp_path / "dr"
    args = ["run", str(log_path), "--out", str(out), "--method", "odometry", "--quiet"]
    assert main([*args, "--no-texture", "--no-record"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["odometry_source"] == "laser"
    got = read_tum(out / "trajectory.tum")
    with pytest.warns(DataWarning, match="the log has no odometry"):
        scans = LogScans.from_log(load_carmen(log_path), slam.load_config(""))
    np.testing.assert_array_equal(got.times, scans.times)
    np.testing.assert_allclose(got.poses, scans.odometry, atol=1e-6)  # TUM's printed digits
    assert np.abs(got.poses[:, :2] - in_first_frame(truth)[:, :2]).max() < 0.05


def test_still_scan_poses_give_way_to_moving_odometry_messages(tmp_path, capsys):
    """FLASER lines whose poses are all zero beside ODOM lines that move: the messages at the
    scans' times are the odometry (with a warning), not the laser's."""
    truth = room_path(60)
    lines = flaser_lines(truth, odometry=False)
    lines += [f"ODOM {x:.6f} {y:.6f} {th:.6f} 0 0 0 {100.0 + 0.1 * k:.6f} h {100.0 + 0.1 * k:.6f}"
              for k, (x, y, th) in enumerate(truth)]  # fmt: skip
    log_path = tmp_path / "still_with_odom.clf"
    log_path.write_text("\n".join(lines) + "\n")
    with pytest.warns(DataWarning, match="the odometry messages at the scans' times stand in"):
        scans = LogScans.from_log(load_carmen(log_path), slam.load_config(""))
    assert scans.odometry_source == "log"
    np.testing.assert_allclose(scans.odometry, truth, atol=1e-6)
    assert main(["data", "inspect", str(log_path)]) == 0
    assert "odometry the odometry messages at the scans' times" in capsys.readouterr().out


def test_aces_turn_during_its_pause_is_found_from_the_scans(carmen_dir):
    """aces' bag pauses for 3 s at 539.7 s while the robot turns 76° (its wheels: −1.326 rad).
    Read without its odometry, the scan after the pause fits nowhere by half its returns; the
    search over every heading finds the turn to 7.5° (−1.456 rad), which explains more of the
    scan than the constant-velocity start (−0.403 rad, kept before the rule)."""
    from slam.io.rosbag import load_bag

    log = load_bag(carmen_dir / "bags" / "aces.orig.bag")
    wheels = LogScans.from_log(log, slam.load_config(""))
    with pytest.warns(DataWarning, match="the longest 3.03 s at 539.7 s into the log"):
        laser = LogScans.from_log(log, slam.load_config("", None, ['robot.odometry="laser"']))
    pause = int(scan_pauses(laser.times)[0])
    assert pause == 2944 and laser.laser_odometry["kept_prediction"] == 0
    step = relative(laser.odometry[pause], laser.odometry[pause + 1])
    truth = relative(wheels.odometry[pause], wheels.odometry[pause + 1])
    assert abs(step[2] - truth[2]) < 0.15  # the start was 0.92 rad off
    assert np.hypot(*(step[:2] - truth[:2])) < 0.15


def zigzag_path(n: int, turn: float = 0.12, block: int = 6) -> np.ndarray:
    """``(n, 3)`` poses through the room: 5 cm ahead per scan, the heading turning by ``turn``
    (rad) per scan, its sign reversed every ``block`` scans (so a constant velocity mispredicts
    every reversal by twice ``turn``)."""
    steps = turn * np.where((np.arange(n) // block) % 2 == 0, 1.0, -1.0)
    theta = np.concatenate([[0.0], np.cumsum(steps[1:])])
    x = -3.0 + np.concatenate([[0.0], np.cumsum(0.05 * np.cos(theta[1:]))])
    y = -1.0 + np.concatenate([[0.0], np.cumsum(0.05 * np.sin(theta[1:]))])
    return np.stack([x, y, theta], axis=1)


def gyro_for(truth: np.ndarray, times: np.ndarray, sign: float = 1.0) -> tuple[np.ndarray, ...]:
    """Gyro z samples at 100 Hz whose (trapezoidal) integral turns the robot as ``truth`` does
    between the scans at ``times`` (the rate constant between two scans), times ``sign``."""
    samples = np.round(np.arange(times[0], times[-1] + 0.05, 0.01), 9)
    heading = np.unwrap(truth[:, 2])
    ahead, behind = (
        np.interp(samples + 0.005, times, heading),
        np.interp(samples - 0.005, times, heading),
    )
    return samples, sign * (ahead - behind) / 0.01


def gyro_config() -> slam.Config:
    return slam.load_config("", None, ["robot.imu_lowpass_hz=0"])


def test_the_gyro_turns_the_prediction_where_a_constant_velocity_misses():
    """Zig-zag turns of 0.12 rad per scan: the constant-velocity start is 0.24 rad off at every
    reversal and does not fit (10 searches); the gyro's turn puts every start on the path, so
    nothing is searched. Both follow the path to 9–11 cm and 0.3–0.9° (the room's walls seen
    at a grazing angle let the matches slide)."""
    truth = zigzag_path(60)
    times = 0.1 * np.arange(60)
    scans = [room_scan(p, t) for p, t in zip(truth, times, strict=True)]
    config = gyro_config()
    alone = LaserOdometry(config)
    poses_alone = np.array([alone.pose_at(s) for s in scans])
    gyro = slam.odometry.OdometryIntegrator(config.robot)
    gyro.add_imu(*gyro_for(truth, times))
    with_gyro = LaserOdometry(config, gyro)
    poses = np.array([with_gyro.pose_at(s) for s in scans])
    assert alone.unfit == [1, 6, 12, 18, 24, 30, 36, 42, 48, 54] and alone.searched == 10
    assert with_gyro.unfit == [] and with_gyro.searched == 0
    assert with_gyro.gyro_turns == 59 and with_gyro.gyro_set_aside_at is None
    correlation, ratio = with_gyro.gyro_agreement
    assert correlation > 0.99 and abs(ratio - 1.0) < 0.05
    for got in (poses, poses_alone):
        error = got - in_first_frame(truth)
        assert np.abs(error[:, :2]).max() < 0.12 and np.abs(error[:, 2]).max() < 0.02


def test_a_turn_in_a_gap_is_measured_by_the_gyro():
    """The robot turns 60° in place in a second in which the log records nothing (the search's
    test above): without the gyro the start is 60° off, the two scans after the pause do not
    fit and four searches (two over every heading) find the turn; with the gyro the start is
    turned by 59.7° (its samples' trapezoid), only the first scan after the pause misses the
    half of its returns (the view turned to walls the local map holds sparsely) and one search
    of ± 20° places it."""
    truth = room_path(40)
    turned = truth[-1] + np.array([0.0, 0.0, np.pi / 3])
    truth = np.vstack([truth, turned, turned + np.array([0.05 * np.cos(turned[2]), 0, 0])])
    times = np.concatenate([0.1 * np.arange(40), [4.9, 5.0]])
    config = gyro_config()
    gyro = slam.odometry.OdometryIntegrator(config.robot)
    gyro.add_imu(*gyro_for(truth, times))
    assert gyro.gyro_heading(4.9) - gyro.gyro_heading(3.9) == pytest.approx(np.pi / 3, abs=0.006)
    for turns, unfit, searched in ((None, [40, 41], 4), (gyro, [40], 1)):
        odometry = LaserOdometry(config, turns)
        poses = [odometry.pose_at(room_scan(p, t)) for p, t in zip(truth, times, strict=True)]
        error = np.array(poses) - in_first_frame(truth)
        assert odometry.unfit == unfit and odometry.searched == searched
        assert np.abs(error[40:, 2]).max() < 0.005
        assert np.abs(error[40:, :2]).max() < 0.12


@pytest.mark.parametrize(
    ("factor", "rule"),
    [(-1.0, "reversed"), (0.0, "dead"), (np.degrees(1.0), "degrees")],
)
def test_a_gyro_that_does_not_read_the_yaw_is_set_aside(factor, rule):
    """A gyro that reads backwards (an IMU upside down, its frame not saying so), nothing, or in
    degrees per second: where its start does not fit, the previous turn's is taken, so it costs
    no match (the starts that miss are the reversals every 10th scan, as without a gyro), and
    after 20 turning scans it is set aside by its rule; the scans carry the path on."""
    truth = zigzag_path(120, turn=0.05, block=10)
    times = 0.1 * np.arange(120)
    config = gyro_config()
    samples, rates = gyro_for(truth, times)
    gyro = slam.odometry.OdometryIntegrator(config.robot)
    gyro.add_imu(samples, factor * rates)
    odometry = LaserOdometry(config, gyro)
    poses = np.array([odometry.pose_at(room_scan(p, t)) for p, t in zip(truth, times, strict=True)])
    correlation, ratio = odometry.gyro_agreement
    assert odometry.gyro_set_aside_at == 20 and odometry.gyro_turns == 20
    assert odometry.counts()["gyro_set_aside_at"] == 20
    if rule == "reversed":
        assert correlation < -0.99 and abs(ratio - 1.0) < 0.05
    elif rule == "dead":
        assert correlation == 0.0 and ratio == 0.0
    else:
        assert correlation > 0.99 and abs(ratio - 57.3) < 1.0
    assert set(odometry.unfit) <= set(range(10, 120, 10))
    error = poses - in_first_frame(truth)
    assert np.abs(error[:, :2]).max() < 0.08 and np.abs(error[:, 2]).max() < 0.013
    off = LaserOdometry(slam.load_config("", None, ["robot.laser_odometry_gyro=false"]), gyro)
    assert off.gyro is None and "gyro_turns" not in off.counts()


def test_the_gyro_heading_reads_only_samples_up_to_the_time():
    """``gyro_heading(t)``: the last sample's integral at or before ``t`` moved on at its rate;
    None before the first sample and beyond ``robot.max_imu_gap_s`` after the last one."""
    config = gyro_config()
    gyro = slam.odometry.OdometryIntegrator(config.robot)
    gyro.add_imu([1.0, 1.1, 1.2], [1.0, 2.0, 3.0])
    assert gyro.has_imu and not gyro.has_encoders
    assert gyro.gyro_heading(0.99) is None
    assert gyro.gyro_heading(1.0) == 0.0
    assert gyro.gyro_heading(1.05) == pytest.approx(0.05)  # not the trapezoid's 0.0625
    assert gyro.gyro_heading(1.2) == pytest.approx(0.15 + 0.25)
    assert gyro.gyro_heading(1.25) == pytest.approx(0.40 + 0.15)
    assert gyro.gyro_heading(1.2 + config.robot.max_imu_gap_s + 1e-6) is None


def cartographer_like_bag(path: Path, truth: np.ndarray, times: np.ndarray, imu_tf: bool) -> Path:
    """A bag as Cartographer's 2D demo bags are: MultiEchoLaserScan scans of the room (two
    echoes a beam), a 100 Hz IMU and no odometry. The IMU is mounted upside down (rolled by π,
    so its z rate is minus the robot's); ``imu_tf`` says so in /tf_static, or not."""
    from bagfixtures import BagContent, Imu, Tf, write_ros1_bag
    from bagfixtures import Scan as BagScan

    content = BagContent()
    for pose, t in zip(truth, times, strict=True):
        content.scans.append(BagScan(t=float(t), ranges=ray_cast(pose, ANGLES).tolist(), echoes=2))
    for t, rate in zip(*gyro_for(truth, times), strict=True):
        content.imu.append(Imu(t=float(t), gyro=(0.0, 0.0, -float(rate))))
    content.tf.append(Tf(t=times[0], parent="base_link", child="laser", static=True))
    if imu_tf:
        flip = (1.0, 0.0, 0.0, 0.0)  # rolled by π
        content.tf.append(
            Tf(t=times[0], parent="base_link", child="imu_link", quaternion=flip, static=True)
        )
    return write_ros1_bag(path, content)


def test_slam_run_on_a_bag_of_multi_echo_scans_and_an_imu(tmp_path, capsys):
    """``slam run`` on a bag of MultiEcho scans, an IMU and no odometry (Cartographer's demo bags'
    shape): laser odometry turns with the gyro, read in the robot frame through /tf_static,
    searching nowhere on the zig-zag path; without the IMU's mount in the bag its rate reads
    backwards, and the gyro is set aside with a warning after 20 turning scans."""
    truth = zigzag_path(60)
    times = 100.0 + 0.1 * np.arange(60)
    for imu_tf in (True, False):
        bag = cartographer_like_bag(tmp_path / f"museum-{imu_tf}.bag", truth, times, imu_tf)
        out = tmp_path / f"run-{imu_tf}"
        args = ["run", str(bag), "--out", str(out), "--quiet", "--no-texture", "--no-record"]
        assert main([*args, "--set", "robot.imu_lowpass_hz=0"]) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        counts = metrics["laser_odometry"]
        err = capsys.readouterr().err
        assert metrics["odometry_source"] == "laser" and counts["matched"] == 59
        if imu_tf:
            assert counts["gyro_turns"] == 59 and "gyro_set_aside_at" not in counts
            assert counts["gyro_correlation"] > 0.99 and abs(counts["gyro_ratio"] - 1.0) < 0.05
            assert "gyro" not in err
        else:
            assert counts["gyro_set_aside_at"] == 20 and counts["gyro_correlation"] < -0.9
            assert "the gyro's turns disagree with the scans' (correlation -1.00, 1.00 times" in err
        got = read_tum(out / "trajectory.tum")
        assert np.abs(got.poses[:, :2] - in_first_frame(truth)[:, :2]).max() < 0.12
    assert main(["data", "inspect", str(bag)]) == 0
    said = capsys.readouterr().out
    assert "(MultiEchoLaserScan: first echoes), odometry none (laser odometry)" in said
    assert "IMU /imu (its gyro turns the laser odometry)" in said


def test_online_encoders_decide_at_the_first_scan():
    """Encoder readings fed only after scans without them would switch the odometry mid-run: a
    ``UsageError``; with ``robot.odometry = "laser"`` they are not read at all."""
    truth = room_path(4)
    s = slam.Slam(slam.load_config(""))
    s.update(room_scan(truth[0], 0.0))
    s.add_encoders(0.05, np.zeros(4))
    with pytest.raises(UsageError, match="earlier scans came without odometry"):
        s.update(room_scan(truth[1], 0.1))
    laser = slam.Slam(slam.load_config("", None, ['robot.odometry="laser"']))
    laser.add_encoders(-0.05, np.zeros(4))
    for k in range(3):
        laser.update(room_scan(truth[k], 0.1 * k))
    assert laser.finish().stats["laser_odometry"]["matched"] == 2


def test_a_run_refused_for_memory_names_the_laser_odometrys_extent(tmp_path, capsys):
    """The maps' size follows the odometry's extent; a run on laser odometry refused for memory
    says how far it spans and that laser odometry can run away (a lost one went 5.7 km off)."""
    log_path = tmp_path / "raw.clf"
    log_path.write_text("\n".join(rawlaser_lines(room_path(60))) + "\n")
    args = ["run", str(log_path), "--out", str(tmp_path / "r"), "--particles", "100000",
            "--set", "checks.max_memory_share=0.01", "--no-record", "--quiet"]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("slam: error: raw (its odometry spans 3.0 m × 0.1 m; laser odometry")
    assert "can run away" in err and not (tmp_path / "r").exists()
