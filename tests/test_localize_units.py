"""Localization's parts with numbers: KLD bound, beam-model normalisation, histogram filter
against a brute-force posterior, the lost monitor."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from slam.config import LocalizeConfig
from slam.localize.histogram import LEVELS, QUANTUM, PoseHistogram, cell_weights
from slam.localize.kernels import DistanceView, particle_loglik, refine_pose
from slam.localize.kld import KldCounter, kld_bound, normal_quantile
from slam.localize.maps import LikelihoodMap, wall_points, wall_surface
from slam.localize.mcl import MotionModel, weighted_mean_pose
from slam.localize.recovery import LostMonitor
from slam.localize.sensor import BeamModel

# -- KLD-sampling


def fox_formula(k: int, epsilon: float, delta: float) -> float:
    """Fox 2003, eq. (12), written out independently of slam.localize.kld."""
    z = normal_quantile(1.0 - delta)
    return (k - 1) / (2 * epsilon) * (1 - 2 / (9 * (k - 1)) + math.sqrt(2 / (9 * (k - 1))) * z) ** 3


@pytest.mark.parametrize("k", [2, 3, 10, 50, 200, 1000])
@pytest.mark.parametrize(("epsilon", "delta"), [(0.05, 0.01), (0.1, 0.05), (0.02, 0.001)])
def test_kld_bound_is_fox_formula(k, epsilon, delta):
    assert kld_bound(k, epsilon, delta) == pytest.approx(fox_formula(k, epsilon, delta), rel=1e-12)


def test_kld_bound_matches_chi_square_quantiles():
    # n = chi2_{k-1, 1-delta} / (2 epsilon); chi-square quantiles from the tables:
    # chi2_{0.99}(10) = 23.209, chi2_{0.99}(50) = 76.154, chi2_{0.95}(20) = 31.410
    assert kld_bound(11, 0.05, 0.01) == pytest.approx(23.209 / 0.1, rel=2e-3)
    assert kld_bound(51, 0.05, 0.01) == pytest.approx(76.154 / 0.1, rel=2e-3)
    assert kld_bound(21, 0.1, 0.05) == pytest.approx(31.410 / 0.2, rel=2e-3)
    assert normal_quantile(0.99) == pytest.approx(2.326348, abs=1e-6)
    assert kld_bound(1, 0.05, 0.01) == 0.0


@pytest.mark.parametrize("bins", [5, 20, 60])
def test_kld_sampler_stops_at_the_bound_of_the_bins_seen(bins):
    # samples cycle through `bins` distinct bins (0.2 m apart in x): after the first `bins`
    # samples k stays at `bins`, so sampling stops at the first n >= bound(bins)
    n_max = 100000
    counter = KldCounter(0.2, 0.1745, 0.05, 0.01, n_min=10, n_max=n_max)
    cycle = np.zeros((bins, 3))
    cycle[:, 0] = 0.2 * np.arange(bins) + 0.1
    poses = np.tile(cycle, (n_max // bins + 1, 1))[:n_max]
    kept = counter.feed(poses)
    assert counter.bins == bins
    assert kept == max(10, math.ceil(kld_bound(bins, 0.05, 0.01)))


def test_kld_sampler_chunks_give_the_same_count_and_respects_limits():
    rng = np.random.default_rng(3)
    poses = rng.normal(0.0, [0.3, 0.3, 0.1], size=(20000, 3))
    whole = KldCounter(0.2, 0.1745, 0.05, 0.01, 50, 20000).feed(poses)
    counter = KldCounter(0.2, 0.1745, 0.05, 0.01, 50, 20000)
    kept, start = -1, 0
    for stop in (100, 400, 1600, 20000):
        kept = counter.feed(poses[:stop], start)
        if kept >= 0:
            break
        start = stop
    assert kept == whole and 50 < whole < 20000
    # a single bin: the minimum; everything spread: the maximum
    assert KldCounter(0.2, 0.1745, 0.05, 0.01, 50, 1000).feed(np.zeros((1000, 3))) == 50
    spread = np.stack([np.arange(1000) * 0.5, np.zeros(1000), np.zeros(1000)], axis=1)
    assert KldCounter(0.2, 0.1745, 0.05, 0.01, 50, 1000).feed(spread) == 1000


# -- the beam model


def wall_map(wall_x: float, size: float, resolution: float) -> LikelihoodMap:
    """A map whose only obstacle is a wall along x = wall_x (one cell thick)."""
    cells = int(round(size / resolution))
    occupied = np.zeros((cells, cells), dtype=bool)
    occupied[:, int(wall_x / resolution)] = True
    return LikelihoodMap.from_masks(occupied, ~occupied, resolution, (0.0, -size / 2))


@pytest.mark.parametrize("sigma", [0.05, 0.1, 0.2])
def test_beam_model_mixture_integrates_to_one(sigma):
    # one beam along +x towards a wall at z* = 5 m: the density the kernel evaluates, over
    # z in [0, z_range], plus the no-return mass z_max, is 1
    z_range = 10.0
    lmap = wall_map(5.0, 12.0, 0.01)
    wall = 5.005  # the occupied cells' centres
    model = BeamModel(0.8, 0.1, 0.1, sigma, z_range)
    table = model.log_table(2.0, size=4096)
    z = np.linspace(0.0, z_range, 20001)
    poses = np.zeros((z.size, 3))  # the robot at the origin, facing +x
    loglik = np.empty(z.size)
    for i, length in enumerate(z):
        out = np.empty(1)
        particle_loglik(
            DistanceView(lmap.distance, 0.0, -6.0, 1.0 / lmap.resolution), poses[i : i + 1],
            np.array([length]), np.array([0.0]), table[0], table[1], out,
        )  # fmt: skip
        loglik[i] = out[0]
    density = np.exp(loglik)
    total = np.trapezoid(density, z) + model.z_max
    assert total == pytest.approx(1.0, abs=3e-3)
    # the peak sits on the wall and has the Gaussian's height
    assert z[np.argmax(density)] == pytest.approx(wall, abs=0.01)
    peak = model.z_hit / (sigma * math.sqrt(2 * math.pi)) + model.z_rand / z_range
    assert density.max() == pytest.approx(peak, rel=0.02)
    # far from the wall only the uniform term is left
    assert density[0] == pytest.approx(model.z_rand / z_range, rel=1e-6)


def test_particle_loglik_is_the_sum_of_beam_log_densities():
    lmap = wall_map(5.0, 12.0, 0.05)
    model = BeamModel(0.9, 0.05, 0.05, 0.1, 27.0)
    table = model.log_table(2.0)
    # beams ending at cell centres 0.025, 0.125 and 0.525 m in front of the wall (x = 5.025)
    ex = np.array([5.0, 4.9, 4.5])
    ey = np.array([0.025, 0.025, 0.025])
    out = np.empty(1)
    particle_loglik(
        DistanceView(lmap.distance, 0.0, -6.0, 20.0),
        np.zeros((1, 3)),
        ex,
        ey,
        table[0],
        table[1],
        out,
    )
    expected = model.log_density(np.array([0.025, 0.125, 0.525])).sum()
    assert out[0] == pytest.approx(expected, abs=1e-4)


def test_weighted_mean_pose_wraps_headings():
    poses = np.array([[1.0, 0.0, math.pi - 0.1], [3.0, 2.0, -math.pi + 0.1]])
    mean, cov = weighted_mean_pose(poses, np.array([0.5, 0.5]))
    assert mean[:2] == pytest.approx([2.0, 1.0])
    assert abs(abs(mean[2]) - math.pi) < 1e-9
    assert cov[2, 2] == pytest.approx(0.01)
    assert cov[0, 0] == pytest.approx(1.0) and cov[0, 1] == pytest.approx(1.0)


# -- the histogram filter


def tiny_map() -> LikelihoodMap:
    """A 2 m × 1.5 m room (0.05 m cells) with walls all round and a pillar: not symmetric."""
    occupied = np.zeros((30, 40), dtype=bool)
    occupied[0, :] = occupied[-1, :] = True
    occupied[:, 0] = occupied[:, -1] = True
    occupied[5:10, 25:30] = True
    free = ~occupied
    return LikelihoodMap.from_masks(occupied, free, 0.05, (0.0, 0.0))


CONFIG = LocalizeConfig(global_resolution=0.25, global_headings=8, global_min_free=0.5)
MOTION = MotionModel(np.array([0.1, 0.05, 0.05, 0.1, 0.02]), np.array([0.002, 0.002, 0.002]))


def brute_loglik(hist: PoseHistogram, lmap: LikelihoodMap, ex, ey, model: BeamModel):
    """Every state's log-likelihood from the definitions, one state and beam at a time."""
    sigma0 = math.sqrt(model.sigma**2 + (hist.resolution / 2) ** 2)
    sigmas = sigma0 * math.sqrt(2.0) ** np.arange(LEVELS)
    out = np.zeros((hist.headings, hist.free_r.size))
    h_cells, w_cells = lmap.shape
    for f, (r, c) in enumerate(zip(hist.free_r, hist.free_c, strict=True)):
        cx = lmap.origin[0] + (c + 0.5) * hist.resolution
        cy = lmap.origin[1] + (r + 0.5) * hist.resolution
        for h, theta in enumerate(hist.theta):
            total = 0.0
            for bx, by in zip(ex, ey, strict=True):
                wanted = math.sqrt(model.sigma**2 + (hist.resolution / 2) ** 2
                                   + (math.hypot(bx, by) * hist.bin / 2) ** 2)  # fmt: skip
                level = min(max(round(math.log(wanted / sigma0) / math.log(math.sqrt(2))), 0),
                            LEVELS - 1)  # fmt: skip
                x = cx + math.cos(theta) * bx - math.sin(theta) * by
                y = cy + math.sin(theta) * bx + math.cos(theta) * by
                ix = math.floor((x - lmap.origin[0]) / lmap.resolution)
                iy = math.floor((y - lmap.origin[1]) / lmap.resolution)
                d = lmap.distance[iy, ix] if 0 <= ix < w_cells and 0 <= iy < h_cells else 1e9
                total += float(model.log_density(np.array([d]), sigmas[level])[0])
            out[h, f] = total
    return out


