"""Write the back end's regression references (``data/reference/backend/``).

Each case is a piece of a real log's filter output: the nodes (update scans and poses of the
best particle's ancestry, as :meth:`slam.particle_filter.RbpfFilter.finish` hands them over) on
one or two stretches of path. The back end (:func:`slam.backend.global_loops.close_loops_global`)
runs on those nodes alone, so the test needs no filter run: it reads the log's scans from
``$SLAM_DATA_DIR``, the stored nodes, and checks the relation errors between nodes
(:mod:`tests.test_backend_regression`). Stored per case: ``<case>.npz`` (node scan numbers and
poses) and ``<case>.json`` (the figures with the local loop closing only and with the back end).

    SLAM_DATA_DIR=../shared/data uv run python tools/make_backend_reference.py

The filter output of each (case's log file, seed) is cached in ``$SLAM_CACHE_DIR/backend/`` (a
full filter run per log, minutes); ``--filter-output DIR`` reads ``<log>-<seed>.npz`` (a case
with its own recording: ``<file name>-<seed>.npz``) from ``DIR`` instead. A case reads the benchmark's CARMEN log unless it names another recording of
the same run in the data directory (a ROS bag: the same scans and times, so the relations hold).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
REFERENCE_DIR = ROOT / "data" / "reference" / "backend"

CASES = {
    # the first return to the start corridor after 470 m, ≈1 m off: beyond the local search
    "fr-clinic-return": ("fr-clinic", 1, [(0.0, 80.0), (440.0, 520.0)]),
    # intel's first loops: closed by the local search today, must stay closed
    "intel-start": ("intel", 0, [(0.0, 120.0)]),
    # fr079's first loops (odometry leads the laser in turns)
    "fr079-start": ("fr079", 1, [(0.0, 120.0)]),
    # aces' ROS bag, seed 1: the first large loop comes back to the start 1.9 m off, where the
    # local search closes a wrong loop; the global search must still look (docs/accuracy.md,
    # "Odometry a few per cent off")
    "aces-bag-return": ("aces", 1, [(0.0, 40.0), (140.0, 200.0)], "carmen/bags/aces.orig.bag"),
    # aces, seed 4, every node: global closures that fit as well a metre along a corridor
    # (3-6 m wrong) pulled the first large loop's return to the start 0.7 m off (docs/accuracy.md,
    # "Closures that could be a metre elsewhere"); a stretch alone does not show it
    "aces-seed4": ("aces", 4, [(0.0, None)]),
}


def log_path(data_dir: Path, log: str) -> Path:
    """The CARMEN file of ``log`` in the data directory."""
    name = "mit-killian-synthtime" if log == "mit-killian" else log
    return data_dir / "carmen" / f"{name}.clf.gz"


def case_path(data_dir: Path, name: str) -> Path:
    """The log file case ``name`` reads: its own recording, or its log's CARMEN file."""
    log, _, _, *source = CASES[name]
    return data_dir / source[0] if source else log_path(data_dir, log)


def load_scans(data_dir: Path, log: str, path: Path | None = None, overrides=()):
    """``(config, ScanSequence)`` of the whole log (its file ``path``, default the CARMEN
    file), as ``slam run`` feeds it; ``overrides`` (``section.key=value``) change the log's
    configuration."""
    from slam.config import load_config
    from slam.io import sources
    from slam.pipeline import _needs
    from slam.scans import LogScans, ScanSequence

    config = load_config(log, overrides=list(overrides))
    ref = sources.resolve(str(path or log_path(data_dir, log)), data_dir)
    src = sources.load(ref, config, _needs(config), False, None)
    seq = ScanSequence()
    for scan, odometry in LogScans.from_log(src.log, config):
        seq.append(scan.resolved(config.lidar), odometry)
    return config, seq


