"""The online ``Slam`` object: online == batch bit for bit, the ECE276A inputs, the API's rules."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import slam
from slam.errors import ConfigError, UsageError
from slam.eval.trajectory import evaluate_against_reference
from slam.io.log import Log
from slam.io.tum import read_tum
from slam.odometry import (
    OdometryIntegrator,
    OdometryWarning,
    dead_reckon_ece276a,
    scan_odometry,
)
from slam.pipeline import load_source
from slam.scans import nominal_scan_period
from slam.stages import (
    BetweenUpdates,
    FinalMap,
    OdometrySmoothing,
    Reregistration,
    ScanRegistration,
    default_stages,
)


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """The simulator's small loop (30 s, no RGB-D, ~1200 scans at 40 Hz) with ground truth."""
    from slam.sim.dataset import SimOptions, generate_dataset

    folder = tmp_path_factory.mktemp("online") / "small"
    generate_dataset(folder, SimOptions(scenario="small", seed=7, duration=30.0, rgbd=False))
    return folder


def _log(name: str, config: slam.Config, data_dir: Path = Path(".")) -> Log:
    return load_source(name, data_dir, config).log


def replay(
    log: Log, config: slam.Config, count: int, seed: int = 0, during=None, **kwargs
) -> slam.Result:
    """What a user does with raw arrays: one Scan per reading, the log's odometry, update();
    ``during(s, k)``, when given, after each update ``k``."""
    scans = log.scans
    odometry = scan_odometry(log, config.robot)
    n = min(count, len(scans))
    s = slam.Slam(config, seed=seed, scan_period=nominal_scan_period(scans.time[:n]), **kwargs)
    for k in range(n):
        scan = slam.Scan(
            time=scans.time[k],
            ranges=scans.ranges[k],
            angles=scans.scan_angles(k),
            range_min=scans.range_min,
            range_max=scans.range_max,
            no_return=scans.no_return,
            laser_offset=scans.laser_offset,
            index=k,
        )
        estimate = s.update(scan, odometry=odometry[k])
        assert estimate.step == k and estimate.scan_index == k
        if during is not None:
            during(s, k)
    return s.finish()


def assert_identical(online: slam.Result, batch: slam.Result) -> None:
    np.testing.assert_array_equal(online.trajectory.times, batch.trajectory.times)
    np.testing.assert_array_equal(online.trajectory.poses, batch.trajectory.poses)
    np.testing.assert_array_equal(online.trajectory.scan_indices, batch.trajectory.scan_indices)
    np.testing.assert_array_equal(online.grid.log_odds, batch.grid.log_odds)
    np.testing.assert_array_equal(online.grid.origin, batch.grid.origin)
    np.testing.assert_array_equal(online.n_eff, batch.n_eff)
    np.testing.assert_array_equal(online.max_weight, batch.max_weight)
    assert online.stats == batch.stats


@pytest.mark.parametrize("method", ["rbpf", "classic"])
def test_online_equals_batch_bit_for_bit_on_a_simulated_log(small, method):
    config = slam.load_config("", None, [f'filter.method="{method}"', "filter.particles=16"])
    batch = slam.run(str(small), config, seed=3, max_scans=400)
    online = replay(_log(str(small), config), config, 400, seed=3)
    assert len(online.trajectory) == 400
    assert_identical(online, batch)
    assert batch.metrics["ate_rmse"] < (0.05 if method == "rbpf" else 0.5)


def test_the_vacancy_grid_option_runs_online_as_in_batch(small):
    """``rbpf.vacate_after`` (off by default): the filter keeps its vacancy grid, written at
    every update, and the online run still equals the batch run bit for bit."""
    config = slam.load_config("", None, ["filter.particles=16", "rbpf.vacate_after=2"])
    batch = slam.run(str(small), config, seed=3, max_scans=400)
    grids = []
    online = replay(
        _log(str(small), config), config, 400, seed=3,
        during=lambda s, k: grids.append(s._filter.vacancy) if k == 399 else None,
    )  # fmt: skip
    assert_identical(online, batch)
    assert batch.metrics["ate_rmse"] < 0.05
    state = grids[0].layers[0]
    assert int((state == 1).sum()) > 500  # the walls' hits, live
    assert int((state == 2).sum()) > 0  # and a few that later rays went through
    assert batch.stats["vacancy_live_hits"] == int((state == 1).sum())
    assert batch.stats["vacancy_gone_hits"] == int((state == 2).sum())
    assert batch.stats["vacancy_grid_mb"] == round(grids[0].memory_bytes() / 2**20, 1)