def test_histogram_update_matches_brute_force_posterior():
    lmap = tiny_map()
    hist = PoseHistogram(lmap, CONFIG, MOTION)
    model = BeamModel(0.9, 0.05, 0.05, 0.1, 10.0)
    # a scan of a few beams, as seen from cell (row 2, column 2) looking along heading 1
    ex = np.array([0.6, 0.3, 0.0, -0.2, 0.45])
    ey = np.array([0.0, 0.4, 0.5, -0.3, -0.45])
    brute = brute_loglik(hist, lmap, ex, ey, model)
    fast = hist.loglik(ex, ey, model)
    assert np.abs(fast - brute).max() <= ex.size * QUANTUM
    # the posterior after one update, against prior · exp(ll / T), normalised
    prior = np.random.default_rng(1).random(hist.belief.shape) * hist.states
    prior /= prior.sum()
    hist.belief[:] = prior
    hist.update(ex, ey, model)
    expected = prior[:, hist.free_r, hist.free_c] * np.exp(
        (brute - brute.max()) / CONFIG.global_temperature
    )
    expected /= expected.sum()
    got = hist.belief[:, hist.free_r, hist.free_c]
    assert np.abs(got - expected).max() < 1e-4 * expected.max()
    assert hist.belief.sum() == pytest.approx(1.0, abs=1e-12)
    assert hist.belief[:, ~hist.states].sum() == 0.0