def filter_output(data_dir: Path, log: str, seed: int, cache: Path, path: Path | None = None):
    """``(steps, node_poses)`` of the filter on ``log`` (its file ``path``, default the CARMEN
    file) with ``seed`` (cached in ``cache``)."""
    carmen = log_path(data_dir, log)
    path = path or carmen
    file = cache / (f"{log}-{seed}.npz" if path == carmen else f"{path.name}-{seed}.npz")
    if not file.is_file():
        from slam.config import load_config
        from slam.io import sources
        from slam.online import Slam
        from slam.pipeline import _needs
        from slam.scans import LogScans

        config = load_config(log, overrides=[f"filter.seed={seed}"])
        ref = sources.resolve(str(path), data_dir)
        scans = LogScans.from_log(
            sources.load(ref, config, _needs(config), False, None).log, config
        )
        slam = Slam(config, stages=[], scan_period=scans.scan_period())
        for scan, odometry in scans:
            slam.update(scan, odometry=odometry)
        out = slam._filter.finish()
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(file, steps=out.steps, node_poses=out.node_poses)
    with np.load(file) as z:
        return z["steps"].astype(np.int64), z["node_poses"].astype(np.float64)


def piece(steps, poses, stretches) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nodes on the given path stretches (``(start, end)`` m; negative from the end), with
    their distance along the whole trajectory."""
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))])
    keep = np.zeros(len(path), dtype=bool)
    for lo, hi in stretches:
        lo = lo if lo >= 0 else path[-1] + lo
        hi = path[-1] if hi is None else hi
        keep |= (path >= lo) & (path <= hi)
    return steps[keep], poses[keep], path[keep]


def node_errors(seq, steps, poses, relations) -> dict:
    """Relation errors between nodes: every relation whose two times are node scans."""
    from slam.eval.relations import relation_errors
    from slam.trajectory import Trajectory

    traj = Trajectory(seq.times[steps].copy(), poses, steps.copy())
    e = relation_errors(traj, relations)
    return {
        "relations": int(e.trans.size),
        "trans_mean": round(float(e.trans.mean()), 4),
        "trans_max": round(float(e.trans.max()), 4),
        "rot_mean_deg": round(float(np.degrees(e.rot).mean()), 3),
    }


def evaluate(data_dir: Path, name: str, steps, poses, path, scans=None, overrides=()) -> dict:
    """The case's figures: filter nodes, local loop closing only, and the back end (with the
    configuration ``overrides``, when ``scans`` are not given)."""
    from slam.backend.global_loops import close_loops_global
    from slam.graph import close_loops
    from slam.io.relations import read_relations

    log = CASES[name][0]
    config, seq = scans or load_scans(data_dir, log, case_path(data_dir, name), overrides)
    relations = read_relations(data_dir / "carmen" / "relations" / f"{log}.relations")
    local = close_loops(seq, steps, poses, config).poses
    result = close_loops_global(seq, steps, poses, config, path)
    return {
        "nodes": int(len(steps)),
        "filter": node_errors(seq, steps, poses, relations),
        "local_only": node_errors(seq, steps, local, relations),
        "backend": node_errors(seq, steps, result.poses, relations),
        "loop_closures": int(result.accepted),
    }


def main() -> int:
    """Write every case's reference."""
    from slam.io.datadir import resolve_cache_dir, resolve_data_dir

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--filter-output", type=Path, default=None)
    parser.add_argument("cases", nargs="*", default=sorted(CASES))
    args = parser.parse_args()
    data_dir = resolve_data_dir()
    cache = args.filter_output or resolve_cache_dir() / "backend"
    REFERENCE_DIR.mkdir(parents=True, exist_ok=True)
    for name in args.cases:
        log, seed, stretches, *source = CASES[name]
        nodes = filter_output(data_dir, log, seed, cache, case_path(data_dir, name))
        steps, poses, path = piece(*nodes, stretches)
        figures = evaluate(data_dir, name, steps, poses, path)
        np.savez_compressed(REFERENCE_DIR / f"{name}.npz", steps=steps, node_poses=poses, path=path)
        head = {"log": log, "seed": seed, "stretches_m": stretches}
        if source:
            head["file"] = source[0]
        text = json.dumps({**head, **figures}, indent=2)
        (REFERENCE_DIR / f"{name}.json").write_text(text + "\n")
        print(name, json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
