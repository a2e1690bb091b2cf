"""Configuration: one frozen dataclass per concern, loaded from TOML, overridable from the CLI.

Every number an algorithm uses lives here with its default, its bounds (declared next to the
default with :func:`slam.validate.bounded`: finite, ``> 0``, ranges, and cross-field
:class:`~slam.validate.Rule`\\ s such as ``log_odds_min < log_odds_max``) and a one-line reason.
A run resolves its configuration in this order, later wins:

1. the dataclass defaults below;
2. ``configs/<dataset>.toml`` shipped with the project (sensor geometry per log);
3. ``--config FILE``;
4. ``--set section.key=value`` overrides (values parsed as TOML literals, never evaluated).

Types are checked as each layer is read; bounds and rules once, when the layers are merged and
each section is built, so ``--set map.log_odds_min=-20 --set map.log_odds_max=-15`` is judged on
the result, not on a half-applied state. A failure is one :class:`~slam.errors.ConfigError`
naming the layer that set the value, the key, the bound and the value.

The resolved configuration is written next to every run's outputs as ``config.toml``, so a run can
be repeated exactly with ``slam run NAME --config RUN_DIR/config.toml``.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from slam.errors import ConfigError, UsageError
from slam.resources import config_dir
from slam.validate import FieldError, Rule, Validated, bounded, coerce, field_types, parse_literal
from slam.validate import read_toml as _read_toml

METHODS = ("odometry", "classic", "rbpf")
"""Estimation methods of ``slam run``."""

TEXTURE_MODES = ("mean", "latest")
"""Accumulation modes of the floor texture (``texture.mode``, ``slam texture --mode``)."""

MAX_RANGE_M = 1000.0
"""Longest range a lidar setting may name (m): no 2D lidar measures a kilometre."""

TAU = 2.0 * math.pi


def _unset_or_less(a: float | None, b: float | None) -> bool:
    return a is None or b is None or a < b


def _unset_or_at_most(a: float | None, b: float | None) -> bool:
    return a is None or b is None or a <= b


def _cell_or_zero(zero_means: str) -> Any:
    """A cell size field (m), default 0: 0 means ``zero_means`` (another cell size), else a
    finite number in [0.001, 10]."""
    return bounded(
        0.0,
        ge=0.0,
        le=10.0,
        test=lambda v: v == 0.0 or v >= 0.001,
        expected=f"0 (use {zero_means}) or a finite number in [0.001, 10]",
    )


@dataclass(frozen=True)
class RobotConfig(Validated):
    """Differential-drive robot geometry and odometry settings."""

    SECTION: ClassVar[str] = "robot"

    meters_per_tick: float = bounded(math.pi * 0.254 / 360.0, gt=0.0, le=1.0)
    """Wheel travel per encoder tick: wheel diameter 0.254 m, 360 ticks per revolution."""
    track_width: float = bounded(0.3937, gt=0.0, le=10.0)
    """Effective skid-steer track width (m), used only when yaw comes from the wheels."""
    yaw_source: str = bounded("imu", choices=("imu", "encoders"))
    """Where yaw rate comes from: ``"imu"`` (z gyro, the course's model) or ``"encoders"``."""
    imu_lowpass_hz: float = bounded(10.0, ge=0.0, le=1000.0)
    """Cut-off of the low-pass filter on the gyro z rate (Hz); 0 disables filtering."""
    max_imu_gap_s: float = bounded(0.1, ge=0.0, le=60.0)
    """Longest stretch past the IMU's last sample that odometry may hold the last rate (s)."""
    odometry_sync: str = bounded("auto", choices=("auto", "scan", "stream"))
    """The odometry of a log that gives both the pose written with each scan and a stream of
    odometry messages (CARMEN ``FLASER`` and ``ODOM``): ``"scan"`` the written poses,
    ``"stream"`` the messages interpolated at each scan's time plus ``odometry_lag_s``, ``"auto"``
    whichever of the written poses and the stream at a lag within ±0.3 s agrees best with the
    rotations the laser measures (:mod:`slam.calibration`; ``metrics.json`` says what it
    chose). Logs with one odometry only use it as it is."""
    odometry_lag_s: float = bounded(0.0, ge=-10.0, le=10.0)
    """With ``odometry_sync = "stream"``: the stream is read this long after each scan's time
    (s; negative: before it)."""
    odometry: str = bounded("auto", choices=("auto", "log", "laser"))
    """Where the odometry comes from: ``"log"`` the log's (wheel odometry, encoders + IMU; a log
    without any is refused), ``"laser"`` scan matching alone (:mod:`slam.laser_odometry`), ``"auto"``
    the log's where it has one, else the laser's — a log without odometry messages, encoders or
    poses with its scans, or whose odometry never moves (poses written with the scans that never
    move give way to the log's odometry messages when those move) (``metrics.json``:
    ``odometry_source``; ``slam run`` warns)."""
    laser_odometry_keyframe_m: float = bounded(0.3, gt=0.0, le=100.0)
    """Laser odometry: a scan becomes a keyframe of the local map after this much travel (m) ..."""
    laser_odometry_keyframe_rad: float = bounded(0.2, gt=0.0, le=TAU)
    """... or this much turn (rad) since the last keyframe."""
    laser_odometry_window: int = bounded(8, ge=1, le=1000)
    """Laser odometry: the local map holds the last this many keyframes."""
    laser_odometry_gyro: bool = True
    """Laser odometry: where the log has an IMU (or ``Slam.add_imu`` feeds one), each scan's
    predicted turn is the gyro's since the previous scan instead of the previous scan's turn;
    a gyro whose turns disagree with the scans' is set aside (:mod:`slam.laser_odometry`)."""


@dataclass(frozen=True)
class LidarConfig(Validated):
    """2D laser geometry and range semantics. ``None`` means: take it from the log."""

    SECTION: ClassVar[str] = "lidar"
    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(("range_min", "range_max"), _unset_or_less, "range_min < range_max"),
        Rule(("range_max", "no_return"), _unset_or_at_most, "range_max <= no_return"),
        Rule(("range_min", "no_return"), _unset_or_less, "range_min < no_return"),
    )

    x: float = bounded(0.13323, ge=-10.0, le=10.0)
    """Laser position ahead of the robot centre (m)."""
    y: float = bounded(0.0, ge=-10.0, le=10.0)
    """Laser position to the left of the robot centre (m)."""
    yaw: float = bounded(0.0, ge=-TAU, le=TAU)
    """Laser heading relative to the robot heading (rad)."""
    fov_deg: float | None = bounded(None, gt=0.0, le=360.0)
    """Field of view (degrees) for logs whose lines carry no geometry (CARMEN FLASER)."""
    beam_step_deg: float | None = bounded(None, gt=0.0, le=10.0)
    """Angle between neighbouring beams (degrees) for logs whose lines carry no geometry (CARMEN
    FLASER): the ``n`` beams are centred on straight ahead this far apart whatever ``n`` (e.g. 1°
    for a SICK LMS logged with 180 or 181 readings); unset: ``fov_deg / (n − 1)``, or measured
    (``measure_beam_step``)."""
    measure_beam_step: bool = True
    """With ``beam_step_deg`` unset, a CARMEN log that mixes scans of ``n`` and ``n − 1``
    readings (a SICK LMS's interlaced sweeps) has its beam geometry measured when it loads
    (:func:`slam.calibration.measure_beam_step`): where beams one step apart, centred, fit the
    odometry best, the log is read with that step and the run's ``config.toml`` records it."""
    range_min: float | None = bounded(None, ge=0.0, lt=MAX_RANGE_M)
    """Shortest valid range (m); shorter readings are invalid beams."""
    range_max: float | None = bounded(None, gt=0.0, le=MAX_RANGE_M)
    """Longest range used as an obstacle hit (m); longer readings clear space only."""
    no_return: float | None = bounded(None, gt=0.0, le=MAX_RANGE_M)
    """Readings at or beyond this (m) mean "no return" (e.g. 80 m on intel)."""
    use_log_laser_pose: bool = True
    """CARMEN: derive the laser offset from the laser and odometry poses written in each line."""


