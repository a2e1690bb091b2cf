"""Map quality without ground truth (slam.eval.quality): the kernels' verdicts on hand-made
geometry, stretches, the simulated loop closed versus opened, and the score against relations."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from slam.config import MapConfig, QualityConfig
from slam.eval.quality import (
    Rays,
    judging_for,
    map_quality,
    rank_correlation,
    scan_rays,
    stretch_bounds,
    stretch_relation_errors,
    summary,
    within_range,
)
from slam.geometry import relative
from slam.io.relations import Relations
from slam.kernels.grid import bresenham
from slam.kernels.quality import (
    AGREE,
    BLOCK_SCANS,
    CONFLICT_FREE,
    CONFLICT_THROUGH,
    HIT,
    ISOLATED,
    UNCHECKED,
    UNKNOWN,
    CountMap,
    ScanRays,
    add_kept,
    classify_beams,
    count_rays,
    counts_for,
    empty_counts,
    to_rows,
    touched_tiles,
)
from slam.sim.fixtures import demo_loop as make_demo_loop
from slam.sim.fixtures import open_the_loop

RES = 0.05
ORIGIN = (-1.0, -3.0)


def wall_scan(x_wall: float, half_width: float = 1.0, beams: int = 41) -> tuple[np.ndarray, ...]:
    """Robot-frame ray ends of a laser at the origin looking at the wall x = ``x_wall``."""
    y = np.linspace(-half_width, half_width, beams)
    ex = np.full((1, beams), x_wall, dtype=np.float32)
    ey = y[None, :].astype(np.float32)
    kind = np.full((1, beams), HIT, dtype=np.int8)
    return ex, ey, kind


def counts_seeing_wall(x_wall: float) -> tuple[np.ndarray, np.ndarray]:
    """Counts of a dense scan from the origin ending on the wall x = ``x_wall`` (a hundred times,
    so every cell in front of the wall is crossed by many rays)."""
    counts = empty_counts(120, 80)
    ex, ey, kind = wall_scan(x_wall, half_width=1.6, beams=401)
    poses = np.zeros((100, 3))
    ex, ey, kind = (np.repeat(a, 100, axis=0) for a in (ex, ey, kind))
    count_rays(_at(counts), ScanRays(poses, 0.0, 0.0, ex, ey, kind), 0, 100, 1)
    return counts


def _at(counts: tuple[np.ndarray, np.ndarray]) -> CountMap:
    """The test grid's counts placed at ORIGIN with cells of RES."""
    return CountMap(*counts, ORIGIN[0], ORIGIN[1], RES)


def _judging(tolerance: float):
    """The default thresholds of the score, with the agreement ``tolerance`` (m)."""
    return judging_for(QualityConfig(tolerance_m=tolerance), MapConfig())


def classify(counts: tuple[np.ndarray, np.ndarray], x_wall: float, tolerance: float = 0.15):
    """Verdicts and offsets of one scan from the origin ending on the wall x = ``x_wall``."""
    ex, ey, kind = wall_scan(x_wall)
    verdict = np.empty(kind.shape, np.int8)
    offset = np.empty(kind.shape, np.float32)
    disc = np.array([[dx, dy] for dx in range(-3, 4) for dy in range(-3, 4)
                     if (dx * dx + dy * dy) * RES**2 <= tolerance**2 + 1e-12])  # fmt: skip
    rays = ScanRays(np.zeros((1, 3)), 0.0, 0.0, ex, ey, kind)
    classify_beams(_at(counts), rays, 0, 1, disc, _judging(tolerance), verdict, offset)
    return verdict[0], offset[0]


def test_counts_add_and_remove_exactly():
    counts = counts_seeing_wall(2.0)
    hits, misses = to_rows(*counts)
    assert hits.sum() == 100 * 401  # every return is one hit
    # The cell on y = 0 just before the wall: crossed by the central ray and its neighbours.
    ix, iy = int((1.9 - ORIGIN[0]) / RES), int((0.0 - ORIGIN[1]) / RES)
    assert misses[iy, ix] >= 100 and misses[iy, ix] % 100 == 0 and hits[iy, ix] == 0
    ex, ey, kind = (np.repeat(a, 100, axis=0) for a in wall_scan(2.0, half_width=1.6, beams=401))
    count_rays(_at(counts), ScanRays(np.zeros((100, 3)), 0.0, 0.0, ex, ey, kind), 0, 100, -1)
    assert not counts[1].any()


