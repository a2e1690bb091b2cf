"""``slam.io.atomic``: the one PNG writer (run pictures, simulated frames, plots), and the
atomic writers' promise: the file appears whole or not at all, a failure leaves no temporary
behind and names the file the caller asked for."""

from __future__ import annotations

import errno

import cv2
import numpy as np
import pytest

from slam.io import atomic
from slam.io.atomic import atomic_path, write_bytes, write_png
from slam.sim.dataset import PNG_PARAMS


def test_round_trip_of_grey_colour_and_16_bit_images(tmp_path):
    rng = np.random.default_rng(0)
    images = {
        "grey.png": rng.integers(0, 256, (5, 7), dtype=np.uint8),
        "bgr.png": rng.integers(0, 256, (5, 7, 3), dtype=np.uint8),
        "disparity.png": rng.integers(0, 2048, (5, 7), dtype=np.uint16),
    }
    for name, image in images.items():
        write_png(tmp_path / name, image, PNG_PARAMS)
        back = cv2.imread(str(tmp_path / name), cv2.IMREAD_UNCHANGED)
        assert back.dtype == image.dtype
        np.testing.assert_array_equal(back, image)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(images)  # no temporary left


def test_bytes_are_opencv_png_whatever_the_suffix_and_an_old_file_is_replaced(tmp_path):
    image = np.arange(12, dtype=np.uint8).reshape(3, 4)
    path = tmp_path / "sub" / "plot.jpg"
    write_png(path, image)
    assert path.read_bytes() == cv2.imencode(".png", image)[1].tobytes()
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    write_png(path, image[::-1].copy())
    np.testing.assert_array_equal(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), image[::-1])


def test_a_failed_encoding_leaves_the_old_file_whole(tmp_path):
    path = tmp_path / "map.png"
    path.write_bytes(b"old")
    with pytest.raises(cv2.error):
        write_png(path, np.zeros((2, 2, 2), dtype=np.uint8))  # PNG has no 2-channel pixels
    assert path.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["map.png"]


def test_write_bytes_replaces_whole_and_a_failed_rename_names_the_asked_file(tmp_path, monkeypatch):
    path = tmp_path / "metrics.json"
    write_bytes(path, b"one")
    write_bytes(path, b"two")
    assert path.read_bytes() == b"two" and [p.name for p in tmp_path.iterdir()] == [path.name]

    def refuse(src, dst):
        raise OSError(28, "No space left on device", str(src))

    monkeypatch.setattr(atomic.os, "replace", refuse)
    with pytest.raises(OSError) as caught:
        write_bytes(path, b"three")
    assert caught.value.errno == 28 and caught.value.filename == str(path)
    assert path.read_bytes() == b"two" and [p.name for p in tmp_path.iterdir()] == [path.name]


def test_atomic_path_renames_on_success_and_removes_its_temporary_on_failure(tmp_path):
    path = tmp_path / "out" / "poses.npz"
    with atomic_path(path) as tmp:
        assert tmp.parent == path.parent and tmp.suffix == ".npz" and tmp.exists()
        tmp.write_bytes(b"new")
    assert path.read_bytes() == b"new" and sorted(p.name for p in path.parent.iterdir()) == [
        "poses.npz"
    ]
    with pytest.raises(ValueError, match="writer failed"), atomic_path(path) as tmp:
        tmp.write_bytes(b"half")
        raise ValueError("writer failed")
    assert path.read_bytes() == b"new" and [p.name for p in path.parent.iterdir()] == [path.name]
    # an error about the temporary names the real file
    with pytest.raises(OSError) as caught, atomic_path(path) as tmp:
        raise OSError(13, "Permission denied", str(tmp))
    assert caught.value.filename == str(path)


def test_write_npz_is_what_np_load_reads_and_refuses_objects_leaving_nothing(tmp_path):
    import zipfile

    from slam.io.atomic import write_npz

    rng = np.random.default_rng(0)
    grid = np.round(rng.normal(size=(300, 400)), 1).astype(np.float32)  # a map's few values
    arrays = {"log_odds": grid, "resolution": np.float64(0.05), "origin": np.array([-1.0, 2.0])}
    path = tmp_path / "map.npz"
    write_npz(path, arrays)
    with np.load(path, allow_pickle=False) as back:
        assert sorted(back.files) == sorted(arrays)
        for name, value in arrays.items():
            assert back[name].dtype == np.asarray(value).dtype
            assert np.array_equal(back[name], value)
    with zipfile.ZipFile(path) as zf:
        assert {i.compress_type for i in zf.infolist()} == {zipfile.ZIP_DEFLATED}
    assert path.stat().st_size < grid.nbytes / 2
    # the level: 1 by default, as np.savez_compressed's 6 when asked
    numpy_way = tmp_path / "numpy.npz"
    np.savez_compressed(numpy_way, **arrays)
    write_npz(tmp_path / "six.npz", arrays, level=6)
    assert (tmp_path / "six.npz").stat().st_size == numpy_way.stat().st_size
    assert path.stat().st_size > numpy_way.stat().st_size  # level 1 deflates less
    # equal arrays, the same bytes (a fixed date in the members, not the time of writing)
    write_npz(tmp_path / "again.npz", arrays)
    assert (tmp_path / "again.npz").read_bytes() == path.read_bytes()
    (tmp_path / "again.npz").unlink()
    # an object array is refused before anything is kept: no file, no temporary
    with pytest.raises(ValueError):
        write_npz(tmp_path / "bad.npz", {"x": np.array([{}, None], dtype=object)})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.npz", "numpy.npz", "six.npz"]


def test_an_output_folder_that_cannot_be_made_is_named_as_given(tmp_path, monkeypatch):
    """The bug: an unwritable parent was reported as its hidden staging folder
    (``.run.777e90d5.partial: Operation not permitted``), a name the user never gave."""
    from slam.errors import UsageError

    def refuse(parent, name):
        raise PermissionError(errno.EPERM, "Operation not permitted", str(parent / f".{name}.x"))

    monkeypatch.setattr(atomic, "make_partial", refuse)
    out = tmp_path / "runs" / "r1"
    with pytest.raises(UsageError) as caught, atomic.atomic_dir(out, kind="run"):
        pass
    assert str(caught.value) == (
        f"--out {out}: cannot write in {out.parent} (Operation not permitted)"
    )
    assert not out.exists()
