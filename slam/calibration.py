"""How a log's odometry relates to its laser, and how good the laser is, measured from the log
itself (no ground truth).

Things a log may state wrongly or not at all, and that the scans can check:

**When the odometry was taken** (:func:`synchronise_odometry`, run by ``slam run`` when
``robot.odometry_sync = "auto"``). A CARMEN log gives every scan an odometry pose, and also the
stream of ``ODOM`` messages. The pose written with a scan is often the last ``ODOM`` message
before it, held (aces: 7215 of 7374 scans; 0.02–0.2 s stale), or the stream runs ahead of or
behind the laser (fr079: about 0.14 s). Either puts the odometry's turns at the wrong scans, which
the filter must then undo. Candidates: the pose written with each scan, and the stream
interpolated at each scan's time plus a lag in ``±max_lag`` (``lag_step`` apart). For evenly
spread pairs of consecutive scans, the rotation between them is measured by the filter's own
matcher (scan ``j`` registered onto a one-scan distance field of scan ``i``; a pair whose beams do
not fit is dropped: :func:`pair_motions`) and compared with each candidate's rotation; the
candidate with the smallest trimmed RMS disagreement wins, a stream candidate only when it beats
the written poses by ``min_gain``. Logs whose stream times cannot be trusted keep their written
poses by that rule (intel's ``ODOM`` times are arrival times of bursts and go backwards 808
times; interpolating them disagrees with the laser more than the written poses do).

**Which angles the shorter scans have** (:func:`measure_beam_step`, run when a CARMEN log loads
with ``lidar.measure_beam_step``). ``FLASER`` lines carry no angles; a log that mixes scans of
``n`` and ``n − 1`` readings (a SICK LMS's interlaced sweeps: fr-clinic's 180 and 181) may have
the shorter ones spread over the field of view or one step apart between the longer one's beams.
Pairs of consecutive scans are matched as above under each candidate (:func:`check_beam_geometry`);
the geometry whose rotations agree best with the odometry's is the log's, and when that is one
step apart and centred the log is read with that ``lidar.beam_step_deg``.

**How much the laser's readings scatter** (:func:`range_noise`, run by the smoothing stage after
the filter, :class:`slam.stages.OdometrySmoothing`): the second differences of neighbouring
readings on flat surfaces are noise alone; a laser noisier than ``rbpf.smooth_noise_ref`` has its
registered poses trusted that many times less against the odometry (:func:`noise_multiple`).

**Where the laser sits** (:func:`calibrate_mount`, reported by ``slam data calibrate``, never
applied by itself): for pairs of scans between which the odometry turned, the laser's motion
``A`` (matched as above) and the odometry's ``B`` obey ``A = L⁻¹ ⊕ B ⊕ L`` with ``L`` the laser's
pose on the robot, which is linear in ``(x, y, cos yaw, sin yaw)``; a trimmed least-squares fit
gives ``L`` and a bootstrap its spread. What it measures is the laser against the odometry's
reference point; a log's ground truth may be expressed at either (docs/accuracy.md, "The laser's
mount"), so the estimate is printed beside what the log states, for the user to decide.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from slam.config import Config
from slam.geometry import interpolate_poses, relative, spread_picks, wrap_angle
from slam.kernels.field import match_one
from slam.kernels.graph import fit_counts
from slam.kernels.threads import in_threads, threads
from slam.mapping import ParticleMaps, likelihood_tables

F64 = NDArray[np.float64]
HitsOf = Callable[[int], tuple[F64, F64]]
"""Robot-frame (or laser-frame) returns ``(ex, ey)`` of scan ``k``."""


@dataclass(frozen=True)
class CalibrationSettings:
    """Which scan pairs the measurements use, and how they are weighed."""

    pairs: int = 1000
    """Pairs of consecutive scans the odometry synchronisation compares, evenly spread."""
    max_lag: float = 0.3
    """The stream is tried from this far before each scan to this far after it (s)."""
    lag_step: float = 0.02
    """... in steps of this (s)."""
    min_gain: float = 0.1
    """A stream candidate replaces the poses written with the scans only when its disagreement
    with the laser is at least this share smaller."""
    trim: float = 0.05
    """Share of the pairs with the largest disagreement left out of the comparison."""
    min_turn: float = 0.1
    """The mount's pairs: odometry rotation at least this (rad) ..."""
    max_dt: float = 3.0
    """... within this time (s) ..."""
    max_step: float = 1.0
    """... and this odometry translation (m)."""
    mount_pairs: int = 600
    """At most this many mount pairs, evenly spread over the log."""
    mount_trim: float = 0.2
    """Share of the mount pairs with the largest residuals dropped in the hand-eye fit."""
    bootstrap: int = 100
    """Bootstrap resamplings of the mount pairs for the estimate's spread (seeded)."""
    max_range: float = 20.0
    """Returns farther than this (m) are not matched (far returns carry the matcher's noise)."""
    min_fit: float = 0.6
    """A pair counts when this share of scan ``j``'s returns lands within ``fit_distance``."""
    fit_distance: float = 0.1
    """See ``min_fit`` (m)."""


