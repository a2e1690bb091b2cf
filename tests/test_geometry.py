"""SE(2) identities and helpers."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from slam.geometry import (
    accumulate,
    compose,
    interpolate_poses,
    inverse,
    quaternion_to_yaw,
    relative,
    row_trig,
    spread_picks,
    transform_points,
    wrap_angle,
    yaw_to_quaternion,
)

coord = st.floats(-100, 100, allow_nan=False)
angle = st.floats(-10, 10, allow_nan=False)
pose = st.tuples(coord, coord, angle).map(np.array)


def test_wrap_angle_range_and_values():
    assert wrap_angle(np.pi) == -np.pi
    assert np.isclose(wrap_angle(3 * np.pi / 2), -np.pi / 2)
    assert np.isclose(wrap_angle(-7.0), -7.0 + 2 * np.pi)


def test_compose_known_values():
    a = np.array([1.0, 2.0, np.pi / 2])
    b = np.array([1.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(compose(a, b), [1.0, 3.0, -np.pi], atol=1e-12)


@given(pose)
def test_inverse_is_identity(a):
    np.testing.assert_allclose(compose(a, inverse(a)), 0.0, atol=1e-9)
    np.testing.assert_allclose(compose(inverse(a), a), 0.0, atol=1e-9)


@given(pose, pose)
def test_relative_then_compose_recovers(a, b):
    r = relative(a, b)
    c = compose(a, r)
    np.testing.assert_allclose(c[:2], b[:2], atol=1e-8)
    assert abs(wrap_angle(c[2] - b[2])) < 1e-9


@given(pose, pose, pose)
def test_compose_is_associative(a, b, c):
    left = compose(compose(a, b), c)
    right = compose(a, compose(b, c))
    np.testing.assert_allclose(left[:2], right[:2], atol=1e-7)
    assert abs(wrap_angle(left[2] - right[2])) < 1e-9


def test_transform_points_matches_compose():
    p = np.array([2.0, -1.0, 0.3])
    pts = np.array([[1.0, 0.0], [0.0, 2.0]])
    out = transform_points(p, pts)
    expected = np.array([compose(p, [x, y, 0.0])[:2] for x, y in pts])
    np.testing.assert_allclose(out, expected, atol=1e-12)


def test_accumulate_square():
    inc = np.tile([1.0, 0.0, np.pi / 2], (4, 1))
    poses = accumulate(inc)
    np.testing.assert_allclose(poses[-1], [0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(poses[2], [1.0, 1.0, -np.pi], atol=1e-12)


def test_interpolate_poses_across_wrap():
    t = np.array([0.0, 1.0])
    p = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 0.0, -np.pi + 0.1]])
    q = interpolate_poses(t, p, [0.5])
    np.testing.assert_allclose(q[0, :2], [1.0, 0.0])
    assert abs(abs(q[0, 2]) - np.pi) < 1e-12


def test_quaternion_round_trip():
    th = np.linspace(-3.1, 3.1, 13)
    np.testing.assert_allclose(quaternion_to_yaw(yaw_to_quaternion(th)), th, atol=1e-12)


def test_spread_corrections_moves_anchors_and_spreads_the_rest():
    from slam.geometry import spread_corrections

    old = accumulate(np.tile([0.1, 0.0, 0.0], (10, 1)))  # 11 poses along x, 0.1 m apart
    progress = np.arange(11) * 0.1
    same = spread_corrections(old, [0, 10], old[[0, 10]], progress)
    np.testing.assert_allclose(same, old, atol=1e-12)
    moved = old[[0, 10]].copy()
    moved[1, 1] += 0.5  # the last anchor is corrected 0.5 m sideways
    out = spread_corrections(old, [0, 10], moved, progress)
    np.testing.assert_allclose(out[10], moved[1], atol=1e-12)
    np.testing.assert_allclose(out[:, 1], np.linspace(0.0, 0.5, 11), atol=1e-12)  # linear spread
    np.testing.assert_allclose(out[:, 0], old[:, 0], atol=1e-12)
    # after the last anchor the chain follows it rigidly
    tail = spread_corrections(old, [0, 5], np.vstack([old[0], old[5] + [0, 0.2, 0]]), progress)
    np.testing.assert_allclose(tail[5:, 1], 0.2, atol=1e-12)


def _spread_anchor_by_anchor(old, anchors, new_anchors, progress):
    """spread_corrections as its docstring defines it, one stretch between anchors at a time."""
    from slam.geometry import compose, relative

    n = old.shape[0]
    out = np.empty_like(old)
    for k, a in enumerate(anchors):
        b = int(anchors[k + 1]) if k + 1 < len(anchors) else n
        idx = np.arange(a, b)
        forward = compose(new_anchors[k], relative(old[a], old[idx]))
        if b == n:
            out[idx] = forward
            continue
        backward = compose(new_anchors[k + 1], relative(old[b], old[idx]))
        span = progress[b] - progress[a]
        f = ((progress[idx] - progress[a]) / span if span > 0 else (idx - a) / (b - a))[:, None]
        blend = forward + f * (backward - forward)
        blend[:, 2] = forward[:, 2] + f[:, 0] * wrap_angle(backward[:, 2] - forward[:, 2])
        out[idx] = blend
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def test_spread_corrections_equals_the_stretch_by_stretch_definition_to_the_bit():
    # the loop closing and the between-update placement call it on whole trajectories at once;
    # it must give what placing each stretch between two anchors on its own gives, bit for bit
    # (standing stretches with zero progress included: the blend then goes by node count)
    from slam.geometry import spread_corrections

    rng = np.random.default_rng(3)
    for _ in range(60):
        n = int(rng.integers(1, 300))
        old = np.cumsum(rng.normal(size=(n, 3)) * [0.2, 0.2, 0.1], axis=0)
        old[:, 2] = wrap_angle(old[:, 2])
        anchors = np.arange(0, n, int(rng.integers(1, 12)))
        if rng.random() < 0.5 and anchors[-1] != n - 1:
            anchors = np.append(anchors, n - 1)
        new_anchors = old[anchors] + rng.normal(size=(anchors.size, 3)) * 0.3
        steps = np.abs(rng.normal(size=n - 1)) * (rng.random(n - 1) < 0.8)
        progress = np.concatenate([[0.0], np.cumsum(steps)])
        expected = _spread_anchor_by_anchor(old, anchors, new_anchors, progress)
        assert np.array_equal(spread_corrections(old, anchors, new_anchors, progress), expected)


def test_row_trig_is_numpys_cos_and_sin_computed_once_for_shared_rows():
    """Rows with the first row's very angles share one computation ((1, B) when all do); the
    values are np.cos / np.sin of each angle, bit for bit, whatever the mix (-0.0 against 0.0
    is not the same row: its sine differs)."""
    rng = np.random.default_rng(2)
    row = rng.uniform(-np.pi, np.pi, 37)
    same = np.tile(row, (5, 1))
    cos, sin = row_trig(same)
    assert cos.shape == sin.shape == (1, 37)
    assert np.broadcast_to(cos, same.shape).tobytes() == np.cos(same).tobytes()
    mixed = np.vstack([same, rng.uniform(-np.pi, np.pi, (3, 37)), row[None, :]])
    mixed[1, 4] = np.nan
    mixed[0, 0] = mixed[2, 0] = 0.0
    mixed[3, 0] = -0.0
    cos, sin = row_trig(mixed)
    assert cos.shape == mixed.shape
    assert cos.tobytes() == np.cos(mixed).tobytes() and sin.tobytes() == np.sin(mixed).tobytes()
    assert np.signbit(sin[3, 0]) and not np.signbit(sin[2, 0])


def test_spread_picks_keeps_both_ends_and_rounds_half_to_even():
    """The one thinning rule: evenly spread positions, the first and last kept, ties to even."""
    assert spread_picks(5, 4).tolist() == [0, 1, 3, 4]  # 0, 1.33, 2.67, 4
    assert spread_picks(6, 3).tolist() == [0, 2, 5]  # 2.5 → 2 (half to even), not 3
    assert spread_picks(10, 4).tolist() == [0, 3, 6, 9]
    assert spread_picks(7, 1).tolist() == [0]
    assert spread_picks(1081, 360).dtype == np.int64
    assert spread_picks(1081, 360)[-1] == 1080
