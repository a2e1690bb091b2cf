"""Kernel unit tests with numbers: Bresenham, log-odds, correlation, resampling, motion, fields."""

import numpy as np
import pytest

from slam.kernels.field import recount_tiles, resample_tables, surface_at
from slam.kernels.grid import bresenham, integrate_rays
from slam.kernels.motion import sample_motion
from slam.kernels.resample import effective_sample_size, systematic_resample
from slam.kernels.scan import correlation, correlation_search
from slam.mapping import ParticleMaps, likelihood_tables, tile_spans


def reference_line(x0, y0, x1, y1):
    """Cells of the segment by the textbook error-accumulation Bresenham (Wikipedia 'all cases')."""
    cells = []
    dx, dy = abs(x1 - x0), -abs(y1 - y0)
    sx = 1 if x0 < x1 else -1
    sy = 1 if y0 < y1 else -1
    err = dx + dy
    x, y = x0, y0
    while True:
        cells.append((x, y))
        if x == x1 and y == y1:
            return cells
        e2 = 2 * err
        if e2 >= dy:
            err += dy
            x += sx
        if e2 <= dx:
            err += dx
            y += sy


ENDS = [
    (7, 3),
    (3, 7),
    (-3, 7),
    (-7, 3),
    (-7, -3),
    (-3, -7),
    (3, -7),
    (7, -3),
    (5, 5),
    (0, 6),
    (6, 0),
    (0, 0),
]


@pytest.mark.parametrize("end", ENDS)
def test_bresenham_matches_reference_in_every_octant(end):
    x1, y1 = end
    ours = [tuple(c) for c in bresenham(0, 0, x1, y1)]
    ref = reference_line(0, 0, x1, y1)
    assert ours[0] == (0, 0) and ours[-1] == (x1, y1)
    assert len(ours) == max(abs(x1), abs(y1)) + 1
    assert ours == ref
    if x1 or y1:
        # 8-connected, and never more than half a cell (along the minor axis) off the ideal line
        assert np.abs(np.diff(np.array(ours), axis=0)).max() <= 1
        for x, y in ours:
            off = abs(x * y1 - y * x1) / max(abs(x1), abs(y1))
            assert off <= 0.5 + 1e-9


@pytest.mark.parametrize("end", ENDS[:8])
def test_bresenham_both_directions_cover_the_same_length(end):
    forward = bresenham(0, 0, *end)
    backward = bresenham(end[0], end[1], 0, 0)
    assert len(forward) == len(backward)
    assert tuple(backward[0]) == end and tuple(backward[-1]) == (0, 0)


def rays_into(grid, ex, ey, hit, sensor=(1.5, 1.5)):
    """integrate_rays of one scan into the whole grid (1 m cells, origin 0)."""
    view = np.array([[0, 0, *grid.shape]])
    sensors = np.array([sensor], dtype=np.float64)
    offsets = np.array([0, len(ex)])
    return integrate_rays(grid, view, np.zeros((1, 2)), 1.0, sensors, offsets,
                          np.array(ex), np.array(ey), np.array(hit), 1.0, -0.5, -2.0, 3.0)  # fmt: skip


def test_integrate_rays_hits_and_misses_and_clamps():
    grid = np.zeros((10, 10), dtype=np.float32)
    # sensor at the centre of cell (1, 1), a ray along +x to cell (6, 1)
    assert rays_into(grid, [6.5], [1.5], [True]) == 6
    np.testing.assert_allclose(grid[1, 1:6], -0.5)
    assert grid[1, 6] == pytest.approx(1.0)
    assert grid[1, 7] == 0.0 and grid[2, 6] == 0.0
    for _ in range(10):
        rays_into(grid, [6.5], [1.5], [True])
    assert grid[1, 6] == pytest.approx(3.0)  # clamped at l_max
    np.testing.assert_allclose(grid[1, 1:6], -2.0)  # clamped at l_min
    # a free-space-only ray (no return) does not mark its end as occupied
    rays_into(grid, [1.5], [8.5], [False])
    assert grid[8, 1] == pytest.approx(-0.5)


