"""Tests for stylize3d_core.depth.files: disparity, invalid filling, range clamp, resizing, settings."""

from __future__ import annotations

import numpy as np
import pytest
import skimage.data

from stylize3d_core.depth.files import MAX_DEPTH_RATIO, load_depth_file, resize_depth
from stylize3d_core.depth.fill import fill_nearest
from stylize3d_core.errors import InputError
from stylize3d_core.io.depth_files import write_pfm


def _ramp(h=30, w=40, low=1.0, high=5.0) -> np.ndarray:
    return np.linspace(low, high, h * w).reshape(h, w).astype(np.float32)


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


def test_bad_settings(tmp_path):
    np.save(tmp_path / "d.npy", _ramp())
    with pytest.raises(InputError, match="kind"):
        load_depth_file(tmp_path / "d.npy", kind="inverse")
    with pytest.raises(InputError, match="scale"):
        load_depth_file(tmp_path / "d.npy", scale=0.0)
    with pytest.raises(InputError, match="size"):
        load_depth_file(tmp_path / "d.npy", size=(0, 40))


@pytest.mark.parametrize("size", [None, (30, 40)])
def test_empty_npy_is_an_input_error_naming_the_file(tmp_path, size):
    np.save(tmp_path / "empty.npy", np.zeros((0, 0), np.float32))
    with pytest.raises(InputError, match="empty.npy.*empty") as info:
        load_depth_file(tmp_path / "empty.npy", size=size)
    assert info.value.source == str(tmp_path / "empty.npy")


def test_resize_depth_refuses_empty_maps_and_sizes():
    with pytest.raises(InputError, match="d.npy.*empty"):
        resize_depth(np.ones((0, 0), np.float32), np.ones((0, 0), bool), (30, 40), "d.npy")
    with pytest.raises(InputError, match="d.npy.*0 x 40"):
        resize_depth(np.ones((3, 4), np.float32), np.ones((3, 4), bool), (0, 40), "d.npy")