def test_tiles_are_allocated_where_rays_pass_and_count_the_same():
    """Counts in the tiles :func:`touched_tiles` allocates equal those of a full grid."""
    rng = np.random.default_rng(4)
    n, beams = 30, 50
    poses = np.column_stack([rng.uniform(0, 2, n), rng.uniform(-1, 1, n), rng.uniform(-3, 3, n)])
    reach = rng.uniform(0.2, 1.5, (n, beams))
    angle = np.linspace(-1.5, 1.5, beams)[None, :]
    ex = (reach * np.cos(angle)).astype(np.float32)
    ey = (reach * np.sin(angle)).astype(np.float32)
    kind = rng.choice(np.array([HIT, 2], np.int8), (n, beams))
    full = empty_counts(120, 80)
    rays = ScanRays(poses, 0.1, 0.0, ex, ey, kind)
    count_rays(_at(full), rays, 0, n, 1)
    touched = touched_tiles(8, 5, ORIGIN[0], ORIGIN[1], RES, rays)
    assert 0 < touched.sum() < touched.size  # rays of at most 1.6 m miss part of the 4 x 6 m
    sparse = counts_for(touched)
    count_rays(_at(sparse), rays, 0, n, 1)
    for a, b in zip(to_rows(*full), to_rows(*sparse), strict=True):
        assert np.array_equal(a, b) and a.sum() > 0


def _reference_counts(rays: ScanRays, height: int, width: int) -> tuple[np.ndarray, ...]:
    """Hits and misses of ``rays`` counted ray by ray in Python (:func:`bresenham`)."""
    hits = np.zeros((height, width), np.int64)
    misses = np.zeros((height, width), np.int64)
    cell = [lambda v, o=o: int(math.floor((v - o) / RES)) for o in ORIGIN]
    for k, (x, y, th) in enumerate(rays.poses):
        c, s = math.cos(th), math.sin(th)
        x0, y0 = cell[0](x + c * rays.lx - s * rays.ly), cell[1](y + s * rays.lx + c * rays.ly)
        for j in np.flatnonzero(rays.kind[k]):
            ex, ey = float(rays.ex[k, j]), float(rays.ey[k, j])
            x1, y1 = cell[0](x + c * ex - s * ey), cell[1](y + s * ex + c * ey)
            line = bresenham(x0, y0, x1, y1)
            for n, (cx, cy) in enumerate(line):
                if 0 <= cx < width and 0 <= cy < height:
                    end_hit = n == len(line) - 1 and rays.kind[k, j] == HIT
                    (hits if end_hit else misses)[cy, cx] += 1
    return hits, misses


def _random_rays(seed: int, n: int, beams: int, kinds: list[int]) -> ScanRays:
    """``n`` scans of ``beams`` rays from random poses around the test grid (some outside it),
    0.2–3 m long over ±2 rad, of random ``kinds``."""
    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.uniform(-0.5, 2.5, n), rng.uniform(-2.5, 2.5, n),
                             rng.uniform(-3, 3, n)])  # fmt: skip
    reach = rng.uniform(0.2, 3.0, (n, beams))
    angle = np.linspace(-2.0, 2.0, beams)[None, :]
    ex = (reach * np.cos(angle)).astype(np.float32)
    ey = (reach * np.sin(angle)).astype(np.float32)
    kind = rng.choice(np.array(kinds, np.int8), (n, beams))
    return ScanRays(poses, 0.1, 0.05, ex, ey, kind)


def test_parallel_counts_and_verdicts_equal_a_reference_whatever_the_threads():
    """:func:`count_rays` over several blocks of scans (rays leaving the grid too) counts what a
    ray-by-ray walk counts, and counts and verdicts are the same on one thread and on all."""
    n = 2 * BLOCK_SCANS + 37
    rays = _random_rays(7, n, 24, [0, HIT, HIT, 2])
    kind = rays.kind
    expected = _reference_counts(rays, 120, 80)
    assert expected[0].sum() > 0 and expected[1].sum() > 0
    disc = np.array([[dx, dy] for dx in range(-3, 4) for dy in range(-3, 4)
                     if (dx * dx + dy * dy) * RES**2 <= 0.15**2 + 1e-12])  # fmt: skip
    results = []
    for threads in sorted({1, numba.config.NUMBA_NUM_THREADS}):
        numba.set_num_threads(threads)
        try:
            counts = counts_for(touched_tiles(8, 5, ORIGIN[0], ORIGIN[1], RES, rays))
            count_rays(_at(counts), rays, 0, n, 1)
            count_rays(_at(counts), rays, 40, 200, -1)  # the window of a stretch taken out
            verdict = np.empty(kind.shape, np.int8)
            offset = np.empty(kind.shape, np.float32)
            classify_beams(_at(counts), rays, 40, 200, disc, _judging(0.15), verdict, offset)
            count_rays(_at(counts), rays, 40, 200, 1)
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        rows = to_rows(*counts)
        for got, want in zip(rows, expected, strict=True):
            assert np.array_equal(got[:120, :80], want)
        results.append((rows, verdict[40:200].copy(), offset[40:200].copy()))
    for rows, verdict, offset in results[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(rows, results[0][0], strict=True))
        assert np.array_equal(verdict, results[0][1])
        assert np.array_equal(offset, results[0][2], equal_nan=True)
    assert (results[0][1] == AGREE).sum() > 0


