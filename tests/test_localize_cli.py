"""``slam localize`` end to end on a synthetic box room, the Python API, and the CLI's errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_process import finished_run
from synthetic_logs import carmen_lines, flaser_line, path, ray_cast, write_carmen

from slam.cli import main
from slam.io.tum import read_tum
from slam.localize.maps import LikelihoodMap, load_map

SCANS = 160
BACK_AT, BACK_S = 50, 0.35
"""The clock of :func:`stepped_log` steps back ``BACK_S`` at scan ``BACK_AT`` (as intel's does)."""


def one_line_error(capsys) -> str:
    """The stderr of a failed command: exactly one ``slam: error:`` line, no traceback."""
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("slam: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> tuple[Path, Path]:
    """A synthetic CARMEN log of a box room and the ``slam run`` folder of its map."""
    folder = tmp_path_factory.mktemp("room")
    log = write_carmen(folder, carmen_lines(SCANS))
    run = finished_run(log, folder / "run", "--no-record", "--no-texture", "--quiet")
    return log, run


@pytest.fixture(scope="module")
def tracked(room, tmp_path_factory) -> Path:
    log, run = room
    out = tmp_path_factory.mktemp("loc") / "tracked"
    x, y, theta = read_tum(run / "trajectory.tum").poses[0]
    code = main(["localize", str(log), "--map", str(run), f"--initial={x},{y},{theta},0.1",
                 "--out", str(out), "--quiet"])  # fmt: skip
    assert code == 0
    return out


def test_localize_writes_the_run_folder(tracked):
    names = {p.name for p in tracked.iterdir()}
    assert {".slam-localize", "config.toml", "trajectory.tum", "localization.npz", "map.png",
            "metrics.json", "recording.rrd"} <= names  # fmt: skip
    m = json.loads((tracked / "metrics.json").read_text())
    for key in ("time_to_convergence_s", "distance_to_convergence_m", "localized_share",
                "mean_match_quality", "particles_mean", "particles_max", "real_time_factor",
                "estimate_cpu_s", "peak_rss_mb", "histogram_steps", "lost_events"):  # fmt: skip
        assert key in m, key
    assert m["scans"] == SCANS and m["mode"] == "initial pose"
    assert m["localized_share"] == 1.0 and m["time_to_convergence_s"] == 0.0
    assert m["mean_match_quality"] > 0.9 and m["lost_events"] == 0
    assert 200 <= m["particles_mean"] <= 10000
    with np.load(tracked / "localization.npz") as d:
        assert d["covariances"].shape == (SCANS, 3, 3)
        assert np.all(np.linalg.eigvalsh(d["covariances"]) >= -1e-12)
        assert set(np.unique(d["phase"])) == {1}


def test_tracking_follows_the_map_run(room, tracked):
    slam = read_tum(room[1] / "trajectory.tum")
    loc = read_tum(tracked / "trajectory.tum")
    err = np.hypot(*(loc.poses[:, :2] - slam.poses[:, :2]).T)
    # the box's walls lie on cell boundaries: the distance field (to occupied cell centres)
    # sits half a cell (2.5 cm) inside them, and the poses follow it
    assert np.median(err) < 0.04 and err.max() < 0.06
    assert np.all(np.abs(np.angle(np.exp(1j * (loc.poses[:, 2] - slam.poses[:, 2])))) < 0.03)


def test_recording_holds_map_particles_and_series(tracked):
    from slam.viz.stream import summarize

    entities = summarize(tracked / "recording.rrd")
    assert entities["/world/map"].static_rows == 1
    assert entities["/world/particles"].rows == SCANS // 10
    assert entities["/world/trajectory/final"].rows == 1
    for name in ("robot", "trajectory/live"):
        assert entities[f"/world/{name}"].rows == SCANS, name
    for name in ("quality", "particles", "localized"):
        assert entities[f"/metrics/{name}"].rows == SCANS, name
    assert "/world/histogram" not in entities  # tracking from the start: no global filter


def test_global_localization_finds_the_room_pose(room, tmp_path):
    log, run = room
    out = tmp_path / "global"
    assert main(["localize", str(log), "--map", str(run), "--global", "--out", str(out),
                 "--quiet"]) == 0  # fmt: skip
    m = json.loads((out / "metrics.json").read_text())
    assert m["mode"] == "global" and m["converged"] and m["histogram_steps"] >= 1
    assert m["time_to_convergence_s"] < 5.0
    assert m["histogram"]["headings"] == 36 and m["histogram"]["resolution"] == 0.25
    slam = read_tum(run / "trajectory.tum").poses
    with np.load(out / "localization.npz") as d:
        localized = d["localized"]
        poses = d["poses"]
    err = np.hypot(*(poses[localized, :2] - slam[localized, :2]).T)
    assert localized.mean() > 0.85 and err.max() < 0.1
    from slam.viz.stream import summarize

    assert summarize(out / "recording.rrd")["/world/histogram"].rows >= m["histogram_steps"]


def test_python_api_localizes_hand_made_scans(room):
    """slam.Localizer(map, config).update(slam.Scan, odometry): scans ray-cast in the room at
    the true poses, odometry with a constant offset (any frame will do)."""
    import slam
    from slam.localize.maps import load_map

    config = slam.load_config("room", None, ["lidar.range_max=30", "lidar.no_return=30",
                                               "lidar.x=0", "lidar.range_min=0.05"])  # fmt: skip
    slam_start = read_tum(room[1] / "trajectory.tum").poses[0]
    loc = slam.Localizer(load_map(room[1]), config, initial=(*slam_start, 0.1), seed=3)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 180)
    truth = path(SCANS)
    offset = np.array([10.0, -4.0, 0.0])
    for k, pose in enumerate(truth):
        est = loc.update(slam.Scan(100.0 + 0.1 * k, ray_cast(pose, angles), angles), pose + offset)
    assert isinstance(est, slam.LocalizationEstimate)
    assert est.localized and est.phase == "tracking"
    assert np.hypot(*(est.pose[:2] - truth[-1][:2])) < 0.1
    assert est.covariance.shape == (3, 3) and est.particles >= 200


def test_python_api_refuses_what_it_cannot_use(room):
    import slam
    from slam.errors import DataError, UsageError
    from slam.localize.maps import load_map

    loc = slam.Localizer(load_map(room[1]), slam.load_config("room"))
    with pytest.raises(UsageError, match="expected a slam.Scan"):
        loc.update(np.zeros(180), np.zeros(3))
    scan = slam.Scan(1.0, np.ones(3), np.zeros(3), range_max=20.0)
    with pytest.raises(DataError, match="odometry must be a finite pose"):
        loc.update(scan, [0.0, np.nan, 0.0])
    with pytest.raises(UsageError, match="initial pose: expected x, y, theta"):
        slam.Localizer(load_map(room[1]), initial=(1.0, 2.0))


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("1,2", "expected x,y,theta or x,y,theta,sigma (metres, radians), found 2 values"),
        ("1,2,3,4,5", "found 5 values"),
        ("a,2,3", "x must be a number, found 'a'"),
        ("1,2,nan", "theta must be finite, found 'nan'"),
        ("1,2,3,0", "sigma must be > 0 m, found '0'"),
        ("1,2,3,-1", "sigma must be > 0 m, found '-1'"),
        ("1,2,90", "theta must be radians within ±2π, found 90 (degrees? 1.571 rad)"),
    ],
)
def test_bad_initial_is_one_line(room, tmp_path, capsys, value, message):
    log, run = room
    code = main(["localize", str(log), "--map", str(run), f"--initial={value}",
                 "--out", str(tmp_path / "o"), "--quiet"])  # fmt: skip
    assert code == 2
    line = one_line_error(capsys)
    assert f"--initial {value!r}" in line and message in line
    assert not (tmp_path / "o").exists()


