"""The global loop search: the branch-and-bound kernel against brute force, and the checks."""

from __future__ import annotations

import numpy as np
import pytest

from slam.backend.global_loops import candidate_order, consistent, keyframes
from slam.backend.submaps import stretches
from slam.config import Config
from slam.kernels.bnb import bnb_search, max_pyramid, splat_likelihood

RES = 0.05


def _room() -> np.ndarray:
    t = np.linspace(0.0, 1.0, 300)
    walls = [
        np.c_[t * 10, 0 * t], np.c_[t * 10, 0 * t + 6], np.c_[0 * t, t * 6],
        np.c_[0 * t + 10, t * 6], np.c_[3 + t * 2, 3 + 0 * t], np.c_[7 + 0 * t, 1 + t * 3],
    ]  # fmt: skip
    return np.vstack(walls)


def _grid(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    ox, oy = -3.0, -3.0
    grid = np.zeros((int(12 / RES), int(16 / RES)), np.float32)
    splat_likelihood(points[:, 0].copy(), points[:, 1].copy(), ox, oy, RES, 0.05, grid)
    return grid, ox, oy


def _scan(points: np.ndarray, pose: np.ndarray, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    sel = points[rng.choice(len(points), n, replace=False)] - pose[:2]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.ascontiguousarray(c * sel[:, 0] + s * sel[:, 1]), np.ascontiguousarray(
        -s * sel[:, 0] + c * sel[:, 1]
    )


def test_pyramid_levels_bound_their_blocks():
    grid = np.random.default_rng(1).random((37, 29)).astype(np.float32)
    pyr = max_pyramid(grid, 4)
    for h in range(4):
        w = 1 << h
        for iy, ix in [(0, 0), (5, 7), (36, 28), (30, 20)]:
            assert pyr[h, iy, ix] == grid[iy : iy + w, ix : ix + w].max()


def test_bnb_finds_the_pose_brute_force_finds():
    """Exact: the branch-and-bound optimum equals the best of all offsets and rotations."""
    room = _room()
    grid, ox, oy = _grid(room)
    pyr = max_pyramid(grid, 6)
    true = np.array([4.0, 2.5, 0.3])
    px, py = _scan(room, true, 80)
    start = np.array([3.1, 3.3, 0.22])
    found = bnb_search(pyr, ox, oy, RES, px, py, *start, 1.5, 0.1, 0.01, 0.3)
    # a scan's own points land exactly on the walls: the true pose is on the search lattice
    assert np.hypot(*(found[:2] - true[:2])) < RES
    assert abs(found[2] - true[2]) < 0.011
    best = -1.0
    level0 = max_pyramid(grid, 1)
    nth = int(np.ceil(0.1 / 0.01))
    for a in range(-nth, nth + 1):
        one = bnb_search(level0, ox, oy, RES, px, py, start[0], start[1], start[2] + a * 0.01,
                         1.5, 0.0, 0.01, 0.0)  # fmt: skip
        best = max(best, one[3])
    assert abs(found[3] - best) < 1e-5


def test_bnb_refuses_below_min_score():
    room = _room()
    grid, ox, oy = _grid(room)
    pyr = max_pyramid(grid, 6)
    rng = np.random.default_rng(3)
    px, py = rng.uniform(-20, 20, 60), rng.uniform(-20, 20, 60)  # noise, far off the walls
    found = bnb_search(pyr, ox, oy, RES, px, py, 4.0, 2.5, 0.0, 1.0, 0.1, 0.02, 0.6)
    assert found[3] == -1.0


def test_stretches_and_keyframes_cover_the_path():
    path = np.linspace(0.0, 47.0, 300)
    subs = stretches(path, 10.0)
    assert subs[0][0] == 0 and subs[-1][1] == 300 and len(subs) == 5
    assert all(a[1] == b[0] for a, b in zip(subs[:-1], subs[1:], strict=True))
    keys = keyframes(path, 2.0)
    assert keys[0] == 0 and np.all(np.diff(path[keys]) <= 2.0 + path[1])


def test_consistency_keeps_agreeing_closures_only():
    """Two closures implying the same correction survive; a lone different one does not."""
    n = 200
    x = np.zeros((n, 3))
    x[:, 0] = np.linspace(0.0, 100.0, n)
    path = x[:, 0].copy()
    info = np.eye(3)
    shift = np.array([0.0, 2.0, 0.0])  # both say: nodes 180-190 lie 2 m further in y

    def closure(j: int, i: int, correction: np.ndarray):
        from slam.geometry import compose, relative

        matched = compose(correction, x[i])
        return (j, i, relative(x[j], matched), info)

    good = [closure(10, 180, shift), closure(14, 186, shift)]
    lone = closure(60, 120, np.array([0.0, -1.5, 0.2]))
    kept = consistent([*good, lone], x, path, Config())
    assert [(e[0], e[1]) for e in kept] == [(10, 180), (14, 186)]
    assert consistent([lone], x, path, Config()) == []


def test_consistency_compares_only_nearby_closures_and_keeps_what_all_pairs_keep():
    """The closures kept when each is compared with those within ``backend.agree_path`` along the
    path are those kept when it is compared with every other (the rule written out below): a
    long path, many closures, some agreeing in pairs, some alone, some at the window's edge."""
    from slam.backend.global_loops import _same_place
    from slam.geometry import compose, inverse, relative

    rng = np.random.default_rng(3)
    n = 3000
    x = np.zeros((n, 3))
    x[:, 0] = np.cumsum(rng.uniform(0.2, 0.6, n))
    x[:, 1] = np.sin(x[:, 0] / 20.0) * 5.0
    path = np.r_[0.0, np.cumsum(np.hypot(*np.diff(x[:, :2], axis=0).T))]
    config = Config()
    edges = []
    for k in range(300):  # in pairs of nearby keyframes with one correction, and alone
        i = int(rng.integers(200, n - 50))
        j = int(rng.integers(0, i - 100))
        correction = np.r_[rng.normal(0.0, 1.0, 2), rng.normal(0.0, 0.05)]
        ends = [(j, i), (j + int(rng.integers(1, 30)), i + int(rng.integers(1, 40)))]
        for jj, ii in ends[: 1 + k % 2]:
            edges.append((jj, ii, relative(x[jj], compose(correction, x[ii])), np.eye(3)))
    # a closure exactly agree_path along from another, with the same correction
    edges.append((edges[0][0], int(np.searchsorted(path, path[edges[0][1]] + 20.0)), *edges[0][2:]))

    def all_pairs() -> list:
        bc = config.backend
        matched = [compose(x[j], z) for j, _, z, _ in edges]
        moves = [compose(m, inverse(x[i])) for m, (_, i, _, _) in zip(matched, edges, strict=True)]
        keep = []
        for k, (jk, ik, _, _) in enumerate(edges):
            for m, (jm, im, _, _) in enumerate(edges):
                if im == ik:
                    continue
                gap_i, gap_j = abs(path[ik] - path[im]), abs(path[jk] - path[jm])
                if gap_i > bc.agree_path or gap_j > bc.agree_path:
                    continue
                if _same_place(compose(moves[k], x[im]), matched[m], gap_i + gap_j, config):
                    keep.append(edges[k])
                    break
        return keep

    expected = all_pairs()
    kept = consistent(edges, x, path, config)
    assert 20 < len(expected) < len(edges)
    assert [id(e) for e in kept] == [id(e) for e in expected]


def test_backend_config_bounds_name_the_key():
    """A bad ``[backend]`` value is one ConfigError naming the key and the bound."""
    from slam.config import load_config
    from slam.errors import ConfigError

    with pytest.raises(ConfigError, match="window_xy_min <= window_xy_max"):
        load_config("demo", None, ["backend.window_xy_min=5", "backend.window_xy_max=1"])
    with pytest.raises(ConfigError, match="window_xy_max <= far_window_xy_max"):
        load_config("demo", None, ["backend.far_window_xy_max=20"])  # narrower than the window


class _SlowScans:
    """Scans as the submap cache reads them (``hits``), each read taking a while so that threads
    asking for the same submap overlap."""

    def __init__(self, points: np.ndarray):
        self.points = points

    def hits(self, step: int, beams: int = 0):
        import time

        time.sleep(0.002)
        rng = np.random.default_rng(step)
        sel = self.points[rng.choice(len(self.points), 120, replace=False)]
        return sel[:, 0].copy(), sel[:, 1].copy()


def test_submap_cache_shared_by_threads_builds_each_submap_once():
    # the global search's threads share one cache: a submap asked for by several threads at once
    # is built by one of them (the others wait for it), and is the one a serial cache builds
    from concurrent.futures import ThreadPoolExecutor

    from slam.backend.submaps import SubmapCache

    config = Config()
    poses = np.zeros((60, 3))
    steps = np.arange(60)
    keys = [(0, 10), (10, 20), (20, 30), (30, 40), (40, 50), (50, 60)]
    asks = [keys[(i * 7) % len(keys)] for i in range(48)]
    shared = SubmapCache(_SlowScans(_room()), steps, poses, config)
    with ThreadPoolExecutor(max_workers=4) as pool:
        got = list(pool.map(lambda key: shared.pyramid(*key), asks))
    assert shared.builds == len(keys)
    serial = SubmapCache(_SlowScans(_room()), steps, poses, config)
    for key, pyr in zip(asks, got, strict=True):
        assert pyr is shared.pyramid(*key)  # still cached: the very same object
        alone = serial.pyramid(*key)
        assert np.array_equal(pyr.levels, alone.levels) and pyr.origin == alone.origin
    assert shared.builds == len(keys) and serial.builds == len(keys)


def test_submap_cache_keeps_the_most_recently_used_within_its_budget():
    from slam.backend.submaps import SubmapCache

    def cache(budget_mb: float) -> SubmapCache:
        return SubmapCache(
            _SlowScans(_room()), np.arange(30), np.zeros((30, 3)), Config(), budget_mb
        )

    keys = [(0, 10), (10, 20), (20, 30)]
    sizes = {}
    for key in keys:  # each pyramid's bytes, alone in a cache
        one = cache(100.0)
        one.pyramid(*key)
        sizes[key] = one.held
    assert min(sizes.values()) > 0
    # room for (0, 10) with either other one, not for all three
    two = cache(max(sizes[(0, 10)] + sizes[k] for k in keys[1:]) / 1e6)
    for key in [(0, 10), (10, 20), (0, 10), (20, 30), (0, 10), (10, 20)]:
        two.pyramid(*key)
    # (10, 20) was dropped for (20, 30) ((0, 10) was used since): built again at the end
    assert two.builds == 4
    assert two.held == sizes[(0, 10)] + sizes[(10, 20)]
    everything = cache(100.0)
    for key in [(0, 10), (10, 20), (0, 10), (20, 30), (0, 10), (10, 20)]:
        everything.pyramid(*key)
    assert everything.builds == 3 and everything.held == sum(sizes.values())
    tiny = cache(1e-6)  # the newest is always kept, however small the budget
    tiny.pyramid(0, 10)
    assert tiny.pyramid(0, 10) is tiny.pyramid(0, 10) and tiny.builds == 1


def test_compact_view_keeps_the_field_and_drops_unused_tiles():
    # the submap cache keeps a field map's used tiles only; the kernels read the same values
    from slam.backend.submaps import compact_view
    from slam.kernels.field import match_one, surface_at
    from slam.mapping import ParticleMaps, likelihood_tables

    points = _room()
    maps = ParticleMaps(1, RES, 0.3, center=(5.0, 3.0), size_m=20.0, capacity=1024)
    reach = np.array([15.0])
    maps.insert_scans(
        np.zeros((1, 3)), np.vstack([points[:, 0], points[:, 1]]), np.array([0, len(points)]),
        reach, 0.0,
    )  # fmt: skip
    full = maps.field(0)
    small = compact_view(full)
    used = int((full.table >= 0).sum())
    assert small.surface.shape[0] == used < maps.capacity
    rng = np.random.default_rng(0)
    for x, y in rng.uniform([-1.0, -1.0], [11.0, 7.0], size=(500, 2)):
        a, b = surface_at(full, x, y), surface_at(small, x, y)
        assert np.array_equal(np.array(a), np.array(b), equal_nan=True)
    luts, step_inv = likelihood_tables(np.array([0.2, 0.075, 0.04]), 1.0, 0.05, 0.3)
    ex, ey = _scan(points, np.array([4.0, 2.5, 0.3]), 150)
    start = np.array([4.1, 2.45, 0.33])
    one = match_one(full, start, ex, ey, luts, step_inv, 10, 1e-3, 1)
    two = match_one(small, start, ex, ey, luts, step_inv, 10, 1e-3, 1)
    assert np.array_equal(one[0], two[0]) and one[1] == two[1] and one[2] == two[2]


def test_candidates_per_pass_reach_an_older_pass_of_the_place():
    """fr-clinic's final return in miniature: three neighbouring submaps of a recent pass lie
    nearer (relative to their windows) than the start's, which ``nearest`` never searches and
    ``per_pass`` searches second; the rest follow by ratio, and the choice never repeats."""
    submaps = np.array([0, 1, 2, 40, 41, 42, 43])  # the start's pass, then a recent one
    ratio = np.array([0.45, 0.40, 0.7, 0.1, 0.05, 0.2, 0.9])
    assert candidate_order(submaps, ratio, 3).tolist() == [4, 3, 5]
    assert candidate_order(submaps, ratio, 3, "per_pass").tolist() == [4, 1, 3]
    full = candidate_order(submaps, ratio, 10, "per_pass")
    assert full.tolist() == [4, 1, 3, 5, 0, 2, 6]
    one_pass = candidate_order(submaps[3:], ratio[3:], 3, "per_pass")
    assert one_pass.tolist() == candidate_order(submaps[3:], ratio[3:], 3).tolist()
    assert candidate_order(submaps[:1], ratio[:1], 3, "per_pass").tolist() == [0]


def test_where_the_local_closures_put_a_keyframe_and_when_two_places_agree():
    """A global match joins a submap a local closure already joins: where that closure puts
    the keyframe (its match carried along the trajectory), and whether a match there agrees
    (the same tolerance as :func:`consistent`)."""
    from slam.backend.global_loops import _same_place, _Stretches
    from slam.geometry import compose, relative

    n = 200
    x = np.zeros((n, 3))
    x[:, 0] = np.linspace(0.0, 100.0, n)
    path = x[:, 0].copy()
    correction = np.array([0.4, -0.2, 0.03])  # the local closure moves keyframe 180 by this
    matched = compose(correction, x[180])
    local = [(10, 180, relative(x[10], matched), np.eye(3))]
    st = _Stretches.of(x, path, 10.0, local)
    assert st.closed_sub.tolist() == [0] and st.closed_node.tolist() == [180]
    placed, drift = st.placed(np.array([True]), 181, x, path)
    assert np.allclose(placed, [compose(correction, x[181])]) and np.allclose(drift, [path[1]])
    assert st.placed(np.array([False]), 181, x, path)[0].shape == (0, 3)
    config, at = Config(), placed[0]
    assert _same_place(at, at + [0.25, 0.0, 0.0], 0.5, config)
    assert not _same_place(at, at + [1.8, 0.0, 0.0], 0.5, config)
    assert _same_place(at, at + [1.8, 0.0, 0.0], 80.0, config)  # 0.3 m + 2 % of 80 m
    assert not _same_place(at, at + [0.0, 0.0, 0.1], 0.5, config)


def _field_of(points: np.ndarray):
    from slam.mapping import ParticleMaps

    maps = ParticleMaps(1, RES, 0.3, center=(10.0, 3.0), size_m=40.0, capacity=2048)
    maps.insert_scans(
        np.zeros((1, 3)), np.vstack([points[:, 0], points[:, 1]]), np.array([0, len(points)]),
        np.array([40.0]), 0.0,
    )  # fmt: skip
    return maps.field(0)


def test_a_scan_that_fits_as_well_a_metre_along_a_corridor_is_not_a_unique_match():
    """A corridor 2 m wide seen 6 m either way: moved 1 m along it, every beam still lies on a
    wall, so the match is not unique (a closure made of it would say nothing about where along
    the corridor the robot was). In a room with inner walls, moved 1 m any way, most beams miss:
    unique. ``unique_shift = 0`` turns the test off."""
    from slam.config import LoopConfig
    from slam.graph import unique_fit
    from slam.kernels.graph import fit_counts, shifted_fit

    x = np.arange(0.0, 30.0, 0.025)
    corridor = np.vstack([np.c_[x, 0.0 * x], np.c_[x, 0.0 * x + 2.0]])
    view = _field_of(corridor)
    pose = np.array([10.0, 1.0, 0.2])
    seen = corridor[np.abs(corridor[:, 0] - pose[0]) < 6.0]
    ex, ey = _scan(seen, pose, 200)
    lc = LoopConfig()
    _, close = fit_counts(view, pose, ex, ey, lc.fit_distance)
    assert close == 200
    moved = shifted_fit(view, pose, ex, ey, lc.fit_distance, 1.0, 16)
    assert moved == 200  # along the corridor (16 directions include 0° and 180°)
    assert not unique_fit(view, pose, ex, ey, close, lc)
    room = _room()
    view = _field_of(room)
    pose = np.array([4.0, 2.5, 0.3])
    ex, ey = _scan(room, pose, 150)
    _, close = fit_counts(view, pose, ex, ey, lc.fit_distance)
    assert close == 150
    moved = shifted_fit(view, pose, ex, ey, lc.fit_distance, 1.0, 16)
    assert moved < 0.7 * close  # every direction loses at least a third of the beams
    assert unique_fit(view, pose, ex, ey, close, lc)
    off = LoopConfig(unique_shift=0.0)
    corridor_view = _field_of(corridor)
    pose = np.array([10.0, 1.0, 0.2])
    ex, ey = _scan(seen, pose, 200)
    assert unique_fit(corridor_view, pose, ex, ey, 200, off)


def _doors(at: list[float]) -> np.ndarray:
    """A corridor 2 m wide and 38 m long whose upper wall has a door (a 1 m gap with a 1 m
    recess behind it) at each of ``at`` (m along the corridor)."""
    x = np.arange(0.0, 38.0, 0.025)
    upper = x[[all(abs(xi - a) > 0.5 for a in at) for xi in x]]
    parts = [np.c_[x, 0.0 * x], np.c_[upper, 0.0 * upper + 2.0]]
    for a in at:
        t = np.arange(0.0, 1.0, 0.025)
        parts += [np.c_[a - 0.5 + 0.0 * t, 2.0 + t], np.c_[a + 0.5 + 0.0 * t, 2.0 + t],
                  np.c_[a - 0.5 + t, 3.0 + 0.0 * t]]  # fmt: skip
    return np.vstack(parts)


def test_a_scan_that_fits_as_well_a_door_further_along_is_rejected_on_the_earlier_pass():
    """A corridor whose doors repeat every 6 m: a scan that sees 7 m either way fits as well one
    door along, so its match on the earlier pass is ambiguous (:func:`fits_elsewhere_on_pass`;
    mit-killian's corridors, where a filter 6 m off closed the loop on the wrong door). It
    passes the metre test (moved 1 m, the door gaps miss). With the doors at irregular places
    the same scan fits nowhere else within 10 m. ``pass_path = 0`` turns the test off."""
    from slam.config import LoopConfig
    from slam.graph import fits_elsewhere_on_pass, unique_fit
    from slam.kernels.graph import fit_counts

    lc = LoopConfig()
    assert lc.pass_path > 0.0
    pose = np.array([19.0, 1.0, 0.1])
    for doors, ambiguous in (([4, 10, 16, 22, 28, 34], True), ([3, 11, 16, 24, 31], False)):
        corridor = _doors(doors)
        view = _field_of(corridor)
        seen = corridor[np.abs(corridor[:, 0] - pose[0]) < 7.0]
        ex, ey = _scan(seen, pose, 240)
        _, close = fit_counts(view, pose, ex, ey, lc.fit_distance)
        assert close == 240
        assert unique_fit(view, pose, ex, ey, close, lc)  # a metre along, the doors miss
        assert fits_elsewhere_on_pass(view, pose, ex, ey, lc) == ambiguous
        assert not fits_elsewhere_on_pass(view, pose, ex, ey, LoopConfig(pass_path=0.0))


def test_the_earlier_pass_is_the_path_around_the_matched_node_behind_the_keyframe():
    """:func:`pass_window`: the nodes within ``pass_path`` of path either side of node ``j``,
    the ends on a grid of a third of it (neighbouring candidates share a map), and never within
    ``min_path / 2`` of the keyframe ``i``."""
    from slam.config import LoopConfig
    from slam.graph import pass_window

    path = np.arange(0.0, 200.0, 0.5)  # node k at 0.5 k m
    lc = LoopConfig(pass_path=15.0, min_path=10.0)
    assert pass_window(path, 100, 380, lc) == (70, 131)  # node 100 at 50 m: 35 m ... 65 m
    assert pass_window(path, 102, 380, lc) == (70, 141)  # at 51 m: 35 m ... 70 m (grid 5 m)
    assert pass_window(path, 108, 380, lc) == (70, 141)  # at 54 m: the same map
    assert pass_window(path, 100, 120, lc) == (70, 111)  # at most 55 m: 5 m behind node 120


def test_candidates_in_turn_cover_the_rest_keyframe_by_keyframe():
    """After a loop that drifted tens of metres, the submaps nearest the drifted estimate are the
    wrong stretch of the right pass: the extra candidates taken in turn search the rest, two
    more per keyframe, so that consecutive keyframes cover every one of them (cyclically), and
    none repeats the fixed choice."""
    submaps = np.array([0, 1, 2, 3, 4, 5, 6])  # one pass
    ratio = np.array([0.30, 0.28, 0.45, 0.50, 0.60, 0.35, 0.70])
    assert candidate_order(submaps, ratio, 3, "per_pass").tolist() == [1, 0, 5]
    assert candidate_order(submaps, ratio, 3, "per_pass", 7, 0).tolist() == [1, 0, 5]
    rest = [2, 3, 4, 6]  # by ratio
    seen = set()
    for turn in range(2):
        order = candidate_order(submaps, ratio, 3, "per_pass", turn, 2).tolist()
        assert order[:3] == [1, 0, 5]
        assert order[3:] == rest[2 * turn : 2 * turn + 2]
        seen.update(order[3:])
    assert seen == set(rest)
    assert candidate_order(submaps, ratio, 3, "per_pass", 2, 2).tolist()[3:] == [2, 3]  # again
    few = candidate_order(submaps[:4], ratio[:4], 3, "nearest", 5, 2)
    assert few.tolist() == [1, 0, 2, 3]  # one left: taken once
    assert candidate_order(submaps[:3], ratio[:3], 3, "nearest", 5, 2).tolist() == [1, 0, 2]


def test_keyframes_far_from_every_closure_are_the_ones_that_search_beyond_the_window():
    """``_far_from`` (which keyframes no closure holds): a keyframe exactly ``reach`` of path from
    a closure's keyframe is held, one a millimetre further is not; with no closure, none is held;
    and it is the brute-force rule it replaces, on random cases."""
    from slam.backend.global_loops import _far_from

    marks = np.array([50.0, 10.0])
    at = np.array([0.0, 40.0, 39.999, 60.0, 60.001, 95.0])
    assert _far_from(at, marks, 10.0).tolist() == [False, False, True, False, True, True]
    assert _far_from(at, np.array([]), 10.0).all()
    rng = np.random.default_rng(0)
    for _ in range(200):
        at, marks = (
            rng.uniform(0, 100, rng.integers(0, 30)),
            rng.uniform(0, 100, rng.integers(1, 9)),
        )
        brute = [not (np.abs(marks - a) <= 7.0).any() for a in at]
        assert _far_from(at, marks, 7.0).tolist() == brute