def test_the_four_verdicts_on_a_wall():
    # The others saw the wall where this scan sees it: every return agrees.
    verdict, offset = classify(counts_seeing_wall(2.0), 2.0)
    assert (verdict == AGREE).all() and (offset == 0).all()
    # The others saw it 0.5 m further: this scan's endpoints lie in their free space, 0.5 m in
    # front of their wall (the offset is measured along the beam, so it grows off-axis).
    verdict, offset = classify(counts_seeing_wall(2.5), 2.0)
    assert (verdict == CONFLICT_FREE).all()
    assert offset[20] == pytest.approx(-0.5, abs=RES)
    assert (offset <= -0.45).all() and (offset >= -0.7).all()
    # The others saw it 0.5 m nearer: this scan's beams pass through their wall.
    verdict, offset = classify(counts_seeing_wall(1.5), 2.0)
    assert (verdict[1:-1] == CONFLICT_THROUGH).all()  # the end beams have one neighbour only
    assert offset[20] == pytest.approx(0.5, abs=RES)
    # The others never looked here.
    verdict, offset = classify(empty_counts(120, 80), 2.0)
    assert (verdict == UNKNOWN).all() and np.isnan(offset).all()


def test_a_wall_face_the_others_only_skimmed_is_not_a_conflict():
    """Rays grazing a wall clear the cells of its face; the inside of the wall behind the face was
    never observed, so an endpoint on the face is unknown, not a conflict."""
    counts = empty_counts(120, 80)
    n = 60
    # Rays along y = 1.02 from x = -0.5 to 2.5, just in front of the face y = 1 (seen head-on
    # below by the scan judged); they end on nothing (FREE rays).
    ex = np.tile(np.linspace(2.5, 2.4, n)[:, None], (1, 1)).astype(np.float32)
    ey = np.full((n, 1), 1.02, np.float32)
    poses = np.zeros((n, 3))
    poses[:, 0] = -0.5
    kind = np.full((n, 1), 2, np.int8)
    count_rays(_at(counts), ScanRays(poses, 0.0, 0.0, ex - 0.0, ey, kind), 0, n, 1)
    # The judged scan: a laser at (1, 0) looking up at the face y = 1.02 (robot frame: x forward).
    verdict = np.empty((1, 9), np.int8)
    offset = np.empty((1, 9), np.float32)
    xs = np.linspace(-0.2, 0.2, 9).astype(np.float32)
    ex2 = np.full((1, 9), 1.02, np.float32)
    ey2 = -xs[None, :]
    kind2 = np.full((1, 9), HIT, np.int8)
    disc = np.array([[0, 0]])
    rays = ScanRays(np.array([[1.0, 0.0, math.pi / 2]]), 0.0, 0.0, ex2, ey2, kind2)
    classify_beams(_at(counts), rays, 0, 1, disc, _judging(0.15), verdict, offset)
    assert (verdict == UNKNOWN).all()


def test_scan_rays_follow_the_range_semantics():
    ranges = np.array([[1.0, np.nan, 0.01, 29.0, 31.0, 40.0]], dtype=np.float32)
    angles = np.zeros(6)
    rays = scan_rays(ranges, angles, np.array([0.1, 0.0, 0.0]), 0.05, 30.0, 35.0)
    assert rays.kind.tolist() == [[1, 0, 0, 1, 2, 0]]  # hit, invalid, short, hit, free, no return
    assert rays.ex[0, 0] == pytest.approx(1.1) and rays.ex[0, 4] == pytest.approx(30.1)
    with_no_return = scan_rays(ranges, angles, np.zeros(3), 0.05, 30.0, 35.0, 5.0)
    assert with_no_return.kind[0, 5] == 2 and with_no_return.ex[0, 5] == pytest.approx(5.0)


