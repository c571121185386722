"""Tests for stylize3d_core.io.depth_files: the formats and bad files (the depth policy: tests/depth/test_files.py).

Most files are read through ``depth.files.load_depth_file``, so a format is checked all the way to the DepthMap.
"""

from __future__ import annotations

import struct

import cv2
import numpy as np
import pytest
from PIL import Image

from stylize3d_core.depth.files import load_depth_file
from stylize3d_core.errors import InputError
from stylize3d_core.io.depth_files import (
    exr_unavailable_reason,
    read_depth_values,
    read_pfm,
    save_depth_png16,
    write_pfm,
)


def _ramp(h=30, w=40, low=1.0, high=5.0) -> np.ndarray:
    return np.linspace(low, high, h * w).reshape(h, w).astype(np.float32)


# ---------------------------------------------------------------------------- PFM


def test_pfm_hand_built_bytes_little_and_big_endian(write_bytes):
    # rows stored bottom-to-top: the bottom row (3, 4) comes first
    little = b"Pf\n2 2\n-1.0\n" + struct.pack("<4f", 3.0, 4.0, 1.0, 2.0)
    big = b"Pf\n2 2\n1.0\n" + struct.pack(">4f", 3.0, 4.0, 1.0, 2.0)
    expected = np.array([[1.0, 2.0], [3.0, 4.0]], np.float32)
    np.testing.assert_array_equal(read_pfm(write_bytes("l.pfm", little)), expected)
    np.testing.assert_array_equal(read_pfm(write_bytes("b.pfm", big)), expected)


def test_write_pfm_produces_the_reference_bytes(tmp_path):
    a = np.array([[1.0, 2.0], [3.0, 4.0]], np.float32)
    write_pfm(tmp_path / "l.pfm", a)
    assert (tmp_path / "l.pfm").read_bytes() == b"Pf\n2 2\n-1.0\n" + struct.pack("<4f", 3.0, 4.0, 1.0, 2.0)
    write_pfm(tmp_path / "b.pfm", a, little_endian=False)
    assert (tmp_path / "b.pfm").read_bytes() == b"Pf\n2 2\n1.0\n" + struct.pack(">4f", 3.0, 4.0, 1.0, 2.0)


@pytest.mark.parametrize("little_endian", [True, False])
def test_pfm_round_trip_grey_and_colour(tmp_path, little_endian):
    rng = np.random.default_rng(0)
    grey = rng.random((7, 5)).astype(np.float32)
    grey[0, 0], grey[1, 1] = np.inf, np.nan  # PFM keeps these as they are
    write_pfm(tmp_path / "g.pfm", grey, little_endian=little_endian)
    np.testing.assert_array_equal(read_pfm(tmp_path / "g.pfm"), grey)
    colour = rng.random((7, 5, 3)).astype(np.float32)
    write_pfm(tmp_path / "c.pfm", colour, little_endian=little_endian)
    assert (tmp_path / "c.pfm").read_bytes().startswith(b"PF\n5 7\n")
    np.testing.assert_array_equal(read_pfm(tmp_path / "c.pfm"), colour)


@pytest.mark.parametrize(
    "data, match",
    [
        (b"P6\n2 2\n255\n" + bytes(12), "not a PFM"),
        (b"Pf\n2 2\n-1.0\n" + bytes(12), "truncated"),
        (b"Pf\n2 2\n0.0\n" + bytes(16), "bad PFM header"),
        (b"Pf\n2 2\nabc\n" + bytes(16), "not a number"),
    ],
)
def test_bad_pfm(write_bytes, data, match):
    path = write_bytes("bad.pfm", data)
    with pytest.raises(InputError, match=match) as info:
        load_depth_file(path)
    assert "bad.pfm" in str(info.value)


def test_colour_pfm_depth_needs_equal_channels(tmp_path):
    d = _ramp()
    write_pfm(tmp_path / "same.pfm", np.dstack([d, d, d]))
    np.testing.assert_array_equal(load_depth_file(tmp_path / "same.pfm").depth, d)
    write_pfm(tmp_path / "diff.pfm", np.dstack([d, d, d + 1]))
    with pytest.raises(InputError, match="diff.pfm.*colour channels"):
        load_depth_file(tmp_path / "diff.pfm")


# ---------------------------------------------------------------------------- other formats