def test_histogram_predict_matches_brute_force_transition_sum():
    lmap = tiny_map()
    hist = PoseHistogram(lmap, CONFIG, MOTION)
    prior = np.random.default_rng(2).random(hist.belief.shape) * hist.states
    prior /= prior.sum()
    hist.belief[:] = prior
    increment = np.array([0.4, 0.1, 0.5])
    hist.predict(increment)
    # scatter form: every source state sends its mass to every destination state with the
    # documented weights (heading shift × row shift × column shift), then renormalise
    dx, dy, dth = increment
    d, a = math.hypot(dx, dy), abs(dth)
    al, fl = MOTION.alphas, MOTION.floor
    sx, sy = al[0] * d + al[1] * a + fl[0], al[2] * d + al[1] * a + fl[1]
    st = al[3] * a + al[4] * d + fl[2]
    first_h, w_h = cell_weights(
        np.array([dth / hist.bin]), np.array([math.sqrt(st**2 + hist.bin**2 / 12) / hist.bin])
    )
    res = hist.resolution
    sigma = math.sqrt(max(sx, sy) ** 2 + (d * hist.bin) ** 2 / 12 + res**2 / 12) / res
    heads, rows, cols = hist.belief.shape
    expected = np.zeros_like(prior)
    for h in range(heads):
        for k, wh in enumerate(w_h[0]):
            dest_h = (h + first_h[0] + k) % heads
            mid = hist.theta[dest_h] - dth / 2
            wx = math.cos(mid) * dx - math.sin(mid) * dy
            wy = math.sin(mid) * dx + math.cos(mid) * dy
            fr, wr = cell_weights(np.array([wy / res]), np.array([sigma]))
            fc, wc = cell_weights(np.array([wx / res]), np.array([sigma]))
            for i, a_r in enumerate(wr[0]):
                for j, a_c in enumerate(wc[0]):
                    for r, c in zip(hist.free_r, hist.free_c, strict=True):
                        r2, c2 = r + fr[0] + i, c + fc[0] + j
                        if 0 <= r2 < rows and 0 <= c2 < cols and hist.states[r2, c2]:
                            expected[dest_h, r2, c2] += wh * a_r * a_c * prior[h, r, c]
    anywhere = CONFIG.kidnap_prior
    expected = (1 - anywhere) * expected + anywhere / hist.state_count * hist.states[None]
    expected /= expected.sum()
    assert np.abs(hist.belief - expected).max() < 1e-12
    # a pure translation moves the mass: the mean heading-0 position shifts by the motion
    assert hist.belief.sum() == pytest.approx(1.0, abs=1e-12)


