"""Rerun recordings read back: entities, timelines, row counts and values (recorder, slam run,
slam grid run --record, slam maze run --record)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from rerun.chunk import RrdReader
from tool_modules import load_tool

from slam.cli import main
from slam.config import VizConfig
from slam.errors import ConfigError
from slam.viz import blueprint as bp
from slam.viz.stream import rerun_executable, summarize, viewer_env


def rows(
    path: Path, entity: str, field: str, timeline: str | None = "scan"
) -> list[tuple[int, object]]:
    """``(index, value)`` of every temporal row of ``entity`` holding ``field``, sorted
    (``timeline=None``: the static rows, index -1)."""
    out = []
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.entity_path != f"/{entity}" or chunk.is_static != (timeline is None):
            continue
        batch = chunk.to_record_batch()
        if field not in batch.schema.names:
            continue
        n = batch.num_rows
        index = [-1] * n if timeline is None else batch.column(timeline).to_pylist()
        values = batch.column(field).to_pylist()
        out += [(i, v) for i, v in zip(index, values, strict=True) if v is not None]
    return sorted(out, key=lambda r: r[0])


def map_pictures(path: Path, entity: str = bp.MAP) -> list[tuple[int, np.ndarray]]:
    """``(scan, pixels)`` of every map picture logged at ``entity`` (PNG blobs, decoded)."""
    out = []
    for i, blob in rows(path, entity, "EncodedImage:blob"):
        pixels = cv2.imdecode(np.frombuffer(bytes(blob[0]), np.uint8), cv2.IMREAD_UNCHANGED)
        out.append((i, pixels))
    return out


@pytest.fixture(scope="module")
def scripted(tmp_path_factory) -> Path:
    """The golden scripted run (tools/make_viz_reference.py) written to a temporary file."""
    tool = load_tool("make_viz_reference")
    return tool.write_reference(tmp_path_factory.mktemp("viz") / "scripted.rrd")


def test_scripted_recording_has_every_entity_with_the_documented_row_counts(scripted):
    s = summarize(scripted)
    steps = 40
    per_scan = (bp.TRAJECTORY, bp.ROBOT, bp.N_EFF, bp.MAX_WEIGHT)
    for entity in per_scan:
        assert s[f"/{entity}"].rows == steps, entity
        assert s[f"/{entity}"].timelines == {"scan", "time"}
    # details every 5 scans: steps 0, 5, ..., 35
    assert s[f"/{bp.PARTICLES}"].rows == 8
    assert s[f"/{bp.SCAN}"].rows == 8
    # a rate needs an earlier detail step: 7 values
    assert s[f"/{bp.SCANS_PER_S}"].rows == 7
    # map every 10 scans (10, 20, 30) and the final map
    assert s[f"/{bp.MAP}"].rows == 4
    assert {"EncodedImage:blob", "Transform3D:translation", "Transform3D:scale"} <= s[
        f"/{bp.MAP}"
    ].fields
    assert s[f"/{bp.TRAJECTORY_FINAL}"].rows == 1
    assert s[f"/{bp.TEXTURE}"].static_rows == 1  # the finished texture, visible at any time
    assert s[f"/{bp.GROUND_TRUTH}"].static_rows == 1 and s[f"/{bp.GROUND_TRUTH}"].rows == 0
    assert s[f"/{bp.WORLD}"].fields == {"Transform3D:mat3x3"}
    assert RrdReader(scripted).blueprints(), "the default blueprint is in the file"


def test_trajectory_segments_join_consecutive_poses(scripted):
    poses = load_tool("make_viz_reference").scripted_poses()
    segments = rows(scripted, bp.TRAJECTORY, "LineStrips2D:strips")
    assert [i for i, _ in segments] == list(range(40))
    for k, strips in segments:
        (segment,) = strips
        start = poses[max(k - 1, 0), :2]
        np.testing.assert_allclose(segment, [start, poses[k, :2]], atol=1e-6)


def test_particles_scans_and_rates_values(scripted):
    tool = load_tool("make_viz_reference")
    poses = tool.scripted_poses()
    particles = rows(scripted, bp.PARTICLES, "Points2D:positions")
    assert [i for i, _ in particles] == [0, 5, 10, 15, 20, 25, 30, 35]
    offsets = np.linspace(-0.05, 0.05, 8)
    np.testing.assert_allclose(
        particles[2][1], poses[10, :2] + np.stack([offsets, -offsets], axis=1), atol=1e-6
    )
    colours = rows(scripted, bp.PARTICLES, "Points2D:colors")
    assert len(colours[0][1]) == 8 and colours[0][1][0] != colours[0][1][-1]
    scans = rows(scripted, bp.SCAN, "Points2D:positions")
    assert all(len(points) == 24 for _, points in scans)  # 36 endpoints thinned to 24
    rates = rows(scripted, bp.SCANS_PER_S, "Scalars:scalars")
    # the fake clock advances 10 ms per reading, one reading every 5 scans: 500 scans/s
    assert [i for i, _ in rates] == [5, 10, 15, 20, 25, 30, 35]
    np.testing.assert_allclose([v[0] for _, v in rates], 500.0, rtol=1e-9)


def test_map_image_is_placed_at_its_lower_left_corner(scripted):
    translations = rows(scripted, bp.MAP, "Transform3D:translation")
    scales = rows(scripted, bp.MAP, "Transform3D:scale")
    assert [i for i, _ in translations] == [10, 20, 30, 39]
    for _, scale in scales:
        np.testing.assert_allclose(scale[0], [0.1, 0.1, 1.0])
    # the observed area spans the robot's circle (radius 2) and the wall at y = 2.6, one cell
    # of margin: x from about -2.6, y from about -0.1
    corner = np.asarray(translations[-1][1][0])
    assert -2.8 < corner[0] < -2.4 and -0.3 < corner[1] < 0.1
    pictures = map_pictures(scripted)
    assert [i for i, _ in pictures] == [10, 20, 30, 39]
    height, width = pictures[-1][1].shape
    assert width * 0.1 > 5.0 and height * 0.1 > 2.6
    media = rows(scripted, bp.MAP, "EncodedImage:media_type")
    assert {m[0] for _, m in media} == {"image/png"}


def _nine_steps_before_a_wall(recorder) -> np.ndarray:
    """Feed ``recorder`` nine steps at the origin, every other one with the endpoints of a wall
    2 m ahead (returned)."""
    from slam.observers import StepRecord

    wall = np.stack([np.linspace(-1, 1, 50), np.full(50, 2.0)], axis=1)
    for k in range(9):
        record = StepRecord(k, k, float(k), np.array([0.0, 0.0, 0.0]), 5.0, 0.2, True, False)
        if k % 2 == 0:
            record.endpoints = wall
        recorder.on_step(record)
    return wall


def test_map_snapshots_preview_the_logged_scans_and_on_map_logs_when_due(tmp_path):
    from slam.config import MapConfig
    from slam.mapping import OccupancyGrid
    from slam.trajectory import Trajectory
    from slam.viz.recorder import RunRecorder

    recorder = RunRecorder(tmp_path / "r.rrd", VizConfig(map_every=4, detail_every=2))
    assert recorder.map_every == 0  # the filter's own live map is not requested
    wall = _nine_steps_before_a_wall(recorder)
    grid = OccupancyGrid(MapConfig(), center=(0.0, 0.0))
    grid.integrate(np.zeros(2), wall, np.ones(50, dtype=bool))
    recorder.on_map(9, 9.0, grid)  # not due: the last snapshot was at 8
    recorder.on_map(13, 13.0, grid)  # due (≥ 12)
    recorder.finish(Trajectory(np.arange(9.0), np.zeros((9, 3))), None)
    snapshots = map_pictures(tmp_path / "r.rrd")
    assert [i for i, _ in snapshots] == [4, 8, 13]
    from slam.viz.images import occupancy_image

    # the PNG is lossless: the snapshot of step 13 is the grid's picture to the pixel
    np.testing.assert_array_equal(snapshots[2][1], occupancy_image(grid, 16).pixels)
    # the preview holds the wall: occupied (dark) pixels in the top rows of the image
    pixels = snapshots[0][1]
    assert pixels.dtype == np.uint8 and pixels.ndim == 2
    assert pixels.min() < 60 and pixels.max() > 200


def test_a_coarsened_grid_keeps_walls_and_free_space_in_place():
    """OccupancyGrid.coarsened: a block takes its largest positive log-odds (a wall), else its
    smallest (free space); odd sides are padded with unknown cells; the lower-left corner stays;
    rays integrate at the coarse cell afterwards."""
    from slam.config import MapConfig
    from slam.mapping import OccupancyGrid

    lo = np.zeros((5, 3), dtype=np.float32)
    lo[0, 0], lo[0, 1] = 2.0, -1.5  # a wall beside free space: the wall wins
    lo[1, 1] = -0.5
    lo[2, 0], lo[3, 1] = -0.4, -2.0  # free space only: the freest
    lo[4, 2] = 3.0  # the padded last row and column
    grid = OccupancyGrid.from_arrays(lo, 0.05, np.array([1.0, -2.0]), MapConfig())
    coarse = grid.coarsened(2)
    assert coarse.shape == (3, 2) and coarse.log_odds.dtype == np.float32
    np.testing.assert_array_equal(coarse.log_odds, [[2.0, 0.0], [-2.0, 0.0], [0.0, 3.0]])
    assert coarse.resolution == coarse.config.resolution == 0.1
    np.testing.assert_array_equal(coarse.origin, [1.0, -2.0])
    coarse.integrate(np.array([1.05, -1.95]), np.array([[1.55, -1.95]]), np.array([True]))
    assert coarse.log_odds[0, 5] > 0 and coarse.log_odds[0, 2] < 0  # a ray at 0.1 m cells
    with pytest.raises(ValueError, match="factor of at least 1"):
        grid.coarsened(0)


@pytest.mark.parametrize(("budget", "cell"), [(8_000_000, 0.05), (200_000, 0.1), (50_000, 0.2)])
def test_the_preview_map_is_coarsened_to_its_cell_budget(tmp_path, budget, cell):
    """viz.preview_cells: a live map over the budget (800 × 800 cells of 5 cm at first) has its
    cells doubled until it fits; the snapshots say so (their scale) and still show the wall."""
    from slam.trajectory import Trajectory
    from slam.viz.recorder import RunRecorder

    config = VizConfig(map_every=4, detail_every=2, preview_cells=budget)
    recorder = RunRecorder(tmp_path / "r.rrd", config)
    _nine_steps_before_a_wall(recorder)
    assert recorder._preview.log_odds.size <= budget
    assert recorder._preview.resolution == pytest.approx(cell)
    recorder.finish(Trajectory(np.arange(9.0), np.zeros((9, 3))), None)
    scales = rows(tmp_path / "r.rrd", bp.MAP, "Transform3D:scale")
    assert [i for i, _ in scales] == [4, 8]
    for _, scale in scales:
        np.testing.assert_allclose(scale[0], [cell, cell, 1.0])
    pixels = map_pictures(tmp_path / "r.rrd")[-1][1]
    assert pixels.min() < 60 and pixels.max() > 200
    assert pixels.shape[1] * cell == pytest.approx(2.0 + 2 * cell, abs=2 * cell)  # the wall's span


def test_texture_is_rgba_with_unseen_cells_transparent(scripted):
    (_, buffer) = rows(scripted, bp.TEXTURE, "Image:buffer", timeline=None)[0]
    (_, fmt) = rows(scripted, bp.TEXTURE, "Image:format", timeline=None)[0]
    assert fmt[0]["width"] == 4 and fmt[0]["height"] == 4
    pixels = np.frombuffer(bytes(buffer[0]), dtype=np.uint8).reshape(4, 4, 4)
    assert pixels[0, 0, 3] == 0 and pixels[1, 1, 3] == 255
    np.testing.assert_array_equal(pixels[..., :3].reshape(-1), np.arange(48) * 5)


def test_viz_config_rejects_bad_cadences():
    with pytest.raises(ConfigError, match="viz.map_every"):
        VizConfig(map_every=-1)
    with pytest.raises(ConfigError, match="viz.map_levels"):
        VizConfig(map_levels=1)
    with pytest.raises(ConfigError, match="viz.scan_points"):
        VizConfig(scan_points=0)
    with pytest.raises(ConfigError, match="viz.preview_cells"):
        VizConfig(preview_cells=0)


@pytest.fixture(scope="module")
def small_log(tmp_path_factory) -> Path:
    """A 6 s noisy simulated log (ECE276A format, with ground truth), no Kinect."""
    out = tmp_path_factory.mktemp("sim") / "small"
    assert main(["sim", "small", "--out", str(out), "--duration", "6", "--no-rgbd", "--quiet"]) == 0
    return out


def test_slam_run_records_one_row_per_scan_and_details_every_k(small_log, tmp_path):
    out = tmp_path / "run"
    code = main(
        ["run", str(small_log), "--out", str(out), "--particles", "8", "--max-scans", "150",
         "--set", "viz.detail_every=7", "--set", "viz.map_every=40", "--quiet"]
    )  # fmt: skip
    assert code == 0
    metrics = json.loads((out / "metrics.json").read_text())
    rrd = out / "recording.rrd"
    verify = subprocess.run(
        [*rerun_executable(), "rrd", "verify", str(rrd)],
        env=viewer_env(),
        capture_output=True,
        text=True,
    )
    assert verify.returncode == 0, verify.stderr
    s = summarize(rrd)
    n = metrics["poses"]
    assert n == 150
    for entity in (bp.TRAJECTORY, bp.ROBOT, bp.N_EFF, bp.MAX_WEIGHT):
        assert s[f"/{entity}"].rows == n, entity
    assert s[f"/{bp.PARTICLES}"].rows == math.ceil(n / 7)
    assert s[f"/{bp.SCAN}"].rows == math.ceil(n / 7)
    # live snapshots at the first update scan at or after 40, 80, 120, plus the final map
    assert 2 <= s[f"/{bp.MAP}"].rows <= 4
    assert s[f"/{bp.GROUND_TRUTH}"].static_rows == 1
    assert metrics["recording"]["steps"] == n
    assert metrics["recording"]["size_mb"] == pytest.approx(rrd.stat().st_size / 2**20, abs=0.01)
    # the live trajectory ends where the run's estimate of the last scan is
    final = rows(rrd, bp.TRAJECTORY_FINAL, "LineStrips2D:strips")
    assert len(final) == 1 and len(final[0][1][0]) == n
    n_eff = rows(rrd, bp.N_EFF, "Scalars:scalars")
    assert all(1.0 <= v[0] <= 8.0 + 1e-9 for _, v in n_eff)


def test_no_record_leaves_no_recording(small_log, tmp_path):
    out = tmp_path / "run"
    code = main(
        ["run", str(small_log), "--out", str(out), "--particles", "4", "--max-scans", "30",
         "--no-record", "--quiet"]
    )  # fmt: skip
    assert code == 0
    assert not (out / "recording.rrd").exists()
    assert "recording" not in json.loads((out / "metrics.json").read_text())
    assert "record = false" in (out / "config.toml").read_text()


def test_grid_run_records_the_posterior_after_every_step(tmp_path, capsys):
    rrd = tmp_path / "grid.rrd"
    assert main(["grid", "run", "tutorial-1d", "--record", str(rrd)]) == 0
    capsys.readouterr()
    s = summarize(rrd)
    assert s["/grid/posterior"].rows == 4 and s["/grid/posterior"].timelines == {"step"}
    assert s["/metrics/max_probability"].rows == 4
    assert s["/grid/world"].static_rows == 1
    best = rows(rrd, "metrics/max_probability", "Scalars:scalars", "step")
    # "move 2" from [0, .5, 0, .5, 0] gives [.4, .05, .05, .4, .1]: the best cell holds 0.4
    assert best[0][1][0] == pytest.approx(0.4)
    (_, fmt) = rows(rrd, "grid/posterior", "Image:format", "step")[0]
    assert (fmt[0]["width"], fmt[0]["height"]) == (5, 1)
    (_, buffer) = rows(rrd, "grid/posterior", "Image:buffer", "step")[0]
    heat = np.frombuffer(bytes(buffer[0]), dtype=np.uint8).reshape(5, 3)
    # viridis: the two 0.4 cells are yellow (the maximum), the 0.05 cells dark
    assert heat[0].tolist() == heat[3].tolist() and heat[0, 1] > 200 and heat[1, 1] < 120


def test_grid_record_needs_an_rrd_name(tmp_path, capsys):
    assert main(["grid", "run", "tutorial-1d", "--record", str(tmp_path / "x.txt")]) == 2
    assert "expected a file name ending in .rrd" in capsys.readouterr().err


def test_maze_recording_shows_known_walls_and_both_runs(tmp_path):
    from slam.maze.bench import trial
    from slam.maze.formats import EAST, NORTH, maze_from_walls
    from slam.viz.maze import record_maze_trial, wall_segments, wall_sides

    maze = maze_from_walls(4, 4, walls=[((0, 0), EAST), ((1, 2), NORTH)], name="tiny")
    sides = wall_sides(maze)
    # the border (4 × 4 sides) and the two interior walls
    assert sides["vertical"].sum() == 8 + 1 and sides["horizontal"].sum() == 8 + 1
    assert wall_segments(sides["vertical"], sides["horizontal"]).shape == (18, 2, 2)
    result = trial(maze, "bounded")
    assert result.success
    rrd = tmp_path / "maze.rrd"
    assert record_maze_trial(result, rrd) == result.total_steps + 1
    s = summarize(rrd)
    assert s["/maze/robot"].rows == result.total_steps + 1
    run0 = int((result.run == 0).sum())
    assert s["/maze/path/run0"].rows == run0 + 1  # plus the start
    assert s["/maze/path/run1"].rows == result.total_steps - run0
    assert s["/maze/walls/true"].static_rows == 1
    known = rows(rrd, "maze/walls/known", "LineStrips2D:strips", "step")
    assert 1 <= len(known) <= result.total_steps + 1
    counts = [len(strips) for _, strips in known]
    assert counts == sorted(counts) and counts[-1] <= 18
    truth = {
        tuple(map(tuple, seg)) for seg in wall_segments(sides["vertical"], sides["horizontal"])
    }
    assert {tuple(map(tuple, np.asarray(seg))) for seg in known[-1][1]} <= truth


def test_maze_run_cli_writes_the_recording(tmp_path, capsys):
    from slam.maze.formats import maze_from_walls, write_maze

    path = tmp_path / "open4.txt"
    write_maze(maze_from_walls(4, 4, name="open4"), path, "udacity")
    rrd = tmp_path / "m.rrd"
    assert main(["maze", "run", str(path), "--record", str(rrd)]) == 0
    assert "score" in capsys.readouterr().out
    assert summarize(rrd)["/maze/robot"].rows >= 2


def test_a_run_without_recording_does_not_import_rerun(carmen_dir, tmp_path):
    # rerun's import costs 0.5-1.3 s of every run's wall time: a run that records nothing
    # (--no-record, no --viewer) must not pay it; the same run recording does import it
    from cli_process import cli_env

    def imports_rerun(*flags: str) -> bool:
        out = tmp_path / f"run{len(flags)}"
        code = (
            "import sys; from slam.cli import main; "
            f"args = ['run', {str(carmen_dir / 'intel.clf.gz')!r}, '--max-scans', '60', "
            f"'--no-texture', '--quiet', '--out', {str(out)!r}, *{list(flags)!r}]; "
            "assert main(args) == 0; print('rerun' in sys.modules)"
        )
        done = subprocess.run(
            [sys.executable, "-c", code], env=cli_env(), capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr
        return done.stdout.strip().splitlines()[-1] == "True"

    assert not imports_rerun("--no-record")
    assert imports_rerun()
