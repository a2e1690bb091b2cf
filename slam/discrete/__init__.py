"""Grid-world localization: the Bayes filter on a finite state space, computed exactly.

The particle filter of :mod:`slam.particle_filter` and this histogram filter are the same Bayes
filter over a robot state ``x``:

* predict:    ``bel⁻(x') = Σ_x p(x' | x, u) · bel(x)``        (motion model, action ``u``)
* update:     ``bel(x)  = η · p(z | x) · bel⁻(x)``              (sensor model, observation ``z``)
* normalize:  ``η = 1 / Σ_x p(z | x) · bel⁻(x)``

The particle filter approximates ``bel`` with samples of a continuous pose; here the state space
is finite — a cell of a grid, or a (cell, heading) pair — so the sums are computed exactly over
every state, as array shifts and element-wise products.

Modules:

* :mod:`~slam.discrete.world` — grids of labelled cells, obstacles, cyclic or walled borders, and
  the shift / step / translate primitives every model is built from;
* :mod:`~slam.discrete.sensors` — colour sensor, confusion matrix, W/N/E/S obstacle bits;
* :mod:`~slam.discrete.motion` — exact/undershoot/overshoot, moves-with-p-else-stays, commanded
  direction with drift and bounce-back, unknown heading, (cell, heading) motion;
* :mod:`~slam.discrete.filter` — ``predict``, ``update``, ``normalize``, the stopping rule, and the
  :class:`~slam.discrete.filter.HistogramFilter`;
* :mod:`~slam.discrete.kernels` — numba one-pass kernels of the (cell, heading) prediction;
* :mod:`~slam.discrete.scenario` — scenario TOML files, the Udacity test vectors, step-by-step runs;
* :mod:`~slam.discrete.study` and :mod:`~slam.discrete.plot` — ``slam grid study``.
"""

from slam.discrete.filter import (
    HistogramFilter,
    ImpossibleObservation,
    localized,
    marginal,
    normalize,
    predict,
    update,
)
from slam.discrete.motion import (
    DriftMotion,
    HeadingMotion,
    MoveOrStay,
    ShiftMotion,
    UnknownHeading,
)
from slam.discrete.scenario import (
    RunResult,
    Scenario,
    StepRecord,
    load_scenario,
    load_udacity_cases,
    resolve_scenario,
    run_scenario,
)
from slam.discrete.sensors import ColourSensor, ConfusionSensor, WnesSensor
from slam.discrete.world import GridWorld, random_colour_world, world_from_rows

__all__ = [
    "ColourSensor",
    "ConfusionSensor",
    "DriftMotion",
    "GridWorld",
    "HeadingMotion",
    "HistogramFilter",
    "ImpossibleObservation",
    "MoveOrStay",
    "RunResult",
    "Scenario",
    "ShiftMotion",
    "StepRecord",
    "UnknownHeading",
    "WnesSensor",
    "load_scenario",
    "load_udacity_cases",
    "localized",
    "marginal",
    "normalize",
    "predict",
    "random_colour_world",
    "resolve_scenario",
    "run_scenario",
    "update",
    "world_from_rows",
]
