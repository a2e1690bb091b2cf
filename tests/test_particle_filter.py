"""The filter's named parts: the update rule, the lineage, the particle cloud's covariance."""

from __future__ import annotations

import numpy as np
import pytest

from slam.config import RbpfConfig
from slam.particle_filter import Lineage, UpdateRule, cloud_covariance

RULE = UpdateRule(distance=0.2, angle=0.1, interval_s=0.3, min_motion=0.02)


def test_update_rule_reads_the_rbpf_section():
    rule = UpdateRule.from_config(
        RbpfConfig(update_distance=0.5, update_angle=0.25, update_interval_s=2.0,
                   update_min_motion=0.05)
    )  # fmt: skip
    assert rule == UpdateRule(0.5, 0.25, 2.0, 0.05)
    assert UpdateRule.from_config(RbpfConfig()) == RULE  # the defaults


@pytest.mark.parametrize(
    "moved, elapsed, due",
    [
        ((0.2, 0.0, 0.0), 0.0, True),  # exactly the update distance
        ((0.199, 0.0, 0.0), 0.0, False),
        ((0.12, -0.16, 0.0), 0.0, True),  # |(0.12, -0.16)| = 0.2: distance in any direction
        ((0.0, 0.0, -0.1), 0.0, True),  # the angle, turning either way
        ((0.0, 0.0, 0.099), 0.0, False),
        ((0.05, 0.0, 0.0), 0.29, False),  # slow motion, not long enough yet
        ((0.05, 0.0, 0.0), 0.3, True),  # ... and once the interval has passed
        ((0.0, 0.0, 0.02), 0.3, True),  # a slow turn counts as motion
        ((0.019, 0.0, 0.019), 10.0, False),  # standing (below min_motion): never re-weighted
    ],
)
def test_update_rule_linear_angular_temporal(moved, elapsed, due):
    assert RULE.due(np.array(moved), elapsed) is due


def test_update_rule_without_the_interval_clause():
    rule = UpdateRule(distance=0.2, angle=0.1, interval_s=0.0, min_motion=0.02)
    assert not rule.due(np.array([0.15, 0.0, 0.05]), 1e6)
    assert rule.due(np.array([0.2, 0.0, 0.0]), 0.0)


@pytest.mark.parametrize(
    "moved, share",
    [
        ((0.1, 0.0, 0.0), 0.5),  # half the update distance
        ((0.03, 0.04, 0.0), 0.25),  # 0.05 m of 0.2
        ((0.0, 0.0, -0.05), 0.5),  # half the update angle
        ((0.1, 0.0, 0.08), 0.8),  # the larger of the two shares
        ((0.5, 0.0, 0.0), 1.0),  # capped at a full update
        ((0.0, 0.0, 0.0), 0.0),
    ],
)
def test_evidence_share_grows_with_motion(moved, share):
    assert RULE.evidence_share(np.array(moved)) == pytest.approx(share)


def _three_updates() -> Lineage:
    """Three particles over three updates; after update 1 particle 2 dies and 0 splits."""
    lineage = Lineage(np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]]))
    lineage.record(4, np.array([[0.0, 1, 0], [1.0, 1, 0], [2.0, 1, 0]]), np.array([0, 1, 2]))
    lineage.record(9, np.array([[0.0, 2, 0], [1.0, 2, 0], [2.0, 2, 0]]), np.array([0, 0, 1]))
    return lineage


def test_lineage_follows_a_particle_back_through_resampling():
    lineage = _three_updates()
    assert len(lineage) == 3 and lineage.particles == 3
    np.testing.assert_array_equal(lineage.steps, [0, 4, 9])
    # particle 2 of the last update descends from particle 1 (update 1) and 1 (update 0)
    np.testing.assert_array_equal(lineage.ancestry(2), [[1, 0, 0], [1, 1, 0], [2, 2, 0]])
    # particles 0 and 1 share particle 0 as parent
    np.testing.assert_array_equal(lineage.ancestry(1)[:2], lineage.ancestry(0)[:2])
    np.testing.assert_array_equal(lineage.ancestry(1), [[0, 0, 0], [0, 1, 0], [1, 2, 0]])


def test_lineage_keeps_copies_and_checks_what_it_records():
    poses = np.zeros((3, 3))
    lineage = Lineage(poses)
    poses[:] = 7.0  # the caller's array changes later: the record does not
    assert lineage.ancestry(0).tolist() == [[0.0, 0.0, 0.0]]
    with pytest.raises(ValueError, match=r"expected \(3, 3\) poses and \(3,\) parents"):
        lineage.record(1, np.zeros((2, 3)), np.arange(2))
    with pytest.raises(ValueError, match="must increase"):
        lineage.record(0, np.zeros((3, 3)), np.arange(3))


