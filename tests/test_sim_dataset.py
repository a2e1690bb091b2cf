"""Simulated datasets on disk: exact ECE276A format, ground truth files, determinism, CLI, cache."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

import slam.sim.demo as demo
from slam.cli import main
from slam.io.ece276a import load_ece276a
from slam.io.tum import read_tum
from slam.sim import dataset
from slam.sim.dataset import SIM_VERSION, SimOptions, generate_dataset


def _sim(out: Path, *extra: str) -> int:
    return main(["sim", "small", "--out", str(out), "--duration", "4", "--rgbd-rate", "4",
                 "--quiet", *extra])  # fmt: skip


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same short noisy dataset twice, once without Kinect, once with another seed."""
    base = tmp_path_factory.mktemp("simruns")
    for name, extra in (
        ("a", ()),
        ("b", ()),
        ("no_rgbd", ("--no-rgbd",)),
        ("seed9", ("--seed", "9")),
    ):
        assert _sim(base / name, *extra) == 0
    return base


def _files(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def test_files_have_exactly_the_documented_keys_dtypes_and_shapes(runs):
    folder = runs / "a"
    with np.load(folder / "Encoders20.npz") as f:
        assert sorted(f.files) == ["counts", "time_stamps"]
        n = f["time_stamps"].shape[0]
        assert f["counts"].dtype == np.int16 and f["counts"].shape == (4, n)
        assert f["time_stamps"].dtype == np.float64 and f["time_stamps"].shape == (n,)
        assert f["time_stamps"][0] > 1.5e9  # Unix-like seconds
    assert 160 <= n <= 164  # 4 s at 40 Hz (the encoders bracket the scans by a few readings)
    with np.load(folder / "Imu20.npz") as f:
        assert sorted(f.files) == ["angular_velocity", "linear_acceleration", "time_stamps"]
        m = f["time_stamps"].shape[0]
        for key in ("angular_velocity", "linear_acceleration"):
            assert f[key].dtype == np.float64 and f[key].shape == (3, m)
        assert 0.95 < np.median(f["linear_acceleration"][2]) < 1.05  # gravity in g
    assert 400 <= m <= 416  # 100 Hz
    with np.load(folder / "Hokuyo20.npz") as f:
        assert sorted(f.files) == sorted(
            ["angle_min", "angle_max", "angle_increment", "range_min", "range_max", "ranges",
             "time_stamps"]
        )  # fmt: skip
        for key, value in (("angle_min", -2.356194490192345), ("angle_max", 2.356194490192345),
                           ("range_min", 0.1), ("range_max", 30.0)):  # fmt: skip
            assert f[key].shape == (1, 1) and f[key].dtype == np.float64
            assert f[key][0, 0] == value
        assert f["angle_increment"][0, 0] == pytest.approx(0.00436332, abs=1e-8)
        s = f["time_stamps"].shape[0]
        assert f["ranges"].dtype == np.float32 and f["ranges"].shape == (1081, s)
        assert f["ranges"].max() <= 30.0
    with np.load(folder / "Kinect20.npz") as f:
        assert sorted(f.files) == ["disparity_time_stamps", "rgb_time_stamps"]
        d, r = f["disparity_time_stamps"], f["rgb_time_stamps"]
        assert d.dtype == np.float64 and r.dtype == np.float64 and d.ndim == 1 and r.ndim == 1
    rgb_files = sorted((folder / "dataRGBD" / "RGB20").iterdir())
    disp_files = sorted((folder / "dataRGBD" / "Disparity20").iterdir())
    assert len(rgb_files) == r.size and len(disp_files) == d.size
    assert (folder / "dataRGBD" / "RGB20" / "rgb20_1.png").is_file()
    assert (folder / "dataRGBD" / "Disparity20" / f"disparity20_{d.size}.png").is_file()
    image = cv2.imread(str(disp_files[0]), cv2.IMREAD_UNCHANGED)
    assert image.dtype == np.uint16 and image.shape == (480, 640)
    image = cv2.imread(str(rgb_files[0]), cv2.IMREAD_UNCHANGED)
    assert image.dtype == np.uint8 and image.shape == (480, 640, 3)


def test_the_ece276a_loader_reads_every_stream(runs):
    log = load_ece276a(runs / "a", 20, need=("encoders", "imu", "scans", "kinect"))
    summary = log.summary()
    assert summary["encoders"]["rate_hz"] == pytest.approx(40.0, rel=0.02)
    assert summary["imu"]["rate_hz"] == pytest.approx(100.0, rel=0.02)
    assert summary["scans"]["rate_hz"] == pytest.approx(40.0, rel=0.02)
    assert summary["scans"]["beams"] == 1081
    assert summary["rgb"]["rate_hz"] == pytest.approx(4.0, rel=0.3)
    assert log.meta["rgbd_images"] == "present"
    assert log.rgbd.load_rgb(0).shape == (480, 640, 3)
    disparity = log.rgbd.load_disparity(0)
    valid = disparity[disparity != 2047]
    assert valid.size > 0.5 * disparity.size and 300 < np.median(valid) < 1000
    assert 0 < summary["scans"]["invalid_beams"] < 0.02 * 160 * 1081  # dropouts: a few


def test_ground_truth_files(runs):
    folder = runs / "a"
    t, poses = read_tum(folder / "groundtruth.tum")
    np.testing.assert_array_equal(poses[0], 0.0)  # starts at the world origin, heading 0
    assert np.median(np.diff(t)) <= 0.01 + 1e-6  # at least 100 Hz
    # one line per time as written (times a fraction of a microsecond apart were two lines
    # with the same stamp, which evo's check refuses)
    stamps = [line.split()[0] for line in (folder / "groundtruth.tum").read_text().splitlines()[1:]]
    assert len(set(stamps)) == len(stamps) == t.size
    with np.load(folder / "Encoders20.npz") as f:
        enc_t = f["time_stamps"]
    nearest = np.abs(t[np.clip(np.searchsorted(t, enc_t), 0, t.size - 1)] - enc_t)
    nearest = np.minimum(
        nearest, np.abs(t[np.clip(np.searchsorted(t, enc_t) - 1, 0, None)] - enc_t)
    )
    assert nearest.max() < 1.5e-6  # every encoder time is in the file (µs precision)
    with np.load(folder / "groundtruth_map.npz") as f:
        occ = f["occupancy"]
        assert occ.dtype == np.uint8 and occ.ndim == 2 and set(np.unique(occ)) == {0, 1}
        assert f["resolution"].shape == () and float(f["resolution"]) == 0.05
        assert f["origin"].shape == (2,)
        res, origin = float(f["resolution"]), f["origin"]
    # Row = y index, column = x index: the start (0, 0) is a free cell.
    assert occ[int((0 - origin[1]) // res), int((0 - origin[0]) // res)] == 0
    with np.load(folder / "groundtruth_texture.npz") as f:
        rgb, floor = f["rgb"], f["floor"]
        assert rgb.dtype == np.uint8 and rgb.shape[2] == 3 and floor.shape == rgb.shape[:2]
        assert floor.dtype == bool and float(f["resolution"]) == 0.02
    for name, shape in (
        ("groundtruth_map.png", occ.shape),
        ("groundtruth_texture.png", floor.shape),
    ):
        image = cv2.imread(str(folder / name), cv2.IMREAD_COLOR)
        assert image.shape[:2] == shape
    meta = json.loads((folder / "simulation.json").read_text())
    assert meta["version"] == SIM_VERSION and meta["scenario"] == "small" and meta["seed"] == 1
    assert "timings" not in meta


def test_same_seed_gives_byte_identical_files(runs):
    a, b = _files(runs / "a"), _files(runs / "b")
    assert a.keys() == b.keys() and len(a) > 30
    assert [k for k in a if a[k] != b[k]] == []


def test_no_rgbd_leaves_the_other_streams_unchanged(runs):
    full, light = _files(runs / "a"), _files(runs / "no_rgbd")
    assert not any(k.startswith("dataRGBD") or k.startswith("Kinect") for k in light)
    for name in ("Encoders20.npz", "Imu20.npz", "Hokuyo20.npz", "groundtruth_map.npz",
                 "groundtruth_texture.npz"):  # fmt: skip
        assert full[name] == light[name], name


def test_another_seed_gives_another_log(runs):
    a, c = _files(runs / "a"), _files(runs / "seed9")
    assert a["Hokuyo20.npz"] != c["Hokuyo20.npz"] and a["Imu20.npz"] != c["Imu20.npz"]


def test_cli_errors_are_one_line_and_exit_2(tmp_path, capsys):
    assert main(["sim", "nowhere", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "unknown simulation scenario 'nowhere'" in err and "demo" in err and "small" in err
    assert not (tmp_path / "x").exists()
    assert main(["sim", "small", "--out", str(tmp_path / "y"), "--duration", "-1"]) == 2
    assert "--duration" in capsys.readouterr().err
    assert main(["sim", "small", "--out", str(tmp_path / "y"), "--seed", "-1"]) == 2
    assert capsys.readouterr().err == "slam: error: --seed: expected an integer ≥ 0, found -1\n"
    assert main(["sim", "small", "--out", str(tmp_path / "y"), "--seed", str(2**64)]) == 2
    assert capsys.readouterr().err == (
        f"slam: error: --seed: expected an integer below 2**63, found {2**64}\n"
    )  # it said '≥ 0'
    assert not (tmp_path / "y").exists()
    (tmp_path / "z").mkdir()
    (tmp_path / "z" / "keep.txt").write_text("mine")
    assert _sim(tmp_path / "z", "--no-rgbd") == 2
    assert "exists" in capsys.readouterr().err
    assert (tmp_path / "z" / "keep.txt").read_text() == "mine"
    assert _sim(tmp_path / "z", "--no-rgbd", "--force") == 2  # not a dataset of slam sim
    assert "--force replaces only a simulated dataset" in capsys.readouterr().err
    assert (tmp_path / "z" / "keep.txt").read_text() == "mine"
    assert _sim(tmp_path / "sim", "--no-rgbd") == 0
    assert _sim(tmp_path / "sim", "--no-rgbd", "--force") == 0  # its own output: replaced
    assert (tmp_path / "sim" / "Hokuyo20.npz").is_file()
    assert (tmp_path / "sim" / ".slam-sim").is_file()


def test_cli_prints_a_summary(tmp_path, capsys):
    assert main(["sim", "small", "--out", str(tmp_path / "s"), "--duration", "2", "--no-rgbd",
                 "--number", "7"]) == 0  # fmt: skip
    line = capsys.readouterr().out.strip()
    with np.load(tmp_path / "s" / "Encoders07.npz") as f:
        n = f["time_stamps"].size
    assert line.startswith(str(tmp_path / "s")) and f"{n} encoder readings" in line
    assert "80 scans" in line and "seed 1" in line


def test_a_failed_generation_leaves_no_folder(tmp_path, monkeypatch):
    def boom(*args, **kwargs):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(dataset, "_write_kinect", boom)
    with pytest.raises(RuntimeError):
        generate_dataset(tmp_path / "out", SimOptions(scenario="small", duration=1.0, rgbd_rate=2))
    assert list(tmp_path.iterdir()) == []


def test_ensure_demo_generates_once_and_reuses_the_cache(tmp_path, monkeypatch):
    short = SimOptions(scenario="small", seed=2, number=demo.DEMO_NUMBER, duration=2.0, rgbd_rate=2)
    monkeypatch.setattr(
        demo, "demo_options", lambda rgbd=True: SimOptions(**{**short.__dict__, "rgbd": rgbd})
    )
    cache = tmp_path / "cache"
    light = demo.ensure_demo(cache, rgbd=False)
    assert light.name == f"demo-v{SIM_VERSION}-seed{demo.DEMO_SEED}-nordgbd"
    assert not (light / "dataRGBD").exists()
    full = demo.ensure_demo(cache)
    assert full.name == f"demo-v{SIM_VERSION}-seed{demo.DEMO_SEED}-rgbd10hz"
    log = load_ece276a(full, demo.DEMO_NUMBER, need=("encoders", "imu", "scans", "kinect"))
    assert log.meta["rgbd_images"] == "present"
    assert sorted(p.name for p in cache.iterdir()) == sorted(
        [light.name, full.name]
    )  # no leftovers

    def no_generation(*args, **kwargs):
        raise AssertionError("the cached demo must be reused")

    monkeypatch.setattr(demo, "write_dataset", no_generation)
    assert demo.ensure_demo(cache) == full
    assert demo.ensure_demo(cache, rgbd=False) == full  # a full demo serves both
