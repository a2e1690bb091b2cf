"""Relations whose log lost its times, re-timed onto the log's scans.

The shared MIT Killian Court log was rebuilt with synthetic times (scan ``k`` at ``1e9 + 0.1 k``):
its relations file (Kümmerle et al. 2009) names the original log's times, which match no scan.
Those times are scan times of a laser that scanned at a fixed period, so they can be put back on
the scans in three steps (docs/evaluation.md, "Relations on a log that lost its times"):

1. **The period.** The gaps between the relations' distinct times are whole multiples of the scan
   period: :func:`relation_period` takes it from the shortest gaps, refines it over every gap
   within ``tolerance`` of a whole multiple, and keeps the shortest submultiple for which the
   relations still fit in the log's scans.
2. **The chain.** Each distinct time's scan index, relative to the first time, is the running sum
   of the gaps in periods. A gap that is not within ``tolerance`` of a whole number of periods
   (a long one, over which the period's error adds up) starts a new segment, placed on its own.
3. **The placement.** A segment's offset (the scan index of its first time) is the one at which
   the scans agree with the relations: for up to ``pairs`` of its relations that turn by at least
   ``min_turn`` over a few scans, scan ``j`` is registered onto scan ``i`` with the filter's
   matcher (:func:`slam.calibration.pair_motions`, from the odometry's motion) at every candidate
   offset, and the offset whose registered turns differ least from the relations' (median) wins.
   A turn is what an offset error shows: over a straight stretch every offset gives the same
   relative motion. The runner-up must be ``margin`` times worse, else the segment is left out.

:func:`retime_relations` returns the relations at the log's own scan times and a report of the
evidence; :func:`slam.io.sources.ground_truth_relations` caches the result for registry datasets
whose entry says ``relations_times = "retime"``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from slam.errors import DataError
from slam.geometry import spread_picks, wrap_angle
from slam.io.relations import Relations

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

RETIME_VERSION = 1
"""Bumped whenever the method changes, so that a cached re-timing is made again."""


@dataclass(frozen=True)
class RetimeSettings:
    """How the relations are put back on the scans (module docstring)."""

    tolerance: float = 0.1
    """A gap is a whole number of periods when its quotient is within this of one."""
    min_turn_deg: float = 5.0
    """A relation places its segment when it turns by at least this (°) ..."""
    max_span_scans: int = 20
    """... over at most this many scans."""
    pairs: int = 60
    """At most this many such relations (evenly spread) place a segment."""
    min_pairs: int = 10
    """A segment with fewer registered pairs than this is left out."""
    margin: float = 2.0
    """The winning offset's median turn error must be this many times below the runner-up's."""
    window: int = 2
    """A later segment's offset is searched this many scans either side of where the rounded
    gap puts it."""


@dataclass
class Segment:
    """One run of relation times whose gaps are whole periods, and where it was placed."""

    first: int
    """Index of its first distinct time."""
    count: int
    """Its distinct times."""
    offset: int | None = None
    """Scan index of its first time (None: not placed, its relations left out)."""
    scores: dict[int, float] = field(default_factory=dict)
    """Candidate offset → median turn error (°) of its registered pairs."""
    pairs: int = 0
    """Relations that placed it (registered at the winning offset)."""
    why: str = ""
    """Why it was left out."""

    def as_dict(self) -> dict[str, Any]:
        """The report's entry for this segment."""
        ranked = sorted(self.scores.items(), key=lambda kv: kv[1])
        out: dict[str, Any] = {"first_time_index": self.first, "times": self.count}
        out["offset"] = self.offset
        out["pairs"] = self.pairs
        if ranked:
            out["best_deg"] = round(ranked[0][1], 4)
        if len(ranked) > 1:
            out["runner_up"] = ranked[1][0]
            out["runner_up_deg"] = round(ranked[1][1], 4)
        if self.why:
            out["left_out"] = self.why
        return out


