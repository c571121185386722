"""Tests of the layered depth image (stylize3d_core/scene/ldi.py) and its helpers."""

from __future__ import annotations


import numpy as np
import pytest

from stylize3d_core.depth.types import DepthMap
from stylize3d_core.errors import InputError
from stylize3d_core.geometry.camera import NEAR_DEPTH
from stylize3d_core.scene._fill import cross_median, push_pull, torn_regions
from stylize3d_core.scene.ldi import (
    BORDER,
    ORIGINAL,
    LDISettings,
    build_ldi,
)

from ldi_cases import inner_outline, outer_outline, photo, square_scene


# ---------------------------------------------------------------- helpers


def test_cross_median_matches_reference():
    rng = np.random.default_rng(0)
    x = rng.random((23, 31)).astype(np.float32)
    p = np.pad(x, 1, mode="edge")
    stack = np.stack([p[1:-1, 1:-1], p[:-2, 1:-1], p[2:, 1:-1], p[1:-1, :-2], p[1:-1, 2:]])
    np.testing.assert_array_equal(cross_median(x), np.median(stack, axis=0))


def test_cross_median_removes_speckle_keeps_corners():
    x = np.zeros((12, 12), np.float32)
    x[2:6, 2:6] = 1.0  # square: corners must survive
    x[9, 9] = 5.0  # single-pixel speckle: removed
    y = cross_median(x)
    np.testing.assert_array_equal(y[2:6, 2:6], 1.0)
    assert y[9, 9] == 0.0
    assert y.sum() == 16.0


def test_push_pull_keeps_sources_and_is_convex():
    rng = np.random.default_rng(1)
    values = rng.random((40, 50, 3)).astype(np.float32)
    weight = (rng.random((40, 50)) < 0.05).astype(np.float32)
    out = push_pull(values, weight)
    src = weight > 0
    np.testing.assert_allclose(out[src], values[src], atol=1e-6)
    lo, hi = values[src].min(axis=0), values[src].max(axis=0)
    assert (out >= lo - 1e-5).all() and (out <= hi + 1e-5).all()
    const = push_pull(np.full((40, 50, 2), 0.7, np.float32), weight)
    np.testing.assert_allclose(const, 0.7, atol=1e-6)


def test_torn_regions_counts_enclosed_island():
    nd = np.zeros((10, 12), np.float32)
    nd[3:5, 6:8] = 1.0
    cut_h = np.abs(np.diff(nd, axis=1)) > 0.5
    cut_v = np.abs(np.diff(nd, axis=0)) > 0.5
    g = torn_regions(cut_h, cut_v)
    assert g.areas[0] == 0 and sorted(g.areas[1:].tolist()) == [4, 116]
    assert len(np.unique(g.labels[3:5, 6:8])) == 1


# ---------------------------------------------------------------- (a) plane


def test_fronto_parallel_plane():
    rng = np.random.default_rng(2)
    rgb = rng.random((48, 64, 3)).astype(np.float32)
    depth = np.full((48, 64), 2.5, np.float32)
    ldi = build_ldi(rgb, depth)
    assert not ldi.inpainted
    assert not ldi.fg_edge.any() and not ldi.bg_edge.any() and not ldi.hidden_mask.any()
    assert ldi.depth_scale == pytest.approx(NEAR_DEPTH / 2.5)
    # the border is sized for the camera range, within its cap; a fixed border is kept exactly
    assert 0 < ldi.pad <= round(LDISettings().max_border * 64)
    assert build_ldi(rgb, depth, LDISettings(border=0.08)).pad == round(0.08 * 64)
    assert ldi.canvas_size == (48 + 2 * ldi.pad, 64 + 2 * ldi.pad)
    np.testing.assert_allclose(ldi.depth, NEAR_DEPTH, rtol=1e-6)  # border too
    np.testing.assert_array_equal(photo(ldi, ldi.rgb), rgb)
    assert (photo(ldi, ldi.label) == ORIGINAL).all()
    assert (ldi.label == BORDER).sum() == ldi.depth.size - 48 * 64
    assert ldi.num_points == ldi.depth.size


def test_border_of_constant_photo_has_its_colour():
    rgb = np.broadcast_to(np.float32([0.2, 0.5, 0.9]), (32, 40, 3))
    ldi = build_ldi(rgb, np.full((32, 40), 4.0, np.float32))
    np.testing.assert_allclose(ldi.rgb, np.broadcast_to(rgb[0, 0], ldi.rgb.shape), atol=1e-5)