@dataclass(frozen=True)
class MapConfig(Validated):
    """Occupancy grid geometry and log-odds update."""

    SECTION: ClassVar[str] = "map"
    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(
            ("log_odds_min", "log_odds_max"), lambda lo, hi: lo < hi, "log_odds_min < log_odds_max"
        ),
        Rule(
            ("log_odds_min", "occupied_threshold", "log_odds_max"),
            lambda lo, t, hi: lo <= t < hi,
            "log_odds_min <= occupied_threshold < log_odds_max",
        ),
    )

    resolution: float = bounded(0.05, ge=0.001, le=10.0)
    """Cell size (m)."""
    initial_size_m: float = bounded(40.0, gt=0.0, le=10000.0)
    """Side of the square map allocated at start (m); the map grows on demand."""
    grow_margin_m: float = bounded(10.0, ge=0.0, le=1000.0)
    """Extra room added on each side when the map must grow (m)."""
    log_odds_hit: float = bounded(math.log(4.0), gt=0.0, le=100.0)
    """Log-odds added to a cell where a beam ends."""
    log_odds_miss: float = bounded(-0.4, ge=-100.0, le=0.0)
    """Log-odds added to cells a beam passes through (smaller than a hit, so a wall is not
    erased by the rays that graze it)."""
    log_odds_min: float = bounded(-10.0, ge=-1000.0, le=0.0)
    """Lower clamp of the log-odds."""
    log_odds_max: float = bounded(10.0, ge=0.0, le=1000.0)
    """Upper clamp of the log-odds."""
    occupied_threshold: float = bounded(0.0, ge=-1000.0, le=1000.0)
    """Log-odds above which a cell counts as occupied in correlation and rendering."""
    free_range_no_return: float = bounded(0.0, ge=0.0, le=MAX_RANGE_M)
    """"No return" beams clear free space up to this range (m); 0 leaves them out."""
    free_beam_stride: int = bounded(1, ge=1, le=10000)
    """Cast free-space rays for every k-th beam only (hits are always integrated)."""
    crop_margin_m: float = bounded(2.0, ge=0.0, le=1000.0)
    """The output map is cropped to the observed cells plus this margin (m)."""


@dataclass(frozen=True)
class FilterConfig(Validated):
    """Particle filter settings shared by both methods."""

    SECTION: ClassVar[str] = "filter"

    method: str = bounded("rbpf", choices=METHODS)
    """``"rbpf"`` (default: per-particle maps, scan-matching proposal), ``"classic"`` (the course's
    single-map correlation filter) or ``"odometry"`` (dead reckoning)."""
    particles: int = bounded(30, ge=1, le=100000)
    """Number of particles."""
    seed: int = bounded(0, ge=0, lt=2**63)
    """Seed of the single random generator of a run (below 2**63: TOML's integers are 64-bit)."""
    every: int = bounded(1, ge=1, le=1000000)
    """Process every k-th scan."""
    max_scans: int = bounded(0, ge=0)
    """Stop after this many processed scans (0: all)."""
    resample_threshold: float = bounded(0.5, ge=0.0, le=1.0)
    """Resample when N_eff falls below this fraction of the particle count."""
    motion_alphas: tuple[float, ...] = bounded(
        (0.1, 0.05, 0.05, 0.1, 0.02), length=5, ge=0.0, le=10.0
    )
    """Odometry noise: σx = a0·d + a1·|dθ|, σy = a2·d + a1·|dθ|, σθ = a3·|dθ| + a4·d."""
    motion_floor: tuple[float, ...] = bounded((0.002, 0.002, 0.002), length=3, ge=0.0, le=10.0)
    """Noise standard deviation added to every update (m, m, rad), for particle diversity."""