@dataclass(frozen=True)
class Retimed:
    """Relations re-timed onto a log's scans, and the evidence."""

    relations: Relations
    """The relations whose both times were placed, at the log's scan times."""
    period: float
    """The original scan period (s)."""
    segments: list[Segment]
    """The runs of whole-period gaps, each with its offset or why it was left out."""
    kept: I64
    """Rows of the source relations that were placed."""
    scan_index: tuple[I64, I64]
    """``(i, j)`` scan indices of the kept relations."""

    def report(self) -> dict[str, Any]:
        """A JSON-ready summary."""
        return {
            "version": RETIME_VERSION,
            "period_s": round(self.period, 6),
            "relations": int(self.kept.size),
            "segments": [s.as_dict() for s in self.segments],
        }


def _distinct_times(relations: Relations) -> tuple[F64, I64, I64]:
    times, inverse = np.unique(np.concatenate([relations.t1, relations.t2]), return_inverse=True)
    n = len(relations)
    return times, inverse[:n].astype(np.int64), inverse[n:].astype(np.int64)


def relation_period(
    times: F64, scans: int, tolerance: float = 0.1, where: str = "relations"
) -> float:
    """The scan period (s) of which the gaps between the sorted distinct ``times`` are whole
    multiples: the median of the shortest gaps, refined by least squares over every gap within
    ``tolerance`` of a whole multiple, then the shortest submultiple ``P / k`` for which the
    times still span at most ``scans − 1`` periods. :class:`DataError` when the gaps share no
    period, its message starting with ``where`` (the relations file)."""
    gaps = np.diff(np.asarray(times, dtype=np.float64))
    gaps = gaps[gaps > 0]
    if gaps.size < 2:
        raise DataError(f"{where}: fewer than three distinct times, no scan period to read")
    shortest = gaps[gaps <= 1.5 * gaps.min()]
    period = float(np.median(shortest))
    for _ in range(3):  # refine: each gap's quotient, then the period that fits them best
        q = gaps / period
        whole = (np.abs(q - np.round(q)) <= tolerance) & (np.round(q) >= 1)
        if whole.mean() < 0.9:
            raise DataError(
                f"{where}: only {whole.mean():.0%} of the gaps between their times are whole "
                f"multiples of a period near {period:.4f} s (expected at least 90 %): the times "
                "are not scan times of a steady laser"
            )
        period = float(gaps[whole].sum() / np.round(q[whole]).sum())
    span = float(times[-1] - times[0])
    k = 1
    while span / (period / (k + 1)) <= scans - 1:
        k += 1
    if span / (period / k) > scans - 1:
        raise DataError(
            f"{where}: their times span {span:.1f} s, {span / period:.0f} periods of "
            f"{period:.4f} s, more than the log's {scans} scans"
        )
    return period / k


def _segments(times: F64, period: float, tolerance: float) -> tuple[list[Segment], I64]:
    """The segments of the distinct times and each time's index relative to its segment's
    first."""
    q = np.diff(times) / period
    whole = np.round(q).astype(np.int64)
    cut = np.abs(q - whole) > tolerance
    local = np.zeros(times.size, dtype=np.int64)
    segments, start = [], 0
    for k in range(1, times.size):
        if cut[k - 1]:
            segments.append(Segment(first=start, count=k - start))
            start = k
        else:
            local[k] = local[k - 1] + whole[k - 1]
    segments.append(Segment(first=start, count=times.size - start))
    return segments, local


@dataclass(frozen=True)
class _Evidence:
    """What the placement of a segment needs."""

    hits_of: Any
    odometry: F64
    relations: Relations
    config: Any
    settings: RetimeSettings