def test_no_border():
    rgb, depth, _ = square_scene()
    ldi = build_ldi(rgb, depth, LDISettings(border=0.0))
    assert ldi.pad == 0 and ldi.canvas_size == (96, 96)
    assert (ldi.label == ORIGINAL).all()


# ---------------------------------------------------------------- (b) square on a wall


@pytest.mark.parametrize("size,lo,hi", [(96, 30, 70), (160, 20, 140)])
def test_square_on_wall(size, lo, hi):
    rgb, depth, square = square_scene(size, lo, hi)
    ldi = build_ldi(rgb, depth, LDISettings(band=0.04))  # a fixed band: its exact extent is known
    assert ldi.inpainted
    assert ldi.depth_scale == pytest.approx(NEAR_DEPTH / 1.0)
    fg, bg = photo(ldi, ldi.fg_edge), photo(ldi, ldi.bg_edge)
    np.testing.assert_array_equal(fg, inner_outline(square))
    np.testing.assert_array_equal(bg, outer_outline(square))
    assert not ldi.fg_edge[ldi.label == BORDER].any()

    band_px = round(0.04 * size)
    i, j = np.mgrid[:size, :size]
    to_side = np.minimum.reduce([i - lo, hi - 1 - i, j - lo, hi - 1 - j])  # distance to the outline
    mask = photo(ldi, ldi.hidden_mask)
    np.testing.assert_array_equal(mask, square & (to_side <= band_px))
    assert not ldi.hidden_mask[ldi.label == BORDER].any()

    wall, near = 3.0 * ldi.depth_scale, 1.0 * ldi.depth_scale
    np.testing.assert_allclose(photo(ldi, ldi.depth)[square], near, rtol=1e-6)
    np.testing.assert_allclose(photo(ldi, ldi.depth)[~square], wall, rtol=1e-6)
    hidden_depth = photo(ldi, ldi.hidden_depth)[mask]
    np.testing.assert_allclose(hidden_depth, wall, rtol=1e-3)
    hidden_rgb = photo(ldi, ldi.hidden_rgb)[mask]  # (M, 3)
    assert hidden_rgb[:, 0].max() < 0.02, "foreground red leaked into the hidden layer"
    assert hidden_rgb[:, 2].min() > 0.98


def test_textured_square_hidden_colour_comes_from_wall():
    rng = np.random.default_rng(3)
    rgb, depth, square = square_scene(128, 24, 104)
    wall_tex = rng.uniform(0.0, 0.3, (128, 128, 3)).astype(np.float32)
    wall_tex[..., 2] += 0.7  # blue-ish noise
    sq_tex = rng.uniform(0.0, 0.3, (128, 128, 3)).astype(np.float32)
    sq_tex[..., 0] += 0.7  # red-ish noise
    rgb = np.where(square[..., None], sq_tex, wall_tex)
    ldi = build_ldi(rgb, depth)
    hidden = photo(ldi, ldi.hidden_rgb)[photo(ldi, ldi.hidden_mask)]
    assert hidden.shape[0] > 0
    assert hidden[:, 0].max() <= 0.3 + 1e-2 and hidden[:, 2].min() >= 0.7 - 1e-2


def test_nested_objects_hidden_layer_takes_the_next_surface():
    """Behind a small box inside a bigger box, the hidden layer is the bigger box, not the wall."""
    depth = np.full((100, 100), 3.0, np.float32)
    depth[10:90, 10:90] = 2.0
    depth[40:60, 40:60] = 1.0
    rgb = np.full((100, 100, 3), 0.5, np.float32)
    ldi = build_ldi(rgb, depth)
    mask = photo(ldi, ldi.hidden_mask)
    inner = np.zeros_like(mask)
    inner[40:60, 40:60] = True
    assert mask[inner].any() and mask[~inner].any()
    hd = photo(ldi, ldi.hidden_depth)
    np.testing.assert_allclose(hd[mask & inner], 2.0 * ldi.depth_scale, rtol=0.02)
    np.testing.assert_allclose(hd[mask & ~inner], 3.0 * ldi.depth_scale, rtol=0.02)


