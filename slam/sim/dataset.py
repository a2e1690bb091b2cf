"""Simulated datasets: sensor streams from a scene, written in the exact ECE276A format.

:func:`simulate_log` builds a scene (world + trajectory) and samples every sensor;
:func:`write_dataset` writes it into a folder; :func:`generate_dataset` does both atomically (the
folder appears complete or not at all). Files, for dataset number ``NN``:

* ``EncodersNN.npz`` — ``counts`` int16 (4, N) FR, FL, RR, RL; ``time_stamps`` float64 (N,);
* ``ImuNN.npz`` — ``angular_velocity``, ``linear_acceleration`` float64 (3, N); ``time_stamps``;
* ``HokuyoNN.npz`` — ``angle_min``, ``angle_max``, ``angle_increment``, ``range_min``,
  ``range_max`` float64 (1, 1); ``ranges`` float32 (1081, N); ``time_stamps`` float64 (N,);
* ``KinectNN.npz`` — ``disparity_time_stamps``, ``rgb_time_stamps`` float64;
  ``dataRGBD/RGBNN/rgbNN_<k>.png`` (480×640 RGB) and ``dataRGBD/DisparityNN/disparityNN_<k>.png``
  (480×640 uint16), k from 1;
* ground truth: ``groundtruth.tum`` (robot centre at 100 Hz and at every sensor time),
  ``groundtruth_map.npz`` (``occupancy`` uint8 (H, W), ``labels``, ``interior``, ``resolution``,
  ``origin``), ``groundtruth_texture.npz`` (``rgb`` uint8 (H, W, 3), ``floor``, ``resolution``,
  ``origin``), PNG renderings of both, and ``simulation.json`` (scenario, seed, rates, counts).

Outputs are byte-identical for the same options: one ``numpy.random.Generator(seed)`` drawn in a
fixed order (scene, encoders, IMU, lidar, then Kinect, so ``--no-rgbd`` leaves the other files
unchanged), zip entries with a fixed date, PNGs with fixed encoder settings, no timings in files.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from slam.budget import check_memory
from slam.errors import UsageError
from slam.io.atomic import atomic_dir, write_npz, write_png
from slam.io.ece276a import rgbd_dirs, rgbd_patterns, stream_file
from slam.io.tum import format_tum
from slam.kinect import KinectModel
from slam.sim.render import FrameNoise, KinectRenderer
from slam.sim.scenarios import Scene, generate_scene, get_scenario
from slam.sim.sensors import (
    LidarSpec,
    NoiseConfig,
    WheelSpec,
    kinect_times,
    sample_times,
    simulate_encoders,
    simulate_imu,
    simulate_lidar,
)
from slam.sim.world import WALL, World
from slam.trajectory import Trajectory

SIM_VERSION = 2
"""Version of the generator; bump it whenever outputs change for the same options."""
START_TIME = 1_600_000_000.0
"""Unix time of the simulated robot's start (s)."""
RGBD_RATE_HZ = 10.0
"""Default Kinect frame rate of simulated logs (Hz); the course logs have ≈19 Hz."""
IMU_RATE_HZ = 100.0
GROUND_TRUTH_RATE_HZ = 100.0

PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1]
if hasattr(cv2, "IMWRITE_PNG_FILTER"):
    PNG_PARAMS += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB]

MAX_DURATION_S = 3600.0
"""Longest log ``slam sim`` writes (s): one hour, 29 times the demo."""
MIN_DURATION_S = 1.0
"""Shortest log ``slam sim`` writes (s): 40 scans, enough for ``slam run`` and its ground-truth
figures (a few hundredths of a second gave a dataset with no scan, which no run can read)."""
SIM_BYTES_PER_SECOND = 1 << 20
"""Memory the simulation holds per simulated second (measured 0.58 MiB/s with ``/usr/bin/time``,
``slam sim small --no-rgbd`` at 600 and 1200 s: mostly the scans, 13 bytes a reading while they
are measured, :func:`slam.sim.sensors.simulate_lidar`; 2.3 MiB/s when they were measured in one
whole-log pass), rounded up."""

_NOISE_TABLE = 1 << 21
_HOLE_TABLE = 1 << 20


