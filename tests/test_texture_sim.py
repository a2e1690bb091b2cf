"""The texture stage on a short simulated dataset: accuracy targets, slam run / slam texture, bad
frames. The dataset is generated once for the module."""

import json
import os
import shutil
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from slam.cli import main
from slam.config import MapConfig, TextureConfig
from slam.io.ece276a import load_ece276a
from slam.mapping import OccupancyGrid
from slam.texture import TextureWarning, build_texture, evaluate_texture, load_ground_truth
from slam.trajectory import Trajectory

RUN = ["--method", "odometry", "--set", "viz.record=false", "--quiet"]
"""Fast runs: dead reckoning (the map still comes from the scans), no recording."""


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """The ``small`` scenario, 15 s with Kinect frames at 4 Hz, with the simulator's noise."""
    out = tmp_path_factory.mktemp("texsim") / "small"
    code = main(["sim", "small", "--out", str(out), "--duration", "15", "--rgbd-rate", "4",
                 "--quiet"])  # fmt: skip
    assert code == 0
    return out


@pytest.fixture(scope="module")
def small_run(small, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("texrun") / "run"
    assert main(["run", str(small), "--out", str(out), *RUN]) == 0
    return out


def _texture_with_ground_truth_path(folder: Path, mode: str):
    log = load_ece276a(folder, 20, need=("kinect",))
    gt = load_ground_truth(folder)
    config = TextureConfig(mode=mode)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TextureWarning)  # the simulator drops a few frames
        result = build_texture(
            log.rgbd, Trajectory(gt.times, gt.poses), OccupancyGrid(MapConfig()), config
        )
    used_times = result.plan.disparity_time[result.used]
    return result, evaluate_texture(result.texture, gt, used_times, config)


def test_ground_truth_path_meets_the_colour_and_coverage_targets(small):
    result, figures = _texture_with_ground_truth_path(small, "mean")
    log = load_ece276a(small, 20, need=("kinect",))
    # Every RGB frame is used except those whose disparity frame the simulator dropped.
    assert result.plan.considered == log.rgbd.rgb_time.size
    assert set(result.plan.skipped) <= {"no_disparity"}
    assert result.used.sum() + sum(result.plan.skipped.values()) == log.rgbd.rgb_time.size
    assert result.used.sum() >= 0.9 * log.rgbd.rgb_time.size
    assert figures["colour_mae"] <= 10.0  # levels of 255, over the floor cells seen
    assert figures["coverage"] >= 0.9  # of the swept floor
    assert figures["swept_area_m2"] > 15.0
    # "latest" keeps one frame's exposure per cell: noisier than the mean, still within target.
    _, latest = _texture_with_ground_truth_path(small, "latest")
    assert figures["colour_mae"] < latest["colour_mae"] <= 10.0
    assert latest["coverage"] == figures["coverage"]


def test_slam_run_writes_texture_outputs_on_the_map_grid(small_run):
    out = small_run
    for name in ("texture.png", "texture.npz", "texture_overlay.png"):
        assert (out / name).is_file()
    map_png = cv2.imread(str(out / "map.png"))
    assert cv2.imread(str(out / "texture.png")).shape == map_png.shape
    assert cv2.imread(str(out / "texture_overlay.png")).shape == map_png.shape
    with np.load(out / "map.npz") as m, np.load(out / "texture.npz") as t:
        assert sorted(t.files) == ["count", "origin", "resolution", "rgb"]
        assert t["rgb"].shape == (*m["log_odds"].shape, 3) and t["rgb"].dtype == np.uint8
        assert t["count"].shape == m["log_odds"].shape
        assert float(t["resolution"]) == float(m["resolution"])
        np.testing.assert_array_equal(t["origin"], m["origin"])
        coloured = int((t["count"] > 0).sum())
        assert (t["rgb"][t["count"] == 0] == 0).all()
    metrics = json.loads((out / "metrics.json").read_text())
    tex = metrics["texture"]
    assert tex["mode"] == "mean" and tex["coloured_cells"] == coloured > 5000
    assert (
        tex["frames_used"] + tex["frames_skipped"] == tex["frames_considered"] == tex["rgb_frames"]
    )
    assert tex["frames_per_s"] > 0 and tex["floor_samples"] > 1_000_000
    gt = tex["ground_truth"]
    assert gt["colour_mae"] is not None and gt["coverage"] > 0.8
    assert gt["colour_mae_aligned"] <= gt["colour_mae"] + 0.5