def test_integrate_rays_puts_each_scan_in_its_part_of_the_grid():
    """Scan by scan, each into its own part of the grid with its own origin: the cells a part
    holds are those its scan alone gives a grid of the part's size; a scan with h = 0 is
    skipped, and rays leaving a part touch nothing outside it."""
    rng = np.random.default_rng(4)
    whole = np.zeros((30, 40), dtype=np.float32)
    views = np.array([[2, 3, 12, 15], [10, 20, 18, 19], [0, 0, 0, 0], [2, 3, 12, 15]])
    origins = np.array([[-1.0, 2.0], [4.0, -3.0], [0.0, 0.0], [-1.0, 2.0]])
    sensors = np.array([[5.2, 7.9], [12.0, 4.1], [1.0, 1.0], [3.3, 9.0]])
    ends = rng.uniform(-5.0, 25.0, (40, 2))
    hit = rng.random(40) < 0.6
    offsets = np.array([0, 10, 25, 30, 40])
    count = integrate_rays(whole, views, origins, 1.0, sensors, offsets, ends[:, 0].copy(),
                           ends[:, 1].copy(), hit, 1.0, -0.5, -2.0, 3.0)  # fmt: skip
    want = np.zeros_like(whole)
    total = 0
    for i in (0, 1, 3):
        r0, c0, h, w = views[i]
        part = np.zeros((h, w), dtype=np.float32)
        part[:] = want[r0 : r0 + h, c0 : c0 + w]
        a, b = offsets[i], offsets[i + 1]
        total += integrate_rays(part, np.array([[0, 0, h, w]]), origins[i : i + 1], 1.0,
                                sensors[i : i + 1], np.array([0, b - a]), ends[a:b, 0].copy(),
                                ends[a:b, 1].copy(), hit[a:b], 1.0, -0.5, -2.0, 3.0)  # fmt: skip
        want[r0 : r0 + h, c0 : c0 + w] = part
    assert count == total > 50
    assert whole.tobytes() == want.tobytes()
    assert (whole[:2] == 0).all() and (whole[:, :3] == 0).all()  # outside every part


def test_correlation_counts_endpoints_on_occupied_cells():
    occupied = np.zeros((20, 20), dtype=np.bool_)
    occupied[10, 5:15] = True  # a wall along y = 10..11 (cells of 1 m)
    ex = np.arange(0.0, 10.0) + 0.5  # endpoints in the robot frame
    ey = np.full(10, 5.5)
    pose = np.array([5.0, 5.0, 0.0])
    assert correlation(occupied, 0.0, 0.0, 1.0, pose, ex, ey) == 10
    assert correlation(occupied, 0.0, 0.0, 1.0, np.array([5.0, 3.0, 0.0]), ex, ey) == 0
    # a local search from 2 cells below finds the full correlation at dy = +2
    poses = np.array([[5.0, 3.0, 0.0], [3.0, 5.0, 0.0]])
    corr = np.empty(2, dtype=np.int64)
    offsets = np.empty((2, 3))
    correlation_search(occupied, 0.0, 0.0, 1.0, poses, ex, ey, 2, np.array([0.0]), corr, offsets)
    assert corr[0] == 10
    np.testing.assert_allclose(offsets[0], [0.0, 2.0, 0.0])
    # from 2 cells left, 8 of 10 endpoints are on the wall; the search finds all 10 at dx = +2
    assert correlation(occupied, 0.0, 0.0, 1.0, poses[1], ex, ey) == 8
    assert corr[1] == 10
    np.testing.assert_allclose(offsets[1], [2.0, 0.0, 0.0])


def test_likelihood_tables_match_the_formula():
    tables, step_inv = likelihood_tables(np.array([0.1, 0.05]), 1.0, 0.05, 0.3, size=301)
    assert step_inv == pytest.approx(1000.0)
    d = 0.07
    i = 70
    assert tables[1, 0, i] == pytest.approx(-np.log(np.exp(-0.5 * (d / 0.05) ** 2) + 0.05))
    phi = np.exp(-0.5 * (d / 0.1) ** 2)
    assert tables[0, 1, i] == pytest.approx(phi / (phi + 0.05) / 0.01)


def test_effective_sample_size():
    assert effective_sample_size(np.full(50, 1 / 50)) == pytest.approx(50.0)
    assert effective_sample_size(np.array([1.0, 0.0, 0.0])) == pytest.approx(1.0)
    assert effective_sample_size(np.array([0.5, 0.5, 0.0, 0.0])) == pytest.approx(2.0)


def test_systematic_resampling_copies_within_one_of_expected():
    rng = np.random.default_rng(3)
    for _ in range(200):
        w = rng.random(40) ** 3
        w /= w.sum()
        idx = systematic_resample(w, rng.random())
        copies = np.bincount(idx, minlength=40)
        assert copies.sum() == 40
        assert np.all(np.abs(copies - 40 * w) < 1.0 + 1e-9)
        assert np.all(np.diff(idx) >= 0)


