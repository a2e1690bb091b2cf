"""The analysis scripts of docs/accuracy.md: ``tools/short_relations.py``,
``tools/beam_step_check.py`` and ``tools/same_relations.py``, on inputs whose answers are known."""

from __future__ import annotations

import numpy as np
import pytest
from tool_modules import load_tool

from slam.io.relations import Relations
from slam.trajectory import Trajectory


def _straight(n: int) -> Trajectory:
    times = np.arange(n, dtype=np.float64)
    return Trajectory(times, np.c_[times, np.zeros(n), np.zeros(n)])


def _two_second_relations(n: int) -> Relations:
    """Relations from every whole second ``t`` to ``t + 2`` along :func:`_straight`'s line."""
    t1 = np.arange(n - 2, dtype=np.float64)
    return Relations(t1, t1 + 2.0, np.full(n - 2, 2.0), np.zeros(n - 2), np.zeros(n - 2))


def test_short_relations_count_where_slam_is_worse_than_dead_reckoning():
    tool = load_tool("short_relations")
    n = 40
    truth = _straight(n)
    relations = _two_second_relations(n)
    slam = Trajectory(truth.times, truth.poses.copy())
    slam.poses[10, 1] = 0.5  # one pose 0.5 m aside: relations 8->10 and 10->12 are 0.5 m off
    odometry = Trajectory(truth.times, truth.poses.copy())
    odometry.poses[30:, 0] += 0.3  # a 0.3 m slip before pose 30: relations 28->30, 29->31
    figures = tool.compare(relations, {"slam": slam, "odometry": odometry}, span=5.0, over=0.2)
    assert figures["short_relations"] == n - 2
    assert figures["slam_share_over"] == pytest.approx(2 / (n - 2), abs=1e-4)
    assert figures["odometry_share_over"] == pytest.approx(2 / (n - 2), abs=1e-4)
    assert figures["slam_over_odometry_under_half"] == 2
    assert figures["odometry_over_slam_under_half"] == 2
    assert figures["bad_slam_to_odometry_median_m"] == pytest.approx(0.5, abs=1e-3)
    assert figures["bad_relation_length_median_m"] == pytest.approx(2.0)
    assert figures["long_relations"] == 0 and figures["long_worst"] == []
    none = tool.compare(relations, {"slam": slam, "odometry": odometry}, span=1.0)
    assert none["short_relations"] == 0 and none["slam_share_over"] is None


def test_long_relations_say_which_windows_carry_the_run_s_error():
    """Relations of 2 s and of 150 s (the loops): with --span 10 the long ones are counted, and
    those from the first 100 s to 200-300 s, where the run is 0.6 m off after a slip at 170 s,
    come first among the windows, with their share of the run's mean."""
    tool = load_tool("short_relations")
    n = 400
    truth = _straight(n)
    t1 = np.r_[np.arange(0.0, n - 2), np.arange(0.0, 100.0, 5.0)]
    t2 = np.r_[t1[: n - 2] + 2.0, t1[n - 2 :] + 150.0]
    relations = Relations(t1, t2, t2 - t1, np.zeros(t1.size), np.zeros(t1.size))
    slam = Trajectory(truth.times, truth.poses.copy())
    slam.poses[170:, 1] += 0.6
    figures = tool.compare(relations, {"slam": slam, "odometry": truth}, span=10.0)
    assert figures["long_relations"] == 20
    long_errors = np.where(t2[n - 2 :] >= 170, 0.6, 0.0)
    assert figures["slam_long_mean_m"] == pytest.approx(long_errors.mean(), abs=1e-4)
    share = long_errors.sum() / t1.size
    worst = figures["long_worst"]
    assert worst[0]["t1_s"] == 0.0 and worst[0]["t2_s"] == 200.0
    assert worst[0]["mean_m"] == pytest.approx(0.6, abs=1e-3)
    assert sum(w["share_of_mean_m"] for w in worst) == pytest.approx(share, abs=1e-3)
    assert figures["long_share_of_slam_mean_m"] == pytest.approx(share, abs=1e-4)