@dataclass(frozen=True)
class RbpfConfig(Validated):
    """The default method: Rao-Blackwellised particles, each with its own distance-field map."""

    SECTION: ClassVar[str] = "rbpf"

    update_distance: float = bounded(0.2, gt=0.0, le=100.0)
    """Run a filter update after this much travel since the last one (m)."""
    update_angle: float = bounded(0.1, gt=0.0, le=TAU)
    """... or after this much rotation (rad). Scans in between move particles by odometry only."""
    update_interval_s: float = bounded(0.3, ge=0.0, le=3600.0)
    """... or, once this long has passed since the last update (counted in scans × the median
    scan period), after any motion beyond ``update_min_motion``; 0 disables this rule."""
    update_min_motion: float = bounded(0.02, ge=0.0, le=100.0)
    """Least motion (m, and rad) for the interval rule: a standing robot is never updated."""
    match_beams: int = bounded(180, ge=1, le=100000)
    """At most this many beams (evenly spread) are used for scan matching and weighting."""
    insert_beams: int = bounded(360, ge=1, le=100000)
    """At most this many beams are inserted into the particle maps per update."""
    tile: int = bounded(16, ge=2, le=128, power_of_two=True)
    """Tile side (cells, a power of two) of the copy-on-write particle maps."""
    resolution: float = _cell_or_zero("map.resolution")
    """Cell size of the particle maps (m); 0 uses ``map.resolution``."""
    field: str = bounded("distance", choices=("distance", "plane"))
    """Particle-map field: ``"distance"`` (Euclidean distance to the nearest hit) or ``"plane"``
    (signed point-to-plane distance, with normals from neighbouring beams)."""
    dmax: float = bounded(0.3, gt=0.0, le=10.0)
    """Truncation of the distance field (m): beams further from any surface carry no gradient."""
    sigmas: tuple[float, ...] = bounded((0.2, 0.075, 0.04), min_length=1, gt=0.0, le=10.0)
    """Scan-matching sensor sigmas (m), wide to narrow; the last one scores the particles."""
    z_hit: float = bounded(1.0, ge=0.0, le=100.0)
    """Weight of the Gaussian term of the likelihood field model."""
    z_rand: float = bounded(0.05, gt=0.0, le=100.0)
    """Weight of the uniform (unexplained beam) term of the likelihood field model (> 0: the
    likelihood of a beam far from every surface must not be 0)."""
    max_iterations: int = bounded(5, ge=1, le=1000)
    """Levenberg-Marquardt iterations per sigma level."""
    coarse_stride: int = bounded(1, ge=1, le=10000)
    """The wide sigma levels use every k-th beam (the last level always uses all of them)."""
    tolerance: float = bounded(1e-3, gt=0.0, le=1.0)
    """A sigma level ends when a step moves less than this (m, and rad)."""
    min_inliers: float = bounded(0.3, ge=0.0, le=1.0)
    """Keep the predicted pose when fewer beams than this fraction lie near known surfaces."""
    temperature: float = bounded(10.0, ge=0.001, le=1e6)
    """Log-likelihoods are divided by this before weighting (beams are not independent)."""
    proposal_spread: float = bounded(0.3, ge=0.0, le=100.0)
    """Particles are drawn around their matched pose with covariance ``proposal_spread ·
    (H / temperature + Σ_motion⁻¹)⁻¹`` (``H`` the matcher's Hessian, ``Σ_motion`` the odometry
    model's covariance); 0 keeps the matched pose."""
    retry_ratio: float = bounded(0.0, ge=0.0, le=1e6)
    """An update whose best match scores a per-beam log-likelihood worse than this multiple of
    the median of the last ``retry_window`` updates' is matched again from starts rotated by
    ±``retry_yaw``, each particle keeping its best match (a rotation the odometry got wrong by
    more than the matcher's basin); 0 (the default): never. At 3 it repairs mit-csail seeds 0
    and 1 but makes intel seed 1 and mit-csail seed 2 worse (docs/slam.md)."""
    retry_window: int = bounded(25, ge=1, le=100000)
    """How many of the latest updates the median of ``retry_ratio`` and of ``probe_gain`` is
    taken over (their best per-beam log-likelihoods)."""
    retry_yaw: tuple[float, ...] = bounded((0.15, 0.3), min_length=1, gt=0.0, le=math.pi)
    """Rotations (rad) of the predicted poses tried, both signs, when an update is retried."""
    probe_gain: float = bounded(0.3, ge=0.0, le=100.0)
    """Every update, the best particle is matched again from starts rotated by ±``probe_yaw``;
    when one scores a per-beam log-likelihood this much above its match and closes at least half
    of the match's shortfall from the median of the last ``retry_window`` updates, every
    particle is matched again from its predicted pose rotated by that start's angle, each
    keeping the better match (an odometry rotation wrong by more than the matcher's basin);
    0: never."""
    probe_yaw: tuple[float, ...] = bounded((0.1, 0.2, 0.3), min_length=1, gt=0.0, le=math.pi)
    """Rotations (rad) of the best particle's predicted pose the probe tries, both signs."""
    probe_shift: tuple[float, ...] = bounded((0.3, 0.6), gt=0.0, le=10.0)
    """Shifts (m) along its heading of the best particle's predicted pose that the translational
    basin probe tries, both signs, at an update whose best match falls short of the recent ones
    by more than ``probe_gain`` per beam: the rotation probe's test and remedy for an odometry
    that gets the distance between two updates wrong by more than the matcher's basin (fr079's
    reversals at a third of its scan rate: 0.4–0.6 m). Open on the same evidence rule
    (``probe_evidence_per_m``, ``probe_evidence_count``), counted over the updates whose best
    first match moved the predicted position by at least ``min(probe_shift)``; empty: never."""
    probe_evidence_per_m: float = bounded(0.03, ge=0.0, le=100.0)
    """The probe runs only on a log whose odometry has been seen to err by the probe's smallest
    rotation: at an update, once the best particle's first match has turned its predicted
    heading by at least ``min(probe_yaw)`` at least this often per metre of the odometry's
    travel so far (3 per 100 m; and in at least ``probe_evidence_count`` updates). Per metre,
    not per update, so that a robot that scans less often, whose updates each span more
    motion, is judged by the same events. On a log whose odometry never errs that much a firing
    can only be a misreading of an ambiguous scan (a wide hall); 0: always."""
    probe_evidence_count: int = bounded(3, ge=0, le=100000)
    """See ``probe_evidence_per_m``: the fewest such updates that open the probe."""
    proposal_motion_prior: bool = False
    """Include the odometry model in the proposal's covariance (else the scan likelihood alone,
    with a unit ridge: σ 1.7 m and 1.7 rad where no beam lands on a known cell). Not the
    default: on seeds 0–3 it improves intel, aces, mit-csail and the demo, but fr-clinic seed 1
    ends with its return to the start 55 m off (docs/accuracy.md)."""
    proposal_mean: str = bounded("match", choices=("match", "fused"))
    """Where each particle's proposal is centred: ``match``, its scan-matched pose; ``fused``,
    the mean of the Gaussian product of the tempered scan likelihood at the match and the
    odometry model at its predicted pose (``μ = x_m + (H/T + Σ_m⁻¹)⁻¹ Σ_m⁻¹ (x_p − x_m)``): where
    the scan constrains the pose it stays at the match, along a direction it does not (a
    corridor, a wide hall's far walls) it stays with the odometry instead of sliding. Not the
    default: on seeds 0–3 it improves fr-clinic (0.144 → 0.130 m) but worsens aces and
    mit-csail, and intel and fr079 diverge (docs/accuracy.md)."""
    refine_passes: int = bounded(3, ge=0, le=100)
    """After the filter, re-register the update scans of the final lineage against the map they
    build this many times (removes the jitter the proposal's sampling leaves; 0: off)."""
    refine_beams: int = bounded(0, ge=0, le=100000)
    """At most this many beams (evenly spread) per scan in the re-registration; 0 (the
    default): every beam. After the filter there is time for all of them: with every beam
    instead of ``match_beams``, fr079's and mit-csail's (360 beams) relation errors fall on
    seeds 0–3 on average (docs/accuracy.md); logs of at most ``match_beams`` beams are unchanged."""
    refine_resolution: float = _cell_or_zero("the particle maps' cell")
    """Cell size (m) of the distance field the stages after the filter register scans against
    (re-registration and :attr:`register_scans`); 0 (the default): the particle maps' own.
    A coarser field (0.1 m) scores better on the benchmark's relations but worse against the
    demo's ground truth and on a synthetic room, since an unsigned field pulls each scan towards
    its cell centres (docs/accuracy.md)."""
    register_scans: bool = True
    """After the scans between updates are placed by odometry, register every scan (not only
    the update scans) against the map of the update scans at their final poses: the odometry
    between two updates is off by up to a few degrees, which the relation metric sees."""
    register_beams: int = bounded(360, ge=0, le=100000)
    """At most this many beams (evenly spread) per scan in :attr:`register_scans`; 0: every
    beam. Twice what the filter matches (``match_beams``): on the demo's 1081-beam scans every
    beam gives the same ATE (0.0469 against 0.0470 m) for 0.65 s more (docs/accuracy.md)."""
    register_rounds: int = bounded(2, ge=1, le=10)
    """Rounds of :attr:`register_scans` and :attr:`smooth_odometry`: each round registers every
    scan again, from the pose the previous round smoothed, against the map of the node scans at
    those poses, then smooths. The second round improves every seed of intel, aces, fr079 and
    mit-csail (docs/accuracy.md); a third changes nothing measurable."""
    smooth_odometry: bool = True
    """After :attr:`register_scans`, smooth every scan's pose with the odometry between
    neighbouring scans (:class:`slam.stages.OdometrySmoothing`): each registered pose is a prior
    of sigma ``smooth_sigma_xy`` / ``smooth_sigma_th``, each odometry step an edge whose sigmas
    along and across the robot's heading and in heading are ``smooth_factor`` times the
    odometry's measured disagreement with the matcher on each
    (:func:`slam.calibration.odometry_disagreement`), so a log's odometry counts as far as its
    own data show it deserves, in each direction (docs/accuracy.md)."""
    smooth_factor: float = bounded(2.0, gt=0.0, le=1000.0)
    """See :attr:`smooth_odometry`."""
    smooth_sigma_xy: float = bounded(0.02, gt=0.0, le=10.0)
    """See :attr:`smooth_odometry` (m)."""
    smooth_sigma_th: float = bounded(0.005, gt=0.0, le=math.pi)
    """See :attr:`smooth_odometry` (rad)."""
    smooth_scales: tuple[float, ...] = bounded((1.0, 10.0, 50.0), min_length=1, gt=0.0, le=1e4)
    """The registration's sigmas (``smooth_sigma_xy``, ``smooth_sigma_th``) are tried at these
    multiples, and the map-quality score (``slam eval``, no reference: the share of returns that
    agree with the map of the other stretches; :func:`slam.eval.quality.map_quality`) of each
    smoothed trajectory picks one, in the first round of :attr:`register_rounds`: the best,
    unless it beats the first scale's score by less than :attr:`smooth_choice_margin` or
    :attr:`smooth_choice_z` standard errors, then the first. A larger multiple trusts the
    odometry's shape more, which a log whose odometry is locally better than its registration
    (fr-clinic) scores better on. One value: no choice
    (``[1]``: the smoothing before the choice existed). The default ``[1, 10, 50]`` takes a
    larger multiple on fr-clinic's seeds 0, 1 and 3 of 0–3 and on no other
    benchmark log, and costs 0.3–1.2 s a run (docs/accuracy.md, "How far to trust the
    odometry's shape")."""
    smooth_noise_ref: float = bounded(0.01, ge=0.0, le=1.0)
    """The registration's sigmas (``smooth_sigma_xy``, ``smooth_sigma_th``) hold for a laser
    whose readings scatter by at most this much (m: about a SICK LMS's, as on intel, fr079 and
    mit-csail). A noisier laser's, its range noise measured from its own scans
    (:func:`slam.calibration.range_noise`), are that noise over this times larger wherever the
    choice among :attr:`smooth_scales` keeps the first (a larger multiple that wins is kept):
    the noisier its scans, the less a registered pose is trusted against the odometry. 0: never
    (docs/accuracy.md, "The registration's weight from the laser's noise")."""
    smooth_choice_margin: float = bounded(0.005, ge=0.0, le=1.0)
    """See :attr:`smooth_scales` (a share of the judged returns)."""
    smooth_choice_z: float = bounded(2.0, ge=0.0, le=100.0)
    """... and the best must also beat the first scale's score by this many standard errors of
    the difference of the two shares (binomial, from the returns each judged; 0: the margin
    alone): a choice that rests on a few hundred judged returns (a log that seldom comes back
    to a place) is a draw, and keeps the first scale (docs/accuracy.md)."""
    recover_below: float = bounded(0.75, ge=0.0, le=1.0)
    """When the result's map-quality score is below this, the filter lost track: the stages
    after it run again from dead reckoning and the better-scoring result is kept
    (:class:`slam.stages.Recovery`; 0: never). At ``quality.warn_below``: under every run of
    the bench's default (six logs, seeds 0–3)."""
    repair_below: float = bounded(0.5, ge=0.0, le=1.0)
    """A stretch of the result (``quality.stretch_m`` of path) whose returns agree with the
    other stretches' map less than this share contradicts them: the stages after the filter run
    again with the loop closing's chain ``loops.flex_factor`` times looser there, and the
    better-scoring result is kept unless it breaks a stretch that agreed
    (:class:`slam.stages.Repair`; 0: never)."""
    smooth_choice_every: int = bounded(4, ge=1, le=1000)
    """The score that chooses among :attr:`smooth_scales` judges every this-many-th scan only
    (and builds its maps from those): the choice costs a quarter of a full score per scale ..."""
    smooth_choice_beams: int = bounded(400, ge=1, le=100000)
    """... and at most this many beams of each (evenly spread): the demo's 1081-beam scans
    would make it three times as long, for a share of agreeing returns that a few hundred beams
    a scan already measure (the benchmark logs have 180–361, all judged)."""
    skip_insert_below: float = bounded(0.02, ge=0.0, le=10.0)
    """A hit closer than this (m) to an existing surface adds nothing to a particle's map."""
    vacate_after: int = bounded(0, ge=0, le=255)
    """A hit of the particle maps that this many later rays went through, with no return in its
    cell since, is gone (a person who walked on, a door): a return whose nearest hit it is
    counts as unexplained in the matcher (:class:`slam.mapping.VacancyGrid`; a ray counts when
    it crosses the hit's surface at 30° or more and passes ``dmax`` + 2 % of its range short of
    its own end). 0 (the default: measured, not adopted, docs/accuracy.md): every hit stays."""