@dataclass(frozen=True)
class SimOptions:
    """What to simulate."""

    scenario: str = "demo"
    """Scenario name (see :data:`slam.sim.scenarios.SCENARIOS`)."""
    seed: int | None = None
    """Seed of the single random generator; ``None`` takes the scenario's default."""
    duration: float | None = None
    """Log length (s); ``None`` takes the scenario's nominal duration."""
    number: int = 20
    """The ``NN`` of the file names."""
    rgbd: bool = True
    """Render Kinect frames."""
    rgbd_rate: float = RGBD_RATE_HZ
    """Kinect frame rate (Hz)."""
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    kinect: KinectModel = field(default_factory=KinectModel)
    lidar: LidarSpec = field(default_factory=LidarSpec)
    wheels: WheelSpec = field(default_factory=WheelSpec)

    def __post_init__(self) -> None:
        if self.seed is not None and not 0 <= self.seed < 2**63:
            bound = "≥ 0" if self.seed < 0 else "below 2**63"
            raise UsageError(f"--seed: expected an integer {bound}, found {self.seed}")
        if not 0 <= self.number <= 99:
            raise UsageError(f"--number: expected 0..99, found {self.number}")
        if not 0 < self.rgbd_rate <= 30:
            raise UsageError(f"--rgbd-rate: expected a rate in (0, 30] Hz, found {self.rgbd_rate}")
        if self.duration is not None and not MIN_DURATION_S <= self.duration <= MAX_DURATION_S:
            raise UsageError(
                f"--duration: expected a number of seconds in [{MIN_DURATION_S:g}, "
                f"{MAX_DURATION_S:g}], found {self.duration:g}"
            )
        seconds = self.duration
        if seconds is None:
            from slam.sim.scenarios import get_scenario

            seconds = get_scenario(self.scenario).duration
        if self.rgbd and seconds * self.rgbd_rate < 2:
            raise UsageError(
                f"--rgbd-rate {self.rgbd_rate:g} over {seconds:g} s gives fewer than 2 Kinect "
                "frames; raise the rate or --duration, or leave the frames out with --no-rgbd"
            )
        if self.duration is not None:
            check_memory(
                self.duration * SIM_BYTES_PER_SECOND,
                f"--duration {self.duration:g}: a simulated log of {self.duration:g} s",
                "simulate a shorter log",
            )


@dataclass
class SimulatedLog:
    """Everything a simulated dataset holds, in memory (Kinect frames are rendered on demand)."""

    options: SimOptions
    seed: int
    scene: Scene
    encoder_time: NDArray[np.float64]
    encoder_counts: NDArray[np.int16]
    imu_time: NDArray[np.float64]
    gyro: NDArray[np.float64]
    accel: NDArray[np.float64]
    lidar_time: NDArray[np.float64]
    ranges: NDArray[np.float32]
    """``(N, beams)``; written transposed as ``(beams, N)``."""
    disparity_time: NDArray[np.float64] | None = None
    rgb_time: NDArray[np.float64] | None = None
    disparity_noise: list[FrameNoise] = field(default_factory=list)
    rgb_noise: list[FrameNoise] = field(default_factory=list)
    renderer: KinectRenderer | None = None
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def world(self) -> World:
        """The simulated building."""
        return self.scene.world