def test_no_texture_flag_skips_the_stage(small, tmp_path):
    out = tmp_path / "run"
    assert main(["run", str(small), "--out", str(out), "--no-texture", *RUN]) == 0
    assert not (out / "texture.png").exists() and not (out / "texture.npz").exists()
    metrics = json.loads((out / "metrics.json").read_text())
    assert "texture" not in metrics
    assert "enabled = false" in (out / "config.toml").read_text().split("[texture]")[1]


def test_slam_texture_recomputes_a_finished_run(small, small_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(small_run, run)
    before = json.loads((run / "metrics.json").read_text())
    with np.load(run / "texture.npz") as t:
        rgb_mean, count_mean = t["rgb"].copy(), t["count"].copy()
    # The run was made from a folder: config.toml names "small", which the registry lacks.
    assert main(["texture", str(run), "--quiet"]) == 2
    assert "--dataset" in capsys.readouterr().err
    # The default mode recomputes the run's own texture from trajectory.tum, whose micrometres
    # move a few pixels across cell borders (docs/texture.md): the same cells, within 1/255.
    assert main(["texture", str(run), "--dataset", str(small), "--quiet"]) == 0
    capsys.readouterr()
    with np.load(run / "texture.npz") as t:
        np.testing.assert_array_equal(t["count"] > 0, count_mean > 0)
        assert np.abs(t["count"] - count_mean).sum() <= 1e-4 * count_mean.sum()
        assert np.abs(t["rgb"].astype(int) - rgb_mean).max() <= 1
    assert main(["texture", str(run), "--dataset", str(small), "--mode", "latest", "--quiet"]) == 0
    line = capsys.readouterr().out
    assert "texture" in line and "(latest)" in line and "colour error" in line
    after = json.loads((run / "metrics.json").read_text())
    assert after["texture"]["mode"] == "latest"
    assert {k: v for k, v in after.items() if k != "texture"} == {
        k: v for k, v in before.items() if k != "texture"
    }
    with np.load(run / "texture.npz") as t:
        np.testing.assert_array_equal(t["count"] > 0, count_mean > 0)  # the same cells
        assert (t["count"] <= count_mean).all() and t["count"].sum() < count_mean.sum()
        assert not np.array_equal(t["rgb"], rgb_mean)  # one frame's exposure instead of the mean
    # atomic writes leave no temporary files behind (.slam-run is the run folder's marker)
    assert [p.name for p in run.glob(".*")] == [".slam-run"]
    # A folder that is not a finished run is refused with the missing files named.
    (run / "map.npz").unlink()
    assert main(["texture", str(run), "--dataset", str(small), "--quiet"]) == 2
    assert "missing map.npz" in capsys.readouterr().err


def _link_dataset(src: Path, dst: Path, with_images: bool = True) -> None:
    """A copy of a simulated dataset made of symbolic links (bad files then replace links)."""
    dst.mkdir(parents=True)
    for path in src.iterdir():
        if path.is_file():
            os.symlink(path, dst / path.name)
    if with_images:
        for sub in ("RGB20", "Disparity20"):
            (dst / "dataRGBD" / sub).mkdir(parents=True)
            for png in (src / "dataRGBD" / sub).iterdir():
                os.symlink(png, dst / "dataRGBD" / sub / png.name)


def test_bad_frames_are_skipped_counted_and_reported(small, small_run, tmp_path, capsys):
    bad = tmp_path / "bad"
    _link_dataset(small, bad)
    rgb_dir, disp_dir = bad / "dataRGBD" / "RGB20", bad / "dataRGBD" / "Disparity20"
    clean = json.loads((small_run / "metrics.json").read_text())["texture"]
    n_rgb = clean["rgb_frames"]
    # Missing RGB frame 3, RGB frame 7 of the wrong size, the disparity frame paired with RGB
    # frame 10 corrupt, and two extra RGB files (count mismatch with the timestamps).
    (rgb_dir / "rgb20_3.png").unlink()
    (rgb_dir / "rgb20_7.png").unlink()
    cv2.imwrite(str(rgb_dir / "rgb20_7.png"), np.zeros((100, 120, 3), np.uint8))
    log = load_ece276a(small, 20, need=("kinect",))
    k_disp = int(np.argmin(np.abs(log.rgbd.disparity_time - log.rgbd.rgb_time[9])))
    sharing = np.abs(
        log.rgbd.rgb_time[:, None] - log.rgbd.disparity_time[None, :]
    ).argmin(axis=1) == k_disp  # fmt: skip
    (disp_dir / f"disparity20_{k_disp + 1}.png").unlink()
    (disp_dir / f"disparity20_{k_disp + 1}.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    for k in (n_rgb + 1, n_rgb + 2):
        shutil.copyfile(small / "dataRGBD" / "RGB20" / "rgb20_1.png", rgb_dir / f"rgb20_{k}.png")

    out = tmp_path / "run"
    assert main(["run", str(bad), "--out", str(out), *RUN]) == 0
    printed = capsys.readouterr().err  # warnings go to stderr
    tex = json.loads((out / "metrics.json").read_text())["texture"]
    skipped = dict(tex["skipped"])
    baseline = dict(clean["skipped"])
    assert skipped.pop("missing_rgb") == 1
    assert skipped.pop("corrupt_rgb") == 1
    assert skipped.pop("corrupt_disparity") == int(sharing.sum()) >= 1
    assert skipped == baseline  # the simulator's dropped disparity frames, as before
    assert tex["frames_used"] == clean["frames_used"] - 2 - int(sharing.sum())
    assert tex["count_mismatch"] == {"rgb": {"files": n_rgb + 1, "timestamps": n_rgb}}
    assert (out / "texture.png").is_file()
    warnings = json.loads((out / "metrics.json").read_text())["warnings"]
    assert any("RGB PNG missing" in w and "rgb20_3.png" in w for w in warnings)
    assert any("wrong size" in w and "rgb20_7.png" in w for w in warnings)
    assert any(f"disparity20_{k_disp + 1}.png" in w for w in warnings)
    assert any(f"holds {n_rgb + 1} rgb PNGs" in w for w in warnings)
    assert "slam: warning: texture: skipped 1 RGB frame(s): RGB PNG missing" in printed


def test_missing_image_folders_skip_the_stage_without_failing_the_run(small, tmp_path, capsys):
    bare = tmp_path / "bare"
    _link_dataset(small, bare, with_images=False)
    out = tmp_path / "run"
    assert main(["run", str(bare), "--out", str(out), *RUN]) == 0
    assert (out / "map.png").is_file() and not (out / "texture.png").exists()
    tex = json.loads((out / "metrics.json").read_text())["texture"]
    assert tex["skipped"].startswith("texture: skipped, RGB-D image folders missing")
    assert "slam: warning: texture: skipped, RGB-D image folders missing" in capsys.readouterr().err
    assert main(["texture", str(out), "--dataset", str(bare), "--quiet"]) == 2
    assert "RGB-D image folders missing" in capsys.readouterr().err


def test_slam_texture_replaces_nothing_with_an_empty_texture_or_in_a_foreign_folder(
    small, small_run, tmp_path, capsys
):
    """The bugs: `slam texture RUN --dataset OTHER`, whose frames lie nowhere on the run's
    trajectory, replaced the run's texture with an empty one and exited 0; and in a folder that
    `slam run` did not make it replaced the user's texture.png."""
    run = tmp_path / "run"
    shutil.copytree(small_run, run)
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    shifted = tmp_path / "shifted"  # the same recording, its Kinect clock 1000 s later
    _link_dataset(small, shifted)
    kinect = shifted / "Kinect20.npz"
    with np.load(small / "Kinect20.npz") as k:
        arrays = {name: k[name] for name in k.files}
    kinect.unlink()
    np.savez(kinect, **{n: a + 1000.0 if "time" in n else a for n, a in arrays.items()})
    assert main(["texture", str(run), "--dataset", str(shifted), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith(f"slam: error: {shifted}: no RGB-D frame of its ") and err.count("\n") == 1
    )
    assert "is it the log of this run? Nothing was written" in err
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == before
    mine = tmp_path / "mine"  # the run's files, copied by hand: no marker
    mine.mkdir()
    for name in ("trajectory.tum", "map.npz", "config.toml"):
        shutil.copyfile(small_run / name, mine / name)
    (mine / "texture.png").write_text("mine")
    assert main(["texture", str(mine), "--dataset", str(small), "--quiet"]) == 2
    assert "not a folder `slam run` made (no .slam-run)" in capsys.readouterr().err
    assert (mine / "texture.png").read_text() == "mine" and not (mine / "texture.npz").exists()
