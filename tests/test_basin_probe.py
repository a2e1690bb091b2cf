"""The filter's basin probe (:meth:`slam.particle_filter.RbpfFilter._probe`) on synthetic data:
a room mapped from its centre, a scan predicted with a heading error beyond the matcher's basin
(mit-csail's odometry glitch in miniature), and the cases where the probe must not fire."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slam.config import Config
from slam.geometry import wrap_angle
from slam.mapping import ParticleMaps, likelihood_tables
from slam.particle_filter import RbpfFilter, match_from_starts

ROOM = 2.0 * np.array([[-4, -2.5], [5, -2.5], [5, 1], [2, 1], [2, 3], [-4, 3]], dtype=np.float64)
"""An L-shaped hall, 18 m × 11 m: no rotational symmetry, so one heading explains a scan best;
its walls are far enough that a 15° error puts the beams beyond the field's reach."""


def _cast(polygon: np.ndarray, beams: int = 180) -> tuple[np.ndarray, np.ndarray]:
    """Robot-frame hits of a 360° scan from the origin (heading 0) inside ``polygon``."""
    angles = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    d = np.c_[np.cos(angles), np.sin(angles)]
    a, b = polygon, np.roll(polygon, -1, axis=0)
    e = b - a
    best = np.full(beams, np.inf)
    for k in range(len(a)):
        # origin + t·d = a + s·e  →  t·d − s·e = a
        den = d[:, 0] * (-e[k, 1]) - d[:, 1] * (-e[k, 0])
        ok = np.abs(den) > 1e-12
        t = np.where(ok, (a[k, 0] * (-e[k, 1]) - a[k, 1] * (-e[k, 0])) / np.where(ok, den, 1), -1)
        s = np.where(ok, (d[:, 0] * a[k, 1] - d[:, 1] * a[k, 0]) / np.where(ok, den, 1), -1)
        hit = ok & (t > 0) & (s >= 0) & (s <= 1)
        best = np.where(hit & (t < best), t, best)
    return np.ascontiguousarray(best * d[:, 0]), np.ascontiguousarray(best * d[:, 1])


def _filter(hits: tuple[np.ndarray, np.ndarray], probe_gain: float = 0.3) -> RbpfFilter:
    """A filter with three particles whose maps hold the scan ``hits`` taken at the origin."""
    config = Config()
    rc = dataclasses.replace(config.rbpf, probe_gain=probe_gain)
    f = RbpfFilter.__new__(RbpfFilter)
    f.config = dataclasses.replace(config, rbpf=rc)
    f.luts = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    f.maps = ParticleMaps(3, config.map.resolution, rc.dmax, size_m=20.0)
    f.maps.insert(np.zeros((3, 3)), *hits, *hits, rc.skip_insert_below)
    f.vacancy = None
    f.probes = 0
    f.recent_best = [-0.05] * 10  # recent updates matched well
    return f


def _match(f: RbpfFilter, predicted: np.ndarray, hits: tuple[np.ndarray, np.ndarray]):
    rc = f.config.rbpf
    return f.maps.match(
        predicted, *hits, f.luts, rc.max_iterations, rc.tolerance, rc.min_inliers,
        rc.coarse_stride,
    )  # fmt: skip


OFF = np.array([[0.05, 0.0, -0.27], [0.0, 0.05, -0.26], [-0.03, 0.0, -0.28]])
"""Predicted poses ≈15° off the true heading 0, as after mit-csail's glitch."""


def test_probe_recovers_a_rotation_beyond_the_basin():
    hits = _cast(ROOM)
    f = _filter(hits)
    first = _match(f, OFF, hits)
    assert np.abs(first.poses[:, 2]).min() > 0.1, "the first match must fail for this test"
    assert (first.loglik / hits[0].size < -2.5).all()  # per beam: the beams are beyond reach
    got = f._probe(OFF, hits, first)
    assert f.probes == 1
    np.testing.assert_allclose(got.poses[:, 2], 0.0, atol=0.01)
    np.testing.assert_allclose(got.poses[:, :2], 0.0, atol=0.05)
    assert (got.loglik / hits[0].size > -1.0).all()  # −0.55 per beam after it