def test_motion_model_mean_and_covariance():
    rng = np.random.default_rng(7)
    n = 200_000
    poses = np.zeros((n, 3))
    inc = np.array([1.0, 0.0, 0.2])
    alphas = np.array([0.1, 0.05, 0.02, 0.1, 0.03])
    floor = np.array([0.01, 0.01, 0.005])
    out = sample_motion(poses, inc, rng.standard_normal((n, 3)), alphas, floor)
    d, a = 1.0, 0.2
    sx = alphas[0] * d + alphas[1] * a + floor[0]
    sy = alphas[2] * d + alphas[1] * a + floor[1]
    st = alphas[3] * a + alphas[4] * d + floor[2]
    np.testing.assert_allclose(out.mean(axis=0), inc, atol=3e-4)
    cov = np.cov(out.T)
    np.testing.assert_allclose(np.diag(cov), [sx**2, sy**2, st**2], rtol=0.02)
    assert abs(cov[0, 1]) < 2e-5 and abs(cov[0, 2]) < 2e-5
    # from a rotated start the increment is applied in the robot frame
    turned = sample_motion(np.array([[1.0, 2.0, np.pi / 2]]), inc, np.zeros((1, 3)), alphas, floor)
    np.testing.assert_allclose(turned[0], [1.0, 3.0, np.pi / 2 + 0.2])


def _wall_maps(particles=3, signed=True):
    maps = ParticleMaps(particles, 0.05, 0.3, tile=8, size_m=8.0, signed=signed)
    hy = np.linspace(-1.5, 1.5, 301)
    hx = np.full_like(hy, 2.0)  # a wall 2 m ahead, along y
    nx, ny = np.full_like(hx, -1.0), np.zeros_like(hy)  # facing the sensor at the origin
    maps.insert(np.zeros((1, 3)), hx, hy, nx, ny, 0.0)
    maps.share_from(0)
    return maps, hx, hy


def test_unsigned_field_is_the_distance_to_the_nearest_hit():
    maps, _, _ = _wall_maps(signed=False)
    view = maps.field(0)
    # a cell centre 12.5 cm from the wall; one hit per cell is kept, so the nearest kept hit may
    # lie up to half a cell (2.5 cm) along the wall: d in [0.125, hypot(0.125, 0.025)]
    upper = np.hypot(0.125, 0.025) + 1e-6
    d, gx, _ = surface_at(view, 1.875, 0.0)
    assert 0.125 - 1e-6 <= d <= upper and gx == pytest.approx(-1.0, abs=0.05)
    d, gx, _ = surface_at(view, 2.125, 0.0)
    assert 0.125 - 1e-6 <= d <= upper and gx == pytest.approx(1.0, abs=0.05)


def test_signed_field_is_exact_across_a_wall():
    maps, _, _ = _wall_maps()
    view = maps.field(0)
    for x in (1.8, 1.9, 1.987, 2.0, 2.013, 2.1, 2.2):
        d, gx, gy = surface_at(view, x, 0.013)
        assert d == pytest.approx(2.0 - x, abs=1e-5)  # sensor side positive, zero on the wall
        assert gx == pytest.approx(-1.0, abs=1e-5) and abs(gy) < 1e-5
    assert np.isnan(surface_at(view, 0.5, 0.0)[0])  # beyond dmax: unknown


def test_tiles_are_shared_until_written():
    maps, hx, hy = _wall_maps(particles=3)
    used = maps.tiles_in_use
    assert np.all(maps.tables[1] == maps.tables[0])
    # particle 2 sees a new wall: only it gets new tiles, the shared ones stay shared
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, np.pi / 2]])
    maps.insert(poses, hx, hy, np.full_like(hx, -1.0), np.zeros_like(hy), 0.01)
    assert np.all(maps.tables[0] == maps.tables[1])
    assert np.any(maps.tables[2] != maps.tables[0])
    assert maps.tiles_in_use > used
    # resampling onto particle 2 frees the tiles only particles 0 and 1 held
    maps.resample(np.array([2, 2, 2]))
    assert np.all(maps.tables[0] == maps.tables[2])
    refcount = np.zeros_like(maps.refcount)
    stack = np.zeros_like(maps.free_stack)
    free = recount_tiles(maps.tables, refcount, stack)
    assert maps.capacity - free == len(np.unique(maps.tables[maps.tables >= 0]))