def test_missing_or_bad_map_is_one_line(room, tmp_path, capsys):
    log, _ = room
    missing = tmp_path / "nowhere"
    assert main(["localize", str(log), "--map", str(missing), "--out", str(tmp_path / "o")]) == 2
    assert f"{missing}: map not found" in one_line_error(capsys)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["localize", str(log), "--map", str(empty), "--out", str(tmp_path / "o")]) == 2
    assert "no map.npz in this folder" in one_line_error(capsys)
    bad = tmp_path / "bad.npz"
    np.savez(bad, log_odds=np.zeros((4, 4)), resolution=0.05)
    assert main(["localize", str(log), "--map", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert f"{bad}: expected keys log_odds, resolution, origin; missing origin" in one_line_error(
        capsys
    )
    flat = tmp_path / "flat.npz"
    np.savez(flat, log_odds=np.zeros((4, 4)), resolution=0.05, origin=np.zeros(2))
    assert main(["localize", str(log), "--map", str(flat), "--out", str(tmp_path / "o")]) == 2
    assert f"{flat}: no occupied cell (log-odds above map.occupied_threshold" in one_line_error(
        capsys
    )
    # a map_server folder, or its image, point at the map.yaml
    served = tmp_path / "served"
    served.mkdir()
    (served / "map.yaml").write_text("image: map.pgm\n")
    (served / "map.pgm").write_bytes(b"P5\n1 1\n255\n\x00")
    for given in (served, served / "map.pgm"):
        assert main(["localize", str(log), "--map", str(given), "--out", str(tmp_path / "o")]) == 2
        assert f"--map {served / 'map.yaml'}" in one_line_error(capsys)
    assert not (tmp_path / "o").exists()


def test_initial_and_global_exclude_each_other(room, capsys):
    log, run = room
    with pytest.raises(SystemExit) as exc:
        main(["localize", str(log), "--map", str(run), "--initial=0,0,0", "--global"])
    assert exc.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_existing_output_needs_force(room, tracked, capsys):
    log, run = room
    args = ["localize", str(log), "--map", str(run), "--initial=-3,-1,0.15,0.1", "--out",
            str(tracked), "--quiet", "--no-record", "--max-scans", "20"]  # fmt: skip
    assert main(args) == 2
    assert "output folder exists and is not empty (use --force" in one_line_error(capsys)
    assert main([*args, "--force"]) == 0
    assert json.loads((tracked / "metrics.json").read_text())["scans"] == 20
    # a slam run folder is not ours to replace
    assert main([*args[:-6], "--out", str(run), "--force"]) == 2
    assert "holds an input of this command" in one_line_error(capsys)


def test_map_yaml_of_a_run_localizes_like_its_run_folder(room, tmp_path):
    """``--map RUN/map.yaml`` (the map_server files every run writes) tracks like ``--map RUN``:
    the map's occupied and free cells are the same masks, up to map_server's thresholds."""
    from slam.localize.maps import load_map

    log, run = room
    from_yaml, from_run = load_map(run / "map.yaml"), load_map(run)
    assert from_yaml.resolution == from_run.resolution
    np.testing.assert_allclose(from_yaml.origin, from_run.origin)
    x, y, theta = read_tum(run / "trajectory.tum").poses[0]
    for name, where in (("folder", run), ("yaml", run / "map.yaml")):
        code = main(["localize", str(log), "--map", str(where), f"--initial={x},{y},{theta},0.1",
                     "--out", str(tmp_path / name), "--quiet"])  # fmt: skip
        assert code == 0
    a = read_tum(tmp_path / "folder" / "trajectory.tum").poses
    b = read_tum(tmp_path / "yaml" / "trajectory.tum").poses
    assert a.shape == b.shape == (SCANS, 3)
    assert np.hypot(*(a[:, :2] - b[:, :2]).T).max() < 0.02


def test_map_yaml_with_a_rotated_origin_is_one_line(room, tmp_path, capsys):
    log, run = room
    text = (run / "map.yaml").read_text()
    bad = tmp_path / "map.yaml"
    (tmp_path / "map.pgm").write_bytes((run / "map.pgm").read_bytes())
    origin = next(line for line in text.splitlines() if line.startswith("origin"))
    bad.write_text(text.replace(origin, origin.replace(", 0.0]", ", 0.5]")))
    assert main(["localize", str(log), "--map", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "origin yaw 0.5 rad" in one_line_error(capsys)


def test_a_negative_initial_needs_no_equals_sign(room, tmp_path, capsys):
    """The bug: ``--initial -3,-1,0.15,0.1`` was read as an option ("argument --initial:
    expected one argument"); only ``--initial=-3,...`` worked. Both forms now give the same
    run, and a negative list of the wrong length is the command's own one-line error."""
    log, run = room
    common = ["localize", str(log), "--map", str(run), "--max-scans", "20", "--no-record",
              "--quiet"]  # fmt: skip
    assert main([*common, "--initial", "-3,-1,0.15,0.1", "--out", str(tmp_path / "a")]) == 0
    assert main([*common, "--initial=-3,-1,0.15,0.1", "--out", str(tmp_path / "b")]) == 0
    a = json.loads((tmp_path / "a" / "metrics.json").read_text())
    b = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert a["initial"] == b["initial"] == [-3.0, -1.0, 0.15, 0.1]
    assert (tmp_path / "a" / "trajectory.tum").read_bytes() == (
        tmp_path / "b" / "trajectory.tum"
    ).read_bytes()
    assert main([*common, "--initial", "-.5,-1e0,-0.1", "--out", str(tmp_path / "c")]) == 0
    assert json.loads((tmp_path / "c" / "metrics.json").read_text())["initial"] == [-0.5, -1, -0.1]
    assert main([*common, "--initial", "-3,-1", "--out", str(tmp_path / "d")]) == 2
    assert one_line_error(capsys) == (
        "slam: error: --initial '-3,-1': expected x,y,theta or x,y,theta,sigma (metres, "
        "radians), found 2 values"
    )
    assert not (tmp_path / "d").exists()


def extent(lmap: LikelihoodMap) -> str:
    """The map's extent as the refusals of ``--initial`` give it."""
    (x0, y0), (rows, cols), res = lmap.origin, lmap.shape, lmap.resolution
    return f"x {x0:.2f} to {x0 + cols * res:.2f} m, y {y0:.2f} to {y0 + rows * res:.2f} m"


def test_an_initial_pose_off_the_map_is_refused_before_the_log_is_read(room, tmp_path, capsys):
    """The bug: ``--initial 1000,1000,0`` ran to the end, exit 0, no warning, 0 % localized.
    Now a pose outside the map's extent, or with no known-free cell within its sigma, is one
    line naming --initial, the pose and the extent, exit 2, nothing written; it is checked
    before the log is read (a log that cannot be read gives the same line)."""
    log, run = room
    unreadable = tmp_path / "bad.clf"
    unreadable.write_text("FLASER 3 1 2\n")
    span = extent(load_map(run))
    x0, y0 = load_map(run).origin
    corner = f"{x0 + 0.05:g},{y0 + 0.05:g}"
    cases = [
        ("1000,1000,0", f"the pose (1000, 1000) lies outside the map ({span}): expected a pose "
         "in the map's frame, or --global"),
        (f"{corner},0,0.1", f"the pose ({corner.replace(',', ', ')}) has no known-free cell of "
         f"the map within 0.1 m (its sigma); the map spans {span}: expected a pose in its free "
         "space, or --global"),
    ]  # fmt: skip
    for where in (log, unreadable):
        for value, message in cases:
            out = tmp_path / "o"
            assert main(["localize", str(where), "--map", str(run), "--initial", value,
                         "--out", str(out), "--quiet"]) == 2  # fmt: skip
            assert one_line_error(capsys) == f"slam: error: --initial {value!r}: {message}"
            assert not out.exists()
    # 0.5 m beyond the room's wall at x = 5 m the default sigma (1 m) reaches free cells
    assert main(["localize", str(log), "--map", str(run), "--initial", "5.5,-1,0", "--max-scans",
                 "5", "--no-record", "--out", str(tmp_path / "ok"), "--quiet"]) == 0  # fmt: skip


def test_check_initial_measures_sigma_to_the_nearest_free_cell():
    """On a hand-made map of 0.1 m cells whose only free cell spans x 1.0-1.1, y 1.0-1.1: a
    pose 0.19 m right of it is accepted with sigma 0.2, refused with 0.18; a pose outside the
    2 m x 2 m map is refused whatever its sigma."""
    from slam.errors import UsageError
    from slam.localize.run import check_initial

    occupied = np.zeros((20, 20), bool)
    occupied[0, 0] = True
    free = np.zeros((20, 20), bool)
    free[10, 10] = True
    lmap = LikelihoodMap.from_masks(occupied, free, 0.1, (0.0, 0.0))
    check_initial(lmap, (1.29, 1.05, 0.0, 0.2), 1.0)
    check_initial(lmap, (1.29, 1.05, 0.0), 0.2)  # the default sigma when none is given
    check_initial(lmap, (1.05, 1.05, 0.0, 1e-6), 1.0)  # inside the free cell
    with pytest.raises(UsageError) as exc:
        check_initial(lmap, (1.29, 1.05, 0.0, 0.18), 1.0)
    assert str(exc.value) == (
        "--initial '1.29,1.05,0,0.18': the pose (1.29, 1.05) has no known-free cell of the map "
        "within 0.18 m (its sigma); the map spans x 0.00 to 2.00 m, y 0.00 to 2.00 m: expected "
        "a pose in its free space, or --global"
    )
    with pytest.raises(UsageError, match=r"the pose \(2.01, 1\) lies outside the map"):
        check_initial(lmap, (2.01, 1.0, 0.0, 100.0), 1.0)
    with pytest.raises(UsageError, match=r"the pose \(1, -0.5\) lies outside the map"):
        check_initial(lmap, (1.0, -0.5, 0.0), 10.0)


def stepped_log(folder: Path) -> Path:
    """The room's log with a clock that steps back ``BACK_S`` at scan ``BACK_AT``."""
    angles = np.linspace(-np.pi / 2, np.pi / 2, 180)
    times = 100.0 + 0.1 * np.arange(SCANS)
    times[BACK_AT:] -= BACK_S
    poses = path(SCANS)
    lines = [flaser_line(ray_cast(p, angles), p, t) for p, t in zip(poses, times, strict=True)]
    return write_carmen(folder, lines, "stepped.clf")


def test_a_clock_stepping_back_is_written_and_counted_as_slam_run_does(room, tmp_path, capsys):
    """The bugs: on a log whose clock runs backwards ``slam localize`` wrote ``trajectory.tum``
    in file order (backward timestamps, which evo and the TUM tools reject) and no
    ``trajectory_file_order.tum``, and counted ``localized_time_s`` over the positive gaps in
    file order: the time before the step back twice, more than the log lasts (15.8 s of a
    15.55 s log here). Now the trajectory files are ``slam run``'s and the localized time is
    summed in time order; ``slam eval`` reads the folder."""
    _, run = room
    log = stepped_log(tmp_path / "log")
    out = tmp_path / "loc"
    x, y, theta = read_tum(run / "trajectory.tum").poses[0]
    assert main(["localize", str(log), "--map", str(run), f"--initial={x},{y},{theta},0.1",
                 "--no-record", "--out", str(out), "--quiet"]) == 0  # fmt: skip
    clock = ("the log's clock runs backwards at 1 of 160 poses: trajectory.tum is sorted by "
             "time, trajectory_file_order.tum keeps the file order")  # fmt: skip
    assert f"slam: warning: {clock}\n" in capsys.readouterr().err
    m = json.loads((out / "metrics.json").read_text())
    assert clock in m["warnings"]
    assert m["localized_share"] == 1.0
    assert m["duration_s"] == 15.55 and m["localized_time_s"] == 15.55
    with np.load(out / "localization.npz") as d:
        times, poses = d["times"], d["poses"]
    assert np.count_nonzero(np.diff(times) < 0) == 1  # the npz keeps the file order
    file_order = read_tum(out / "trajectory_file_order.tum")
    np.testing.assert_allclose(file_order.times, times, rtol=0, atol=1e-6)
    np.testing.assert_allclose(file_order.poses[:, :2], poses[:, :2], rtol=0, atol=1e-6)
    by_time = read_tum(out / "trajectory.tum")
    order = np.argsort(times, kind="stable")
    assert np.all(np.diff(by_time.times) >= 0)
    np.testing.assert_allclose(by_time.times, times[order], rtol=0, atol=1e-6)
    np.testing.assert_allclose(by_time.poses[:, :2], poses[order, :2], rtol=0, atol=1e-6)
    # the same writer as slam run: the same bytes for the same poses
    from slam.io.exports import write_trajectories
    from slam.trajectory import Trajectory

    write_trajectories(tmp_path, Trajectory(times, poses))
    for name in ("trajectory.tum", "trajectory_file_order.tum"):
        assert (out / name).read_bytes() == (tmp_path / name).read_bytes(), name
    assert main(["eval", str(out), "--dataset", str(log), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["poses"] == SCANS and report["trajectory"] == str(out / "trajectory.tum")


def test_a_map_of_another_building_is_warned_about(room, tmp_path, capsys):
    """The bug: a log localized on a map of another building ended with exit 0, no warning and
    `converged: true` (aces on intel's map: localized 1.3 % of its scans)."""
    log, _ = room
    other = tmp_path / "other.npz"  # a narrow corridor, nothing like the room
    log_odds = np.full((60, 400), -5.0, dtype=np.float32)
    log_odds[[0, 1, 58, 59], :] = 5.0
    np.savez(other, log_odds=log_odds, resolution=0.05, origin=np.array([-10.0, -1.5]))
    out = tmp_path / "o"
    assert main(["localize", str(log), "--map", str(other), "--initial=0,0,0,0.1", "--no-record",
                 "--out", str(out), "--quiet"]) == 0  # fmt: skip
    m = json.loads((out / "metrics.json").read_text())
    # its particles agree (localized on most scans), but its scans do not fit the map
    assert m["mean_match_quality"] < 0.3 and m["map"] == str(other)
    share = m["localized_share_after_convergence"]
    warning = (f"localized on {100 * share:.1f} % of the scans after it first converged, with a "
               f"mean match quality of {m['mean_match_quality']:.2f} (on its own building's map a "
               f"log scores 0.8–0.94): is {other} a map of this log's building")  # fmt: skip
    assert warning in capsys.readouterr().err and any(warning in w for w in m["warnings"])
