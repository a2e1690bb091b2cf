"""Histogram filter, sensor and motion models: the teaching numbers, checked exactly."""

import numpy as np
import pytest

from slam.discrete.filter import (
    HistogramFilter,
    ImpossibleObservation,
    localized,
    sample_motion,
)
from slam.discrete.motion import (
    DriftMotion,
    HeadingMotion,
    MoveOrStay,
    ShiftMotion,
    UnknownHeading,
)
from slam.discrete.scenario import (
    UDACITY_FILE,
    load_udacity_cases,
    resolve_scenario,
    run_scenario,
)
from slam.discrete.sensors import ColourSensor, ConfusionSensor, WnesSensor
from slam.discrete.world import OFFSETS, GridWorld, random_colour_world, step, world_from_rows
from slam.errors import ConfigError

MAZE = [".......", ".....#.", ".#..#..", ".#..#..", ".......", "......."]


# --- 1D tutorial -----------------------------------------------------------------------------


def test_tutorial_inexact_move_gives_the_published_numbers():
    scenario = resolve_scenario("tutorial-1d")
    result = run_scenario(scenario)
    first = result.steps[0]
    assert (first.after, first.action) == ("move", "2")
    assert first.posterior[0] == pytest.approx([0.4, 0.05, 0.05, 0.4, 0.1], abs=1e-15)


def test_tutorial_converges_to_uniform_after_1000_moves():
    scenario = resolve_scenario("tutorial-1d")
    bayes = scenario.make_filter()
    for _ in range(1000):
        bayes.predict((0, 2))
    assert bayes.posterior[0] == pytest.approx([0.2] * 5, abs=1e-12)


def test_shift_kernel_of_a_zero_command_blurs_both_ways():
    world = world_from_rows(["abcde"], cyclic=True)
    belief = np.array([[[0.0, 0.0, 1.0, 0.0, 0.0]]])
    out = ShiftMotion().predict(belief, world, (0, 0))
    assert out[0, 0].tolist() == pytest.approx([0, 0.1, 0.8, 0.1, 0])
    with pytest.raises(ConfigError, match="= 0.95; expected 1"):
        ShiftMotion(0.8, 0.1, 0.05)


# --- colour grid -------------------------------------------------------------------------------


def test_colour_grid_first_observation_numbers():
    scenario = resolve_scenario("colour-grid")
    world = scenario.world
    blue = world.labels == world.colour_index("blue")
    assert blue.sum() == 25
    result = run_scenario(scenario)
    first = result.steps[0]
    assert (first.after, first.action) == ("sense", "blue")
    post = first.posterior
    assert post[blue] == pytest.approx(np.full(25, 0.03996), rel=1e-12)
    assert post[~blue] == pytest.approx(np.full(75, 0.001 / 3 / 25), rel=1e-12)
    assert round(post[~blue][0], 7) == 0.0000133


def test_colour_grid_scenario_localizes_at_the_true_cell():
    result = run_scenario(resolve_scenario("colour-grid"))
    assert result.localized_cell == (8, 0)
    assert len([r for r in result.steps if r.after == "sense"]) == 14
    assert result.steps[-1].posterior[8, 0] >= 0.999


def test_unknown_heading_is_uniform_over_reachable_neighbours():
    world = world_from_rows(["...", ".#.", "..."])
    motion = UnknownHeading()
    belief = np.zeros((1, 3, 3))
    belief[0, 0, 0] = 1.0  # corner: two neighbours
    out = motion.predict(belief, world)
    assert out[0, 0, 1] == pytest.approx(0.5) and out[0, 1, 0] == pytest.approx(0.5)
    belief = np.zeros((1, 3, 3))
    belief[0, 0, 1] = 1.0  # top middle: west, east (south is the obstacle)
    out = motion.predict(belief, world)
    assert out[0, 0, 0] == pytest.approx(0.5) and out[0, 0, 2] == pytest.approx(0.5)
    isolated = world_from_rows([".#", "#."])
    belief = isolated.uniform_belief()
    assert np.array_equal(motion.predict(belief, isolated), belief)