@pytest.mark.parametrize("parents", [[3, 3, 0, 1, 1, 1], [5, 4, 3, 2, 1, 0], [2, 2, 2, 2]])
def test_resampled_tables_count_their_tiles_as_a_recount_does(parents):
    """``resample_tables`` (each surviving parent's table counted once, times its children)
    gives the copied tables, reference counts and free stack of indexing plus
    ``recount_tiles``."""
    rng = np.random.default_rng(7)
    tables = rng.integers(-1, 40, size=(6, 5, 7)).astype(np.int32)
    tables[rng.random(tables.shape) < 0.6] = -1  # mostly unknown, as a big building's
    parents = np.array(parents, dtype=np.int64)
    children = np.bincount(parents, minlength=6).astype(np.int64)
    want = np.ascontiguousarray(tables[parents])
    want_count, want_stack = np.zeros(48, np.int32), np.zeros(48, np.int32)
    want_top = recount_tiles(want, want_count, want_stack)
    out = np.full_like(want, -1)  # what the kernel asks of it: -1 outside the spans
    count, stack = np.full(48, 99, np.int32), np.full(48, -5, np.int32)
    top = resample_tables(tables, tile_spans(tables), parents, children, out, count, stack)
    assert np.array_equal(out, want) and np.array_equal(count, want_count)
    assert top == want_top and np.array_equal(stack[:top], want_stack[:top])
    assert count.sum() == (want >= 0).sum() and top == 48 - len(np.unique(want[want >= 0]))


def test_spans_cover_every_tile_through_inserts_growth_and_resamplings():
    """Each row's span holds every tile of every particle's table, through inserts, growth of
    the tables and resamplings that write into the tables an earlier resampling left (stale
    entries within the spans, -1 outside): each resampling gives exactly ``tables[parents]``
    and the counts a recount gives."""
    rng = np.random.default_rng(3)
    maps = ParticleMaps(4, 0.05, 0.3, tile=16, size_m=8.0, grow_margin_m=2.0)
    grew = 0
    for step in range(12):
        poses = np.column_stack(
            [rng.uniform(-3, 3, 4) + step, rng.uniform(-3, 3, 4), rng.uniform(-np.pi, np.pi, 4)]
        )
        angles = np.linspace(-1.5, 1.5, 40)
        reach = rng.uniform(0.5, 6.0, 40)
        hx, hy = reach * np.cos(angles), reach * np.sin(angles)
        shape = maps.tables.shape
        maps.ensure_contains(
            poses[:, 0].min() - 6,
            poses[:, 1].min() - 6,
            poses[:, 0].max() + 6,
            poses[:, 1].max() + 6,
        )
        grew += maps.tables.shape != shape
        maps.insert(poses, hx, hy, hx, hy, 0.01)
        cols = np.arange(maps.tables.shape[2])
        outside = (cols < maps.spans[:, :1]) | (cols > maps.spans[:, 1:])
        assert np.all(maps.tables[:, outside] == -1)
        tight = tile_spans(maps.tables)  # the spans of today's tiles: within the kept ones
        assert np.all(maps.spans[:, 0] <= tight[:, 0]) and np.all(maps.spans[:, 1] >= tight[:, 1])
        parents = np.sort(rng.integers(0, 4, 4))
        want = maps.tables[parents].copy()
        maps.resample(parents)
        assert np.array_equal(maps.tables, want)
        count, stack = np.zeros_like(maps.refcount), np.zeros_like(maps.free_stack)
        top = recount_tiles(want, count, stack)
        assert np.array_equal(maps.refcount, count) and maps.free_top[0] == top
    assert grew >= 2  # the tables grew in between: the spans were shifted with them


def _room_maps(signed):
    """Two particles' maps of one room (four walls of a 6 m x 4 m rectangle around the origin,
    sampled every 2 cm) and the walls' points ``hx``, ``hy``."""
    maps = ParticleMaps(2, 0.05, 0.3, tile=16, size_m=12.0, signed=signed)
    s = np.arange(-3.0, 3.0, 0.02)
    t = np.arange(-2.0, 2.0, 0.02)
    hx = np.concatenate([s, s, np.full_like(t, -3.0), np.full_like(t, 3.0)])
    hy = np.concatenate([np.full_like(s, -2.0), np.full_like(s, 2.0), t, t])
    nx = np.concatenate([np.zeros_like(s), np.zeros_like(s), np.ones_like(t), -np.ones_like(t)])
    ny = np.concatenate([np.ones_like(s), -np.ones_like(s), np.zeros_like(t), np.zeros_like(t)])
    maps.insert(np.zeros((1, 3)), hx, hy, nx, ny, 0.0)
    maps.share_from(0)
    return maps, hx, hy


