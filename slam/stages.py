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
4. :class:`FinalMap` — the occupancy grid of the node scans at their final poses (:func:`build_map`).

``rbpf`` runs all four (:func:`default_stages`); ``classic`` none (its filter outputs every
scan's pose and its own map). A stage is anything with a ``name`` and a ``run(output, config)``
method (:class:`Stage`), so a caller can drop, reorder or add stages.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from slam.config import Config
from slam.geometry import relative, spread_corrections
from slam.mapping import OccupancyGrid, likelihood_tables
from slam.particle_filter import (
    FilterOutput,
    hits_for_insert,
    integrate_scan,
    particle_maps,
)
from slam.scans import ScanSequence

F64 = NDArray[np.float64]


class Stage(Protocol):
    """One step from the filter's output towards the final trajectory and map."""

    name: str
    """Short name (for messages and timings)."""

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Return the output with this stage applied (the input is not modified)."""


class LoopClosing:
    """Close loops over the nodes with a pose graph (``[loops]``; skipped when disabled)."""

    name = "loop closing"

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Optimise the node poses; the stats get the candidates, closures and correction."""
        if not config.loops.enabled or len(output.steps) <= 1:
            return output
        from slam.backend.global_loops import close_loops_global
        from slam.graph import close_loops

        close = close_loops_global if config.backend.global_search else close_loops
        closed = close(output.scans, output.steps, output.node_poses, config)
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
        for _ in range(config.rbpf.refine_passes):
            poses = refine_trajectory(output.scans, poses, output.steps, config)
        return dataclasses.replace(output, node_poses=poses)


class BetweenUpdates:
    """Place every scan: the nodes at their poses, the scans between them by odometry."""

    name = "between-update placement"

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """Every scan's pose (:func:`interpolate_between_updates`)."""
        poses = interpolate_between_updates(output.scans, output.steps, output.node_poses)
        return dataclasses.replace(output, poses=poses)


class FinalMap:
    """The occupancy grid of the node scans at their final poses (after :class:`BetweenUpdates`)."""

    name = "final map"

    def run(self, output: FilterOutput, config: Config) -> FilterOutput:
        """The grid (:func:`build_map`)."""
        if output.poses is None:
            raise ValueError("final map: the scans have no poses yet (run BetweenUpdates first)")
        grid = build_map(output.scans, output.poses, output.steps, config)
        return dataclasses.replace(output, grid=grid)


def default_stages(config: Config) -> list[Stage]:
    """The stages a run of ``config.filter.method`` goes through after its filter."""
    if config.filter.method == "rbpf":
        return [LoopClosing(), Reregistration(), BetweenUpdates(), FinalMap()]
    return []


def run_stages(output: FilterOutput, stages: list[Stage], config: Config) -> FilterOutput:
    """Apply ``stages`` in order."""
    for stage in stages:
        output = stage.run(output, config)
    return output


def build_map(
    seq: ScanSequence, poses: F64, steps: NDArray[np.int64], config: Config
) -> OccupancyGrid:
    """Occupancy grid of the scans ``steps`` of ``seq`` taken at ``poses[steps]``."""
    grid = OccupancyGrid(config.map, center=(float(poses[0, 0]), float(poses[0, 1])))
    span = np.concatenate([poses[:, :2].min(axis=0) - 1.0, poses[:, :2].max(axis=0) + 1.0])
    grid.ensure_contains(*span)
    for k in steps:
        integrate_scan(grid, seq, int(k), poses[k])
    return grid.cropped(config.map.crop_margin_m)


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


def refine_trajectory(
    seq: ScanSequence, poses: F64, steps: NDArray[np.int64], config: Config
) -> F64:
    """Re-register the scans ``steps`` (taken at ``poses``) against the map they build together.

    The filter's lineage carries the jitter of the proposal's sampling (that is what gives the
    filter the diversity to close loops); with the best lineage chosen, one map is built from its
    scans and each of them is registered against that map again, which keeps the global shape and
    removes the jitter. Returns the refined poses ``(len(steps), 3)``.
    """
    rc = config.rbpf
    maps = particle_maps(config, poses[0], 1)
    reach = 0.0
    for pose, k in zip(poses, steps, strict=True):
        hx, hy, nx, ny = hits_for_insert(seq, int(k), rc.insert_beams, maps.signed)
        if hx.size == 0:
            continue
        reach = max(reach, float(np.sqrt((hx * hx + hy * hy).max())))
        r = reach + rc.dmax + 1.0
        maps.ensure_contains(pose[0] - r, pose[1] - r, pose[0] + r, pose[1] + r)
        maps.insert(np.ascontiguousarray(pose[None, :]), hx, hy, nx, ny, rc.skip_insert_below)
    width = max(1, min(rc.match_beams or seq.num_beams, seq.num_beams))
    ex = np.zeros((len(steps), width))
    ey = np.zeros((len(steps), width))
    counts = np.zeros(len(steps), dtype=np.int64)
    for i, k in enumerate(steps):
        hx, hy = seq.hits(int(k), width)
        counts[i] = hx.size
        ex[i, : hx.size] = hx
        ey[i, : hy.size] = hy
    luts = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    return maps.register(
        poses, ex, ey, counts, luts, rc.max_iterations, rc.tolerance, rc.min_inliers,
        coarse_stride=rc.coarse_stride,
    )  # fmt: skip