MAX_SEARCH_CANDIDATES = 1_000_000
"""Most candidate poses one correlative loop-closure search may score."""


def _search_candidates(xy: float, step: float, th: float, th_step: float) -> bool:
    cells = 2 * (xy / step) + 1  # floats: a tiny step gives inf, which fails the bound
    turns = 2 * (th / th_step) + 1
    if not cells * cells * turns <= 2 * MAX_SEARCH_CANDIDATES:
        return False
    return (2 * math.ceil(xy / step) + 1) ** 2 * (2 * math.ceil(th / th_step) + 1) <= (
        MAX_SEARCH_CANDIDATES
    )


@dataclass(frozen=True)
class LoopConfig(Validated):
    """Loop closing after the filter: a pose graph with scan-matched loop edges (rbpf only)."""

    SECTION: ClassVar[str] = "loops"
    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(
            ("search_xy", "search_step", "search_th", "search_th_step"),
            _search_candidates,
            f"(2·⌈search_xy/search_step⌉+1)²·(2·⌈search_th/search_th_step⌉+1) ≤ "
            f"{MAX_SEARCH_CANDIDATES} candidate poses",
        ),
    )

    enabled: bool = True
    """Run the stage."""
    stride: int = bounded(5, ge=1, le=1000000)
    """Look for a loop closure at every k-th node (filter update)."""
    radius: float = bounded(3.0, gt=0.0, le=10000.0)
    """A candidate is the nearest earlier node within this distance (m) ..."""
    min_path: float = bounded(10.0, ge=0.0, le=1e6)
    """... and at least this far back along the path (m)."""
    submap_path: float = bounded(5.0, ge=0.0, le=10000.0)
    """A candidate's scan is matched against the nodes within this distance of ``j`` along the
    path (m) ..."""
    submap_stride: int = bounded(2, ge=1, le=1000000)
    """... every k-th of them."""
    search_xy: float = bounded(0.6, gt=0.0, le=100.0)
    """Correlative search half-width in x and y (m)."""
    search_step: float = bounded(0.1, gt=0.0, le=100.0)
    """Correlative search step in x and y (m)."""
    search_th: float = bounded(0.1, gt=0.0, le=math.pi)
    """Correlative search half-width in heading (rad)."""
    search_th_step: float = bounded(0.02, gt=0.0, le=math.pi)
    """Correlative search step in heading (rad)."""
    search_sigma: float = bounded(0.15, gt=0.0, le=10.0)
    """Sensor sigma of the correlative search (m): wide, to rank coarse offsets smoothly."""
    search_beams: int = bounded(60, ge=1, le=100000)
    """The correlative search scores about this many of the scan's beams (every
    ``⌊n / search_beams⌋``-th of its ``n``; all of them when ``n < 2·search_beams``)."""
    match_iteration_factor: int = bounded(2, ge=1, le=100)
    """Levenberg-Marquardt iterations of a loop match per level, in multiples of
    ``rbpf.max_iterations`` (a loop match starts further from its optimum than a filter match)."""
    submap_size: float = bounded(20.0, gt=0.0, le=10000.0)
    """Side of a loop submap when created (m), centred on node ``j``; it grows to hold its
    nodes' scans ..."""
    submap_grow_margin: float = bounded(10.0, ge=0.0, le=10000.0)
    """... by at least this much (m) each time."""
    submap_tiles: int = bounded(1024, ge=1, le=65536)
    """Tiles a loop submap's pool holds when created (it doubles when full)."""
    fit_distance: float = bounded(0.1, gt=0.0, le=10.0)
    """A beam fits when it lands within this distance (m) of a submap surface."""
    min_fit: float = bounded(0.5, ge=0.0, le=1.0)
    """Accept a loop closure when at least this fraction of the scan's beams fit."""
    min_beams: int = bounded(30, ge=0, le=100000)
    """... and at least this many."""
    unique_shift: float = bounded(1.0, ge=0.0, le=100.0)
    """A closure, local or global, must place its scan uniquely: moved this far (m) in any of
    16 directions, the scan must fit its submap clearly worse than where it matched
    (``unique_ratio``); 0: no such test."""
    unique_ratio: float = bounded(0.95, gt=0.0, le=10.0)
    """... that is, with fewer than this share of the beams that fit at the match (within
    ``fit_distance`` of a surface). A scan that fits as well a metre along a corridor says where
    across the corridor the robot was, not where along it (docs/accuracy.md, "Closures that could
    be a metre elsewhere")."""
    pass_path: float = bounded(15.0, ge=0.0, le=1e6)
    """A closure, local or global, must also place its scan uniquely on the earlier pass: on the
    map of the nodes within about this distance (m) of path of the matched node (but at least
    ``min_path / 2`` behind the keyframe), moved ``unique_shift`` to ``pass_shift`` metres in any
    of 32 directions, the scan must fit fewer than ``unique_ratio`` of the beams that fit where it
    matched (0: no such test).
    A corridor whose doors repeat every few metres fits a scan as well one period along, and a
    submap of one stretch may not hold the true place at all: mit-killian's corridors, where a
    filter 6 m off closed its loop on the wrong door (docs/accuracy.md, "Closures that fit as
    well a door further along")."""
    pass_shift: float = bounded(10.0, gt=0.0, le=1000.0)
    """See ``pass_path``: the farthest shift tried (m), in steps of ``pass_shift_step``."""
    pass_shift_step: float = bounded(0.25, ge=0.01, le=100.0)
    """See ``pass_shift``."""
    sigma_xy: float = bounded(0.02, gt=0.0, le=100.0)
    """Floor of a loop edge's standard deviation in x and y (m), added to the match's own."""
    sigma_th: float = bounded(0.005, gt=0.0, le=10.0)
    """Floor of a loop edge's standard deviation in heading (rad)."""
    robust: float = bounded(3.0, ge=0.0, le=1000.0)
    """Cauchy kernel width of loop edges, in standard deviations (wrong closures lose weight)."""
    seq_sigma_xy: float = bounded(0.01, gt=0.0, le=100.0)
    """Standard deviation of a sequential edge: this much (m) ..."""
    seq_sigma_th: float = bounded(0.005, gt=0.0, le=10.0)
    """... (rad) ..."""
    seq_sigma_rel: float = bounded(0.02, ge=0.0, le=10.0)
    """... plus this fraction of the edge's translation (and rotation): where the filter failed
    to close a loop, its drift is of this order, and the chain must be able to absorb it."""
    flex_factor: float = bounded(5.0, ge=1.0, le=1000.0)
    """The chain's sigmas are this many times larger across a stretch whose scans contradict the
    map of the others (``rbpf.repair_below``, :class:`slam.stages.Repair`): there the filter's
    relative poses are what is wrong, and the loop closures must be able to bend them."""
    min_correction: float = bounded(0.15, ge=0.0, le=1000.0)
    """Keep the filter's trajectory when the optimisation would move no node this far (m):
    loop edges are only about as precise as the filter's own relative poses, so they are used to
    repair gross inconsistencies (decimetres to metres), not to re-shape a closed map."""
    iterations: int = bounded(10, ge=1, le=1000)
    """Gauss-Newton iterations (at most; they stop when the poses stop moving) ..."""
    converged_xy: float = bounded(1e-3, gt=0.0, le=100.0)
    """... that is when no node's x or y moves more than this (m) in an iteration ..."""
    converged_th: float = bounded(1e-4, gt=0.0, le=math.pi)
    """... and no node's heading more than this (rad)."""
    solver_iterations: int = bounded(10000, ge=1, le=100000)
    """Conjugate-gradient iterations per Gauss-Newton step, at most: a bound, not a setting. The
    chain-preconditioned solve needs 0.2–0.8 × the keyframes (more where closures are dense), so
    a graph of 12,000 keyframes is solved to ``solver_tolerance``; a step the bound cuts short
    warns (the run's warnings, ``metrics.json``) ..."""
    solver_tolerance: float = bounded(1e-8, gt=0.0, le=1.0)
    """... stopping when the residual is this fraction of the right-hand side's norm."""
    rounds: int = bounded(2, ge=1, le=100)
    """Detection + optimisation rounds."""