@pytest.mark.parametrize("signed, tolerance", [(True, 1e-3), (False, 0.025)])
def test_scan_matching_recovers_a_known_offset(signed, tolerance):
    """The signed field is exact; the unsigned one snaps walls to cell centres (≤ half a cell)."""
    maps, hx, hy = _room_maps(signed)
    # the same room seen from the true pose (0.4, -0.3, 0.1): endpoints in that robot frame
    true = np.array([0.4, -0.3, 0.1])
    c, s_ = np.cos(true[2]), np.sin(true[2])
    dx, dy = hx - true[0], hy - true[1]
    ex, ey = c * dx + s_ * dy, -s_ * dx + c * dy
    pick = slice(None, None, 5)
    start = np.array([[0.48, -0.22, 0.14], [0.35, -0.35, 0.07]])
    luts = likelihood_tables(np.array([0.15, 0.075, 0.04]), 1.0, 0.05, maps.dmax)
    out = maps.match(start, ex[pick].copy(), ey[pick].copy(), luts, 20, 1e-5, 0.3)
    np.testing.assert_allclose(out.poses, np.tile(true, (2, 1)), atol=tolerance)
    if signed:  # a well-posed match: the Hessian (inverse covariance) is positive definite
        assert np.all(np.linalg.eigvalsh(out.hessian) > 0)
    assert np.all(out.inliers > 0.99)


@pytest.mark.parametrize("signed", [True, False])
def test_one_pose_insert_equals_the_parallel_kernels(signed):
    """One pose goes through the serial kernel (insert_serial), several through the three
    parallel ones: the same maps, bit for bit, with a pool that has to grow on the way."""
    hy = np.linspace(-1.5, 1.5, 301)
    hx = np.full_like(hy, 2.0) + 0.3 * np.sin(3.0 * hy)  # a wavy wall 2 m ahead
    nx, ny = np.full_like(hx, -1.0), np.zeros_like(hy)
    pose = np.array([[0.11, -0.07, 0.2]])
    one = ParticleMaps(1, 0.05, 0.3, tile=8, size_m=8.0, capacity=4, signed=signed)
    many = ParticleMaps(2, 0.05, 0.3, tile=8, size_m=8.0, capacity=4, signed=signed)
    for maps, poses in ((one, pose), (many, np.repeat(pose, 2, axis=0))):
        maps.insert(poses, hx, hy, nx, ny, 0.01)
        maps.insert(poses + [0.02, 0.01, 0.0], hx, hy, nx, ny, 0.01)  # partly seen already
    assert one.capacity > 4 and one.tiles_in_use == many.tiles_in_use // 2
    for p in (0, 1):
        known = many.tables[p] >= 0
        assert np.array_equal(known, one.tables[0] >= 0)
        for layer in ("dist", "surface"):
            a = getattr(one, layer)[one.tables[0][known]]
            b = getattr(many, layer)[many.tables[p][known]]
            assert np.array_equal(a, b, equal_nan=True)


def _cell_values(maps, particle=0):
    """Every cell of one particle's ``dist`` layer as one 2-D array (NaN where no tile is)."""
    t = maps.tables[particle]
    side = 1 << maps.shift
    out = np.full((t.shape[0] * side, t.shape[1] * side), np.nan, dtype=np.float32)
    for ty, tx in zip(*np.nonzero(t >= 0), strict=True):
        out[ty * side : (ty + 1) * side, tx * side : (tx + 1) * side] = maps.dist[t[ty, tx]]
    return out


