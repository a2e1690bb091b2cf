"""Localization on a saved map (``slam localize``): the figures of docs/localize.md.

Every bench localizes a CARMEN log on the map that ``slam run`` builds from it (default
configuration, seed 0; built in a temporary folder, or taken from ``$SLAM_BENCH_MAPS/<log>`` when
that names a folder of such runs) and compares the poses with that run's own trajectory, the
map's frame (scan by scan in the log's order: ``trajectory_file_order.tum`` when the log's clock
runs backwards; relation errors match times, from ``trajectory.tum`` as ``slam eval`` does):

* ``tracking_<log>``: from the true start pose (the SLAM trajectory's first pose, σ 0.1 m /
  0.05 rad): relation error (Kümmerle et al.) beside the SLAM run's own, speed (wall and CPU time
  of the localizer, real-time factor), memory; then 20 starts (5 seeded start times × 4
  directions) with the initial pose off by 1 m and 20°: how many converge within 10 s of log time
  (localized, and within 0.3 m / 5° of the SLAM pose for the next 5 s).
* ``cross_run_intel``: intel localized over its second half on the map built from its first half
  (``--max-scans 6815``), starting from that run's last pose; relation error over the relations
  of the second half, beside the full SLAM run's over the same relations.
* ``global_<log>``: 20 seeded start times without an initial pose: success (within 0.3 m / 5° of
  the SLAM pose 30 s of log time after convergence), wrong first convergences and whether they
  stayed wrong, distance driven and time to converge, histogram steps and their duration.
* ``kidnap_intel``: two distant stretches of intel spliced (the pose jumps, the odometry does
  not): time until the localizer declares itself lost, until it is localized again.
* ``histogram_step_intel``: one histogram filter step (predict + update) over intel's map at
  0.25 m × 36 headings: wall (median, min) and CPU time, states, memory.

The machine may be shared: wall times are contended figures, CPU times less so; accuracy
figures are deterministic for the seed.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from benches._util import data_dir, skip

LOGS = ("intel", "aces", "fr079")
TOLERANCE_M = 0.3
TOLERANCE_DEG = 5.0


@contextmanager
def _map_run(name: str, extra: tuple[str, ...] = (), label: str = ""):
    """The folder of ``slam run NAME`` (default configuration, seed 0, no texture/recording)."""
    cached = os.environ.get("SLAM_BENCH_MAPS")
    folder = Path(cached) / (label or name) if cached else None
    if folder is not None and (folder / "map.npz").is_file():
        yield folder
        return
    from slam.config import load_config
    from slam.pipeline import RunRequest, run

    config = load_config(name, None, ["texture.enabled=false", "viz.record=false", *extra])
    with tempfile.TemporaryDirectory(prefix="slam-bench-map-") as tmp:
        out = Path(tmp) / (label or name)
        run(RunRequest(name=name, config=config, data_dir=data_dir(), out=out))
        yield out


def _scans(name: str, config):
    from slam.io import sources
    from slam.scans import LogScans

    ref = sources.resolve(name, data_dir())
    return LogScans.from_log(sources.load(ref, config, ("scans",)).log, config)


def _relation_summary(times, poses, relations) -> dict:
    from slam.eval.relations import relation_errors
    from slam.trajectory import Trajectory

    s = relation_errors(Trajectory(times, poses), relations).summary()
    return {
        "trans_mean": round(s["trans_mean"], 4),
        "trans_std": round(s["trans_std"], 4),
        "rot_mean_deg": round(s["rot_mean_deg"], 3),
        "relations": s["count"],
    }


def _file_order(folder: Path):
    """The SLAM run's trajectory in the log's scan order (``trajectory_file_order.tum`` when the
    log's clock runs backwards and ``trajectory.tum`` is sorted by time, as on intel), so that
    pose ``k`` is the pose of scan ``k``."""
    from slam.io.tum import read_tum

    path = folder / "trajectory_file_order.tum"
    return read_tum(path if path.is_file() else folder / "trajectory.tum")


def _errors(poses, truth):
    from slam.geometry import relative

    e = relative(truth, poses)
    return np.hypot(e[:, 0], e[:, 1]), np.rad2deg(np.abs(e[:, 2]))


def _relations(name: str):
    from slam.io.registry import get_dataset
    from slam.io.relations import read_relations

    return read_relations(data_dir() / get_dataset(name).relations)


def _available(name: str) -> str | None:
    from slam.io.registry import get_dataset

    path = data_dir() / get_dataset(name).log_file().path
    return None if path.is_file() else f"{path} is absent"


def _converged_at(trace, truth, start_time: float, hold_s: float = 5.0) -> float | None:
    """Log time (from the start) after which the pose is localized and within tolerance for
    ``hold_s`` seconds."""
    err, deg = _errors(trace.poses, truth)
    good = trace.localized & (err <= TOLERANCE_M) & (deg <= TOLERANCE_DEG)
    times = trace.times
    bad_after = np.full(len(good), np.inf)
    last_bad = np.inf
    for i in range(len(good) - 1, -1, -1):  # next bad time at or after i
        if not good[i]:
            last_bad = times[i]
        bad_after[i] = last_bad
    for i in np.flatnonzero(good):
        if bad_after[i] - times[i] >= hold_s or bad_after[i] == np.inf:
            return float(times[i] - start_time)
    return None


def _tracking(name: str) -> dict:
    reason = _available(name)
    if reason:
        return skip(reason)
    from slam.config import load_config
    from slam.io.tum import read_tum
    from slam.localize.localizer import Localizer
    from slam.localize.maps import load_map
    from slam.localize.run import LocalizeRequest, localize, run_localizer

    relations = _relations(name)
    out: dict = {"log": name}
    with _map_run(name) as folder, tempfile.TemporaryDirectory(prefix="slam-bench-") as tmp:
        out["slam"] = _relation_summary(*read_tum(folder / "trajectory.tum"), relations)
        slam_trajectory = _file_order(folder)
        first = slam_trajectory.poses[0]
        settings = ["viz.record=false", "localize.initial_sigma_theta=0.05"]
        config = load_config(name, None, settings)
        initial = (*first, 0.1)
        warm = load_config(name, None, [*settings, "filter.max_scans=300"])
        localize(LocalizeRequest(name, folder, warm, data_dir(), initial, Path(tmp) / "warm"))
        run = localize(LocalizeRequest(name, folder, config, data_dir(), initial, Path(tmp) / "t"))
        m = json.loads((run / "metrics.json").read_text())
        loc = read_tum(run / "trajectory.tum")
        out["localize"] = _relation_summary(*loc, relations)
        ratio = out["localize"]["trans_mean"] / out["slam"]["trans_mean"]
        out["trans_ratio_to_slam"] = round(ratio, 3)
        err, deg = _errors(_file_order(run).poses, slam_trajectory.poses)  # pose k: scan k
        out["pose_vs_slam"] = {
            "median_m": round(float(np.median(err)), 4),
            "p95_m": round(float(np.percentile(err, 95)), 4),
            "median_deg": round(float(np.median(deg)), 3),
        }
        for key in ("scans", "duration_s", "estimate_wall_s", "estimate_cpu_s", "scans_per_s",
                    "real_time_factor", "localized_share", "mean_match_quality",
                    "particles_mean", "mcl_updates", "lost_events", "relocalizations",
                    "map_memory_mb", "peak_rss_mb"):  # fmt: skip
            out[key] = m[key]
        out["real_time_factor_cpu"] = round(m["duration_s"] / m["estimate_cpu_s"], 1)
        # initial pose off by 1 m and 20°, from 5 start times × 4 directions
        lmap = load_map(folder)
        scans = _scans(name, load_config(name))
        rng = np.random.default_rng(0)
        times = scans.times
        last = int(np.searchsorted(times, times[-1] - 40.0))
        starts = sorted(int(s) for s in rng.integers(0, last, 5))
        runs = []
        for s in starts:
            stop = int(np.searchsorted(times, times[s] + 40.0))
            for k in range(4):
                truth = slam_trajectory.poses[s]
                direction = truth[2] + k * math.pi / 2
                guess = truth + np.array([math.cos(direction), math.sin(direction),
                                          math.radians(20.0 if k % 2 == 0 else -20.0)])  # fmt: skip
                localizer = Localizer(lmap, load_config(name), initial=guess, seed=s + k)
                items = [(scans.scan(i), scans.odometry[i]) for i in range(s, stop)]
                trace = run_localizer(localizer, items)
                at = _converged_at(trace, slam_trajectory.poses[s:stop], float(times[s]))
                moving = float(np.hypot(*(scans.odometry[stop - 1, :2] - scans.odometry[s, :2])))
                runs.append({"start": s, "direction": k, "converged_s": at,
                             "moved_m": round(moving, 2)})  # fmt: skip
        within = [r for r in runs if r["converged_s"] is not None and r["converged_s"] <= 10.0]
        conv = [r["converged_s"] for r in runs if r["converged_s"] is not None]
        out["offset_1m_20deg"] = {
            "runs": len(runs),
            "converged_within_10s": len(within),
            "converged": len(conv),
            "median_s": round(float(np.median(conv)), 2) if conv else None,
            "max_s": round(float(np.max(conv)), 2) if conv else None,
            "not_within_10s": [r for r in runs if r not in within],
        }
    return out


def _cross_run() -> dict:
    reason = _available("intel")
    if reason:
        return skip(reason)
    from slam.config import load_config
    from slam.io.tum import read_tum
    from slam.localize.localizer import Localizer
    from slam.localize.maps import load_map
    from slam.localize.run import run_localizer

    half = 6815
    relations = _relations("intel")
    with (
        _map_run("intel", (f"filter.max_scans={half}",), "intel-half") as half_run,
        _map_run("intel") as full_run,
    ):
        config = load_config("intel")
        scans = _scans("intel", config)
        half_trajectory = _file_order(half_run)
        full = read_tum(full_run / "trajectory.tum")
        start = half - 1
        initial = (*half_trajectory.poses[start], 0.1)
        localizer = Localizer(load_map(half_run), config, initial=initial)
        items = [(scans.scan(i), scans.odometry[i]) for i in range(start, len(scans))]
        trace = run_localizer(localizer, items)
        t0 = float(scans.times[start])
        keep = (relations.t1 >= t0) & (relations.t2 >= t0)
        from slam.io.relations import Relations

        second = Relations(
            relations.t1[keep], relations.t2[keep], relations.x[keep], relations.y[keep],
            relations.yaw[keep],
        )  # fmt: skip
        return {
            "map_scans": half,
            "localized_scans": len(items),
            "localize": _relation_summary(trace.times, trace.poses, second),
            "slam_full_run_same_relations": _relation_summary(*full, second),
            "localized_share": round(float(trace.localized.mean()), 4),
            "lost_events": int(trace.lost.sum()),
            "relocalizations": localizer.counters["reseeds"],
        }


def _global(name: str, count: int = 20, max_s: float = 300.0, after_s: float = 30.0) -> dict:
    reason = _available(name)
    if reason:
        return skip(reason)
    from slam.config import load_config
    from slam.localize.localizer import Localizer
    from slam.localize.maps import load_map

    with _map_run(name) as folder:
        slam_poses = _file_order(folder).poses
        lmap = load_map(folder)
        config = load_config(name)
        scans = _scans(name, config)
    times = scans.times
    rng = np.random.default_rng(0)
    starts = sorted(
        int(s) for s in rng.integers(0, np.searchsorted(times, times[-1] - max_s), count)
    )
    runs = []
    for s in starts:
        localizer = Localizer(lmap, config, seed=s)
        converged = first_error = end_error = None
        step_wall, step_cpu = [], []
        k = s
        while k < len(scans):
            before = localizer.counters["histogram_steps"]
            wall, cpu = time.perf_counter(), time.process_time()
            est = localizer.update(scans.scan(k), scans.odometry[k])
            if localizer.counters["histogram_steps"] != before and est.phase != "tracking":
                step_wall.append(time.perf_counter() - wall)
                step_cpu.append(time.process_time() - cpu)
            err, deg = _errors(est.pose[None], slam_poses[k][None])
            if converged is None and est.phase == "tracking":
                converged, first_error = k, (float(err[0]), float(deg[0]))
            if converged is not None and times[k] - times[converged] >= after_s:
                end_error = (float(err[0]), float(deg[0]))
                break
            if times[k] - times[s] > max_s:
                break
            k += 1
        ok = lambda e: e is not None and e[0] <= TOLERANCE_M and e[1] <= TOLERANCE_DEG  # noqa: E731
        driven = (
            float(np.sum(np.hypot(*np.diff(slam_poses[s : converged + 1, :2], axis=0).T)))
            if converged is not None else None
        )  # fmt: skip
        runs.append({
            "start": s,
            "converged_after_s": None if converged is None else round(float(times[converged] - times[s]), 2),
            "driven_m": None if driven is None else round(driven, 2),
            "first_ok": ok(first_error),
            "success": ok(end_error),
            "first_error": None if first_error is None else [round(v, 3) for v in first_error],
            "end_error": None if end_error is None else [round(v, 3) for v in end_error],
            "histogram_steps": localizer.counters["histogram_steps"],
            "relocalizations": localizer.counters["reseeds"],
            "step_wall_ms": round(1000 * float(np.median(step_wall)), 1) if step_wall else None,
            "step_cpu_ms": round(1000 * float(np.median(step_cpu)), 1) if step_cpu else None,
        })  # fmt: skip
    driven = [r["driven_m"] for r in runs if r["driven_m"] is not None]
    after = [r["converged_after_s"] for r in runs if r["converged_after_s"] is not None]
    wrong = [r for r in runs if r["converged_after_s"] is not None and not r["first_ok"]]
    return {
        "log": name,
        "starts": len(runs),
        "success": sum(r["success"] for r in runs),
        "success_rate": round(sum(r["success"] for r in runs) / len(runs), 3),
        "first_convergence_correct": sum(r["first_ok"] for r in runs),
        "wrong_first_convergences": len(wrong),
        "wrong_and_stayed": sum(not r["success"] for r in wrong),
        "median_driven_m": round(float(np.median(driven)), 2) if driven else None,
        "median_time_s": round(float(np.median(after)), 2) if after else None,
        "max_time_s": round(float(np.max(after)), 2) if after else None,
        "histogram_states": localizer.histogram.state_count,
        "histogram_memory_mb": round(localizer.histogram.memory_bytes() / 2**20, 1),
        "median_step_wall_ms": round(float(np.median([r["step_wall_ms"] for r in runs if r["step_wall_ms"]])), 1),
        "median_step_cpu_ms": round(float(np.median([r["step_cpu_ms"] for r in runs if r["step_cpu_ms"]])), 1),
        "runs": runs,
    }  # fmt: skip


def _kidnap() -> dict:
    reason = _available("intel")
    if reason:
        return skip(reason)
    from slam.config import load_config
    from slam.localize.localizer import Localizer
    from slam.localize.maps import load_map
    from slam.localize.run import run_localizer, splice

    first, second = (500, 2500), (9500, 11500)
    with _map_run("intel") as folder:
        slam_poses = _file_order(folder).poses
        lmap = load_map(folder)
    config = load_config("intel")
    scans = _scans("intel", config)
    items = splice(scans, first, second)
    localizer = Localizer(lmap, config, initial=(*slam_poses[first[0]], 0.1))
    trace = run_localizer(localizer, items)
    truth = np.concatenate([slam_poses[first[0] : first[1]], slam_poses[second[0] : second[1]]])
    n = first[1] - first[0]
    jump = float(trace.times[n])
    lost = np.flatnonzero(trace.lost[n:])
    recovered = _converged_at(
        type(trace)(*(getattr(trace, f)[n:] for f in trace.__dataclass_fields__)), truth[n:], jump
    )
    err, deg = _errors(trace.poses, truth)
    return {
        "first_scans": list(first),
        "second_scans": list(second),
        "jump_m": round(float(np.hypot(*(slam_poses[second[0], :2] - slam_poses[first[1] - 1, :2]))), 2),
        "jump_deg": round(abs(math.degrees(math.remainder(
            slam_poses[second[0], 2] - slam_poses[first[1] - 1, 2], 2 * math.pi))), 1),
        "noticed_after_s": round(float(trace.times[n + lost[0]] - jump), 2) if lost.size else None,
        "recovered_after_s": None if recovered is None else round(recovered, 2),
        "false_lost_before_jump": int(trace.lost[:n].sum()),
        "end_error": [round(float(err[-1]), 3), round(float(deg[-1]), 3)],
        "relocalizations": localizer.counters["reseeds"],
    }  # fmt: skip


def _histogram_step() -> dict:
    reason = _available("intel")
    if reason:
        return skip(reason)
    from slam.config import load_config
    from slam.geometry import relative
    from slam.localize.histogram import PoseHistogram
    from slam.localize.maps import load_map
    from slam.localize.mcl import MotionModel
    from slam.localize.sensor import BeamModel

    config = load_config("intel")
    c = config.localize
    with _map_run("intel") as folder:
        lmap = load_map(folder)
    scans = _scans("intel", config)
    motion = MotionModel(
        np.asarray(config.filter.motion_alphas), np.asarray(config.filter.motion_floor)
    )
    hist = PoseHistogram(lmap, c, motion)
    model = BeamModel(c.z_hit, c.z_rand, c.z_max, c.sigma_hit, scans.range_max)
    picks = list(range(2000, 2600, 6))

    def hits(i):
        ex, ey = scans.scan(i).hits()
        keep = np.linspace(0, ex.size - 1, min(c.global_beams, ex.size)).round().astype(int)
        return ex[keep], ey[keep]

    hist.update(*hits(picks[0]), model)  # warm-up: compile and likelihood grids
    hist.predict(relative(scans.odometry[picks[0]], scans.odometry[picks[1]]))
    wall, cpu = [], []
    for a, b in zip(picks[:-1], picks[1:], strict=True):
        inc = relative(scans.odometry[a], scans.odometry[b])
        ex, ey = hits(b)
        w, p = time.perf_counter(), time.process_time()
        hist.predict(inc)
        hist.update(ex, ey, model)
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - p)
    import numba

    return {
        "resolution_m": hist.resolution,
        "headings": hist.headings,
        "free_cells": int(hist.free_r.size),
        "states": hist.state_count,
        "beams": c.global_beams,
        "steps": len(wall),
        "step_wall_ms_median": round(1000 * float(np.median(wall)), 2),
        "step_wall_ms_min": round(1000 * float(np.min(wall)), 2),
        "step_cpu_ms_median": round(1000 * float(np.median(cpu)), 2),
        "numba_threads": numba.get_num_threads(),
        "memory_mb": round(hist.memory_bytes() / 2**20, 1),
    }  # fmt: skip


def _with_load(bench):
    """``bench`` with the machine's 1-minute load average before and after it (the machine may
    be shared: the wall times are read against it)."""

    def run() -> dict:
        before = os.getloadavg()[0]
        out = bench()
        if "skipped" not in out:
            out["load_average"] = [round(before, 2), round(os.getloadavg()[0], 2)]
        return out

    return run


def benches() -> dict:
    """The localization benches."""
    out = {f"tracking_{name}": (lambda n=name: _tracking(n)) for name in LOGS}
    out["cross_run_intel"] = _cross_run
    out.update({f"global_{name}": (lambda n=name: _global(n)) for name in LOGS})
    out["kidnap_intel"] = _kidnap
    out["histogram_step_intel"] = _histogram_step
    return {name: _with_load(bench) for name, bench in out.items()}