@dataclass(frozen=True)
class BackendConfig(Validated):
    """Global loop search over submaps (``slam.backend``), added to the loop closing (rbpf only).

    The loop closing of ``[loops]`` looks for closures within ``loops.radius`` of the drifted
    estimate and ±``loops.search_xy``; after a long stretch without closure the drift is larger.
    This search registers keyframe scans against submaps by branch-and-bound over a window that
    grows with the path since the submap (``window_*``), verifies each match and keeps only
    closures that agree with another one (:mod:`slam.backend.global_loops`).
    """

    SECTION: ClassVar[str] = "backend"
    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(("window_xy_min", "window_xy_max"), lambda a, b: a <= b, "window_xy_min <= window_xy_max"),
        Rule(("window_th_min", "window_th_max"), lambda a, b: a <= b, "window_th_min <= window_th_max"),
        Rule(("window_xy_max", "far_window_xy_max"), lambda a, b: a <= b, "window_xy_max <= far_window_xy_max"),
    )  # fmt: skip

    global_search: bool = True
    """Run the global search (with ``loops.enabled``)."""
    keyframe_path: float = bounded(2.0, ge=0.01, le=10000.0)
    """Path (m) between two keyframes whose scans are searched for (at least 1 cm: the keyframes
    are laid along the path at this spacing, so a vanishing one would lay billions)."""
    submap_length: float = bounded(10.0, ge=0.1, le=10000.0)
    """Path (m) covered by one submap (consecutive node scans at their current poses; at least
    10 cm, for the same reason)."""
    submap_range: float = bounded(15.0, gt=0.0, le=1000.0)
    """Only hits within this distance (m) of their scan enter submaps and searched scans."""
    resolution: float = bounded(0.1, ge=0.01, le=1.0)
    """Cell size (m) of the branch-and-bound grids."""
    sigma: float = bounded(0.1, gt=0.0, le=10.0)
    """Width (m) of a hit's likelihood in the branch-and-bound grid."""
    levels: int = bounded(7, ge=1, le=12)
    """Levels of the max pyramid (the coarsest block is 2^(levels-1) cells wide)."""
    points: int = bounded(60, ge=10, le=10000)
    """Scan points scored by the search (evenly thinned)."""
    window_xy_min: float = bounded(1.0, gt=0.0, le=1000.0)
    """Half-width (m) of the search window, at least ..."""
    drift_xy: float = bounded(0.03, ge=0.0, le=10.0)
    """... plus this fraction of the path (m) between submap and keyframe ..."""
    window_xy_max: float = bounded(30.0, gt=0.0, le=1000.0)
    """... at most (m)."""
    window_th_min: float = bounded(0.1, gt=0.0, le=math.pi)
    """Half-width (rad) of the rotation window, at least ..."""
    drift_th: float = bounded(0.002, ge=0.0, le=1.0)
    """... plus this much (rad) per metre of path between submap and keyframe ..."""
    window_th_max: float = bounded(0.5, gt=0.0, le=math.pi)
    """... at most (rad)."""
    candidates: int = bounded(3, ge=1, le=1000)
    """Submaps searched per keyframe: those nearest relative to their window (see
    ``candidate_choice``)."""
    far_drift_xy: float = bounded(0.05, ge=0.0, le=10.0)
    """In the first round, the keyframes that no closure holds within ``agree_path`` of path
    (none found within the window, no local one) also search beyond the window, out to
    ``window_xy_min + far_drift_xy · path gap`` (at most ``far_window_xy_max``):
    ``far_candidates`` of those submaps each, taken in turn. A long loop whose drift exceeds
    the window (fr-clinic started at a third of its log: 31 m after 750 m) closes; where
    closures already hold the place, nothing is searched (0: no such search)."""
    far_window_xy_max: float = bounded(60.0, gt=0.0, le=1000.0)
    """See ``far_drift_xy`` (m)."""
    far_candidates: int = bounded(4, ge=0, le=1000)
    """See ``far_drift_xy``: submaps beyond the window each such keyframe searches."""
    candidate_choice: str = bounded("per_pass", choices=("nearest", "per_pass"))
    """How the ``candidates`` are chosen among the submaps whose window holds the keyframe:
    ``nearest``, nearest relative to their window; ``per_pass``, the nearest of each earlier
    pass through the place first (a pass: submaps next to each other along the path), then the
    nearest of the rest."""
    min_score: float = bounded(0.55, ge=0.0, le=1.0)
    """A match must score this mean likelihood in the branch-and-bound grid ..."""
    min_fit: float = bounded(0.6, ge=0.0, le=1.0)
    """... and, refined, put this share of its beams that land on the submap's known cells
    within ``loops.fit_distance`` of the submap's surfaces ..."""
    min_overlap: float = bounded(0.3, ge=0.0, le=1.0)
    """... those beams being at least this share of all the scan's beams."""
    agree_xy: float = bounded(0.3, gt=0.0, le=100.0)
    """Two closures agree when the corrections they imply move a keyframe to within this (m) ..."""
    agree_th: float = bounded(0.05, gt=0.0, le=math.pi)
    """... and this (rad) of each other, plus ``loops.seq_sigma_rel`` of the path between them."""
    agree_path: float = bounded(30.0, gt=0.0, le=1e6)
    """Closures whose keyframes lie within this path (m) of each other are compared."""
    chi2_gate: float = bounded(16.0, gt=0.0, le=1e6)
    """After optimising, a global closure whose error exceeds this χ² (3 dof) is dropped."""


MAX_CLASSIC_OFFSETS = 20000
"""Most pose offsets the classic method's local search may score per particle and scan."""


@dataclass(frozen=True)
class ClassicConfig(Validated):
    """The course's method: one shared map, map correlation with a local pose search."""

    SECTION: ClassVar[str] = "classic"
    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(
            ("xy_radius", "yaw_steps"),
            lambda r, s: (2 * r + 1) ** 2 * (2 * s + 1) <= MAX_CLASSIC_OFFSETS,
            f"(2·xy_radius+1)²·(2·yaw_steps+1) ≤ {MAX_CLASSIC_OFFSETS} offsets",
        ),
    )

    beams: int = bounded(270, ge=1, le=100000)
    """At most this many beams (evenly spread) are correlated."""
    xy_radius: int = bounded(4, ge=0, le=50)
    """Local search over ±xy_radius cells in x and y (the course's 9×9 grid)."""
    yaw_step: float = bounded(0.01, gt=0.0, le=math.pi)
    """Yaw step of the local search (rad)."""
    yaw_steps: int = bounded(2, ge=0, le=1000)
    """Yaw offsets −yaw_steps..yaw_steps times yaw_step."""
    temperature: float = bounded(10.0, ge=0.001, le=1e6)
    """Softmax temperature on the correlation counts (hundreds of beams: counts are large)."""
    snap_to_best: bool = False
    """Move each particle to its best local offset (the search then acts as a scan matcher);
    the course uses the best correlation only as the particle's score."""
    motion_floor: tuple[float, ...] = bounded((0.0005, 0.0005, 0.0005), length=3, ge=0.0, le=10.0)
    """Noise standard deviation added at every scan (m, m, rad); this method predicts at every
    scan, so its floor is smaller than the filter-wide one (used per update)."""
    log_odds_miss: float = bounded(-math.log(4.0), ge=-100.0, le=0.0)
    """The course's symmetric update: a miss removes what a hit adds (``±log 4``)."""


@dataclass(frozen=True)
class TextureConfig(Validated):
    """Floor texture mapping from RGB-D frames (docs/texture.md)."""

    SECTION: ClassVar[str] = "texture"
    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(("min_depth", "max_depth"), lambda lo, hi: lo < hi, "min_depth < max_depth"),
    )

    enabled: bool = True
    """Compute the texture map when the dataset has RGB-D frames."""
    mode: str = bounded("mean", choices=TEXTURE_MODES)
    """``"mean"``: running mean of every floor pixel that fell in a cell; ``"latest"``: the mean
    of the most recent frame that saw the cell."""
    floor_height: float = bounded(0.1, gt=0.0, le=10.0)
    """A point is floor when its height above the floor plane is within ± this (m)."""
    min_depth: float = bounded(0.4, ge=0.0, le=100.0)
    """Nearest depth used (m): the Kinect measures nothing closer."""
    max_depth: float = bounded(4.0, gt=0.0, le=100.0)
    """Farthest depth used (m): beyond, depth quantisation and pose errors blur the texture."""
    pair_tolerance_s: float = bounded(0.1, ge=0.0, le=3600.0)
    """An RGB frame is used only with a disparity frame at most this far away in time (s)."""
    frame_stride: int = bounded(1, ge=1, le=1000000)
    """Use every k-th RGB frame."""
    pixel_stride: int = bounded(1, ge=1, le=1000)
    """Use every k-th row and column of the disparity image."""
    motion_compensation: bool = True
    """Look colours up from the robot pose at the RGB frame's time (the points come from the pose
    at the disparity frame's time); off: both from the disparity pose."""
    read_threads: int = bounded(2, ge=1, le=64)
    """Threads decoding PNG frames ahead of the accumulation."""
    camera_x: float = bounded(0.18, ge=-10.0, le=10.0)
    """Kinect position ahead of the robot centre (m), course project text."""
    camera_y: float = bounded(0.005, ge=-10.0, le=10.0)
    """Kinect position to the left of the robot centre (m)."""
    camera_z: float = bounded(0.36, ge=-10.0, le=10.0)
    """Kinect height above the floor (m)."""
    camera_roll: float = bounded(0.0, ge=-TAU, le=TAU)
    """Kinect roll (rad)."""
    camera_pitch: float = bounded(0.36, ge=-TAU, le=TAU)
    """Kinect pitch (rad), positive looks down."""
    camera_yaw: float = bounded(0.021, ge=-TAU, le=TAU)
    """Kinect yaw relative to the robot heading (rad), positive looks left."""