def test_stretch_bounds_cut_the_path_every_stretch_m():
    x = np.linspace(0.0, 34.0, 341)  # 0.1 m steps along a line
    poses = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    bounds = stretch_bounds(poses, 10.0)
    assert bounds.tolist() == [0, 100, 200, 341]  # the last 4 m join the third stretch
    assert stretch_bounds(poses[:10], 10.0).tolist() == [0, 10]


def test_config_rejects_bad_quality_parameters():
    from slam.errors import ConfigError

    with pytest.raises(ConfigError, match=r"quality.tolerance_m: expected .* \(0, 100\], found 0"):
        QualityConfig(tolerance_m=0.0)
    with pytest.raises(ConfigError, match=r"quality.flag_below: expected .*\[0, 1\], found 1.5"):
        QualityConfig(flag_below=1.5)


# --- a simulated loop, closed and opened ------------------------------------------------------


@pytest.fixture(scope="module")
def demo_loop():
    """The demo building, its true trajectory and its rays (:func:`slam.sim.fixtures.demo_loop`)."""
    return make_demo_loop()


@pytest.fixture(scope="module")
def scored(demo_loop):
    times, truth, rays = demo_loop
    opened = open_the_loop(truth, len(truth) // 2, 5.0, 1.015)
    return map_quality(times, truth, rays), map_quality(times, opened, rays), opened


def test_the_true_trajectory_scores_near_perfect(scored):
    closed, _, _ = scored
    report = summary(closed)
    assert report["stretches"] == 7 and report["judged_stretches"] == 7
    assert report["score"] > 0.999
    assert report["worst_score"] > 0.995
    assert report["flagged"] == 0
    assert report["coverage"] > 0.5  # the loop revisits: half the returns can be judged


def test_an_opened_loop_scores_clearly_worse_where_the_walls_double(scored, demo_loop):
    closed, opened, poses = scored
    times = demo_loop[0]
    report = summary(opened)
    assert report["score"] < 0.87 and summary(closed)["score"] - report["score"] > 0.12
    assert report["worst_score"] < 0.7
    assert report["flagged"] == 1
    worst = opened.worst()[0]
    # The worst stretch is the last one, driving back past the start: its walls lie beside the
    # first pass's (5° and 1.5 % of drift since the midpoint) ...
    assert worst.index == len(opened.stretches) - 1
    assert worst.t_start - times[0] > 90.0
    # ... and the conflicts it finds lie where the two passes overlap, by the first stretch's path.
    first = opened.stretches[0]
    assert np.hypot(*(poses[first.first : first.last + 1, :2] - worst.place_xy).T).min() < 2.0
    assert worst.offset_m == pytest.approx(0.35, abs=0.15)
    # The first stretch sees the same doubled walls from the other pass, the middle ones do not.
    scores = [s.score for s in opened.stretches]
    assert scores[0] < 0.85 and min(scores[2:4]) > 0.99
    assert opened.worst()[1].index == 0


def test_the_score_flags_the_stretches_with_large_relation_errors(scored, demo_loop):
    """Relations from the truth between nearby poses (like the benchmark's): the stretches the
    score ranks worst are the ones whose relations the opened loop gets wrong."""
    times, truth, _ = demo_loop
    _, opened, _ = scored
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(times), (2, 20000))
    near = (np.hypot(*(truth[i, :2] - truth[j, :2]).T) < 3.0) & (times[j] - times[i] > 1.0)
    i, j = i[near][:2000], j[near][:2000]
    motion = relative(truth[i], truth[j])
    relations = Relations(times[i], times[j], motion[:, 0], motion[:, 1], motion[:, 2])
    per = stretch_relation_errors(opened, relations)
    assert per.count.sum() >= 2000 and (per.count > 0).all()
    scores = np.array([s.score for s in opened.stretches])
    assert rank_correlation(scores, per.mean) < -0.6
    worst = opened.worst()[0].index
    assert per.max[worst] > 0.25 and per.max[2] < 0.1


def test_rank_correlation():
    a = np.array([1.0, 2.0, 3.0, 4.0, np.nan])
    assert rank_correlation(a, a**2) == pytest.approx(1.0)
    assert rank_correlation(a, -a) == pytest.approx(-1.0)
    assert math.isnan(rank_correlation(a[:2], a[:2]))