@pytest.fixture(scope="module")
def intel(carmen_dir) -> Log:
    return _log("intel", slam.load_config("intel"), carmen_dir.parent)


@pytest.mark.parametrize("method", ["rbpf", "classic"])
def test_online_equals_batch_bit_for_bit_on_intel(carmen_dir, intel, method):
    config = slam.load_config("intel", None, [f'filter.method="{method}"'])
    batch = slam.run("intel", config, seed=0, max_scans=500, data_dir=carmen_dir.parent)
    online = replay(intel, config, 500)
    assert_identical(online, batch)
    if method == "rbpf":  # the committed regression reference of these 500 scans
        reference = read_tum(Path(__file__).parent.parent / "data/reference/slam/intel-rbpf.tum")
        in_time_order = online.trajectory.sorted_by_time()  # trajectory.tum is in time order
        assert np.array_equal(in_time_order.times, reference.times)
        assert np.abs(in_time_order.poses[:, :2] - reference.poses[:, :2]).max() < 1e-5


class Recorder:
    """An observer keeping every record and map it is sent."""

    def __init__(self, detail_every: int, map_every: int) -> None:
        self.detail_every, self.map_every = detail_every, map_every
        self.records: list[slam.StepRecord] = []
        self.maps: list[int] = []

    def on_step(self, record: slam.StepRecord) -> None:
        self.records.append(record)

    def on_map(self, step: int, time: float, grid) -> None:
        self.maps.append(step)


def test_estimates_and_observers_follow_every_step(small):
    config = slam.load_config("", None, ["filter.particles=12"])
    log = _log(str(small), config)
    watcher = Recorder(detail_every=10, map_every=25)
    s = slam.Slam(config, seed=1, observers=[watcher])
    odometry, scans = scan_odometry(log, config.robot), log.scans
    estimates = []
    for k in range(120):
        scan = slam.Scan(scans.time[k], scans.ranges[k], scans.angles, no_return=scans.no_return)
        estimates.append(s.update(scan, odometry=odometry[k]))
    result = s.finish()
    assert [r.step for r in watcher.records] == list(range(120))
    for record, estimate in zip(watcher.records, estimates, strict=True):
        np.testing.assert_array_equal(record.pose, estimate.pose)
        assert record.updated == estimate.updated and record.n_eff == estimate.n_eff
        assert (record.particles is not None) == (record.step % 10 == 0)
    assert watcher.records[10].endpoints.shape[1] == 2
    updates = [e.step for e in estimates if e.updated]
    assert len(updates) == result.stats["updates"] and 5 < len(updates) < 60
    assert sum(e.resampled for e in estimates) == result.stats["resamples"]
    assert watcher.maps == [k for k in updates if k > 0 and k % 25 == 0]
    for e in estimates:
        assert e.covariance.shape == (3, 3)
        np.testing.assert_allclose(e.covariance, e.covariance.T, atol=1e-15)
        assert np.all(np.linalg.eigvalsh(e.covariance) > -1e-12)
        assert e.weights.sum() == pytest.approx(1.0)
    assert max(e.covariance[0, 0] for e in estimates) > 0  # the cloud spreads between updates
    # between updates the estimate moves the cloud by odometry
    moving = next(e for e in estimates[1:] if not e.updated)
    np.testing.assert_allclose(moving.particles[np.argmax(moving.weights)], moving.pose)