def test_histogram_localizes_a_scan_taken_in_the_tiny_room():
    lmap = tiny_map()
    hist = PoseHistogram(lmap, CONFIG, MOTION)
    model = BeamModel(0.9, 0.05, 0.05, 0.1, 10.0)
    # ray-cast a 180-beam scan from the centre of cell (row 2, col 6) at heading index 2 (−π/2)
    r, c, h = 2, 6, 2
    pose = np.array([(c + 0.5) * 0.25, (r + 0.5) * 0.25, hist.theta[h]])
    angles = np.linspace(-math.pi / 2, math.pi / 2, 180)
    ex, ey = [], []
    for angle in angles:
        for length in np.arange(0.05, 3.0, 0.005):
            x = pose[0] + length * math.cos(pose[2] + angle)
            y = pose[1] + length * math.sin(pose[2] + angle)
            if lmap.occupied[int(y / 0.05), int(x / 0.05)]:
                ex.append(length * math.cos(angle))
                ey.append(length * math.sin(angle))
                break
    hist.update(np.array(ex[::6]), np.array(ey[::6]), model)
    mode = hist.mode()
    assert (mode.heading, mode.row, mode.col) == (h, r, c)
    assert mode.share > 0.5


def test_cell_weights_are_gaussian_masses_over_cells():
    first, w = cell_weights(np.array([0.0, 2.5, -1.2]), np.array([1e-9, 0.5, 1.0]))
    assert first[0] == 0 and w[0, 0] == pytest.approx(1.0)
    assert np.allclose(w.sum(axis=1), 1.0)
    offsets = first[1] + np.arange(w.shape[1])
    assert float((offsets * w[1]).sum()) == pytest.approx(2.5, abs=1e-6)
    offsets = first[2] + np.arange(w.shape[1])
    assert float((offsets * w[2]).sum()) == pytest.approx(-1.2, abs=1e-3)


# -- recovery


def test_lost_monitor_fires_when_the_short_average_drops():
    monitor = LostMonitor(alpha_slow=0.01, alpha_fast=0.2, lost_ratio=0.5, warmup=10)
    assert not any(monitor.observe(0.8) for _ in range(50))
    assert monitor.injection_probability == pytest.approx(0.0)
    # quality falls to 0.1: after n updates w_fast = 0.1 + 0.7·0.8^n and
    # w_slow = 0.1 + 0.7·0.99^n; n = 4: 0.3867 > 0.5·0.7724, n = 5: 0.3294 < 0.5·0.7657
    fired = [monitor.observe(0.1) for _ in range(6)]
    assert fired.index(True) == 4
    assert monitor.injection_probability > 0.5