def pair_motions(
    hits_of: HitsOf,
    odometry: F64,
    pairs: NDArray[np.int64],
    config: Config,
    settings: CalibrationSettings,
    match_beams: int = 0,
) -> tuple[F64, NDArray[np.int64]]:
    """The motions ``(K', 3)`` from scan ``i`` to scan ``j`` of the ``pairs`` that fit, in the
    frame ``hits_of`` gives the returns in (scan ``j`` registered onto a one-scan distance field
    of scan ``i`` by the filter's matcher, from the odometry's motion), and which pairs those are
    (rows of ``pairs``). ``match_beams``: at most this many of scan ``j``'s returns (evenly
    spread; 0: all) are matched, the field keeping every return of scan ``i``. Ranges of pairs
    are matched on the kernel threads (:func:`slam.kernels.threads.in_threads`); the result
    does not depend on their number."""
    cuts = np.linspace(0, len(pairs), 4 * threads() + 1).round().astype(np.int64)
    work = partial(_pair_range, config=config, settings=settings, match_beams=match_beams)
    parts = in_threads(
        [
            partial(work, hits_of, odometry, pairs, int(a), int(b))
            for a, b in zip(cuts[:-1], cuts[1:], strict=True)
            if b > a
        ]
    )
    motions = [m for part, _ in parts for m in part]
    kept = [k for _, part in parts for k in part]
    return np.array(motions).reshape(-1, 3), np.array(kept, dtype=np.int64)


def _pair_range(
    hits_of: HitsOf,
    odometry: F64,
    pairs: NDArray[np.int64],
    first: int,
    stop: int,
    config: Config,
    settings: CalibrationSettings,
    match_beams: int = 0,
) -> tuple[list[F64], list[int]]:
    """:func:`pair_motions` for rows ``first`` to ``stop - 1`` of ``pairs``."""
    rc, lc = config.rbpf, config.loops
    luts, step_inv = likelihood_tables(np.asarray(rc.sigmas), rc.z_hit, rc.z_rand, rc.dmax)
    iterations = rc.max_iterations * lc.match_iteration_factor
    motions, kept = [], []
    for row in range(first, stop):
        i, j = pairs[row]
        hx, hy = _near(hits_of(int(i)), settings.max_range)
        ex, ey = _near(hits_of(int(j)), settings.max_range)
        if hx.size < lc.min_beams or ex.size < lc.min_beams:
            continue
        if match_beams and ex.size > match_beams:  # evenly spread, as Scan.hits thins
            pick = spread_picks(ex.size, match_beams)
            ex, ey = np.ascontiguousarray(ex[pick]), np.ascontiguousarray(ey[pick])
        maps = ParticleMaps(
            1, rc.resolution or config.map.resolution, rc.dmax, tile=rc.tile,
            size_m=2.0 * settings.max_range + 2.0, capacity=256,
        )  # fmt: skip
        reach = float(np.sqrt((hx * hx + hy * hy).max())) + rc.dmax + 1.0
        maps.insert_scans(
            np.zeros((1, 3)), np.vstack([hx, hy]), np.array([0, hx.size]), np.array([reach]), 0.0
        )
        view = maps.field(0)
        start = relative(odometry[i], odometry[j])
        found, _, _ = match_one(view, start, ex, ey, luts, step_inv, iterations, rc.tolerance, 1)
        _, close = fit_counts(view, found, ex, ey, settings.fit_distance)
        if close >= settings.min_fit * ex.size:
            motions.append(found)
            kept.append(row)
    return motions, kept