@dataclass(frozen=True)
class QualityConfig(Validated):
    """Map quality without ground truth (docs/evaluation.md, "Map quality without ground truth")."""

    SECTION: ClassVar[str] = "quality"

    enabled: bool = True
    """``slam run`` scores its map at the end (metrics.json ``quality``, ``quality.png``)."""
    resolution: float = bounded(0.1, ge=0.005, le=10.0)
    """Cell size of the count grids the score uses (m): half the map's resolution halves the
    cost and changes the figures by about 0.01 (docs/evaluation.md)."""
    stretch_m: float = bounded(10.0, ge=0.1, le=1e6)
    """A stretch is this much path (m) of consecutive scans."""
    separation_m: float = bounded(10.0, ge=0.0, le=1e6)
    """A stretch is judged against the scans more than this much path (m) away from it."""
    max_range_m: float = bounded(10.0, gt=0.0, le=MAX_RANGE_M)
    """Rays are cut at this range (m): farther returns are not judged and clear space only up
    to here (far points are placed too loosely: 0.3° of heading moves a point 5 cm at 10 m)."""
    tolerance_m: float = bounded(0.15, gt=0.0, le=100.0)
    """An endpoint agrees when a surface of the other stretches lies within this distance (m)."""
    min_free_rays: int = bounded(2, ge=1, le=1000000)
    """A cell counts as seen free when at least this many rays of the others crossed it (and its
    log-odds are negative)."""
    min_incidence_deg: float = bounded(15.0, ge=0.0, lt=90.0)
    """Beams meeting their surface at less than this angle are not tested for passing through
    the others' surfaces (a grazing beam skims the wall it ends on)."""
    max_offset_m: float = bounded(2.0, ge=0.0, le=1000.0)
    """How far past a conflicting endpoint the others' surface is looked for (m)."""
    min_checked: int = bounded(200, ge=0)
    """A stretch is ranked only when at least this many of its returns were judged ..."""
    min_coverage: float = bounded(0.1, ge=0.0, le=1.0)
    """... and at least this share of them."""
    flag_below: float = bounded(0.8, ge=0.0, le=1.0)
    """A ranked stretch whose score is below this is flagged as inconsistent."""
    worst: int = bounded(5, ge=0, le=1000)
    """How many of the worst stretches are reported and marked on ``quality.png``."""
    warn_below: float = bounded(0.75, ge=0.0, le=1.0)
    """``slam run`` warns when its map's score is below this: stretches of the map contradict
    each other (a loop left open or closed wrongly, or the filter lost track; 0: never). Under
    every default run measured (0.78–0.995 on the six benchmark logs, seeds 0–11), above a run
    whose long loop stayed open (0.67) and the odometry alone (0.29–0.51; docs/evaluation.md)."""


@dataclass(frozen=True)
class VizConfig(Validated):
    """Rerun recording of a run."""

    SECTION: ClassVar[str] = "viz"

    record: bool = True
    """Write ``recording.rrd`` in the run folder."""
    map_every: int = bounded(200, ge=0)
    """Scans between snapshots of the live occupancy map (0: only the final map)."""
    detail_every: int = bounded(10, ge=0)
    """Scans between logged particle sets, scan endpoints and scans/s values (0: never)."""
    scan_points: int = bounded(180, ge=1, le=100000)
    """At most this many endpoints (evenly spread) of a logged scan."""
    map_levels: int = bounded(16, ge=2, le=256)
    """Grey levels of the logged map images (fewer levels make smaller recordings)."""
    preview_cells: int = bounded(8_000_000, ge=1)
    """At most this many cells in the live map the snapshots are drawn from: a larger one is
    coarsened, its cells doubled (:meth:`slam.mapping.OccupancyGrid.coarsened`), so a large
    building's recording holds neither a full-size preview grid nor full-size snapshots
    (mit-killian: 32.8 M cells at 5 cm, docs/viz.md "Memory"); the final map is logged at full
    size."""


@dataclass(frozen=True)
class ChecksConfig(Validated):
    """Plausibility checks of the input and of the run's size (docs/data.md, docs/slam.md)."""

    SECTION: ClassVar[str] = "checks"

    min_valid_beams: int = bounded(20, ge=1, le=100000)
    """A scan with fewer valid beams (finite readings in [range_min, range_max): obstacle hits a
    scan matcher can use) than this is "sparse"; the benchmark logs' sparsest scan has 72."""
    max_sparse_scan_share: float = bounded(0.1, ge=0.0, le=1.0)
    """Warn (stderr and ``metrics.json``) when more than this share of the processed scans are
    sparse; a log where no scan has a valid beam is an error."""
    max_backward_share: float = bounded(0.25, ge=0.0, le=1.0)
    """A stream whose timestamps step backwards at more than this share of its steps is an error
    (CARMEN logs step back now and then: intel 631 of 13630 steps, 4.6 %); fewer are a warning."""
    min_time_overlap: float = bounded(0.5, ge=0.0, le=1.0)
    """At least this share of the scans (and of the encoder readings) must lie within the time
    span of the stream they are paired with (encoders, IMU); less means the clocks differ."""
    strict_time: bool = True
    """Time-base errors (a stream mostly stepping backwards, a stream whose timestamps are all
    equal, streams that do not overlap) stop the run; false turns them into warnings."""
    max_speed: float = bounded(10.0, gt=0.0, le=1e6)
    """Odometry moving faster than this between consecutive readings (m/s, time steps floored at
    the stream's median step) is a corrupt reading, an error naming it; the fastest step of the
    benchmark logs is 4.5 m/s (mit-csail)."""
    max_memory_share: float = bounded(0.5, gt=0.0, le=1.0)
    """Refuse, before allocating, a run whose estimated memory exceeds this share of the
    machine's physical memory (or of the cgroup's limit, when lower)."""


def _is_mixture(z_hit: float, z_rand: float, z_max: float) -> bool:
    return abs(z_hit + z_rand + z_max - 1.0) <= 1e-9