@pytest.mark.parametrize("particles", [1, 2])
def test_the_distance_updates_are_the_straightforward_rule_bit_for_bit(particles):
    """Each kept hit gives every cell whose centre is nearer than ``dmax`` (strictly) its
    distance ``sqrt(dx² + dy²)`` where that is below what the cell holds. The kernel decides most
    cells by squared distances with no square root; against this rule written out in numpy,
    the same float32 values cell for cell, with hits placed so that cell centres lie within a
    few units in the last place of ``dmax`` (both sides), and a second scan whose squares
    overlap the first's (cells that already hold a nearer hit). Which hits are kept follows the
    selection's rule (a hit in the cell of the hit before it, or in a cell that already holds a
    distance no larger than its own, adds nothing)."""
    res, dmax = 0.05, 0.3
    maps = ParticleMaps(particles, res, dmax, tile=8, size_m=8.0, capacity=4, signed=False)
    (ox, oy) = maps.geometry.origin
    rng = np.random.default_rng(11)
    centre = ox + (80 + 0.5) * res  # a cell centre (x); hits dmax away from centres along x
    edge = centre + dmax + np.array([-2e-16, 0.0, 2e-16, -1e-12, 1e-12])
    first = np.r_[edge, rng.uniform(-2.5, 2.5, 40)]
    first_y = np.r_[np.full(edge.size, oy + 90.5 * res), rng.uniform(-2.5, 2.5, 40)]
    second = first[edge.size :] + rng.uniform(-0.2, 0.2, 40)  # near the first ones
    second_y = first_y[edge.size :] + rng.uniform(-0.2, 0.2, 40)
    nx = ny = np.zeros(first.size)
    poses = np.zeros((particles, 3))
    cells = _cell_values(maps)
    expected = np.full(cells.shape, np.inf)
    iy, ix = np.mgrid[0 : cells.shape[0], 0 : cells.shape[1]]
    dropped = 0
    for hx, hy in ((first, first_y), (second, second_y)):
        before = np.where(np.isfinite(expected), expected, np.float32(dmax))
        last = None
        for k in range(hx.size):
            cell = (int(np.floor((hy[k] - oy) / res)), int(np.floor((hx[k] - ox) / res)))
            own = np.hypot(ox + (cell[1] + 0.5) * res - hx[k], oy + (cell[0] + 0.5) * res - hy[k])
            kept = cell != last and np.float32(before[cell]) > own  # what adds something
            last = cell
            if not kept:
                dropped += 1
                continue
            ccx = ox + (ix + 0.5) * res - hx[k]
            ccy = oy + (iy + 0.5) * res - hy[k]
            d = np.sqrt(ccx * ccx + ccy * ccy)
            near = d < dmax
            expected[near] = np.minimum(expected[near], d[near])
        maps.insert(poses, hx, hy, nx[: hx.size], ny[: hx.size], 0.0)
    want = np.where(np.isfinite(expected), expected, np.nan).astype(np.float32)
    assert np.sum(np.isfinite(expected)) > 3000  # the squares cover thousands of cells
    assert dropped > 0  # the second scan has hits the selection drops
    for p in range(particles):
        got = _cell_values(maps, p)
        written = ~np.isnan(got)
        assert np.array_equal(np.isnan(want[written]), np.isnan(got[written]))
        assert np.array_equal(want[written], got[written], equal_nan=True)
        assert np.all(np.isnan(want[~written]))  # no cell outside the tiles was due a value


def test_the_unsigned_fields_one_layer_holds_what_two_layers_do():
    """The unsigned field keeps one array for both layers (NaN where no hit is near, read as
    ``dmax``): its maps equal, bit for bit, those of a pool that keeps the ``dist`` layer apart,
    through insertions that keep or skip hits, copy shared tiles and grow the pool."""
    hy = np.linspace(-1.5, 1.5, 301)
    hx = np.full_like(hy, 2.0) + 0.3 * np.sin(3.0 * hy)
    nx, ny = np.full_like(hx, -1.0), np.zeros_like(hy)
    one = ParticleMaps(3, 0.05, 0.3, tile=8, size_m=8.0, capacity=4, signed=False)
    two = ParticleMaps(3, 0.05, 0.3, tile=8, size_m=8.0, capacity=4, signed=False)
    two.dist = np.empty_like(two.surface)  # the two-layer storage (what the signed field keeps)
    assert one.one_layer and not two.one_layer
    rng = np.random.default_rng(5)
    for step in range(6):
        poses = np.array([[0.1 * step, 0.0, 0.05 * step]]) + 0.03 * rng.standard_normal((3, 3))
        for maps in (one, two):
            maps.insert(poses, hx, hy, nx, ny, 0.01)
            if step == 2:
                maps.resample(np.array([1, 1, 0]))  # shared tiles, copied on the next write
    assert one.capacity > 4 and one.one_layer and not two.one_layer
    assert np.array_equal(one.tables, two.tables)
    used = np.unique(one.tables[one.tables >= 0])
    a, b = one.surface[used], two.surface[used]
    assert np.array_equal(a, b, equal_nan=True) and np.isnan(a).any() and not np.isnan(a).all()
    assert np.array_equal(two.dist[used], np.where(np.isnan(a), np.float32(0.3), a))
    assert one.memory_bytes() < two.memory_bytes()