def test_hidden_layer_is_behind_and_finite_on_noise():
    rng = np.random.default_rng(4)
    rgb = rng.random((64, 80, 3)).astype(np.float32)
    depth = np.kron(1.0 + 4.0 * rng.random((8, 10)), np.ones((8, 8))).astype(np.float32)
    ldi = build_ldi(rgb, depth)
    m = ldi.hidden_mask
    assert m.any()
    # behind the foreground by at least the jump in normalised disparity
    gap = NEAR_DEPTH / ldi.depth[m] - NEAR_DEPTH / ldi.hidden_depth[m]
    assert (gap >= 0.04 - 1e-5).all()
    for a in (ldi.rgb, ldi.depth, ldi.hidden_rgb, ldi.hidden_depth):
        assert np.isfinite(a).all()
    assert (ldi.hidden_rgb >= 0).all() and (ldi.hidden_rgb <= 1).all()


def test_short_edges_are_ignored():
    depth = np.full((64, 64), 3.0, np.float32)
    depth[20:40, 30] = 1.0  # a 1-px wide line survives the median but ...
    ldi = build_ldi(np.zeros((64, 64, 3), np.float32), depth, LDISettings(edge_min_px=50))
    assert not ldi.fg_edge.any() and not ldi.inpainted  # ... its edge is too short to tear


# ---------------------------------------------------------------- (c) tiny islands


def test_tiny_speck_is_flattened():
    rgb, depth, _ = square_scene(64, 30, 32)  # a 2 x 2 speck at depth 1 on a wall at 3
    ldi = build_ldi(rgb, depth)
    assert not ldi.fg_edge.any() and not ldi.bg_edge.any() and not ldi.inpainted
    np.testing.assert_allclose(ldi.depth, NEAR_DEPTH, rtol=1e-6)  # every point on the wall


def test_tiny_hole_is_filled_with_its_surroundings():
    depth = np.full((64, 64), 3.0, np.float32)
    depth[10:50, 10:50] = 1.0
    depth[30:32, 30:32] = 3.0  # a 2 x 2 hole through the square
    ldi = build_ldi(np.zeros((64, 64, 3), np.float32), depth)
    np.testing.assert_allclose(photo(ldi, ldi.depth)[30:32, 30:32], 1.0 * ldi.depth_scale, rtol=1e-6)
    assert not photo(ldi, ldi.fg_edge)[25:37, 25:37].any()


# ---------------------------------------------------------------- (d) slanted plane


def test_slanted_plane_has_no_discontinuity():
    h, w = 64, 80
    disparity = np.linspace(1.0, 1.0 / 3.0, h, dtype=np.float32)[:, None]  # a plane: disparity linear in v
    depth = np.broadcast_to(1.0 / disparity, (h, w)).astype(np.float32)
    ldi = build_ldi(np.full((h, w, 3), 0.5, np.float32), depth)
    assert not ldi.fg_edge.any() and not ldi.inpainted
    assert np.isfinite(ldi.depth).all()
    p, d = ldi.pad, ldi.depth
    rows = slice(p, p + h)
    # the border continues the background: never nearer than the photo's border pixel
    assert (d[rows, :p] >= d[rows, p : p + 1] * (1 - 1e-6)).all()
    assert (d[rows, p + w :] >= d[rows, p + w - 1 : p + w] * (1 - 1e-6)).all()
    assert (d[: p] >= d[p : p + 1].min() * (1 - 1e-6)).all()


# ---------------------------------------------------------------- (e) normalisation


def test_depth_normalisation():
    rng = np.random.default_rng(5)
    depth = np.exp(rng.normal(1.0, 0.3, (40, 50))).astype(np.float32)
    rgb = rng.random((40, 50, 3)).astype(np.float32)
    ldi = build_ldi(rgb, depth, LDISettings(median_filter=False, disparity_jump=0.9))
    assert np.percentile(depth * ldi.depth_scale, 1) == pytest.approx(NEAR_DEPTH, rel=1e-6)
    np.testing.assert_allclose(photo(ldi, ldi.depth), depth * ldi.depth_scale, rtol=1e-5)
    scaled = build_ldi(rgb, depth * 7.0, LDISettings(median_filter=False, disparity_jump=0.9))
    assert scaled.depth_scale == pytest.approx(ldi.depth_scale / 7.0, rel=1e-6)
    np.testing.assert_allclose(scaled.depth, ldi.depth, rtol=1e-5)