@dataclass(frozen=True)
class LocalizeConfig(Validated):
    """``slam localize``: Monte Carlo localization on a saved map, global localization by an exact
    histogram filter, recovery from a lost robot (docs/localize.md). The motion model is the
    filter's (``filter.motion_alphas``, ``filter.motion_floor``)."""

    SECTION: ClassVar[str] = "localize"
    RULES: ClassVar[tuple[Rule, ...]] = (
        Rule(("z_hit", "z_rand", "z_max"), _is_mixture, "z_hit + z_rand + z_max = 1"),
        Rule(
            ("min_particles", "max_particles"),
            lambda lo, hi: lo <= hi,
            "min_particles <= max_particles",
        ),
        Rule(
            ("min_particles", "global_particles", "max_particles"),
            lambda lo, n, hi: lo <= n <= hi,
            "min_particles <= global_particles <= max_particles",
            blame=("global_particles",),
        ),
    )

    update_distance: float = bounded(0.2, gt=0.0, le=100.0)
    """Run a particle update after this much travel since the last one (m) ..."""
    update_angle: float = bounded(0.1, gt=0.0, le=TAU)
    """... or this much rotation (rad); scans in between move the estimate by odometry only."""
    beams: int = bounded(60, ge=1, le=100000)
    """At most this many returns (evenly spread) weight the particles."""
    sigma_hit: float = bounded(0.1, gt=0.0, le=10.0)
    """Standard deviation of the likelihood field's Gaussian term (m)."""
    z_hit: float = bounded(0.9, gt=0.0, le=1.0)
    """Mixture weight of the Gaussian (hit) term of the beam model."""
    z_rand: float = bounded(0.05, gt=0.0, le=1.0)
    """Mixture weight of the uniform term over ``[0, range_max]`` (unexplained readings)."""
    z_max: float = bounded(0.05, ge=0.0, le=1.0)
    """Mixture weight of the point mass at ``range_max`` (no return); ``z_hit + z_rand + z_max``
    must be 1."""
    temperature: float = bounded(4.0, ge=1.0, le=1000.0)
    """Scan log-likelihoods are divided by this before weighting (beams are not independent)."""
    subdivision: int = bounded(2, ge=1, le=8)
    """MCL and the pose refinement read the distance to the walls at sub-cell precision on a
    grid this many times finer than the map (:func:`slam.localize.maps.wall_surface`; memory
    grows with its square)."""
    field_max: float = bounded(2.0, gt=0.0, le=100.0)
    """Distances to the nearest wall are tabulated up to this far (m); beyond, the Gaussian term
    is 0 anyway."""
    refine_iterations: int = bounded(10, ge=0, le=1000)
    """Levenberg-Marquardt steps that refine the reported pose on the likelihood field (the most
    likely pose near the candidates; 0: the particles' mean itself)."""
    refine_beams: int = bounded(180, ge=1, le=100000)
    """At most this many returns (evenly spread) refine the pose."""
    inject_share: float = bounded(0.05, ge=0.0, le=0.5)
    """At each update this share of the predicted particles is drawn around the scan-matched
    pose instead (sensor resetting; 0: off)."""
    min_particles: int = bounded(200, ge=1, le=1000000)
    """KLD-sampling never draws fewer particles than this ..."""
    max_particles: int = bounded(10000, ge=1, le=1000000)
    """... nor more than this (also the size of the initial cloud around ``--initial``)."""
    kld_epsilon: float = bounded(0.05, gt=0.0, le=1.0)
    """KLD-sampling: largest Kullback-Leibler distance between the sample and the posterior."""
    kld_delta: float = bounded(0.01, gt=0.0, lt=1.0)
    """KLD-sampling: the bound holds with probability ``1 − kld_delta``."""
    kld_bin_xy: float = bounded(0.2, gt=0.0, le=100.0)
    """KLD-sampling histogram bin size in x and y (m)."""
    kld_bin_theta: float = bounded(0.1745, gt=0.0, le=TAU)
    """KLD-sampling histogram bin size in heading (rad, 10°)."""
    initial_sigma_xy: float = bounded(1.0, gt=0.0, le=1000.0)
    """Standard deviation of the initial particle cloud in x and y (m), when ``--initial`` gives
    no sigma."""
    initial_sigma_theta: float = bounded(0.35, gt=0.0, le=TAU)
    """Standard deviation of the initial particle cloud in heading (rad, 20°)."""
    localized_std_xy: float = bounded(0.15, gt=0.0, le=100.0)
    """The robot counts as localized when the particles' standard deviation in x and y is at
    most this (m) ..."""
    localized_std_theta: float = bounded(0.05, gt=0.0, le=TAU)
    """... and in heading at most this (rad), in the tracking phase."""
    global_resolution: float = bounded(0.25, gt=0.0, le=10.0)
    """Cell size of the global histogram filter (m), rounded to the nearest whole number of the
    map's cells (at least one): 0.25 on a 0.05 m map, 0.3 on a 0.1 m map."""
    global_headings: int = bounded(36, ge=4, le=3600)
    """Heading bins of the global histogram filter."""
    global_beams: int = bounded(30, ge=1, le=100000)
    """At most this many returns weight the histogram filter's states."""
    global_temperature: float = bounded(4.0, ge=1.0, le=1000.0)
    """The histogram filter's log-likelihoods are divided by this."""
    global_update_distance: float = bounded(0.3, gt=0.0, le=100.0)
    """The histogram filter steps after this much travel (m) ..."""
    global_update_angle: float = bounded(0.2, gt=0.0, le=TAU)
    """... or this much rotation (rad)."""
    global_min_free: float = bounded(0.5, gt=0.0, le=1.0)
    """A histogram cell is a state when at least this share of its map cells is known free."""
    global_mode_share: float = bounded(0.9, gt=0.0, le=1.0)
    """Global localization ends when one mode holds this share of the probability ..."""
    global_mode_radius: float = bounded(0.5, gt=0.0, le=100.0)
    """... a mode being the states within this distance (m) ..."""
    global_mode_angle: float = bounded(0.35, ge=0.0, le=math.pi)
    """... and this heading difference (rad) of the most probable state."""
    global_particles: int = bounded(5000, ge=1, le=1000000)
    """Particles drawn from the mode's states when MCL takes over ..."""
    relocalize_quality: float = bounded(0.8, ge=0.0, le=1.0)
    """... provided the scan matches at the mode's refined centre with at least this quality
    (the geometric mean per-beam likelihood over its largest value): a mode the map explains
    poorly is a guess, not a place."""
    recovery: bool = True
    """Watch the match quality and re-localize globally when the robot is lost."""
    alpha_slow: float = bounded(0.01, gt=0.0, le=1.0)
    """Augmented MCL: rate of the long-term average of the match quality."""
    alpha_fast: float = bounded(0.2, gt=0.0, le=1.0)
    """Augmented MCL: rate of the short-term average."""
    lost_ratio: float = bounded(0.5, gt=0.0, lt=1.0)
    """The robot is lost when the short-term average falls below this fraction of the long-term
    one."""
    monitor_warmup: int = bounded(10, ge=0, le=1000000)
    """Updates after (re)localization before the lost test applies."""
    kidnap_prior: float = bounded(0.01, ge=0.0, lt=1.0)
    """Probability that the robot was carried anywhere since the last histogram step: each
    prediction spreads this share of the mass over every state. When the robot is lost, the
    histogram filter also starts from this much spread over the whole map and the rest around
    the tracked pose (``global_mode_radius``, ``global_mode_angle``, or the particles' spread
    when wider): a real kidnapping soon shows, a poorly mapped stretch does not throw the pose
    away."""


