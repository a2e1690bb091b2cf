"""Pose-graph kernels and loop closing: errors, Jacobians, the solver, a closed square loop."""

import dataclasses
import warnings

import numpy as np
import pytest

from slam.config import LoopConfig
from slam.geometry import accumulate, compose, relative
from slam.graph import chain_graph, optimize
from slam.kernels.graph import _jacobians, _matvec, edge_error, linearize, solve_system


def test_edge_error_is_zero_for_a_consistent_edge_and_known_otherwise():
    xi = np.array([1.0, 2.0, 0.5])
    xj = np.array([2.0, 2.5, 1.0])
    z = relative(xi, xj)
    np.testing.assert_allclose(edge_error(xi, xj, z), 0.0, atol=1e-12)
    shifted = compose(xj, np.array([0.0, 0.0, 0.1]))
    np.testing.assert_allclose(edge_error(xi, shifted, z), [0.0, 0.0, 0.1], atol=1e-12)
    # move j 0.1 m along i's x axis: the error is that step seen from z's frame
    moved = xj + np.array([0.1 * np.cos(0.5), 0.1 * np.sin(0.5), 0.0])
    c, s = np.cos(z[2]), np.sin(z[2])
    expected = [c * 0.1, -s * 0.1, 0.0]  # Rzᵀ (0.1, 0), no heading error
    np.testing.assert_allclose(edge_error(xi, moved, z), expected, atol=1e-12)


def test_jacobians_match_finite_differences():
    rng = np.random.default_rng(4)
    for _ in range(10):
        xi, xj, z = rng.normal(size=(3, 3))
        a, b = _jacobians(xi, xj, z)
        h = 1e-6
        for k in range(3):
            dx = np.zeros(3)
            dx[k] = h
            num_a = (edge_error(xi + dx, xj, z) - edge_error(xi - dx, xj, z)) / (2 * h)
            num_b = (edge_error(xi, xj + dx, z) - edge_error(xi, xj - dx, z)) / (2 * h)
            np.testing.assert_allclose(a[:, k], num_a, atol=1e-6)
            np.testing.assert_allclose(b[:, k], num_b, atol=1e-6)


