"""Configuration: one frozen dataclass per concern, loaded from TOML, overridable from the CLI.

Every number an algorithm uses lives here with its default and a one-line reason. A run resolves
its configuration in this order, later wins:

1. the dataclass defaults below;
2. ``configs/<dataset>.toml`` shipped with the project (sensor geometry per log);
3. ``--config FILE``;
4. ``--set section.key=value`` overrides (values parsed as TOML literals, never evaluated).

The resolved configuration is written next to every run's outputs as ``config.toml``, so a run can
be repeated exactly with ``slam run NAME --config RUN_DIR/config.toml``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from slam.errors import ConfigError
from slam.resources import config_dir

METHODS = ("odometry", "classic", "rbpf")
"""Estimation methods of ``slam run``."""

TEXTURE_MODES = ("mean", "latest")
"""Accumulation modes of the floor texture (``texture.mode``, ``slam texture --mode``)."""


def _check_choice(name: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ConfigError(f"{name}: expected one of {', '.join(choices)}, found {value!r}")


@dataclass(frozen=True)
class RobotConfig:
    """Differential-drive robot geometry and odometry settings."""

    meters_per_tick: float = math.pi * 0.254 / 360.0
    """Wheel travel per encoder tick: wheel diameter 0.254 m, 360 ticks per revolution."""
    track_width: float = 0.3937
    """Effective skid-steer track width (m), used only when yaw comes from the wheels."""
    yaw_source: str = "imu"
    """Where yaw rate comes from: ``"imu"`` (z gyro, the course's model) or ``"encoders"``."""
    imu_lowpass_hz: float = 10.0
    """Cut-off of the low-pass filter on the gyro z rate (Hz); 0 disables filtering."""
    max_imu_gap_s: float = 0.1
    """Longest stretch past the IMU's last sample that odometry may hold the last rate (s)."""

    def __post_init__(self) -> None:
        _check_choice("robot.yaw_source", self.yaw_source, ("imu", "encoders"))


@dataclass(frozen=True)
class LidarConfig:
    """2D laser geometry and range semantics. ``None`` means: take it from the log."""

    x: float = 0.13323
    """Laser position ahead of the robot centre (m)."""
    y: float = 0.0
    """Laser position to the left of the robot centre (m)."""
    yaw: float = 0.0
    """Laser heading relative to the robot heading (rad)."""
    fov_deg: float | None = None
    """Field of view (degrees) for logs whose lines carry no geometry (CARMEN FLASER)."""
    range_min: float | None = None
    """Shortest valid range (m); shorter readings are invalid beams."""
    range_max: float | None = None
    """Longest range used as an obstacle hit (m); longer readings clear space only."""
    no_return: float | None = None
    """Readings at or beyond this (m) mean "no return" (e.g. 80 m on intel)."""
    use_log_laser_pose: bool = True
    """CARMEN: derive the laser offset from the laser and odometry poses written in each line."""


@dataclass(frozen=True)
class MapConfig:
    """Occupancy grid geometry and log-odds update."""

    resolution: float = 0.05
    """Cell size (m)."""
    initial_size_m: float = 40.0
    """Side of the square map allocated at start (m); the map grows on demand."""
    grow_margin_m: float = 10.0
    """Extra room added on each side when the map must grow (m)."""
    log_odds_hit: float = math.log(4.0)
    """Log-odds added to a cell where a beam ends."""
    log_odds_miss: float = -0.4
    """Log-odds added to cells a beam passes through (smaller than a hit, so a wall is not
    erased by the rays that graze it)."""
    log_odds_min: float = -10.0
    """Lower clamp of the log-odds."""
    log_odds_max: float = 10.0
    """Upper clamp of the log-odds."""
    occupied_threshold: float = 0.0
    """Log-odds above which a cell counts as occupied in correlation and rendering."""
    free_range_no_return: float = 0.0
    """"No return" beams clear free space up to this range (m); 0 leaves them out."""
    free_beam_stride: int = 1
    """Cast free-space rays for every k-th beam only (hits are always integrated)."""
    crop_margin_m: float = 2.0
    """The output map is cropped to the observed cells plus this margin (m)."""


@dataclass(frozen=True)
class FilterConfig:
    """Particle filter settings shared by both methods."""

    method: str = "rbpf"
    """``"rbpf"`` (default: per-particle maps, scan-matching proposal), ``"classic"`` (the course's
    single-map correlation filter) or ``"odometry"`` (dead reckoning)."""
    particles: int = 30
    """Number of particles."""
    seed: int = 0
    """Seed of the single random generator of a run."""
    every: int = 1
    """Process every k-th scan."""
    max_scans: int = 0
    """Stop after this many processed scans (0: all)."""
    resample_threshold: float = 0.5
    """Resample when N_eff falls below this fraction of the particle count."""
    motion_alphas: tuple[float, ...] = (0.1, 0.05, 0.05, 0.1, 0.02)
    """Odometry noise: σx = a0·d + a1·|dθ|, σy = a2·d + a1·|dθ|, σθ = a3·|dθ| + a4·d."""
    motion_floor: tuple[float, ...] = (0.002, 0.002, 0.002)
    """Noise standard deviation added to every update (m, m, rad), for particle diversity."""

    def __post_init__(self) -> None:
        _check_choice("filter.method", self.method, METHODS)
        if self.particles < 1:
            raise ConfigError(f"filter.particles: expected at least 1, found {self.particles}")
        if self.every < 1:
            raise ConfigError(f"filter.every: expected at least 1, found {self.every}")
        if self.max_scans < 0:
            raise ConfigError(f"filter.max_scans: expected 0 or more, found {self.max_scans}")
        if self.seed < 0:
            raise ConfigError(f"filter.seed: expected 0 or more, found {self.seed}")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ConfigError(
                f"filter.resample_threshold: expected 0..1, found {self.resample_threshold}"
            )
        if len(self.motion_alphas) != 5:
            raise ConfigError(
                f"filter.motion_alphas: expected 5 numbers, found {len(self.motion_alphas)}"
            )
        if len(self.motion_floor) != 3:
            raise ConfigError(
                f"filter.motion_floor: expected 3 numbers, found {len(self.motion_floor)}"
            )


@dataclass(frozen=True)
class RbpfConfig:
    """The default method: Rao-Blackwellised particles, each with its own distance-field map."""

    update_distance: float = 0.2
    """Run a filter update after this much travel since the last one (m)."""
    update_angle: float = 0.1
    """... or after this much rotation (rad). Scans in between move particles by odometry only."""
    update_interval_s: float = 0.3
    """... or, once this long has passed since the last update (counted in scans × the median
    scan period), after any motion beyond ``update_min_motion``; 0 disables this rule."""
    update_min_motion: float = 0.02
    """Least motion (m, and rad) for the interval rule: a standing robot is never updated."""
    match_beams: int = 180
    """At most this many beams (evenly spread) are used for scan matching and weighting."""
    insert_beams: int = 360
    """At most this many beams are inserted into the particle maps per update."""
    tile: int = 16
    """Tile side (cells, a power of two) of the copy-on-write particle maps."""
    resolution: float = 0.0
    """Cell size of the particle maps (m); 0 uses ``map.resolution``."""
    field: str = "distance"
    """Particle-map field: ``"distance"`` (Euclidean distance to the nearest hit) or ``"plane"``
    (signed point-to-plane distance, with normals from neighbouring beams)."""
    dmax: float = 0.3
    """Truncation of the distance field (m): beams further from any surface carry no gradient."""
    sigmas: tuple[float, ...] = (0.2, 0.075, 0.04)
    """Scan-matching sensor sigmas (m), wide to narrow; the last one scores the particles."""
    z_hit: float = 1.0
    """Weight of the Gaussian term of the likelihood field model."""
    z_rand: float = 0.05
    """Weight of the uniform (unexplained beam) term of the likelihood field model."""
    max_iterations: int = 5
    """Levenberg-Marquardt iterations per sigma level."""
    coarse_stride: int = 1
    """The wide sigma levels use every k-th beam (the last level always uses all of them)."""
    tolerance: float = 1e-3
    """A sigma level ends when a step moves less than this (m, and rad)."""
    min_inliers: float = 0.3
    """Keep the predicted pose when fewer beams than this fraction lie near known surfaces."""
    temperature: float = 10.0
    """Log-likelihoods are divided by this before weighting (beams are not independent)."""
    proposal_spread: float = 0.3
    """Particles are drawn around their matched pose with covariance ``proposal_spread ·
    (H / temperature + Σ_motion⁻¹)⁻¹`` (``H`` the matcher's Hessian, ``Σ_motion`` the odometry
    model's covariance); 0 keeps the matched pose."""
    proposal_motion_prior: bool = False
    """Include the odometry model in the proposal's covariance (else the scan likelihood alone,
    with a unit ridge)."""
    refine_passes: int = 3
    """After the filter, re-register the update scans of the final lineage against the map they
    build this many times (removes the jitter the proposal's sampling leaves; 0: off)."""
    skip_insert_below: float = 0.02
    """A hit closer than this (m) to an existing surface adds nothing to a particle's map."""

    def __post_init__(self) -> None:
        if not self.sigmas or any(s <= 0 for s in self.sigmas):
            raise ConfigError(f"rbpf.sigmas: expected positive numbers, found {self.sigmas}")
        if self.tile < 2 or self.tile & (self.tile - 1):
            raise ConfigError(f"rbpf.tile: expected a power of two (8, 16, 32), found {self.tile}")
        if self.temperature <= 0:
            raise ConfigError(f"rbpf.temperature: expected > 0, found {self.temperature}")
        _check_choice("rbpf.field", self.field, ("distance", "plane"))


@dataclass(frozen=True)
class LoopConfig:
    """Loop closing after the filter: a pose graph with scan-matched loop edges (rbpf only)."""

    enabled: bool = True
    """Run the stage."""
    stride: int = 5
    """Look for a loop closure at every k-th node (filter update)."""
    radius: float = 3.0
    """A candidate is the nearest earlier node within this distance (m) ..."""
    min_path: float = 10.0
    """... and at least this far back along the path (m)."""
    submap_path: float = 5.0
    """A candidate's scan is matched against the nodes within this distance of ``j`` along the
    path (m) ..."""
    submap_stride: int = 2
    """... every k-th of them."""
    search_xy: float = 0.6
    """Correlative search half-width in x and y (m)."""
    search_step: float = 0.1
    """Correlative search step in x and y (m)."""
    search_th: float = 0.1
    """Correlative search half-width in heading (rad)."""
    search_th_step: float = 0.02
    """Correlative search step in heading (rad)."""
    search_sigma: float = 0.15
    """Sensor sigma of the correlative search (m): wide, to rank coarse offsets smoothly."""
    fit_distance: float = 0.1
    """A beam fits when it lands within this distance (m) of a submap surface."""
    min_fit: float = 0.5
    """Accept a loop closure when at least this fraction of the scan's beams fit."""
    min_beams: int = 30
    """... and at least this many."""
    sigma_xy: float = 0.02
    """Floor of a loop edge's standard deviation in x and y (m), added to the match's own."""
    sigma_th: float = 0.005
    """Floor of a loop edge's standard deviation in heading (rad)."""
    robust: float = 3.0
    """Cauchy kernel width of loop edges, in standard deviations (wrong closures lose weight)."""
    seq_sigma_xy: float = 0.01
    """Standard deviation of a sequential edge: this much (m) ..."""
    seq_sigma_th: float = 0.005
    """... (rad) ..."""
    seq_sigma_rel: float = 0.02
    """... plus this fraction of the edge's translation (and rotation): where the filter failed
    to close a loop, its drift is of this order, and the chain must be able to absorb it."""
    min_correction: float = 0.15
    """Keep the filter's trajectory when the optimisation would move no node this far (m):
    loop edges are only about as precise as the filter's own relative poses, so they are used to
    repair gross inconsistencies (decimetres to metres), not to re-shape a closed map."""
    iterations: int = 10
    """Gauss-Newton iterations (at most; they stop when the poses stop moving)."""
    solver_iterations: int = 300
    """Conjugate-gradient iterations per Gauss-Newton step (at most)."""
    rounds: int = 2
    """Detection + optimisation rounds."""

    def __post_init__(self) -> None:
        for name in ("stride", "submap_stride", "iterations", "solver_iterations", "rounds"):
            if getattr(self, name) < 1:
                raise ConfigError(
                    f"loops.{name}: expected an integer ≥ 1, found {getattr(self, name)}"
                )
        for name in ("radius", "search_xy", "search_step", "search_th", "search_th_step",
                     "search_sigma", "fit_distance", "sigma_xy", "sigma_th", "seq_sigma_xy",
                     "seq_sigma_th"):  # fmt: skip
            if not getattr(self, name) > 0:
                raise ConfigError(f"loops.{name}: expected > 0, found {getattr(self, name)}")
        for name in ("min_path", "submap_path", "min_beams", "robust", "seq_sigma_rel",
                     "min_correction"):  # fmt: skip
            if not getattr(self, name) >= 0:
                raise ConfigError(f"loops.{name}: expected ≥ 0, found {getattr(self, name)}")
        if not 0.0 <= self.min_fit <= 1.0:
            raise ConfigError(f"loops.min_fit: expected a fraction in [0, 1], found {self.min_fit}")


@dataclass(frozen=True)
class ClassicConfig:
    """The course's method: one shared map, map correlation with a local pose search."""

    beams: int = 270
    """At most this many beams (evenly spread) are correlated."""
    xy_radius: int = 4
    """Local search over ±xy_radius cells in x and y (the course's 9×9 grid)."""
    yaw_step: float = 0.01
    """Yaw step of the local search (rad)."""
    yaw_steps: int = 2
    """Yaw offsets −yaw_steps..yaw_steps times yaw_step."""
    temperature: float = 10.0
    """Softmax temperature on the correlation counts (hundreds of beams: counts are large)."""
    snap_to_best: bool = False
    """Move each particle to its best local offset (the search then acts as a scan matcher);
    the course uses the best correlation only as the particle's score."""
    motion_floor: tuple[float, ...] = (0.0005, 0.0005, 0.0005)
    """Noise standard deviation added at every scan (m, m, rad); this method predicts at every
    scan, so its floor is smaller than the filter-wide one (used per update)."""
    log_odds_miss: float = -math.log(4.0)
    """The course's symmetric update: a miss removes what a hit adds (``±log 4``)."""


@dataclass(frozen=True)
class TextureConfig:
    """Floor texture mapping from RGB-D frames (docs/texture.md)."""

    enabled: bool = True
    """Compute the texture map when the dataset has RGB-D frames."""
    mode: str = "mean"
    """``"mean"``: running mean of every floor pixel that fell in a cell; ``"latest"``: the mean
    of the most recent frame that saw the cell."""
    floor_height: float = 0.1
    """A point is floor when its height above the floor plane is within ± this (m)."""
    min_depth: float = 0.4
    """Nearest depth used (m): the Kinect measures nothing closer."""
    max_depth: float = 4.0
    """Farthest depth used (m): beyond, depth quantisation and pose errors blur the texture."""
    pair_tolerance_s: float = 0.1
    """An RGB frame is used only with a disparity frame at most this far away in time (s)."""
    frame_stride: int = 1
    """Use every k-th RGB frame."""
    pixel_stride: int = 1
    """Use every k-th row and column of the disparity image."""
    motion_compensation: bool = True
    """Look colours up from the robot pose at the RGB frame's time (the points come from the pose
    at the disparity frame's time); off: both from the disparity pose."""
    read_threads: int = 2
    """Threads decoding PNG frames ahead of the accumulation."""
    camera_x: float = 0.18
    """Kinect position ahead of the robot centre (m), course project text."""
    camera_y: float = 0.005
    """Kinect position to the left of the robot centre (m)."""
    camera_z: float = 0.36
    """Kinect height above the floor (m)."""
    camera_roll: float = 0.0
    """Kinect roll (rad)."""
    camera_pitch: float = 0.36
    """Kinect pitch (rad), positive looks down."""
    camera_yaw: float = 0.021
    """Kinect yaw relative to the robot heading (rad), positive looks left."""

    def __post_init__(self) -> None:
        _check_choice("texture.mode", self.mode, TEXTURE_MODES)
        if self.floor_height <= 0:
            raise ConfigError(f"texture.floor_height: expected > 0, found {self.floor_height}")
        if not 0 <= self.min_depth < self.max_depth:
            raise ConfigError(
                "texture.min_depth, texture.max_depth: expected 0 <= min_depth < max_depth, "
                f"found {self.min_depth}, {self.max_depth}"
            )
        if self.pair_tolerance_s < 0:
            raise ConfigError(
                f"texture.pair_tolerance_s: expected >= 0, found {self.pair_tolerance_s}"
            )
        for name in ("frame_stride", "pixel_stride", "read_threads"):
            if getattr(self, name) < 1:
                raise ConfigError(
                    f"texture.{name}: expected at least 1, found {getattr(self, name)}"
                )


@dataclass(frozen=True)
class VizConfig:
    """Rerun recording of a run."""

    record: bool = True
    """Write ``recording.rrd`` in the run folder."""
    map_every: int = 200
    """Scans between snapshots of the live occupancy map (0: only the final map)."""
    detail_every: int = 10
    """Scans between logged particle sets, scan endpoints and scans/s values (0: never)."""
    scan_points: int = 180
    """At most this many endpoints (evenly spread) of a logged scan."""
    map_levels: int = 16
    """Grey levels of the logged map images (fewer levels make smaller recordings)."""

    def __post_init__(self) -> None:
        for name in ("map_every", "detail_every"):
            if getattr(self, name) < 0:
                raise ConfigError(f"viz.{name}: expected 0 or more, found {getattr(self, name)}")
        if self.scan_points < 1:
            raise ConfigError(f"viz.scan_points: expected at least 1, found {self.scan_points}")
        if not 2 <= self.map_levels <= 256:
            raise ConfigError(f"viz.map_levels: expected 2..256, found {self.map_levels}")


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
    texture: TextureConfig = field(default_factory=TextureConfig)
    viz: VizConfig = field(default_factory=VizConfig)


def _section_types() -> dict[str, type]:
    hints = typing.get_type_hints(Config)
    return {name: tp for name, tp in hints.items() if dataclasses.is_dataclass(tp)}


def _coerce(value: Any, tp: Any, where: str) -> Any:
    """Check ``value`` against the annotated type ``tp``; return it converted (int → float)."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(value, arg, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: unexpected value {value!r}")
    if origin is tuple:
        (item,) = typing.get_args(tp)[:1]
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, found {value!r}")
        return tuple(_coerce(v, item, f"{where}[{i}]") for i, v in enumerate(value))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, found {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, found {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, found {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, found {value!r}")
        return value
    raise ConfigError(f"{where}: unsupported type {tp!r}")


def _apply(config: Config, table: Mapping[str, Any], source: str) -> Config:
    sections = _section_types()
    changes: dict[str, Any] = {}
    for key, value in table.items():
        if key == "dataset":
            changes["dataset"] = _coerce(value, str, f"{source}: dataset")
            continue
        if key not in sections:
            raise ConfigError(
                f"{source}: unknown section [{key}]; expected one of {', '.join(sorted(sections))}"
            )
        if not isinstance(value, Mapping):
            raise ConfigError(f"{source}: [{key}] must be a table, found {value!r}")
        cls = sections[key]
        hints = typing.get_type_hints(cls)
        current = getattr(config, key)
        updates = {}
        for name, raw in value.items():
            if name not in hints:
                raise ConfigError(
                    f"{source}: unknown key {key}.{name}; expected one of "
                    f"{', '.join(sorted(hints))}"
                )
            updates[name] = _coerce(raw, hints[name], f"{source}: {key}.{name}")
        changes[key] = dataclasses.replace(current, **updates)
    return dataclasses.replace(config, **changes)


def parse_override(text: str) -> tuple[str, str, Any]:
    """Parse ``section.key=value`` (value a TOML literal, else a bare string)."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise ConfigError(f"--set {text!r}: expected section.key=value, e.g. filter.particles=100")
    lhs, raw = text.split("=", 1)
    section, key = lhs.strip().split(".", 1)
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return section, key, value


def read_toml(path: Path) -> dict[str, Any]:
    """Read a TOML file, turning I/O and syntax errors into :class:`ConfigError`."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: config file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None


def load_config(
    dataset: str = "",
    config_file: Path | None = None,
    overrides: Iterable[str] = (),
    base: Config | None = None,
) -> Config:
    """Resolve the configuration of a run (defaults, dataset config, file, overrides)."""
    config = base or Config()
    if dataset:
        config = dataclasses.replace(config, dataset=dataset)
        shipped = config_dir() / f"{dataset}.toml"
        if shipped.is_file():
            config = _apply(config, read_toml(shipped), str(shipped))
    if config_file is not None:
        config = _apply(config, read_toml(Path(config_file)), str(config_file))
    for text in overrides:
        section, key, value = parse_override(text)
        config = _apply(config, {section: {key: value}}, f"--set {text}")
    if dataset:
        config = dataclasses.replace(config, dataset=dataset)
    return config


def to_dict(config: Any) -> dict[str, Any]:
    """Nested plain-dict view of a config dataclass."""
    return dataclasses.asdict(config)


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
        escaped = value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"'
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
