"""map_server maps (map.yaml + map.pgm), sorted trajectories, KITTI and ``slam export``."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import yaml

from slam.cli import main
from slam.errors import DataError
from slam.io.exports import format_kitti, write_trajectories
from slam.io.mapserver import (
    FREE_PIXEL,
    OCCUPIED_PIXEL,
    UNKNOWN_PIXEL,
    parse_map_yaml,
    read_map_yaml,
    trinary,
    write_map,
)
from slam.io.tum import format_tum, read_tum
from slam.localize.maps import load_map
from slam.trajectory import Trajectory

RES = 0.05
ORIGIN = np.array([-1.5, 0.5])


def _hand_made_map() -> np.ndarray:
    """80 × 100 cells (x −1.5..3.5 m, y 0.5..4.5 m): free, unknown in the quarter of small x and
    large y, one obstacle cell holding the world point (2.0, 3.0) and a weak cell (one miss)
    that stays unknown."""
    log_odds = np.full((80, 100), -2.0, dtype=np.float32)  # p = 0.12 < 0.196: free
    log_odds[40:, :50] = 0.0  # unknown (rows 40.. are the larger y)
    ix, iy = int((2.0 - ORIGIN[0]) / RES), int((3.0 - ORIGIN[1]) / RES)
    log_odds[iy, ix] = math.log(4.0)  # p = 0.8 > 0.65: occupied
    log_odds[5, 5] = -0.4  # p = 0.40: unknown
    return log_odds


def test_map_yaml_and_pgm_round_trip_with_an_independent_reader(tmp_path):
    log_odds = _hand_made_map()
    yaml_path = write_map(tmp_path / "map.pgm", log_odds, RES, ORIGIN)
    assert yaml_path == tmp_path / "map.yaml"

    meta = yaml.safe_load(yaml_path.read_text())  # PyYAML, not our reader
    assert meta == {
        "image": "map.pgm",
        "mode": "trinary",
        "resolution": RES,
        "origin": [-1.5, 0.5, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    image = cv2.imread(str(tmp_path / meta["image"]), cv2.IMREAD_UNCHANGED)  # OpenCV's PGM
    assert image.dtype == np.uint8 and image.shape == (80, 100)
    assert set(np.unique(image)) == {OCCUPIED_PIXEL, FREE_PIXEL, UNKNOWN_PIXEL}
    # map_server's rule, by hand: occupancy p = (255 - v) / 255, > occ occupied, < free free
    p = (255.0 - image) / 255.0
    expected = trinary(log_odds)[::-1]  # image rows: top = +y
    np.testing.assert_array_equal(p > meta["occupied_thresh"], expected == 100)
    np.testing.assert_array_equal(p < meta["free_thresh"], expected == 0)

    # the obstacle: the only black pixel, at the world point (2.0, 3.0)
    rows, cols = np.nonzero(image == OCCUPIED_PIXEL)
    assert rows.size == 1
    x = meta["origin"][0] + (cols[0] + 0.5) * meta["resolution"]
    y = meta["origin"][1] + (image.shape[0] - 1 - rows[0] + 0.5) * meta["resolution"]
    assert abs(x - 2.0) <= RES and abs(y - 3.0) <= RES
    assert rows[0] == 80 - 1 - 50 and cols[0] == 70  # y = 3.0 is above the middle (2.5 m)
    # the unknown quarter (larger y, smaller x) is the image's top left
    assert (image[:40, :50] == UNKNOWN_PIXEL).all() and (image[40:, 50:] == FREE_PIXEL).all()

    ours = read_map_yaml(yaml_path)
    np.testing.assert_array_equal(ours.occupancy, trinary(log_odds))  # cell for cell
    assert ours.resolution == RES and ours.origin.tolist() == [-1.5, 0.5, 0.0]
    ix, iy = ours.world_to_cell(np.array([2.0, 3.0]))
    assert ours.occupied()[iy, ix] and ours.occupied().sum() == 1
    np.testing.assert_allclose(ours.cell_center(ix, iy), [2.0, 3.0], atol=RES)
    assert ours.unknown()[5, 5] and ours.free()[0, 0]


def test_reader_applies_negate_scale_and_png(tmp_path):
    image = np.array([[0, 100, 205, 254]], dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "m.png"), image)
    (tmp_path / "m.yaml").write_text(
        "image: m.png\nmode: scale\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196  # comment\n"
    )
    m = read_map_yaml(tmp_path / "m.yaml")
    p = (255 - 100) / 255
    assert m.occupancy.tolist() == [[100, round(99 * (p - 0.196) / (0.65 - 0.196)), 0, 0]]
    (tmp_path / "n.yaml").write_text(
        "image: 'm.png'\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    assert read_map_yaml(tmp_path / "n.yaml").occupancy.tolist() == [[0, -1, 100, 100]]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
         "free_thresh: 0.196\n", r"m\.yaml:3: origin: expected 3 numbers"),
        ("image: m.pgm\nresolution: -1\n", r"m\.yaml:2: resolution: expected a positive"),
        ("image: m.pgm\ncolour: red\n", r"m\.yaml: missing key\(s\) resolution, origin"),
        ("map_name: a\nimage: m.pgm\nmap_name: b\n", r"m\.yaml:3: map_name is given twice"),
        ("image: m.pgm\nimage: n.pgm\n", r"m\.yaml:2: image is given twice"),
        ("image: m.pgm\nresolution: 0.05\n", r"missing key\(s\) origin, negate"),
        ("image: m.pgm\nnegate: 2\n", r"m\.yaml:2: negate: expected 0, 1, true or false, found '2'"),
        ("image: m.pgm\n  nested: 1\n", r"m\.yaml:2: expected a top-level 'key: value' line"),
        ("image: m.pgm\nmode: raw\n", r"m\.yaml:2: mode: expected one of trinary, scale"),
        ("image: m.pgm\nresolution: abc\n", r"m\.yaml:2: resolution: expected a number"),
    ],
)  # fmt: skip
def test_map_yaml_errors_name_the_line_and_key(text, message):
    with pytest.raises(DataError, match=message):
        parse_map_yaml(text, "m.yaml")


KEYS = {
    "image": "m.pgm",
    "mode": "trinary",
    "resolution": 0.05,
    "origin": [-10.0, -5.0, 0.0],
    "negate": 0,
    "occupied_thresh": 0.65,
    "free_thresh": 0.196,
}
BLOCK = (
    "image: m.pgm\nresolution: 0.05\norigin: [-10.0, -5.0, 0.0]\nnegate: 0\n"
    "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
)


@pytest.mark.parametrize(
    "text",
    [
        "\ufeff" + BLOCK,  # a byte-order mark (Windows editors)
        "{image: m.pgm, resolution: 0.05, origin: [-10.0, -5.0, 0.0], negate: 0, "
        "occupied_thresh: 0.65, free_thresh: 0.196}\n",  # a flow mapping on one line
        '{"image": "m.pgm", "resolution": 0.05,\n "origin": [-10.0, -5.0,  # x, y\n  0.0],\n'
        ' "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196, "meta": {"a": [1, 2]},}\n',
        BLOCK.replace("[-10.0, -5.0, 0.0]", "\n  - -10.0\n  - -5.0\n  - 0.0"),  # a block list
        BLOCK.replace("[-10.0, -5.0, 0.0]", "\n- -10.0\n- -5.0  # y\n\n- 0.0"),  # PyYAML's
        BLOCK.replace("[-10.0, -5.0, 0.0]", "[-10.0,\n  -5.0, 0.0]"),  # a flow list over lines
        "map_name: intel\n" + BLOCK + "saved_by: slam_toolbox\nnotes: |\n  a: [\n  # x\n"
        "meta:\n  author: me\n  tags:\n  - a\nmore:\n- 1\n- 2\n",  # unknown keys
        BLOCK.replace("0.0]", "-0.000001]"),  # float noise in the yaw
    ],
)
def test_map_yaml_as_map_server_reads_it(text):
    assert parse_map_yaml(text, "m.yaml") == KEYS
    oracle = yaml.safe_load(text.removeprefix("\ufeff"))  # PyYAML: each case is valid YAML
    assert {k: oracle[k] for k in KEYS if k not in ("mode", "origin")} == {
        k: v for k, v in KEYS.items() if k not in ("mode", "origin")
    }
    np.testing.assert_allclose(oracle["origin"], KEYS["origin"], rtol=0, atol=1e-4)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("- image: m.pgm\n  resolution: 0.05\n",
         r"m\.yaml:1: the file must be a mapping of keys \('key: value' lines\), found a list"),
        ("[image, m.pgm]\n", r"m\.yaml:1: the file must be a mapping of keys"),
        (BLOCK.replace("[-10.0, -5.0, 0.0]", "\n  - 1\n  - 2\n"),
         r"m\.yaml:3: origin: expected 3 numbers \[x, y, yaw\], found 2"),
        (BLOCK.replace("[-10.0, -5.0, 0.0]", "\n  x: 1\n"),
         r"m\.yaml:4: origin: expected '- number' lines \[x, y, yaw\], found 'x: 1'"),
        (BLOCK.replace("[-10.0, -5.0, 0.0]", "\n  - 1\n  - a\n  - 3\n"),
         r"m\.yaml:5: origin: expected a number, found 'a'"),
        (BLOCK.replace("[-10.0, -5.0, 0.0]", "[1, 2,\n"), r"m\.yaml:3: origin: '\[' is never closed"),
        ("{image: m.pgm, resolution: -1}\n", r"m\.yaml:1: resolution: expected a positive"),
        ("{image: m.pgm,\n resolution: 0.05, resolution: 1}\n",
         r"m\.yaml:2: resolution is given twice"),
        ("{image: m.pgm, resolution}\n", r"m\.yaml:1: expected 'key: value' in the mapping, "
         r"found 'resolution'"),
        ("{image: m.pgm} x\n", r"m\.yaml:1: expected nothing after the mapping's '}', found 'x'"),
        ("{image: m.pgm}\nresolution: 1\n",
         r"m\.yaml:2: expected nothing after the mapping that ends on line 1, found 'resolution"),
        ("image:\n  m.pgm\n", r"m\.yaml:2: image: expected a value on the key's line"),
    ],
)  # fmt: skip
def test_map_yaml_shape_errors(text, message):
    with pytest.raises(DataError, match=message):
        parse_map_yaml(text, "m.yaml")


def test_origin_yaw_float_noise_is_zero_a_rotation_is_refused(tmp_path):
    write_map(tmp_path / "map.pgm", _hand_made_map(), RES, ORIGIN)
    text = (tmp_path / "map.yaml").read_text()
    (tmp_path / "map.yaml").write_text(text.replace("0.0]", "-0.000001]"))
    assert read_map_yaml(tmp_path / "map.yaml").origin.tolist() == [-1.5, 0.5, 0.0]
    assert load_map(tmp_path / "map.yaml").occupied.sum() >= 1  # localize takes it
    (tmp_path / "map.yaml").write_text(text.replace("0.0]", "0.5]"))
    with pytest.raises(DataError, match=r"map\.yaml: origin yaw 0\.5 rad: expected 0"):
        load_map(tmp_path / "map.yaml")
    (tmp_path / "map.yaml").write_text(text.replace("0.0]", "0.0002]"))
    with pytest.raises(DataError, match=r"origin yaw 0\.0002 rad: expected 0"):
        load_map(tmp_path / "map.yaml")


@pytest.mark.parametrize("data", [b"", b"x"])
def test_an_empty_or_garbage_image_is_one_error(tmp_path, data):
    (tmp_path / "map.yaml").write_text(BLOCK)
    (tmp_path / "m.pgm").write_bytes(data)
    with pytest.raises(DataError, match=r"m\.pgm: not a PGM or an image OpenCV can read"):
        read_map_yaml(tmp_path / "map.yaml")


def test_truncated_pgm_is_an_error(tmp_path):
    write_map(tmp_path / "map.pgm", _hand_made_map(), RES, ORIGIN)
    data = (tmp_path / "map.pgm").read_bytes()
    (tmp_path / "map.pgm").write_bytes(data[:-10])
    with pytest.raises(
        DataError, match=r"map\.pgm: expected 8000 pixel bytes \(100×80\), found 7990"
    ):
        read_map_yaml(tmp_path / "map.yaml")


def test_trajectory_sorted_by_time_keeps_file_order_variant(tmp_path):
    times = np.array([1.0, 2.0, 1.5, 3.0, 3.0])
    poses = np.column_stack([times * 10, np.arange(5.0), np.zeros(5)])
    assert write_trajectories(tmp_path, Trajectory(times, poses)) is True
    t, p = read_tum(tmp_path / "trajectory.tum")
    np.testing.assert_array_equal(t, [1.0, 1.5, 2.0, 3.0, 3.0])
    np.testing.assert_array_equal(p[:, 1], [0, 2, 1, 3, 4])  # stable for equal times
    t, p = read_tum(tmp_path / "trajectory_file_order.tum")
    np.testing.assert_array_equal(t, times)
    ordered = tmp_path / "ordered"
    assert write_trajectories(ordered, Trajectory(np.sort(times), poses)) is False
    assert not (ordered / "trajectory_file_order.tum").exists()


def test_kitti_rows_are_pose_matrices():
    text = format_kitti(np.array([[1.0, 2.0, math.pi / 2]]))
    values = np.array(text.split(), dtype=float).reshape(3, 4)
    np.testing.assert_allclose(values, [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 0]], atol=1e-9)


def _run_folder(tmp_path):
    """A run folder as ``slam run`` writes it, before map.pgm existed (map.npz + a file-order
    trajectory)."""
    run = tmp_path / "run"
    run.mkdir()
    np.savez_compressed(run / "map.npz", log_odds=_hand_made_map(), resolution=np.float64(RES),
                        origin=ORIGIN)  # fmt: skip
    times = np.array([10.0, 10.2, 10.1, 10.3])
    poses = np.column_stack([np.arange(4.0), np.zeros(4), np.full(4, 0.5)])
    (run / "trajectory.tum").write_text(format_tum(Trajectory(times, poses)))
    return run


def test_export_every_format(tmp_path, capsys):
    run = _run_folder(tmp_path)
    for fmt in ("pgm", "png", "npz", "tum", "kitti"):
        assert main(["export", str(run), "--format", fmt]) == 0
    out = capsys.readouterr().out.split()
    export = run / "export"
    assert out == [str(export / n) for n in ("map.pgm", "map.yaml", "map_clean.png",
                   "occupancy.npz", "trajectory.tum", "trajectory.kitti", "trajectory_times.txt")]  # fmt: skip
    np.testing.assert_array_equal(
        read_map_yaml(export / "map.yaml").occupancy, trinary(_hand_made_map())
    )
    clean = cv2.imread(str(export / "map_clean.png"), cv2.IMREAD_UNCHANGED)
    assert clean.shape == (80, 100) and clean[0, 0] == 127  # unknown grey, top-left (+y up)
    with np.load(export / "occupancy.npz") as z:
        np.testing.assert_array_equal(z["occupancy"], trinary(_hand_made_map()))
        assert z["origin"].tolist() == [-1.5, 0.5, 0.0]
    t, p = read_tum(export / "trajectory.tum")
    np.testing.assert_array_equal(t, [10.0, 10.1, 10.2, 10.3])
    np.testing.assert_array_equal(p[:, 0], [0, 2, 1, 3])
    kitti = np.loadtxt(export / "trajectory.kitti")
    assert kitti.shape == (4, 12) and kitti[1, 3] == 2.0
    assert np.loadtxt(export / "trajectory_times.txt").tolist() == [10.0, 10.1, 10.2, 10.3]


def test_export_never_overwrites_without_force(tmp_path, capsys):
    run = _run_folder(tmp_path)
    target = tmp_path / "elsewhere" / "m.pgm"
    assert main(["export", str(run), "--format", "pgm", "--out", str(target)]) == 0
    assert (tmp_path / "elsewhere" / "m.yaml").read_text().startswith("image: m.pgm\n")
    (tmp_path / "elsewhere" / "m.yaml").write_text("mine\n")
    capsys.readouterr()
    assert main(["export", str(run), "--format", "pgm", "--out", str(target)]) == 2
    err = capsys.readouterr().err
    assert "exists" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert (tmp_path / "elsewhere" / "m.yaml").read_text() == "mine\n"
    assert main(["export", str(run), "--format", "pgm", "--out", str(target), "--force"]) == 0
    assert (tmp_path / "elsewhere" / "m.yaml").read_text().startswith("image: m.pgm\n")
    assert main(["export", str(tmp_path / "nope"), "--format", "tum"]) == 2
    assert "nope: expected a run folder, found nothing" in capsys.readouterr().err
    assert main(["export", str(run / "map.npz"), "--format", "tum"]) == 2
    assert "map.npz: expected a run folder, found a file" in capsys.readouterr().err


def test_export_guards_the_run_and_names_a_damaged_map(tmp_path, capsys):
    """The audit's bugs: `--format pgm --out m.yaml` wrote the YAML over the image; `--force`
    let an export replace the run's own map.npz or trajectory.tum; a dangling link was replaced
    without --force; an image name with '#' was cut at it by YAML readers; a damaged map.npz
    gave a BadZipFile, EOFError or TypeError traceback."""
    run = _run_folder(tmp_path)
    cases = (
        (["--format", "pgm", "--out", str(tmp_path / "m.yaml")], "expected a .pgm name for --format pgm"),
        (["--format", "npz", "--out", str(run / "map.npz"), "--force"], "map.npz would be written into the run folder itself"),
        (["--format", "kitti", "--out", str(run / "trajectory.tum"), "--force"], "trajectory.tum would be written into the run folder itself"),
    )  # fmt: skip
    for argv, message in cases:
        assert main(["export", str(run), *argv]) == 2
        assert message in capsys.readouterr().err
    dangling = tmp_path / "dl.tum"
    dangling.symlink_to(tmp_path / "nowhere")
    assert main(["export", str(run), "--format", "tum", "--out", str(dangling)]) == 2
    assert f"--out {dangling}: exists; it was left alone" in capsys.readouterr().err
    assert dangling.is_symlink()
    odd = tmp_path / "maps" / "map #2.pgm"
    odd.parent.mkdir()
    assert main(["export", str(run), "--format", "pgm", "--out", str(odd)]) == 0
    assert (odd.parent / "map #2.yaml").read_text().startswith('image: "map #2.pgm"\n')
    assert read_map_yaml(odd.parent / "map #2.yaml").occupancy.shape == (80, 100)
    data = (run / "map.npz").read_bytes()
    for damage, message in (
        (data[:200], "not a readable .npz archive"),
        (b"", "expected an .npz archive (a zip of arrays), found an empty file"),
        (b"resolution: 0.05\n", "expected an .npz archive (a zip of arrays), found a file starting b'reso'"),
    ):  # fmt: skip
        (run / "map.npz").write_bytes(damage)
        assert main(["export", str(run), "--format", "png", "--out", str(tmp_path / "x.png")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    for arrays, message in (
        ({"resolution": np.array([0.05, 0.05])}, "key 'resolution': expected one finite number > 0"),
        ({"resolution": np.array("0.05")}, "key 'resolution': expected one finite number > 0"),
        ({"resolution": np.inf}, "key 'resolution': expected one finite number > 0"),
        ({"origin": np.array([np.inf, 0.0])}, "key 'origin': expected 2 finite numbers"),
        ({"log_odds": np.zeros((0, 0))}, "key 'log_odds': expected a non-empty 2-D numeric array"),
        ({"origin": np.array([object(), 0.0], dtype=object)}, "key 'origin': expected a numeric array, found pickled objects"),
    ):  # fmt: skip
        fields = {"log_odds": np.zeros((4, 4)), "resolution": 0.05, "origin": np.zeros(2), **arrays}
        np.savez(run / "map.npz", **fields)
        assert main(["export", str(run), "--format", "pgm", "--out", str(tmp_path / "y.pgm")]) == 2
        assert message in capsys.readouterr().err


def test_nav2_spellings_read_as_nav2_reads_them():
    """Nav2's loadMapYaml takes negate as an int, else a bool, and yaml-cpp a quoted number."""
    text = (
        'image: m.pgm\nresolution: "0.05"\norigin: [0, 0, 0]\nnegate: false\n'
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    values = parse_map_yaml(text, "m.yaml")
    assert values["negate"] == 0 and values["resolution"] == 0.05
    assert parse_map_yaml(text.replace("false", "true"), "m.yaml")["negate"] == 1