def test_only_returns_within_range_are_judged(demo_loop):
    times, truth, rays = demo_loop
    few = Rays(rays.ex[:400], rays.ey[:400], rays.kind[:400], rays.laser_xy)
    config = QualityConfig(stretch_m=2.0)
    result = map_quality(times[:400], truth[:400], few, config)
    near = within_range(few, config.max_range_m)
    reach = np.hypot(near.ex - few.laser_xy[0], near.ey - few.laser_xy[1])[near.kind != 0]
    assert reach.max() <= config.max_range_m + 1e-4
    assert (near.kind == HIT).sum() < (few.kind == HIT).sum()  # some returns lie beyond 10 m
    assert ((result.verdict == UNCHECKED) == (near.kind != HIT)).all()
    t = result.totals()
    assert t["returns"] == int((near.kind == HIT).sum())
    assert t["checked"] + t["unknown"] + t["isolated"] == t["returns"]
    assert t["isolated"] == int((result.verdict == ISOLATED).sum()) > 0


def test_touched_tiles_are_exactly_the_tiles_of_the_walked_cells():
    """:func:`touched_tiles` marks exactly the tiles of the cells the counting walk counts: rays
    in every direction, long and short, of zero length, from inside and outside the grid,
    leaving it or passing by it."""
    rng = np.random.default_rng(11)
    n, beams = 12, 10
    poses = np.column_stack([rng.uniform(-1.5, 5.5, n), rng.uniform(-4.5, 4.5, n),
                             rng.uniform(-np.pi, np.pi, n)])  # fmt: skip
    reach = rng.choice([0.0, 0.01, 0.3, 1.0, 4.0, 9.0], (n, beams))
    angle = rng.uniform(-np.pi, np.pi, (n, beams))
    ex = (reach * np.cos(angle)).astype(np.float32)
    ey = (reach * np.sin(angle)).astype(np.float32)
    kind = rng.choice(np.array([0, HIT, 2], np.int8), (n, beams))
    rays = ScanRays(poses, 0.1, 0.05, ex, ey, kind)
    full = empty_counts(120, 80)
    count_rays(_at(full), rays, 0, n, 1)
    hits, misses = to_rows(*full)
    walked = (hits + misses) > 0
    expected = walked.reshape(8, 16, 5, 16).any(axis=(1, 3))  # (the tiles hold 128 rows)
    touched = touched_tiles(8, 5, ORIGIN[0], ORIGIN[1], RES, rays)
    assert 5 < expected.sum() < expected.size  # some tiles touched, some not
    assert np.array_equal(touched, expected)
    for x0, y0, x1, y1 in [(3, 5, 3, 5), (0, 0, 40, 17), (40, 17, 0, 0), (5, 70, 9, -30)]:
        one = ScanRays(np.array([[ORIGIN[0] + (x0 + 0.5) * RES, ORIGIN[1] + (y0 + 0.5) * RES, 0]]),
                       0.0, 0.0, np.array([[(x1 - x0) * RES]], np.float32),
                       np.array([[(y1 - y0) * RES]], np.float32), np.array([[HIT]], np.int8))  # fmt: skip
        mask = np.zeros((8, 5), np.bool_)
        for cx, cy in bresenham(x0, y0, x1, y1):
            if 0 <= cx < 80 and 0 <= cy < 128:
                mask[cy // 16, cx // 16] = True
        assert np.array_equal(touched_tiles(8, 5, ORIGIN[0], ORIGIN[1], RES, one), mask)


def test_kept_patches_give_back_a_window_without_walking_it_again():
    """``count_rays(..., cuts, kept)`` cuts its blocks at ``cuts`` too and keeps their patches;
    :func:`add_kept` adds them back: the same counts as walking the rays again, block by
    block, and only whole kept blocks."""
    n = 400
    rays = _random_rays(9, n, 16, [0, HIT, 2])
    touched = touched_tiles(8, 5, ORIGIN[0], ORIGIN[1], RES, rays)

    def counted(*ranges: tuple[int, int]) -> list[np.ndarray]:
        counts = counts_for(touched)
        for k0, k1 in ranges:
            count_rays(_at(counts), rays, k0, k1, 1)
        return to_rows(*counts)

    counts = counts_for(touched)
    count_rays(_at(counts), rays, 0, n, 1)
    kept: dict = {}
    count_rays(_at(counts), rays, 40, 300, -1, cuts=[0, 100, 250, 300, 350], kept=kept)
    assert sorted(kept) == [40, 100, 228, 250]  # cut at 100 and 250, and 128 scans at most
    assert [kept[a][0] for a in sorted(kept)] == [100, 228, 250, 300]
    for a, b in zip(to_rows(*counts), counted((0, 40), (300, n)), strict=True):
        assert np.array_equal(a, b)
    add_kept(_at(counts), kept, 40, 100, 1)
    for a, b in zip(to_rows(*counts), counted((0, 100), (300, n)), strict=True):
        assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="scans 100..227 runs past scan 200"):
        add_kept(_at(counts), kept, 100, 200, 1)
    with pytest.raises(KeyError):
        add_kept(_at(counts), kept, 101, 228, 1)
    add_kept(_at(counts), kept, 250, 300, 1)  # (the failed calls gave back nothing)
    add_kept(_at(counts), kept, 100, 250, 1)
    assert not kept
    for a, b in zip(to_rows(*counts), counted((0, n)), strict=True):
        assert np.array_equal(a, b) and a.sum() > 0


