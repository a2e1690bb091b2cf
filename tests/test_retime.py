"""Relations of a log that lost its times, re-timed onto its scans (slam.eval.retime)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from slam.config import load_config
from slam.errors import DataError
from slam.eval.retime import format_relations, relation_period, retime_relations
from slam.geometry import relative
from slam.io.relations import Relations, read_relations

PERIOD = 0.4392  # mit-killian's laser


def _times_with_gaps(rng, scans, period, every=(1, 2, 3, 4, 5), pause_at=None, pause=0.0):
    """Original scan times of scans at a steady ``period`` (jitter ±0.7 % of it, as
    mit-killian's ±3 ms), the indices of a
    subset with gaps of ``every`` scans, and a logger pause of ``pause`` s after ``pause_at``."""
    times = 5000.0 + period * np.arange(scans) + rng.uniform(-0.007, 0.007, scans) * period
    if pause_at is not None:
        times[pause_at:] += pause
    picks = [int(rng.integers(0, 5))]
    while picks[-1] + max(every) < scans:
        picks.append(picks[-1] + int(rng.choice(every)))
    return times, np.array(picks)


def test_the_period_is_read_from_the_gaps():
    rng = np.random.default_rng(1)
    times, picks = _times_with_gaps(rng, 2000, PERIOD)
    assert relation_period(times[picks], 2000) == pytest.approx(PERIOD, abs=2e-5)


def test_only_even_gaps_still_give_the_scan_period_when_the_log_has_the_scans():
    """Gaps of 2, 4 and 6 scans look like a period of 2 P; the log's scan count rules it out
    for every submultiple but P itself."""
    rng = np.random.default_rng(2)
    times, picks = _times_with_gaps(rng, 3000, PERIOD, every=(2, 4, 6))
    assert relation_period(times[picks], 3000) == pytest.approx(PERIOD, abs=2e-5)
    # a log of half as many scans can only be the double period
    half = picks[-1] // 2 + 1
    assert relation_period(times[picks], half) == pytest.approx(2 * PERIOD, abs=4e-5)


def test_times_that_are_not_scan_times_are_refused():
    rng = np.random.default_rng(3)
    times = np.sort(rng.uniform(0.0, 1000.0, 500))
    with pytest.raises(
        DataError, match=r"^r\.relations: only .* whole multiples of a period .*not"
    ):
        relation_period(times, 10000, where="r.relations")
    with pytest.raises(DataError, match=r"more than the log's 100 scans"):
        relation_period(PERIOD * np.arange(0, 400, 2.0), 100)


def test_relations_that_never_turn_cannot_be_placed_and_the_file_is_named(tmp_path):
    """Over a straight stretch every offset gives the same relative motions: relations without
    a turn leave the segment unplaced, and the refusal names the relations file and why."""
    rng = np.random.default_rng(5)
    times, picks = _times_with_gaps(rng, 500, PERIOD)
    first, second = picks[:-1], picks[1:]
    relations = Relations(
        t1=times[first], t2=times[second], x=0.4 * (second - first), y=0.0 * first,
        yaw=0.0 * first, source=tmp_path / "straight.relations",
    )  # fmt: skip

    def never(k):
        raise AssertionError("no scan is registered without turning relations")

    synthetic = 1e9 + 0.1 * np.arange(500)
    with pytest.raises(DataError, match=r"straight\.relations: no segment .*0 turning relations"):
        retime_relations(relations, synthetic, np.zeros((500, 3)), never, load_config())


@pytest.fixture(scope="module")
def simulated():
    """The simulator's demo (4960 scans at 40 Hz, true poses): its ranges, angles and laser
    mount, and the true poses of the robot at each scan."""
    from slam.sim.dataset import SimOptions, simulate_log

    log = simulate_log(SimOptions(scenario="demo", rgbd=False))
    truth = log.scene.trajectory.pose_at(log.lidar_time)
    return log, truth


def test_relations_are_put_back_on_the_scans_they_were_made_on(simulated):
    """Relations between true poses at original times (every 16th scan of the demo, 2.5 Hz as
    mit-killian's 2.3 Hz, with a logger pause of 0.37 periods after scan 150), on a copy of the
    log whose times are synthetic: every one lands on its scans, the pause starts a second
    segment placed on its own."""
    log, truth = simulated
    lidar = log.options.lidar
    rows = np.arange(0, truth.shape[0], 16)
    truth = truth[rows]
    n = rows.size
    rng = np.random.default_rng(4)
    period = 16.0 / lidar.rate_hz
    original, picks = _times_with_gaps(rng, n, period, pause_at=150, pause=0.37 * period)
    picks = picks[(picks >= 3) & (picks < n - 3)]
    first, second = picks[:-1], picks[1:]
    motions = relative(truth[first], truth[second])
    relations = Relations(
        t1=original[first], t2=original[second], x=motions[:, 0], y=motions[:, 1],
        yaw=motions[:, 2],
    )  # fmt: skip
    angles = lidar.angles()
    keep = np.arange(0, angles.size, 6)  # 181 beams are plenty to register a pair

    def hits_of(k):
        r = log.ranges[rows[k], keep].astype(np.float64)
        ok = np.isfinite(r) & (r > lidar.range_min) & (r < lidar.range_max)
        a = angles[keep][ok]
        return r[ok] * np.cos(a) + lidar.x, r[ok] * np.sin(a)

    drift = np.cumsum(rng.normal(0.0, [0.01, 0.01, 0.005], size=(n, 3)), axis=0)
    synthetic = 1e9 + 0.1 * np.arange(n)
    config = load_config("demo", None, [])
    retimed = retime_relations(relations, synthetic, truth + drift, hits_of, config)
    report = retimed.report()
    assert report["relations"] == len(relations)
    second_start = int(picks[picks >= 150][0])
    assert [s["offset"] for s in report["segments"]] == [int(picks[0]), second_start]
    assert report["period_s"] == pytest.approx(period, rel=1e-4)
    i, j = retimed.scan_index
    np.testing.assert_array_equal(i, first)
    np.testing.assert_array_equal(j, second)
    np.testing.assert_array_equal(retimed.relations.t1, synthetic[first])
    for segment in report["segments"]:
        assert segment["runner_up_deg"] >= 2.0 * segment["best_deg"]


def test_written_relations_read_back_exactly(tmp_path):
    rel = Relations(
        t1=np.array([1e9 + 0.1, 1e9 + 0.30000000000000004]),
        t2=np.array([1e9 + 0.5, 1e9 + 0.7]),
        x=np.array([0.44464, -1.0 / 3.0]),
        y=np.array([0.00051, 2.0]),
        yaw=np.array([-0.0008, np.pi]),
    )
    path = tmp_path / "r.relations"
    path.write_text(format_relations(rel))
    back = read_relations(path)
    for name in ("t1", "t2", "x", "y", "yaw"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rel, name))


def test_mit_killian_relations_are_retimed_and_cached(data_dir, tmp_path, monkeypatch):
    """The shared mit-killian copy's relations land on its scans: one steady period (0.4392 s),
    the first relation time at scan 20, the winning offset's turns 4 times closer to the
    relations' than the runner-up's; the copy is cached and made once."""
    from slam.eval.retime import relations_file
    from slam.io import sources

    if not (data_dir / "carmen" / "mit-killian-synthtime.clf.gz").is_file():
        pytest.skip(f"{data_dir}/carmen/mit-killian-synthtime.clf.gz is absent")
    monkeypatch.setenv("SLAM_CACHE_DIR", str(tmp_path / "cache"))
    ref = sources.resolve("mit-killian", data_dir)
    assert ref.relations_retime
    path = relations_file(ref)
    assert path == tmp_path / "cache" / "relations" / "mit-killian.retimed.relations"
    report = json.loads(path.with_suffix(".json").read_text())
    assert report["period_s"] == pytest.approx(0.43919, abs=1e-5)
    assert report["relations"] == 4677
    (segment,) = report["segments"]
    assert segment["offset"] == 20 and segment["pairs"] >= 50
    assert segment["runner_up_deg"] >= 4.0 * segment["best_deg"]
    assert segment["best_deg"] < 0.3
    rel = read_relations(path)
    steps = np.round((rel.t1 - 1e9) / 0.1)
    assert steps.min() >= 20 and np.round((rel.t2 - 1e9) / 0.1).max() <= 17479
    stamp = os.stat(path).st_mtime_ns
    assert relations_file(ref) == path and os.stat(path).st_mtime_ns == stamp  # cached
    # an intel relations file is its own: never re-timed
    assert (
        relations_file(sources.resolve("intel", data_dir))
        == data_dir / "carmen/relations/intel.relations"
    )