@pytest.mark.parametrize("signed", [True, False])
def test_inserting_scans_in_one_call_equals_inserting_them_one_by_one(signed):
    """ParticleMaps.insert_scans (one kernel call per stretch that needs no growth) gives the
    map of ensure_contains + insert scan by scan, bit for bit: the robot drives 12 m out of a
    4 m map (the tables grow on the way, the tile pool too) and one scan has no hits."""
    rng = np.random.default_rng(3)
    scans, poses, reach = [], [], []
    for k in range(14):
        angles = np.linspace(-1.5, 1.5, 90)
        ranges = 1.5 + 0.5 * np.sin(2.0 * angles + k) + 0.01 * rng.standard_normal(90)
        hx, hy = ranges * np.cos(angles), ranges * np.sin(angles)
        if k == 5:
            hx, hy = hx[:0], hy[:0]  # a scan without hits is skipped
        nx, ny = -np.cos(angles[: hx.size]), -np.sin(angles[: hx.size])
        scans.append((hx, hy, nx, ny))
        poses.append([0.9 * k, 0.05 * k, 0.1 * k])
        reach.append(float(np.sqrt((hx * hx + hy * hy).max())) + 1.3 if hx.size else 0.0)
    poses = np.array(poses)
    reach = np.array(reach)
    one = ParticleMaps(1, 0.05, 0.3, tile=8, size_m=4.0, capacity=4, signed=signed)
    for pose, r, (hx, hy, nx, ny) in zip(poses, reach, scans, strict=True):
        if hx.size:
            one.ensure_contains(pose[0] - r, pose[1] - r, pose[0] + r, pose[1] + r)
            one.insert(pose[None, :].copy(), hx, hy, nx, ny, 0.01)
    batch = ParticleMaps(1, 0.05, 0.3, tile=8, size_m=4.0, capacity=4, signed=signed)
    offsets = np.cumsum([0] + [hx.size for hx, _, _, _ in scans])
    hits = np.concatenate([np.stack(part) for part in scans], axis=1)
    batch.insert_scans(poses, hits, offsets, reach, 0.01)
    assert batch.tables.shape == one.tables.shape and batch.tables.shape[2] > 8
    assert np.array_equal(batch.origin, one.origin)
    assert batch.capacity == one.capacity > 4
    assert np.array_equal(batch.tables, one.tables)
    used = one.tables[one.tables >= 0]
    for layer in ("dist", "surface"):
        assert np.array_equal(
            getattr(batch, layer)[used], getattr(one, layer)[used], equal_nan=True
        )
    if not signed:  # the unsigned field ignores normals: (2, N) hits stand for their own
        plain = ParticleMaps(1, 0.05, 0.3, tile=8, size_m=4.0, capacity=4, signed=False)
        plain.insert_scans(poses, hits[:2].copy(), offsets, reach, 0.01)
        again = ParticleMaps(1, 0.05, 0.3, tile=8, size_m=4.0, capacity=4, signed=False)
        again.insert_scans(poses, np.concatenate([hits[:2], hits[:2]]), offsets, reach, 0.01)
        assert np.array_equal(plain.tables, again.tables)
        used = again.tables[again.tables >= 0]
        for layer in ("dist", "surface"):
            assert np.array_equal(
                getattr(plain, layer)[used], getattr(again, layer)[used], equal_nan=True
            )
    with pytest.raises(ValueError, match="one-particle map, found 2"):
        ParticleMaps(2, 0.05, 0.3).insert_scans(poses, hits, offsets, reach, 0.01)


def test_scan_hits_take_gathers_the_rows_asked_for():
    """ScanSequence.hit_table keeps each scan's hits as Scan.hits gives them; take() gathers
    any rows, in the order asked, with the hits again where no normals were kept."""
    from slam.config import LidarConfig
    from slam.scans import Scan, ScanSequence

    seq = ScanSequence()
    angles = np.linspace(-1.0, 1.0, 50)
    for k in range(4):
        ranges = np.full(50, 2.0 + k, dtype=np.float32)
        ranges[: 10 * k] = np.nan  # fewer returns each scan
        scan = Scan(float(k), ranges, angles).resolved(LidarConfig())
        seq.append(scan, [0.0, 0.0, 0.0])
    table = seq.hit_table([3, 1, 2], max_beams=20)
    hits, offsets, reach = table.take(np.array([2, 0]))
    hx2, hy2 = seq.hits(2, 20)
    hx3, hy3 = seq.hits(3, 20)
    assert offsets.tolist() == [0, hx2.size, hx2.size + hx3.size]
    assert np.array_equal(hits[0], np.concatenate([hx2, hx3]))
    assert hits.shape[0] == 2 and np.array_equal(hits[1], np.concatenate([hy2, hy3]))
    far = [np.sqrt((hx * hx + hy * hy).max()) for hx, hy in ((hx2, hy2), (hx3, hy3))]
    assert reach.tolist() == far
    with_normals = seq.hit_table([1], normals=True)
    assert with_normals.xy.shape[0] == 4
    assert np.array_equal(with_normals.xy[2], seq.hits_with_normals(1)[2])