def test_preconditioned_solver_matches_a_dense_solve():
    rng = np.random.default_rng(1)
    n = 30
    poses = accumulate(np.tile([0.5, 0.0, 0.2], (n - 1, 1)))
    poses += rng.normal(scale=0.05, size=poses.shape)
    ei = np.concatenate([np.arange(n - 1), [0, 5, 3]]).astype(np.int64)
    ej = np.concatenate([np.arange(1, n), [29, 20, 27]]).astype(np.int64)
    z = rng.normal(scale=0.3, size=(ei.size, 3))
    info = np.tile(np.diag([100.0, 100.0, 400.0]), (ei.size, 1, 1))
    robust = np.zeros(ei.size)
    diag, band, far, grad = (
        np.zeros((n, 3, 3)),
        np.zeros((n - 1, 3, 3)),
        np.zeros((ei.size, 3, 3)),
        np.zeros((n, 3)),
    )
    linearize(poses, ei, ej, z, info, robust, diag, band, far, grad)
    diag[0] += np.eye(3) * 1e3
    dense = np.zeros((3 * n, 3 * n))
    for k in range(n):
        dense[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = diag[k]
    for k in range(n - 1):
        dense[3 * k : 3 * k + 3, 3 * k + 3 : 3 * k + 6] = band[k]
        dense[3 * k + 3 : 3 * k + 6, 3 * k : 3 * k + 3] = band[k].T
    for e in range(n - 1, ei.size):
        i, j = ei[e], ej[e]
        dense[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] += far[e]
        dense[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] += far[e].T
    expected = np.linalg.solve(dense, -grad.ravel()).reshape(n, 3)
    x, iterations, _ = solve_system(diag, band, far, ei, ej, -grad, 200, 1e-12)
    np.testing.assert_allclose(x, expected, rtol=1e-6, atol=1e-8)
    assert iterations < 20  # the chain preconditioner leaves only the 3 loop edges to iterate on


def test_the_default_solves_a_long_loopy_graph_to_its_tolerance():
    """Four laps of a 400-keyframe loop with closures between the laps (as mit-killian's 1,640
    keyframes): the chain-preconditioned solve needs over 400 iterations, which the old cap of
    300 cut short by more than a metre; the default cap lets it reach ``solver_tolerance``."""
    rng = np.random.default_rng(2)
    lap, n = 400, 1600
    step = np.tile([2 * np.pi * 20 / lap, 0.0, 2 * np.pi / lap], (n - 1, 1))
    truth = accumulate(step)
    drifted = accumulate(step + rng.normal(scale=[0.01, 0.01, 0.003], size=step.shape))
    loops = [(k, k + lap * m) for k in range(0, n, 7) for m in (1, 2, 3) if k + lap * m < n]
    ei = np.concatenate([np.arange(n - 1), [a for a, _ in loops]]).astype(np.int64)
    ej = np.concatenate([np.arange(1, n), [b for _, b in loops]]).astype(np.int64)
    z = np.ascontiguousarray(relative(truth[ei], truth[ej]))
    info = np.tile(np.diag([400.0, 400.0, 4000.0]), (ei.size, 1, 1))
    diag, band, far, grad = (
        np.zeros((n, 3, 3)),
        np.zeros((n - 1, 3, 3)),
        np.zeros((ei.size, 3, 3)),
        np.zeros((n, 3)),
    )
    linearize(drifted, ei, ej, z, info, np.zeros(ei.size), diag, band, far, grad)
    diag[0] += np.eye(3) * 1e9
    lc = LoopConfig()

    def residual(x: np.ndarray) -> float:
        return float(
            np.linalg.norm(_matvec(diag, band, far, ei, ej, x) + grad) / np.linalg.norm(grad)
        )

    x, used, converged = solve_system(
        diag, band, far, ei, ej, -grad, lc.solver_iterations, lc.solver_tolerance
    )
    assert 300 < used < lc.solver_iterations
    assert residual(x) <= lc.solver_tolerance
    cut, _, reached = solve_system(diag, band, far, ei, ej, -grad, 300, lc.solver_tolerance)
    assert converged and not reached
    assert residual(cut) > 1e-4
    assert np.abs(cut - x).max() > 0.5


def test_a_system_with_a_nan_stops_at_once():
    """A NaN in the right-hand side, or an infinity in a loop edge's block, cannot converge: the
    solve returns after no iteration (it ran to the cap, 10,000 iterations a Gauss-Newton step by
    default), NaN everywhere as before."""
    n = 50
    diag = np.tile(np.eye(3) * 4.0, (n, 1, 1))
    band = np.tile(-np.eye(3), (n - 1, 1, 1))
    ei = np.arange(n - 1, dtype=np.int64)
    rhs = np.ones((n, 3))
    rhs[7, 1] = np.nan
    x, used, _ = solve_system(diag, band, np.zeros((n - 1, 3, 3)), ei, ei + 1, rhs, 10000, 1e-8)
    assert used == 0
    assert np.isnan(x).all()
    rhs[7, 1] = 1.0
    x, used, _ = solve_system(diag, band, np.zeros((n - 1, 3, 3)), ei, ei + 1, rhs, 10000, 1e-8)
    assert np.isfinite(x).all() and used <= 1
    # a loop edge's block alone (the chain's preconditioner never reads it)
    ei2, ej2 = np.append(ei, 3), np.append(ei + 1, 40)
    far = np.zeros((n, 3, 3))
    far[-1, 0, 0] = np.inf
    x, used, _ = solve_system(diag, band, far, ei2, ej2, rhs, 10000, 1e-8)
    assert used == 0 and np.isnan(x).all()


def _drifted_square() -> tuple[np.ndarray, np.ndarray, list]:
    """A 4 m square driven in 40 steps, truth and dead reckoning (turns 1 % too small, steps 1 %
    too long: the loop does not close), and the loop edge that closes it (the last pose seen from
    the first, far more certain than 40 drifting steps)."""
    true_steps = np.tile([0.4, 0.0, 0.0], (40, 1))
    true_steps[9::10, 2] = np.pi / 2
    truth = accumulate(true_steps)
    drifted_steps = true_steps.copy()
    drifted_steps[:, 2] *= 0.99
    drifted_steps[:, 0] *= 1.01
    edge = (0, 40, relative(truth[0], truth[40]), np.diag([1e6, 1e6, 1e7]))
    return truth, accumulate(drifted_steps), [edge]


def test_optimize_closes_a_drifted_square_loop():
    truth, drifted, edges = _drifted_square()
    assert np.hypot(*drifted[-1, :2]) > 0.05  # visibly open
    # the chain's uncertainty matches this drift: 2 % of each step, 5 mrad per turn
    lc = LoopConfig(seq_sigma_xy=0.005, seq_sigma_rel=0.02, seq_sigma_th=0.005)
    closed = optimize(drifted, edges, lc)
    gap = relative(closed[0], closed[40])
    assert np.hypot(gap[0], gap[1]) < 0.01 and abs(gap[2]) < 0.005
    assert np.abs(closed - truth)[:, :2].max() < 0.05  # the whole square comes back into shape
    np.testing.assert_allclose(closed[0], drifted[0], atol=1e-6)  # node 0 is fixed


@pytest.mark.parametrize("where", ["z", "info"])
def test_a_loop_edge_that_is_not_finite_is_left_out_with_a_warning(where):
    """One NaN in a loop edge used to make every optimised pose NaN: the edge is now left out
    (the other closures still apply) and the run is told."""
    truth, drifted, edges = _drifted_square()
    lc = LoopConfig(seq_sigma_xy=0.005, seq_sigma_rel=0.02, seq_sigma_th=0.005)
    good = optimize(drifted, edges, lc)
    i, j, z, info = edges[0]
    bad = (i, 20, np.array([np.nan, 0.0, 0.0]), info) if where == "z" else None
    if where == "info":
        broken = info.copy()
        broken[2, 2] = np.inf
        bad = (i, 20, relative(truth[i], truth[20]), broken)
    with pytest.warns(UserWarning, match=r"1 of its 2 loop edges .* not finite"):
        out = optimize(drifted, [*edges, bad], lc, robust=np.array([3.0, 3.0]))
    np.testing.assert_array_equal(out, good)
    assert np.abs(out - truth)[:, :2].max() < 0.05


def test_a_system_that_turns_non_finite_keeps_the_last_finite_estimate():
    """An information whose entries overflow only once squared by the Jacobians (finite going
    in) makes the system infinite: the steps stop and the poses stay finite, with a warning."""
    truth, drifted, edges = _drifted_square()
    i, j, z, _ = edges[0]
    huge = [(i, j, z, np.diag([1e306, 1e306, 1e306]))]
    with pytest.warns(UserWarning, match="NaN or an infinity; the optimisation stops"):
        out = optimize(drifted, huge, LoopConfig(robust=0.0))
    assert np.isfinite(out).all()


def test_a_solve_cut_by_its_cap_warns():
    """A step whose conjugate gradients stop at ``loops.solver_iterations`` says so (the poses
    may be off); the default cap on the same graph does not."""
    truth, drifted, edges = _drifted_square()
    lc = LoopConfig(seq_sigma_xy=0.005, seq_sigma_rel=0.02, seq_sigma_th=0.005)
    with pytest.warns(UserWarning, match=r"stopped at loops.solver_iterations = 1 before"):
        optimize(drifted, edges, dataclasses.replace(lc, solver_iterations=1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        optimize(drifted, edges, lc)
        # every step of this graph reaches the tolerance on its 3rd iteration: a cap of 3 cuts
        # nothing short (the review's find: it warned, the residual not checked after the last)
        optimize(drifted, edges, dataclasses.replace(lc, solver_iterations=3))


def test_a_wrong_loop_edge_is_down_weighted():
    steps = np.tile([0.5, 0.0, 0.0], (30, 1))
    poses = accumulate(steps)
    info = np.diag([400.0, 400.0, 4e4])
    wrong = [(0, 30, np.array([0.0, 3.0, 0.5]), info)]  # claims the end is 3 m to the side
    lc = LoopConfig()
    out = optimize(poses, wrong, lc)
    # the robust kernel keeps one contradicting edge from bending a consistent chain much
    assert np.abs(out - poses)[:, :2].max() < 0.3
    plain = optimize(poses, wrong, LoopConfig(robust=0.0))
    assert np.abs(plain - poses)[:, :2].max() > np.abs(out - poses)[:, :2].max()


@pytest.mark.parametrize("stride, radius", [(1, 3.0), (5, 3.0), (3, 0.7), (2, 12.0)])
def test_loop_candidates_from_nearby_cells_are_those_of_every_earlier_node(stride, radius):
    """The local loop candidates found by looking only at the cells around each node are those of
    comparing it with every earlier node far enough behind (``candidates_every_node``, the rule
    as it was written before): a random walk that comes back often, on a lattice so that equal
    distances (ties) occur."""
    from slam.geometry import path_along
    from slam.graph import _candidates, candidates_every_node

    rng = np.random.default_rng(stride)
    steps = rng.integers(-1, 2, (4000, 2)) * 0.5
    poses = np.zeros((4001, 3))
    poses[1:, :2] = np.cumsum(steps, axis=0)
    poses[:, 2] = rng.uniform(-np.pi, np.pi, 4001)
    path = path_along(poses)
    lc = LoopConfig(stride=stride, radius=radius, min_path=10.0)
    expected = candidates_every_node(poses, path, lc)
    assert len(expected) > 100
    assert _candidates(poses, path, lc) == expected
    # a pose that is not a number has no cell: the rule itself answers, as before (no crash)
    for bad in (np.nan, np.inf):
        odd = poses.copy()
        odd[2000, 0] = bad
        with np.errstate(invalid="ignore"):  # inf − inf along the path
            odd_path = path_along(odd)
            assert _candidates(odd, odd_path, lc) == candidates_every_node(odd, odd_path, lc)


def test_chain_graph_is_the_chain_then_the_loops():
    poses = accumulate(np.tile([0.5, 0.0, 0.1], (3, 1)))  # 4 poses
    info = np.diag([1.0, 2.0, 3.0])
    edges = [(0, 3, np.array([0.1, 0.2, 0.3]), info), (1, 3, np.array([0.4, 0.5, 0.6]), info)]
    graph = chain_graph(poses, edges, np.array([0.7, 0.0]), LoopConfig())
    assert graph.i.tolist() == [0, 1, 2, 0, 1] and graph.j.tolist() == [1, 2, 3, 3, 3]
    assert graph.i.dtype == graph.j.dtype == np.int64
    np.testing.assert_allclose(graph.z[:3], np.tile([0.5, 0.0, 0.1], (3, 1)), atol=1e-12)
    np.testing.assert_array_equal(graph.z[3:], [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    assert graph.z.flags.c_contiguous and graph.info.shape == (5, 3, 3)
    np.testing.assert_array_equal(graph.info[3], info)
    np.testing.assert_array_equal(graph.robust, [0.0, 0.0, 0.0, 0.7, 0.0])
    empty = chain_graph(poses, [], np.zeros(0), LoopConfig())
    assert empty.i.tolist() == [0, 1, 2] and empty.z.shape == (3, 3)


def test_optimize_robust_scales_and_start():
    steps = np.tile([0.5, 0.0, 0.0], (30, 1))
    poses = accumulate(steps)
    wrong = [(0, 30, np.array([0.0, 3.0, 0.5]), np.diag([400.0, 400.0, 4e4]))]
    lc = LoopConfig()
    # per-edge scales equal to lc.robust are the default; 0 is no kernel
    np.testing.assert_array_equal(
        optimize(poses, wrong, lc, np.array([lc.robust])), optimize(poses, wrong, lc)
    )
    np.testing.assert_array_equal(
        optimize(poses, wrong, lc, np.zeros(1)), optimize(poses, wrong, LoopConfig(robust=0.0))
    )
    # the chain measures the relative poses of ``poses`` whatever ``start`` the steps begin at
    start = poses + np.array([0.0, 0.05, 0.0])
    moved = optimize(poses, [], lc, start=start)
    np.testing.assert_allclose(relative(moved[:-1], moved[1:]), steps, atol=1e-6)
    np.testing.assert_allclose(moved[0], start[0], atol=1e-6)  # node 0 fixed where it starts


@pytest.mark.parametrize("n", [2, 5])
def test_optimize_without_loops_keeps_the_chain(n):
    poses = accumulate(np.tile([0.3, 0.1, 0.05], (n - 1, 1)))
    np.testing.assert_allclose(optimize(poses, [], LoopConfig()), poses, atol=1e-9)


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    """The simulator's small loop (no RGB-D) as a scan sequence, with true poses at every scan."""
    from slam.config import load_config
    from slam.geometry import interpolate_poses
    from slam.io.ece276a import load_ece276a
    from slam.io.tum import read_tum
    from slam.scans import ScanSequence
    from slam.sim.dataset import SimOptions, generate_dataset

    folder = tmp_path_factory.mktemp("loops") / "small"
    generate_dataset(folder, SimOptions(scenario="small", seed=7, rgbd=False))  # the whole loop
    config = load_config()
    log = load_ece276a(folder, 20, need=("encoders", "imu", "scans"), lidar=config.lidar)
    seq = ScanSequence.from_log(log, config)
    times, poses = read_tum(folder / "groundtruth.tum")
    return seq, interpolate_poses(times, poses, seq.times), config


def compose_all(start, moves):
    """Poses reached from ``start`` by the relative ``moves`` in turn."""
    out, pose = [], start
    for m in moves:
        pose = compose(pose, m)
        out.append(pose)
    return np.array(out)


def opened_loop(true_nodes):
    """``true_nodes`` with the loop opened the way a filter drifts: every step over-turns a little
    and over-counts its length by 1.5 %, until the path has turned 5 degrees too far."""
    moves = relative(true_nodes[:-1], true_nodes[1:])
    moves[:, :2] *= 1.015
    moves[:, 2] += np.deg2rad(5.0) / len(moves)
    return np.vstack([true_nodes[:1], compose_all(true_nodes[0], moves)])


def relation_error(poses, truth, a, b):
    """Mean translational error of the relative poses ``a → b`` (m)."""
    diff = relative(poses[a], poses[b]) - relative(truth[a], truth[b])
    return float(np.hypot(diff[:, 0], diff[:, 1]).mean())


def test_close_loops_repairs_an_opened_loop(small_log):
    from slam.graph import close_loops

    seq, truth, config = small_log
    steps = np.arange(0, len(seq), 8)
    true_nodes = truth[steps]
    broken = opened_loop(true_nodes)
    result = close_loops(seq, steps, broken, config)
    assert result.accepted > 5
    assert result.correction_max_m > 0.1
    # judge by relations (the Kümmerle metric): absolute positions depend on where the solver
    # puts the drift, which one loop closure cannot tell; relative poses across the loop can
    n = len(steps)
    first, last = np.arange(0, n // 10), np.arange(n - n // 10, n)
    across = (np.repeat(first, last.size), np.tile(last, first.size))
    idx = np.arange(0, n, 5)
    every = (np.repeat(idx, idx.size), np.tile(idx, idx.size))
    before_across = relation_error(broken, true_nodes, *across)
    after_across = relation_error(result.poses, true_nodes, *across)
    assert before_across > 0.2
    assert after_across < 0.5 * before_across  # the loop is closed
    before_all = relation_error(broken, true_nodes, *every)
    after_all = relation_error(result.poses, true_nodes, *every)
    assert after_all < 0.8 * before_all  # and the map as a whole is more consistent


def test_close_loops_keeps_a_consistent_trajectory(small_log):
    from slam.graph import close_loops

    seq, truth, config = small_log
    steps = np.arange(0, len(seq), 8)
    result = close_loops(seq, steps, truth[steps], config)
    np.testing.assert_array_equal(result.poses, truth[steps])  # nothing to repair
    assert result.accepted > 5


def test_window_chunks_cut_only_where_the_submap_changes():
    from slam.graph import window_chunks

    windows = [(0, 5)] * 7 + [(2, 8)] * 2 + [(3, 9)] + [(4, 12)] * 6
    for parts in (1, 2, 3, 4, 8, 40):
        ranges = window_chunks(windows, parts)
        assert ranges[0][0] == 0 and ranges[-1][1] == len(windows)
        assert all(a < b for a, b in ranges)
        assert all(b == c for (_, b), (c, _) in zip(ranges[:-1], ranges[1:], strict=True))
        assert all(windows[a] != windows[a - 1] for a, _ in ranges[1:])  # cut at a change only
        assert len(ranges) <= min(parts, 4)  # four distinct windows: at most four ranges
    assert window_chunks(windows, 2) == [(0, 9), (9, 16)]  # the middle (8) moves to the change
    assert window_chunks([], 4) == []


def test_loop_search_does_not_depend_on_the_thread_count(small_log):
    """The local and global loop searches split their candidates over the kernel threads; the
    edges, in order and to the bit, are those of one thread."""
    import numba

    from slam.backend.global_loops import detect_global
    from slam.config import load_config
    from slam.geometry import path_along
    from slam.graph import _detect

    seq, truth, _ = small_log
    # the small loop is 34 m long: keyframes every 0.5 m and a lower score bar give the global
    # search closures to find on it
    config = load_config("", None, ["backend.keyframe_path=0.5", "backend.min_score=0.3"])
    steps = np.arange(0, len(seq), 8)
    drifted = opened_loop(truth[steps])
    path = path_along(drifted)
    found = {}
    before = numba.get_num_threads()
    try:
        for n in (1, 2):
            numba.set_num_threads(n)
            local, count = _detect(seq, steps, drifted, path, config)
            glob, searched = detect_global(seq, steps, drifted, path, config)
            found[n] = (local, count, glob, searched)
    finally:
        numba.set_num_threads(before)
    (l1, c1, g1, s1), (l2, c2, g2, s2) = found[1], found[2]
    assert len(l1) > 5 and len(g1) > 5  # both searches found closures
    assert (c1, s1) == (c2, s2)
    for a, b in zip(l1 + g1, l2 + g2, strict=True):
        assert a[:2] == b[:2]
        np.testing.assert_array_equal(a[2], b[2])
        np.testing.assert_array_equal(a[3], b[3])


def test_smoothing_with_good_odometry_removes_the_registration_noise():
    from slam.graph import smooth_with_odometry

    rng = np.random.default_rng(3)
    t = np.arange(400) * 0.1
    truth = np.stack([1.5 * np.sin(0.21 * t), np.sin(0.33 * t), 1.2 * np.sin(0.5 * t)], axis=1)
    registered = truth + rng.normal(0.0, [0.02, 0.02, 0.005], truth.shape)
    lc = LoopConfig()

    def rmse(poses):
        return float(np.sqrt(np.mean(np.sum((poses[:, :2] - truth[:, :2]) ** 2, axis=1))))

    smoothed = smooth_with_odometry(registered, truth, (0.02, 0.005), (0.002, 0.002, 0.001), lc)
    assert rmse(smoothed) < 0.5 * rmse(registered)
    # odometry trusted as little as it deserves (metres of noise): the registered poses stay
    noisy = truth + rng.normal(0.0, [0.5, 0.5, 0.3], truth.shape)
    kept = smooth_with_odometry(registered, noisy, (0.02, 0.005), (5.0, 5.0, 3.0), lc)
    assert np.abs(kept - registered).max() < 2e-3
    one = smooth_with_odometry(registered[:1], truth[:1], (0.02, 0.005), (0.01, 0.01, 0.01), lc)
    assert one.shape == (1, 3)


def test_smoothing_trusts_the_odometry_per_axis():
    """Each odometry edge's sigmas are along and across the robot's heading: odometry whose
    steps are 3 cm off in length but exact sideways, trusted only across (1 mm) and not along
    (1 m), straightens the registration's sideways noise and leaves its noise along the path;
    trusted along too, it takes on the odometry's error in length."""
    from slam.geometry import compose, relative
    from slam.graph import smooth_with_odometry

    rng = np.random.default_rng(5)
    n = 300
    truth = np.zeros((n, 3))
    truth[:, 0] = np.arange(n) * 0.1  # a straight corridor along x, heading 0
    registered = truth + rng.normal(0.0, [0.02, 0.02, 0.0], truth.shape)
    steps = relative(truth[:-1], truth[1:])
    steps[:, 0] += rng.normal(0.0, 0.03, n - 1)
    odometry = [truth[0]]
    for step in steps:
        odometry.append(compose(odometry[-1], step))
    odometry = np.array(odometry)
    lc = LoopConfig()
    across = smooth_with_odometry(registered, odometry, (0.02, 0.005), (1.0, 0.001, 0.001), lc)
    err_x = np.abs(across[:, 0] - truth[:, 0]).mean()
    err_y = np.abs(across[:, 1] - truth[:, 1]).mean()
    assert err_y < 0.3 * np.abs(registered[:, 1] - truth[:, 1]).mean()
    assert err_x < 1.1 * np.abs(registered[:, 0] - truth[:, 0]).mean()
    both = smooth_with_odometry(registered, odometry, (0.02, 0.005), (0.001, 0.001, 0.001), lc)
    assert np.abs(both[:, 0] - truth[:, 0]).mean() > 2.0 * err_x  # the odometry's length error


def test_search_beyond_the_drift_window_only_from_keyframes_no_closure_holds(small_log):
    """The search beyond the drift window (``backend.far_drift_xy``) adds searches, from the
    keyframes that no closure within the window holds, of submaps beyond that window only;
    ``far=False`` (the loop closing's later rounds) and a closure that holds every keyframe
    (``agree_path`` over the whole loop) leave the search within the window. (Whether what
    it finds is right is the real log's test: fr-clinic from 1546 s, test_slam_regression. The
    small loop's few far matches see walls that fit as well a few metres along, which the test
    of the earlier pass, ``loops.pass_path``, rejects: it is off here.)"""
    from slam.backend.global_loops import detect_global
    from slam.config import load_config
    from slam.geometry import path_along
    from slam.graph import _detect

    seq, truth, _ = small_log
    narrow = [
        "backend.keyframe_path=0.5", "backend.min_score=0.3", "backend.window_xy_min=0.2",
        "backend.drift_xy=0", "backend.window_xy_max=0.2", "backend.agree_path=2",
        "backend.far_drift_xy=0", "loops.pass_path=0",
    ]  # fmt: skip
    steps = np.arange(0, len(seq), 8)
    nodes = truth[steps]
    path = path_along(nodes)
    half = path > 0.5 * path[-1]  # the loop's second half moved rigidly: its end 3 m off
    drifted = nodes.copy()
    drifted[half] = compose(np.array([3.0, -1.0, 0.05]), nodes[half])
    within, searched = detect_global(seq, steps, drifted, path, load_config("", None, narrow))
    wide = load_config("", None, [*narrow, "backend.far_drift_xy=0.2"])
    both, more = detect_global(seq, steps, drifted, path, wide)
    assert [e[:2] for e in both[: len(within)]] == [e[:2] for e in within]  # the same first
    assert more > searched and len(both) > len(within)
    for j, i, z, _ in both[len(within) :]:
        assert np.hypot(*(compose(drifted[j], z)[:2] - drifted[i, :2])) > 0.2  # beyond it
    assert detect_global(seq, steps, drifted, path, wide, far=False)[1] == searched
    # on the closed loop, local closures, and every keyframe within agree_path of one: nothing
    # is searched beyond the window
    held = load_config("", None, [*narrow, "backend.far_drift_xy=0.2", "backend.agree_path=1e5"])
    local, _ = _detect(seq, steps, nodes, path, held)
    assert local
    base = detect_global(seq, steps, nodes, path, load_config("", None, narrow), local)[1]
    assert detect_global(seq, steps, nodes, path, held, local)[1] == base
    unheld = load_config("", None, [*narrow, "backend.far_drift_xy=0.2", "backend.agree_path=0.1"])
    assert detect_global(seq, steps, nodes, path, unheld, local)[1] > base


def test_search_beyond_the_window_only_in_the_first_round(small_log, monkeypatch):
    """``close_loops_global`` asks for the search beyond the drift window in its first round
    only: once that round has pulled a long loop in, the next finds its closures within the
    window."""
    import slam.backend.global_loops as gl

    seq, truth, config = small_log
    steps = np.arange(0, len(seq), 8)
    asked = []
    detect = gl.detect_global

    def recording(*args, **kwargs):
        asked.append(args[7] if len(args) > 7 else kwargs.get("far", True))
        return detect(*args, **kwargs)

    monkeypatch.setattr(gl, "detect_global", recording)
    gl.close_loops_global(seq, steps, opened_loop(truth[steps]), config)
    assert len(asked) == config.loops.rounds >= 2  # the opened loop is closed: both rounds run
    assert asked == [True] + [False] * (len(asked) - 1)


def test_a_second_loop_closing_over_the_same_nodes_takes_the_first_rounds_closures(
    small_log, monkeypatch
):
    """With a shared :class:`slam.graph.FirstRound` a second loop closing over the same nodes
    (the repair's rerun, with a looser chain) does not search its first round again, and ends
    exactly where it would have ended searching it; other nodes are searched anew."""
    import slam.backend.global_loops as gl
    import slam.graph as graph

    seq, truth, config = small_log
    steps = np.arange(0, len(seq), 8)
    opened = opened_loop(truth[steps])
    calls = {"local": 0, "global": 0}
    real_local, real_global = graph._detect, gl.detect_global

    def local(*args, **kwargs):
        calls["local"] += 1
        return real_local(*args, **kwargs)

    def global_(*args, **kwargs):
        calls["global"] += 1
        return real_global(*args, **kwargs)

    monkeypatch.setattr(graph, "_detect", local)
    monkeypatch.setattr(gl, "detect_global", global_)

    def searches(nodes, first=None, loose_nodes=None):
        before = dict(calls)
        result = gl.close_loops_global(
            seq, steps, nodes, config, loose_nodes=loose_nodes, first=first
        )
        return result, {k: calls[k] - before[k] for k in calls}

    first = graph.FirstRound()
    plain, rounds = searches(opened, first)
    assert plain.accepted > 0 and rounds["local"] == rounds["global"] >= 2
    loose = np.zeros(len(steps), dtype=bool)
    loose[10:15] = True
    again, fewer = searches(opened, first, loose)
    alone, full = searches(opened, None, loose)
    assert np.array_equal(again.poses, alone.poses)
    assert (again.accepted, again.candidates) == (alone.accepted, alone.candidates)
    assert fewer == {k: v - 1 for k, v in full.items()}
    moved = opened + np.array([0.01, 0.0, 0.0])
    assert searches(moved, first)[1] == rounds  # other nodes: every round searched
    assert searches(moved, first)[1] == {k: v - 1 for k, v in rounds.items()}


def test_chain_looseness_marks_the_keyframe_edges_around_the_loose_nodes():
    """An edge between two keyframes is loose when any node from one to the other (both
    included) is; no loose node: no multiple at all."""
    from slam.graph import chain_looseness

    keys = np.array([0, 5, 10, 12])
    loose = np.zeros(13, dtype=bool)
    assert chain_looseness(loose, keys, 5.0) is None
    assert chain_looseness(None, keys, 5.0) is None
    loose[3] = True
    np.testing.assert_array_equal(chain_looseness(loose, keys, 5.0), [5.0, 1.0, 1.0])
    loose[:] = False
    loose[5] = True  # a keyframe: both edges that meet there
    np.testing.assert_array_equal(chain_looseness(loose, keys, 4.0), [4.0, 4.0, 1.0])
    loose[:] = False
    loose[12] = True
    np.testing.assert_array_equal(chain_looseness(loose, keys, 3.0), [1.0, 1.0, 3.0])


def test_a_loose_stretch_of_the_chain_takes_the_loop_correction():
    """A straight chain of 21 poses 0.5 m apart and a closure that puts the last one 1 m to the
    side: with the chain's sigmas five times larger on four edges in the middle, those edges
    take most of the bend (the rest stay straight), where the stiff chain spreads it evenly;
    the loose edges' information is the stiff one's over 25."""
    poses = accumulate(np.tile([0.5, 0.0, 0.0], (20, 1)))
    side = [(0, 20, np.array([10.0, 1.0, 0.0]), np.diag([1e4, 1e4, 1e5]))]
    lc = LoopConfig(robust=0.0)
    loose = np.ones(20)
    loose[8:12] = 5.0
    stiff_graph, loose_graph = (
        chain_graph(poses, side, np.zeros(1), lc),
        chain_graph(poses, side, np.zeros(1), lc, loose),
    )
    np.testing.assert_allclose(loose_graph.info[8:12], stiff_graph.info[8:12] / 25.0)
    np.testing.assert_array_equal(loose_graph.info[:8], stiff_graph.info[:8])

    stiff = optimize(poses, side, lc, np.zeros(1))
    bent = optimize(poses, side, lc, np.zeros(1), loose=loose)
    assert np.hypot(*(bent[20, :2] - [10.0, 1.0])) < 0.05
    assert np.hypot(*(stiff[20, :2] - [10.0, 1.0])) < 0.05
    # the sideways step of each edge: the loose edges take 0.19 m each, the others 0.008 m;
    # the stiff chain 0.032 m on every edge
    lateral = relative(bent[:-1], bent[1:])[:, 1]
    assert np.abs(lateral[8:12]).min() > 20 * np.abs(np.delete(lateral, range(8, 12))).max()
    even = relative(stiff[:-1], stiff[1:])[:, 1]
    assert even.min() > 0.95 * even.max() > 0.0