def simulate_log(options: SimOptions) -> SimulatedLog:
    """Generate the scene and sample the encoder, IMU and lidar streams (and Kinect times)."""
    scenario = get_scenario(options.scenario)
    seed = scenario.seed if options.seed is None else int(options.seed)
    rng = np.random.default_rng(seed)
    noise = options.noise
    timings: dict[str, float] = {}

    clock = time.perf_counter()
    scene = generate_scene(scenario, rng, options.duration, t0=START_TIME)
    traj = scene.trajectory
    timings["scene_s"] = time.perf_counter() - clock

    clock = time.perf_counter()
    # Encoders and IMU bracket the scans and frames (with jitter): odometry never extrapolates.
    enc_t = sample_times(
        rng, traj.t0 - 0.01, traj.t_end + 0.045, options.wheels.rate_hz, noise.time_jitter
    )
    counts = simulate_encoders(traj, enc_t, rng, noise, options.wheels)
    timings["encoders_s"] = time.perf_counter() - clock

    clock = time.perf_counter()
    imu_t = sample_times(rng, traj.t0 - 0.05, traj.t_end + 0.08, IMU_RATE_HZ, noise.time_jitter / 2)
    gyro, accel = simulate_imu(traj, imu_t, rng, noise)
    timings["imu_s"] = time.perf_counter() - clock

    clock = time.perf_counter()
    lidar_t = sample_times(
        rng, traj.t0 + 0.0125, traj.t_end, options.lidar.rate_hz, noise.time_jitter
    )
    ranges = simulate_lidar(scene.world, traj, lidar_t, rng, noise, options.lidar)
    timings["lidar_s"] = time.perf_counter() - clock

    log = SimulatedLog(
        options=options,
        seed=seed,
        scene=scene,
        encoder_time=enc_t,
        encoder_counts=counts,
        imu_time=imu_t,
        gyro=gyro,
        accel=accel,
        lidar_time=lidar_t,
        ranges=ranges,
        timings=timings,
    )
    if options.rgbd:
        _plan_kinect(log, rng)
    return log


def _plan_kinect(log: SimulatedLog, rng: np.random.Generator) -> None:
    """Kinect frame times, per-frame noise and the renderer (noise tables drawn here)."""
    options = log.options
    noise = options.noise
    traj = log.scene.trajectory
    disp_t, rgb_t = kinect_times(rng, traj.t0 + 0.3, traj.t_end, options.rgbd_rate, noise)
    m = options.kinect
    pixels = m.height * m.width
    noise_table = rng.standard_normal(_NOISE_TABLE + 3 * pixels, dtype=np.float32)
    hole_table = rng.random(_HOLE_TABLE + pixels, dtype=np.float32)

    def frames(n: int, with_holes: bool, gain_sigma: float) -> list[FrameNoise]:
        offsets = rng.integers(0, _NOISE_TABLE, size=n)
        holes = rng.integers(0, _HOLE_TABLE, size=n) if with_holes else np.zeros(n, np.int64)
        gains = 1.0 + gain_sigma * rng.standard_normal(n)
        return [
            FrameNoise(int(o), int(hh), float(g))
            for o, hh, g in zip(offsets, holes, gains, strict=True)
        ]

    log.disparity_time = disp_t
    log.rgb_time = rgb_t
    log.disparity_noise = frames(len(disp_t), True, 0.0)
    log.rgb_noise = frames(len(rgb_t), False, noise.rgb_gain)
    log.renderer = KinectRenderer(
        log.scene.world,
        m,
        noise_table=noise_table,
        hole_table=hole_table,
        disparity_sigma=noise.disparity_noise,
        hole_prob=noise.disparity_holes,
        rgb_sigma=noise.rgb_noise,
    )


# ----------------------------------------------------------------------------------- writing


def save_npz(path: Path, arrays: dict[str, NDArray[Any]]) -> None:
    """Write an uncompressed ``.npz`` like :func:`numpy.savez` (the course's files are stored,
    not deflated), byte-identical for equal arrays (:func:`slam.io.atomic.write_npz`, level 0)."""
    write_npz(path, arrays, level=0)


def _scalar(value: float) -> NDArray[np.float64]:
    return np.array([[value]], dtype=np.float64)


def hokuyo_arrays(
    lidar: LidarSpec, times: NDArray[np.float64], ranges: NDArray[np.float32]
) -> dict[str, NDArray[Any]]:
    """The keys of ``HokuyoNN.npz`` for scans ``ranges`` ``(N, beams)`` taken at ``times``."""
    return {
        "angle_min": _scalar(lidar.angle_min),
        "angle_max": _scalar(lidar.angle_max),
        "angle_increment": _scalar(lidar.angle_increment),
        "range_min": _scalar(lidar.range_min),
        "range_max": _scalar(lidar.range_max),
        "ranges": np.ascontiguousarray(ranges.T),
        "time_stamps": times,
    }


