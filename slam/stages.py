"""The stages after the filter: from the filter's nodes to the final trajectory and map.

When a run's filter finishes (:meth:`slam.particle_filter.RbpfFilter.finish`) it hands over a
:class:`~slam.particle_filter.FilterOutput`: the poses of its updates (the nodes, for ``rbpf`` the
ancestry of the best particle), its diagnostics and every processed scan. Stages then run in
order, each taking an output and returning the next (:meth:`slam.online.Slam.finish` runs them):

1. :class:`LoopClosing` — a pose graph with scan-matched loop edges (:func:`slam.graph.close_loops`);
2. :class:`Reregistration` — the node scans registered again against the map they build together
   (:func:`refine_trajectory`, ``rbpf.refine_passes`` times);
3. :class:`BetweenUpdates` — a pose for every scan: odometry between the nodes, the correction
   found at each node spread along the way (:func:`interpolate_between_updates`);
4. :class:`ScanRegistration` — every scan registered against the map of the node scans
   (:func:`register_every_scan`, ``rbpf.register_scans``);
5. :class:`OdometrySmoothing` — every scan's pose smoothed with the odometry between neighbours,
   as far as the log's odometry deserves (``rbpf.smooth_odometry``); 4 and 5 run
   ``rbpf.register_rounds`` times, each round's map built from the node scans at the poses the
   previous round smoothed;
6. :class:`Repair` — when stretches of the result contradict the map of the others
   (``rbpf.repair_below``), stages 1–5 again from the filter's nodes with the loop closing's
   chain looser across them (``loops.flex_factor``), the better-scoring result kept;
7. :class:`Recovery` — when the result's map-quality score says the filter lost track
   (``rbpf.recover_below``), stages 1–5 again from dead reckoning (the odometry's poses as the
   nodes), the better-scoring result kept;
8. :class:`FinalMap` — the occupancy grid of the node scans at their final poses (:func:`build_map`).

``rbpf`` runs all eight (:func:`default_stages`); ``classic`` none (its filter outputs every
scan's pose and its own map). A stage is anything with a ``name`` and a ``run(output, config)``
method (:class:`Stage`), so a caller can drop, reorder or add stages.
"""

from __future__ import annotations

import dataclasses
import time
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from slam.budget import release_free_memory
from slam.config import Config, MapConfig
from slam.geometry import compose, relative, spread_corrections, spread_picks
from slam.graph import FirstRound
from slam.kernels.scan import thin_returns
from slam.mapping import (
    OccupancyGrid,
    ParticleMaps,
    WorldRays,
    _check_growth,
    growth_steps,
    integrate_scan_rays,
    likelihood_tables,
)
from slam.particle_filter import FilterOutput, particle_maps
from slam.scans import ScanHits, ScanSequence

if TYPE_CHECKING:
    from slam.eval.quality import QualityResult, Rays, StretchScore

F64 = NDArray[np.float64]