def test_accepts_depth_map_and_uint8_and_does_not_mutate():
    rgb, depth, _ = square_scene(48, 10, 30)
    rgb8 = (rgb * 255).astype(np.uint8)
    rgb8_before, depth_before = rgb8.copy(), depth.copy()
    dm = DepthMap(depth, np.ones_like(depth, bool), "relative", "synthetic")
    a = build_ldi(rgb8, dm)
    b = build_ldi(rgb, depth)
    np.testing.assert_array_equal(rgb8, rgb8_before)
    np.testing.assert_array_equal(depth, depth_before)
    np.testing.assert_allclose(a.depth, b.depth)
    np.testing.assert_array_equal(a.hidden_mask, b.hidden_mask)


# ---------------------------------------------------------------- (f) bad inputs


@pytest.mark.parametrize(
    "case",
    ["shape_mismatch", "nan", "inf", "zero", "negative", "too_small", "rgb_channels", "rgb_range",
     "rgb_nan", "rgb_dtype", "depth_3d"],
)
def test_bad_inputs_raise(case):
    rgb = np.full((32, 32, 3), 0.5, np.float32)
    depth = np.full((32, 32), 2.0, np.float32)
    if case == "shape_mismatch":
        depth = np.full((32, 30), 2.0, np.float32)
    elif case == "nan":
        depth[3, 4] = np.nan
    elif case == "inf":
        depth[3, 4] = np.inf
    elif case == "zero":
        depth[3, 4] = 0.0
    elif case == "negative":
        depth[3, 4] = -1.0
    elif case == "too_small":
        rgb, depth = rgb[:8, :8], depth[:8, :8]
    elif case == "rgb_channels":
        rgb = rgb[..., :2]
    elif case == "rgb_range":
        rgb = rgb * 255.0
    elif case == "rgb_nan":
        rgb[0, 0, 0] = np.nan
    elif case == "rgb_dtype":
        rgb = (rgb * 1000).astype(np.int16)
    elif case == "depth_3d":
        depth = depth[..., None]
    with pytest.raises(InputError):
        build_ldi(rgb, depth)


@pytest.mark.parametrize(
    "kwargs",
    [{"band": -0.1}, {"border": 2.0}, {"disparity_jump": 0.0}, {"hidden_depth": "fast"},
     {"edge_min_px": 2.5}, {"island_area": float("nan")}],
)
def test_bad_settings_raise(kwargs):
    with pytest.raises(InputError):
        LDISettings(**kwargs)


def test_settings_type_is_checked():
    with pytest.raises(InputError):
        build_ldi(np.zeros((32, 32, 3), np.float32), np.ones((32, 32), np.float32), settings={"band": 0.1})


# ---------------------------------------------------------------- (g) a real photo


def test_real_photo_disc_in_front_of_ramp():
    skimage_data = pytest.importorskip("skimage.data")
    rgb = skimage_data.astronaut()  # (512, 512, 3) uint8
    h, w = rgb.shape[:2]
    rows = np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None]
    depth = np.broadcast_to(4.0 - 2.0 * rows, (h, w)).astype(np.float32).copy()
    i, j = np.mgrid[:h, :w]
    disc = (i - 200) ** 2 + (j - 250) ** 2 < 110**2
    depth[disc] = 1.2
    ldi = build_ldi(rgb, depth)
    assert ldi.inpainted
    for a in (ldi.rgb, ldi.depth, ldi.hidden_rgb, ldi.hidden_depth):
        assert np.isfinite(a).all()
    assert (ldi.depth > 0).all()
    m = ldi.hidden_mask
    assert (ldi.hidden_depth[m] > ldi.depth[m]).all()
    # the hidden layer lies behind the disc only, and behind the pixels just outside it that joined
    # it (where the disc cuts the photo's texture, 63 of the 624 happen to look mostly like the
    # pixels just inside, across a colour edge: LDISettings.unmix_silhouettes)
    joined = photo(ldi, m) & ~disc
    assert not (joined & ~outer_outline(disc)).any() and joined.sum() < 0.15 * outer_outline(disc).sum()
    assert np.allclose(photo(ldi, ldi.depth)[joined], 1.2 * ldi.depth_scale, rtol=1e-4)
    # the hidden layer continues the ramp: its depth lies within the ramp's range around the disc
    ramp = depth[~disc] * ldi.depth_scale
    hd = ldi.hidden_depth[m]
    assert hd.min() >= ramp.min() * 0.99 and hd.max() <= ramp.max() * 1.01