def map_arrays(world: World) -> dict[str, NDArray[Any]]:
    """The keys of ``groundtruth_map.npz``: the true occupancy grid of ``world``."""
    return {
        "occupancy": world.occupancy,
        "labels": world.labels,
        "interior": world.interior,
        "resolution": np.float64(world.resolution),
        "origin": np.asarray(world.origin, dtype=np.float64),
    }


def write_dataset(log: SimulatedLog, folder: Path, progress: bool = False) -> dict[str, Any]:
    """Write ``log`` into ``folder`` (created if needed); return a summary with timings."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    nn = f"{log.options.number:02d}"
    clock = time.perf_counter()
    save_npz(
        stream_file(folder, nn, "encoders"),
        {"counts": log.encoder_counts, "time_stamps": log.encoder_time},
    )
    save_npz(
        stream_file(folder, nn, "imu"),
        {
            "angular_velocity": log.gyro,
            "linear_acceleration": log.accel,
            "time_stamps": log.imu_time,
        },
    )
    save_npz(
        stream_file(folder, nn, "scans"),
        hokuyo_arrays(log.options.lidar, log.lidar_time, log.ranges),
    )
    log.timings["write_npz_s"] = time.perf_counter() - clock

    clock = time.perf_counter()
    _write_ground_truth(log, folder)
    log.timings["ground_truth_s"] = time.perf_counter() - clock

    if log.options.rgbd:
        _write_kinect(log, folder, nn, progress)
    summary = _summary(log)
    (folder / "simulation.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return {**summary, "timings": dict(log.timings)}


def _write_ground_truth(log: SimulatedLog, folder: Path) -> None:
    traj = log.scene.trajectory
    world = log.world
    # 100 Hz from the start, plus every sensor time (the robot stands still outside [t0, t_end]).
    grid = traj.t0 + np.arange(int(np.floor(traj.duration * GROUND_TRUTH_RATE_HZ)) + 1) / (
        GROUND_TRUTH_RATE_HZ
    )
    parts = [grid, log.encoder_time, log.lidar_time]
    if log.disparity_time is not None:
        parts += [log.disparity_time, log.rgb_time]
    # rounded as the file writes them (microseconds), so that no two lines share a time
    times = np.unique(np.round(np.concatenate(parts), 6))
    (folder / "groundtruth.tum").write_text(format_tum(Trajectory(times, traj.pose_at(times))))
    save_npz(folder / "groundtruth_map.npz", map_arrays(world))
    save_npz(
        folder / "groundtruth_texture.npz",
        {
            "rgb": world.texture,
            "floor": world.floor,
            "resolution": np.float64(world.texture_resolution),
            "origin": np.asarray(world.texture_origin, dtype=np.float64),
        },
    )
    write_png(
        folder / "groundtruth_map.png", render_map_png(world, traj.sample_xy(0.05)), PNG_PARAMS
    )
    write_png(
        folder / "groundtruth_texture.png",
        np.ascontiguousarray(world.texture[::-1, :, ::-1]),
        PNG_PARAMS,
    )


def render_map_png(world: World, path_xy: NDArray[np.float64] | None = None) -> NDArray[np.uint8]:
    """A BGR picture of the true map (y up): walls black, furniture and pillars dark grey, free
    floor white, outside light grey, the true path in blue."""
    img = np.full((*world.labels.shape, 3), 200, dtype=np.uint8)
    img[world.interior] = 255
    img[world.labels != 0] = 90
    img[world.labels == WALL] = 0
    if path_xy is not None and len(path_xy) > 1:
        pix = (np.asarray(path_xy) - np.asarray(world.origin)) / world.resolution - 0.5
        pts = np.round(pix * 16).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [pts], False, (200, 80, 0), 1, cv2.LINE_AA, shift=4)
        start = tuple(int(v) for v in np.round(pix[0]).astype(int))
        cv2.circle(img, start, 3, (0, 0, 220), -1)
    return np.ascontiguousarray(img[::-1])


def _write_kinect(log: SimulatedLog, folder: Path, nn: str, progress: bool) -> None:
    assert log.renderer is not None and log.disparity_time is not None
    assert log.rgb_time is not None
    save_npz(
        stream_file(folder, nn, "kinect"),
        {"disparity_time_stamps": log.disparity_time, "rgb_time_stamps": log.rgb_time},
    )
    rgb_dir, disp_dir = rgbd_dirs(folder, nn)
    rgb_pattern, disp_pattern = rgbd_patterns(nn)
    rgb_dir.mkdir(parents=True, exist_ok=True)
    disp_dir.mkdir(parents=True, exist_ok=True)
    traj = log.scene.trajectory
    jobs = [(t, 0, k) for k, t in enumerate(log.disparity_time)]
    jobs += [(t, 1, k) for k, t in enumerate(log.rgb_time)]
    jobs.sort()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), desc="kinect frames", unit="frame", leave=False)
    render_s = 0.0
    pending: deque[Future] = deque()
    clock = time.perf_counter()
    with ThreadPoolExecutor(max_workers=2) as pool:
        for t, kind, k in jobs:
            pose = traj.pose_at(np.array([t]))[0]
            start = time.perf_counter()
            if kind == 0:
                disparity, _, _ = log.renderer.disparity(pose, log.disparity_noise[k])
                path = disp_dir / disp_pattern.format(k + 1)
                image = disparity
            else:
                rgb = log.renderer.rgb(pose, log.rgb_noise[k])
                path = rgb_dir / rgb_pattern.format(k + 1)
                image = np.ascontiguousarray(rgb[:, :, ::-1])
            render_s += time.perf_counter() - start
            pending.append(pool.submit(write_png, path, image, PNG_PARAMS))
            while len(pending) > 8:
                pending.popleft().result()
            if bar is not None:
                bar.update(1)
        while pending:
            pending.popleft().result()
    if bar is not None:
        bar.close()
    log.timings["kinect_render_s"] = render_s
    log.timings["kinect_total_s"] = time.perf_counter() - clock


def _summary(log: SimulatedLog) -> dict[str, Any]:
    """Facts about a simulated dataset, written to ``simulation.json`` (no timings: the file must
    be byte-identical for equal options)."""
    options = log.options
    traj = log.scene.trajectory
    out: dict[str, Any] = {
        "generator": "slam.sim",
        "version": SIM_VERSION,
        "scenario": options.scenario,
        "seed": log.seed,
        "number": options.number,
        "start_time": traj.t0,
        "duration_s": traj.duration,
        "noise": dataclasses.asdict(options.noise),
        "kinect": dataclasses.asdict(options.kinect),
        "lidar": dataclasses.asdict(options.lidar),
        "wheels": dataclasses.asdict(options.wheels),
        "counts": {
            "encoders": int(log.encoder_time.shape[0]),
            "imu": int(log.imu_time.shape[0]),
            "scans": int(log.lidar_time.shape[0]),
        },
        "rates_hz": {
            "encoders": options.wheels.rate_hz,
            "imu": IMU_RATE_HZ,
            "lidar": options.lidar.rate_hz,
        },
        "trajectory": {k: v for k, v in log.scene.info.items()},
        "world": {
            "map_shape": list(log.world.labels.shape),
            "map_resolution": log.world.resolution,
            "map_origin": list(log.world.origin),
            "texture_resolution": log.world.texture_resolution,
            "wall_height": log.world.wall_height,
            **log.world.meta,
        },
    }
    if options.rgbd and log.disparity_time is not None and log.rgb_time is not None:
        out["counts"]["disparity_frames"] = int(log.disparity_time.shape[0])
        out["counts"]["rgb_frames"] = int(log.rgb_time.shape[0])
        out["rates_hz"]["kinect"] = options.rgbd_rate
    return out


def generate_dataset(
    out: Path, options: SimOptions, progress: bool = False, overwrite: bool = False
) -> dict[str, Any]:
    """Simulate and write a dataset into ``out`` atomically; return its summary with timings.

    ``overwrite`` replaces only a simulated dataset written by ``slam sim`` (its ``.slam-sim``
    marker and ``simulation.json``), see :func:`slam.io.atomic.atomic_dir`."""
    clock = time.perf_counter()
    with atomic_dir(Path(out), overwrite=overwrite, kind="sim") as tmp:
        log = simulate_log(options)
        summary = write_dataset(log, tmp, progress=progress)
    summary["timings"]["total_s"] = time.perf_counter() - clock
    return summary
