"""Recording of ``slam grid run``: the posterior heat map after every step.

Timeline ``step`` (0-based index of the scenario step). Entities:

* ``grid/posterior`` — ``Image`` (RGB): the posterior over cells (summed over headings) as a
  heat map scaled to the step's largest probability (dark blue 0 → yellow max), obstacles
  black; one row per step. Image row 0 is the world's top (north) row, as in the scenario file.
* ``grid/world`` — ``Image`` (RGB, static): the cell colours, drawn to the right of the posterior;
* ``metrics/max_probability`` — ``Scalars``: the largest cell probability, one row per step;
* ``log/steps`` — ``TextLog``: what each step did (``sense red``, ``move N``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import rerun as rr
from numpy.typing import NDArray

from slam.discrete.scenario import RunResult
from slam.io.atomic import atomic_path
from slam.viz.blueprint import grid_blueprint
from slam.viz.images import as_image
from slam.viz.stream import close_stream, open_stream

POSTERIOR = "grid/posterior"
WORLD = "grid/world"
MAX_PROBABILITY = "metrics/max_probability"
STEPS = "log/steps"

_NAMED = {
    "red": (220, 50, 50),
    "green": (60, 170, 60),
    "blue": (50, 90, 220),
    "yellow": (235, 210, 40),
    "white": (245, 245, 245),
    "black": (30, 30, 30),
    "orange": (240, 150, 20),
    "purple": (140, 60, 170),
    "cyan": (40, 200, 210),
    "grey": (150, 150, 150),
    "gray": (150, 150, 150),
}


def heat_map(posterior: NDArray[np.float64], blocked: NDArray[np.bool_]) -> NDArray[np.uint8]:
    """``(R, C, 3)`` RGB heat map of ``posterior`` (viridis, scaled to its maximum)."""
    peak = float(posterior.max())
    scaled = posterior / peak if peak > 0 else posterior
    grey = np.round(255.0 * np.clip(scaled, 0.0, 1.0)).astype(np.uint8)
    bgr = cv2.applyColorMap(grey, cv2.COLORMAP_VIRIDIS)
    rgb = np.ascontiguousarray(bgr[..., ::-1])
    rgb[blocked] = 0
    return rgb


def world_colours(
    labels: NDArray[np.int16], palette: tuple[str, ...], blocked
) -> NDArray[np.uint8]:
    """``(R, C, 3)`` RGB picture of the cells' colours (unknown names get distinct greys)."""
    table = np.zeros((len(palette) + 1, 3), dtype=np.uint8)
    table[-1] = (200, 200, 200)  # open cell without a colour (label -1)
    for i, name in enumerate(palette):
        grey = 80 + (150 * i) // max(len(palette), 1)
        table[i] = _NAMED.get(name.lower(), (grey, grey, grey))
    rgb = table[np.asarray(labels)]
    rgb[np.asarray(blocked)] = 0
    return np.ascontiguousarray(rgb)


def _write_grid(result: RunResult, path: Path, recording_id: str | None = None) -> int:
    """Log the recording of a grid run to ``path``; return the number of steps logged."""
    scenario = result.scenario
    world = scenario.world
    rec = open_stream(
        Path(path),
        name=f"slam grid run {scenario.name}",
        recording_id=recording_id,
        blueprint=grid_blueprint(),
    )
    cols = world.shape[1]
    rec.log(
        WORLD,
        rr.Transform3D(translation=[cols + 1.0, 0.0, 0.0]),
        as_image(world_colours(world.labels, world.palette, world.blocked)),
        static=True,
    )
    rec.log(MAX_PROBABILITY, rr.SeriesLines(names="max probability"), static=True)
    for record in result.steps:
        posterior = record.posterior
        rec.set_time("step", sequence=record.index)
        rec.log(POSTERIOR, as_image(heat_map(posterior, world.blocked)))
        rec.log(MAX_PROBABILITY, rr.Scalars(float(posterior.max())))
        rec.log(STEPS, rr.TextLog(f"{record.after} {record.action}"))
    close_stream(rec, Path(path))
    return len(result.steps)


def record_grid_run(result: RunResult, path: Path, recording_id: str | None = None) -> int:
    """Write the recording of a grid run to ``path`` atomically (it appears whole or not at
    all); return the number of steps logged. ``recording_id`` fixes the id (reproducible files)."""
    with atomic_path(Path(path)) as tmp:
        return _write_grid(result, tmp, recording_id)