@dataclass(frozen=True)
class Config:
    """The whole configuration of a run."""

    dataset: str = ""
    """Dataset name this configuration was resolved for."""
    robot: RobotConfig = field(default_factory=RobotConfig)
    lidar: LidarConfig = field(default_factory=LidarConfig)
    map: MapConfig = field(default_factory=MapConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    rbpf: RbpfConfig = field(default_factory=RbpfConfig)
    classic: ClassicConfig = field(default_factory=ClassicConfig)
    loops: LoopConfig = field(default_factory=LoopConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)
    texture: TextureConfig = field(default_factory=TextureConfig)
    quality: QualityConfig = field(default_factory=QualityConfig)
    viz: VizConfig = field(default_factory=VizConfig)
    checks: ChecksConfig = field(default_factory=ChecksConfig)
    localize: LocalizeConfig = field(default_factory=LocalizeConfig)


def section_types() -> dict[str, type]:
    """The sections of :class:`Config` and their dataclasses."""
    return {name: tp for name, tp in field_types(Config).items() if dataclasses.is_dataclass(tp)}


class Override(str):
    """A ``section.key=value`` override (the string itself) that an option set rather than
    ``--set`` (``--every 0`` sets ``filter.every=0``): a message about its value names
    :attr:`option`, what the user typed. Anything that takes override strings takes it."""

    option: str
    """What set it, as the user typed it: ``--every 0``, ``slam.run(every=0)``."""

    def __new__(cls, text: str, option: str) -> Override:
        """The override ``text`` set by ``option``."""
        self = super().__new__(cls, text)
        self.option = option
        return self

    def __getnewargs__(self) -> tuple[str, str]:  # type: ignore[override]
        """What pickling needs to rebuild it (a plain ``str`` pickles its text only)."""
        return (str(self), self.option)


def override_list(overrides: Iterable[str]) -> list[str]:
    """``overrides`` as a list, refused with one :class:`UsageError` when it is not a list of
    ``section.key=value`` strings (a single string would be read character by character)."""
    expected = "overrides: expected a list of 'section.key=value' strings"
    if isinstance(overrides, str):
        raise UsageError(f"{expected}, found the string {overrides!r}")
    if isinstance(overrides, (bytes, bytearray, Mapping)):
        raise UsageError(f"{expected}, found {type(overrides).__name__}")
    try:
        items = list(overrides)
    except TypeError:
        raise UsageError(f"{expected}, found {type(overrides).__name__}") from None
    wrong = next((x for x in items if not isinstance(x, str)), None)
    if wrong is not None:
        raise UsageError(f"{expected}, found an item {wrong!r} ({type(wrong).__name__})")
    return items


def parse_override(text: str) -> tuple[str, str, Any]:
    """Parse ``section.key=value`` (value a TOML literal, else a bare string)."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise ConfigError(f"--set {text!r}: expected section.key=value, e.g. filter.particles=100")
    lhs, raw = text.split("=", 1)
    section, key = lhs.strip().split(".", 1)
    try:
        return section, key, parse_literal(raw)
    except ConfigError as exc:
        raise ConfigError(f"--set {lhs.strip()}: {exc}") from None


def read_toml(path: Path) -> dict[str, Any]:
    """Read a TOML config file, turning I/O, encoding and syntax errors into :class:`ConfigError`."""
    return _read_toml(Path(path), "config file")


@dataclass
class _Layers:
    """Raw section values being merged, and which layer set each key last."""

    values: dict[str, dict[str, Any]]
    origin: dict[tuple[str, str], tuple[int, str]] = field(default_factory=dict)
    dataset: str = ""
    options: set[str] = field(default_factory=set)
    """The sources that are options (:class:`Override`), not files or ``--set``."""

    def apply(self, table: Mapping[str, Any], source: str) -> None:
        sections = section_types()
        layer = len({index for index, _ in self.origin.values()}) + 1
        for key, value in table.items():
            if key == "dataset":
                self.dataset = coerce(value, str, source, "dataset")
                continue
            if key not in sections and not isinstance(value, Mapping):
                raise ConfigError(outside_sections(source, key))
            if key not in sections:
                raise ConfigError(
                    f"{source}: unknown section [{key}]; expected one of "
                    f"{', '.join(sorted(sections))}"
                )
            if not isinstance(value, Mapping):
                raise ConfigError(f"{source}: [{key}] must be a table, found {value!r}")
            types_ = field_types(sections[key])
            for name, raw in value.items():
                if name not in types_:
                    raise ConfigError(
                        f"{source}: {key}.{name}: unknown key; expected one of "
                        f"{', '.join(sorted(types_))}"
                    )
                self.values[key][name] = coerce(raw, types_[name], source, f"{key}.{name}")
                self.origin[(key, name)] = (layer, source)

    def build(self, base: Config) -> Config:
        sections = section_types()
        built = {}
        for name, cls in sections.items():
            try:
                built[name] = cls(**self.values[name])
            except FieldError as exc:
                keys = [re.split(r"[\[.]", f, maxsplit=1)[0] for f in exc.fields]
                set_by = [self.origin[(name, k)] for k in keys if (name, k) in self.origin]
                source = max(set_by)[1] if set_by else ""
                if source in self.options and len(exc.fields) == 1:  # `--every 0: expected ...`
                    raise ConfigError(f"{source}: {exc.detail}") from None
                raise ConfigError(f"{source}: {exc}" if source else str(exc)) from None
        return dataclasses.replace(base, dataset=self.dataset or base.dataset, **built)


def outside_sections(source: str, key: str) -> str:
    """The message of a key ``key`` of ``source`` (a TOML file) outside any section: the section
    it belongs to when exactly one has such a key, else the sections there are."""
    sections = section_types()
    owners = [name for name, cls in sections.items() if key in field_types(cls)]
    if len(owners) == 1:
        return (
            f"{source}: {key!r} is a key outside any section; expected [section] tables such as "
            f"[{owners[0]}] (did you mean {owners[0]}.{key}?)"
        )
    owned = f" ({key!r} is a key of {', '.join(f'[{o}]' for o in owners)})" if owners else ""
    return (
        f"{source}: {key!r} is a key outside any section; expected [section] tables, one of "
        f"{', '.join(f'[{name}]' for name in sorted(sections))}{owned}"
    )


def case_variant(dataset: str) -> str | None:
    """The shipped configuration (``configs/<name>.toml``) whose name differs from ``dataset``
    only by letter case or surrounding spaces (``intel`` for ``Intel`` or ``intel ``), else
    ``None`` (also when one is ``dataset``)."""
    shipped = [path.stem for path in sorted(config_dir().glob("*.toml"))]
    if not dataset or dataset in shipped:
        return None
    wanted = dataset.strip().casefold()
    return next((name for name in shipped if name.casefold() == wanted), None)


def shipped_config(dataset: str) -> Path | None:
    """``configs/<dataset>.toml`` when the project ships it, else ``None`` (a log of one's own
    runs on the defaults). A name that differs from a shipped configuration's only by letter case
    (``Intel``) is a :class:`ConfigError` naming both, not the defaults."""
    if dataset and dataset.endswith(".toml"):  # a path to a log is fine: its defaults
        raise ConfigError(
            f"dataset {dataset!r}: expected a dataset's name such as 'intel'; a configuration "
            "file is given as config_file (--config FILE)"
        )
    near = case_variant(dataset)
    if near is not None:
        raise ConfigError(f"no configuration {dataset!r}; did you mean {near!r}?")
    path = config_dir() / f"{dataset}.toml"
    return path if dataset and path.is_file() else None


def load_config(
    dataset: str = "",
    config_file: Path | None = None,
    overrides: Iterable[str] = (),
    base: Config | None = None,
) -> Config:
    """Resolve the configuration of a run (defaults, dataset config, file, overrides).

    Each layer's keys and types are checked as it is read; bounds and cross-field rules once, on
    the merged result (see the module docstring). ``dataset`` names its shipped configuration
    (:func:`shipped_config`: none is the defaults, a wrong letter case an error); ``overrides``
    is a list of ``section.key=value`` strings (a message names ``--set <it>``, or the option
    of an :class:`Override`).
    """
    overrides = override_list(overrides)
    base = base or Config()
    layers = _Layers({name: dataclasses.asdict(getattr(base, name)) for name in section_types()})
    for name in section_types():  # asdict turns tuples into lists; keep the declared types
        layers.values[name] = {
            f.name: getattr(getattr(base, name), f.name)
            for f in dataclasses.fields(getattr(base, name))
        }
    shipped = shipped_config(dataset)
    if shipped is not None:
        layers.apply(read_toml(shipped), str(shipped))
    if config_file is not None:
        layers.apply(read_toml(Path(config_file)), str(config_file))
    for text in overrides:
        section, key, value = parse_override(text)
        if isinstance(text, Override):
            source = text.option
            layers.options.add(source)
        else:
            source = f"--set {text if text.isprintable() else repr(text)}"
        layers.apply({section: {key: value}}, source)
    config = layers.build(base)
    if dataset:
        config = dataclasses.replace(config, dataset=dataset)
    return config


def config_for(owner: str, config: Config | None, seed: int | None = None) -> Config:
    """The configuration an object ``owner`` (``"Slam"``, ``"Localizer"``) is built with:
    ``Config()`` for None, a :class:`UsageError` for anything that is not a :class:`Config`,
    ``filter.seed`` replaced by ``seed`` when given."""
    from slam.errors import UsageError

    config = Config() if config is None else config
    if not isinstance(config, Config):
        raise UsageError(
            f"{owner}(config): expected a slam.Config (slam.load_config(...)), found "
            f"{type(config).__name__}"
        )
    if seed is not None:
        value = seed_value(owner, seed)
        if value < 0:
            raise UsageError(f"{owner}(seed): expected an integer ≥ 0, found {seed!r}")
        config = dataclasses.replace(config, filter=dataclasses.replace(config.filter, seed=value))
    return config


def seed_value(owner: str, seed: object) -> int:
    """``seed`` as the integer it is, or one :class:`UsageError` naming ``owner`` (``1.9`` is not
    silently 1, ``"x"`` not a bare ``ValueError``; the range is the configuration's to check)."""
    from slam.errors import UsageError

    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise UsageError(f"{owner}(seed): expected an integer ≥ 0, found {seed!r}")
    return int(seed)


def to_dict(config: Any) -> dict[str, Any]:
    """Nested plain-dict view of a config dataclass."""
    return dataclasses.asdict(config)


_TOML_ESCAPES = {
    "\\": "\\\\",
    '"': '\\"',
    "\n": "\\n",
    "\t": "\\t",
    "\r": "\\r",
    "\b": "\\b",
    "\f": "\\f",
}


def _escape_control(char: str) -> str:
    """A character of a TOML basic string: control characters as ``\\uXXXX``."""
    code = ord(char)
    return f"\\u{code:04x}" if code < 0x20 or code == 0x7F else char


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        if math.isnan(value):
            return "nan"
        return repr(value)
    if isinstance(value, str):
        return '"' + "".join(_TOML_ESCAPES.get(c) or _escape_control(c) for c in value) + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise ConfigError(f"cannot write {value!r} to TOML")


def dumps(config: Config) -> str:
    """Serialise a configuration to TOML text that :func:`load_config` reads back identically."""
    lines = ["# Resolved configuration of this run (slam).", ""]
    data = to_dict(config)
    lines.append(f"dataset = {_toml_value(data.pop('dataset'))}")
    for section, table in data.items():
        lines.append("")
        lines.append(f"[{section}]")
        for key, value in table.items():
            if value is None:
                lines.append(f"# {key} unset: taken from the log")
            else:
                lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"