def test_a_small_grid_allocated_whole_scores_as_the_touched_tiles_do(
    scored, demo_loop, monkeypatch
):
    """:func:`counts_over` allocates every tile of a grid up to ``DENSE_BYTES`` and only the
    touched ones above it: the same verdicts, picture and scores either way."""
    import slam.kernels.quality as kq

    times, _, rays = demo_loop
    _, opened, poses = scored  # (computed with the defaults: the demo's grid is allocated whole)
    monkeypatch.setattr(kq, "DENSE_BYTES", 0)
    sparse = map_quality(times, poses, rays)
    assert np.array_equal(sparse.verdict, opened.verdict)
    timing = ("wall_s", "cpu_s")
    assert {k: v for k, v in summary(sparse).items() if k not in timing} == {
        k: v for k, v in summary(opened).items() if k not in timing
    }
    assert np.array_equal(sparse.shades, opened.shades)
    assert [s.score for s in sparse.stretches] == [s.score for s in opened.stretches]
    monkeypatch.setattr(kq, "DENSE_BYTES", 8 * 5 * 16 * 16 * 2 * 4)  # just the 8 x 5 tiles
    rays_one = ScanRays(np.zeros((1, 3)), 0.0, 0.0, *(a[:1] for a in wall_scan(1.0, 0.5, 9)))
    assert (kq.counts_over(8, 5, ORIGIN[0], ORIGIN[1], RES, rays_one)[0] >= 0).all()
    monkeypatch.setattr(kq, "DENSE_BYTES", 8 * 5 * 16 * 16 * 2 * 4 - 1)
    table, pool = kq.counts_over(8, 5, ORIGIN[0], ORIGIN[1], RES, rays_one)
    assert 0 < (table >= 0).sum() == pool.shape[0] < 8 * 5  # only what the rays touch


def test_rays_made_and_cut_in_blocks_are_the_same_to_the_bit(monkeypatch):
    """scan_rays and within_range work RAY_ROWS scans at a time (the float64 intermediates of a
    block, not of a 20-minute log); blocks of 3 scans give what one block gives, the cut in
    place what the cut copy gives, and the rays hold 0 where there is no ray."""
    import slam.eval.quality as q

    rng = np.random.default_rng(4)
    ranges = rng.uniform(0.0, 40.0, (10, 50)).astype(np.float32)
    ranges[rng.random(ranges.shape) < 0.1] = np.nan
    angles = np.tile(np.linspace(-2.0, 2.0, 50), (10, 1))
    angles[5] += 0.01  # one scan with beams of its own
    args = (ranges, angles, np.array([0.2, 0.0, 0.0]), 0.1, 30.0, 35.0, 2.0)
    whole = q.scan_rays(*args)
    monkeypatch.setattr(q, "RAY_ROWS", 3)
    blocks = q.scan_rays(*args)
    for name in ("ex", "ey", "kind"):
        np.testing.assert_array_equal(getattr(whole, name), getattr(blocks, name))
    assert np.all(whole.ex[whole.kind == q.NO_RAY] == 0) and (whole.kind == q.NO_RAY).any()
    cut = q.within_range(whole, 20.0)
    assert cut is not whole and (cut.kind != whole.kind).any()
    q.within_range(blocks, 20.0, in_place=True)
    for name in ("ex", "ey", "kind"):
        np.testing.assert_array_equal(getattr(cut, name), getattr(blocks, name))
