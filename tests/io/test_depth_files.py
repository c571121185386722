"""Tests for stylize3d_core.io.depth_files: formats, disparity, invalid filling, resizing, bad files."""

from __future__ import annotations

import struct

import cv2
import numpy as np
import pytest
import skimage.data
from PIL import Image

from stylize3d_core.errors import InputError
from stylize3d_core.io.depth_files import (
    MAX_DEPTH_RATIO,
    exr_unavailable_reason,
    fill_nearest,
    load_depth_file,
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


# ---------------------------------------------------------------------------- values


def test_disparity_known_values(tmp_path):
    disp = np.array([[1.0, 2.0, 4.0, 0.5]] * 4, np.float32)
    np.save(tmp_path / "disp.npy", disp)
    result = load_depth_file(tmp_path / "disp.npy", kind="disparity", scale=2.0)
    np.testing.assert_allclose(result.depth[0], [0.5, 0.25, 0.125, 1.0])
    assert result.kind == "relative" and result.source == "file:disp.npy (disparity)"


def test_zero_disparity_is_invalid_and_filled(tmp_path):
    disp = np.full((10, 10), 4.0, np.float32)
    disp[:, 5:] = 2.0
    disp[3, 7] = 0.0  # "infinitely far": no finite depth
    np.save(tmp_path / "disp.npy", disp)
    result = load_depth_file(tmp_path / "disp.npy", kind="disparity")
    assert not result.valid[3, 7] and result.valid.sum() == 99
    assert result.depth[3, 7] == 0.5  # from its neighbours


def test_invalid_values_get_the_nearest_valid_depth(tmp_path):
    d = np.ones((40, 40), np.float32)
    d[:, 20:] = 10.0  # foreground at 1, background at 10
    bad = np.zeros((40, 40), bool)
    bad[10:30, 12:28] = True  # a hole across the depth edge
    d[bad] = np.array([np.nan, np.inf, 0.0, -1.0, -np.inf])[np.arange(bad.sum()) % 5]
    write_pfm(tmp_path / "holes.pfm", d)
    result = load_depth_file(tmp_path / "holes.pfm")
    np.testing.assert_array_equal(result.valid, ~bad)
    assert np.isfinite(result.depth).all() and (result.depth > 0).all()
    assert set(np.unique(result.depth)) == {1.0, 10.0}  # never a blend of the two
    cols = np.arange(40)[None].repeat(40, 0)
    np.testing.assert_array_equal(result.depth[bad], np.where(cols[bad] < 20, 1.0, 10.0))


def test_fill_nearest_does_not_touch_its_input():
    values = np.array([[1.0, 0.0, 0.0, 5.0]])
    valid = values > 0
    np.testing.assert_array_equal(fill_nearest(values, valid), [[1.0, 1.0, 5.0, 5.0]])
    np.testing.assert_array_equal(values, [[1.0, 0.0, 0.0, 5.0]])


def test_all_or_almost_all_invalid_raises(tmp_path):
    np.save(tmp_path / "none.npy", np.full((30, 40), np.nan, np.float32))
    with pytest.raises(InputError, match="none.npy.*no valid depth"):
        load_depth_file(tmp_path / "none.npy")
    few = np.zeros((100, 100), np.float32)
    few.flat[:50] = 1.0  # 0.5 % valid
    np.save(tmp_path / "few.npy", few)
    with pytest.raises(InputError, match="few.npy.*0.50%"):
        load_depth_file(tmp_path / "few.npy")
    few.flat[:200] = 1.0  # 2 % valid is accepted
    np.save(tmp_path / "enough.npy", few)
    result = load_depth_file(tmp_path / "enough.npy")
    assert result.valid.sum() == 200 and (result.depth == 1.0).all()


def test_absurd_range_is_clamped_around_the_median(tmp_path):
    d = np.full((30, 40), 2.0, np.float32)
    d[0, 0], d[0, 1] = 1e9, 1e-9
    np.save(tmp_path / "wild.npy", d)
    result = load_depth_file(tmp_path / "wild.npy")
    assert result.depth[0, 0] == pytest.approx(2.0 * 1e3) and result.depth[0, 1] == pytest.approx(2.0 / 1e3)
    assert result.depth.max() / result.depth.min() <= MAX_DEPTH_RATIO * (1 + 1e-6)
    assert result.valid.all()


# ---------------------------------------------------------------------------- resizing


def test_resize_keeps_depth_edges_sharp(tmp_path):
    d = np.full((30, 40), 10.0, np.float32)
    d[8:23, 11:27] = 1.0  # a foreground box
    np.save(tmp_path / "box.npy", d)
    for size in ((60, 80), (15, 20), (45, 60), (9, 12), (100, 133)):
        result = load_depth_file(tmp_path / "box.npy", size=size)
        assert result.shape == size and result.valid.shape == size
        near, far = np.isclose(result.depth, 1.0, rtol=1e-5), np.isclose(result.depth, 10.0, rtol=1e-5)
        assert (near | far).all() and near.any() and far.any()  # no flying pixels in between


def test_resize_interpolates_a_plane_in_disparity(tmp_path):
    h0, w0, h, w = 30, 40, 60, 80
    disparity = lambda x: 1.0 + x / w0  # a plane: disparity linear in the pixel coordinate x
    x0 = np.arange(w0) + 0.5  # pixel centres
    np.save(tmp_path / "plane.npy", np.tile(1.0 / disparity(x0), (h0, 1)).astype(np.float32))
    result = load_depth_file(tmp_path / "plane.npy", size=(h, w))
    x = (np.arange(w) + 0.5) * w0 / w  # output pixel centres in source pixels
    inner = slice(2, -2)  # away from the clamped borders
    np.testing.assert_allclose(result.depth[:, inner], np.tile(1.0 / disparity(x), (h, 1))[:, inner], rtol=1e-5)


def test_resize_valid_mask_is_nearest(tmp_path):
    d = np.ones((30, 40), np.float32)
    d[10:20, 10:20] = np.nan
    np.save(tmp_path / "m.npy", d)
    result = load_depth_file(tmp_path / "m.npy", size=(60, 80))
    expected = np.ones((60, 80), bool)
    expected[20:40, 20:40] = False
    np.testing.assert_array_equal(result.valid, expected)


def test_aspect_mismatch_raises_naming_both_sizes(tmp_path):
    np.save(tmp_path / "d.npy", _ramp(60, 80))
    with pytest.raises(InputError, match=r"d.npy.*60 x 80.*60 x 60"):
        load_depth_file(tmp_path / "d.npy", size=(60, 60))
    assert load_depth_file(tmp_path / "d.npy", size=(61, 80)).shape == (61, 80)  # 1.6 % off: accepted


def test_motorcycle_disparity_resized_to_the_photo(tmp_path):
    left, _, disparity = skimage.data.stereo_motorcycle()  # Middlebury: inf where unknown
    write_pfm(tmp_path / "motorcycle.pfm", disparity)
    size = (left.shape[0] // 2, left.shape[1] // 2)
    result = load_depth_file(tmp_path / "motorcycle.pfm", kind="disparity", size=size)
    assert result.shape == size and result.kind == "relative"
    assert np.isfinite(result.depth).all() and (result.depth > 0).all()
    assert abs(result.valid.mean() - np.isfinite(disparity).mean()) < 0.01
    known = result.valid
    lo, hi = 1 / disparity[np.isfinite(disparity)].max(), 1 / disparity[np.isfinite(disparity)].min()
    assert lo * 0.999 <= result.depth[known].min() and result.depth[known].max() <= hi * 1.001


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


def test_bad_settings(tmp_path):
    np.save(tmp_path / "d.npy", _ramp())
    with pytest.raises(InputError, match="kind"):
        load_depth_file(tmp_path / "d.npy", kind="inverse")
    with pytest.raises(InputError, match="scale"):
        load_depth_file(tmp_path / "d.npy", scale=0.0)
    with pytest.raises(InputError, match="size"):
        load_depth_file(tmp_path / "d.npy", size=(0, 40))