def test_observers_hear_the_filter_end_before_the_stages(small, tmp_path):
    """on_filter_end, where an observer defines it, comes once, after the last step and before
    the stages after the filter; observers without it (the progress bar) are passed over; the
    rerun recorder lets go of its preview map there."""
    from slam.observers import ProgressObserver
    from slam.viz.recorder import RunRecorder

    config = slam.load_config("", None, ["filter.particles=8", "viz.map_every=20"])
    log = _log(str(small), config)
    events: list[str] = []

    class Ends(Recorder):
        def on_step(self, record) -> None:
            super().on_step(record)
            events.append("step")

        def on_filter_end(self) -> None:
            events.append("end")

    class Stage:
        name = "probe"

        def run(self, output, config):
            events.append("stage")
            return output

    recorder = RunRecorder(tmp_path / "r.rrd", config.viz, map_config=config.map)
    recorder.detail_every = 10
    s = slam.Slam(config, seed=0, observers=[Ends(detail_every=10, map_every=0),
                                             ProgressObserver(60, enabled=False), recorder])  # fmt: skip
    s.stages = [*s.stages[:-1], Stage(), s.stages[-1]]
    odometry, scans = scan_odometry(log, config.robot), log.scans
    for k in range(60):
        scan = slam.Scan(scans.time[k], scans.ranges[k], scans.angles, no_return=scans.no_return)
        s.update(scan, odometry=odometry[k])
    assert recorder._preview is not None and recorder.maps >= 1  # snapshots during the filter
    result = s.finish()
    assert events == ["step"] * 60 + ["end", "stage"]
    assert recorder._preview is None
    assert recorder.finish(result.trajectory, result.grid)["maps"] == recorder.maps


def test_custom_stages_replace_the_default_ones(small):
    config = slam.load_config("", None, ["filter.particles=8", "filter.max_scans=200"])
    no_loops = slam.load_config("", None, ["filter.particles=8", "loops.enabled=false"])
    log = _log(str(small), config)
    measured: dict = {}
    stages = [
        Reregistration(),
        BetweenUpdates(),
        ScanRegistration(),
        OdometrySmoothing(measured),
        ScanRegistration(),  # rbpf.register_rounds = 2
        OdometrySmoothing(measured),
        FinalMap(),
    ]
    custom = replay(log, no_loops, 200, stages=stages)
    np.testing.assert_array_equal(custom.poses, replay(log, no_loops, 200).poses)
    assert "loop_candidates" not in custom.stats
    raw = replay(log, config, 200, stages=[BetweenUpdates(), FinalMap()])
    assert 0 < np.abs(raw.poses - custom.poses).max() < 0.1  # without re-registration: jitter
    # the time of each part: the filter, then every stage that ran, by its name, in order
    assert list(custom.seconds) == ["filter"] + list(dict.fromkeys(s.name for s in stages))
    assert list(raw.seconds) == ["filter", "between-update placement", "final map"]
    assert all(v >= 0.0 for v in custom.seconds.values()) and custom.seconds["filter"] > 0.0


def test_the_map_so_far_is_the_best_particles_and_changes_nothing(small):
    """``Slam.map()`` while the run goes on: the update scans at the best particle's ancestry —
    just before ``finish()``, the very grid :class:`FinalMap` builds from the filter's nodes —
    growing as the robot explores; calling it changes nothing in the run; before the first scan
    and after the end it is one clear error; ``classic``'s is a copy of its own grid."""
    config = slam.load_config("", None, ["filter.particles=8"])
    log = _log(str(small), config)
    stages = [BetweenUpdates(), FinalMap()]
    occupied: list[int] = []
    grids: list = []

    def look(s: slam.Slam, k: int) -> None:
        if k % 100 == 99:
            grids.append(s.map())
            occupied.append(int((grids[-1].log_odds > 0).sum()))

    watched = replay(log, config, 400, during=look, stages=stages)
    assert_identical(watched, replay(log, config, 400, stages=stages))
    np.testing.assert_array_equal(grids[-1].log_odds, watched.grid.log_odds)
    np.testing.assert_array_equal(grids[-1].origin, watched.grid.origin)
    assert 0 < occupied[0] < occupied[-1] and len(occupied) == 4
    s = slam.Slam(config)
    with pytest.raises(UsageError, match=r"Slam\.map: no scan was processed"):
        s.map()
    classic = slam.load_config("", None, ["filter.method=classic", "filter.particles=8"])

    def spoil(s: slam.Slam, k: int) -> None:
        if k == 59:
            grid = s.map()
            grid.log_odds[:] = 0.0
            assert np.abs(s.map().log_odds).max() > 0  # a copy: the filter's own is untouched

    replay(log, classic, 60, during=spoil)
    ended = slam.Slam(config)
    scan = log.scans
    ended.update(slam.Scan(scan.time[0], scan.ranges[0], scan.scan_angles(0)), odometry=[0, 0, 0])
    ended.finish()
    with pytest.raises(UsageError, match=r"Slam\.map: the run is finished"):
        ended.map()