def test_cloud_covariance_known_values():
    cloud = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, -2.0, 0.0]])
    cov = cloud_covariance(cloud, np.full(4, 0.25))
    np.testing.assert_allclose(cov, np.diag([0.5, 2.0, 0.0]), atol=1e-12)
    # weights move the mean: 3/4 at x = 1, 1/4 at x = -1 -> mean 0.5, variance 0.75
    two = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    assert cloud_covariance(two, np.array([3.0, 1.0]))[0, 0] == pytest.approx(0.75)
    # headings either side of ±π: the mean is π, the deviations ±0.1
    wrap = np.array([[0.0, 0.0, np.pi - 0.1], [0.0, 0.0, -np.pi + 0.1]])
    assert cloud_covariance(wrap, np.array([0.5, 0.5]))[2, 2] == pytest.approx(0.01)


def test_the_fused_proposal_mean_keeps_the_match_where_the_scan_constrains_and_odometry_where_not():
    """rbpf.proposal_mean = "fused": a corridor along x (the scan constrains y and the heading,
    not x) keeps the predicted x and the matched y and heading; a scan that constrains every
    direction keeps the match; headings across ±π are fused the short way round."""
    from slam.particle_filter import fuse_with_prediction

    matched = np.array([[1.0, 2.0, 0.1], [1.0, 2.0, 0.1], [0.0, 0.0, np.pi - 0.01]])
    predicted = np.array([[1.5, 2.2, 0.2], [1.5, 2.2, 0.2], [0.0, 0.0, -np.pi + 0.01]])
    motion = np.tile(np.diag([0.01, 0.01, 0.001]), (3, 1, 1))
    hessian = np.stack([np.diag([0.0, 1e9, 1e9]), np.eye(3) * 1e9, np.zeros((3, 3))])
    out = fuse_with_prediction(matched, predicted, hessian, 10.0, motion)
    np.testing.assert_allclose(out[0], [1.5, 2.0, 0.1], atol=1e-6)
    np.testing.assert_allclose(out[1], matched[1], atol=1e-6)
    assert out[2, 2] == pytest.approx(-np.pi + 0.01, abs=1e-9)  # not through 0
    # equal information on both sides: half way
    half = fuse_with_prediction(matched[:1], predicted[:1], np.linalg.inv(motion[:1]) * 10.0,
                                10.0, motion[:1])  # fmt: skip
    np.testing.assert_allclose(half[0], [1.25, 2.1, 0.15], atol=1e-9)


def test_the_estimate_follows_the_best_particle_through_a_resampling(monkeypatch):
    """After a resampling the weights are equal, so ``argmax`` would name particle 0, a copy of
    whichever particle the resampling drew first. The estimate keeps following the particle that
    had the highest weight (its first copy), and the final ancestry is that particle's, also when
    the last update resampled (every update does here: ``filter.resample_threshold = 1``)."""
    from synthetic_logs import path as room_path
    from synthetic_logs import ray_cast

    import slam
    from slam.particle_filter import RbpfFilter

    best_before: list[np.ndarray] = []
    resample = RbpfFilter.resample

    def watched(self: RbpfFilter, n_eff: float) -> bool:
        best_before.append(self.particles[int(np.argmax(self.weights))].copy())
        return resample(self, n_eff)

    monkeypatch.setattr(RbpfFilter, "resample", watched)
    config = slam.load_config("", None, ["filter.resample_threshold=1.0", "filter.particles=20"])
    s = slam.Slam(config, seed=3, stages=[])
    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    poses = room_path(60)
    moved_on = 0
    for k, pose in enumerate(poses):
        est = s.update(slam.Scan(100.0 + 0.1 * k, ray_cast(pose, angles), angles), odometry=pose)
        if est.updated and k > 0:
            assert est.resampled
            np.testing.assert_array_equal(est.pose, best_before[-1])
            cloud = np.asarray(est.particles)
            moved_on += int(not np.array_equal(cloud[0], best_before[-1]))
    assert len(best_before) >= 10 and moved_on >= 3  # particle 0 was not the best, often
    nodes = s._filter.finish().node_poses
    np.testing.assert_array_equal(nodes[-1], best_before[-1])