def _place(segment: Segment, rows: I64, local_i: I64, local_j: I64, candidates: range,
           ev: _Evidence) -> None:  # fmt: skip
    """Score ``candidates`` offsets of ``segment`` on the relations ``rows`` (module docstring,
    step 3) and set its offset, or why it was left out."""
    from slam.calibration import CalibrationSettings, pair_motions

    st = ev.settings
    if rows.size < st.min_pairs:  # a straight stretch: every offset gives the same motions
        segment.why = f"{rows.size} turning relations (expected at least {st.min_pairs})"
        return
    yaw = ev.relations.yaw[rows]
    n = ev.odometry.shape[0]
    fitted: dict[int, int] = {}
    for offset in candidates:
        i, j = local_i + offset, local_j + offset
        if i.min() < 0 or j.max() >= n:
            continue
        pairs = np.stack([i, j], axis=1).astype(np.int64)
        motions, kept = pair_motions(
            ev.hits_of, ev.odometry, pairs, ev.config, CalibrationSettings()
        )
        if kept.size < st.min_pairs:
            continue
        error = np.degrees(np.abs(wrap_angle(motions[:, 2] - yaw[kept])))
        segment.scores[offset] = float(np.median(error))
        fitted[offset] = int(kept.size)
    if not segment.scores:
        segment.why = f"fewer than {st.min_pairs} turning relations registered at any offset"
        return
    ranked = sorted(segment.scores.items(), key=lambda kv: kv[1])
    if len(ranked) > 1 and ranked[1][1] < st.margin * max(ranked[0][1], 1e-9):
        segment.why = (
            f"offsets {ranked[0][0]} and {ranked[1][0]} fit almost as well "
            f"({ranked[0][1]:.3f}° and {ranked[1][1]:.3f}°)"
        )
        return
    segment.offset, segment.pairs = ranked[0][0], fitted[ranked[0][0]]


def retime_relations(
    relations: Relations,
    log_times: F64,
    odometry: F64,
    hits_of: Any,
    config: Any,
    settings: RetimeSettings | None = None,
) -> Retimed:
    """Put ``relations`` (times of the original log) on the scans of a log whose times were
    lost (module docstring). ``log_times`` ``(N,)`` and ``odometry`` ``(N, 3)`` are the log's
    scans' times and odometry poses in file order, ``hits_of(k)`` scan ``k``'s returns in the
    robot frame, ``config`` the log's :class:`slam.config.Config` (the matcher's settings).
    :class:`DataError`, naming the relations file, when their times share no period or no
    segment can be placed."""
    st = settings or RetimeSettings()
    where = str(relations.source) if relations.source is not None else "relations"
    times, ti, tj = _distinct_times(relations)
    n = int(np.asarray(log_times).shape[0])
    period = relation_period(times, n, st.tolerance, where)
    segments, local = _segments(times, period, st.tolerance)
    seg_of = np.zeros(times.size, dtype=np.int64)
    for s, segment in enumerate(segments):
        seg_of[segment.first : segment.first + segment.count] = s
    ev = _Evidence(hits_of, np.asarray(odometry, dtype=np.float64), relations, config, st)
    span_scans = np.round((relations.t2 - relations.t1) / period)
    turning = (np.abs(np.degrees(relations.yaw)) >= st.min_turn_deg) & (
        span_scans <= st.max_span_scans
    )
    # the whole chain as if every cut were a whole gap: how far the first segment can sit
    nominal_span = int(np.round((times[-1] - times[0]) / period))
    previous_end: tuple[int, float] | None = None  # (scan index, time) of the last placed time
    for s, segment in enumerate(segments):
        within = np.flatnonzero(turning & (seg_of[ti] == s) & (seg_of[tj] == s))
        if previous_end is None:
            slack = len(segments) - 1
            candidates = range(0, max(0, n - 1 - nominal_span) + slack + 1)
        else:
            guess = previous_end[0] + int(round((times[segment.first] - previous_end[1]) / period))
            candidates = range(guess - st.window, guess + st.window + 1)
        if within.size > st.pairs:
            within = within[spread_picks(within.size, st.pairs)]
        _place_rows(segment, within, local, ti, tj, candidates, ev)
        if segment.offset is not None:
            last = segment.first + segment.count - 1
            previous_end = (segment.offset + int(local[last]), float(times[last]))
    index = np.full(times.size, -1, dtype=np.int64)
    for segment in segments:
        if segment.offset is not None:
            sl = slice(segment.first, segment.first + segment.count)
            index[sl] = local[sl] - local[segment.first] + segment.offset
    if not any(s.offset is not None for s in segments):
        why = "; ".join(f"segment {k}: {s.why}" for k, s in enumerate(segments))
        raise DataError(
            f"{where}: no segment of the relations' times could be placed on the log's scans "
            f"({why})"
        )
    i, j = index[ti], index[tj]
    kept = np.flatnonzero((i >= 0) & (j >= 0) & (i < n) & (j < n))
    log_times = np.asarray(log_times, dtype=np.float64)
    out = Relations(
        t1=log_times[i[kept]],
        t2=log_times[j[kept]],
        x=relations.x[kept],
        y=relations.y[kept],
        yaw=relations.yaw[kept],
        source=relations.source,
    )
    return Retimed(out, period, segments, kept.astype(np.int64), (i[kept], j[kept]))


