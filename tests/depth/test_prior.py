"""The built-in depth prior: always valid depth, believable layout on the bundled samples."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from stylize3d_core.depth.foreground import fill_small_holes, remove_ground, snap_mask_to_edges
from stylize3d_core.depth.prior import PriorSettings, estimate_horizon, estimate_prior
from stylize3d_core.errors import InputError

SAMPLES = ["astronaut", "chelsea", "coffee", "rocket", "motorcycle"]


@pytest.fixture(scope="module")
def sample_results(helpers):
    return {name: (helpers.sample_photo(name), estimate_prior(helpers.sample_photo(name))) for name in SAMPLES}


@pytest.mark.parametrize("name", SAMPLES)
def test_samples_give_valid_relative_depth(sample_results, name):
    rgb, r = sample_results[name]
    h, w = rgb.shape[:2]
    assert r.depth.shape == (h, w) and r.depth.dtype == np.float32
    assert np.isfinite(r.depth).all() and (r.depth >= 1.0 - 1e-6).all()
    ratio = r.depth.max() / r.depth.min()
    assert 3.0 <= ratio <= 10.0, f"near/far ratio {ratio:.2f}"
    # Depth recedes upwards: the bottom tenth is nearer than the top tenth.
    assert np.median(r.depth[-h // 10 :]) < np.median(r.depth[: h // 10])
    # It must have real structure (parallax), not a plain gradient: a popped-out object.
    assert 0.02 < r.foreground.mean() < 0.8


def test_portrait_subject_is_in_front(sample_results):
    _, r = sample_results["astronaut"]
    face = r.depth[100:160, 200:280]  # the astronaut's face
    corners = np.concatenate([r.depth[:60, :60].ravel(), r.depth[:60, -60:].ravel()])
    assert np.median(face) < 0.5 * np.median(corners)
    assert r.foreground[100:160, 200:280].mean() > 0.9


def test_cup_pops_out_of_the_table(sample_results):
    _, r = sample_results["coffee"]
    cup = r.depth[100:250, 250:350]
    table_far = r.depth[10:60, 480:590]  # table top, upper right
    assert np.median(cup) < 0.6 * np.median(table_far)


def test_rocket_sky_is_farthest(sample_results):
    _, r = sample_results["rocket"]
    sky = r.depth[40:120, 230:280]  # open sky left of the rocket
    assert r.sky[40:120, 230:280].mean() > 0.9
    assert np.median(sky) == pytest.approx(r.depth.max(), rel=0.05)
    assert r.horizon > 0.6  # the launch pad is low in the frame


def test_far_ratio_setting(sample_results):
    rgb, _ = sample_results["chelsea"]
    r = estimate_prior(rgb[::2, ::2], PriorSettings(far_ratio=3.0))
    assert r.depth.min() >= 1.0 - 1e-6 and r.depth.max() <= 3.0 + 1e-5


@pytest.mark.parametrize(
    "rgb",
    [
        np.zeros((40, 60, 3), np.float32),  # black
        np.ones((40, 60, 3), np.float32),  # white
        np.full((2, 2, 3), 0.5, np.float32),  # tiny
        np.random.default_rng(0).random((33, 17, 3)).astype(np.float32),  # noise, odd size
        np.random.default_rng(1).random((5, 400, 3)).astype(np.float32),  # a strip
    ],
)
def test_degenerate_images_still_give_valid_depth(rgb):
    r = estimate_prior(rgb)
    assert r.depth.shape == rgb.shape[:2]
    assert np.isfinite(r.depth).all() and (r.depth > 0).all()


def test_out_of_range_values_are_clipped_not_trusted():
    rgb = np.random.default_rng(2).normal(0.5, 2.0, (40, 60, 3)).astype(np.float32)
    r = estimate_prior(rgb)
    assert np.isfinite(r.depth).all() and (r.depth > 0).all()


def test_synthetic_object_on_a_plain_backdrop():
    h, w = 120, 160
    rgb = np.empty((h, w, 3), np.float32)
    rgb[:] = (0.55, 0.6, 0.65)  # plain grey-blue backdrop
    rgb[70:, :] = (0.45, 0.4, 0.3) + 0.05 * np.random.default_rng(0).random((h - 70, w, 1))  # textured floor
    yy, xx = np.mgrid[0:h, 0:w]
    disc = (yy - 70) ** 2 + (xx - 80) ** 2 < 28**2
    rgb[disc] = (0.9, 0.15, 0.1)  # a red ball standing on the floor
    r = estimate_prior(rgb)
    assert r.foreground[disc].mean() > 0.8 and r.foreground[~disc].mean() < 0.1
    ring = ((yy - 70) ** 2 + (xx - 80) ** 2 > 34**2) & ((yy - 70) ** 2 + (xx - 80) ** 2 < 45**2) & (yy < 70)
    assert np.median(r.depth[disc]) < np.median(r.depth[ring])


def test_horizon_from_sky_and_setting():
    sky = np.zeros((100, 80), bool)
    sky[:40] = True
    assert estimate_horizon(sky, 0.45) == pytest.approx(0.4, abs=0.01)
    assert estimate_horizon(np.zeros((100, 80), bool), 0.45) == 0.45
    rgb = np.random.default_rng(3).random((60, 80, 3)).astype(np.float32)
    assert estimate_prior(rgb, PriorSettings(horizon=0.3, foreground=False)).horizon == 0.3


def test_input_is_not_modified(helpers):
    rgb = helpers.sample_photo("coffee")[::2, ::2].copy()
    before = rgb.copy()
    estimate_prior(rgb)
    np.testing.assert_array_equal(rgb, before)


@pytest.mark.parametrize(
    "rgb, message",
    [
        (np.full((20, 20, 3), np.nan, np.float32), "NaN"),
        (np.zeros((20, 20), np.float32), "shape"),
        (np.zeros((20, 20, 4), np.float32), "shape"),
        (np.zeros((20, 20, 3), np.uint8), "float"),
        (np.zeros((1, 20, 3), np.float32), "too small"),
    ],
)
def test_bad_photos(rgb, message):
    with pytest.raises(InputError, match=message):
        estimate_prior(rgb)


@pytest.mark.parametrize(
    "kwargs", [{"far_ratio": 1.0}, {"horizon": 1.5}, {"work_size": 8}, {"edge_sigma_color": 0.0}]
)
def test_bad_settings(kwargs):
    with pytest.raises(InputError):
        PriorSettings(**kwargs)


# --------------------------------------------------------------------------- helpers


def test_snap_mask_to_edges_moves_the_outline_to_the_colour_edge():
    h, w = 30, 60
    photo = np.zeros((h, w, 3), np.float32)
    photo[:, 30:] = 1.0  # colour edge between columns 29 and 30
    soft = np.zeros((h, w), np.float32)
    soft[:, 28:] = 1.0  # upsampled mask: edge 2 px too far left, and soft
    soft[:, 27] = 0.5
    snapped = snap_mask_to_edges(soft, photo, radius=6, sigma_color=0.1)
    assert (snapped[:, 30:]).all() and not snapped[:, :30].any()


def test_fill_small_holes_and_remove_ground():
    mask = np.zeros((40, 40), bool)
    mask[5:30, 5:30] = True
    mask[10:14, 10:14] = False  # small hole: filled
    mask[0:3, 20:24] = False  # notch on the top border: not a hole of the mask... stays as is
    filled = fill_small_holes(mask, 0.25)
    assert filled[10:14, 10:14].all()
    assert not filled[35:, 35:].any()
    ground = np.zeros((50, 100), bool)
    ground[30:, :] = True  # a flat-topped band across the bottom
    ground[5:, 40:60] = True  # a person standing on it
    out = remove_ground(ground)
    assert out[5:, 40:60].all()  # the person stays
    assert not out[:, :30].any() and not out[:, 70:].any()  # the ground at both sides goes


def test_snap_in_two_threads_gives_the_one_thread_mask(monkeypatch):
    """A large band is snapped in two halves on two threads: the same mask as in one pass."""
    import stylize3d_core.depth.foreground as fg

    g = np.random.default_rng(3)
    h, w = 300, 400
    photo = cv2.GaussianBlur(g.random((h, w, 3)).astype(np.float32), (0, 0), 3)
    yy, xx = np.mgrid[:h, :w]
    soft = cv2.GaussianBlur(((yy - 150) ** 2 + (xx - 200) ** 2 < 110 ** 2).astype(np.float32), (0, 0), 4)
    monkeypatch.setattr(fg, "_SPLIT_BAND_PX", 1 << 30)
    one = snap_mask_to_edges(soft, photo, radius=9, sigma_color=0.1)
    monkeypatch.setattr(fg, "_SPLIT_BAND_PX", 1)
    two = snap_mask_to_edges(soft, photo, radius=9, sigma_color=0.1)
    assert np.array_equal(one, two) and one.sum() > 1000 and (one != (soft > 0.5)).any()
