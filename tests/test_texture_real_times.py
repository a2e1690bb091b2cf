"""Frame selection driven by the real Kinect20.npz timestamps (frames simulated at those times)."""

import cv2
import numpy as np
import pytest

from slam.config import MapConfig, TextureConfig
from slam.io.ece276a import load_ece276a
from slam.mapping import OccupancyGrid
from slam.sim.dataset import save_npz
from slam.sim.render import KinectRenderer
from slam.sim.scenarios import SCENARIOS, generate_scene
from slam.texture import (
    GroundTruth,
    TextureWarning,
    build_texture,
    evaluate_texture,
    pair_frames,
)
from slam.trajectory import Trajectory

pytestmark = pytest.mark.data


@pytest.fixture(scope="module")
def kinect20(ece276a_dir):
    with np.load(ece276a_dir / "Kinect20.npz") as f:
        return f["rgb_time_stamps"].astype(np.float64), f["disparity_time_stamps"].astype(
            np.float64
        )


def _brute_force_pairs(rgb_t, disp_t, tolerance):
    gaps = np.abs(rgb_t[:, None] - disp_t[None, :])
    nearest = gaps.argmin(axis=1)  # first minimum: ties go to the earlier (sorted) frame
    ok = gaps[np.arange(rgb_t.size), nearest] <= tolerance
    return np.flatnonzero(ok), nearest[ok]


def test_pairing_on_the_real_kinect20_timestamps(kinect20):
    rgb_t, disp_t = kinect20
    assert (rgb_t.size, disp_t.size) == (2289, 2407)
    plan = pair_frames(rgb_t, disp_t, TextureConfig().pair_tolerance_s)
    expected_rgb, expected_disp = _brute_force_pairs(rgb_t, disp_t, 0.1)
    np.testing.assert_array_equal(plan.rgb, expected_rgb)
    np.testing.assert_array_equal(plan.disparity, expected_disp)
    # The real log has 26 RGB frames with no disparity frame within 0.1 s (gaps up to 0.21 s).
    assert plan.skipped == {"no_disparity": 26} and plan.rgb.size == 2263
    assert np.abs(plan.rgb_time - plan.disparity_time).max() <= 0.1
    # With a stride of 2 and a 50 ms tolerance the same rule holds on every other frame.
    plan = pair_frames(rgb_t, disp_t, 0.05, stride=2)
    r2, d2 = _brute_force_pairs(rgb_t[::2], disp_t, 0.05)
    np.testing.assert_array_equal(plan.rgb, 2 * r2)
    np.testing.assert_array_equal(plan.disparity, d2)


def _write_png(path, image):
    ok, data = cv2.imencode(".png", image)
    assert ok
    path.write_bytes(data.tobytes())


def test_simulated_frames_at_real_timestamps_texture_the_floor(kinect20, tmp_path):
    rgb_all, disp_all = kinect20
    # A 2.4 s window of the real log around 15 s, where four RGB frames have no disparity frame
    # within 0.1 s (the Kinect skipped disparity frames there).
    start = rgb_all[0] + 14.3
    rgb_t = rgb_all[(rgb_all >= start) & (rgb_all < start + 2.4)]
    disp_t = disp_all[(disp_all >= start - 0.2) & (disp_all < start + 2.6)]
    # The small simulated building, its robot reaching the window 6 s after its start.
    scene = generate_scene(SCENARIOS["small"], np.random.default_rng(4), t0=start - 6.0)
    world, traj = scene.world, scene.trajectory
    renderer = KinectRenderer(world)
    folder = tmp_path / "ece276a"
    rgb_dir, disp_dir = folder / "dataRGBD" / "RGB20", folder / "dataRGBD" / "Disparity20"
    rgb_dir.mkdir(parents=True)
    disp_dir.mkdir(parents=True)
    save_npz(folder / "Kinect20.npz", {"disparity_time_stamps": disp_t, "rgb_time_stamps": rgb_t})
    for k, t in enumerate(disp_t):
        disparity = renderer.disparity(traj.pose_at(np.array([t]))[0])[0]
        _write_png(disp_dir / f"disparity20_{k + 1}.png", disparity)
    for k, t in enumerate(rgb_t):
        rgb = renderer.rgb(traj.pose_at(np.array([t]))[0])
        _write_png(rgb_dir / f"rgb20_{k + 1}.png", np.ascontiguousarray(rgb[:, :, ::-1]))

    log = load_ece276a(folder, 20, need=("kinect",))
    times = np.arange(start - 1.0, start + 3.0, 0.01)
    poses = traj.pose_at(times)
    grid = OccupancyGrid(MapConfig())
    with pytest.warns(TextureWarning, match="skipped 4 RGB frame"):
        result = build_texture(log.rgbd, Trajectory(times, poses), grid, TextureConfig())
    expected_rgb, expected_disp = _brute_force_pairs(rgb_t, disp_t, 0.1)
    np.testing.assert_array_equal(result.plan.rgb, expected_rgb)
    np.testing.assert_array_equal(result.plan.disparity, expected_disp)
    assert result.plan.skipped == {"no_disparity": 4}
    assert result.used.all() and result.used.size == rgb_t.size - 4 == 36
    assert result.warnings == [
        "texture: skipped 4 RGB frame(s): no disparity frame (with a PNG) within the pairing "
        "tolerance (e.g. RGB frame 17: nearest disparity 0.121 s away)"
    ]
    gt = GroundTruth(
        times=times,
        poses=poses,
        texture=world.texture,
        floor=world.floor,
        texture_resolution=world.texture_resolution,
        texture_origin=np.asarray(world.texture_origin, dtype=np.float64),
        occupancy=world.occupancy,
        map_resolution=world.resolution,
        map_origin=np.asarray(world.origin, dtype=np.float64),
    )
    figures = evaluate_texture(
        result.texture, gt, result.plan.disparity_time[result.used], TextureConfig()
    )
    assert figures["colour_mae"] <= 10.0
    assert figures["coverage"] >= 0.9
    assert figures["swept_cells"] > 2000