def test_npy_round_trip_and_layouts(tmp_path):
    d = _ramp()
    for name, array in {"hw": d, "hw1": d[..., None], "1hw": d[None], "f64": d.astype(np.float64)}.items():
        np.save(tmp_path / f"{name}.npy", array)
        result = load_depth_file(tmp_path / f"{name}.npy")
        np.testing.assert_array_equal(result.depth, d)
        assert result.valid.all() and result.kind == "metric" and result.source == f"file:{name}.npy (depth)"
    np.save(tmp_path / "int.npy", np.arange(1, 1201, dtype=np.int32).reshape(30, 40))
    np.testing.assert_array_equal(load_depth_file(tmp_path / "int.npy", scale=0.5).depth[0, :3], [0.5, 1.0, 1.5])


@pytest.mark.parametrize(
    "array, match",
    [
        (np.zeros((30, 40, 3), np.float32), "2-D"),
        (np.zeros(30, np.float32), "2-D"),
        (np.zeros((30, 40), bool), "numeric"),
        (np.array([{"a": 1}], dtype=object), "not a valid .npy"),
    ],
)
def test_bad_npy(tmp_path, array, match):
    np.save(tmp_path / "bad.npy", array, allow_pickle=True)
    with pytest.raises(InputError, match=match) as info:
        load_depth_file(tmp_path / "bad.npy")
    assert "bad.npy" in str(info.value)


