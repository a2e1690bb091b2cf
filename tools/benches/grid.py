"""Grid-localization benches: the 1000×1000 × 4-heading histogram filter and the default study.

* ``heading_1000x1000`` — a 1000×1000 colour world (4 colours, 5 % obstacles, bounded) with 4
  headings per cell (4 million states): predict + update steps per second, both as the fused
  one-pass cycle (``HistogramFilter.step``) and as separate ``predict`` then ``update`` calls.
  Actions cycle forward / left / forward / right; observations are drawn beforehand.
* ``study_default`` — wall time of ``slam grid study`` with its default settings.
"""

from __future__ import annotations

import time

import numpy as np
from benches._util import best_of


def _heading_world():
    from slam.discrete.world import GridWorld

    rng = np.random.default_rng(0)
    labels = rng.integers(0, 4, size=(1000, 1000)).astype(np.int16)
    blocked = rng.random((1000, 1000)) < 0.05
    return GridWorld(labels, blocked, ("blue", "green", "red", "white"), False, 4)


def heading_1000x1000() -> dict:
    """Steps per second of the exact filter on 4 million (cell, heading) states."""
    from slam.discrete.filter import HistogramFilter
    from slam.discrete.motion import HeadingMotion
    from slam.discrete.sensors import ColourSensor

    world = _heading_world()
    bayes = HistogramFilter(world, ColourSensor(0.9), HeadingMotion(0.9, 0.9))
    rng = np.random.default_rng(1)
    steps = 30
    actions = [(0, 1, 0, 2)[k % 4] for k in range(steps)]
    observations = rng.integers(0, 4, size=steps).tolist()
    start = time.perf_counter()
    for z in range(4):
        bayes.likelihood(z)
    bayes.step(0, 0)
    bayes.step(1, 1)
    bayes.predict(0)
    bayes.predict(1)
    bayes.update(0)
    warmup = time.perf_counter() - start

    def fused() -> None:
        for a, z in zip(actions, observations, strict=True):
            bayes.step(a, z)

    def separate() -> None:
        for a, z in zip(actions, observations, strict=True):
            bayes.predict(a)
            bayes.update(z)

    fused_s, _ = best_of(fused, 3)
    separate_s, _ = best_of(separate, 3)
    return {
        "states": int(np.prod(world.belief_shape)),
        "steps": steps,
        "fused_steps_per_s": round(steps / fused_s, 1),
        "separate_steps_per_s": round(steps / separate_s, 1),
        "warmup_s": round(warmup, 2),
        "total_after_run": float(bayes.belief.sum()),
    }


def study_default() -> dict:
    """Run time of the default ``slam grid study`` (without writing the plot)."""
    from slam.discrete.study import StudyConfig, run_study

    config = StudyConfig()
    start = time.perf_counter()
    rows = run_study(config)
    seconds = time.perf_counter() - start
    trials = len(config.sizes) * len(config.errors) * config.trials
    return {
        "trials": trials,
        "seconds": round(seconds, 2),
        "ms_per_trial": round(1000 * seconds / trials, 2),
        "localized_trials": sum(r.localized for r in rows),
    }


def benches() -> dict:
    """The grid benches."""
    return {"heading_1000x1000": heading_1000x1000, "study_default": study_default}