def test_probe_keeps_a_good_match_and_can_be_disabled():
    hits = _cast(ROOM)
    near = np.array([[0.03, 0.0, 0.03], [0.0, 0.02, -0.02], [0.0, 0.0, 0.0]])
    for gain, predicted in ((0.3, near), (0.0, OFF)):
        f = _filter(hits, probe_gain=gain)
        first = _match(f, predicted, hits)
        kept = first.poses.copy()
        got = f._probe(predicted, hits, first)
        assert f.probes == 0
        np.testing.assert_array_equal(got.poses, kept)


def test_probe_leaves_a_scan_that_no_start_explains():
    """A scan of another room (new space): every start scores badly, the probe does not fire."""
    hits = _cast(ROOM)
    f = _filter(hits)
    other = _cast(ROOM[:, ::-1] * np.array([1.6, 0.7]))
    first = _match(f, OFF, other)
    got_poses = first.poses.copy()
    got = f._probe(OFF, other, first)
    assert f.probes == 0
    np.testing.assert_array_equal(got.poses, got_poses)


@pytest.mark.parametrize("particle", [0, 2])
def test_match_from_starts_matches_one_particles_map(particle):
    """Several starts against one particle's map give what that particle's own match gives."""
    hits = _cast(ROOM)
    f = _filter(hits)
    rc = f.config.rbpf
    starts = np.array([[0.05, 0.0, 0.05], [0.0, 0.0, -0.27]])
    one = match_from_starts(f.maps, particle, starts, hits, f.luts, rc)
    for s in range(2):
        predicted = np.tile(starts[s], (3, 1))
        direct = _match(f, predicted, hits)
        np.testing.assert_allclose(one.poses[s], direct.poses[particle])
        np.testing.assert_allclose(one.loglik[s], direct.loglik[particle])


@pytest.mark.parametrize("off", [OFF, OFF[[2, 0, 1]]])
def test_the_proposals_kernel_call_probes_as_the_probe_does(off):
    """One kernel call matches the particles and the best one's rotated starts
    (``ParticleMaps.match`` with ``probe_yaws``): the same bits as the match, then the probe's own
    ``match_from_starts`` from the best particle's predicted pose; ``_probe`` given them decides
    as it does alone."""
    hits = _cast(ROOM)
    rc = _filter(hits).config.rbpf
    f = _filter(hits)
    args = (f.luts, rc.max_iterations, rc.tolerance, rc.min_inliers, rc.coarse_stride)
    both = f.maps.match(off, *hits, *args, f.probe_yaws)
    probe = both.probe
    alone = _match(f, off, hits)
    for name in ("poses", "loglik", "inliers", "hessian"):
        np.testing.assert_array_equal(getattr(both, name), getattr(alone, name))
    b = int(np.argmax(alone.loglik))
    starts = np.repeat(off[b : b + 1], 6, axis=0)
    starts[:, 2] = wrap_angle(starts[:, 2] + f.probe_yaws)
    separate = match_from_starts(f.maps, b, starts, hits, f.luts, rc)
    assert probe.poses.shape == (6, 3)
    for name in ("poses", "loglik", "inliers", "hessian"):
        np.testing.assert_array_equal(getattr(probe, name), getattr(separate, name))
    g = _filter(hits)
    fired_with = f._probe(off, hits, both, probe)
    fired_alone = g._probe(off, hits, _match(g, off, hits))
    assert f.probes == g.probes == 1
    np.testing.assert_array_equal(fired_with.poses, fired_alone.poses)
    assert f.maps.match(off, *hits, *args, np.zeros(0)).probe.poses.shape == (0, 3)
    assert alone.probe is None


def test_a_closed_probe_keeps_its_reference_and_does_not_fire():
    """Closed (no evidence yet of an odometry that errs by the probe's rotations), the probe
    leaves mit-csail's glitch alone but still records the first match's score."""
    hits = _cast(ROOM)
    f = _filter(hits)
    first = _match(f, OFF, hits)
    kept = first.poses.copy()
    got = f._probe(OFF, hits, first, None, probe_open=False)
    assert f.probes == 0
    np.testing.assert_array_equal(got.poses, kept)
    assert len(f.recent_best) == 11
    assert f.recent_best[-1] == pytest.approx(float(first.loglik.max()) / hits[0].size)