def test_the_map_so_far_spans_the_robots_path_wherever_its_odometry_starts():
    """Odometry 5 km from its frame's origin (a robot's odometry need not start at 0): the map
    so far covers the room it drove through, not the 5 km back to the origin."""
    from synthetic_logs import path as room_path
    from synthetic_logs import ray_cast

    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    s = slam.Slam(slam.load_config("", None, ["filter.particles=8"]), seed=0)
    for k, pose in enumerate(room_path(40)):
        scan = slam.Scan(100.0 + 0.1 * k, ray_cast(pose, angles), angles)
        s.update(scan, odometry=pose + np.array([5000.0, -3000.0, 0.0]))
    grid = s.map()
    rows, cols = grid.shape
    assert rows * grid.resolution < 20.0 and cols * grid.resolution < 20.0  # the 10 m × 6 m room
    assert (grid.log_odds > 0).sum() > 100


def test_the_run_times_its_parts(small, tmp_path):
    """``metrics.json``'s ``estimate_parts_s``: the filter and each default stage; their sum is
    the estimate's time (compilation included, as each part counts what it compiled)."""
    overrides = ["filter.particles=8", "texture.enabled=false", "viz.record=false"]
    config = slam.load_config("", None, overrides)
    result = slam.run(str(small), config, seed=0, max_scans=150, out=tmp_path / "run")
    parts = result.metrics["estimate_parts_s"]
    # a stage run in several rounds (rbpf.register_rounds) counts once, its rounds added up
    assert list(parts) == ["filter"] + list(dict.fromkeys(s.name for s in default_stages(config)))
    assert parts == {k: round(v, 3) for k, v in result.seconds.items()}
    total = result.metrics["estimate_wall_s"] + result.metrics["estimate_compile_s"]
    assert 0.0 < sum(parts.values()) <= total + 0.01
    assert json.loads((tmp_path / "run" / "metrics.json").read_text())["estimate_parts_s"] == parts


def _feed_ece276a(s: slam.Slam, log: Log, k: int, cursors: list[int], arguments: bool) -> None:
    """Feed the encoder and IMU readings up to scan ``k``'s time, then the scan."""
    enc, imu, scans = log.encoders, log.imu, log.scans
    t = scans.time[k]
    i = int(np.searchsorted(imu.time, t, side="right"))
    e = int(np.searchsorted(enc.time, t, side="right"))
    gyro = (imu.time[cursors[0] : i], imu.angular_velocity[2, cursors[0] : i])
    ticks = (enc.time[cursors[1] : e], enc.counts[:, cursors[1] : e])
    cursors[:] = [i, e]
    scan = slam.Scan(t, scans.ranges[k], scans.angles, no_return=scans.no_return, index=k)
    if arguments:
        s.update(scan, encoders=ticks, imu=gyro)
    else:
        s.add_imu(*gyro)
        s.add_encoders(*ticks)
        s.update(scan)


def test_online_encoders_and_imu_track_the_batch_run(small):
    """ECE276A inputs online (causal odometry) against the batch run (zero-phase odometry)."""
    config = slam.load_config("", None, ["filter.particles=20"])
    truth = read_tum(small / "groundtruth.tum")
    batch = slam.run(str(small), config, seed=0)
    log = _log(str(small), config)
    s = slam.Slam(config, seed=0)
    cursors = [0, 0]
    for k in range(len(log.scans)):
        _feed_ece276a(s, log, k, cursors, arguments=k % 2 == 0)
    online = s.finish()
    ate = evaluate_against_reference(online.trajectory, truth)["ate_rmse"]
    assert len(online.trajectory) == len(batch.trajectory) == len(log.scans)
    # batch 0.011 m, online 0.025 m (seeds 0-3: batch 0.009-0.052, online 0.020-0.026)
    assert batch.metrics["ate_rmse"] < 0.02
    assert ate < batch.metrics["ate_rmse"] + 0.03
    assert "odometry_wheel_yaw_intervals" not in online.stats