def _near(hits: tuple[F64, F64], max_range: float) -> tuple[F64, F64]:
    ex, ey = hits
    keep = ex * ex + ey * ey <= max_range * max_range
    return np.ascontiguousarray(ex[keep]), np.ascontiguousarray(ey[keep])


# --- when the odometry was taken -------------------------------------------------------------


@dataclass(frozen=True)
class OdometrySync:
    """Which odometry :func:`synchronise_odometry` chose, and why."""

    source: str
    """``"scan"`` (the poses written with the scans) or ``"stream"`` (the odometry messages
    interpolated at each scan's time plus ``lag_s``)."""
    lag_s: float
    """The stream's lag (s; 0 for ``"scan"``): negative reads the stream before the scan."""
    disagreement_deg: float
    """Trimmed RMS difference between the laser's and the chosen odometry's rotation over the
    compared pairs (degrees)."""
    scan_disagreement_deg: float
    """The same for the poses written with the scans."""
    stream_lag_s: float
    """The stream's best lag (s), chosen or not."""
    stream_disagreement_deg: float
    """The disagreement of the stream at that lag (degrees)."""
    pairs: int
    """Pairs of consecutive scans compared (those whose match fitted)."""
    written: bool = True
    """Whether the log writes a pose with each scan (CARMEN); else (a bag, raw CARMEN scans)
    the first candidate, ``"scan"``, is the stream at the scans' own times, and a choice of it
    is reported as ``"stream"`` at lag 0."""

    def as_dict(self) -> dict[str, float | int | str]:
        """The choice as plain values (for ``metrics.json``)."""
        out = dataclasses.asdict(self)
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in out.items()}


def _trimmed_rms(d: F64, trim: float) -> float:
    """RMS of ``|d|`` without its largest ``trim`` share (at least one value kept)."""
    d = np.sort(np.abs(d))
    d = d[: max(1, int(round((1.0 - trim) * d.size)))]
    return float(np.sqrt(np.mean(d * d)))


def _consecutive_pairs(n: int, count: int) -> NDArray[np.int64]:
    """``(K, 2)`` pairs ``(k, k + 1)`` of ``n >= 2`` scans, at most ``count``, evenly spread."""
    starts = np.unique(np.linspace(0, n - 2, min(count, n - 1)).round().astype(np.int64))
    return np.c_[starts, starts + 1]


def _disagreement(first: F64, second: F64, laser_turn: F64, trim: float) -> float:
    """Trimmed RMS (degrees) of the rotation from poses ``first`` to ``second`` minus
    ``laser_turn``, pair by pair."""
    turn = relative(first, second)[:, 2]
    return float(np.degrees(_trimmed_rms(wrap_angle(turn - laser_turn), trim)))


def stream_at(stream_times: F64, stream_poses: F64, times: F64) -> F64:
    """The odometry stream interpolated at ``times`` (messages sorted by time first; times
    outside the stream hold its end poses)."""
    order = np.argsort(stream_times, kind="stable")
    return interpolate_poses(stream_times[order], stream_poses[order], times)


def synchronise_odometry(
    hits_of: HitsOf,
    times: F64,
    written: F64,
    stream: tuple[F64, F64],
    config: Config,
    settings: CalibrationSettings | None = None,
) -> tuple[F64, OdometrySync]:
    """The odometry at each scan that agrees best with the laser (module docstring): ``written``
    ``(N, 3)`` are the poses written with the scans at ``times``, ``stream`` the log's odometry
    messages ``(times, poses)``, ``hits_of`` the scans' returns. Returns the chosen ``(N, 3)``
    poses and the choice."""
    settings = settings or CalibrationSettings()
    n = len(times)
    pairs = _consecutive_pairs(n, settings.pairs)
    laser, kept = pair_motions(hits_of, written, pairs, config, settings)
    pairs = pairs[kept]
    if len(pairs) < 10:  # too little to judge by: keep what the log says
        nan = float("nan")
        return written, OdometrySync("scan", 0.0, nan, nan, nan, nan, len(pairs))
    i, j = pairs[:, 0], pairs[:, 1]
    at_scan = _disagreement(written[i], written[j], laser[:, 2], settings.trim)
    steps = int(round(settings.max_lag / settings.lag_step))
    best_lag, best = 0.0, np.inf
    for lag in np.arange(-steps, steps + 1) * settings.lag_step:
        first = stream_at(stream[0], stream[1], times[i] + lag)
        second = stream_at(stream[0], stream[1], times[j] + lag)
        value = _disagreement(first, second, laser[:, 2], settings.trim)
        if value < best - 1e-12:
            best_lag, best = float(lag), value
    best_lag = round(best_lag, 6)
    if best <= (1.0 - settings.min_gain) * at_scan:
        poses = stream_at(stream[0], stream[1], times + best_lag)
        return poses, OdometrySync("stream", best_lag, best, at_scan, best_lag, best, len(pairs))
    return written, OdometrySync("scan", 0.0, at_scan, at_scan, best_lag, best, len(pairs))