def test_unknown_heading_sampler_draws_the_predicted_distribution():
    world = world_from_rows(["....", ".#..", "...."])
    motion = UnknownHeading()
    rng = np.random.default_rng(3)
    for cell in [(0, 0), (0, 1), (1, 2), (2, 3)]:
        one_hot = np.zeros((1, 3, 4))
        one_hot[(0, *cell)] = 1.0
        p = motion.predict(one_hot, world)[0]
        draws = [sample_motion(world, motion, (0, *cell), None, rng) for _ in range(4000)]
        counts = np.zeros((3, 4))
        for _, r, c in draws:
            counts[r, c] += 1
        assert set(zip(*np.nonzero(counts), strict=True)) == set(zip(*np.nonzero(p), strict=True))
        assert counts / 4000 == pytest.approx(p, abs=0.03)


# --- obstacle maze with the WNES sensor ---------------------------------------------------------


def _naive_maze_filter(rows, evidence_actions):
    """A straight transcription of the assignment text, loops over cells (reference)."""
    n_rows, n_cols = len(rows), len(rows[0])

    def is_open(r, c):
        return 0 <= r < n_rows and 0 <= c < n_cols and rows[r][c] != "#"

    cells = [(r, c) for r in range(n_rows) for c in range(n_cols) if is_open(r, c)]
    p = {cell: 1.0 / len(cells) for cell in cells}
    delta = {"W": (0, -1), "N": (-1, 0), "E": (0, 1), "S": (1, 0)}
    left = {"N": "W", "W": "S", "S": "E", "E": "N"}
    right = {v: k for k, v in left.items()}
    tables = []
    for bits, action in evidence_actions:
        for cell in cells:
            like = 1.0
            for bit, d in zip(bits, "WNES", strict=True):
                obstacle = not is_open(cell[0] + delta[d][0], cell[1] + delta[d][1])
                if obstacle:
                    like *= 0.85 if bit else 0.15
                else:
                    like *= 0.05 if bit else 0.95
            p[cell] *= like
        total = sum(p.values())
        p = {cell: v / total for cell, v in p.items()}
        tables.append(dict(p))
        q = dict.fromkeys(cells, 0.0)
        for cell in cells:
            for d, prob in ((action, 0.8), (left[action], 0.1), (right[action], 0.1)):
                target = (cell[0] + delta[d][0], cell[1] + delta[d][1])
                q[target if is_open(*target) else cell] += prob * p[cell]
        p = q
        tables.append(dict(p))
    return tables


def test_obstacle_maze_matches_a_loop_transcription_of_the_assignment():
    scenario = resolve_scenario("obstacle-maze")
    result = run_scenario(scenario)
    assert len(result.steps) == 8
    assert [r.after for r in result.steps] == ["sense", "move"] * 4
    assert [r.action for r in result.steps] == [
        "[0, 0, 0, 0]", "N", "[1, 0, 0, 0]", "N", "[1, 0, 0, 0]", "W", "[1, 0, 0, 0]", "N",
    ]  # fmt: skip
    reference = _naive_maze_filter(
        MAZE, [((0, 0, 0, 0), "N"), ((1, 0, 0, 0), "N"), ((1, 0, 0, 0), "W"), ((1, 0, 0, 0), "N")]
    )
    for record, table in zip(result.steps, reference, strict=True):
        for (r, c), value in table.items():
            assert record.posterior[r, c] == pytest.approx(value, abs=1e-14)
        assert record.posterior[scenario.world.blocked].sum() == 0


def test_obstacle_maze_first_filtering_by_hand():
    # 37 open cells; evidence 0000: likelihood 0.95^(open neighbours) · 0.15^(blocked ones).
    world = world_from_rows(MAZE)
    counts = world.neighbour_blocked.sum(axis=0)[world.open]
    z = sum(0.95 ** (4 - k) * 0.15**k for k in counts)
    bayes = HistogramFilter(world, WnesSensor(0.85, 0.95), DriftMotion())
    bayes.update((0, 0, 0, 0))
    assert bayes.posterior[1, 2] == pytest.approx(0.95**4 / z, rel=1e-12)
    assert bayes.posterior[0, 0] == pytest.approx(0.95**2 * 0.15**2 / z, rel=1e-12)
    assert round(100 * bayes.posterior[1, 2], 2) == 11.46
    assert round(100 * bayes.posterior[0, 0], 2) == 0.29


