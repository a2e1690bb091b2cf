"""Property tests (hypothesis) of the histogram filter: conservation, neutrality, normalisation."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from slam.discrete.filter import HistogramFilter, update
from slam.discrete.motion import (
    DriftMotion,
    HeadingMotion,
    MoveOrStay,
    ShiftMotion,
    UnknownHeading,
)
from slam.discrete.sensors import ColourSensor, ConfusionSensor, WnesSensor
from slam.discrete.world import GridWorld


@st.composite
def worlds(draw, headings=1):
    """Small random worlds: 1..6 × 1..6, random obstacles (never all), 2..4 colours, either topology."""
    rows = draw(st.integers(1, 6))
    cols = draw(st.integers(2 if rows == 1 else 1, 6))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    colours = draw(st.integers(2, 4))
    labels = rng.integers(0, colours, size=(rows, cols)).astype(np.int16)
    blocked = rng.random((rows, cols)) < draw(st.sampled_from([0.0, 0.2, 0.4]))
    blocked.flat[rng.integers(rows * cols)] = False
    cyclic = draw(st.booleans())
    palette = tuple("abcd"[:colours])
    return GridWorld(labels, blocked, palette, cyclic, headings)


def random_belief(world: GridWorld, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    belief = rng.random(world.belief_shape) * world.open
    return belief / belief.sum()


probability = st.floats(0.0, 1.0, allow_nan=False)


@st.composite
def cell_motions(draw):
    """A cell-state motion model and one of its actions."""
    kind = draw(st.sampled_from(["shift", "move_or_stay", "drift", "unknown"]))
    offset = (draw(st.integers(-3, 3)), draw(st.integers(-3, 3)))
    if kind == "shift":
        a = draw(probability)
        b = draw(st.floats(0.0, 1.0 - a))
        return ShiftMotion(a, b, 1.0 - a - b), offset
    if kind == "move_or_stay":
        return MoveOrStay(draw(probability)), offset
    if kind == "drift":
        f = draw(probability)
        left = draw(st.floats(0.0, 1.0 - f))
        right = draw(st.floats(0.0, 1.0 - f - left))
        return DriftMotion(f, left, right), draw(st.integers(0, 3))
    return UnknownHeading(), None


@settings(max_examples=60, deadline=None)
@given(world=worlds(), motion_action=cell_motions(), seed=st.integers(0, 1000))
def test_prediction_preserves_total_probability(world, motion_action, seed):
    motion, action = motion_action
    belief = random_belief(world, seed)
    out = motion.predict(belief, world, action)
    assert abs(out.sum() - 1.0) <= 1e-12
    assert out.min() >= 0.0
    assert out[:, world.blocked].sum() == 0.0


@settings(max_examples=30, deadline=None)
@given(
    world=worlds(headings=4),
    p_move=probability,
    p_turn=probability,
    action=st.integers(0, 2),
    seed=st.integers(0, 1000),
)
def test_heading_prediction_preserves_total_probability(world, p_move, p_turn, action, seed):
    belief = random_belief(world, seed)
    out = HeadingMotion(p_move, p_turn).predict(belief, world, action)
    assert abs(out.sum() - 1.0) <= 1e-12
    assert out[:, world.blocked].sum() == 0.0


@st.composite
def uninformative_sensors(draw, world):
    kind = draw(st.sampled_from(["colour", "wnes", "confusion"]))
    colours = len(world.palette)
    if kind == "colour":
        return ColourSensor(1.0 / colours), int(draw(st.integers(0, colours - 1)))
    if kind == "wnes":
        p = draw(st.floats(0.01, 0.99))
        bits = tuple(draw(st.lists(st.integers(0, 1), min_size=4, max_size=4)))
        return WnesSensor(p, 1.0 - p), bits
    symbols = draw(st.integers(1, 4))
    row = np.random.default_rng(draw(st.integers(0, 1000))).random(symbols) + 0.01
    matrix = np.tile(row / row.sum(), (colours, 1))
    names = tuple(f"s{j}" for j in range(symbols))
    return ConfusionSensor(matrix, names), int(draw(st.integers(0, symbols - 1)))


@settings(max_examples=60, deadline=None)
@given(data=st.data(), world=worlds(), seed=st.integers(0, 1000))
def test_uninformative_sensor_leaves_the_belief_unchanged(data, world, seed):
    sensor, observation = data.draw(uninformative_sensors(world))
    belief = random_belief(world, seed)
    after = update(belief, sensor.likelihood(world, observation))
    assert np.max(np.abs(after - belief)) <= 1e-12


def _long_run(bayes: HistogramFilter, steps: int, rng: np.random.Generator, actions, fused):
    colours = len(bayes.world.palette)
    worst = 0.0
    for k in range(steps):
        action = actions[int(rng.integers(len(actions)))]
        z = int(rng.integers(colours))
        if fused:
            bayes.step(action, z)
        else:
            bayes.predict(action)
            worst = max(worst, abs(bayes.belief.sum() - 1.0))
            bayes.update(z)
        worst = max(worst, abs(bayes.belief.sum() - 1.0))
        if k % 1000 == 0:
            assert np.isfinite(bayes.belief).all()
    return worst


@settings(max_examples=3, deadline=None)
@given(world=worlds(), p_correct=st.floats(0.6, 0.999), seed=st.integers(0, 2**32 - 1))
def test_posterior_stays_normalised_over_10000_steps(world, p_correct, seed):
    rng = np.random.default_rng(seed)
    bayes = HistogramFilter(world, ColourSensor(p_correct), DriftMotion(0.8, 0.1, 0.1))
    worst = _long_run(bayes, 10_000, rng, [0, 1, 2, 3], fused=False)
    assert worst <= 1e-12
    assert bayes.belief.min() >= 0.0


@settings(max_examples=2, deadline=None)
@given(world=worlds(headings=4), p_correct=st.floats(0.6, 0.999), seed=st.integers(0, 2**32 - 1))
def test_heading_posterior_stays_normalised_over_10000_fused_steps(world, p_correct, seed):
    rng = np.random.default_rng(seed)
    bayes = HistogramFilter(world, ColourSensor(p_correct), HeadingMotion(0.9, 0.9))
    worst = _long_run(bayes, 10_000, rng, [0, 1, 2], fused=True)
    assert worst <= 1e-12