class Disagreement(NamedTuple):
    """How far a log's odometry moves between consecutive scans from where the matcher puts the
    second scan (:func:`odometry_disagreement`): trimmed RMS differences in the robot's frame at
    the first scan, NaN when nothing was measured."""

    along: float
    """Along the robot's heading (m): how far the two disagree on the distance driven."""
    across: float
    """Across the heading (m): a differential drive does not move sideways, so this is the
    smaller one wherever the matcher sees walls on either side."""
    heading: float
    """In heading (rad)."""
    pairs: int
    """The pairs of consecutive scans that fitted (0: nothing measured)."""


def odometry_disagreement(
    hits_of: HitsOf,
    odometry: F64,
    config: Config,
    settings: CalibrationSettings | None = None,
) -> Disagreement:
    """How far the odometry's motion between consecutive scans is from the matcher's: trimmed
    RMS (``trim``) of the differences along and across the robot's heading (m) and in heading
    (rad) over ``pairs`` evenly spread pairs, and the pairs that fitted. It holds the matcher's
    own noise too, so it bounds the odometry's error from above; measured per axis, as the
    smoothing weighs each (docs/accuracy.md, "The odometry's disagreement along and across the
    heading"). Scan ``j`` of a pair is matched with at most ``rbpf.register_beams`` of its
    returns, as the registration that the smoothing weighs against the odometry matches a scan
    (:func:`pair_motions`)."""
    settings = settings or CalibrationSettings()
    nothing = Disagreement(float("nan"), float("nan"), float("nan"), 0)
    n = odometry.shape[0]
    if n < 2:
        return nothing
    pairs = _consecutive_pairs(n, settings.pairs)
    beams = config.rbpf.register_beams  # scan j matched as the registration matches a scan
    laser, kept = pair_motions(hits_of, odometry, pairs, config, settings, beams)
    if len(kept) == 0:
        return nothing
    pairs = pairs[kept]
    odo = relative(odometry[pairs[:, 0]], odometry[pairs[:, 1]])  # both in scan i's robot frame
    return Disagreement(
        _trimmed_rms(laser[:, 0] - odo[:, 0], settings.trim),
        _trimmed_rms(laser[:, 1] - odo[:, 1], settings.trim),
        _trimmed_rms(wrap_angle(laser[:, 2] - odo[:, 2]), settings.trim),
        len(kept),
    )


RANGE_NOISE_SCANS = 2000
"""At most this many scans (evenly spread) measure the laser's range noise."""

HALF_NORMAL_RMS = 0.37770
"""RMS of the smaller half of ``|X|`` for a standard normal ``X`` (``√(1 − 2aφ(a)/(2Φ(a) − 1))``
at the median ``a = 0.6745``): what :func:`range_noise` divides by."""


def noise_picks(n: int) -> NDArray[np.int64]:
    """Which of ``n`` scans :func:`noise_multiple` reads: at most :data:`RANGE_NOISE_SCANS`,
    evenly spread."""
    return spread_picks(n, min(n, RANGE_NOISE_SCANS)) if n else np.zeros(0, dtype=np.int64)