def test_drift_bounces_back_in_a_corner():
    world = world_from_rows(["...", "..."])
    belief = np.zeros((1, 2, 3))
    belief[0, 0, 0] = 1.0
    out = DriftMotion(0.8, 0.1, 0.1).predict(belief, world, 0)  # N: blocked; W blocked; E ok
    assert out[0, 0, 0] == pytest.approx(0.9) and out[0, 0, 1] == pytest.approx(0.1)
    out = DriftMotion(0.7, 0.1, 0.1).predict(belief, world, 1)  # E; left N blocked; right S
    assert out[0] == pytest.approx(np.array([[0.2, 0.7, 0], [0.1, 0, 0]]))
    with pytest.raises(ConfigError, match="expected at most 1"):
        DriftMotion(0.8, 0.2, 0.1)


# --- sensors ---------------------------------------------------------------------------------


def test_colour_sensor_spreads_the_error_over_the_other_colours():
    world = world_from_rows(["ABCD"])
    like = ColourSensor(0.7).likelihood(world, 2)
    assert like[0].tolist() == pytest.approx([0.1, 0.1, 0.7, 0.1])
    with pytest.raises(ConfigError, match="at least 2 colours"):
        ColourSensor(0.9).check(world_from_rows(["AA"]))
    with pytest.raises(ConfigError, match=r"every open cell needs a colour; cell \(0, 1\)"):
        ColourSensor(0.9).check(world_from_rows(["A.B"]))


def test_confusion_sensor_with_its_own_symbols():
    world = world_from_rows(["dlD"], legend={"d": "dark", "l": "light", "D": "deep"})
    sensor = ConfusionSensor(np.array([[0.9, 0.1], [0.2, 0.8], [0.6, 0.4]]), ("black", "white"))
    sensor.check(world)
    z = sensor.parse_observation(world, "white")
    assert sensor.likelihood(world, z)[0].tolist() == pytest.approx([0.1, 0.8, 0.4])
    assert sensor.format_observation(world, z) == "white"
    with pytest.raises(ConfigError, match="row 1 sums to"):
        ConfusionSensor(np.array([[1.0, 0.0], [0.5, 0.6]]))
    with pytest.raises(ConfigError, match="unknown observation 'grey'"):
        sensor.parse_observation(world, "grey")


def test_wnes_sensor_parses_bits_and_counts_the_border():
    world = world_from_rows(["..", ".#"])
    sensor = WnesSensor(0.9, 0.8)
    z = sensor.parse_observation(world, "[1, 1, 0, 1]")
    assert z == (1, 1, 0, 1)
    like = sensor.likelihood(world, z)
    # (0, 0): W border sensed (0.9), N border sensed (0.9), E open sensed open (0.8),
    # S open sensed as obstacle (1 - 0.8)
    assert like[0, 0] == pytest.approx(0.9 * 0.9 * 0.8 * 0.2)
    # (0, 1): W open sensed (0.2), N border (0.9), E border sensed open (0.1), S obstacle (0.9)
    assert like[0, 1] == pytest.approx(0.2 * 0.9 * 0.1 * 0.9)
    assert like[1, 1] == 0
    with pytest.raises(ConfigError, match="four bits"):
        sensor.parse_observation(world, "102")


def test_impossible_observation_is_a_clear_error():
    world = world_from_rows(["GR"])
    bayes = HistogramFilter(world, ColourSensor(1.0), MoveOrStay(1.0), np.array([[1.0, 0.0]]))
    with pytest.raises(ImpossibleObservation, match="impossible in every state"):
        bayes.update(world.colour_index("R"))


# --- (cell, heading) states -----------------------------------------------------------------


def _heading_reference(belief, world, motion, action):
    """Numpy reference of the heading model built from ``step`` and ``np.roll``."""
    if action == 0:
        out = np.empty_like(belief)
        for h in range(4):
            out[h] = (1 - motion.p_move) * belief[h] + motion.p_move * step(belief[h], world, h)
        return out
    turn = -1 if action == 1 else 1
    return (1 - motion.p_turn) * belief + motion.p_turn * np.roll(belief, turn, axis=0)