# -- the wall surface (sub-cell walls)


def test_wall_points_are_log_odds_weighted_centroids():
    # a wall along x: row 3 saturated (+10), row 4 hit less often (+2), the rest free (-5)
    log_odds = np.full((7, 9), -5.0)
    log_odds[3, :] = 10.0
    log_odds[4, :] = 2.0
    rows, cols, px, py = wall_points(log_odds, log_odds > 0, 0.0)
    inner = (cols > 0) & (cols < 8)
    # row 3's cell centre is at 3.5 cells, row 4's at 4.5: the centroid is 2/12 of a cell
    # from the saturated row, for the cells of both rows
    assert py[inner] == pytest.approx(np.full(inner.sum(), 3.5 + 2.0 / 12.0), abs=1e-12)
    assert px[inner] == pytest.approx(cols[inner] + 0.5, abs=1e-12)
    # equal weights (a wall on the boundary between the rows): the boundary; a one-cell wall
    # stays on its cells' centres
    _, _, _, py = wall_points(np.where(log_odds > 0, 10.0, -5.0), log_odds > 0, 0.0)
    assert np.abs(py[inner] - 4.0).max() < 1e-12
    thin = np.full((7, 9), -5.0)
    thin[3, :] = 7.0
    _, cols, _, py = wall_points(thin, thin > 0, 0.0)
    assert np.abs(py - 3.5).max() < 1e-12


@pytest.mark.parametrize("subdivision", [1, 2, 4])
def test_wall_surface_is_the_distance_to_the_sub_cell_wall(subdivision):
    log_odds = np.full((40, 30), -5.0)
    log_odds[20, :] = 10.0
    log_odds[21, :] = 2.0
    resolution = 0.05
    field = wall_surface(log_odds, log_odds > 0, 0.0, resolution, subdivision)
    assert field.shape == (40 * subdivision, 30 * subdivision)
    wall_y = (20.5 + 2.0 / 12.0) * resolution  # 1.0333 m
    fine = resolution / subdivision
    centres = (np.arange(40 * subdivision) + 0.5) * fine
    column = field[:, 15 * subdivision]
    # every fine cell centre reads its distance to the wall line, to within one fine cell (the
    # line is drawn into the fine cells it crosses)
    assert np.abs(column - np.abs(centres - wall_y)).max() <= fine + 1e-6
    # the field's zero lies on the wall: within half a fine cell
    assert abs(centres[np.argmin(column)] - wall_y) <= fine / 2 + 1e-9


def box_room(resolution: float = 0.05) -> tuple[LikelihoodMap, float, float]:
    """A 6 m room whose walls are two cells thick, both cells saturated: each wall lies on the
    boundary between its two cells (1.05 m and 5.0 m in x and y)."""
    occupied = np.zeros((120, 120), dtype=bool)
    for k in (20, 21, 99, 100):
        occupied[k, 20:101] = True
        occupied[20:101, k] = True
    inside = np.zeros_like(occupied)
    inside[22:99, 22:99] = True
    return LikelihoodMap.from_masks(occupied, inside, resolution, (0.0, 0.0)), 1.05, 5.0


def box_scan(pose, low: float, high: float, beams: int = 180):
    """Robot-frame endpoints of a 360° scan from ``pose`` inside the box ``[low, high]²``."""
    x, y, th = pose
    angles = th + np.linspace(-math.pi, math.pi, beams, endpoint=False)
    c, s = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (high - x) / c, (low - x) / c)
        ty = np.where(s > 0, (high - y) / s, (low - y) / s)
    r = np.minimum(np.abs(tx), np.abs(ty))
    rel = angles - th
    return r * np.cos(rel), r * np.sin(rel)