def test_both_ways_of_feeding_readings_are_the_same(small):
    config = slam.load_config("", None, ["filter.particles=8", 'filter.method="classic"'])
    log = _log(str(small), config)
    results = []
    for arguments in (True, False):
        s = slam.Slam(config, seed=0)
        cursors = [0, 0]
        for k in range(60):
            _feed_ece276a(s, log, k, cursors, arguments)
        results.append(s.finish())
    np.testing.assert_array_equal(results[0].poses, results[1].poses)


def test_causal_integrator_without_low_pass_equals_batch_dead_reckoning(small):
    config = slam.load_config("", None, ["robot.imu_lowpass_hz=0"])
    log = _log(str(small), config)
    enc, imu = log.encoders, log.imu
    batch = dead_reckon_ece276a(enc, imu, config.robot)
    online = OdometryIntegrator(config.robot)
    online.add_imu(imu.time, imu.angular_velocity[2])
    online.add_encoders(enc.time, enc.counts)
    poses = np.array([online.pose_at(t) for t in enc.time])
    np.testing.assert_allclose(poses, batch.poses, atol=1e-9)
    # with the 10 Hz low-pass the causal filter lags: a few millimetres over the loop
    lagged = OdometryIntegrator(slam.Config().robot)
    lagged.add_imu(imu.time, imu.angular_velocity[2])
    lagged.add_encoders(enc.time, enc.counts)
    zero_phase = dead_reckon_ece276a(enc, imu, slam.Config().robot)
    end = lagged.pose_at(enc.time[-1])
    assert 0 < np.hypot(*(end[:2] - zero_phase.poses[-1, :2])) < 0.05


def test_integrator_extrapolates_one_interval_and_falls_back_to_wheel_yaw():
    robot = slam.Config().robot
    odo = OdometryIntegrator(robot)
    counts = np.full(4, 10)  # 10 ticks per wheel per 25 ms: straight ahead
    with pytest.warns(OdometryWarning, match="yaw comes from the wheels"):
        odo.add_encoders([0.0, 0.025], np.stack([counts, counts], axis=1))  # no IMU yet
    assert odo.wheel_yaw_intervals == 1
    step = 10 * robot.meters_per_tick
    np.testing.assert_allclose(odo.pose_at(0.0125), [0.5 * step, 0, 0], atol=1e-12)
    np.testing.assert_allclose(odo.pose_at(0.0375), [1.5 * step, 0, 0], atol=1e-12)
    np.testing.assert_allclose(odo.pose_at(5.0), [2 * step, 0, 0], atol=1e-12)  # then it stands
    with pytest.raises(slam.SlamError, match="comes after"):
        odo.add_encoders(0.01, counts)


def test_api_errors_are_one_clear_line(small):
    with pytest.raises(ConfigError, match="Slam runs the particle filters"):
        slam.Slam(slam.load_config("", None, ['filter.method="odometry"']))
    with pytest.raises(UsageError, match="expected a slam.Config"):
        slam.Slam("intel")  # type: ignore[arg-type]
    with pytest.raises(
        UsageError, match="odometry_source: expected 'log' or 'laser', found 'wheels'"
    ):
        slam.Slam(odometry_source="wheels")
    s = slam.Slam()
    with pytest.raises(UsageError, match="no scan was processed"):
        s.finish()
    strict = slam.Slam(slam.load_config("", None, ['robot.odometry="log"']))
    with pytest.raises(UsageError, match="give odometry"):
        strict.update(slam.Scan(0.0, [1.0], [0.0]))
    with pytest.raises(UsageError, match="expected a slam.Scan"):
        s.update(np.ones(3), odometry=np.zeros(3))  # type: ignore[arg-type]
    s.update(slam.Scan(0.0, [1.0, 1.0], [0.0, 0.1]), odometry=np.zeros(3))
    s.finish()
    with pytest.raises(UsageError, match="the run is finished"):
        s.update(slam.Scan(0.1, [1.0], [0.0]), odometry=np.zeros(3))
    with pytest.raises(UsageError, match="unknown option"):
        slam.run(str(small), particle=3)


