"""``slam eval RUN_DIR`` without ground truth, and the score ``slam run`` writes at its end: the
table, eval.json, quality.png, and one-line errors (exit 2) for run folders that cannot be
scored."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from slam.cli import main

SCANS = 900  # every other scan of the 45 s log: one loop, back past the start


@pytest.fixture(scope="module")
def small_log(tmp_path_factory) -> Path:
    """The simulator's small loop (45 s, no RGB-D) as an ECE276A folder."""
    from slam.sim.dataset import SimOptions, generate_dataset

    folder = tmp_path_factory.mktemp("quality") / "small"
    generate_dataset(folder, SimOptions(scenario="small", seed=3, rgbd=False))
    return folder


@pytest.fixture(scope="module")
def run_folder(small_log, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("quality-run") / "run"
    assert main(["run", str(small_log), "--out", str(out), "--every", "2", "--quiet",
                 "--no-record"]) == 0  # fmt: skip
    return out


def copy_run(run_folder: Path, folder: Path) -> Path:
    """A copy of the run folder as `slam run` left it (no eval.json, no quality.png)."""
    shutil.copytree(run_folder, folder, ignore=shutil.ignore_patterns("eval.json", "quality.png"))
    return folder


def one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


def test_slam_run_scores_its_map(run_folder):
    metrics = json.loads((run_folder / "metrics.json").read_text())
    quality = metrics["quality"]
    assert metrics["log_source"].endswith("small")
    assert quality["score"] > 0.99  # the filter closes this small loop
    assert quality["stretches"] == 3 and quality["judged_stretches"] == 2
    assert quality["returns"] > 500_000 and quality["coverage"] > 0.4
    assert quality["picture"] == "quality.png"
    assert "per_stretch" not in quality  # metrics.json stays small
    image = cv2.imread(str(run_folder / "quality.png"))
    assert image is not None and max(image.shape[:2]) >= 1200


def test_a_good_run_gives_no_quality_warning(run_folder):
    metrics = json.loads((run_folder / "metrics.json").read_text())
    assert not [w for w in metrics["warnings"] if "map quality" in w]


def test_a_score_below_warn_below_is_a_warning_and_the_summary_line_gives_it(
    small_log, tmp_path, capsys
):
    """The same run with ``quality.warn_below = 1``: its score (above 0.99, below 1) warns on
    stderr and in metrics.json, naming the worst stretches; the summary line gives the score."""
    out = tmp_path / "run"
    assert main(["run", str(small_log), "--out", str(out), "--every", "2", "--quiet",
                 "--no-record", "--set", "quality.warn_below=1.0"]) == 0  # fmt: skip
    captured = capsys.readouterr()
    metrics = json.loads((out / "metrics.json").read_text())
    score, worst = metrics["quality"]["score"], metrics["quality"]["worst"]
    assert 0.99 < score < 1.0
    assert f"map quality {score:.3f}" in captured.out.splitlines()[-1]
    warned = [w for w in metrics["warnings"] if w.startswith("map quality")]
    assert len(warned) == 1 and f"slam: warning: {warned[0]}" in captured.err
    first = f"{worst[0]['time_s'][0]:.0f}-{worst[0]['time_s'][1]:.0f} s"
    assert f"{score:.3f} is below quality.warn_below = 1:" in warned[0] and first in warned[0]


def test_low_score_warning_needs_a_score_below_the_threshold():
    from slam.eval.quality_run import low_score_warning

    worst = [{"time_s": [12.3, 40.9]}, {"time_s": [100.0, 131.5]}]
    text = low_score_warning({"score": 0.1523, "worst": worst}, 0.65)
    assert text is not None and text.startswith("map quality 0.152 is below quality.warn_below")
    assert "the worst stretches at 12-41 s, 100-132 s (marked on map.png" in text
    assert text.endswith("docs/troubleshooting.md says what to check")
    assert low_score_warning({"score": 0.65, "worst": worst}, 0.65) is None
    assert low_score_warning({"score": float("nan"), "worst": []}, 0.65) is None
    assert low_score_warning({"score": None, "worst": []}, 0.65) is None
    assert low_score_warning({"score": 0.3, "worst": []}, 0.0) is None  # 0: never
    assert "worst" not in low_score_warning({"score": 0.3, "worst": []}, 0.65)


def test_map_png_marks_the_worst_stretches(run_folder):
    """map.png circles each of the score's worst stretches where its returns conflict, in the
    purple of quality.png, and draws its part of the path; a picture without them has none."""
    from slam.config import MapConfig
    from slam.io.exports import read_run_map
    from slam.io.tum import read_tum
    from slam.mapping import OccupancyGrid
    from slam.pipeline import WORST_COLOUR, render_map

    worst = json.loads((run_folder / "metrics.json").read_text())["quality"]["worst"]
    assert len(worst) == 2
    image = cv2.imread(str(run_folder / "map.png"))
    purple = np.all(image == WORST_COLOUR, axis=2)
    log_odds, resolution, origin = read_run_map(run_folder)
    grid = OccupancyGrid.from_arrays(log_odds, resolution, origin, MapConfig())
    scale = image.shape[0] // grid.shape[0]
    for mark in worst:
        cx, cy = grid.world_to_pixel(np.array(mark["place_xy"])) * scale + scale // 2
        r = 18 * max(1, round(max(image.shape[:2]) / 1000))
        ring = purple[max(cy - r - 3, 0) : cy + r + 4, max(cx - r - 3, 0) : cx + r + 4]
        assert ring.sum() > 3 * r, mark  # a circle of radius r there
    run = read_tum(run_folder / "trajectory.tum")
    plain = render_map(grid, run.poses)
    assert not np.all(plain == WORST_COLOUR, axis=2).any()
    again = np.all(render_map(grid, run.poses, None, worst, run.times) == WORST_COLOUR, axis=2)
    assert (again & purple).sum() > 0.9 * purple.sum()  # the marks slam run drew
    inside = (run.times >= worst[0]["log_time"][0]) & (run.times <= worst[0]["log_time"][1])
    px = grid.world_to_pixel(run.poses[inside][len(run.poses[inside]) // 2, :2]) * scale
    assert purple[px[1] - 3 : px[1] + 4, px[0] - 3 : px[0] + 4].any()  # the stretch's path


def test_a_label_at_the_right_edge_moves_to_the_left_of_its_mark():
    from slam.eval.quality_run import draw_label

    image = np.zeros((200, 300, 3), np.uint8)
    placed: list = []
    draw_label(image, "#1 100-200 s  0.50", (250, 50), (0, 0, 255), 1, placed, flip_gap=40)
    draw_label(image, "#2 300-400 s  0.60", (250, 50), (0, 0, 255), 1, placed, flip_gap=40)
    (a0, a1, a2, a3), (b0, b1, b2, b3) = placed
    assert a2 <= 250 - 40 + 3 and a0 >= 0  # ends left of the mark, inside the picture
    assert b1 >= a3  # the second one below the first, not over it
    draw_label(image, "legend", (10, 180), (0, 0, 0), 1, placed)
    assert placed[-1][0] == 7  # room on the right: where it was put


def test_eval_without_reference_prints_writes_and_draws(run_folder, capsys):
    (run_folder / "quality.png").unlink()
    assert main(["eval", str(run_folder)]) == 0
    out = capsys.readouterr().out
    assert "map quality  score 1.000" in out or "map quality  score 0.99" in out
    assert "stretches  3 of 10 m (2 ranked)" in out
    assert "worst      rank  time (s)" in out
    report = json.loads((run_folder / "eval.json").read_text())
    quality = report["quality"]
    assert report["poses"] == SCANS and "relations" not in report
    assert report["reference"].endswith("groundtruth.tum")  # the simulated folder's truth, too
    assert report["ate_rmse"] < 0.05
    assert len(quality["per_stretch"]) == 3
    assert quality["per_stretch"][0]["scans"] == [0, quality["per_stretch"][1]["scans"][0] - 1]
    assert (
        quality["checked"]
        == quality["agree"] + quality["conflict_free"] + quality["conflict_through"]
    )
    # The same figures as the run's own score (same trajectory, same scans, same parameters).
    metrics = json.loads((run_folder / "metrics.json").read_text())["quality"]
    for key in ("score", "coverage", "checked", "agree", "worst_score"):
        assert quality[key] == metrics[key]
    image = cv2.imread(str(run_folder / "quality.png"))
    assert image is not None and max(image.shape[:2]) >= 1200
    assert [p.name for p in run_folder.glob(".*")] == [".slam-run"]  # no temporary file left


def test_eval_with_reference_adds_quality_only_when_asked(run_folder, small_log, capsys):
    reference = small_log / "groundtruth.tum"
    assert main(["eval", str(run_folder), "--reference", str(reference), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert "quality" not in report and report["ate_rmse"] < 0.05
    assert main(["eval", str(run_folder), "--reference", str(reference), "--quality",
                 "--json"]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["ate_rmse"] < 0.05 and report["quality"]["score"] > 0.99


def test_an_opened_loop_in_a_run_folder_scores_worse(run_folder, tmp_path, capsys):
    """The same run folder with its trajectory bent after the midpoint: the score drops."""
    from slam.geometry import compose, relative
    from slam.io.tum import read_tum, write_tum
    from slam.trajectory import Trajectory

    bent = copy_run(run_folder, tmp_path / "bent")
    times, poses = read_tum(bent / "trajectory.tum")
    steps = relative(poses[:-1], poses[1:])
    half = len(poses) // 2
    for k in range(half, len(poses) - 1):
        step = steps[k] * np.array([1.015, 1.015, 1.0]) + np.array([0, 0, np.radians(8) / half])
        poses[k + 1] = compose(poses[k], step)
    write_tum(bent / "trajectory.tum", Trajectory(times, poses))
    assert main(["eval", str(bent), "--json"]) == 0
    bad = json.loads(capsys.readouterr().out)["quality"]
    good = json.loads((run_folder / "metrics.json").read_text())["quality"]
    assert bad["score"] < good["score"] - 0.1
    # The worst stretch is one of the two passes by the start, where the bent half meets the first.
    assert bad["worst"][0]["index"] in (0, 2) and bad["worst"][0]["score"] < 0.85


def test_run_folder_without_trajectory(run_folder, tmp_path, capsys):
    broken = copy_run(run_folder, tmp_path / "broken")
    (broken / "trajectory.tum").unlink()
    assert main(["eval", str(broken)]) == 2
    assert "broken/trajectory.tum: trajectory file not found" in one_line_error(capsys)
    assert not (broken / "eval.json").exists()


def test_run_folder_without_config(run_folder, tmp_path, capsys):
    broken = copy_run(run_folder, tmp_path / "noconfig")
    (broken / "config.toml").unlink()
    assert main(["eval", str(broken)]) == 2
    assert "noconfig/config.toml: not found" in one_line_error(capsys)
    assert not (broken / "eval.json").exists() and not (broken / "quality.png").exists()


@pytest.mark.parametrize(
    "text, expected",
    [
        ("{not json", "expected the run's metrics as JSON, cannot read it (Expecting property"),
        ("[1, 2]", "expected a JSON object, found list"),
    ],
)
def test_a_damaged_metrics_json_is_named(run_folder, tmp_path, capsys, text, expected):
    """The bug: a metrics.json that is not JSON was taken for a run that recorded no log, and
    the message blamed the dataset."""
    broken = copy_run(run_folder, tmp_path / "badmetrics")
    (broken / "metrics.json").write_text(text)
    assert main(["eval", str(broken), "--quality"]) == 2
    assert f"badmetrics/metrics.json: {expected}" in one_line_error(capsys)
    assert not (broken / "eval.json").exists() and not (broken / "quality.png").exists()


def test_log_no_longer_present(run_folder, small_log, tmp_path, capsys):
    moved = copy_run(run_folder, tmp_path / "moved")
    gone = tmp_path / "gone"
    metrics = json.loads((moved / "metrics.json").read_text())
    metrics["log_source"] = str(gone)
    (moved / "metrics.json").write_text(json.dumps(metrics))
    assert main(["eval", str(moved)]) == 2
    err = one_line_error(capsys)
    assert f"log_source {gone} no longer exists" in err and "--dataset PATH" in err
    assert not (moved / "eval.json").exists() and not (moved / "quality.png").exists()
    # Given the log again, the same folder scores as before.
    assert main(["eval", str(moved), "--dataset", str(small_log), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["quality"]["score"] > 0.99
    assert main(["eval", str(moved), "--dataset", str(tmp_path / "nowhere")]) == 2
    err = one_line_error(capsys)
    assert f"--dataset: {tmp_path / 'nowhere'}: no such file or folder" in err


def test_a_run_of_another_log_is_refused(run_folder, tmp_path, capsys):
    other = copy_run(run_folder, tmp_path / "other")
    text = (other / "trajectory.tum").read_text().splitlines()
    shifted = []
    for line in text:
        if line.startswith("#") or not line.strip():
            shifted.append(line)
            continue
        t, *rest = line.split()
        shifted.append(" ".join([f"{float(t) + 1e5:.6f}", *rest]))
    (other / "trajectory.tum").write_text("\n".join(shifted) + "\n")
    assert main(["eval", str(other)]) == 2  # the simulated folder's truth says it first
    assert "is it the same log?" in one_line_error(capsys)
    # Against itself as the reference, the trajectory passes; the map score still refuses it.
    itself = ["--reference", str(other / "trajectory.tum"), "--quality"]
    assert main(["eval", str(other), *itself]) == 2
    assert "cover none of the log's 900 scans" in one_line_error(capsys)
    assert not (other / "eval.json").exists() and not (other / "quality.png").exists()


def test_the_score_can_be_switched_off(small_log, tmp_path):
    out = tmp_path / "off"
    assert main(["run", str(small_log), "--out", str(out), "--max-scans", "50", "--quiet",
                 "--no-record", "--set", "quality.enabled=false"]) == 0  # fmt: skip
    metrics = json.loads((out / "metrics.json").read_text())
    assert "quality" not in metrics and metrics["log_source"].endswith("small")
    assert not (out / "quality.png").exists()
    assert "enabled = false" in (out / "config.toml").read_text().split("[quality]")[1]


@pytest.mark.parametrize("linked", [False, True])
def test_eval_of_a_registry_ece276a_run_reads_its_dataset_not_the_shared_folder(
    small_log, tmp_path, capsys, monkeypatch, linked
):
    """``slam run dataset20`` on a data directory whose ece276a/ holds datasets 20 and 21 side by
    side (docs/data.md): metrics.json's log_source is that folder, which names neither; `slam
    eval RUN` reads the config's dataset20 (on main: "expected the files of one ECE276A dataset
    in the folder ..., found those of 20, 21"), from --data-dir, or without it from the data
    directory the run read (the default one, here empty, lacks the dataset's scans); also when
    the data directory's ece276a/ is a link to a folder of another name."""
    data = tmp_path / "data"
    if linked:
        (tmp_path / "store" / "pr2data").mkdir(parents=True)
        data.mkdir()
        (data / "ece276a").symlink_to(tmp_path / "store" / "pr2data")
    else:
        (data / "ece276a").mkdir(parents=True)
    for number in ("20", "21"):
        for stream in ("Encoders", "Imu", "Hokuyo"):
            shutil.copy(small_log / f"{stream}20.npz", data / "ece276a" / f"{stream}{number}.npz")
    run = tmp_path / "run20"
    assert main(["run", "dataset20", "--data-dir", str(data), "--out", str(run), "--every", "2",
                 "--quiet", "--no-record"]) == 0  # fmt: skip
    capsys.readouterr()
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["log_source"] == os.path.abspath(data / "ece276a")
    (tmp_path / "empty").mkdir()
    monkeypatch.setenv("SLAM_DATA_DIR", str(tmp_path / "empty"))
    for extra in (["--data-dir", str(data)], []):
        assert main(["eval", str(run), "--json", *extra]) == 0, capsys.readouterr().err
        report = json.loads(capsys.readouterr().out)
        assert report["dataset"] == "dataset20"
        assert report["quality"]["score"] == metrics["quality"]["score"] > 0.99
        assert report["quality"]["checked"] == metrics["quality"]["checked"]


def test_a_registry_run_of_another_log_says_why_there_is_no_ground_truth(
    carmen_dir, tmp_path, capsys
):
    """intel's run with its times moved away: its relations match nothing (a warning) and the map
    score refuses it; the error says why there is no ground truth either (it ended in a literal
    'None')."""
    data = ["--data-dir", str(carmen_dir.parent)]
    out = tmp_path / "intel"
    run = ["run", "intel", *data, "--max-scans", "150", "--out", str(out), "--quiet", "--no-record"]
    assert main(run) == 0
    lines = (out / "trajectory.tum").read_text().splitlines()
    moved = [
        line if line.startswith("#") else " ".join([f"{float(line.split()[0]) + 1e5:.6f}",
                                                    *line.split()[1:]])
        for line in lines
    ]  # fmt: skip
    (out / "trajectory.tum").write_text("\n".join(moved) + "\n")
    capsys.readouterr()
    assert main(["eval", str(out), *data]) == 2
    warning, error = capsys.readouterr().err.splitlines()
    assert warning.startswith("slam: warning: ") and warning.endswith("; left out")
    assert "is it the same log?" in error and "None" not in error
    assert error.endswith(
        "and no ground truth either: the dataset's relations were left out (the warning above "
        "says why)"
    )