def test_refinement_on_the_wall_surface_finds_walls_between_cells():
    # the cell-centre field is 0 across each 2-cell wall (a flat valley a cell wide): the pose
    # is not pinned there; the wall surface puts the wall on the cells' boundary
    lmap, low, high = box_room()
    truth = np.array([2.5, 2.7, 0.3])
    ex, ey = box_scan(truth, low, high)
    start = truth + np.array([0.02, -0.018, 0.0])
    model = BeamModel(0.9, 0.05, 0.05, 0.1, 27.0)
    outlier = model.z_rand / model.z_range / (model.z_hit / (model.sigma * math.sqrt(2 * math.pi)))
    errors = {}
    for name, view in (("cells", lmap.view()), ("surface", lmap.surface_view(2))):
        out = np.empty(3)
        refine_pose(view, start, ex, ey, model.sigma, outlier, 30, 1e-6, out)
        errors[name] = float(np.hypot(*(out[:2] - truth[:2])))
    assert errors["surface"] < 0.004, errors  # a flat valley one fine cell wide is left
    assert errors["cells"] > 0.01, errors  # stays where it started, 2.7 cm off


# -- metrics of a trace


def test_localized_time_is_summed_in_time_order():
    """A clock that steps back (intel's, 631 times): scans at 0, 1, 2, then 1.5 and 3 s. The
    localized time was the positive gaps in file order after each localized scan (1 + 0 + 1.5 =
    2.5 s here; 327.96 s of the 297.58 s of intel's first 1500 scans); in time order (0, 1,
    1.5, 2, 3 s, localized at 1, 1.5 and 2 s) it is 0.5 + 0.5 + 1 = 2 s, never more than the
    3 s the trace lasts."""
    from slam.localize.run import LocalizationTrace, trace_metrics

    n = 5
    trace = LocalizationTrace(
        times=np.array([0.0, 1.0, 2.0, 1.5, 3.0]),
        poses=np.zeros((n, 3)),
        covariances=np.zeros((n, 3, 3)),
        localized=np.array([False, True, True, True, False]),
        phase=np.ones(n, dtype=np.int8),
        particles=np.full(n, 300, dtype=np.int32),
        quality=np.full(n, 0.9),
        updated=np.ones(n, dtype=bool),
        lost=np.zeros(n, dtype=bool),
    )
    m = trace_metrics(trace, np.zeros((n, 3)))
    assert m["duration_s"] == 3.0 and m["localized_time_s"] == 2.0
    assert m["time_to_convergence_s"] == 1.0
    # converged only at the scan behind the step back (1.5 s): the localizer had seen 0–2 s of
    # the log then, not the 1.5 s its time stamp alone would say
    trace.localized[:] = [False, False, False, True, True]
    m = trace_metrics(trace, np.zeros((n, 3)))
    assert m["time_to_convergence_s"] == 2.0 and m["localized_time_s"] == 0.5
    trace.localized[:] = True
    assert trace_metrics(trace, np.zeros((n, 3)))["localized_time_s"] == 3.0
    one = trace_metrics(
        LocalizationTrace(*(a[:1] for a in dataclasses.astuple(trace))), np.zeros((1, 3))
    )
    assert one["duration_s"] == 0.0 and one["localized_time_s"] == 0.0


@pytest.mark.parametrize(
    ("resolution", "cells", "cell_m"),
    [(0.05, 5, 0.25), (0.1, 3, 0.3), (0.04, 6, 0.24), (0.5, 1, 0.5)],
)
def test_the_histogram_cell_is_a_whole_number_of_map_cells(resolution, cells, cell_m):
    """The bug: a map whose cell does not divide localize.global_resolution (0.1 m, 0.04 m, as
    other tools write them) stopped the run with a configuration error the first time the
    robot got lost. The histogram now takes the nearest whole number of map cells."""
    occupied = np.zeros((40, 40), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    free = ~occupied
    lmap = LikelihoodMap.from_masks(occupied, free, resolution, (0.0, 0.0))
    hist = PoseHistogram(lmap, LocalizeConfig(), MOTION)
    assert hist.factor == cells and hist.resolution == pytest.approx(cell_m)


def test_a_wall_surface_too_large_for_memory_is_refused(monkeypatch):
    import slam.localize.maps as maps
    from slam.errors import UsageError

    occupied = np.zeros((50, 80), dtype=bool)
    occupied[10, 10:70] = True
    monkeypatch.setattr(maps, "SURFACE_BYTES_PER_CELL", 1 << 40)
    with pytest.raises(
        UsageError,
        match=r"the wall-surface field of a 80×50-cell map at 2× its resolution \(160×100 cells\) would need about",
    ):
        wall_surface(np.where(occupied, 5.0, -5.0), occupied, 1.0, 0.05, 2)