def test_short_relations_flag_the_ones_that_travel_sideways_of_dead_reckoning():
    """Three relations have the robot travel 19° off the heading dead reckoning keeps (0.7 m
    aside over 2 m): they are counted, with the share of the SLAM run's mean error they carry,
    and the span of time they cover; a longer --sideways threshold passes them over."""
    tool = load_tool("short_relations")
    n = 40
    truth = _straight(n)
    t1 = np.arange(n - 2, dtype=np.float64)
    dy = np.zeros(n - 2)
    dy[[20, 21, 22]] = 0.7
    relations = Relations(t1, t1 + 2.0, np.full(n - 2, 2.0), dy, np.zeros(n - 2))
    runs = {"slam": truth, "odometry": truth}
    figures = tool.compare(relations, runs, span=5.0)
    assert figures["sideways_relations"] == 3
    assert figures["sideways_share_of_slam_mean_m"] == pytest.approx(3 * 0.7 / (n - 2), abs=1e-4)
    assert figures["sideways_times_s"] == [[20.0, 24.0]]
    assert figures["slam_short_mean_m"] == pytest.approx(3 * 0.7 / (n - 2), abs=1e-4)
    assert figures["odometry_short_mean_m"] == figures["slam_short_mean_m"]
    assert tool.compare(relations, runs, span=5.0, sideways_deg=25.0)["sideways_relations"] == 0


@pytest.mark.parametrize(
    ("option", "value", "expected"),
    [
        ("--sideways", "-5", "--sideways: expected degrees in [0, 180], found -5"),
        ("--sideways", "200", "--sideways: expected degrees in [0, 180], found 200"),
        ("--sideways-length", "-1", "--sideways-length: expected metres >= 0, found -1"),
        ("--span", "0", "--span: expected seconds > 0, found 0"),
        ("--span", "nan", "--span: expected seconds > 0, found nan"),
        ("--over", "-0.2", "--over: expected metres > 0, found -0.2"),
    ],
)
def test_short_relations_refuse_a_threshold_out_of_range(
    monkeypatch, capsys, option, value, expected
):
    """A threshold out of range: one line naming the option, what was expected and what was
    found, exit code 2, before any file is read."""
    tool = load_tool("short_relations")
    argv = [
        "short_relations.py",
        "fr-clinic",
        "/nonexistent/run",
        "/nonexistent/odo",
        option,
        value,
    ]
    monkeypatch.setattr("sys.argv", argv)
    assert tool.main() == 2
    assert capsys.readouterr().err.strip() == expected


def test_icp_residual_is_least_for_the_true_beam_geometry():
    tool = load_tool("beam_step_check")
    # A room 6 m wide seen from its middle by 181 beams 1° apart: walls at y = ±3 and x = 4.
    angles = tool.ANGLES_181
    with np.errstate(divide="ignore"):
        to_side = np.where(np.sin(angles) != 0, 3.0 / np.abs(np.sin(angles)), np.inf)
        ahead = np.where(np.cos(angles) > 0, 4.0 / np.cos(angles), np.inf)
    ranges = np.minimum(to_side, ahead)
    dst = tool._points(ranges, angles, 15.0)
    same = tool.icp_residual(dst, dst, np.zeros(3))
    assert same == pytest.approx(0.0, abs=1e-9)
    # the same ranges read at angles stretched by 0.56 % (the 180/179 spread) fit worse
    stretched = tool._points(ranges, angles * (180 / 179 / 1.0), 15.0)
    assert tool.icp_residual(stretched, dst, np.zeros(3)) > 0.005


def test_same_relations_scores_the_base_run_on_each_runs_own_subset():
    """A run at half the rate (even times only) matches the relations between even times; the
    base run (every time, 0.3 m off after time 20) is scored on exactly those: 19 relations of
    the 38, where it is off on the 1 that crosses the slip, so 0.3 / 19; the half-rate run, off
    0.1 m after time 10, on its own: 0.1 / 19. A run that matches none gets None."""
    tool = load_tool("same_relations")
    n = 40
    truth = _straight(n)
    relations = _two_second_relations(n)
    base = Trajectory(truth.times, truth.poses.copy())
    base.poses[20:, 1] += 0.3  # relations 18->20 and 19->21 are 0.3 m off
    even = truth.times[::2]
    half = Trajectory(even, np.c_[even, np.zeros(even.size), np.zeros(even.size)])
    half.poses[5:, 1] += 0.1  # from time 10: relation 8->10 is 0.1 m off
    none = Trajectory(truth.times + 0.5, truth.poses.copy())
    rows = tool.on_same_relations(relations, base, {"half": half, "none": none})
    assert rows[0] == {
        "run": "half",
        "relations": 19,
        "run_mean_m": round(0.1 / 19, 4),
        "base_mean_m": round(0.3 / 19, 4),
    }
    assert rows[1] == {"run": "none", "relations": 0, "run_mean_m": None, "base_mean_m": None}