def noise_multiple(ranges: F64, reference: float) -> tuple[float, float, int]:
    """How much less a registered pose is trusted than with a laser that scatters by
    ``reference`` (``rbpf.smooth_noise_ref``; 0: off): the range noise of ``ranges`` (the scans
    :func:`noise_picks` chose, :func:`range_noise`) over ``reference``, at least 1; that noise
    (NaN when off or unmeasurable, the multiple then 1) and the triples it rests on."""
    if reference <= 0:
        return 1.0, float("nan"), 0
    noise, triples = range_noise(ranges)
    if not np.isfinite(noise):
        return 1.0, noise, triples
    return max(1.0, noise / reference), noise, triples


def range_noise(ranges: F64, near: float = 0.5, far: float = 3.0) -> tuple[float, int]:
    """The laser's range noise (m) read from its own scans ``ranges`` ``(S, B)`` (beam order,
    NaN where no reading), and how many triples it rests on.

    Three neighbouring readings on a flat surface seen about head-on lie on a line, so the
    second difference ``r₍ᵢ₋₁₎ − 2rᵢ + r₍ᵢ₊₁₎`` is noise alone, of standard deviation ``√6 σ``;
    corners, edges and grazing surfaces add large values. Over the triples whose readings all
    lie in ``[near, far)`` the RMS of the smaller half of the ``|second differences|``, divided
    by ``√6`` and by :data:`HALF_NORMAL_RMS`, estimates ``σ`` (exact for Gaussian noise; the
    large half, where geometry shows, is left out). NaN with no triple."""
    r = np.asarray(ranges, dtype=np.float64)
    if r.ndim != 2 or r.shape[1] < 3:
        return float("nan"), 0
    ok = np.isfinite(r) & (r >= near) & (r < far)
    both = ok[:, :-2] & ok[:, 1:-1] & ok[:, 2:]
    d2 = np.abs(r[:, :-2] - 2.0 * r[:, 1:-1] + r[:, 2:])[both]
    if d2.size == 0:
        return float("nan"), 0
    half = np.sort(d2)[: max(1, d2.size // 2)]
    return float(np.sqrt(np.mean(half * half)) / (np.sqrt(6.0) * HALF_NORMAL_RMS)), int(d2.size)


# --- where the laser sits --------------------------------------------------------------------


@dataclass(frozen=True)
class MountEstimate:
    """The laser's pose on the robot (relative to the odometry's reference point) as the data
    shows it."""

    x: float
    """Forward offset (m)."""
    y: float
    """Leftward offset (m)."""
    yaw: float
    """Rotation of the laser relative to the robot's heading (rad)."""
    std_x: float
    """Bootstrap standard deviation of ``x`` (m)."""
    std_y: float
    """... of ``y`` (m)."""
    std_yaw: float
    """... of ``yaw`` (rad)."""
    pairs: int
    """Turning pairs that fitted and entered the estimate."""
    residual_m: float
    """Median residual of the kept pairs under the estimate (m)."""
    residual_stated_m: float
    """Median residual of the same pairs under the mount the log or configuration states (m)."""

    def as_dict(self) -> dict[str, float | int]:
        """The estimate as plain numbers (metres; the angles in degrees)."""
        out = dataclasses.asdict(self)
        out["yaw_deg"] = float(np.degrees(out.pop("yaw")))
        out["std_yaw_deg"] = float(np.degrees(out.pop("std_yaw")))
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in out.items()}


def turning_pairs(times: F64, odometry: F64, settings: CalibrationSettings) -> NDArray[np.int64]:
    """``(K, 2)`` scan pairs ``(i, j)``: ``j`` is the first scan after ``i`` by which the odometry
    has turned ``min_turn``, within ``max_dt`` and ``max_step``; the next pair starts at ``j``.
    At most ``mount_pairs``, evenly spread."""
    pairs = []
    n, i = len(times), 0
    while i < n - 1:
        j = i + 1
        while j < n and abs(times[j] - times[i]) <= settings.max_dt:
            if abs(relative(odometry[i], odometry[j])[2]) >= settings.min_turn:
                break
            j += 1
        if j < n and abs(times[j] - times[i]) <= settings.max_dt:
            move = relative(odometry[i], odometry[j])
            if np.hypot(move[0], move[1]) <= settings.max_step:
                pairs.append((i, j))
                i = j
                continue
        i += 1
    out = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    if len(out) > settings.mount_pairs:
        out = out[spread_picks(len(out), settings.mount_pairs)]
    return out


def _hand_eye(laser: F64, odo: F64) -> F64:
    """Least-squares ``(x, y, yaw)`` of ``laser = L⁻¹ ⊕ odo ⊕ L`` over the pairs: with
    ``R(yaw)·t_A − (R_B − I)·(x, y) = t_B`` linear in ``(x, y, cos yaw, sin yaw)``."""
    c, s = np.cos(odo[:, 2]), np.sin(odo[:, 2])
    ax, ay = laser[:, 0], laser[:, 1]
    m = np.zeros((2 * len(laser), 4))
    m[0::2] = np.c_[1.0 - c, s, ax, -ay]
    m[1::2] = np.c_[-s, 1.0 - c, ay, ax]
    rhs = np.empty(2 * len(laser))
    rhs[0::2], rhs[1::2] = odo[:, 0], odo[:, 1]
    sol, *_ = np.linalg.lstsq(m, rhs, rcond=None)
    return np.array([sol[0], sol[1], np.arctan2(sol[3], sol[2])])


def _residuals(mount: F64, laser: F64, odo: F64) -> F64:
    """Each pair's translation residual (m) of ``odo`` against ``mount ⊕ laser ⊕ mount⁻¹``."""
    c, s = np.cos(odo[:, 2]), np.sin(odo[:, 2])
    cy, sy = np.cos(mount[2]), np.sin(mount[2])
    px = cy * laser[:, 0] - sy * laser[:, 1] - ((c - 1.0) * mount[0] - s * mount[1])
    py = sy * laser[:, 0] + cy * laser[:, 1] - (s * mount[0] + (c - 1.0) * mount[1])
    return np.hypot(px - odo[:, 0], py - odo[:, 1])


def _trimmed_fit(laser: F64, odo: F64, trim: float) -> tuple[F64, NDArray[np.bool_]]:
    keep = np.ones(len(laser), dtype=bool)
    for _ in range(2):
        residual = _residuals(_hand_eye(laser[keep], odo[keep]), laser, odo)
        keep = residual <= np.quantile(residual, 1.0 - trim)
    return _hand_eye(laser[keep], odo[keep]), keep


def estimate_mount(
    laser: F64, odo: F64, stated: F64, settings: CalibrationSettings
) -> MountEstimate:
    """The hand-eye estimate (module docstring) from the pairs' laser motions ``laser`` (laser
    frame) and odometry motions ``odo``; ``stated`` is the mount the log or configuration
    gives, for comparison. :class:`ValueError` with fewer than 10 pairs."""
    if len(laser) < 10:
        raise ValueError(f"{len(laser)} turning scan pairs fitted; at least 10 are needed")
    mount, keep = _trimmed_fit(laser, odo, settings.mount_trim)
    rng = np.random.default_rng(0)
    picks = rng.integers(0, len(laser), size=(settings.bootstrap, len(laser)))
    boots = np.array([_trimmed_fit(laser[p], odo[p], settings.mount_trim)[0] for p in picks])
    boots[:, 2] = wrap_angle(boots[:, 2] - mount[2])
    stated_residual = _residuals(np.asarray(stated, dtype=np.float64), laser, odo)
    return MountEstimate(
        x=float(mount[0]),
        y=float(mount[1]),
        yaw=float(wrap_angle(mount[2])),
        std_x=float(boots[:, 0].std()),
        std_y=float(boots[:, 1].std()),
        std_yaw=float(boots[:, 2].std()),
        pairs=int(keep.sum()),
        residual_m=float(np.median(_residuals(mount, laser, odo)[keep])),
        residual_stated_m=float(np.median(stated_residual[keep])),
    )


def calibrate_mount(
    scans, config: Config, settings: CalibrationSettings | None = None
) -> MountEstimate:
    """The laser's mount measured from ``scans`` (a :class:`slam.scans.LogScans`, with the
    odometry the run would use) against the mount they state (module docstring)."""
    settings = settings or CalibrationSettings()
    stated = np.asarray(scans.log.scans.laser_offset, dtype=np.float64)

    def laser_frame(k: int) -> tuple[F64, F64]:  # the returns before the stated mount
        ex, ey = scans.scan(k).hits()
        c, s = np.cos(stated[2]), np.sin(stated[2])
        dx, dy = ex - stated[0], ey - stated[1]
        return c * dx + s * dy, -s * dx + c * dy

    pairs = turning_pairs(scans.times, scans.odometry, settings)
    laser, kept = pair_motions(laser_frame, scans.odometry, pairs, config, settings)
    pairs = pairs[kept]
    odo = relative(scans.odometry[pairs[:, 0]], scans.odometry[pairs[:, 1]])
    return estimate_mount(laser, odo, stated, settings)


# --- the beams of a log that mixes n and n − 1 readings --------------------------------------


def short_scan_geometries(short: int, fov: float) -> dict[str, F64]:
    """The angles (rad) that scans of ``short`` readings may have when the log's other scans
    have ``short + 1`` spread over ``fov`` (one step ``fov / short`` apart, centred): spread
    over the whole field of view, one step apart and centred (a SICK LMS's interlaced sweeps:
    the half steps between the long scan's beams), or one step apart from its first beam or to
    its last."""
    i = np.arange(short, dtype=np.float64)
    step = fov / short
    return {
        "spread": (i - (short - 1) / 2.0) * (fov / max(short - 1, 1)),
        "centred": (i - (short - 1) / 2.0) * step,
        "from_first": (i - short / 2.0) * step,
        "to_last": (i - short / 2.0 + 1.0) * step,
    }


@dataclass(frozen=True)
class BeamGeometryCheck:
    """How well each candidate geometry of a log's shorter scans lets the matcher agree with
    the odometry (:func:`check_beam_geometry`)."""

    short: int
    """Readings of the shorter scans (the longer ones have one more)."""
    fov_deg: float
    """The span of the longer scans (degrees)."""
    rows: dict[str, dict[str, float | int]]
    """Per geometry (:func:`short_scan_geometries`): ``rotation_rms_deg`` (trimmed RMS of the
    matcher's rotation minus the odometry's), ``pairs_fitted`` and the median difference
    (degrees) on pairs from a short to a long scan (``short_to_long_deg``) and back
    (``long_to_short_deg``)."""
    best: str
    """The geometry with the smallest disagreement."""

    @property
    def beam_step_deg(self) -> float:
        """The step (degrees) that declares the ``centred`` geometry (``lidar.beam_step_deg``),
        to a micro-degree (the same step however the field of view's end angles round)."""
        return round(self.fov_deg / self.short, 6)

    @property
    def declares_step(self) -> bool:
        """Whether the ``centred`` geometry won, on at least :data:`MIN_BEAM_PAIRS` fitted pairs
        and by at least :data:`BEAM_MARGIN` of the ``spread`` one's disagreement (the geometry
        the loader gives the shorter scans when nothing declares another): then
        ``lidar.beam_step_deg = beam_step_deg`` reads the log as measured."""
        centred, spread = self.rows["centred"], self.rows["spread"]
        return (
            self.best == "centred"
            and centred["pairs_fitted"] >= MIN_BEAM_PAIRS
            and centred["rotation_rms_deg"] <= (1.0 - BEAM_MARGIN) * spread["rotation_rms_deg"]
        )

    def as_dict(self) -> dict:
        """The check as plain values (for ``slam data calibrate --json``)."""
        return {
            "short": self.short,
            "fov_deg": round(self.fov_deg, 4),
            "best": self.best,
            "beam_step_deg": self.beam_step_deg,
            "geometries": self.rows,
        }


BEAM_PAIRS = 500
"""Pairs of consecutive scans (evenly spread) a run's beam measurement compares: on fr-clinic
the centred beams beat the spread ones by 0.02–0.03° of trimmed RMS, and the two one-sided
geometries lose by 0.1°, whether 360 or 2522 pairs fit (docs/accuracy.md); about 0.2 s per 100
pairs for the four geometries on two cores."""
MIN_BEAM_PAIRS = 50
"""Fewest fitted pairs on which a measured beam geometry is applied."""
BEAM_MARGIN = 0.02
"""Share by which the centred geometry's disagreement must be below the spread one's to be
applied: fr-clinic's is 5–8 % below at every sample size (360 to 2522 fitted pairs); in a small
room whose walls are a few metres away the two differ by less than 2 % either way (the matcher's
noise), and the log is then read as its lines say (spread)."""


def measure_beam_step(log, config: Config) -> BeamGeometryCheck | None:
    """:func:`check_beam_geometry` of a whole loaded log (a :class:`slam.io.log.Log`) as a run
    measures it: every scan (not only the run's ``filter.every``/``max_scans`` selection), the
    odometry written with the scans, about :data:`BEAM_PAIRS` pairs of consecutive scans evenly
    spread. ``None`` when the log does not mix scans of ``n`` and ``n − 1`` readings."""
    import warnings

    from slam.config import load_config
    from slam.io.log import mixed_widths
    from slam.scans import LogScans

    if log.scans is None or mixed_widths(log.scans.readings()) is None:
        return None
    whole = ["filter.every=1", "filter.max_scans=0", 'robot.odometry_sync="scan"']
    measuring = load_config("", None, whole, base=config)  # "": the shipped file is in base
    with warnings.catch_warnings():  # the run's own selection reports sparse scans
        warnings.simplefilter("ignore")
        scans = LogScans.from_log(log, measuring)
    every = max(1, -(-(len(scans) - 1) // BEAM_PAIRS))
    return check_beam_geometry(scans, measuring, every=every)


def check_beam_geometry(
    scans, config: Config, every: int = 2, settings: CalibrationSettings | None = None
) -> BeamGeometryCheck | None:
    """Which angles the shorter scans of ``scans`` (a :class:`slam.scans.LogScans`) have, when
    the log mixes scans of ``n`` and ``n − 1`` readings whose lines carry no angles (fr-clinic's
    180 and 181): every ``every``-th pair of consecutive scans is registered as
    :func:`pair_motions` registers them, in the laser's frame, under each geometry of
    :func:`short_scan_geometries` (the longer scans as the loader spreads them), and the rotation
    found is compared with the odometry's. A wrong geometry turns a short scan against a long
    one (opposite biases on the two kinds of mixed pair) or distorts it (fewer pairs fit, a larger
    disagreement). ``None`` when the log's scans do not mix two such counts."""
    from slam.io.log import mixed_widths

    settings = settings or CalibrationSettings()
    log_scans = scans.log.scans
    readings = log_scans.readings()[scans.indices]
    short = mixed_widths(readings)
    if short is None:
        return None
    long_angles = log_scans.angles[scans.indices[int(np.argmax(readings))]]
    fov = float(long_angles[-1] - long_angles[0])
    pairs = np.array([(k, k + 1) for k in range(0, len(scans) - 1, every)], dtype=np.int64)
    kinds = readings[pairs[:, 0]] - readings[pairs[:, 1]]  # -1: short to long, +1: back
    odometry = np.asarray(scans.odometry, dtype=np.float64)
    turn = relative(odometry[pairs[:, 0]], odometry[pairs[:, 1]])[:, 2]
    rows: dict[str, dict[str, float | int]] = {}
    for name, angles in short_scan_geometries(short, fov).items():

        def laser_frame(k: int, angles: F64 = angles) -> tuple[F64, F64]:
            sc = scans.scan(k)
            a = angles if readings[k] == short else long_angles
            r = np.asarray(sc.ranges[: a.size], dtype=np.float64)
            ok = np.isfinite(r) & (r >= sc.range_min) & (r > 0) & (r < sc.range_max)
            return r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])

        motions, kept = pair_motions(laser_frame, odometry, pairs, config, settings)
        d = np.degrees(wrap_angle(motions[:, 2] - turn[kept])) if kept.size else np.zeros(0)
        rms = round(_trimmed_rms(d, settings.trim), 4) if d.size else float("nan")
        row: dict[str, float | int] = {"pairs_fitted": int(kept.size), "rotation_rms_deg": rms}
        for kind, label in ((-1, "short_to_long_deg"), (1, "long_to_short_deg")):
            sel = kinds[kept] == kind
            if sel.any():
                row[label] = round(float(np.median(d[sel])), 4)
        rows[name] = row
    best = min(rows, key=lambda n: np.nan_to_num(rows[n]["rotation_rms_deg"], nan=np.inf))
    return BeamGeometryCheck(short, float(np.degrees(fov)), rows, best)
