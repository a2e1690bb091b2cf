"""The stages after the filter (slam.stages): the final map, built once at its final size, equals
the grid that grows scan by scan, to the bit; the row-block pictures equal the whole-grid ones."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from synthetic_logs import carmen_lines, write_carmen

import slam.rowwise as rowwise
import slam.stages as stages
from slam.config import Config, MapConfig, load_config
from slam.io import sources
from slam.io.exports import clean_image
from slam.io.mapserver import trinary
from slam.mapping import OccupancyGrid
from slam.particle_filter import integrate_scan
from slam.scans import ScanSequence
from slam.stages import build_map
from slam.viz.images import occupancy_pixels


def growing_map(seq, poses, steps, config) -> OccupancyGrid:
    """The final map as a grid that grows with every scan and is cropped at the end."""
    grid = OccupancyGrid(config.map, center=(float(poses[0, 0]), float(poses[0, 1])))
    span = np.concatenate([poses[:, :2].min(axis=0) - 1.0, poses[:, :2].max(axis=0) + 1.0])
    grid.ensure_contains(*span)
    for k in steps:
        integrate_scan(grid, seq, int(k), poses[k])
    return grid.cropped(config.map.crop_margin_m)


def turning(seq: ScanSequence) -> np.ndarray:
    """The odometry moved off its lattice and turned a little more at every scan, so that the
    rays keep reaching past the grid grown so far (the map is a mess; the test is the bits)."""
    rng = np.random.default_rng(3)
    poses = seq.odometry.copy()
    poses[:, :2] += rng.normal(0.0, 0.05, (len(seq), 2))
    poses[:, 2] += 0.11 * np.arange(len(seq))
    return poses


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> tuple[ScanSequence, object]:
    """The synthetic box room as a scan sequence, with a map that starts small and grows by
    little, so that building it takes many growths in every direction."""
    path = write_carmen(tmp_path_factory.mktemp("room"), carmen_lines(60))
    config = load_config(
        "", None, ["map.initial_size_m=1.0", "map.grow_margin_m=0.0", "map.resolution=0.03"]
    )
    ref = sources.resolve(str(path), path.parent, where="test")
    log = sources.load(ref, config, ("scans",)).log
    return ScanSequence.from_log(log, config), config


@pytest.mark.parametrize("beams_at_once", [1 << 16, 7 * 181])
def test_final_map_equals_the_growing_grid_to_the_bit(room, monkeypatch, beams_at_once):
    """Whether the rays of the 30 scans are computed together or 7 scans at a time."""
    monkeypatch.setattr(stages, "_RAYS_AT_ONCE", beams_at_once)
    seq, config = room
    poses = turning(seq)
    steps = np.arange(0, len(seq), 2)
    got = build_map(seq, poses, steps, config)
    want = growing_map(seq, poses, steps, config)
    assert got.shape == want.shape and got.shape[0] * got.shape[1] > 10_000
    assert got.origin.tobytes() == want.origin.tobytes()
    assert got.log_odds.tobytes() == want.log_odds.tobytes()
    assert (got.log_odds > 0).sum() > 100 and (got.log_odds < 0).sum() > 1000


def test_pictures_by_blocks_of_rows_equal_the_whole(monkeypatch):
    rng = np.random.default_rng(5)
    log_odds = (rng.standard_normal((301, 257)) * 4).astype(np.float32)
    log_odds[rng.random(log_odds.shape) < 0.3] = 0.0
    grid = OccupancyGrid.from_arrays(log_odds, 0.05, np.array([1.0, -2.0]), MapConfig())

    def pictures():
        return [trinary(log_odds), clean_image(log_odds), occupancy_pixels(log_odds, 256),
                occupancy_pixels(log_odds[5:-3, 2:-9], 16), rowwise.grid_image(grid)]  # fmt: skip

    monkeypatch.setattr(rowwise, "BLOCK_CELLS", 1000)  # blocks of 3 rows, the last one shorter
    blocks = pictures()
    monkeypatch.setattr(rowwise, "BLOCK_CELLS", 1 << 40)  # one block: the whole grid
    whole = pictures()
    assert np.array_equal(whole[4], grid.to_image())
    for a, b in zip(blocks, whole, strict=True):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
    monkeypatch.setattr(rowwise, "BLOCK_CELLS", 1000)
    colour = rowwise.grid_image(grid, channels=3)  # what map.png draws on
    assert colour.flags.c_contiguous
    assert np.array_equal(colour, cv2.cvtColor(grid.to_image(), cv2.COLOR_GRAY2BGR))


def test_the_room_map_grows_many_times(room):
    """The test above is only worth something if the growing grid grows often."""
    from slam.stages import _growth_plan, _world_rays

    seq, config = room
    poses = turning(seq)
    steps = np.arange(0, len(seq), 2)
    start = OccupancyGrid(config.map, center=(float(poses[0, 0]), float(poses[0, 1])))
    span = np.concatenate([poses[:, :2].min(axis=0) - 1.0, poses[:, :2].max(axis=0) + 1.0])
    _, boxes = _world_rays(seq, poses, steps, config.map)
    plan, _ = _growth_plan(boxes, config.map, start, span)
    shapes = {(s[1], s[2]) for s in plan if s is not None}
    assert len(shapes) >= 3


def test_the_reregistration_uses_every_beam_unless_told(tmp_path):
    """rbpf.refine_beams = 0 (the default) registers each scan with all of its beams: on a
    360-beam room it gives the poses of refine_beams = 360, and others than the filter's 180,
    both closer to the true poses than the perturbed start."""
    from slam.stages import refine_trajectory

    path = write_carmen(tmp_path, carmen_lines(30, beams=360))
    ref = sources.resolve(str(path), path.parent, where="test")
    runs = {}
    for beams in (0, 360, 180):
        config = load_config("", None, [f"rbpf.refine_beams={beams}"])
        log = sources.load(ref, config, ("scans",)).log
        seq = ScanSequence.from_log(log, config)
        steps = np.arange(0, len(seq), 3)
        truth = seq.odometry[steps]  # the synthetic log's odometry is exact
        start = truth + np.random.default_rng(1).normal(0.0, [0.02, 0.02, 0.01], truth.shape)
        runs[beams] = refine_trajectory(seq, start, steps, config)
    assert seq.num_beams == 360
    assert np.array_equal(runs[0], runs[360])
    assert not np.array_equal(runs[0], runs[180])
    for got in runs.values():
        assert np.abs(got[:, :2] - truth[:, :2]).mean() < np.abs(start[:, :2] - truth[:, :2]).mean()


def test_scan_registration_corrects_the_scans_between_updates(tmp_path):
    """rbpf.register_scans: every scan is matched against the map of the node scans. Scans
    placed 3.6 cm and 2° off (an odometry error between updates) come back to the accuracy of
    the node scans themselves (the unsigned field's half-cell bias, about 1.5 cm on this room) and
    within a fifth of the angle; rbpf.register_scans = false leaves the output as it is."""
    from slam.particle_filter import FilterOutput
    from slam.stages import ScanRegistration

    path = write_carmen(tmp_path, carmen_lines(30, beams=180))
    ref = sources.resolve(str(path), path.parent, where="test")
    config = load_config("", None, [])
    seq = ScanSequence.from_log(sources.load(ref, config, ("scans",)).log, config)
    truth = seq.odometry.copy()  # the synthetic log's odometry is exact
    steps = np.arange(0, len(seq), 3)
    between = np.setdiff1d(np.arange(len(seq)), steps)
    placed = truth.copy()
    placed[between] += [0.03, -0.02, np.radians(2.0)]
    output = FilterOutput(seq, steps, truth[steps], np.ones(len(seq)), np.ones(len(seq)),
                          poses=placed)  # fmt: skip
    got = ScanRegistration().run(output, config)
    assert np.array_equal(got.node_poses, got.poses[steps])
    off = np.hypot(*(placed[between, :2] - truth[between, :2]).T).mean()
    err = np.hypot(*(got.poses[between, :2] - truth[between, :2]).T).mean()
    rot = np.abs(got.poses[between, 2] - truth[between, 2]).mean()
    nodes = np.hypot(*(got.poses[steps, :2] - truth[steps, :2]).T)
    assert off > 0.035 and err < 0.6 * off and err < nodes.mean() + 0.01, (off, err, nodes.mean())
    assert rot < np.radians(2.0) / 5, np.degrees(rot)
    assert nodes.max() < 0.03  # the nodes, exact at the start, stay within the field's bias
    off_config = load_config("", None, ["rbpf.register_scans=false"])
    assert ScanRegistration().run(output, off_config) is output


def _beams_scan_by_scan(seq: ScanSequence, scans, width: int):
    """registration_beams as it was written before it was vectorised: one scan at a time."""
    ex = np.zeros((len(scans), width))
    ey = np.zeros((len(scans), width))
    counts = np.zeros(len(scans), dtype=np.int64)
    for i, k in enumerate(scans):
        all_x, all_y = seq.scan(int(k)).endpoints()
        hit = ~np.isnan(all_x)
        n = int(np.count_nonzero(hit))
        if n > width:
            hx, hy = seq.hits(int(k), width)
            n = hx.size
            ex[i, :n], ey[i, :n] = hx, hy
        else:
            ex[i, :n], ey[i, :n] = all_x[hit], all_y[hit]
        counts[i] = n
    return ex, ey, counts


@pytest.mark.parametrize("most", [0, 1, 2, 7, 40, 61, 1000])
def test_registration_beams_give_what_each_scan_gives(most):
    """The vectorised extraction equals Scan.hits scan by scan, bit for bit: scans of different
    widths, invalid and no-return readings, thinned (evenly spread) and not."""
    from slam.scans import Scan
    from slam.stages import registration_beams

    rng = np.random.default_rng(3)
    seq = ScanSequence()
    for k in range(25):
        n = int(rng.choice([0, 1, 2, 30, 59, 60, 61]))
        ranges = rng.uniform(0.2, 12.0, n).astype(np.float32)
        ranges[rng.random(n) < 0.2] = np.nan
        ranges[rng.random(n) < 0.1] = 30.0  # beyond range_max: not a return
        angles = np.linspace(-1.5, 1.5, n) if n > 1 else np.zeros(n)
        scan = Scan(float(k), ranges, angles, 0.1, 20.0, 30.0, np.array([0.1, 0.02, 0.01]))
        seq.append(scan, np.array([0.1 * k, 0.0, 0.0]))
    config = load_config("", None, [f"rbpf.refine_beams={most}"])
    scans = np.array([3, 0, 24, 7, 7, 11, 19, 2], dtype=np.int64)
    width = max(1, min(most or seq.num_beams, seq.num_beams))

    def check(chosen):  # the selection and thinning (the endpoints' values: test_scans.py)
        got = registration_beams(seq, chosen, config)
        want = _beams_scan_by_scan(seq, chosen, width)
        for a, b in zip(got, want, strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape
            np.testing.assert_array_equal(a, b)

    check(scans)  # endpoints computed by the batch
    check(scans)  # known: copied
    empty = np.array([k for k in range(25) if not np.isfinite(seq.scan(k).endpoints()[0]).any()])
    assert empty.size > 0
    check(empty)  # a batch of scans with no return at all


@pytest.fixture(scope="module")
def long_room(tmp_path_factory) -> tuple[ScanSequence, object]:
    """120 scans along the synthetic room (6 m), with map-quality stretches of 1 m so that
    every stretch is judged against the others' map."""
    path = write_carmen(tmp_path_factory.mktemp("long_room"), carmen_lines(120))
    overrides = ["quality.stretch_m=1.0", "quality.separation_m=1.0", "rbpf.smooth_choice_every=1",
                 "rbpf.smooth_scales=[1.0, 10.0, 50.0]"]  # fmt: skip
    config = load_config("", None, overrides)
    ref = sources.resolve(str(path), path.parent, where="test")
    log = sources.load(ref, config, ("scans",)).log
    return ScanSequence.from_log(log, config), config


def test_the_map_quality_picks_the_odometry_where_it_is_the_better_shape(long_room):
    """The registered poses bent by a slow wave (a distorted node map) and an exact odometry:
    trusting the odometry's shape (the largest scale) scores best and is picked; the same
    poses exact and an odometry that curves away: the registration's own sigmas are kept."""
    from slam.stages import choose_smoothing

    seq, config = long_room
    truth = seq.odometry.copy()
    k = np.arange(len(seq))
    bent = truth.copy()
    bent[:, 1] += 0.3 * np.sin(k / 10.0)
    bent[:, 2] += 0.03 * np.cos(k / 10.0)
    scale, scores, judged, poses = choose_smoothing(bent, truth, seq, (0.002, 0.002, 0.001), config)
    assert len(judged) == 3 and min(judged) > 1000
    assert scale == 10.0 and len(scores) == 3  # 10 and 50 score alike (1.0): the first of them
    assert scores[0] < 0.9 and scores[1] - scores[0] >= config.rbpf.smooth_choice_margin
    bent_err = np.abs(bent[:, 1] - truth[:, 1]).mean()  # 0.195 m
    assert np.abs(poses[:, 1] - truth[:, 1]).mean() < 0.2 * bent_err  # 0.018 m
    from slam.geometry import accumulate, relative

    steps = relative(truth[:-1], truth[1:])
    steps[:, 2] += 0.02  # the odometry turns 1.1° a step too far
    curved = accumulate(steps, truth[0])
    scale, scores, _, poses = choose_smoothing(truth, curved, seq, (0.002, 0.002, 0.001), config)
    assert scale == 1.0 and scores[0] > 0.95 and max(scores[1:]) < 0.5
    assert np.abs(poses[:, :2] - truth[:, :2]).max() < 0.03


def test_one_smoothing_scale_is_no_choice(long_room):
    """With one scale the trajectory is the smoothing's with the configured sigmas, bit for bit,
    and nothing is scored."""
    from slam.graph import smooth_with_odometry
    from slam.stages import choose_smoothing

    seq, config = long_room
    one = dataclasses.replace(config, rbpf=dataclasses.replace(config.rbpf, smooth_scales=(1.0,)))
    rng = np.random.default_rng(2)
    poses = seq.odometry + rng.normal(0.0, 0.01, seq.odometry.shape)
    scale, scores, judged, got = choose_smoothing(
        poses, seq.odometry, seq, (0.004, 0.004, 0.002), one
    )
    assert judged == []
    rc = config.rbpf
    want = smooth_with_odometry(
        poses,
        seq.odometry,
        (rc.smooth_sigma_xy, rc.smooth_sigma_th),
        (0.004, 0.004, 0.002),
        one.loops,
    )
    assert scale == 1.0 and scores == [] and got.tobytes() == want.tobytes()


def test_nothing_judged_keeps_the_first_smoothing_scale(long_room):
    """When the score judges nothing (one stretch: no other stretches' map to judge it
    against, NaN for every scale), the first scale is kept, without a warning."""
    import warnings

    from slam.stages import choose_smoothing

    seq, config = long_room
    quality = dataclasses.replace(config.quality, stretch_m=1000.0)
    alone = dataclasses.replace(config, quality=quality)
    rng = np.random.default_rng(3)
    poses = seq.odometry + rng.normal(0.0, 0.01, seq.odometry.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scale, scores, judged, got = choose_smoothing(
            poses, seq.odometry, seq, (0.004, 0.004, 0.002), alone
        )
    assert len(scores) == 3 and all(np.isnan(v) for v in scores) and judged == [0, 0, 0]
    assert scale == 1.0
    _, _, _, first = choose_smoothing(
        poses, seq.odometry, seq, (0.004, 0.004, 0.002),
        dataclasses.replace(alone, rbpf=dataclasses.replace(alone.rbpf, smooth_scales=(1.0,))),
    )  # fmt: skip
    np.testing.assert_array_equal(got, first)


def test_a_smoothing_choice_needs_a_gain_beyond_the_scores_noise():
    """smoothing_pick keeps the first scale unless the best beats it by the margin and by z
    standard errors of the difference of the two shares: 0.84 against 0.80 of 500 judged
    returns each is within two standard errors (0.049), of 24,000 each it is far beyond them
    (0.007); NaN never wins; the first is kept on a tie or a loss."""
    from slam.stages import smoothing_pick

    assert smoothing_pick([0.80, 0.84, 0.83], [500, 500, 500], 0.005, 2.0) == 0
    assert smoothing_pick([0.80, 0.84, 0.83], [24000, 24000, 24000], 0.005, 2.0) == 1
    assert smoothing_pick([0.80, 0.84, 0.83], [500, 500, 500], 0.005, 0.0) == 1  # margin alone
    assert smoothing_pick([0.80, 0.803, 0.79], [10**6] * 3, 0.005, 2.0) == 0  # under the margin
    assert smoothing_pick([float("nan"), 0.9, 0.8], [0, 5000, 5000], 0.005, 2.0) == 1
    assert smoothing_pick([0.9, float("nan"), float("nan")], [5000, 0, 0], 0.005, 2.0) == 0
    assert smoothing_pick([float("nan")] * 3, [0, 0, 0], 0.005, 2.0) == 0
    assert smoothing_pick([0.95, 0.95, 0.94], [5000] * 3, 0.0, 0.0) == 0  # a tie: the first


@pytest.mark.parametrize("width", [1, 2, 3, 5, 7])
def test_thin_returns_rounds_half_to_even_as_linspace_does(width):
    """The thinning kernel keeps the returns at ``np.linspace(0, n - 1, width).round()``, ties
    (n - 1 = 3, width - 1 = 2: position 1.5) rounded half to even as numpy rounds them."""
    from slam.kernels.scan import thin_returns

    rows = []
    for n in range(0, 12):
        row = np.full(14, np.nan, dtype=np.float32)
        where = np.sort(np.random.default_rng(n).choice(14, n, replace=False))
        row[where] = np.arange(1, n + 1, dtype=np.float32)  # the return's rank + 1
        rows.append(row)
    all_x = np.array(rows)
    ex = np.empty((len(rows), width))
    ey = np.empty((len(rows), width))
    counts = np.empty(len(rows), dtype=np.int64)
    thin_returns(all_x, -all_x, np.int64(width), ex, ey, counts)
    for n, (x, y, c) in enumerate(zip(ex, ey, counts, strict=True)):
        want = np.arange(n) if n <= width else np.linspace(0, n - 1, width).round().astype(int)
        assert c == len(want)
        np.testing.assert_array_equal(x[:c], want + 1.0)
        np.testing.assert_array_equal(y[:c], -(want + 1.0))
        assert not x[c:].any() and not y[c:].any()


def test_the_lasers_noise_sets_the_smoothing_multiple():
    """noise_multiple on the scans noise_picks chooses: the range noise over
    ``rbpf.smooth_noise_ref``, at least 1; off (1, NaN) with a reference of 0."""
    from synthetic_logs import ray_cast

    from slam.calibration import RANGE_NOISE_SCANS, noise_multiple, noise_picks
    from slam.scans import Scan

    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    rng = np.random.default_rng(6)

    def scans(sigma: float) -> ScanSequence:
        seq = ScanSequence()
        for k in range(100):
            pose = np.array([-1.0 + 0.02 * k, -0.5, 0.01 * k])
            ranges = ray_cast(pose, angles) + rng.normal(0.0, sigma, angles.size)
            seq.append(Scan(float(k), ranges, angles, 0.1, 20.0, 30.0, np.zeros(3)), pose)
        return seq

    noisy = scans(0.03)
    readings = noisy.readings(noise_picks(len(noisy)))[0]
    multiple, noise, triples = noise_multiple(readings, 0.01)
    assert triples > 1000 and abs(noise / 0.03 - 1.0) < 0.1
    assert multiple == pytest.approx(noise / 0.01)
    multiple, noise, triples = noise_multiple(readings, 0.0)
    assert multiple == 1.0 and np.isnan(noise) and triples == 0
    quiet = scans(0.002)
    assert noise_multiple(quiet.readings(noise_picks(100))[0], 0.01)[0] == 1.0
    assert noise_picks(100).tolist() == list(range(100))
    most = noise_picks(10 * RANGE_NOISE_SCANS)
    assert (
        most.size == RANGE_NOISE_SCANS and most[0] == 0 and most[-1] == 10 * RANGE_NOISE_SCANS - 1
    )
    assert noise_picks(0).size == 0


def _output(seq: ScanSequence, poses: np.ndarray, every: int = 3):
    """A filter's output over ``seq`` whose nodes (every ``every``-th scan) and scans sit at
    ``poses``, as the stages before :class:`slam.stages.Recovery` leave it."""
    from slam.particle_filter import FilterOutput

    steps = np.arange(0, len(seq), every)
    n = len(seq)
    return FilterOutput(
        scans=seq, steps=steps, node_poses=poses[steps].copy(), n_eff=np.ones(n),
        max_weight=np.ones(n), stats={"updates": int(steps.size), "loop_closures": 7},
        poses=poses.copy(),
    )  # fmt: skip


def test_a_lost_filter_is_recovered_from_dead_reckoning(long_room):
    """A result that turned away from the room (1° more each scan, the filter lost) scores under
    ``rbpf.recover_below``: the stages run again from the exact odometry, score far better, and
    that trajectory is kept, with a warning and both scores in the stats; the filter's own
    counters stay, its loop figures are the new run's."""
    from slam.geometry import accumulate, relative

    seq, config = long_room
    truth = seq.odometry.copy()
    steps = relative(truth[:-1], truth[1:])
    steps[:, 2] += np.radians(1.0)
    lost = accumulate(steps, truth[0])
    assert np.hypot(*(lost[:, :2] - truth[:, :2]).T).max() > 1.0
    repaired = _output(seq, lost)  # as the repair leaves a result it ran again and did not keep
    record = {"repair_stretches": 2, "repair_scores": [0.41, 0.43], "repair_broke": []}
    repaired.stats.update(record, repaired=False)
    with pytest.warns(UserWarning, match="the filter lost track .* keeps that trajectory"):
        out = stages.Recovery().run(repaired, config)
    assert out.stats["recovered"] is True
    # the repair's record stays (it was dropped with the filter's result: a run that spent its
    # time on a repair showed none in metrics.json)
    assert {k: out.stats[k] for k in record} == record and out.stats["repaired"] is False
    before, after = out.stats["recovery_scores"]
    assert before < config.rbpf.recover_below < after
    assert after - before > 0.3
    # the room's shape back (the stages may shift the whole by a few centimetres)
    assert np.hypot(*(out.poses[:, :2] - truth[:, :2]).T).max() < 0.1
    apart = relative(out.poses[:-20], out.poses[20:]) - relative(truth[:-20], truth[20:])
    assert np.hypot(*apart[:, :2].T).max() < 0.02
    assert out.stats["updates"] == 40 and out.stats.get("loop_closures") != 7
    never = load_config("", None, ["rbpf.recover_below=0"], base=config)
    kept = _output(seq, lost)
    assert stages.Recovery().run(kept, never) is kept


def test_no_recovery_from_laser_odometry(long_room, monkeypatch):
    """Where the odometry is the laser's, there is no dead reckoning to start again from: the
    lost result is kept as it is."""
    from slam.geometry import accumulate, relative

    seq, config = long_room
    steps = relative(seq.odometry[:-1], seq.odometry[1:])
    steps[:, 2] += np.radians(1.0)
    lost = _output(seq, accumulate(steps, seq.odometry[0]))
    monkeypatch.setattr(seq, "odometry_source", "laser")
    assert stages.Recovery().run(lost, config) is lost


def test_a_result_that_scores_well_is_not_run_again(long_room, monkeypatch):
    """A result at the true poses scores above ``rbpf.recover_below``: returned as it is, and
    no stage runs again."""
    seq, config = long_room
    ran = []
    monkeypatch.setattr(stages, "run_stages", lambda *a, **k: ran.append(a))
    good = _output(seq, seq.odometry.copy())
    assert stages.Recovery().run(good, config) is good
    assert ran == [] and "recovered" not in good.stats


def test_the_default_stages_recover_before_the_final_map():
    """``rbpf`` runs the repair and then the recovery after the rounds of registration and
    smoothing, before the map, which is then built once from the trajectory kept; the loop
    closing and the repair share one dict (the filter's output), the smoothings and the repair
    another (the odometry's disagreement and the multiple chosen)."""
    default = stages.default_stages(load_config())
    names = [s.name for s in default]
    assert names[-3:] == ["repair", "recovery", "final map"]
    closing, repair = default[0], default[-3]
    assert isinstance(closing, stages.LoopClosing) and isinstance(repair, stages.Repair)
    assert closing.start is repair.start
    smoothings = [s for s in default if isinstance(s, stages.OdometrySmoothing)]
    assert len(smoothings) == 2 and all(s.measured is repair.measured for s in smoothings)
    recovery = default[-2]
    assert isinstance(recovery, stages.Recovery) and recovery.scored is repair.scored is not None
    assert stages.default_stages(load_config("", None, ['filter.method="classic"'])) == []


def _shifted(poses: np.ndarray, first: int, last: int, by: float) -> np.ndarray:
    """``poses`` with the scans ``first`` to ``last`` moved ``by`` metres sideways (in y)."""
    moved = poses.copy()
    moved[first : last + 1, 1] += by
    return moved


def test_a_stretch_that_contradicts_the_others_is_repaired(long_room):
    """A result with 20 scans (1 m of the room) moved 0.4 m sideways: their stretches agree
    with the others' map less than ``rbpf.repair_below``, so the stages run again from the
    filter's output (kept by the loop closing) with the chain looser there; that result
    scores better and is kept, with both scores, the stretches and ``repaired`` in the stats,
    the room's shape back; the filter's output is not kept beyond the run."""
    seq, config = long_room
    truth = seq.odometry.copy()
    start = {"output": dataclasses.replace(_output(seq, truth), poses=None)}
    bad = _output(seq, _shifted(truth, 50, 69, 0.4))
    out = stages.Repair(start, {}).run(bad, config)
    assert start == {}
    assert out.stats["repaired"] is True and out.stats["repair_stretches"] >= 1
    before, after = out.stats["repair_scores"]
    assert before < after and after - before > 0.05
    assert np.hypot(*(out.poses[:, :2] - truth[:, :2]).T).max() < 0.1
    assert out.stats["updates"] == 40


def _repaired_with(long_room, monkeypatch, rerun: np.ndarray):
    """:class:`slam.stages.Repair` run on the room's scans 50-69 moved 0.4 m sideways, the
    stages that run again giving the poses ``rerun``: its output and the result handed in."""
    seq, config = long_room
    truth = seq.odometry.copy()
    bad = _output(seq, _shifted(truth, 50, 69, 0.4))
    monkeypatch.setattr(stages, "run_stages", lambda *a, **k: _output(seq, rerun))
    start = {"output": dataclasses.replace(_output(seq, truth), poses=None)}
    return stages.Repair(start, {}).run(bad, config), bad


def test_the_repair_keeps_a_result_that_scores_better(long_room, monkeypatch):
    """When the stages run again and score worse (here: they move more of the room), the
    result handed in is kept, with ``repaired`` false and both scores."""
    worse = _shifted(long_room[0].odometry, 30, 89, 0.4)
    out, bad = _repaired_with(long_room, monkeypatch, worse)
    assert out.stats["repaired"] is False
    np.testing.assert_array_equal(out.poses, bad.poses)
    before, after = out.stats["repair_scores"]
    assert after < before


def test_the_repair_keeps_no_rerun_that_breaks_a_stretch_that_agreed(long_room, monkeypatch):
    """A rerun that mends the contradicting stretch (scans 50-69 back in place) but moves the
    last 20 scans 0.4 m sideways scores better over the run (0.917 against 0.885), by more than
    the margin: the score alone would keep it. The last stretch agreed (1.0) and now does not
    (0.69 on the same scans), so the result handed in is kept, and ``repair_broke`` gives that
    stretch's times."""
    seq = long_room[0]
    out, bad = _repaired_with(long_room, monkeypatch, _shifted(seq.odometry, 100, 119, 0.4))
    before, after = out.stats["repair_scores"]
    assert after - before > 0.03  # 0.885 -> 0.917
    assert out.stats["repaired"] is False
    np.testing.assert_array_equal(out.poses, bad.poses)
    assert out.stats["repair_broke"] == [[round(seq.times[90], 3), round(seq.times[119], 3)]]


def test_broken_stretches_are_those_that_agreed_and_no_longer_do(long_room):
    """:func:`slam.stages.broken_stretches`: a stretch's score over its own scans is what the
    result itself says (:meth:`QualityResult.score_over`); a result breaks none of its own; the
    last 20 scans moved 0.4 m break the last stretch (it agreed, 1.0, and scores 0.69 on the
    same scans); a drop that is not significant (z = 100) breaks nothing."""
    from slam.eval.quality import map_quality
    from slam.stages import broken_stretches, quality_rays

    seq, config = long_room
    truth = seq.odometry.copy()
    picks = np.arange(len(seq))
    rays = quality_rays(seq, picks, config)

    def scored(poses):
        return map_quality(seq.times, poses, rays, config.quality, config.map)

    bad = scored(_shifted(truth, 50, 69, 0.4))
    for s in bad.stretches:
        share, checked = bad.score_over(s.first, s.last)
        assert checked == s.checked and (share == s.score or (np.isnan(share) and s.checked == 0))
    assert broken_stretches(bad, bad, 0.005, 2.0) == []
    worse = scored(_shifted(truth, 100, 119, 0.4))
    broken = broken_stretches(bad, worse, 0.005, 2.0)
    assert [(s.first, s.last) for s in broken] == [(90, 119)]
    assert broken[0].score >= config.quality.flag_below > worse.score_over(90, 119)[0]
    assert broken_stretches(bad, worse, 0.005, 100.0) == []


def test_a_result_without_contradicting_stretches_is_not_repaired(long_room, monkeypatch):
    """At the true poses no stretch scores under ``rbpf.repair_below``: the result is returned
    as it is and no stage runs again; nor with ``rbpf.repair_below = 0``, ``loops.flex_factor
    = 1``, or without the filter's output to start from (a caller's own list of stages)."""
    seq, config = long_room
    ran = []
    monkeypatch.setattr(stages, "run_stages", lambda *a, **k: ran.append(a))
    truth = seq.odometry.copy()
    first = dataclasses.replace(_output(seq, truth), poses=None)
    good = _output(seq, truth)
    assert stages.Repair({"output": first}, {}).run(good, config) is good
    bad = _output(seq, _shifted(truth, 50, 69, 0.4))
    for off in (["rbpf.repair_below=0"], ["loops.flex_factor=1"]):
        start = {"output": first}
        assert stages.Repair(start, {}).run(bad, load_config("", None, off, base=config)) is bad
        assert start == {}
    assert stages.Repair({}, {}).run(bad, config) is bad
    assert ran == [] and "repaired" not in good.stats


def test_the_loop_closing_keeps_its_input_for_the_repair(long_room, monkeypatch):
    """``LoopClosing(start)`` keeps the output it was handed (the filter's), whatever it does
    with it; ``LoopClosing(loose=...)`` hands the graph the nodes within those times."""
    import slam.backend.global_loops as global_loops

    seq, config = long_room
    start: dict = {}
    handed = dataclasses.replace(_output(seq, seq.odometry.copy()), poses=None)
    stages.LoopClosing(start).run(handed, config)
    assert start["output"] is handed
    seen = []
    real = global_loops.close_loops_global

    def spy(*args, loose_nodes=None, **kwargs):
        seen.append(loose_nodes)
        return real(*args, loose_nodes=loose_nodes, **kwargs)

    monkeypatch.setattr(global_loops, "close_loops_global", spy)
    times = seq.times[handed.steps]
    stages.LoopClosing(loose=[(times[10], times[14])]).run(handed, config)
    stages.LoopClosing().run(handed, config)
    assert np.flatnonzero(seen[0]).tolist() == [10, 11, 12, 13, 14] and seen[1] is None


def test_the_repair_reruns_the_loop_closing_with_the_runs_first_round(long_room, monkeypatch):
    """The default stages share one :class:`slam.graph.FirstRound` between the loop closing and
    the repair, which hands it to the loop closing of its rerun (the same nodes: the same first
    round of closures)."""
    from slam.graph import FirstRound

    seq, config = long_room
    made = stages.default_stages(config)
    closing, repair = made[0], next(s for s in made if isinstance(s, stages.Repair))
    assert isinstance(closing.first, FirstRound) and repair.first is closing.first
    truth = seq.odometry.copy()
    handed = []

    def rerun(output, again, *args, **kwargs):
        handed.extend(again)
        return _output(seq, truth)

    monkeypatch.setattr(stages, "run_stages", rerun)
    start = {"output": dataclasses.replace(_output(seq, truth), poses=None)}
    bad = _output(seq, _shifted(truth, 50, 69, 0.4))
    assert stages.Repair(start, {}, None, closing.first).run(bad, config).stats["repaired"]
    assert isinstance(handed[0], stages.LoopClosing) and handed[0].first is closing.first
    assert handed[0].loose  # the rerun's chain is looser across the contradicting stretch


def test_first_round_keeps_one_result_per_kind_for_the_same_inputs():
    from slam.graph import FirstRound

    seq, config = object(), Config()
    steps, poses, path = np.arange(3), np.zeros((3, 3)), np.arange(3.0)
    first, made = FirstRound(), []

    def make():
        made.append(1)
        return len(made)

    inputs = (seq, steps, poses, path, config)
    assert first.found("local", inputs, make) == 1
    assert first.found("local", (seq, steps.copy(), poses.copy(), path.copy(), Config()), make) == 1
    assert first.found("global", inputs, make) == 2  # another kind: computed once too
    poses[0, 0] = 1.0  # the caller's array changed: not what was kept
    assert first.found("local", inputs, make) == 3
    assert first.found("local", (object(), steps, poses, path, config), make) == 4
    other = load_config("", None, ["loops.rounds=3"], base=config)
    assert first.found("local", (seq, steps, poses, path, other), make) == 5


def test_the_recovery_keeps_every_counter_the_filter_hands_over(long_room):
    """The counters a result started from dead reckoning keeps are exactly those the ``rbpf``
    filter hands to the stages (a counter added to the filter is not silently dropped)."""
    import slam

    seq, config = long_room
    handed = []

    class Watch:
        name = "watch"

        def run(self, output, config):
            handed.append(set(output.stats))
            return output

    s = slam.Slam(config, stages=[Watch(), stages.BetweenUpdates()])
    for k in range(len(seq)):
        s.update(seq.scan(k), odometry=seq.odometry[k])
    s.finish()
    assert handed == [set(stages._FILTER_STATS)]


def test_the_recovery_takes_the_repairs_score_of_the_same_poses(long_room, monkeypatch):
    """The repair scores the result it returns; the recovery that follows takes that score
    instead of scoring the same poses again (and forgets it); for other poses it scores anew,
    to the same figure."""
    import slam.eval.quality as quality

    seq, config = long_room
    truth = seq.odometry.copy()
    start = {"output": dataclasses.replace(_output(seq, truth), poses=None)}
    scored: dict = {}
    good = _output(seq, truth)
    assert stages.Repair(start, {}, scored).run(good, config) is good
    assert scored["poses"] is good.poses and scored["score"] > config.rbpf.recover_below
    real, calls = quality.map_quality, []

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(quality, "map_quality", counted)
    kept = dict(scored)
    assert stages.Recovery(scored).run(good, config) is good
    assert calls == [] and scored == {}
    again = _output(seq, truth)  # the same poses in another array
    assert stages.Recovery().run(again, config) is again
    assert calls == [1]
    picks = np.arange(0, len(seq), config.rbpf.smooth_choice_every)
    rays = stages.quality_rays(seq, picks, config)
    assert stages._score(again.poses, seq, picks, rays, config) == (kept["score"], kept["judged"])