@pytest.mark.parametrize("cyclic", [False, True])
def test_heading_kernel_matches_the_numpy_reference(cyclic):
    rng = np.random.default_rng(5)
    labels = rng.integers(0, 3, size=(7, 9)).astype(np.int16)
    blocked = rng.random((7, 9)) < 0.2
    world = GridWorld(labels, blocked, ("a", "b", "c"), cyclic, 4)
    motion = HeadingMotion(0.85, 0.7)
    belief = rng.random(world.belief_shape) * world.open
    belief /= belief.sum()
    for action in (0, 1, 2):
        expected = _heading_reference(belief, world, motion, action)
        assert motion.predict(belief, world, action) == pytest.approx(expected, abs=1e-16)


def test_heading_turns_and_forward_move():
    world = world_from_rows(["...", "..."], headings=4)
    motion = HeadingMotion(1.0, 1.0)
    belief = np.zeros(world.belief_shape)
    belief[0, 1, 1] = 1.0  # facing N at (1, 1)
    left = motion.predict(belief, world, motion.parse_action(world, "L"))
    assert left[3, 1, 1] == 1.0  # now facing W
    ahead = motion.predict(left, world, motion.parse_action(world, "F"))
    assert ahead[3, 1, 0] == 1.0
    bounced = motion.predict(ahead, world, 0)  # W of (1, 0) is the border
    assert bounced[3, 1, 0] == 1.0
    with pytest.raises(ConfigError, match="needs world.headings = 4"):
        HistogramFilter(world_from_rows(["..."]), None, motion)


def test_fused_step_equals_predict_then_update():
    rng = np.random.default_rng(11)
    world = random_colour_world(12, 15, ("a", "b", "c", "d"), rng, headings=4)
    sensor, motion = ColourSensor(0.8), HeadingMotion(0.9, 0.8)
    fused = HistogramFilter(world, sensor, motion)
    separate = HistogramFilter(world, sensor, motion)
    for k in range(40):
        action, z = k % 3, int(rng.integers(4))
        fused.step(action, z)
        separate.predict(action)
        separate.update(z)
        assert fused.belief == pytest.approx(separate.belief, abs=1e-15)
    assert fused.belief.sum() == pytest.approx(1.0, abs=1e-13)


def test_cell_prior_is_spread_over_headings_and_checked():
    world = world_from_rows(["ab"], headings=4)
    bayes = HistogramFilter(world, None, None, np.array([[0.25, 0.75]]))
    assert bayes.belief[:, 0, 1] == pytest.approx([0.1875] * 4)
    assert bayes.posterior == pytest.approx(np.array([[0.25, 0.75]]))


def test_stopping_rule():
    belief = np.zeros((2, 2, 2))
    belief[0, 1, 0] = 0.6
    belief[1, 1, 0] = 0.3985
    belief[1, 0, 0] = 0.0015
    assert localized(belief, 0.999) is None
    assert localized(belief, 0.998) == (1, 0)


def test_offsets_are_clockwise_from_north():
    assert OFFSETS == ((-1, 0), (0, 1), (1, 0), (0, -1))


# --- Udacity test vectors (real data) ----------------------------------------------------------


def test_every_udacity_case_within_1e3(data_dir):
    cases = load_udacity_cases(data_dir / UDACITY_FILE)
    assert len(cases) == 7
    for scenario in cases:
        result = run_scenario(scenario)
        kinds = [r.after for r in result.steps]
        assert kinds == ["move", "sense"] * len(scenario.steps[::2])
        assert result.expected_error is not None and result.expected_error <= 1e-3, scenario.name


def test_udacity_case_c4_numbers(data_dir):
    cases = {s.name: s for s in load_udacity_cases(data_dir / UDACITY_FILE)}
    final = run_scenario(cases["udacity:c4"]).final
    assert final[1].tolist() == pytest.approx([2 / 15, 2 / 15, 8 / 15], abs=1e-12)
    assert final[0, 0] == pytest.approx(1 / 30, abs=1e-12)