def test_run_writes_the_run_folder_when_asked(small, tmp_path):
    result = slam.run(str(small), seed=2, particles=8, max_scans=80, out=tmp_path / "run",
                      overrides=["viz.record=false"])  # fmt: skip
    assert result.folder == tmp_path / "run"
    assert (tmp_path / "run" / "trajectory.tum").read_text().count("\n") == 81
    assert result.metrics["scans"] == 80 and result.metrics["seed"] == 2
    again = slam.run(str(small), seed=2, particles=8, max_scans=80)
    np.testing.assert_array_equal(again.poses, result.poses)
    assert again.folder is None


def test_import_slam_loads_neither_numba_nor_rerun():
    code = (
        "import sys, slam; assert 'numba' not in sys.modules and 'numpy' not in sys.modules; "
        "slam.Slam; assert 'numba' in sys.modules and 'rerun' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_causal_odometry_warns_once_when_it_uses_the_wheels():
    odo = OdometryIntegrator(slam.Config().robot)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        odo.add_encoders(np.arange(5) * 0.025, np.ones((4, 5)))
    assert odo.wheel_yaw_intervals == 4
    assert len([w for w in caught if "wheels" in str(w.message)]) == 1


def test_registration_rounds_measure_the_odometry_once(small, monkeypatch):
    """``rbpf.register_rounds``: the registration and the smoothing run that many times, the
    odometry's disagreement (a property of the log) is measured once, and each round moves the
    poses (the second starts from the first's smoothed poses and map)."""
    import slam.calibration as calibration

    calls = []
    real = calibration.odometry_disagreement

    def spy(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(calibration, "odometry_disagreement", spy)
    three = slam.load_config("", None, ["filter.particles=8", "rbpf.register_rounds=3"])
    names = [stage.name for stage in default_stages(three)]
    assert names.count("scan registration") == 3 and names.count("odometry smoothing") == 3
    log = _log(str(small), three)
    result = replay(log, three, 200)
    assert len(calls) == 1
    one = slam.load_config("", None, ["filter.particles=8", "rbpf.register_rounds=1"])
    single = replay(log, one, 200)
    assert len(calls) == 2  # a run of its own measures again
    assert 0 < np.abs(result.poses - single.poses).max() < 0.05
    # stage objects given to a second run measure that run's log, not the first one's
    measured: dict = {}
    stages = [BetweenUpdates(), ScanRegistration(), OdometrySmoothing(measured), FinalMap()]
    first = replay(log, one, 200, stages=stages)
    again = replay(log, one, 150, stages=stages)
    assert len(calls) == 4 and len(first.poses) == 200 and len(again.poses) == 150


def test_slam_run_keeps_a_given_config_over_the_datasets_file(carmen_dir, tmp_path):
    """``slam.run(name, config)`` with a key the dataset's shipped file also sets (fr-clinic's
    ``lidar.range_max``): the run uses the given value, and the beam step measured as the log
    loads is added to it, not in place of it."""
    config = slam.load_config("fr-clinic", None, ["lidar.range_max=8"])
    out = tmp_path / "run"
    slam.run("fr-clinic", config, max_scans=20, data_dir=carmen_dir.parent, out=out)
    used = slam.load_config("", out / "config.toml")
    assert used.lidar.range_max == 8.0
    assert used.lidar.beam_step_deg == 1.0  # measured: configs/fr-clinic.toml declares none
    assert used.dataset == "fr-clinic"


def test_an_exact_odometry_gets_a_finite_weight(small, monkeypatch):
    """A noise-free log can measure no disagreement at all between its odometry and its scans:
    the smoothing weighs its steps at the floor (``slam.stages.ODOMETRY_FLOOR``), finite, and
    the run ends with finite poses (an infinite weight divided by zero before)."""
    import slam.calibration as calibration

    monkeypatch.setattr(
        calibration,
        "odometry_disagreement",
        lambda *args, **kwargs: calibration.Disagreement(0.0, 0.0, 0.0, 100),
    )
    config = slam.load_config("", None, ["filter.particles=8"])
    result = replay(_log(str(small), config), config, 200)
    assert np.isfinite(result.poses).all()
    assert result.stats["odometry_disagreement_along_m"] == 0.0
