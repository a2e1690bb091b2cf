"""Relations files and the Kümmerle relation metric, with values computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam.errors import DataError
from slam.eval.relations import match_times, relation_errors
from slam.geometry import relative
from slam.io.relations import Relations, read_relations
from slam.trajectory import Trajectory

# --- the file format ------------------------------------------------------------------------------


def test_read_relations_keeps_planar_columns(tmp_path):
    path = tmp_path / "r.relations"
    path.write_text(
        "# timestamp1 timestamp2 x y z roll pitch yaw\n"
        "10.5 11.25 0.31293 0.02935 0.00000  0.00000 0.00000 0.24198\n"
        "\n"
        "11.25 12.0 -1 2 9 9 9 -0.5\n"
    )
    rel = read_relations(path)
    assert len(rel) == 2
    np.testing.assert_array_equal(rel.t1, [10.5, 11.25])
    np.testing.assert_array_equal(rel.t2, [11.25, 12.0])
    np.testing.assert_array_equal(rel.motions, [[0.31293, 0.02935, 0.24198], [-1.0, 2.0, -0.5]])
    assert rel.source == path


@pytest.mark.parametrize(
    "line, message",
    [
        (
            "1 2 3 4 5 6 7",
            r"r\.relations:3: expected 8 columns 't1 t2 x y z roll pitch yaw', found 7",
        ),
        ("1 2 3 4 5 6 7 8 9", r"r\.relations:3: expected 8 columns .*found 9"),
        ("1 2 0.5 abc 0 0 0 0.1", r"r\.relations:3: y: expected a number, found 'abc'"),
        ("1 2 0.5 0 0 0 0 nan", r"r\.relations:3: yaw: expected a finite number, found nan"),
    ],
)
def test_bad_relation_line_is_named(tmp_path, line, message):
    path = tmp_path / "r.relations"
    path.write_text(f"# header\n1 2 0 0 0 0 0 0\n{line}\n3 4 0 0 0 0 0 0\n")
    with pytest.raises(DataError, match=message):
        read_relations(path)


def test_empty_and_missing_relations(tmp_path):
    path = tmp_path / "r.relations"
    path.write_text("# only a header\n")
    with pytest.raises(DataError, match=r"r\.relations: no relations"):
        read_relations(path)
    with pytest.raises(DataError, match=r"nope\.relations: relations file not found"):
        read_relations(tmp_path / "nope.relations")
    with pytest.raises(DataError, match=r"is a folder"):
        read_relations(tmp_path)


def test_non_text_relations_name_the_line(tmp_path):
    path = tmp_path / "r.relations"
    path.write_bytes(b"1 2 3 4 5 6 7 8\n\xff 2\n")
    with pytest.raises(DataError, match=f"{path}:2: expected text, found the non-text byte 0xff"):
        read_relations(path)


@pytest.mark.parametrize(
    "name, count",
    [("intel", 2984), ("aces", 1279), ("fr079", 1685), ("fr-clinic", 2820), ("mit-csail", 1172)],
)
def test_real_relations_files(carmen_dir, name, count):
    rel = read_relations(carmen_dir / "relations" / f"{name}.relations")
    assert len(rel) == count
    assert np.all(rel.t2 != rel.t1)


# --- matching -------------------------------------------------------------------------------------


def test_match_times_any_order_ties_and_tolerance():
    times = np.array([5.0, 3.0, 4.0, 3.0, 10.0])  # file order, not sorted; 3.0 twice
    query = np.array([3.0, 4.00005, 4.0002, 10.0, 2.99995, 11.0])
    np.testing.assert_array_equal(match_times(times, query, 1e-4), [1, 2, -1, 4, 1, -1])


# --- the metric -----------------------------------------------------------------------------------

TRUTH = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, np.pi / 2]])
TIMES = np.array([100.0, 101.0, 102.0])


def relations_of(truth: np.ndarray, pairs: list[tuple[int, int]], times=TIMES) -> Relations:
    i, j = np.array(pairs).T
    motion = relative(truth[i], truth[j])
    return Relations(t1=times[i], t2=times[j], x=motion[:, 0], y=motion[:, 1], yaw=motion[:, 2])


def test_metric_is_zero_on_the_true_trajectory():
    rng = np.random.default_rng(3)
    truth = np.cumsum(rng.normal(0, 1, (50, 3)), axis=0)
    times = 1e9 + np.arange(50) * 0.2
    pairs = [(int(a), int(b)) for a, b in rng.integers(0, 50, (200, 2)) if a != b]
    errors = relation_errors(Trajectory(times, truth), relations_of(truth, pairs, times))
    s = errors.summary()
    assert s["count"] == len(pairs) and s["unmatched"] == 0
    assert s["trans_mean"] == pytest.approx(0, abs=1e-9)
    assert s["rot_mean_deg"] == pytest.approx(0, abs=1e-9)
    assert s["trans_std"] == pytest.approx(0, abs=1e-9)


def test_metric_on_a_known_perturbation():
    # Estimate: pose 1 is 0.1 m too far forward, pose 2 is turned 0.1 rad too far. By hand:
    #   0->1: e = (0.1, 0, 0)       trans 0.1  rot 0
    #   1->2: δ = (-0.1, 1, π/2+0.1), δ* = (0, 1, π/2) -> e = (0, 0.1, 0.1)  trans 0.1  rot 0.1
    #   0->2: e = (0, 0, 0.1)       trans 0    rot 0.1
    estimate = TRUTH + np.array([[0, 0, 0], [0.1, 0, 0], [0, 0, 0.1]])
    rel = relations_of(TRUTH, [(0, 1), (1, 2), (0, 2)])
    errors = relation_errors(Trajectory(TIMES, estimate), rel)
    np.testing.assert_allclose(errors.trans, [0.1, 0.1, 0.0], atol=1e-12)
    np.testing.assert_allclose(errors.rot, [0.0, 0.1, 0.1], atol=1e-12)
    s = errors.summary()
    assert s["trans_mean"] == pytest.approx(0.2 / 3)
    assert s["trans_std"] == pytest.approx(math.sqrt(2) / 30)
    assert s["rot_mean_deg"] == pytest.approx(math.degrees(0.2 / 3))
    assert s["rot_std_deg"] == pytest.approx(math.degrees(math.sqrt(2) / 30))
    assert s["trans_sq_mean"] == pytest.approx(0.02 / 3)
    assert s["rot_sq_mean_deg2"] == pytest.approx(2 * math.degrees(0.1) ** 2 / 3)
    assert s["trans_max"] == pytest.approx(0.1)


def test_unmatched_relations_are_counted_not_dropped():
    rel = relations_of(TRUTH, [(0, 1), (1, 2), (0, 2)])
    t1 = rel.t1.copy()
    t2 = rel.t2.copy()
    t2[0] = 99.0  # no pose there
    t1[1] += 2e-4  # beyond the 1e-4 s tolerance
    t1[2] += 5e-5  # within it
    shifted = Relations(t1=t1, t2=t2, x=rel.x, y=rel.y, yaw=rel.yaw)
    errors = relation_errors(Trajectory(TIMES, TRUTH), shifted)
    assert errors.count == 1 and errors.unmatched == 2 and errors.total == 3
    np.testing.assert_array_equal(errors.unmatched_index, [0, 1])
    np.testing.assert_array_equal(errors.matched_index, [2])
    wider = relation_errors(Trajectory(TIMES, TRUTH), shifted, tolerance=3e-4)
    assert wider.count == 2 and wider.unmatched == 1


def test_metric_does_not_depend_on_pose_order_or_frame():
    estimate = TRUTH + np.array([[0, 0, 0], [0.1, 0, 0], [0, 0, 0.1]])
    rel = relations_of(TRUTH, [(0, 1), (1, 2), (0, 2)])
    base = relation_errors(Trajectory(TIMES, estimate), rel).summary()
    order = [2, 0, 1]  # poses in "file order" with non-monotonic times
    moved = relative(np.array([3.0, -2.0, 1.0]), estimate)  # a rigid change of frame
    again = relation_errors(Trajectory(TIMES[order], moved[order]), rel).summary()
    for key in ("trans_mean", "trans_std", "rot_mean_deg", "rot_std_deg"):
        assert again[key] == pytest.approx(base[key], abs=1e-12)


def test_no_match_gives_nan_statistics():
    rel = relations_of(TRUTH, [(0, 1)], times=TIMES + 50)
    s = relation_errors(Trajectory(TIMES, TRUTH), rel).summary()
    assert s["count"] == 0 and s["unmatched"] == 1
    assert math.isnan(s["trans_mean"])