def test_npy_truncated(tmp_path, write_bytes):
    np.save(tmp_path / "whole.npy", _ramp())
    data = (tmp_path / "whole.npy").read_bytes()
    with pytest.raises(InputError, match="cut.npy"):
        load_depth_file(write_bytes("cut.npy", data[: len(data) // 2]))


def test_png16_round_trip_with_returned_scale(tmp_path):
    d = _ramp(low=0.5, high=20.0)
    scale = save_depth_png16(tmp_path / "d.png", d)
    assert scale == pytest.approx(65535 / 20.0)
    stored = cv2.imread(str(tmp_path / "d.png"), cv2.IMREAD_UNCHANGED)
    assert stored.dtype == np.uint16 and stored.max() == 65535
    back = load_depth_file(tmp_path / "d.png", scale=1 / scale)
    np.testing.assert_allclose(back.depth, d, atol=0.5 / scale + 1e-6)


def test_png16_invalid_values_are_stored_as_zero(tmp_path):
    d = _ramp(low=0.01, high=1.0).astype(np.float64)
    d[0, :4] = (np.nan, np.inf, 0.0, -2.0)
    d[1, 0] = 1e-5  # valid but below one step: stored as 1, stays valid
    scale = save_depth_png16(tmp_path / "d.png", d, scale=1000.0)
    assert scale == 1000.0
    back = load_depth_file(tmp_path / "d.png", scale=1 / scale)
    assert not back.valid[0, :4].any() and back.valid.sum() == d.size - 4
    assert back.depth[1, 0] == pytest.approx(1e-3)


def test_save_depth_png16_rejects(tmp_path):
    with pytest.raises(InputError, match="65535"):
        save_depth_png16(tmp_path / "d.png", _ramp(high=1000.0), scale=100.0)
    with pytest.raises(InputError, match=r"\.png"):
        save_depth_png16(tmp_path / "d.tif", _ramp())
    with pytest.raises(InputError, match="no finite positive"):
        save_depth_png16(tmp_path / "d.png", np.zeros((4, 4)))
    assert not (tmp_path / "d.png").exists()


def test_png8_and_grey_rgb_png(write_image):
    g = np.arange(1, 1201).reshape(30, 40) % 250 + 1
    np.testing.assert_array_equal(load_depth_file(write_image("g8.png", g.astype(np.uint8))).depth, g)
    rgb = np.repeat(g.astype(np.uint8)[..., None], 3, axis=2)
    np.testing.assert_array_equal(load_depth_file(write_image("rgb.png", rgb)).depth, g)
    rgb[0, 0, 1] += 1
    with pytest.raises(InputError, match="rgb2.png.*colour channels"):
        load_depth_file(write_image("rgb2.png", rgb))


def test_grey_alpha_png_transparent_pixels_are_invalid(write_image):
    la = np.full((30, 40, 2), 100, np.uint8)
    la[:5, :5, 1] = 0
    result = load_depth_file(write_image("la.png", la, "LA"))
    assert not result.valid[:5, :5].any() and result.valid.sum() == 30 * 40 - 25
    np.testing.assert_array_equal(result.depth, 100)


@pytest.mark.parametrize("writer", ["cv2", "pil"])
def test_float_tiff(tmp_path, writer):
    d = _ramp()
    if writer == "cv2":
        cv2.imwrite(str(tmp_path / "d.tiff"), d)
    else:
        Image.fromarray(d, "F").save(tmp_path / "d.tiff")
    np.testing.assert_array_equal(load_depth_file(tmp_path / "d.tiff").depth, d)


def test_exr_reads_or_says_why_not(tmp_path):
    reason = exr_unavailable_reason()
    path = tmp_path / "d.exr"
    if reason is None:  # this OpenCV reads EXR: a real round trip
        d = _ramp()
        assert cv2.imwrite(str(path), d)
        np.testing.assert_array_equal(load_depth_file(path).depth, d)
    else:
        path.write_bytes(b"\x76\x2f\x31\x01" + bytes(64))
        with pytest.raises(InputError, match="d.exr.*EXR") as info:
            load_depth_file(path)
        assert reason in str(info.value)


# ---------------------------------------------------------------------------- bad files and settings


def test_bad_files_are_named(tmp_path, write_bytes, make_png_bytes):
    (tmp_path / "dir.npy").mkdir()
    whole = _ramp()
    save_depth_png16(tmp_path / "whole.png", whole)
    png = (tmp_path / "whole.png").read_bytes()
    cases = {
        tmp_path / "missing.png": "not found",
        tmp_path / "dir.npy": "folder",
        write_bytes("empty.pfm", b""): "empty",
        write_bytes("depth.bmp", b"BM" + bytes(100)): "unsupported depth file type",
        write_bytes("junk.png", b"hello world, not a png"): "not a PNG",
        write_bytes("cut.png", png[: len(png) // 2]): "truncated",
        write_bytes("huge.png", make_png_bytes(100_000, 100_000, colour_type=0)): "more than",
        write_bytes("junk.tif", b"II*\x00" + bytes(40)): "could not decode",
    }
    for path, match in cases.items():
        with pytest.raises(InputError, match=match) as info:
            load_depth_file(path)
        assert path.name in str(info.value), path


def test_raw_values_are_as_stored(write_image):
    la = np.full((30, 40, 2), 100, np.uint8)
    la[:5, :5] = (0, 0)  # transparent, and a zero value: the reader decides nothing about validity
    values, usable = read_depth_values(write_image("la.png", la, "LA"))
    assert values.dtype == np.float64 and values.shape == (30, 40)
    assert values[0, 0] == 0.0 and values[10, 10] == 100.0
    np.testing.assert_array_equal(usable, la[..., 1] > 0)


@pytest.mark.parametrize("shape", [(0, 0), (0, 40), (30, 0), (1, 0, 0), (0, 0, 1)])
def test_empty_npy_is_named(tmp_path, shape):
    np.save(tmp_path / "empty.npy", np.zeros(shape, np.float32))
    with pytest.raises(InputError, match="empty.npy.*depth map is empty"):
        read_depth_values(tmp_path / "empty.npy")


def _tiff_declaring(width: int, height: int) -> bytes:
    """A small float TIFF whose ImageWidth/ImageLength tags are rewritten to ``width`` x ``height``."""
    import io as _io
    import struct

    from PIL import Image

    buf = _io.BytesIO()
    Image.fromarray(np.ones((6, 8), np.float32)).save(buf, format="TIFF")
    data = bytearray(buf.getvalue())
    assert data[:2] == b"II"
    (ifd,) = struct.unpack_from("<I", data, 4)
    (count,) = struct.unpack_from("<H", data, ifd)
    for i in range(count):
        at = ifd + 2 + 12 * i
        tag, kind = struct.unpack_from("<HH", data, at)
        if tag in (256, 257):  # ImageWidth, ImageLength
            value = width if tag == 256 else height
            struct.pack_into("<HHII", data, at, tag, 4, 1, value)  # as LONG
    return bytes(data)


def test_tiff_declaring_a_huge_size_is_refused_before_decoding(tmp_path):
    import tracemalloc

    path = tmp_path / "huge.tiff"
    path.write_bytes(_tiff_declaring(40_000, 40_000))
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="declares 1,600,000,000 pixels, more than 150,000,000") as err:
            read_depth_values(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert str(path) in str(err.value)
    assert peak < 16 * 2**20


def test_tiff_with_rewritten_tags_still_reads_at_its_true_size(tmp_path):
    path = tmp_path / "same.tiff"
    path.write_bytes(_tiff_declaring(8, 6))
    values, _ = read_depth_values(path)
    assert values.shape == (6, 8) and np.all(values == 1.0)