class Stage(Protocol):
    """One step from the filter's output towards the final trajectory and map."""

    name: str
    """Short name (for messages and timings)."""

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Return the output with this stage applied (the input is not modified)."""


class LoopClosing:
    """Close loops over the nodes with a pose graph (``[loops]``; skipped when disabled).

    ``start``: a dict that the instances of one run share with :class:`Repair`, which keeps the
    output this stage was handed (the filter's) under ``"output"`` to start from again.
    ``loose``: time spans ``(t0, t1)`` (the log's clock) across which the chain's sigmas are
    ``loops.flex_factor`` times larger (:func:`slam.graph.chain_looseness`). ``first``: a
    :class:`slam.graph.FirstRound` shared with the :class:`Repair` of the run, whose rerun from
    the same output takes the first round's closures from it instead of searching again.
    """

    name = "loop closing"

    def __init__(
        self,
        start: dict | None = None,
        loose: list[tuple[float, float]] | None = None,
        first: FirstRound | None = None,
    ) -> None:
        self.start = start
        self.loose = loose or []
        self.first = first

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Optimise the node poses; the stats get the candidates, closures and correction."""
        if self.start is not None:
            self.start["output"] = output
        if not config.loops.enabled or len(output.steps) <= 1:
            return output
        from slam.backend.global_loops import close_loops_global
        from slam.graph import close_loops

        loose_nodes = None
        if self.loose:
            times = output.scans.times[output.steps]
            loose_nodes = np.zeros(len(times), dtype=bool)
            for t0, t1 in self.loose:
                loose_nodes |= (times >= t0) & (times <= t1)
        close = close_loops_global if config.backend.global_search else close_loops
        closed = close(
            output.scans,
            output.steps,
            output.node_poses,
            config,
            loose_nodes=loose_nodes,
            first=self.first,
        )
        stats = {
            **output.stats,
            "loop_candidates": closed.candidates,
            "loop_closures": closed.accepted,
            "loop_correction_max_m": round(closed.correction_max_m, 3),
        }
        return dataclasses.replace(output, node_poses=closed.poses, stats=stats)


class Reregistration:
    """Register the node scans again against their joint map, ``rbpf.refine_passes`` times."""

    name = "re-registration"

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Refined node poses (:func:`refine_trajectory`)."""
        poses = output.node_poses
        if config.rbpf.refine_passes == 0:
            return output
        scans = RegistrationScans.of(output.scans, output.steps, config)
        for _ in range(config.rbpf.refine_passes):
            poses = refine_trajectory(output.scans, poses, output.steps, config, scans)
        return dataclasses.replace(output, node_poses=poses)


class BetweenUpdates:
    """Place every scan: the nodes at their poses, the scans between them by odometry."""

    name = "between-update placement"

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Every scan's pose (:func:`interpolate_between_updates`)."""
        poses = interpolate_between_updates(output.scans, output.steps, output.node_poses)
        return dataclasses.replace(output, poses=poses)


class ScanRegistration:
    """Register every scan against the node map (``rbpf.register_scans``; after
    :class:`BetweenUpdates`)."""

    name = "scan registration"

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Every scan's pose registered (:func:`register_every_scan`); the nodes' poses follow."""
        if not config.rbpf.register_scans or output.poses is None or len(output.steps) == 0:
            return output
        poses = register_every_scan(output.scans, output.poses, output.steps, config)
        return dataclasses.replace(output, poses=poses, node_poses=poses[output.steps])


ODOMETRY_FLOOR = 1e-3
"""The least odometry disagreement (m along and across, rad in heading) the smoothing weighs a
step by: a simulated log without noise can measure 0; the benchmark logs measure at least
3.6 mm and 3.7 mrad, which it leaves alone."""


class OdometrySmoothing:
    """Smooth every scan's pose with the odometry between neighbours (``rbpf.smooth_odometry``;
    after :class:`ScanRegistration`).

    ``measured``: a dict that instances of one run share, so that the odometry's disagreement
    with the matcher — a property of the log, not of the poses — is measured once however many
    rounds of registration and smoothing the run makes (``rbpf.register_rounds``).
    """

    name = "odometry smoothing"

    def __init__(self, measured: dict | None = None) -> None:
        self.measured = {} if measured is None else measured

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Every scan's pose pulled towards the odometry's shape
        (:func:`slam.graph.smooth_with_odometry`), the odometry's sigmas measured on the log
        (:func:`slam.calibration.odometry_disagreement`); the nodes' poses follow."""
        rc = config.rbpf
        if not rc.smooth_odometry or output.poses is None or len(output.poses) < 2:
            return output
        from slam.calibration import odometry_disagreement
        from slam.graph import smooth_with_odometry

        seq = output.scans
        odometry = np.asarray(seq.odometry, dtype=np.float64)
        if self.measured.get("scans") is not seq:  # another run's scans (stages reused): anew
            self.measured["scans"] = seq
            self.measured["value"] = odometry_disagreement(seq.hits, odometry, config)
        measured = self.measured["value"]
        if measured.pairs == 0:
            return output
        # along, across, heading; floored: a noise-free log whose scans match its odometry
        # exactly would give an infinite weight
        odo = tuple(rc.smooth_factor * max(v, ODOMETRY_FLOOR) for v in measured[:3])
        if self.measured.get("choice_of") is not seq:  # the first round chooses the scale
            from slam.calibration import noise_multiple, noise_picks

            readings = seq.readings(noise_picks(len(seq)))[0]
            base, self.measured["range_noise"], _ = noise_multiple(readings, rc.smooth_noise_ref)
            choice = choose_smoothing(output.poses, odometry, seq, odo, config)
            scale, poses = choice.scale, choice.poses
            if scale < base:  # no multiple won: the laser's noise sets how far to trust it
                scale = base
                reg = (scale * rc.smooth_sigma_xy, scale * rc.smooth_sigma_th)
                poses = smooth_with_odometry(output.poses, odometry, reg, odo, config.loops)
            self.measured.update(
                choice_of=seq, scale=scale, scores=choice.scores, judged=choice.judged
            )
        else:
            scale = self.measured["scale"]
            reg = (scale * rc.smooth_sigma_xy, scale * rc.smooth_sigma_th)
            poses = smooth_with_odometry(output.poses, odometry, reg, odo, config.loops)
        stats = {
            **output.stats,
            "odometry_disagreement_along_m": round(measured.along, 4),
            "odometry_disagreement_across_m": round(measured.across, 4),
            "odometry_disagreement_deg": round(float(np.degrees(measured.heading)), 3),
            "smooth_scale": round(float(scale), 4),
        }
        if np.isfinite(self.measured["range_noise"]):
            stats["range_noise_m"] = round(float(self.measured["range_noise"]), 4)
        if self.measured["scores"]:
            stats["smooth_scale_scores"] = [
                round(v, 4) if np.isfinite(v) else None for v in self.measured["scores"]
            ]
            stats["smooth_scale_judged"] = list(self.measured["judged"])
        return dataclasses.replace(output, poses=poses, node_poses=poses[output.steps], stats=stats)


class SmoothingChoice(NamedTuple):
    """What :func:`choose_smoothing` chose, and on what."""

    scale: float
    """The multiple of the registration's sigmas kept."""
    scores: list[float]
    """The map-quality score of each multiple of ``rbpf.smooth_scales`` (NaN: nothing judged;
    empty with one multiple: nothing scored)."""
    judged: list[int]
    """The returns each score judged (``checked`` of :meth:`~slam.eval.quality.QualityResult.totals`)."""
    poses: F64
    """The trajectory smoothed at ``scale``."""


def smoothing_pick(scores: list[float], judged: list[int], margin: float, z: float) -> int:
    """Which of ``scores`` (shares of ``judged`` returns that agree) :func:`choose_smoothing`
    keeps: the best, when it beats the first by at least ``margin`` and by at least ``z``
    standard errors of the difference of the two shares (each a binomial share of its judged
    returns, the two taken as independent: an upper bound on the error, since both judge the
    same returns); else the first. A NaN score (nothing judged) never wins."""
    values = np.nan_to_num(np.array(scores, dtype=np.float64), nan=-np.inf)
    best = int(np.argmax(values))
    if best == 0 or not np.isfinite(values[best]):
        return 0
    gain = values[best] - values[0]
    if gain < margin:
        return 0
    if np.isfinite(values[0]) and z > 0.0:
        p, q = values[best], values[0]
        se = np.sqrt(p * (1.0 - p) / max(judged[best], 1) + q * (1.0 - q) / max(judged[0], 1))
        if gain < z * se:
            return 0
    return best


def choose_smoothing(
    poses: F64, odometry: F64, seq: ScanSequence, odo: tuple[float, float, float], config: Config
) -> SmoothingChoice:
    """The multiple of the registration's sigmas :attr:`~slam.config.RbpfConfig.smooth_scales`
    picks for ``poses`` (every scan's, registered) and the odometry's sigmas ``odo`` (along,
    across, heading; :func:`slam.graph.smooth_with_odometry`): each
    scale's smoothed trajectory (:func:`slam.graph.smooth_with_odometry`) scored by the map
    quality (:func:`slam.eval.quality.map_quality`) of every ``smooth_choice_every``-th scan,
    the best unless it beats the first by less than ``smooth_choice_margin`` or by less than
    ``smooth_choice_z`` standard errors (:func:`smoothing_pick`)."""
    from slam.eval.quality import map_quality
    from slam.graph import smooth_with_odometry

    rc = config.rbpf
    trials = []
    for scale in rc.smooth_scales:
        reg = (scale * rc.smooth_sigma_xy, scale * rc.smooth_sigma_th)
        trials.append(smooth_with_odometry(poses, odometry, reg, odo, config.loops))
    if len(trials) == 1:
        return SmoothingChoice(rc.smooth_scales[0], [], [], trials[0])
    picks = np.arange(0, len(seq), rc.smooth_choice_every)
    rays = quality_rays(seq, picks, config)
    times = seq.times[picks]
    results = [
        map_quality(times, trial[picks], rays, config.quality, config.map) for trial in trials
    ]
    scores = [r.score for r in results]
    judged = [r.totals()["checked"] for r in results]
    best = smoothing_pick(scores, judged, rc.smooth_choice_margin, rc.smooth_choice_z)
    return SmoothingChoice(rc.smooth_scales[best], scores, judged, trials[best])


def quality_rays(seq: ScanSequence, picks: NDArray[np.int64], config: Config) -> Rays:
    """The rays of scans ``picks`` of ``seq`` as the map-quality score reads them
    (:func:`slam.eval.quality.scan_rays`: the scans padded to the run's widest with NaN
    readings (:meth:`ScanSequence.readings`), each with its own beam angles, at most
    ``rbpf.smooth_choice_beams`` of them; the range limits and laser pose of the first scan)."""
    from slam.eval.quality import scan_rays

    first = seq.scan(0)
    most = config.rbpf.smooth_choice_beams
    # evenly spread, as Scan.hits thins; only those columns are read (the whole width in
    # float64 was 16 bytes a reading of every picked scan)
    beams = spread_picks(seq.num_beams, most) if seq.num_beams > most else None
    ranges, angles = seq.readings(picks, seq.num_beams, beams)
    return scan_rays(
        ranges, angles, seq.laser_offset, first.range_min, first.range_max, first.no_return,
        config.map.free_range_no_return,
    )  # fmt: skip


class Repair:
    """Stages 1–5 again with a looser chain across the stretches that contradict the others.

    The loop closing trusts the filter's relative poses between keyframes to ``loops.seq_sigma_xy
    + seq_sigma_rel`` of each step, which fits a filter that kept its shape. Where it did not (a
    laser that sees 8 m down a corridor, where a metre's drift along it goes unseen), the right
    closures would bend the chain further than that, fail the χ² gate after their pull-in, and
    leave the stretch where the filter put it: its walls then lie off the walls that the other
    passes through the same place saw. The map-quality score finds such stretches without
    ground truth: a stretch (``quality.stretch_m`` of path) whose returns agree with the others'
    map less than ``rbpf.repair_below`` contradicts them. When any does, stages 1–5 run again
    from the filter's output (kept by :class:`LoopClosing` in ``start``) with the chain's sigmas
    ``loops.flex_factor`` times larger between the keyframes across those stretches, the
    smoothing at the multiple the first pass chose (``measured``, shared with its
    :class:`OdometrySmoothing`), and the better-scoring result is kept, the first unless the
    other beats it by the smoothing choice's margin and standard errors (:func:`smoothing_pick`)
    and breaks no stretch that agreed (:func:`broken_stretches`). The stats record the
    stretches (``repair_stretches``), both scores (``repair_scores``), the stretches the rerun
    broke (``repair_broke``, their times) and which was kept (``repaired``). Scored on every
    ``rbpf.smooth_choice_every``-th scan, as the smoothing's choice and :class:`Recovery` score;
    ``scored``, a dict shared with the run's :class:`Recovery`, hands it the score of the result
    returned, so that it is not computed twice. ``first``, shared with the run's
    :class:`LoopClosing`, gives the rerun the first round's closures (the same nodes, the same
    closures: only the optimisation sees the looser chain).
    """

    name = "repair"

    def __init__(
        self,
        start: dict,
        measured: dict,
        scored: dict | None = None,
        first: FirstRound | None = None,
    ) -> None:
        self.start = start
        self.measured = measured
        self.scored = scored
        self.first = first

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """``output``, or the stages' result with the looser chain when it scores better."""
        rc = config.rbpf
        first = self.start.pop("output", None)  # not kept beyond the run
        seq = output.scans
        if (
            first is None
            or first.scans is not seq
            or rc.repair_below <= 0.0
            or config.loops.flex_factor == 1.0
            or not config.loops.enabled
            or output.poses is None
            or len(output.steps) < 2
        ):
            return output
        picks = np.arange(0, len(seq), rc.smooth_choice_every)
        rays = quality_rays(seq, picks, config)
        result = _quality(output.poses, seq, picks, rays, config)
        score, checked = _score_of(result)
        loose = [(s.t_start, s.t_end) for s in result.judged() if s.score < rc.repair_below]
        if not loose:
            _remember(self.scored, output.poses, picks, rays, score, checked)
            return output
        closing = LoopClosing(loose=loose, first=self.first)
        again = _stages_one_to_five(closing, self.measured, config)
        other = run_stages(first, again, config)
        after = _quality(other.poses, seq, picks, rays, config)
        other_score, other_judged = _score_of(after)
        scores, judged = [score, other_score], [checked, other_judged]
        kept = smoothing_pick(scores, judged, rc.smooth_choice_margin, rc.smooth_choice_z)
        broken = broken_stretches(result, after, rc.smooth_choice_margin, rc.smooth_choice_z)
        if broken:
            kept = 0
        chosen = other if kept == 1 else output
        _remember(self.scored, chosen.poses, picks, rays, scores[kept], judged[kept])
        stats = {
            **chosen.stats,
            "repair_stretches": len(loose),
            "repair_scores": [round(v, 4) if np.isfinite(v) else None for v in scores],
            "repair_broke": [[round(s.t_start, 3), round(s.t_end, 3)] for s in broken],
            "repaired": kept == 1,
        }
        return dataclasses.replace(chosen, stats=stats)


class Recovery:
    """Stages 1–5 again from dead reckoning when the result scores as a filter that lost track.

    A filter can lose track where its scans say too little (a laser that sees 8 m in a hall 20 m
    wide; docs/accuracy.md, "A laser that sees less far"), and the stages after it start from
    its nodes. The same stages started from the odometry's poses instead close the loops the
    odometry left open (the global loop search looks as far as the drift) and register every
    scan; where the filter was lost, that is the better trajectory. So: when the result's
    map-quality score (on every ``rbpf.smooth_choice_every``-th scan, as the smoothing choice
    scores) is below ``rbpf.recover_below``, stages 1–5 run again (fresh instances,
    :func:`default_stages`) on the filter's output with the odometry's poses as its nodes, and
    the better of the two by the score is kept, the filter's unless the other beats it by the
    smoothing choice's margin and standard errors (:func:`smoothing_pick`). The stats record
    both scores (``recovery_scores``) and which was kept (``recovered``); keeping the odometry's
    start warns. On the bench's default runs (six logs, seeds 0–3) the score is above the
    threshold and nothing runs again. Only from dead reckoning: where the odometry is the
    laser's (``ScanSequence.odometry_source``), it is a scan matcher that lost its way with the
    filter (fr-clinic without its wheels: lost either way, and chosen between by a score that
    cannot tell two wrong maps apart).
    """

    name = "recovery"

    def __init__(self, scored: dict | None = None) -> None:
        self.scored = scored

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """``output``, or the stages' result from dead reckoning when it scores better (the
        score :class:`Repair` left in ``scored`` for the same poses is taken, not computed
        again)."""
        rc = config.rbpf
        seq = output.scans
        known = self.scored.copy() if self.scored is not None else {}
        if self.scored is not None:
            self.scored.clear()  # not kept beyond the run
        if rc.recover_below <= 0.0 or output.poses is None or len(output.steps) < 2:
            return output
        if seq.odometry_source != "log":
            return output  # laser odometry is a scan matcher too: no dead reckoning to start from
        import warnings

        if known.get("poses") is output.poses:
            picks, rays, score, judged = (known[k] for k in ("picks", "rays", "score", "judged"))
        else:
            picks = np.arange(0, len(seq), rc.smooth_choice_every)
            rays = quality_rays(seq, picks, config)
            score, judged = _score(output.poses, seq, picks, rays, config)
        if not np.isfinite(score) or score >= rc.recover_below:
            return output
        again = [stage for stage in default_stages(config) if _redone(stage)]
        start = dataclasses.replace(
            output,
            node_poses=np.asarray(seq.odometry, dtype=np.float64)[output.steps].copy(),
            poses=None,
            grid=None,
            stats={k: v for k, v in output.stats.items() if k in _FILTER_STATS},
        )
        other = run_stages(start, again, config)
        other_score, other_judged = _score(other.poses, seq, picks, rays, config)
        scores = [score, other_score]
        kept = smoothing_pick(
            scores, [judged, other_judged], rc.smooth_choice_margin, rc.smooth_choice_z
        )
        result = other if kept == 1 else output
        stats = {
            **result.stats,
            # what the repair did ran either way: the record of it stays with either result
            **{k: v for k, v in output.stats.items() if k in _REPAIR_STATS},
            "recovery_scores": [round(v, 4) if np.isfinite(v) else None for v in scores],
            "recovered": kept == 1,
        }
        if kept == 1:
            warnings.warn(
                f"the filter lost track (map quality {score:.3f}, below rbpf.recover_below = "
                f"{rc.recover_below:g}): the stages after it, run again from dead reckoning, "
                f"score {other_score:.3f}, and the run keeps that trajectory",
                stacklevel=2,
            )
        return dataclasses.replace(result, stats=stats)


_FILTER_STATS = frozenset(
    {"updates", "resamples", "match_fallbacks", "match_retries", "basin_probes", "gross_turns",
     "shift_probes", "gross_shifts", "peak_tiles", "peak_particle_map_mb"}
)  # fmt: skip
"""The filter's own counters, which a result started from dead reckoning keeps."""

_REPAIR_STATS = frozenset({"repair_stretches", "repair_scores", "repair_broke", "repaired"})
"""What :class:`Repair` records, which :class:`Recovery` keeps whichever result it keeps."""


def _redone(stage: Stage) -> bool:
    """Whether :class:`Recovery` runs ``stage`` again (stages 1–5: not the repair, itself nor
    the map)."""
    return not isinstance(stage, Repair | Recovery | FinalMap)


def broken_stretches(
    before: QualityResult, after: QualityResult, margin: float, z: float
) -> list[StretchScore]:
    """The stretches of ``before`` that agreed and that ``after`` makes doubtful: judged in
    ``before`` with a score at least ``quality.flag_below``, and over the same scans
    (:meth:`~slam.eval.quality.QualityResult.score_over`) judged on at least
    ``quality.min_checked`` returns of ``after``, below ``flag_below`` and lower by ``margin``
    and ``z`` standard errors (:func:`smoothing_pick`'s rule). :class:`Repair` keeps no rerun
    that breaks one: a looser chain that mends the stretches it was loosened for can let a
    closure pull a stretch that held out of place (mit-killian read every third scan:
    docs/accuracy.md, "Stretches that contradict the others, repaired")."""
    qc = before.config
    broken = []
    for s in before.judged():
        if s.score < qc.flag_below:
            continue
        share, checked = after.score_over(s.first, s.last)
        if checked < qc.min_checked or not share < qc.flag_below:
            continue
        if smoothing_pick([share, s.score], [checked, s.checked], margin, z) == 1:
            broken.append(s)
    return broken


def _remember(
    scored: dict | None,
    poses: F64 | None,
    picks: NDArray[np.int64],
    rays: Rays,
    score: float,
    judged: int,
) -> None:
    """Keep in ``scored`` (when given) the score of ``poses`` on the scans ``picks`` and the
    returns it judged, for :class:`Recovery` to take (keyed by the poses array itself)."""
    if scored is not None:
        scored.update(poses=poses, picks=picks, rays=rays, score=score, judged=judged)


def _quality(
    poses: F64, seq: ScanSequence, picks: NDArray[np.int64], rays: Rays, config: Config
) -> QualityResult:
    """The map quality of ``poses`` on the scans ``picks`` (their ``rays``)."""
    from slam.eval.quality import map_quality

    return map_quality(seq.times[picks], poses[picks], rays, config.quality, config.map)


def _score_of(result: QualityResult) -> tuple[float, int]:
    """A map quality's score and the returns it judged."""
    return float(result.score), int(result.totals()["checked"])


def _score(
    poses: F64, seq: ScanSequence, picks: NDArray[np.int64], rays: Rays, config: Config
) -> tuple[float, int]:
    """The map-quality score of ``poses`` on the scans ``picks`` and the returns it judged."""
    return _score_of(_quality(poses, seq, picks, rays, config))


def _stages_one_to_five(closing: LoopClosing, measured: dict, config: Config) -> list[Stage]:
    """Stages 1–5 of ``rbpf``: ``closing``, the re-registration, the placement between updates,
    and ``rbpf.register_rounds`` rounds of registration and smoothing, whose smoothings share
    ``measured`` (the odometry's disagreement and the multiple chosen)."""
    rounds = [
        stage
        for _ in range(config.rbpf.register_rounds)
        for stage in (ScanRegistration(), OdometrySmoothing(measured))
    ]
    return [closing, Reregistration(), BetweenUpdates(), *rounds]


class FinalMap:
    """The occupancy grid of the node scans at their final poses (after :class:`BetweenUpdates`)."""

    name = "final map"

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """The grid (:func:`build_map`)."""
        if output.poses is None:
            raise ValueError("final map: the scans have no poses yet (run BetweenUpdates first)")
        release_free_memory()  # the stages' freed heap, before the run's largest array
        grid = build_map(output.scans, output.poses, output.steps, config)
        return dataclasses.replace(output, grid=grid)


def default_stages(config: Config) -> list[Stage]:
    """The stages a run of ``config.filter.method`` goes through after its filter."""
    if config.filter.method == "rbpf":
        measured: dict = {}  # the odometry's disagreement, measured once for every round
        start: dict = {}  # the filter's output, for the repair to start from again
        scored: dict = {}  # the repair's score of its result, for the recovery to take
        first = FirstRound()  # the loop closing's first round, for the repair's rerun
        return [
            *_stages_one_to_five(LoopClosing(start, first=first), measured, config),
            Repair(start, measured, scored, first), Recovery(scored), FinalMap(),
        ]  # fmt: skip
    return []


def run_stages(
    output: FilterOutput,
    stages: list[Stage],
    config: Config,
    seconds: dict[str, float] | None = None,
) -> FilterOutput:
    """Apply ``stages`` in order; ``seconds``, when given, receives each stage's wall time under
    its name (added to what the name already holds)."""
    for stage in stages:
        start = time.perf_counter()
        output = stage.run(output, config)
        if seconds is not None:
            seconds[stage.name] = seconds.get(stage.name, 0.0) + time.perf_counter() - start
    return output


def build_map(
    seq: ScanSequence, poses: F64, steps: NDArray[np.int64], config: Config
) -> OccupancyGrid:
    """Occupancy grid of the scans ``steps`` of ``seq`` taken at ``poses[steps]``.

    The same grid, to the bit, as integrating the scans one by one into a growing
    :class:`~slam.mapping.OccupancyGrid` and cropping it (``crop_margin_m``), with one
    allocation instead of a copy per growth: :func:`_growth_plan` replays how that grid would
    grow (no cells), the grid is allocated once at its final size, and each scan is integrated
    into the part of it the growing grid covered then, with the origin it had then, so every ray
    falls on the very cells it did; the crop then moves the kept rows to the front of the same
    buffer (:func:`_crop_in_place`). The peak is one grid instead of two (old and new copy). The
    rays are computed for many scans at once (:func:`_world_rays`, ``_RAYS_AT_ONCE`` beams at a
    time, once for the plan and again to integrate them) and integrated in one kernel call per
    such part (:func:`slam.mapping.integrate_scan_rays`), not in numpy and kernel calls per scan.
    """
    mc = config.map
    start = OccupancyGrid(mc, center=(float(poses[0, 0]), float(poses[0, 1])))
    span = np.concatenate([poses[:, :2].min(axis=0) - 1.0, poses[:, :2].max(axis=0) + 1.0])
    steps = np.asarray(steps, dtype=np.int64)
    at_once = max(1, _RAYS_AT_ONCE // max(seq.num_beams, 1))  # scans whose rays fit at once
    parts = [steps[a : a + at_once] for a in range(0, steps.size, at_once)]
    boxes = np.concatenate([_world_rays(seq, poses, part, mc)[1] for part in parts] or [[]])
    plan, final = _growth_plan(boxes.reshape(-1, 4), mc, start, span)
    origin, rows, cols, bottom, left = final
    res = start.resolution
    _check_growth(4.0 * rows * cols, "an occupancy grid", cols * res, rows * res)
    views = np.zeros((len(plan), 4), dtype=np.int64)  # (r0, c0, h, w); h = 0: no rays, skipped
    origins = np.zeros((len(plan), 2))
    for i, state in enumerate(plan):
        if state is not None:
            at, h, w, below, beside = state
            views[i] = bottom - below, left - beside, h, w
            origins[i] = at
    buffer = np.zeros(rows * cols, dtype=np.float32)
    for a, part in zip(range(0, steps.size, at_once), parts, strict=True):
        rays, _ = _world_rays(seq, poses, part, mc)  # again: rays of a few scans at a time
        b = a + part.size
        integrate_scan_rays(buffer.reshape(rows, cols), views[a:b], origins[a:b], res, rays, mc)
    return _crop_in_place(buffer, rows, cols, origin, config)


_RAYS_AT_ONCE = 1 << 16
"""Beams whose rays :func:`build_map` computes at once (:func:`_world_rays`, as many scans as
hold this many beams): a few MB of rays at a time, whatever the length of the log."""


def _world_rays(
    seq: ScanSequence, poses: F64, steps: NDArray[np.int64], mc: MapConfig
) -> tuple[WorldRays, F64]:
    """The rays :func:`slam.particle_filter.integrate_scan` would integrate for each of the scans
    ``steps`` at ``poses[steps]``, for all of them at once, and each scan's box ``(S, 4)``:
    ``(xmin, ymin, xmax, ymax)`` of its ray ends and sensor (NaN: no rays). The same element-wise
    operations (:meth:`ScanSequence.ray_table`, then those of
    :func:`slam.geometry.transform_points` and :func:`compose` over the scans), so the same
    values to the bit, without calls per scan."""
    ends, hit, offsets = seq.ray_table(steps, mc.free_range_no_return, mc.free_beam_stride)
    at = poses[steps]
    sensors = np.ascontiguousarray(compose(at, seq.laser_offset)[:, :2])
    counts = np.diff(offsets)
    scan_of = np.repeat(np.arange(len(steps)), counts)
    c, s = np.cos(at[:, 2])[scan_of], np.sin(at[:, 2])[scan_of]
    x = at[scan_of, 0] + c * ends[:, 0] - s * ends[:, 1]  # transform_points' order of operations
    y = at[scan_of, 1] + s * ends[:, 0] + c * ends[:, 1]
    boxes = np.full((len(steps), 4), np.nan)
    some = np.flatnonzero(counts > 0)
    if some.size:
        first = offsets[some]
        boxes[some, 0] = np.minimum(np.minimum.reduceat(x, first), sensors[some, 0])
        boxes[some, 1] = np.minimum(np.minimum.reduceat(y, first), sensors[some, 1])
        boxes[some, 2] = np.maximum(np.maximum.reduceat(x, first), sensors[some, 0])
        boxes[some, 3] = np.maximum(np.maximum.reduceat(y, first), sensors[some, 1])
    return (np.stack([x, y], axis=1), hit, offsets, sensors), boxes


GridState = tuple[F64, int, int, int, int]
"""A growing grid's ``(origin, rows, cols, bottom, left)``: origin, shape, and how many rows
and columns were added below and to the left since it started."""


def _grown(state: GridState, box: tuple[float, float, float, float], mc: MapConfig) -> GridState:
    """``state`` after :meth:`slam.mapping.OccupancyGrid.ensure_contains` of ``box`` (the same
    arithmetic, so the same origin to the bit)."""
    origin, rows, cols, bottom, left = state
    res = float(mc.resolution)
    x0, y0 = float(origin[0]), float(origin[1])
    grow = growth_steps(box, (x0, y0, x0 + cols * res, y0 + rows * res), res, mc.grow_margin_m)
    if grow is None:
        return state
    dl, db, dr, dt = grow
    origin = origin - np.array([dl * res, db * res])
    return origin, rows + db + dt, cols + dl + dr, bottom + db, left + dl


def _growth_plan(
    boxes: F64, mc: MapConfig, start: OccupancyGrid, span: F64
) -> tuple[list[GridState | None], GridState]:
    """The state of the growing grid of :func:`build_map` at each scan, given each scan's box
    (:func:`_world_rays`; ``None`` for a scan without rays, a NaN box), and its final state."""
    state: GridState = (start.origin.copy(), *start.shape, 0, 0)
    state = _grown(state, tuple(float(v) for v in span), mc)
    plan: list[GridState | None] = []
    for xmin, ymin, xmax, ymax in boxes:
        if np.isnan(xmin):
            plan.append(None)
            continue
        state = _grown(state, (xmin, ymin, xmax, ymax), mc)
        plan.append(state)
    return plan, state


def _crop_in_place(
    buffer: NDArray[np.float32], rows: int, cols: int, origin: F64, config: Config
) -> OccupancyGrid:
    """The grid ``buffer`` (``rows × cols``, lower-left corner ``origin``) reduced as
    :meth:`slam.mapping.OccupancyGrid.cropped` reduces it (observed cells plus
    ``map.crop_margin_m``), the kept rows moved to the front of ``buffer`` and the rest freed."""
    mc = config.map
    res = float(mc.resolution)
    full = buffer.reshape(rows, cols)
    known = full != 0
    if not known.any():
        return OccupancyGrid.from_arrays(full, res, origin, mc)
    used_rows = np.flatnonzero(known.any(axis=1))
    used_cols = np.flatnonzero(known.any(axis=0))
    del known
    pad = int(np.ceil(mc.crop_margin_m / res))
    r0 = max(int(used_rows[0]) - pad, 0)
    r1 = min(int(used_rows[-1]) + pad + 1, rows)
    c0 = max(int(used_cols[0]) - pad, 0)
    c1 = min(int(used_cols[-1]) + pad + 1, cols)
    h, w = r1 - r0, c1 - c0
    for i in range(h):  # row i lands before where it is read from: earlier rows stay intact
        buffer[i * w : (i + 1) * w] = full[r0 + i, c0:c1]
    del full
    buffer.resize(h * w, refcheck=False)  # no view of it is left
    origin = origin + np.array([c0, r0]) * res
    return OccupancyGrid.from_arrays(buffer.reshape(h, w), res, origin, mc)


def interpolate_between_updates(
    seq: ScanSequence, update_steps: NDArray[np.int64], update_poses: F64
) -> F64:
    """Poses of every scan from the poses at update scans and odometry in between.

    A scan between updates ``a`` and ``b`` is placed by odometry from both ends and the two are
    blended by the fraction of odometry motion covered, so the correction found at ``b`` is
    spread over the stretch instead of appearing as a jump.
    """
    odo = seq.odometry
    step = np.zeros(len(seq))
    delta = relative(odo[:-1], odo[1:])
    step[1:] = np.hypot(delta[:, 0], delta[:, 1]) + 0.2 * np.abs(delta[:, 2])
    return spread_corrections(odo, update_steps, update_poses, np.cumsum(step))


class RegistrationScans(NamedTuple):
    """The node scans as the re-registration reads them, extracted once for all its passes."""

    table: ScanHits
    """Their hits (with normals for the signed field) to build the map from."""
    ex: F64
    """``(S, W)`` robot-frame x of the beams each scan is registered with (``rbpf.refine_beams``)."""
    ey: F64
    """``(S, W)`` robot-frame y of those beams."""
    counts: NDArray[np.int64]
    """``(S,)`` beams of each scan in ``ex``, ``ey``."""

    @classmethod
    def of(cls, seq: ScanSequence, steps: NDArray[np.int64], config: Config) -> RegistrationScans:
        """The scans ``steps`` of ``seq`` with ``config``'s beam budgets."""
        rc = config.rbpf
        table = seq.hit_table(steps, rc.insert_beams, normals=rc.field == "plane")
        return cls(table, *registration_beams(seq, steps, config))


def registration_beams(
    seq: ScanSequence, scans: NDArray[np.int64], config: Config, most: int | None = None
) -> tuple[F64, F64, NDArray[np.int64]]:
    """The robot-frame beams ``(ex, ey, counts)`` the scans ``scans`` of ``seq`` are registered
    with: at most ``most`` each (0: all), evenly spread; by default ``rbpf.refine_beams`` (see
    :class:`RegistrationScans`)."""
    most = config.rbpf.refine_beams if most is None else most
    width = max(1, min(most or seq.num_beams, seq.num_beams))
    # every scan's endpoints side by side (NaN where no return or no beam); each row's returns
    # in beam order, thinned to ``width`` evenly spread as Scan.hits thins them: the values
    # Scan.hits gives, without a copy per scan
    all_x, all_y = seq.endpoint_table(scans)
    ex = np.empty((len(scans), width))
    ey = np.empty((len(scans), width))
    counts = np.empty(len(scans), dtype=np.int64)
    if len(scans):
        thin_returns(all_x, all_y, np.int64(width), ex, ey, counts)
    return ex, ey, counts


def registration_map(table: ScanHits, poses: F64, config: Config) -> ParticleMaps:
    """The distance field the stages register against: the hits ``table`` (of the node scans)
    at ``poses`` (one per node), with cells of ``rbpf.refine_resolution``."""
    rc = config.rbpf
    resolution = rc.refine_resolution or rc.resolution or config.map.resolution
    maps = particle_maps(config, poses[0], 1, resolution=resolution)
    reach = np.maximum.accumulate(table.reach) if len(poses) else table.reach  # farthest so far
    maps.insert_scans(poses, table.xy, table.offsets, reach + rc.dmax + 1.0, rc.skip_insert_below)
    return maps


def _register(maps: ParticleMaps, poses: F64, ex: F64, ey: F64, counts: NDArray[np.int64],
              config: Config) -> F64:  # fmt: skip
    """``poses`` (one per row of ``ex``) registered against ``maps`` with ``rbpf``'s matcher."""
    rc = config.rbpf
    luts = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    return maps.register(
        poses, ex, ey, counts, luts, rc.max_iterations, rc.tolerance, rc.min_inliers,
        coarse_stride=rc.coarse_stride,
    )  # fmt: skip


def refine_trajectory(
    seq: ScanSequence,
    poses: F64,
    steps: NDArray[np.int64],
    config: Config,
    scans: RegistrationScans | None = None,
) -> F64:
    """Re-register the scans ``steps`` (taken at ``poses``) against the map they build together.

    The filter's lineage carries the jitter of the proposal's sampling (that is what gives the
    filter the diversity to close loops); with the best lineage chosen, one map is built from its
    scans and each of them is registered against that map again, which keeps the global shape and
    removes the jitter. ``scans``: the scans as :meth:`RegistrationScans.of` extracts them (done
    here when not given; a caller running several passes extracts them once). Returns the
    refined poses ``(len(steps), 3)``.
    """
    if scans is None:
        scans = RegistrationScans.of(seq, steps, config)
    table, ex, ey, counts = scans
    return _register(registration_map(table, poses, config), poses, ex, ey, counts, config)


REGISTER_CHUNK = 1024
"""Scans whose beams :func:`register_every_scan` extracts at a time (bounds its memory)."""


def register_every_scan(
    seq: ScanSequence, poses: F64, steps: NDArray[np.int64], config: Config
) -> F64:
    """Every scan of ``seq`` (placed at ``poses``, one per scan) registered against the map of
    the node scans ``steps`` at ``poses[steps]``.

    Between two updates a scan is placed by odometry (:func:`interpolate_between_updates`), which
    errs by up to a few degrees there; the node map is the run's best picture of the building,
    so each scan is matched against it from its placed pose, with at most
    ``rbpf.register_beams`` of its beams. Scans are matched independently
    (no scan's pose feeds another's), in chunks of :data:`REGISTER_CHUNK`. Returns ``(N, 3)``.
    """
    table = seq.hit_table(steps, config.rbpf.insert_beams, normals=config.rbpf.field == "plane")
    maps = registration_map(table, poses[steps], config)
    out = np.empty_like(poses)
    for a in range(0, len(seq), REGISTER_CHUNK):
        chunk = np.arange(a, min(a + REGISTER_CHUNK, len(seq)), dtype=np.int64)
        ex, ey, counts = registration_beams(seq, chunk, config, config.rbpf.register_beams)
        out[chunk] = _register(maps, poses[chunk], ex, ey, counts, config)
    return out