@pytest.mark.parametrize(
    ("per_m", "count", "gross", "travelled", "open_"),
    [
        (0.03, 3, 0, 0.0, False),  # nothing seen yet
        (0.03, 3, 2, 10.0, False),  # 20 per 100 m, but fewer than 3
        (0.03, 3, 3, 100.0, True),  # 3 per 100 m: mit-csail's odometry shows 34-39, fr079's 4-7
        (0.03, 3, 3, 100.1, False),  # just under 3 per 100 m
        (0.03, 3, 12, 516.5, False),  # intel: 2.3 per 100 m
        (0.03, 3, 1, 1416.5, False),  # fr-clinic: 1 in 1.4 km
        (0.0, 3, 0, 0.0, True),  # 0: always open
    ],
)
def test_the_probe_opens_on_evidence_of_gross_odometry_turns(per_m, count, gross, travelled, open_):
    f = _filter(_cast(ROOM))
    rc = dataclasses.replace(f.config.rbpf, probe_evidence_per_m=per_m, probe_evidence_count=count)
    f.config = dataclasses.replace(f.config, rbpf=rc)
    f.gross_turns, f.travelled = gross, travelled
    assert f.probe_open is open_
    f.config = dataclasses.replace(f.config, rbpf=dataclasses.replace(rc, probe_gain=0.0))
    assert f.probe_open is False


SHIFTED = np.array([[0.5, 0.0, 0.0], [0.53, 0.02, 0.01], [0.48, -0.02, -0.01]])
"""Predicted poses 0.5 m ahead of the true position along the heading, as after an odometry
that counted forward travel while the robot backed up (fr079's reversals)."""


def test_the_shift_probe_recovers_a_distance_beyond_the_basin():
    hits = _cast(ROOM)
    f = _filter(hits)
    f.shift_probes = 0
    first = _match(f, SHIFTED, hits)
    assert (first.poses[:, 0] > 0.4).all(), "the first match must stay in the wrong basin"
    assert (first.loglik / hits[0].size < -1.5).all()
    got = f._shift_probe(SHIFTED, hits, first, -0.05)
    assert f.shift_probes == 1
    np.testing.assert_allclose(got.poses[:, :2], 0.0, atol=0.05)
    np.testing.assert_allclose(got.poses[:, 2], 0.0, atol=0.01)
    assert (got.loglik / hits[0].size > -1.0).all()


def test_the_shift_probe_leaves_good_matches_and_new_space_alone():
    """No firing without a shortfall from the recent updates (a good match, or no reference
    yet), nor when no shifted start explains the scan (another room)."""
    hits = _cast(ROOM)
    near = np.array([[0.03, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.0]])
    other = _cast(ROOM[:, ::-1] * np.array([1.6, 0.7]))
    for predicted, scan, typical in ((near, hits, -0.05), (SHIFTED, hits, None),
                                     (SHIFTED, other, -0.05)):  # fmt: skip
        f = _filter(hits)
        f.shift_probes = 0
        first = _match(f, predicted, scan)
        kept = first.poses.copy()
        got = f._shift_probe(predicted, scan, first, typical)
        assert f.shift_probes == 0
        np.testing.assert_array_equal(got.poses, kept)


@pytest.mark.parametrize(
    ("shift", "shifts", "travelled", "open_"),
    [
        ((0.3, 0.6), 3, 100.0, True),  # fr079: 6.4 first matches of 0.3 m or more per 100 m
        ((0.3, 0.6), 2, 10.0, False),  # fewer than 3
        ((0.3, 0.6), 20, 1402.0, False),  # fr-clinic: 1.4 per 100 m
        ((), 50, 100.0, False),  # no shifts: never
    ],
)
def test_the_shift_probe_opens_on_evidence_of_gross_odometry_shifts(
    shift, shifts, travelled, open_
):
    f = _filter(_cast(ROOM))
    f.config = dataclasses.replace(
        f.config, rbpf=dataclasses.replace(f.config.rbpf, probe_shift=shift)
    )
    f.gross_turns, f.gross_shifts, f.travelled = 0, shifts, travelled
    assert f.shift_probe_open is open_
    assert f.probe_open is False  # the rotation probe counts its own evidence
