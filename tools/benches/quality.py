"""Map quality without ground truth: the figures of docs/evaluation.md, "Map quality".

``synthetic``: the simulator's demo building (124 s, one loop) scored with its true trajectory
and with the loop opened (a drift of 5° and 1.5 % of scale growing after the midpoint, so the
second pass lays its walls beside the first pass's).

One bench per benchmark log (``intel``, ``aces``, ``fr079``, ``fr-clinic``, ``mit-csail``,
``mit-killian``): ``slam run LOG`` with the default configuration (texture and recording off),
the score it writes to metrics.json, its cost beside the filter's, and, where the log has
relations (mit-killian's re-timed onto its scans), how the per-stretch scores line up with the
relation errors of the same trajectory (:func:`slam.eval.quality.stretch_relation_errors`): a
relation counts for the stretch of each of its ends; "bad" stretches are those with a relation
error above 0.5 m.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path

from benches._util import data_dir, skip

LOGS = ("intel", "aces", "fr079", "fr-clinic", "mit-csail", "mit-killian")
BAD_RELATION_M = 0.5
"""A stretch is "bad" by the relations when one of its relations is off by more than this."""


def _round(value: float | None, digits: int = 4) -> float | None:
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def synthetic() -> dict:
    """Scores of the demo building's true trajectory and of the same trajectory, loop opened."""
    from slam.eval.quality import map_quality, summary
    from slam.sim.fixtures import demo_loop, open_the_loop

    times, truth, rays = demo_loop()
    opened = open_the_loop(truth, len(truth) // 2, 5.0, 1.015)
    out: dict = {"scans": int(len(times))}
    for name, poses in (("truth", truth), ("opened_loop", opened)):
        start = time.perf_counter()
        result = map_quality(times, poses, rays)
        wall = time.perf_counter() - start
        s = summary(result)
        worst = s["worst"][0]
        out[name] = {
            "score": s["score"],
            "worst_score": s["worst_score"],
            "flagged": s["flagged"],
            "judged_stretches": s["judged_stretches"],
            "worst_time_s": worst["time_s"],
            "worst_place_xy": worst["place_xy"],
            "worst_offset_m": worst["offset_m"],
            "wall_s": round(wall, 3),
        }
    return out


def _log_bench(name: str, overrides: tuple[str, ...] = ()) -> dict:
    import numpy as np

    from slam.config import load_config
    from slam.eval.quality import rank_correlation, stretch_relation_errors
    from slam.eval.quality_run import evaluate_run, resolve_run_log
    from slam.eval.relations import relation_errors
    from slam.eval.retime import relations_file
    from slam.io import sources
    from slam.io.registry import get_dataset
    from slam.io.relations import read_relations
    from slam.pipeline import RunRequest, run
    from slam.trajectory import Trajectory

    root = data_dir()
    dataset = get_dataset(name)
    if not dataset.log_file().location(root).is_file():
        return skip(f"{name}: log absent from {root}")
    config = load_config(name, None, ["texture.enabled=false", "viz.record=false", *overrides])
    with tempfile.TemporaryDirectory(prefix="slam-bench-") as tmp:
        start = time.perf_counter()
        folder = run(RunRequest(name=name, config=config, data_dir=root, out=Path(tmp) / "run"))
        run_wall = time.perf_counter() - start
        metrics = json.loads((folder / "metrics.json").read_text())
        report, result = evaluate_run(folder, resolve_run_log(folder, root))
    q = metrics["quality"]
    out: dict = {
        "scans": metrics["scans"],
        "path_length_m": metrics["path_length_m"],
        "score": q["score"],
        "coverage": q["coverage"],
        "median_stretch_score": q["median_stretch_score"],
        "worst_score": q["worst_score"],
        "flagged": q["flagged"],
        "judged_stretches": q["judged_stretches"],
        "stretches": q["stretches"],
        "worst": [
            {k: w[k] for k in ("rank", "time_s", "path_m", "place_xy", "score", "offset_m")}
            for w in q["worst"]
        ],
        "quality_wall_s": q["wall_s"],
        "quality_cpu_s": q["cpu_s"],
        "estimate_wall_s": metrics["estimate_wall_s"],
        "run_wall_s": round(run_wall, 3),
        "quality_share_of_run": round(q["wall_s"] / metrics["wall_s"], 4),
        "quality_cpu_share_of_estimate": round(q["cpu_s"] / metrics["estimate_wall_s"], 4),
        "peak_rss_mb": metrics["peak_rss_mb"],
        "same_as_slam_eval": report["score"] == q["score"],
    }
    # mit-killian's shared copy lost its times: its relations re-timed onto its scans
    path = relations_file(sources.resolve(name, root))
    if path is not None:
        relations = read_relations(path)
        errors = relation_errors(Trajectory(result.times, result.poses), relations)
        per = stretch_relation_errors(result, relations)
        judged = {s.index for s in result.judged()}
        scores = np.array([s.score if s.index in judged else np.nan for s in result.stretches])
        bad = np.nan_to_num(per.max, nan=0.0) > BAD_RELATION_M
        flagged = scores < config.quality.flag_below  # NaN (not judged) compares False
        bad_judged = bad & np.isfinite(scores)
        out["relations"] = {
            "trans_mean": _round(float(errors.trans.mean()), 4),
            "trans_max": _round(float(errors.trans.max()), 3),
            "share_over_0.2m": _round(float((errors.trans > 0.2).mean()), 4),
            "rank_correlation_score_vs_mean_error": _round(rank_correlation(scores, per.mean), 3),
            "bad_stretches": int(bad.sum()),
            "bad_stretches_judged": int(bad_judged.sum()),
            "bad_stretches_flagged": int((bad & flagged).sum()),
            "flagged": int(flagged.sum()),
            "median_score_bad": _round(float(np.nanmedian(scores[bad_judged])), 4)
            if bad_judged.any()
            else None,
            "median_score_other": _round(float(np.nanmedian(scores[~bad])), 4),
        }
    return out


def benches() -> dict:
    """The synthetic check, one bench per benchmark log, and mit-killian without the test of the
    earlier pass (``loops.pass_path = 0``: seed 0 then closes its loop one door along its
    corridors, docs/accuracy.md) — what the score says of a stretch misplaced by 6 m."""
    found = {"synthetic": synthetic}
    for name in LOGS:
        found[name.replace("-", "_")] = lambda name=name: _log_bench(name)
    found["mit_killian_no_pass_test"] = lambda: _log_bench("mit-killian", ("loops.pass_path=0",))
    return found