def test_particle_score_and_hessian_are_those_at_the_reported_pose():
    """match_particles reuses the matcher's last evaluation when it was at the reported pose;
    its score and Hessian equal a fresh normal_equations there either way."""
    from slam.kernels.field import normal_equations

    maps, hx, hy = _wall_maps(particles=4)
    luts, step_inv = likelihood_tables(np.array([0.2, 0.075, 0.04]), 0.9, 0.1, 0.3)
    ex, ey = hx[::3] - 0.03, hy[::3] + 0.02
    # matches near the wall (headings whose wrapping keeps or changes their bits), one facing
    # away from it and one far off (both untrusted: the predicted pose is kept)
    poses = np.array([[0.0, 0.0, -2.9], [0.01, 0.0, 0.1], [0.0, 0.01, -0.03], [5.0, 5.0, 0.0]])
    out = maps.match(poses, ex, ey, (luts, step_inv), 5, 1e-3, 0.5)
    assert np.all(out.inliers[1:3] > 0.9) and np.all(out.inliers[[0, 3]] == 0.0)
    assert np.array_equal(out.poses[[0, 3]], poses[[0, 3]])
    for p in range(4):
        h, g = np.zeros((3, 3)), np.zeros(3)
        cost, _ = normal_equations(
            maps.field(p), *out.poses[p], ex, ey, luts[-1, 0], luts[-1, 1], step_inv, h, g, 1
        )
        assert out.loglik[p] == -cost and np.array_equal(out.hessian[p], h)


def _refine_by_the_rule(view, pose, ex, ey, settings):
    """The Levenberg-Marquardt levels of ``refine`` written out in Python from its docstring
    (every beam, ``coarse_stride`` 1): the refined ``(x, y, th, cost, inliers)``."""
    from slam.kernels.field import accumulate, beam_geometry, gauss_newton_system, scan_cost
    from slam.kernels.linalg import solve_sym3

    luts, step_inv, tol = settings.luts, settings.step_inv, settings.tolerance
    x, y, th = (float(v) for v in pose)
    h, g = np.zeros((3, 3)), np.zeros(3)
    geo = np.empty((ex.size, 4))
    none = np.zeros(ex.size, np.uint8)  # no beam gone (the view has no vacancy grid)
    beam_geometry(geo, view, x, y, th, 1, ex, ey, none)
    cost, inliers = 0.0, 0
    for level in range(luts.shape[0]):
        cost_row, weight_row = luts[level, 0], luts[level, 1]
        cost, inliers = accumulate(geo, cost_row, weight_row, step_inv, h, g)
        lam = 1e-3
        for _ in range(settings.max_iter):
            hd = h.copy()
            for k in range(3):
                hd[k, k] += lam * h[k, k] + 1e-9
            s0, s1, s2, _ = solve_sym3(
                hd[0, 0], hd[0, 1], hd[0, 2], hd[1, 1], hd[1, 2], hd[2, 2], g[0], g[1], g[2], 1e-18
            )
            trial = np.empty((ex.size, 4))
            beam_geometry(trial, view, x - s0, y - s1, th - s2, 1, ex, ey, none)
            new_cost, new_inliers = scan_cost(trial, cost_row, step_inv)
            if new_cost < cost:  # taken: its Gauss-Newton system too
                gauss_newton_system(trial, weight_row, step_inv, h, g)
                x, y, th, cost, inliers, geo = x - s0, y - s1, th - s2, new_cost, new_inliers, trial
                lam = max(lam * 0.3, 1e-7)
                if abs(s0) < tol and abs(s1) < tol and abs(s2) < tol:
                    break
            else:  # undone, the damping raised tenfold
                lam *= 10.0
                if lam > 1e3:
                    break
    return x, y, th, cost, inliers


def test_the_matcher_is_its_documented_levenberg_marquardt_bit_for_bit():
    """``refine`` is, bit for bit, the Levenberg-Marquardt of its docstring (written out in
    Python above), from 24 starts around the true pose in a room of the unsigned field, and it
    ends near the true pose (within the unsigned field's half cell)."""
    from slam.kernels.field import MatchSettings, refine

    maps, hx, hy = _room_maps(signed=False)
    true = np.array([0.4, -0.3, 0.1])
    c, s = np.cos(true[2]), np.sin(true[2])
    ex = np.ascontiguousarray((c * (hx - true[0]) + s * (hy - true[1]))[::7])
    ey = np.ascontiguousarray((-s * (hx - true[0]) + c * (hy - true[1]))[::7])
    luts, step_inv = likelihood_tables(np.array([0.2, 0.075, 0.04]), 1.0, 0.05, maps.dmax)
    settings = MatchSettings(luts, step_inv, 5, 1e-3, 1, 0.0)
    view = maps.field(0)
    starts = true + np.random.default_rng(3).normal(0.0, [0.05, 0.05, 0.03], size=(24, 3))
    for start in starts:
        got = refine(view, start, ex, ey, settings, np.zeros((3, 3)))
        assert got == _refine_by_the_rule(view, start, ex, ey, settings)
        assert np.hypot(got[0] - true[0], got[1] - true[1]) < 0.025 and abs(got[2] - true[2]) < 0.01
