"""slam.io.png: the fast PNG decoder returns OpenCV's pixels, and hands every other PNG to OpenCV."""

from __future__ import annotations

import zlib

import cv2
import numpy as np
import pytest

from slam.io.png import read_rgb, read_unchanged


def _images(rng: np.random.Generator, shape: tuple[int, ...], dtype) -> list[np.ndarray]:
    top = np.iinfo(dtype).max
    noise = rng.integers(0, top + 1, shape, dtype=dtype)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    ramp = (yy * 7 + xx * 3) * (300 if dtype == np.uint16 else 1)
    if len(shape) == 3:
        ramp = ramp[..., None] + np.arange(shape[2]) * 50
    return [noise, (ramp % (top + 1)).astype(dtype)]


@pytest.mark.parametrize("shape", [(37, 53, 3), (1, 1, 3), (31, 17), (1, 1), (48, 64)])
def test_same_pixels_as_opencv_for_every_filter_strategy(tmp_path, shape) -> None:
    rng = np.random.default_rng(0)
    dtype = np.uint8 if len(shape) == 3 else np.uint16
    path = tmp_path / "x.png"
    checked = 0
    for image in _images(rng, shape, dtype):
        for level in (0, 1, 9):
            for strategy in range(5):  # libpng picks different row filters for these
                params = [cv2.IMWRITE_PNG_COMPRESSION, level, cv2.IMWRITE_PNG_STRATEGY, strategy]
                assert cv2.imwrite(str(path), image, params)
                if len(shape) == 3:
                    ours, theirs = read_rgb(path), cv2.imread(str(path))[:, :, ::-1]
                    assert ours.flags.c_contiguous
                else:
                    ours, theirs = read_unchanged(path), cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
                assert ours.dtype == theirs.dtype and ours.shape == theirs.shape
                assert np.array_equal(ours, theirs)
                checked += 1
    assert checked == 30


def _chunk(kind: bytes, body: bytes) -> bytes:
    crc = zlib.crc32(kind + body)
    return len(body).to_bytes(4, "big") + kind + body + crc.to_bytes(4, "big")


def _png(rows: list[bytes], width: int, height: int, depth: int, colour: int, extra=b"") -> bytes:
    header = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([depth, colour, 0, 0, 0])
    stream = zlib.compress(b"".join(rows))
    return (
        b"\x89PNG\r\n\x1a\n"
        + _chunk(b"IHDR", header)
        + extra
        + _chunk(b"IDAT", stream)
        + (_chunk(b"IEND", b""))
    )


def test_each_filter_type_by_hand(tmp_path) -> None:
    """A 2x3 RGB image, one row per filter type, against the PNG specification's arithmetic."""
    image = np.array([[[10, 20, 30], [40, 50, 60], [70, 80, 90]],
                      [[15, 25, 35], [45, 55, 65], [75, 85, 95]]], dtype=np.uint8)  # fmt: skip
    flat = image.reshape(2, -1).astype(np.int32)
    for kind in range(5):
        rows = []
        for i in range(2):
            out = []
            for x in range(9):
                a = flat[i, x - 3] if x >= 3 else 0
                b = flat[i - 1, x] if i else 0
                c = flat[i - 1, x - 3] if i and x >= 3 else 0
                p = a + b - c
                paeth = min((abs(p - a), 0, a), (abs(p - b), 1, b), (abs(p - c), 2, c))[2]
                pred = [0, a, b, (a + b) // 2, paeth][kind]
                out.append((flat[i, x] - pred) % 256)
            rows.append(bytes([kind, *out]))
        path = tmp_path / f"f{kind}.png"
        path.write_bytes(_png(rows, 3, 2, 8, 2))
        assert np.array_equal(read_rgb(path), image)


def test_other_kinds_and_broken_files_go_to_opencv(tmp_path) -> None:
    rgba = np.arange(4 * 5 * 4, dtype=np.uint8).reshape(4, 5, 4)
    cv2.imwrite(str(tmp_path / "rgba.png"), rgba)
    assert np.array_equal(
        read_rgb(tmp_path / "rgba.png"), cv2.imread(str(tmp_path / "rgba.png"))[:, :, ::-1]
    )
    grey8 = np.arange(20, dtype=np.uint8).reshape(4, 5)
    cv2.imwrite(str(tmp_path / "g8.png"), grey8)
    assert read_unchanged(tmp_path / "g8.png").dtype == np.uint8  # as OpenCV gives it
    assert read_rgb(tmp_path / "g8.png") is None  # grey is no colour frame (OpenCV: grey "RGB")
    rows = [bytes([0, 1, 2, 3])]
    gamma = _chunk(b"gAMA", (45455).to_bytes(4, "big"))
    (tmp_path / "gamma.png").write_bytes(_png(rows, 1, 1, 8, 2, gamma))
    assert np.array_equal(
        read_rgb(tmp_path / "gamma.png"), cv2.imread(str(tmp_path / "gamma.png"))[:, :, ::-1]
    )
    good = _png(rows, 1, 1, 8, 2)
    (tmp_path / "truncated.png").write_bytes(good[: len(good) - 20])
    assert read_rgb(tmp_path / "truncated.png") is None
    bad_crc = bytearray(good)
    bad_crc[-20] ^= 0xFF  # inside the IDAT chunk
    (tmp_path / "crc.png").write_bytes(bytes(bad_crc))
    assert read_rgb(tmp_path / "crc.png") is None
    (tmp_path / "filter.png").write_bytes(_png([bytes([7, 1, 2, 3])], 1, 1, 8, 2))
    assert read_rgb(tmp_path / "filter.png") is None
    assert read_rgb(tmp_path / "absent.png") is None
    assert read_unchanged(tmp_path / "absent.png") is None