def _place_rows(segment: Segment, rows: I64, local: I64, ti: I64, tj: I64, candidates: range,
                ev: _Evidence) -> None:  # fmt: skip
    """:func:`_place` on the relations ``rows``, their indices relative to the segment's first
    time."""
    base = int(local[segment.first])
    _place(segment, rows, local[ti[rows]] - base, local[tj[rows]] - base, candidates, ev)


def format_relations(relations: Relations) -> str:
    """``relations`` as a relations file's text (``t1 t2 x y z roll pitch yaw``, z, roll and
    pitch 0), every float written exactly."""
    lines = [
        f"{a!r} {b!r} {x!r} {y!r} 0.0 0.0 0.0 {yaw!r}"
        for a, b, x, y, yaw in zip(
            relations.t1.tolist(),
            relations.t2.tolist(),
            relations.x.tolist(),
            relations.y.tolist(),
            relations.yaw.tolist(),
            strict=True,
        )
    ]
    return "\n".join(lines) + "\n"


def relations_file(ref: Any, progress: bool = False) -> Path | None:
    """The relations file to evaluate a run of the dataset ``ref`` (a
    :class:`slam.io.sources.DatasetRef`) with: ``None`` when it has none (or it is absent), its
    own file when its times are the log's, else the re-timed copy in the cache
    (``<cache>/relations/<name>.retimed.relations``, with its report beside it as ``.json``),
    made on first use (a few seconds) and made again when the relations, the log or the method
    changed. :class:`DataError` when the relations cannot be re-timed."""
    import json

    from slam.io import sources
    from slam.io.atomic import write_files
    from slam.io.datadir import resolve_cache_dir
    from slam.io.relations import read_relations

    if ref.relations is None or not ref.relations.is_file():
        return None
    if not ref.relations_retime:
        return ref.relations
    folder = resolve_cache_dir() / "relations"
    out, report_path = folder / f"{ref.name}.retimed.relations", folder / f"{ref.name}.retimed.json"
    log_path = _log_file(ref)
    stamp = {
        "version": RETIME_VERSION,
        "relations_sha256": _sha256(ref.relations),
        "log_sha256": _sha256(log_path),
    }
    if out.is_file() and report_path.is_file():
        try:
            old = json.loads(report_path.read_text())
        except (OSError, ValueError):
            old = {}
        if all(old.get(k) == v for k, v in stamp.items()):
            return out
    if progress:
        print(f"slam: re-timing {ref.relations.name} onto the scans of {log_path.name} ...")
    config = _matching_config(ref)
    scans = _all_scans(sources.load(ref, config, ("scans",)).log, config)
    retimed = retime_relations(
        read_relations(ref.relations),
        scans.times,
        np.asarray(scans.odometry, dtype=np.float64),
        lambda k: scans.scan(k).hits(),
        config,
    )
    report = {**stamp, "source": str(ref.relations), "log": str(log_path), **retimed.report()}
    folder.mkdir(parents=True, exist_ok=True)
    write_files(
        {
            out: format_relations(retimed.relations).encode(),
            report_path: (json.dumps(report, indent=2) + "\n").encode(),
        }
    )
    return out


def _log_file(ref: Any) -> Path:
    from slam.io.registry import get_dataset

    return ref.data_dir / get_dataset(ref.name).log_file().path


def _sha256(path: Path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _matching_config(ref: Any) -> Any:
    """The log's configuration with every scan kept and the odometry at the scans' times."""
    from slam.config import load_config

    whole = ["filter.every=1", "filter.max_scans=0", 'robot.odometry_sync="scan"']
    return load_config(ref.config_name, None, whole)


def _all_scans(log: Any, config: Any) -> Any:
    import warnings

    from slam.scans import LogScans

    with warnings.catch_warnings():  # the selection's own notes (sparse scans) do not apply
        warnings.simplefilter("ignore")
        return LogScans.from_log(log, config)
