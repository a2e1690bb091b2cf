"""Recording of ``slam localize``: the map, the particles and the histogram posterior.

Timelines ``scan`` and ``time`` as in ``slam run`` recordings (:mod:`slam.viz.recorder`).
Entities:

==============================  =============================================  ==================
entity                          content                                        rows
==============================  =============================================  ==================
``world``                       transform flipping y (+y up on screen)          static
``world/map``                   ``Image``: the map localized in                 static
``world/trajectory/live``       ``LineStrips2D``: segment previous → current    one per scan
``world/robot``                 ``Arrows2D``: the pose estimate                 one per scan
``world/particles``             ``Points2D`` coloured by weight                 every
                                                                               ``detail_every``
                                                                               scans (tracking)
``world/histogram``             ``Image`` (RGBA): the histogram filter's        every histogram
                                posterior over cells (summed over headings) as  step
                                a heat map over the map, transparent off the
                                states; cleared when MCL takes over
``world/trajectory/final``      ``LineStrips2D``: the whole trajectory          once, at the end
``metrics/particles``           ``Scalars``                                     one per scan
``metrics/quality``             ``Scalars``: match quality (0..1)               one per scan
``metrics/localized``           ``Scalars``: 1 localized, 0 not                 one per scan
==============================  =============================================  ==================

Per-scan rows are buffered and sent as columns when the run ends (a localization recording is
written, not watched live).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from slam.config import VizConfig
from slam.localize.histogram import PoseHistogram
from slam.localize.maps import LikelihoodMap
from slam.viz import blueprint as bp
from slam.viz.grid import heat_map
from slam.viz.images import PlacedImage, occupancy_image
from slam.viz.recorder import log_placed, log_track_styles, send_track, weight_colours
from slam.viz.stream import close_stream, open_stream, set_time

F64 = NDArray[np.float64]

HISTOGRAM = "world/histogram"
PARTICLE_COUNT = "metrics/particles"
QUALITY = "metrics/quality"
LOCALIZED = "metrics/localized"


def localize_blueprint() -> rrb.Blueprint:
    """The map view (map, heat map, particles, trajectory) beside the three time series."""
    map_view = rrb.Spatial2DView(
        name="map", origin="/", contents=["+ /world/**"], overrides=bp.history(bp.TRAJECTORY)
    )
    series = rrb.Vertical(
        *(
            rrb.TimeSeriesView(name=name, origin=f"/{path}", axis_x=bp.whole_run())
            for name, path in (
                ("particles", PARTICLE_COUNT),
                ("match quality", QUALITY),
                ("localized", LOCALIZED),
            )
        )
    )
    layout = rrb.Horizontal(map_view, series, column_shares=[3, 2])
    return rrb.Blueprint(
        layout,
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="scan", play_state="following"),
    )


def posterior_image(histogram: PoseHistogram) -> PlacedImage:
    """The histogram's posterior over cells as an RGBA heat map placed on the map (states
    opaque-ish, everything else transparent)."""
    posterior = histogram.posterior()
    rgb = heat_map(posterior, ~histogram.states)
    rgba = np.empty(rgb.shape[:2] + (4,), dtype=np.uint8)
    rgba[..., :3] = rgb
    rgba[..., 3] = np.where(histogram.states, 170, 0)
    origin = histogram.map.origin
    return PlacedImage(rgba, (float(origin[0]), float(origin[1])), histogram.resolution)


class LocalizeRecorder:
    """Writes ``recording.rrd`` of a localization run (see the module docstring)."""

    def __init__(self, path: Path, config: VizConfig, lmap: LikelihoodMap, name: str) -> None:
        self.path = Path(path)
        self.config = config
        self.rec = open_stream(self.path, name=name, blueprint=localize_blueprint())
        rec = self.rec
        rec.log(bp.WORLD, bp.world_flip(), static=True)
        image = occupancy_image(lmap.grid, config.map_levels)
        if image is not None:
            log_placed(rec, bp.MAP, image, draw_order=0.0, static=True)
        log_track_styles(
            rec,
            ((PARTICLE_COUNT, "particles"), (QUALITY, "match quality"), (LOCALIZED, "localized")),
        )
        self._rows: list[tuple[float, ...]] = []
        self.steps = 0
        self.particle_sets = 0
        self.heat_maps = 0
        self._heat_shown = False

    def on_step(
        self,
        step: int,
        time_s: float,
        pose: F64,
        particles: int,
        quality: float,
        localized: bool,
        particle_poses: F64 | None = None,
        weights: F64 | None = None,
        histogram: PoseHistogram | None = None,
    ) -> None:
        """One scan: buffered rows; particles (``particle_poses``/``weights``) and the
        histogram's heat map (``histogram``, when it stepped) are logged right away."""
        self._rows.append(
            (step, time_s, *pose[:3], particles, quality if math.isfinite(quality) else 0.0,
             1.0 if localized else 0.0)
        )  # fmt: skip
        self.steps += 1
        if particle_poses is not None and weights is not None:
            set_time(self.rec, step, time_s)
            self.rec.log(
                bp.PARTICLES,
                rr.Points2D(particle_poses[:, :2], colors=weight_colours(weights)),
            )
            self.particle_sets += 1
        if histogram is not None:
            set_time(self.rec, step, time_s)
            log_placed(self.rec, HISTOGRAM, posterior_image(histogram), draw_order=10.0)
            self.heat_maps += 1
            self._heat_shown = True
        elif self._heat_shown and particles > 0 and localized:
            set_time(self.rec, step, time_s)
            self.rec.log(HISTOGRAM, rr.Clear(recursive=False))
            self._heat_shown = False

    def finish(self, poses: F64) -> dict[str, Any]:
        """Send the buffered rows and the final trajectory, close the file; return figures for
        ``metrics.json``."""
        rec = self.rec
        if self._rows:
            rows = np.asarray(self._rows, dtype=np.float64)
            send_track(rec, rows, None, ((PARTICLE_COUNT, 5), (QUALITY, 6), (LOCALIZED, 7)))
            set_time(rec, int(rows[-1, 0]), float(rows[-1, 1]))
            rec.log(bp.TRAJECTORY_FINAL, rr.LineStrips2D([np.asarray(poses)[:, :2]]))
        close_stream(rec)
        out: dict[str, Any] = {
            "steps": self.steps,
            "particle_sets": self.particle_sets,
            "heat_maps": self.heat_maps,
        }
        if self.path.is_file():
            out["file"] = self.path.name
            out["size_mb"] = round(self.path.stat().st_size / 2**20, 2)
        return out
